//! A scene written back as a GLB with its generated levels of detail as
//! `MSFT_lod` nodes (`impostor lod`).
//!
//! The levels are the ones the cost model uses ([`super::lod::generate`]
//! with the job's `lod` options and camera): the same simplification steps
//! are kept, their index lists are the very ones counted, and the switching
//! coverages are the levels' [`LodLevel::min_coverage`]. Each object becomes
//! one node in the default scene, in object order, named as the object and
//! placed by its world transform; its full-detail mesh holds its
//! primitives with their materials. An object with generated levels gets,
//! before its node, one node per coarser level (same transform, a mesh of
//! the simplified primitives), listed in `extensions.MSFT_lod.ids`, and
//! `extras.MSFT_screencoverage` with one value per level including the full
//! one, the last 0 — exactly what [`crate::scene::gltf_load`] reads back.
//!
//! A level's geometry keeps only positions (the welded vertices the
//! simplifier works on) and, when the primitive has them, the texture
//! coordinates of the first original vertex at each position; without
//! normals, glTF viewers shade it flat. A primitive simplified away to no
//! triangles is left out of its level (which then has fewer draw calls
//! than the cost model counts: it keeps the object's); a level left with
//! no primitives ends the chain (the level before it is then drawn down to
//! coverage 0).
//! Levels the input file carried itself are not written (their geometry is
//! not read): such objects are written at full detail only.
//!
//! [`LodLevel::min_coverage`]: crate::api::scene::LodLevel::min_coverage

use std::collections::BTreeMap;

use glam::DAffine3;
use rayon::prelude::*;
use serde_json::json;

use crate::api::job::LodParams;
use crate::api::stats::LodReport;
use crate::scene::Scene;
use crate::scene::geometry::SceneGeometry;
use crate::scene::glb::{self, GlbBuilder, MeshPrimitive, Node};
use crate::scene::lod::{Simplified, generate_kept, simplify_levels};
use crate::{Error, Result};

/// What [`write_lod_glb`] wrote.
#[derive(Clone, Debug)]
pub struct LodWritten {
    /// The GLB file.
    pub glb: Vec<u8>,
    /// The generation's report (as `place` gives it).
    pub report: LodReport,
    /// Objects written with coarser levels.
    pub objects_with_levels: u64,
    /// Level nodes written.
    pub level_nodes: u64,
}

/// Generates levels of detail for `scene` from its geometry `geom` (see
/// [`super::lod::generate`] for the parameters) and writes the scene with
/// them as a GLB (see the module notes).
pub fn write_lod_glb(
    scene: &Scene,
    geom: &SceneGeometry,
    params: &LodParams,
    focal_px: f64,
    screen_px: f64,
    max_error_px: f64,
) -> Result<LodWritten> {
    let mut scene = scene.clone();
    let (report, steps) =
        generate_kept(&mut scene, geom, params, focal_px, screen_px, max_error_px)?;
    let ranges = geom.instance_ranges();

    // Simplify once per distinct mesh of an object with levels (the same
    // call, so the same index lists, as the generation's).
    let mut wanted: Vec<u32> = Vec::new();
    for (id, s) in steps.iter().enumerate() {
        if !s.is_empty() {
            let (a, b) = ranges[id];
            wanted.extend(geom.instances[a..b].iter().map(|i| i.mesh));
        }
    }
    wanted.sort_unstable();
    wanted.dedup();
    let simplified: Vec<Result<Simplified>> = wanted
        .par_iter()
        .map(|&m| simplify_levels(&geom.meshes[m as usize], m, params))
        .collect();
    let mut cache: BTreeMap<u32, Simplified> = BTreeMap::new();
    for (&m, s) in wanted.iter().zip(simplified) {
        cache.insert(m, s?);
    }

    let mut b = GlbBuilder::new();
    let materials = add_materials(&mut b, geom)?;
    // Full-detail geometry, written once per mesh primitive.
    let mut full: BTreeMap<u32, glb::GeometryId> = BTreeMap::new();
    // Simplified geometry per (mesh, step); `None` when nothing is left.
    let mut coarse: BTreeMap<(u32, usize), Option<glb::GeometryId>> = BTreeMap::new();
    let mut roots = Vec::with_capacity(scene.objects.len());
    let (mut objects_with_levels, mut level_nodes) = (0u64, 0u64);
    for (id, o) in scene.objects.iter().enumerate() {
        let (a, b_end) = ranges[id];
        let insts = &geom.instances[a..b_end];
        let transform = insts.first().map(|i| i.transform);
        let mut prims = Vec::with_capacity(insts.len());
        for inst in insts {
            let g = match full.get(&inst.mesh) {
                Some(&g) => g,
                None => {
                    let m = &geom.meshes[inst.mesh as usize];
                    let positions: Vec<[f32; 3]> =
                        m.positions.iter().map(|p| p.to_array()).collect();
                    let normals: Vec<[f32; 3]> = m.normals.iter().map(|n| n.to_array()).collect();
                    let uvs: Vec<[f32; 2]> = m.uvs.iter().map(|t| t.to_array()).collect();
                    let g = b.add_geometry(&glb::Geometry {
                        positions: &positions,
                        normals: (!normals.is_empty()).then_some(&normals[..]),
                        texcoords: (!uvs.is_empty()).then_some(&uvs[..]),
                        indices: &m.indices,
                    })?;
                    full.insert(inst.mesh, g);
                    g
                }
            };
            prims.push(MeshPrimitive {
                geometry: g,
                material: materials
                    .get(geom.meshes[inst.mesh as usize].material as usize)
                    .copied()
                    .flatten(),
            });
        }
        let mut node = Node::new(o.name.clone());
        if let Some(t) = transform {
            node = placed(node, &t);
        }
        if prims.is_empty() {
            // An object whose primitives are all points or lines: no mesh
            // to write, so it cannot stay an object.
            return Err(Error::bad(
                format!("lod: object {id} ({})", o.name),
                "has no triangles to write",
            ));
        }
        node = node.with_mesh(b.add_mesh(&o.name, &prims)?);

        let mut ids = Vec::new();
        let mut coverages = Vec::new();
        for (j, &k) in steps[id].iter().enumerate() {
            let mut level_prims = Vec::new();
            for inst in insts {
                let key = (inst.mesh, k);
                let g = match coarse.get(&key) {
                    Some(&g) => g,
                    None => {
                        let g = add_level(&mut b, geom, &cache[&inst.mesh], inst.mesh, k)?;
                        coarse.insert(key, g);
                        g
                    }
                };
                if let Some(g) = g {
                    level_prims.push(MeshPrimitive {
                        geometry: g,
                        material: materials
                            .get(geom.meshes[inst.mesh as usize].material as usize)
                            .copied()
                            .flatten(),
                    });
                }
            }
            if level_prims.is_empty() {
                break;
            }
            let name = format!("{} LOD{}", o.name, j + 1);
            let mesh = b.add_mesh(&name, &level_prims)?;
            let mut level = Node::new(name).with_mesh(mesh);
            if let Some(t) = transform {
                level = placed(level, &t);
            }
            ids.push(b.add_node(level)?);
            coverages.push(o.lods[j].min_coverage);
        }
        if !ids.is_empty() {
            coverages.push(o.lods[ids.len()].min_coverage);
            if let Some(last) = coverages.last_mut() {
                // A chain cut short: its last written level is never culled.
                if ids.len() + 1 < o.lods.len() {
                    *last = 0.0;
                }
            }
            objects_with_levels += 1;
            level_nodes += ids.len() as u64;
            node = node
                .with_extension("MSFT_lod", json!({ "ids": ids }))
                .with_extras(json!({ "MSFT_screencoverage": coverages }));
        }
        roots.push(b.add_node(node)?);
    }
    b.set_scene_roots(&roots)?;
    Ok(LodWritten {
        glb: b.finish(),
        report,
        objects_with_levels,
        level_nodes,
    })
}

/// The scene's materials in the builder (with their base colour textures
/// as PNG images), by geometry material index; `None` for the trailing
/// glTF default material.
fn add_materials(b: &mut GlbBuilder, geom: &SceneGeometry) -> Result<Vec<Option<u32>>> {
    let mut textures = Vec::with_capacity(geom.textures.len());
    for (t, tex) in geom.textures.iter().enumerate() {
        textures.push(b.add_loaded_texture(&format!("texture {t}"), tex)?);
    }
    let last = geom.materials.len().saturating_sub(1);
    geom.materials
        .iter()
        .enumerate()
        .map(|(i, m)| {
            if i == last {
                return Ok(None);
            }
            let mut m = m.clone();
            m.base_color_texture = m
                .base_color_texture
                .map(|t| {
                    textures.get(t as usize).copied().ok_or_else(|| {
                        Error::Internal(format!("material {i} names missing texture {t}"))
                    })
                })
                .transpose()?;
            b.add_material(&m).map(Some)
        })
        .collect()
}

/// Writes step `k` of mesh `m` (its used welded vertices, their texture
/// coordinates when the mesh has them); `None` when no triangle is left.
fn add_level(
    b: &mut GlbBuilder,
    geom: &SceneGeometry,
    s: &Simplified,
    m: u32,
    k: usize,
) -> Result<Option<glb::GeometryId>> {
    let (indices, _) = &s.levels[k - 1];
    if indices.is_empty() {
        return Ok(None);
    }
    let mesh = &geom.meshes[m as usize];
    let mut remap = vec![u32::MAX; s.positions.len()];
    let mut positions = Vec::new();
    let mut uvs = Vec::new();
    let mut out = Vec::with_capacity(indices.len());
    for &i in indices {
        let slot = &mut remap[i as usize];
        if *slot == u32::MAX {
            *slot = positions.len() as u32;
            positions.push(s.positions[i as usize]);
            if !mesh.uvs.is_empty() {
                uvs.push(mesh.uvs[s.first[i as usize] as usize].to_array());
            }
        }
        out.push(*slot);
    }
    b.add_geometry(&glb::Geometry {
        positions: &positions,
        normals: None,
        texcoords: (!uvs.is_empty()).then_some(&uvs[..]),
        indices: &out,
    })
    .map(Some)
}

/// A node placed by a world transform: translation, rotation and scale
/// when they reproduce it, else its column-major matrix.
fn placed(node: Node, t: &DAffine3) -> Node {
    let (scale, rotation, translation) = t.to_scale_rotation_translation();
    let back = DAffine3::from_scale_rotation_translation(scale, rotation, translation);
    let size = t
        .matrix3
        .to_cols_array()
        .iter()
        .fold(1.0f64, |m, v| m.max(v.abs()));
    if back.abs_diff_eq(*t, 1e-9 * size.max(t.translation.abs().max_element())) {
        let f = |v: glam::DVec3| v.as_vec3().to_array();
        node.with_trs(f(translation), rotation.as_quat().to_array(), f(scale))
    } else {
        node.with_matrix(glam::DMat4::from(*t).to_cols_array().map(|v| v as f32))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::citygen::{CityParams, generate};
    use crate::scene::geometry::load_geometry_bytes;
    use crate::scene::gltf_load::load_scene_bytes;

    #[test]
    fn the_written_levels_are_the_cost_models() {
        let glb = generate(&CityParams {
            seed: 2,
            scale: 0.05,
            lod: false,
            ..Default::default()
        })
        .unwrap();
        let scene = load_scene_bytes(&glb, "city").unwrap();
        let geom = load_geometry_bytes(&glb, "city").unwrap();
        let params = LodParams {
            generate: true,
            ..LodParams::default()
        };
        let (focal, screen, err) = (618.0, 512.0 * 512.0, 1.0);
        let written = write_lod_glb(&scene, &geom, &params, focal, screen, err).unwrap();
        let mut expected = scene.clone();
        crate::scene::lod::generate(&mut expected, &geom, &params, focal, screen, err).unwrap();
        assert!(written.objects_with_levels > 0);

        // Read back, the file's MSFT_lod levels are the generated ones:
        // triangles, draw calls and switching coverages, object for object.
        let back = load_scene_bytes(&written.glb, "lod.glb").unwrap();
        assert_eq!(back.objects.len(), expected.objects.len());
        let mut with_levels = 0;
        for (a, b) in expected.objects.iter().zip(&back.objects) {
            assert_eq!(a.name, b.name);
            // The same triangles and coverages; a primitive simplified
            // away is not drawn, so a level may have fewer draw calls than
            // the cost model's (which keeps the object's count).
            assert_eq!(a.lods.len(), b.lods.len(), "{}", a.name);
            for (x, y) in a.lods.iter().zip(&b.lods) {
                assert_eq!(
                    (x.triangles, x.min_coverage),
                    (y.triangles, y.min_coverage),
                    "{}",
                    a.name
                );
                assert!(y.draw_calls >= 1 && y.draw_calls <= x.draw_calls);
            }
            with_levels += u64::from(!b.lods.is_empty());
            let close = |x: glam::DVec3, y: glam::DVec3| (x - y).abs().max_element() < 1e-3;
            assert!(close(a.min, b.min) && close(a.max, b.max), "{}", a.name);
        }
        assert_eq!(with_levels, written.objects_with_levels);
        // Control: the levels read back are not the file's absence of them.
        assert!(back.objects.iter().any(|o| o.lods.len() > 1));
    }

    #[test]
    fn absurd_parameters_are_refused_before_writing() {
        let glb = generate(&CityParams {
            seed: 2,
            scale: 0.02,
            lod: false,
            ..Default::default()
        })
        .unwrap();
        let scene = load_scene_bytes(&glb, "city").unwrap();
        let geom = load_geometry_bytes(&glb, "city").unwrap();
        let params = LodParams {
            levels: 1 << 20,
            ..LodParams::default()
        };
        let e = write_lod_glb(&scene, &geom, &params, 618.0, 1e5, 1.0)
            .unwrap_err()
            .to_string();
        assert!(e.contains("lod.levels") && e.contains("at most 31"), "{e}");
    }
}
