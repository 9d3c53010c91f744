//! The baked GLB: writing it (one node, mesh and primitive per impostor,
//! every layer of it a quad of that primitive, extras per
//! [`crate::api::baked`]) and reading its layers back.

use glam::Vec3;
use serde_json::{Value, json};

use super::atlas::Slot;
use super::formats::add_atlas;
use super::{ALPHA_CUTOFF, Layer};
use crate::api::baked::{BakedImpostor, BakedScene};
use crate::api::job::ViewSpace;
use crate::api::placement::Placement;
use crate::api::texture_format::TextureFormat;
use crate::model::layers::slabs;
use crate::scene::glb::{self, GlbBuilder, MeshPrimitive, MinFilter, Node, Sampler, object_extras};
use crate::scene::material::{AlphaMode, Material};
use crate::{Error, Result};

/// The atlases of a bake: the encoded file (in `format`) and size of each.
pub(super) struct Atlases<'a> {
    pub(super) files: &'a [Vec<u8>],
    pub(super) sizes: &'a [(u32, u32)],
    pub(super) format: TextureFormat,
}

/// Writes the GLB of `layers` (in impostor, then layer order) placed at
/// `slots` (one per layer) in `atlases`. `object_nodes` are the glTF node
/// indices of the scene's objects (empty when unknown).
pub(super) fn write(
    placement: &Placement,
    layers: &[Layer],
    slots: &[Slot],
    atlases: &Atlases<'_>,
    object_nodes: &[u32],
    view_space: Option<&ViewSpace>,
) -> Result<Vec<u8>> {
    let mut b = GlbBuilder::new();
    let sampler = b.add_sampler(&Sampler {
        min_filter: MinFilter::LinearMipmapLinear,
        ..Sampler::linear_clamp()
    })?;
    let mut materials = Vec::with_capacity(atlases.files.len());
    for (i, file) in atlases.files.iter().enumerate() {
        let texture = add_atlas(&mut b, &format!("atlas {i}"), file, atlases.format, sampler)?;
        let mut m = Material::new(format!("impostor atlas {i}"), [1.0; 4]);
        m.base_color_texture = Some(texture);
        m.alpha_mode = AlphaMode::Mask {
            cutoff: ALPHA_CUTOFF,
        };
        m.double_sided = true;
        m.unlit = true;
        materials.push(b.add_material(&m)?);
    }
    let mut roots = Vec::new();
    let mut i = 0;
    while i < layers.len() {
        let id = layers[i].impostor;
        let n = layers[i..].iter().take_while(|l| l.impostor == id).count();
        let (group, group_slots) = (&layers[i..i + n], &slots[i..i + n]);
        i += n;
        let atlas = group_slots[0].atlas;
        if group_slots.iter().any(|s| s.atlas != atlas) {
            return Err(Error::Internal(format!(
                "bake: the layers of impostor {id} are split across atlases"
            )));
        }
        let (aw, ah) = atlases.sizes[atlas as usize];
        let (mut positions, mut normals, mut uvs, mut indices) = (
            Vec::with_capacity(4 * n),
            Vec::with_capacity(4 * n),
            Vec::with_capacity(4 * n),
            Vec::with_capacity(6 * n),
        );
        for (k, (l, s)) in group.iter().zip(group_slots).enumerate() {
            let (u0, v0) = (s.x as f32 / aw as f32, s.y as f32 / ah as f32);
            let (u1, v1) = (
                (s.x + l.res) as f32 / aw as f32,
                (s.y + l.res) as f32 / ah as f32,
            );
            positions.extend(l.corners.map(|p| p.as_vec3().to_array()));
            normals.extend([l.normal.to_array(); 4]);
            uvs.extend([[u0, v0], [u0, v1], [u1, v1], [u1, v0]]);
            let v = 4 * k as u32;
            indices.extend([v, v + 1, v + 2, v, v + 2, v + 3]);
        }
        let g = b.add_geometry(&glb::Geometry {
            positions: &positions,
            normals: Some(&normals),
            texcoords: Some(&uvs),
            indices: &indices,
        })?;
        let mesh = b.add_mesh(
            &format!("impostor {id}"),
            &[MeshPrimitive {
                geometry: g,
                material: Some(materials[atlas as usize]),
            }],
        )?;
        let imp = &placement.impostors[id as usize];
        let source_nodes = (!object_nodes.is_empty())
            .then(|| {
                imp.objects
                    .iter()
                    .map(|&o| object_nodes.get(o as usize).copied())
                    .collect::<Option<Vec<u32>>>()
            })
            .flatten();
        let extras = BakedImpostor {
            id,
            cluster: imp.node,
            objects: imp.objects.clone(),
            source_nodes,
            view_cell: imp.view_cell.clone(),
            sphere: imp.sphere.clone(),
            reference_viewpoint: slabs(imp).0.to_array(),
            layers: imp.layers,
            layers_written: group.iter().map(|l| l.index).collect(),
            resolution: imp.resolution,
            atlas,
        };
        let node = b.add_node(
            Node::new(format!("impostor {id}"))
                .with_mesh(mesh)
                .with_extras(json!({ "impostor": to_value(&extras)? })),
        )?;
        roots.push(node);
    }
    b.set_scene_roots(&roots)?;
    let scene = BakedScene {
        view_space: view_space.cloned(),
        summary: placement.summary.clone(),
    };
    b.set_scene_extras(json!({ "impostor": to_value(&scene)? }));
    Ok(b.finish())
}

fn to_value<T: serde::Serialize>(v: &T) -> Result<Value> {
    serde_json::to_value(v).map_err(|e| Error::Internal(format!("bake: extras: {e}")))
}

/// An impostor node's `extras.impostor`: the placement id and, in files
/// written since the extras became an object, the written layers' indices.
/// Files whose `extras.impostor` is the bare id still read.
struct NodeImpostor {
    id: u32,
    layers_written: Option<Vec<u32>>,
}

/// Reads the layers back from a GLB written by [`super::bake`]: every mesh
/// node is an impostor (its `extras.impostor` names the placement id),
/// every quad (4 vertices) of its primitives a layer whose texels are cut
/// out of its atlas by its UVs. The file is loaded with the safe geometry
/// loader; `source` names it in errors.
pub fn read_layers(bytes: &[u8], source: &str) -> Result<Vec<Layer>> {
    let geom = crate::scene::geometry::load_geometry_bytes(bytes, source)?;
    let ids = node_impostors(bytes, source)?;
    let mut layers: Vec<Layer> = Vec::new();
    let bad = |m: String| Error::bad(source, m);
    for inst in &geom.instances {
        let Some(node) = ids.get(inst.object as usize) else {
            return Err(bad(format!(
                "object {} has no `extras.impostor`",
                inst.object
            )));
        };
        let impostor = node.id;
        let mesh = &geom.meshes[inst.mesh as usize];
        let quads = mesh.positions.len() / 4;
        if quads == 0 || mesh.positions.len() % 4 != 0 || mesh.uvs.len() != mesh.positions.len() {
            return Err(bad(format!(
                "impostor {impostor}: layers must be quads with texture coordinates"
            )));
        }
        let tex = geom.materials[mesh.material as usize]
            .base_color_texture
            .and_then(|t| geom.textures.get(t as usize))
            .ok_or_else(|| bad(format!("impostor {impostor}: a layer has no texture")))?;
        let (aw, ah) = (f64::from(tex.width), f64::from(tex.height));
        let m = inst.transform;
        for q in 0..quads {
            let v = 4 * q;
            let x0 = (f64::from(mesh.uvs[v].x) * aw).round() as i64;
            let y0 = (f64::from(mesh.uvs[v].y) * ah).round() as i64;
            let x1 = (f64::from(mesh.uvs[v + 2].x) * aw).round() as i64;
            let y1 = (f64::from(mesh.uvs[v + 2].y) * ah).round() as i64;
            let res = x1 - x0;
            if res <= 0
                || y1 - y0 != res
                || x0 < 0
                || y0 < 0
                || x1 > i64::from(tex.width)
                || y1 > i64::from(tex.height)
            {
                return Err(bad(format!(
                    "impostor {impostor}: layer texture coordinates do not span a square inside the atlas"
                )));
            }
            let mut rgba = Vec::with_capacity((res * res * 4) as usize);
            for y in y0..y1 {
                let row = ((y * i64::from(tex.width) + x0) * 4) as usize;
                rgba.extend_from_slice(&tex.rgba[row..row + res as usize * 4]);
            }
            let before = layers
                .iter()
                .rev()
                .take_while(|l| l.impostor == impostor)
                .count();
            let index = match &node.layers_written {
                Some(w) => *w.get(before).ok_or_else(|| {
                    bad(format!(
                        "impostor {impostor}: more quads than `layers_written` names"
                    ))
                })?,
                None => before as u32,
            };
            layers.push(Layer {
                impostor,
                index,
                res: res as u32,
                rgba,
                corners: [0, 1, 2, 3].map(|k| m.transform_point3(mesh.positions[v + k].as_dvec3())),
                normal: mesh.normals.get(v).map_or(Vec3::Z, |n| {
                    (m.matrix3 * n.as_dvec3()).normalize().as_vec3()
                }),
            });
        }
    }
    Ok(layers)
}

/// The `extras.impostor` of every object (mesh node) of a baked GLB, in
/// object order, read with the safe glTF loader.
fn node_impostors(bytes: &[u8], source: &str) -> Result<Vec<NodeImpostor>> {
    object_extras(bytes, source)?
        .iter()
        .enumerate()
        .map(|(object, extras)| {
            let lacks = |what: &str| {
                Error::bad(
                    source,
                    format!("not a baked impostor file: object {object} {what}"),
                )
            };
            let value = extras
                .as_ref()
                .and_then(|e| e.get("impostor"))
                .ok_or_else(|| lacks("lacks `extras.impostor`"))?;
            let as_id = |v: &Value| v.as_u64().and_then(|v| u32::try_from(v).ok());
            if let Some(id) = as_id(value) {
                return Ok(NodeImpostor {
                    id,
                    layers_written: None,
                });
            }
            let baked: BakedImpostor = serde_json::from_value(value.clone())
                .map_err(|e| lacks(&format!("has an unreadable `extras.impostor`: {e}")))?;
            Ok(NodeImpostor {
                id: baked.id,
                layers_written: Some(baked.layers_written),
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::api::placement::{PlacedImpostor, SphereJson, Summary, ViewCellJson};
    use crate::scene::glb::Geometry;

    /// Three triangles facing +z whose objects (the scene walk's pre-order)
    /// are not in node order: node 2 (a root, with child node 0) is object
    /// 0, node 0 (at x = −3, z = −2) object 1, node 1 (a root at x = 3,
    /// z = 2) object 2.
    fn shuffled_scene() -> Vec<u8> {
        let mut b = GlbBuilder::new();
        let g = Geometry {
            positions: &[[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [0.0, 1.0, 0.0]],
            normals: Some(&[[0.0, 0.0, 1.0]; 3]),
            texcoords: None,
            indices: &[0, 1, 2],
        };
        let mut m = Material::new("grey", [0.6, 0.6, 0.6, 1.0]);
        m.double_sided = true;
        let m = b.add_material(&m).unwrap();
        let mesh = b.add_mesh_from("tri", &[(g, Some(m))]).unwrap();
        let id = [0.0, 0.0, 0.0, 1.0];
        let left = b
            .add_node(
                Node::new("left")
                    .with_mesh(mesh)
                    .with_trs([-3.0, 0.0, -2.0], id, [1.0; 3]),
            )
            .unwrap();
        let right = b
            .add_node(
                Node::new("right")
                    .with_mesh(mesh)
                    .with_trs([3.0, 0.0, 2.0], id, [1.0; 3]),
            )
            .unwrap();
        let mid = b
            .add_node(Node::new("mid").with_mesh(mesh).with_children(vec![left]))
            .unwrap();
        b.set_scene_roots(&[mid, right]).unwrap();
        b.finish()
    }

    fn impostor(
        id: u32,
        objects: Vec<u32>,
        radius: f64,
        view_cell: ViewCellJson,
    ) -> PlacedImpostor {
        PlacedImpostor {
            id,
            node: 10 + id,
            objects,
            sphere: SphereJson {
                center: [0.0; 3],
                radius,
            },
            view_cell,
            layers: 2,
            resolution: 16,
            memory_bytes: 0,
            time_ms: 0.0,
        }
    }

    fn placement() -> Placement {
        Placement {
            summary: Summary {
                cpvs: 0,
                candidates: 2,
                impostors: 2,
                memory_bytes: 0,
                unsolved_cpvs: 0,
                target_frame_time_ms: 10.0,
                max_residual_ms: 0.0,
                unsolved_by_reason: Default::default(),
                budget_bytes: None,
            },
            impostors: vec![
                impostor(
                    0,
                    vec![1, 2],
                    6.0,
                    ViewCellJson::Box {
                        min: [-1.0, -1.0, 20.0],
                        max: [1.0, 1.0, 22.0],
                    },
                ),
                impostor(
                    1,
                    vec![0],
                    2.0,
                    ViewCellJson::Shaft {
                        apex: [0.0; 3],
                        axis: [0.0, 0.0, 1.0],
                        half_angle_deg: 10.0,
                        min_distance: 20.0,
                    },
                ),
            ],
            cpvs: Vec::new(),
        }
    }

    #[test]
    fn extras_name_the_source_nodes_and_each_impostor_is_one_primitive() {
        let bytes = shuffled_scene();
        let scene = crate::scene::gltf_load::load_scene_bytes(&bytes, "s.glb").unwrap();
        let geom = crate::scene::geometry::load_geometry_bytes(&bytes, "s.glb").unwrap();
        assert_eq!(geom.object_nodes, vec![2, 0, 1]);
        let p = placement();
        let view_space = ViewSpace {
            min: [-30.0, -30.0, 0.0],
            max: [30.0, 30.0, 30.0],
            pitch_deg: [-90.0, 90.0],
        };
        let opts = super::super::BakeOptions::default();
        let memory = crate::api::job::MemoryParams::default();
        let (glb, report) = super::super::bake(
            &scene,
            &geom,
            &memory,
            Some(&view_space),
            &p,
            &opts,
            "p.json",
        )
        .unwrap();
        // Impostor 0's objects lie in its two slabs; impostor 1's flat
        // triangle in one of them.
        assert_eq!(report.layers_written, 3);

        let doc: Value = {
            let g = gltf::Gltf::from_slice(&glb).unwrap();
            serde_json::to_value(g.document.into_json()).unwrap()
        };
        let nodes = doc["nodes"].as_array().unwrap();
        let rendered = super::super::render_layers(&scene, &geom, &p, "p.json").unwrap();
        let rendered_index = |id: u32| -> Vec<u32> {
            rendered
                .iter()
                .filter(|l| l.impostor == id)
                .map(|l| l.index)
                .collect()
        };
        assert_eq!(nodes.len(), 2);
        for (k, node) in nodes.iter().enumerate() {
            let baked: BakedImpostor =
                serde_json::from_value(node["extras"]["impostor"].clone()).unwrap();
            let imp = &p.impostors[k];
            assert_eq!((baked.id, baked.cluster), (imp.id, imp.node));
            assert_eq!(baked.objects, imp.objects);
            assert_eq!(baked.view_cell, imp.view_cell);
            let written = rendered_index(k as u32);
            assert_eq!(baked.layers_written, written);
            assert_eq!(written.len(), 2 - k);
            assert_eq!(baked.resolution, 16);
            assert_eq!(baked.reference_viewpoint, slabs(imp).0.to_array());
            let mesh = &doc["meshes"][node["mesh"].as_u64().unwrap() as usize];
            assert_eq!(mesh["primitives"].as_array().unwrap().len(), 1);
        }
        // The glTF node indices, not the object ids (which differ here).
        let source = |k: usize| {
            serde_json::from_value::<BakedImpostor>(nodes[k]["extras"]["impostor"].clone())
                .unwrap()
                .source_nodes
        };
        assert_eq!(source(0), Some(vec![0, 1]));
        assert_eq!(source(1), Some(vec![2]));
        let scene_extras: BakedScene =
            serde_json::from_value(doc["scenes"][0]["extras"]["impostor"].clone()).unwrap();
        assert_eq!(scene_extras.view_space, Some(view_space));
        assert_eq!(scene_extras.summary, p.summary);

        // The layers read back are the layers rendered.
        let read = read_layers(&glb, "i.glb").unwrap();
        assert_eq!(read.len(), rendered.len());
        for (a, b) in read.iter().zip(&rendered) {
            assert_eq!((a.impostor, a.index, a.res), (b.impostor, b.index, b.res));
            assert!(
                a.rgba == b.rgba,
                "impostor {} layer {}",
                a.impostor,
                a.index
            );
            for k in 0..4 {
                assert!(a.corners[k].distance(b.corners[k]) < 1e-4);
            }
            assert!(a.normal.distance(b.normal) < 1e-6);
        }

        // Geometry without node indices writes no `source_nodes`.
        let mut bare = geom.clone();
        bare.object_nodes.clear();
        let (glb, _) =
            super::super::bake(&scene, &bare, &memory, None, &p, &opts, "p.json").unwrap();
        let extras = object_extras(&glb, "i.glb").unwrap();
        assert!(
            extras[0].as_ref().unwrap()["impostor"]
                .get("source_nodes")
                .is_none()
        );
    }

    #[test]
    fn files_with_a_bare_id_still_read() {
        let bytes = shuffled_scene();
        let scene = crate::scene::gltf_load::load_scene_bytes(&bytes, "s.glb").unwrap();
        let geom = crate::scene::geometry::load_geometry_bytes(&bytes, "s.glb").unwrap();
        let p = placement();
        let (glb, _) = super::super::bake(
            &scene,
            &geom,
            &crate::api::job::MemoryParams::default(),
            None,
            &p,
            &super::super::BakeOptions::default(),
            "p.json",
        )
        .unwrap();
        let new = read_layers(&glb, "i.glb").unwrap();
        // The same file with `extras.impostor` replaced by the bare id, as
        // earlier versions wrote it (their files drew one primitive per
        // layer; a multi-quad primitive reads the same way).
        let gltf::Gltf { document, blob } = gltf::Gltf::from_slice(&glb).unwrap();
        let mut root = document.into_json();
        for (k, n) in root.nodes.iter_mut().enumerate() {
            n.extras = Some(serde_json::value::to_raw_value(&json!({ "impostor": k })).unwrap());
        }
        let json = serde_json::to_vec(&root).unwrap();
        let old = gltf::binary::Glb {
            header: gltf::binary::Header {
                magic: *b"glTF",
                version: 2,
                length: 0,
            },
            json: json.into(),
            bin: blob.map(Into::into),
        };
        let mut old = old.to_vec().unwrap();
        let len = old.len() as u32;
        old[8..12].copy_from_slice(&len.to_le_bytes());
        let old = read_layers(&old, "old.glb").unwrap();
        assert_eq!(old.len(), new.len());
        for (a, b) in old.iter().zip(&new) {
            // Old files name no layer indices: layers count from 0.
            assert_eq!((a.impostor, &a.rgba), (b.impostor, &b.rgba));
        }
    }
}
