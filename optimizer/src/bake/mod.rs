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
//! Atlases: layers are shelf-packed (largest first, then impostor id and
//! layer) into atlases of at most `atlas_size`² texels with a gutter of
//! edge-extended texels around each layer, so that mip levels do not bleed
//! between neighbours; the colour of transparent texels is dilated from
//! their covered neighbours so that filtering does not darken silhouettes.
//! Layers without any covered texel are not written.

mod atlas;
pub mod ktx2;
pub mod mips;

use std::collections::BTreeMap;

use glam::{DAffine3, DVec3, Vec2, Vec3};
use rayon::prelude::*;
use serde::Serialize;
use serde_json::json;

use crate::api::job::MemoryParams;
use crate::api::placement::{PlacedImpostor, Placement};
use crate::api::texture_format::TextureFormat;
use crate::input::Prepared;
use crate::model::layers::slabs;
use crate::render::raster::{Raster, Surface, TextureRef, Vertex, View};
use crate::scene::Scene;
use crate::scene::geometry::SceneGeometry;
use crate::scene::glb::{self, GlbBuilder, MeshPrimitive, MinFilter, Node, Sampler, object_extras};
use crate::scene::material::{AlphaMode, Material};
use crate::{Error, Result};

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
            rgba: dilate(&raster.resolve().concat(), res),
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

/// Where a layer went: atlas index and top-left texel of its interior.
#[derive(Clone, Copy, Debug)]
struct Slot {
    atlas: u32,
    x: u32,
    y: u32,
}

/// Shelf packing of square layers (sides `res + 2·gutter`) into atlases.
/// Returns one slot per layer (same order) and each atlas's size.
fn pack(sizes: &[u32], atlas_size: u32, gutter: u32) -> (Vec<Slot>, Vec<(u32, u32)>) {
    let mut order: Vec<usize> = (0..sizes.len()).collect();
    order.sort_by_key(|&i| (std::cmp::Reverse(sizes[i]), i));
    let mut slots = vec![
        Slot {
            atlas: 0,
            x: 0,
            y: 0
        };
        sizes.len()
    ];
    let mut atlases: Vec<(u32, u32)> = Vec::new();
    // The current atlas's shelf: top, height, cursor.
    let (mut shelf_y, mut shelf_h, mut cursor) = (0u32, 0u32, 0u32);
    for i in order {
        let side = sizes[i] + 2 * gutter;
        if let Some(&(w, _)) = atlases.last()
            && cursor + side > w
        {
            shelf_y += shelf_h;
            shelf_h = 0;
            cursor = 0;
        }
        // Atlases are at most square: a full one starts the next. Sides
        // come largest first, so the first layer of an atlas sets its width.
        if atlases.last().is_none_or(|&(w, _)| shelf_y + side > w) {
            atlases.push((atlas_size.max(side), 0));
            (shelf_y, shelf_h, cursor) = (0, 0, 0);
        }
        let a = atlases.len() - 1;
        slots[i] = Slot {
            atlas: a as u32,
            x: cursor + gutter,
            y: shelf_y + gutter,
        };
        cursor += side;
        shelf_h = shelf_h.max(side);
        atlases[a].1 = atlases[a].1.max(shelf_y + shelf_h);
    }
    for a in &mut atlases {
        a.1 = a.1.div_ceil(4) * 4;
    }
    (slots, atlases)
}

/// Copies a layer into an atlas with edge-extended gutters.
fn blit(atlas: &mut [u8], aw: u32, layer: &Layer, slot: Slot, gutter: u32) {
    let res = layer.res as i64;
    let g = i64::from(gutter);
    for dy in -g..res + g {
        for dx in -g..res + g {
            let (sx, sy) = (dx.clamp(0, res - 1), dy.clamp(0, res - 1));
            let src = ((sy * res + sx) * 4) as usize;
            let (tx, ty) = (i64::from(slot.x) + dx, i64::from(slot.y) + dy);
            let dst = ((ty * i64::from(aw) + tx) * 4) as usize;
            atlas[dst..dst + 4].copy_from_slice(&layer.rgba[src..src + 4]);
        }
    }
}

/// Encodes RGBA8 pixels as PNG.
pub fn encode_png(rgba: &[u8], w: u32, h: u32) -> Result<Vec<u8>> {
    use image::ImageEncoder;
    let mut out = Vec::new();
    image::codecs::png::PngEncoder::new_with_quality(
        &mut out,
        image::codecs::png::CompressionType::Fast,
        image::codecs::png::FilterType::Adaptive,
    )
    .write_image(rgba, w, h, image::ExtendedColorType::Rgba8)
    .map_err(|e| Error::Internal(format!("PNG encoding: {e}")))?;
    Ok(out)
}

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

/// Reads the layers back from a GLB written by [`bake`]: every mesh node is
/// an impostor (its `extras.impostor` is the placement id), every primitive
/// a layer quad whose texels are cut out of its atlas by its UVs. The file
/// is loaded with the safe geometry loader; `source` names it in errors.
pub fn read_layers(bytes: &[u8], source: &str) -> Result<Vec<Layer>> {
    let geom = crate::scene::geometry::load_geometry_bytes(bytes, source)?;
    let ids = impostor_ids(bytes, source)?;
    let mut layers = Vec::new();
    let bad = |m: String| Error::bad(source, m);
    for inst in &geom.instances {
        let Some(&impostor) = ids.get(inst.object as usize) else {
            return Err(bad(format!(
                "object {} has no `extras.impostor`",
                inst.object
            )));
        };
        let mesh = &geom.meshes[inst.mesh as usize];
        if mesh.positions.len() != 4 || mesh.uvs.len() != 4 {
            return Err(bad(format!(
                "impostor {impostor}: a layer must be a quad with texture coordinates"
            )));
        }
        let tex = geom.materials[mesh.material as usize]
            .base_color_texture
            .and_then(|t| geom.textures.get(t as usize))
            .ok_or_else(|| bad(format!("impostor {impostor}: a layer has no texture")))?;
        let (aw, ah) = (f64::from(tex.width), f64::from(tex.height));
        let x0 = (f64::from(mesh.uvs[0].x) * aw).round() as i64;
        let y0 = (f64::from(mesh.uvs[0].y) * ah).round() as i64;
        let x1 = (f64::from(mesh.uvs[2].x) * aw).round() as i64;
        let y1 = (f64::from(mesh.uvs[2].y) * ah).round() as i64;
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
        let m = inst.transform;
        let index = layers
            .iter()
            .rev()
            .take_while(|l: &&Layer| l.impostor == impostor)
            .count() as u32;
        layers.push(Layer {
            impostor,
            index,
            res: res as u32,
            rgba,
            corners: [0, 1, 2, 3].map(|k| m.transform_point3(mesh.positions[k].as_dvec3())),
            normal: mesh.normals.first().map_or(Vec3::Z, |n| {
                (m.matrix3 * n.as_dvec3()).normalize().as_vec3()
            }),
        });
    }
    Ok(layers)
}

/// The `extras.impostor` of every object (mesh node) of a baked GLB, in
/// object order, read with the safe glTF loader.
fn impostor_ids(bytes: &[u8], source: &str) -> Result<Vec<u32>> {
    object_extras(bytes, source)?
        .iter()
        .enumerate()
        .map(|(object, extras)| {
            extras
                .as_ref()
                .and_then(|e| e.get("impostor"))
                .and_then(serde_json::Value::as_u64)
                .and_then(|v| u32::try_from(v).ok())
                .ok_or_else(|| {
                    Error::bad(
                        source,
                        format!(
                            "not a baked impostor file: object {object} lacks `extras.impostor`"
                        ),
                    )
                })
        })
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

/// Bakes every impostor of `placement` over `geom` (the geometry of
/// `scene`) into a GLB. The placement is checked first by
/// [`Placement::validate`].
/// `source` names the placement in errors.
pub fn bake(
    scene: &Scene,
    geom: &SceneGeometry,
    memory: &MemoryParams,
    placement: &Placement,
    opts: &BakeOptions,
    source: &str,
) -> Result<(Vec<u8>, BakeReport)> {
    let layers = render_layers(scene, geom, placement, source)?;

    let sizes: Vec<u32> = layers.iter().map(|l| l.res).collect();
    let (slots, mut atlas_sizes) = pack(&sizes, opts.atlas_size, opts.gutter);
    atlas::fit_sizes(&mut atlas_sizes, opts.textures);
    let mut atlases: Vec<Vec<u8>> = atlas_sizes
        .iter()
        .map(|&(w, h)| vec![0u8; w as usize * h as usize * 4])
        .collect();
    for (l, s) in layers.iter().zip(&slots) {
        let aw = atlas_sizes[s.atlas as usize].0;
        blit(&mut atlases[s.atlas as usize], aw, l, *s, opts.gutter);
    }
    let files = atlas::encode_atlases(&atlases, &atlas_sizes, opts.textures)?;

    let mut b = GlbBuilder::new();
    let sampler = b.add_sampler(&Sampler {
        min_filter: MinFilter::LinearMipmapLinear,
        ..Sampler::linear_clamp()
    })?;
    let mut materials = Vec::with_capacity(files.len());
    for (i, file) in files.iter().enumerate() {
        let texture =
            atlas::add_atlas(&mut b, &format!("atlas {i}"), file, opts.textures, sampler)?;
        let mut m = Material::new(format!("impostor atlas {i}"), [1.0; 4]);
        m.base_color_texture = Some(texture);
        m.alpha_mode = AlphaMode::Mask {
            cutoff: ALPHA_CUTOFF,
        };
        m.double_sided = true;
        m.unlit = true;
        materials.push(b.add_material(&m)?);
    }
    // Layers grouped by impostor, in impostor order (layers are already
    // in impostor then layer order).
    let mut roots = Vec::new();
    let mut i = 0;
    while i < layers.len() {
        let id = layers[i].impostor;
        let mut prims = Vec::new();
        while i < layers.len() && layers[i].impostor == id {
            let l = &layers[i];
            let s = slots[i];
            let (aw, ah) = atlas_sizes[s.atlas as usize];
            let (u0, v0) = (s.x as f32 / aw as f32, s.y as f32 / ah as f32);
            let (u1, v1) = (
                (s.x + l.res) as f32 / aw as f32,
                (s.y + l.res) as f32 / ah as f32,
            );
            let positions = l.corners.map(|p| p.as_vec3().to_array());
            let normals = [l.normal.to_array(); 4];
            let uvs = [[u0, v0], [u0, v1], [u1, v1], [u1, v0]];
            let g = b.add_geometry(&glb::Geometry {
                positions: &positions,
                normals: Some(&normals),
                texcoords: Some(&uvs),
                indices: &[0, 1, 2, 0, 2, 3],
            })?;
            prims.push(MeshPrimitive {
                geometry: g,
                material: Some(materials[s.atlas as usize]),
            });
            i += 1;
        }
        let imp = &placement.impostors[id as usize];
        let mesh = b.add_mesh(&format!("impostor {id}"), &prims)?;
        let node = b.add_node(
            Node::new(format!("impostor {id}"))
                .with_mesh(mesh)
                .with_extras(json!({
                    "impostor": id,
                    "cluster": imp.node,
                    "layers": imp.layers,
                    "layers_written": prims.len(),
                    "resolution": imp.resolution,
                })),
        )?;
        roots.push(node);
    }
    b.set_scene_roots(&roots)?;

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
        texture_bytes: files.iter().map(|f| f.len() as u64).sum(),
        placement_memory_bytes: placement.summary.memory_bytes,
        atlas_texels: atlas_sizes
            .iter()
            .map(|&(w, h)| u64::from(w) * u64::from(h))
            .sum(),
        impostor_memory_bytes: impostor_texels.into_iter().map(bytes).collect(),
    };
    Ok((b.finish(), report))
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
            placement,
            opts,
            source,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn packing_never_overlaps_and_stays_inside() {
        let mut rng = crate::math::rng::Rng::new(3);
        let sizes: Vec<u32> = (0..300)
            .map(|_| 4 + (rng.next_u64() % 200) as u32)
            .collect();
        let (gutter, atlas) = (4, 512);
        let (slots, atlases) = pack(&sizes, atlas, gutter);
        assert!(atlases.len() > 1);
        let rect = |i: usize| {
            let s = slots[i];
            (s.atlas, s.x - gutter, s.y - gutter, sizes[i] + 2 * gutter)
        };
        for i in 0..sizes.len() {
            let (a, x, y, side) = rect(i);
            let (w, h) = atlases[a as usize];
            assert!(x + side <= w && y + side <= h && w <= atlas && h <= atlas);
            for j in 0..i {
                let (b, x2, y2, side2) = rect(j);
                let apart = a != b
                    || x + side <= x2
                    || x2 + side2 <= x
                    || y + side <= y2
                    || y2 + side2 <= y;
                assert!(apart, "layers {i} and {j} overlap");
            }
        }
        // A layer larger than the atlas size gets an atlas of its own size;
        // the next layer starts a regular one.
        let (slots, atlases) = pack(&[600, 10], 512, 2);
        assert_eq!(atlases[0], (604, 604));
        assert_eq!((slots[1].atlas, atlases[1].0), (1, 512));
    }

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
