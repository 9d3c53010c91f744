//! Baking layered impostors (DESIGN §2.9): render each impostor of a
//! placement into its depth-slab layers with the CPU rasterizer, pack the
//! layers into texture atlases and write one GLB of alpha-masked quads.
//!
//! The reference viewpoint and the depth slabs of an impostor are those of
//! [`crate::model::layers`]. The camera looks from the reference viewpoint
//! at the cluster sphere's centre with a square window that exactly
//! encloses the sphere, at the placement's resolution. Each slab is
//! rendered alone (fragments outside it are discarded), and the layer's
//! quad lies at the slab's layer depth and covers the window there, so from
//! the reference viewpoint every texel lands exactly where its geometry was.
//!
//! Atlases ([`atlas`]): an impostor's layers are shelf-packed together
//! into one atlas of at most `atlas_size`² texels (larger only for an
//! impostor that needs more), with a gutter of edge-extended texels around
//! each layer; the colour of transparent texels is dilated from their
//! covered neighbours so that filtering does not darken silhouettes.
//! Layers without any covered texel are not written. The file ([`file`])
//! draws each impostor with one primitive (one draw call, as the cost model
//! counts it).

mod atlas;
mod file;
mod formats;
pub mod ktx2;
pub mod mips;
mod sharpen;

pub use file::read_layers;

use std::collections::BTreeMap;

use glam::{DAffine3, DVec3, Vec2, Vec3};
use rayon::prelude::*;
use serde::Serialize;

use crate::api::job::{MemoryParams, ViewSpace};
use crate::api::placement::{PlacedImpostor, Placement};
use crate::api::texture_format::TextureFormat;
use crate::input::Prepared;
use crate::model::layers::slabs;
use crate::render::raster::{Raster, Surface, TextureRef, Vertex, View};
use crate::scene::Scene;
use crate::scene::geometry::SceneGeometry;
use crate::scene::material::AlphaMode;
use crate::{Error, Result};
use atlas::{Group, Slot};

/// Baking options.
#[derive(Clone, Copy, Debug)]
pub struct BakeOptions {
    /// Largest atlas side, texels.
    pub atlas_size: u32,
    /// Gutter around each layer in an atlas, texels.
    pub gutter: u32,
    /// How atlases are written (PNG, or KTX2 with a coverage-keeping mip chain).
    pub textures: TextureFormat,
}

/// The alpha cutoff of the baked materials (`AlphaMode::Mask`).
pub const ALPHA_CUTOFF: f32 = 0.5;

impl Default for BakeOptions {
    fn default() -> Self {
        BakeOptions {
            atlas_size: 4096,
            gutter: 4,
            textures: TextureFormat::Png,
        }
    }
}

/// What was baked.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct BakeReport {
    /// Impostors baked.
    pub impostors: u64,
    /// Layers in the placement.
    pub layers: u64,
    /// Layers written (those with at least one covered texel).
    pub layers_written: u64,
    /// Atlases written.
    pub atlases: u64,
    /// Texels of the written layers.
    pub texels: u64,
    /// Memory of the written layers under the job's memory model in the
    /// baked texture format (see `MemoryParams::baked_texel_bytes`), bytes.
    pub memory_bytes: u64,
    /// The format the atlases were written in.
    pub texture_format: TextureFormat,
    /// Bytes of the atlas files in the GLB.
    pub texture_bytes: u64,
    /// The placement's memory estimate, bytes.
    pub placement_memory_bytes: u64,
    /// Atlas texels including gutters and unused space.
    pub atlas_texels: u64,
    /// Per impostor of the placement, the memory of its written layers
    /// under the job's memory model, bytes.
    #[serde(skip)]
    pub impostor_memory_bytes: Vec<u64>,
}

/// One rendered impostor layer: a square RGBA image on a world-space quad.
#[derive(Clone, Debug)]
pub struct Layer {
    /// The placement's impostor id.
    pub impostor: u32,
    /// The layer's index among the impostor's layers (front to back).
    pub index: u32,
    /// Texels per side.
    pub res: u32,
    /// `res × res` RGBA8 texels (sRGB colour, alpha = coverage), rows from the top.
    pub rgba: Vec<u8>,
    /// World corners of the quad: top-left, bottom-left, bottom-right,
    /// top-right (texel rows run from the first to the second corner).
    pub corners: [DVec3; 4],
    /// Unit normal, towards the reference viewpoint.
    pub normal: Vec3,
}

/// A triangle ready to draw, with its material.
pub(crate) struct Tri {
    pub(crate) v: [Vertex; 3],
    pub(crate) material: u32,
}

/// Checks `placement` against `scene` ([`Placement::validate`], the same
/// rules as the evaluation) and that `geom` is the same scene's geometry.
fn check(scene: &Scene, geom: &SceneGeometry, placement: &Placement, source: &str) -> Result<()> {
    if geom.object_count() != scene.objects.len() {
        return Err(Error::Internal(format!(
            "bake: the geometry has {} objects, the scene {}",
            geom.object_count(),
            scene.objects.len()
        )));
    }
    placement.validate(scene, source)
}

/// World-space triangles of the given objects.
pub(crate) fn cluster_triangles(
    geom: &SceneGeometry,
    by_object: &[Vec<u32>],
    objects: &[u32],
) -> Vec<Tri> {
    let mut out = Vec::new();
    for &o in objects {
        for &ii in &by_object[o as usize] {
            let inst = &geom.instances[ii as usize];
            let mesh = &geom.meshes[inst.mesh as usize];
            let m: DAffine3 = inst.transform;
            let nm = m.matrix3.inverse().transpose();
            let vert = |i: u32| {
                let i = i as usize;
                Vertex {
                    pos: m.transform_point3(mesh.positions[i].as_dvec3()),
                    normal: mesh
                        .normals
                        .get(i)
                        .map_or(Vec3::ZERO, |n| (nm * n.as_dvec3()).as_vec3()),
                    uv: mesh.uvs.get(i).copied().unwrap_or(Vec2::ZERO),
                }
            };
            for t in mesh.indices.chunks_exact(3) {
                out.push(Tri {
                    v: [vert(t[0]), vert(t[1]), vert(t[2])],
                    material: mesh.material,
                });
            }
        }
    }
    out
}

/// The rasterizer surface of a material.
pub(crate) fn surface<'a>(geom: &'a SceneGeometry, material: u32) -> Surface<'a> {
    let Some(m) = geom.materials.get(material as usize) else {
        return Surface::default();
    };
    let texture = m
        .base_color_texture
        .and_then(|t| geom.textures.get(t as usize))
        .map(|t| TextureRef {
            width: t.width,
            height: t.height,
            rgba: &t.rgba,
            wrap_s: t.wrap_s,
            wrap_t: t.wrap_t,
        });
    Surface {
        base_color: m.base_color,
        texture,
        alpha_cutoff: match m.alpha_mode {
            AlphaMode::Opaque => None,
            AlphaMode::Mask { cutoff } => Some(cutoff),
            AlphaMode::Blend => Some(0.5),
        },
        double_sided: m.double_sided,
        lit: true,
        alpha_to_coverage: false,
    }
}

/// Samples per side of a texel: a layer is drawn at this many times its
/// resolution and box-filtered, so a texel's alpha is the share of it the
/// slab's geometry covers and its colour their mean (thin features keep
/// their share instead of being kept or lost whole by one sample).
const TEXEL_SAMPLES: u32 = 4;

/// Renders the layers of one impostor.
fn render_impostor(
    geom: &SceneGeometry,
    by_object: &[Vec<u32>],
    imp: &PlacedImpostor,
) -> Vec<Layer> {
    let c = DVec3::from_array(imp.sphere.center);
    let (eye, slabs) = slabs(imp);
    let res = imp.resolution;
    let view = View::enclosing_sphere(eye, c, imp.sphere.radius, res * TEXEL_SAMPLES);
    let tris = cluster_triangles(geom, by_object, &imp.objects);
    // Depth range of every triangle, to draw each only into its slabs.
    let ranges: Vec<(f64, f64)> = tris
        .iter()
        .map(|t| {
            let z = t.v.map(|v| view.to_view(v.pos).z);
            (z[0].min(z[1]).min(z[2]), z[0].max(z[1]).max(z[2]))
        })
        .collect();
    let surfaces: BTreeMap<u32, Surface> = tris
        .iter()
        .map(|t| (t.material, surface(geom, t.material)))
        .collect();
    let mut raster = Raster::supersampled(res, res, TEXEL_SAMPLES);
    let last = slabs.len() - 1;
    let mut layers = Vec::with_capacity(slabs.len());
    for (k, &(z0, z1, mid)) in slabs.iter().enumerate() {
        // The first and last slabs are open-ended so that nothing of the
        // cluster is lost to rounding.
        let lo = if k == 0 { 0.0 } else { z0 };
        let hi = if k == last { f64::INFINITY } else { z1 };
        raster.reset(view.width, view.height);
        for (t, &(zmin, zmax)) in tris.iter().zip(&ranges) {
            if zmax < lo || zmin >= hi {
                continue;
            }
            raster.draw(&view, &t.v, &surfaces[&t.material], (lo, hi));
        }
        if raster.color.iter().all(|p| p[3] == 0) {
            continue;
        }
        let r = f64::from(view.width);
        layers.push(Layer {
            impostor: imp.id,
            index: k as u32,
            res,
            rgba: dilate(&sharpen::sharpen(&raster.resolve(), res).concat(), res),
            corners: [
                view.unproject(0.0, 0.0, mid),
                view.unproject(0.0, r, mid),
                view.unproject(r, r, mid),
                view.unproject(r, 0.0, mid),
            ],
            normal: (-view.forward).as_vec3(),
        });
    }
    layers
}

/// Gives transparent texels the mean colour of their covered neighbours
/// (two rings), keeping alpha 0, so bilinear filtering and mipmapping do not
/// pull black into silhouettes.
fn dilate(rgba: &[u8], res: u32) -> Vec<u8> {
    let n = res as usize;
    let mut cur = rgba.to_vec();
    let mut known: Vec<bool> = cur.chunks_exact(4).map(|p| p[3] > 0).collect();
    for _ in 0..2 {
        let mut next = cur.clone();
        let mut next_known = known.clone();
        for y in 0..n {
            for x in 0..n {
                let i = y * n + x;
                if known[i] {
                    continue;
                }
                let mut sum = [0u32; 3];
                let mut cnt = 0u32;
                for (dx, dy) in [(-1i64, 0i64), (1, 0), (0, -1), (0, 1)] {
                    let (nx, ny) = (x as i64 + dx, y as i64 + dy);
                    if nx < 0 || ny < 0 || nx >= n as i64 || ny >= n as i64 {
                        continue;
                    }
                    let j = ny as usize * n + nx as usize;
                    if known[j] {
                        for k in 0..3 {
                            sum[k] += u32::from(cur[j * 4 + k]);
                        }
                        cnt += 1;
                    }
                }
                if let Some(mean) = sum
                    .map(|v| v.checked_div(cnt))
                    .into_iter()
                    .collect::<Option<Vec<u32>>>()
                {
                    for (k, m) in mean.into_iter().enumerate() {
                        next[i * 4 + k] = m as u8;
                    }
                    next_known[i] = true;
                }
            }
        }
        cur = next;
        known = next_known;
    }
    cur
}

/// Encodes RGBA8 pixels as PNG (the GLB writer's encoder).
pub use crate::scene::glb::encode_png;

/// Renders the layers of every impostor of `placement` (in impostor, then
/// layer order; layers without a covered texel are left out), in parallel
/// across impostors. `source` names the placement in errors.
pub fn render_layers(
    scene: &Scene,
    geom: &SceneGeometry,
    placement: &Placement,
    source: &str,
) -> Result<Vec<Layer>> {
    check(scene, geom, placement, source)?;
    Ok(render(
        geom,
        &placement.impostors.iter().collect::<Vec<_>>(),
    ))
}

/// The layers of the impostors `ids` of `placement` only, in the order of
/// `ids` (as [`render_layers`] renders them; ids beyond the placement are
/// ignored).
pub fn render_layers_of(
    scene: &Scene,
    geom: &SceneGeometry,
    placement: &Placement,
    ids: &[u32],
    source: &str,
) -> Result<Vec<Layer>> {
    check(scene, geom, placement, source)?;
    let chosen: Vec<&PlacedImpostor> = ids
        .iter()
        .filter_map(|&k| placement.impostors.get(k as usize))
        .collect();
    Ok(render(geom, &chosen))
}

fn render(geom: &SceneGeometry, impostors: &[&PlacedImpostor]) -> Vec<Layer> {
    let by_object = geom_objects(geom);
    impostors
        .par_iter()
        .map(|imp| render_impostor(geom, &by_object, imp))
        .collect::<Vec<_>>()
        .into_iter()
        .flatten()
        .collect()
}

/// Per object id, its instance indices.
pub(crate) fn geom_objects(geom: &SceneGeometry) -> Vec<Vec<u32>> {
    let mut by_object: Vec<Vec<u32>> = vec![Vec::new(); geom.object_count()];
    for (i, inst) in geom.instances.iter().enumerate() {
        by_object[inst.object as usize].push(i as u32);
    }
    by_object
}

/// Width and height of each atlas, texels.
pub type AtlasSizes = Vec<(u32, u32)>;

/// A baked GLB as [`write_glb`] writes it.
#[derive(Debug)]
pub struct BakedGlb {
    /// The file.
    pub glb: Vec<u8>,
    /// Each atlas's size.
    pub atlas_sizes: AtlasSizes,
    /// Bytes of the encoded atlas files (PNG or KTX2) in it.
    pub texture_bytes: u64,
}

/// Writes `layers` (of `placement`'s impostors, in impostor then layer
/// order, as [`render_layers`] gives them) as a baked GLB: the layers
/// packed into atlases, one node and primitive per impostor. Returns the
/// file, each atlas's size and the atlas files' bytes. `object_nodes` are the glTF node indices of
/// the scene's objects (empty when unknown).
pub fn write_glb(
    placement: &Placement,
    layers: &[Layer],
    object_nodes: &[u32],
    view_space: Option<&ViewSpace>,
    opts: &BakeOptions,
) -> Result<BakedGlb> {
    if let Some(l) = layers
        .iter()
        .find(|l| placement.impostors.get(l.impostor as usize).is_none())
    {
        return Err(Error::Internal(format!(
            "bake: layer of impostor {} beyond the placement",
            l.impostor
        )));
    }
    // Groups of layers, one per impostor, in impostor order (layers are
    // in impostor, then layer order).
    let mut groups: Vec<Group> = Vec::new();
    for (i, l) in layers.iter().enumerate() {
        match groups.last_mut() {
            Some(g) if i > 0 && layers[i - 1].impostor == l.impostor => g.count += 1,
            _ => groups.push(Group {
                res: l.res,
                count: 1,
            }),
        }
    }
    let (group_slots, mut atlas_sizes) = atlas::pack(&groups, opts.atlas_size, opts.gutter);
    formats::fit_sizes(&mut atlas_sizes, opts.textures);
    let slots: Vec<Slot> = group_slots.into_iter().flatten().collect();
    let mut atlases: Vec<Vec<u8>> = atlas_sizes
        .iter()
        .map(|&(w, h)| vec![0u8; w as usize * h as usize * 4])
        .collect();
    for (l, s) in layers.iter().zip(&slots) {
        let aw = atlas_sizes[s.atlas as usize].0;
        atlas::blit(&mut atlases[s.atlas as usize], aw, l, *s, opts.gutter);
    }
    let files = formats::encode_atlases(&atlases, &atlas_sizes, opts.textures)?;
    let glb = file::write(
        placement,
        layers,
        &slots,
        &file::Atlases {
            files: &files,
            sizes: &atlas_sizes,
            format: opts.textures,
        },
        object_nodes,
        view_space,
    )?;
    Ok(BakedGlb {
        glb,
        atlas_sizes,
        texture_bytes: files.iter().map(|f| f.len() as u64).sum(),
    })
}

/// Bakes every impostor of `placement` over `geom` (the geometry of
/// `scene`) into a GLB: one node with one primitive per impostor, all its
/// layers in one atlas, described by its `extras.impostor`
/// ([`crate::api::baked`]); the scene's extras carry `view_space` (when
/// given) and the placement's summary. The placement is checked first by
/// [`Placement::validate`].
/// `source` names the placement in errors.
pub fn bake(
    scene: &Scene,
    geom: &SceneGeometry,
    memory: &MemoryParams,
    view_space: Option<&ViewSpace>,
    placement: &Placement,
    opts: &BakeOptions,
    source: &str,
) -> Result<(Vec<u8>, BakeReport)> {
    let layers = render_layers(scene, geom, placement, source)?;

    let BakedGlb {
        glb,
        atlas_sizes,
        texture_bytes,
    } = write_glb(placement, &layers, &geom.object_nodes, view_space, opts)?;

    let texels: u64 = layers.iter().map(|l| u64::from(l.res).pow(2)).sum();
    let mip = if memory.mipmaps { 4.0 / 3.0 } else { 1.0 };
    let mut impostor_texels = vec![0u64; placement.impostors.len()];
    for l in &layers {
        if let Some(t) = impostor_texels.get_mut(l.impostor as usize) {
            *t += u64::from(l.res).pow(2);
        }
    }
    let bpt = memory.baked_texel_bytes(opts.textures);
    let bytes = |texels: u64| (texels as f64 * bpt * mip).ceil() as u64;
    let report = BakeReport {
        impostors: placement.impostors.len() as u64,
        layers: placement
            .impostors
            .iter()
            .map(|i| u64::from(i.layers))
            .sum(),
        layers_written: layers.len() as u64,
        atlases: atlas_sizes.len() as u64,
        texels,
        memory_bytes: bytes(texels),
        texture_format: opts.textures,
        texture_bytes,
        placement_memory_bytes: placement.summary.memory_bytes,
        atlas_texels: atlas_sizes
            .iter()
            .map(|&(w, h)| u64::from(w) * u64::from(h))
            .sum(),
        impostor_memory_bytes: impostor_texels.into_iter().map(bytes).collect(),
    };
    Ok((glb, report))
}

impl Prepared<'_> {
    /// Bakes `placement` (made for this scene) with the job's memory model.
    /// Needs the scene's geometry ([`GeometryUse::Required`](crate::input::GeometryUse)).
    pub fn bake(
        &self,
        placement: &Placement,
        opts: &BakeOptions,
        source: &str,
    ) -> Result<(Vec<u8>, BakeReport)> {
        let input = self.input();
        let geom = input.geometry.as_ref().ok_or_else(|| {
            Error::bad(
                source,
                "baking needs the scene's geometry (a .glb/.gltf scene, not a summary)",
            )
        })?;
        bake(
            &input.scene,
            geom,
            &self.job().memory,
            Some(&self.job().view_space),
            placement,
            opts,
            source,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::glb::{self, GlbBuilder, Node};
    use crate::scene::material::Material;
    use serde_json::json;

    #[test]
    fn dilation_colours_transparent_neighbours_only() {
        let mut px = vec![0u8; 3 * 3 * 4];
        px[4 * 4..4 * 4 + 4].copy_from_slice(&[200, 100, 50, 255]);
        let d = dilate(&px, 3);
        assert_eq!(&d[4 * 4..4 * 4 + 4], &[200, 100, 50, 255]);
        assert_eq!(&d[4..8], &[200, 100, 50, 0]); // (1, 0): a direct neighbour
        assert_eq!(&d[0..4], &[200, 100, 50, 0]); // (0, 0): second ring
    }

    /// A GLB shaped like a baked one: one impostor node (`extras` given)
    /// drawing one textured quad that spans a 2 × 2 atlas.
    fn one_layer_glb(extras: serde_json::Value) -> Vec<u8> {
        let texels: Vec<u8> = (0..16).map(|i| (i * 16) as u8).collect();
        let mut b = GlbBuilder::new();
        let image = b
            .add_image_png("atlas", &encode_png(&texels, 2, 2).unwrap())
            .unwrap();
        let texture = b.add_texture(image, None).unwrap();
        let mut m = Material::new("atlas", [1.0; 4]);
        m.base_color_texture = Some(texture);
        let material = b.add_material(&m).unwrap();
        let positions = [
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
        ];
        let mesh = b
            .add_mesh_from(
                "impostor 0",
                &[(
                    glb::Geometry {
                        positions: &positions,
                        normals: Some(&[[0.0, 0.0, 1.0]; 4]),
                        texcoords: Some(&[[0.0, 0.0], [0.0, 1.0], [1.0, 1.0], [1.0, 0.0]]),
                        indices: &[0, 1, 2, 0, 2, 3],
                    },
                    Some(material),
                )],
            )
            .unwrap();
        b.add_node(Node::new("impostor 0").with_mesh(mesh).with_extras(extras))
            .unwrap();
        b.finish()
    }

    #[test]
    fn layers_read_back_with_their_impostor_texels_and_corners() {
        let layers = read_layers(&one_layer_glb(json!({ "impostor": 7 })), "i.glb").unwrap();
        assert_eq!(layers.len(), 1);
        let l = &layers[0];
        assert_eq!((l.impostor, l.index, l.res), (7, 0, 2));
        assert_eq!(l.rgba, (0..16).map(|i| (i * 16) as u8).collect::<Vec<u8>>());
        assert_eq!(l.corners[0], DVec3::Y);
        assert_eq!(l.normal, Vec3::Z);
    }

    #[test]
    fn bad_impostor_files_are_bad_input_naming_the_file() {
        let e = read_layers(&one_layer_glb(json!({ "other": 1 })), "i.glb").unwrap_err();
        assert!(e.is_bad_input(), "{e}");
        assert!(e.to_string().contains("i.glb") && e.to_string().contains("extras.impostor"));
        for bytes in [&b"glTF\x02\0\0\0"[..], b"not a file", &[]] {
            let e = read_layers(bytes, "i.glb").unwrap_err();
            assert!(e.is_bad_input() && e.to_string().contains("i.glb"), "{e}");
        }
        let glb = one_layer_glb(json!({ "impostor": 0 }));
        let mut rng = crate::math::rng::Rng::new(5);
        for _ in 0..300 {
            let mut b = glb.clone();
            let i = (rng.next_u64() % b.len() as u64) as usize;
            b[i] ^= 1 << (rng.next_u64() % 8);
            if let Err(e) = read_layers(&b, "i.glb") {
                assert!(e.is_bad_input(), "{e}");
            }
        }
    }
}
