//! Scene geometry for rendering: triangles, normals, texture coordinates and
//! materials ([`crate::scene::material::Material`]) of a glTF scene, read
//! with the same safety rules and the same object ids as
//! [`crate::scene::gltf_load`] (which reads bounds only).
//! Only full detail is read: `MSFT_lod` level nodes are not objects (the
//! shared scene walk skips them) and their meshes are not loaded.
//!
//! Every mesh primitive with triangles is read once, however often it is
//! instanced; an [`Instance`] places it in the world for one object. Object
//! ids follow the default scene's depth-first pre-order walk, so they match
//! the ids of [`crate::scene::Scene`] built from the same file.
//!
//! Base colour images (PNG, JPEG) are decoded to RGBA8 with their size
//! checked before decoding (at most [`MAX_IMAGE_SIDE`] per side). An image in
//! another format (e.g. KTX2) or that fails to decode is an error naming it.
//! Only `TEXCOORD_0` is read; a base colour texture's
//! `KHR_texture_transform` (how `gltfpack` dequantizes texture coordinates)
//! is applied to the coordinates of the primitives that use its material.

use std::borrow::Cow;
use std::io::Cursor;
use std::path::Path;

use base64::Engine;
use glam::{DAffine3, Vec2, Vec3};
use gltf::accessor::{DataType, Dimensions};
use gltf::mesh::Mode;

use crate::scene::gltf_load::{
    base_dir_of, check_glb_header, check_indices, checked_accessor, decode_compressed_views,
    decode_draco_primitives, gltf_error, guarded, place_gpu_instances, precheck_root_with,
    read_floats, read_uri, resolve_buffers, walk_scene,
};
use crate::scene::material::{AlphaMode, Material, UvTransform, Wrap, uv_transform};
use crate::{Error, Result};

/// The largest decoded image side, texels.
pub const MAX_IMAGE_SIDE: u32 = 8192;

/// The most bytes a scene's decoded images may take together (RGBA8):
/// 4 GiB, sixteen images of the largest size. Checked from each image's
/// header before it is decoded.
pub const MAX_DECODED_IMAGE_BYTES: u64 = 4 << 30;

/// A scene's renderable geometry.
#[derive(Clone, Debug, Default)]
pub struct SceneGeometry {
    /// Distinct triangle primitives.
    pub meshes: Vec<MeshData>,
    /// Placements of meshes, one per (object, primitive with triangles).
    pub instances: Vec<Instance>,
    /// Materials: the glTF materials by index, then the glTF default material
    /// (for primitives that name none).
    pub materials: Vec<Material>,
    /// Decoded base colour images.
    pub textures: Vec<Texture>,
    /// Number of objects (nodes with a mesh), as in the scene.
    pub objects: usize,
    /// Per object, the index of its node in the glTF file it was loaded
    /// from (objects are the scene walk's mesh nodes, which need not be in
    /// node order); empty when the geometry was not loaded from glTF.
    pub object_nodes: Vec<u32>,
}

/// One triangle primitive in its local space.
#[derive(Clone, Debug, Default)]
pub struct MeshData {
    /// Positions.
    pub positions: Vec<Vec3>,
    /// Unit normals, one per position (computed when the file has none).
    pub normals: Vec<Vec3>,
    /// `TEXCOORD_0`, one per position, or empty.
    pub uvs: Vec<Vec2>,
    /// Triangle list.
    pub indices: Vec<u32>,
    /// Index into [`SceneGeometry::materials`].
    pub material: u32,
}

/// A mesh placed for an object.
#[derive(Clone, Copy, Debug)]
pub struct Instance {
    /// Object id.
    pub object: u32,
    /// Index into [`SceneGeometry::meshes`].
    pub mesh: u32,
    /// Local to world.
    pub transform: DAffine3,
}

/// A decoded texture with its sampler's wrapping.
#[derive(Clone, Debug)]
pub struct Texture {
    /// Width, texels.
    pub width: u32,
    /// Height, texels.
    pub height: u32,
    /// RGBA8 (sRGB colour), rows from the top; shared by the textures of
    /// one image.
    pub rgba: std::sync::Arc<[u8]>,
    /// Wrapping of `u`.
    pub wrap_s: Wrap,
    /// Wrapping of `v`.
    pub wrap_t: Wrap,
}

impl SceneGeometry {
    /// Number of objects (nodes with a mesh).
    pub fn object_count(&self) -> usize {
        self.objects
    }

    /// Triangles over all instances.
    pub fn triangle_count(&self) -> u64 {
        self.instances
            .iter()
            .map(|i| self.meshes[i.mesh as usize].indices.len() as u64 / 3)
            .sum()
    }
}

/// Loads the geometry of a `.glb` / `.gltf` file (relative resources next to
/// it). A JSON scene summary has no geometry: that is an error.
pub fn load_geometry_file(path: &Path) -> Result<SceneGeometry> {
    let source = path.display().to_string();
    let bytes = crate::files::read_file(path, crate::files::MAX_SCENE_BYTES, "scene")?;
    load(&bytes, &source, Some(base_dir_of(path)))
}

/// Loads the geometry of uploaded bytes (GLB or glTF JSON with embedded
/// resources; no external URIs).
pub fn load_geometry_bytes(bytes: &[u8], source: &str) -> Result<SceneGeometry> {
    load(bytes, source, None)
}

fn load(bytes: &[u8], source: &str, base_dir: Option<&Path>) -> Result<SceneGeometry> {
    if !bytes.starts_with(b"glTF") {
        #[derive(serde::Deserialize)]
        struct Probe {
            #[serde(default)]
            objects: Option<serde::de::IgnoredAny>,
        }
        if let Ok(Probe { objects: Some(_) }) = serde_json::from_slice::<Probe>(bytes) {
            return Err(Error::bad(
                source,
                "a JSON scene summary has no geometry (bounds and costs only); use the .glb or .gltf scene",
            ));
        }
    }
    guarded(source, || load_inner(bytes, source, base_dir))
}

fn load_inner(bytes: &[u8], source: &str, base_dir: Option<&Path>) -> Result<SceneGeometry> {
    if bytes.starts_with(b"glTF") {
        check_glb_header(bytes, source)?;
    }
    let gltf::Gltf { document, blob } =
        gltf::Gltf::from_slice_without_validation(bytes).map_err(|e| gltf_error(source, e))?;
    let mut root = document.into_json();
    precheck_root_with(&mut root, source, true)?;
    let doc = gltf::Document::from_json(root).map_err(|e| gltf_error(source, e))?;
    let mut buffers = resolve_buffers(&doc, blob.as_deref(), source, base_dir)?;
    let doc = decode_compressed_views(doc, &mut buffers, source)?;
    let doc = decode_draco_primitives(doc, &mut buffers, source)?;
    let mut scene_instances = walk_scene(&doc, source)?;
    place_gpu_instances(&doc, &buffers, &mut scene_instances, source)?;

    // Textures used as base colour; each image is decoded once, however
    // many textures use it.
    let mut textures = Vec::new();
    let mut texture_of: Vec<Option<u32>> = vec![None; doc.textures().len()];
    let mut image_of: Vec<Option<Decoded>> = vec![None; doc.images().len()];
    let mut image_budget = MAX_DECODED_IMAGE_BYTES;
    let mut materials = Vec::with_capacity(doc.materials().len() + 1);
    let mut uv_transforms: Vec<Option<UvTransform>> = Vec::new();
    for m in doc.materials() {
        let pbr = m.pbr_metallic_roughness();
        let mut tex = None;
        let uv = pbr
            .base_color_texture()
            .map(|info| {
                uv_transform(
                    &info,
                    &format!("{source}: material {}", m.index().unwrap_or(0)),
                )
            })
            .transpose()?
            .flatten();
        uv_transforms.push(uv);
        if let Some(info) = pbr.base_color_texture() {
            let t = info.texture();
            if texture_of[t.index()].is_none() {
                let what = format!(
                    "{source}: texture {} image {}",
                    t.index(),
                    t.source().index()
                );
                let image = t.source().index();
                if image_of[image].is_none() {
                    let (w, h, rgba) =
                        decode_image(&t.source(), &buffers, base_dir, &what, &mut image_budget)?;
                    image_of[image] = Some((w, h, rgba.into()));
                }
                let (width, height, rgba) = image_of[image].clone().expect("decoded above");
                let s = t.sampler();
                textures.push(Texture {
                    width,
                    height,
                    rgba,
                    wrap_s: wrap(s.wrap_s()),
                    wrap_t: wrap(s.wrap_t()),
                });
                texture_of[t.index()] = Some(textures.len() as u32 - 1);
            }
            tex = texture_of[t.index()];
        }
        materials.push(Material {
            name: m.name().unwrap_or_default().to_string(),
            base_color: pbr.base_color_factor(),
            base_color_texture: tex,
            metallic: pbr.metallic_factor(),
            roughness: pbr.roughness_factor(),
            alpha_mode: match m.alpha_mode() {
                gltf::material::AlphaMode::Opaque => AlphaMode::Opaque,
                gltf::material::AlphaMode::Mask => AlphaMode::Mask {
                    cutoff: m.alpha_cutoff().unwrap_or(0.5),
                },
                gltf::material::AlphaMode::Blend => AlphaMode::Blend,
            },
            double_sided: m.double_sided(),
            unlit: m.unlit(),
        });
    }
    let default_material = materials.len() as u32;
    materials.push(Material::default());

    // Every used mesh's triangle primitives, read once.
    let gmeshes: Vec<gltf::Mesh> = doc.meshes().collect();
    let mut mesh_prims: Vec<Option<Vec<u32>>> = vec![None; gmeshes.len()];
    let mut meshes = Vec::new();
    let mut instances = Vec::new();
    for (object, inst) in scene_instances.iter().enumerate() {
        if mesh_prims[inst.mesh].is_none() {
            let mut ids = Vec::new();
            for prim in gmeshes[inst.mesh].primitives() {
                let what = format!("{source}: mesh {} primitive {}", inst.mesh, prim.index());
                if let Some(mut data) = read_primitive(&prim, &buffers, &what)? {
                    data.material = prim
                        .material()
                        .index()
                        .map_or(default_material, |i| i as u32);
                    if let Some(t) = prim.material().index().and_then(|i| uv_transforms[i]) {
                        for uv in &mut data.uvs {
                            *uv = t.apply(*uv);
                        }
                    }
                    meshes.push(data);
                    ids.push(meshes.len() as u32 - 1);
                }
            }
            mesh_prims[inst.mesh] = Some(ids);
        }
        for &mesh in mesh_prims[inst.mesh].as_deref().unwrap_or_default() {
            instances.push(Instance {
                object: object as u32,
                mesh,
                transform: inst.world,
            });
        }
    }
    Ok(SceneGeometry {
        meshes,
        instances,
        materials,
        textures,
        objects: scene_instances.len(),
        object_nodes: scene_instances.iter().map(|i| i.node as u32).collect(),
    })
}

/// An image's width, height and RGBA8 pixels, shared by its textures.
type Decoded = (u32, u32, std::sync::Arc<[u8]>);

fn wrap(m: gltf::texture::WrappingMode) -> Wrap {
    match m {
        gltf::texture::WrappingMode::ClampToEdge => Wrap::ClampToEdge,
        gltf::texture::WrappingMode::MirroredRepeat => Wrap::MirroredRepeat,
        gltf::texture::WrappingMode::Repeat => Wrap::Repeat,
    }
}

/// The bytes of an image: a buffer view, a base64 `data:` URI or (for local
/// files) a relative path; a PNG, a JPEG or a KTX2 file of UASTC content
/// (`KHR_texture_basisu`, as `bake --textures ktx2` writes), decoded to
/// RGBA8 (KTX2: its level 0) with its size checked first,
/// against [`MAX_IMAGE_SIDE`] and against `budget`, the bytes the scene's
/// images may still take (reduced by this one's).
fn decode_image(
    image: &gltf::Image,
    buffers: &[Cow<'_, [u8]>],
    base_dir: Option<&Path>,
    what: &str,
    budget: &mut u64,
) -> Result<(u32, u32, Vec<u8>)> {
    let bytes: Cow<[u8]> = match image.source() {
        gltf::image::Source::View { view, .. } => {
            let data = buffers
                .get(view.buffer().index())
                .ok_or_else(|| Error::bad(what, "its buffer is missing"))?;
            let (start, len) = (view.offset(), view.length());
            match start.checked_add(len) {
                Some(end) if end <= data.len() => Cow::Borrowed(&data[start..end]),
                _ => return Err(Error::bad(what, "its bufferView lies outside its buffer")),
            }
        }
        gltf::image::Source::Uri { uri, .. } => {
            if let Some(rest) = uri.strip_prefix("data:") {
                let (header, payload) = rest
                    .split_once(',')
                    .ok_or_else(|| Error::bad(what, "data: URI has no `,`"))?;
                if !header.to_ascii_lowercase().ends_with(";base64") {
                    return Err(Error::bad(what, "data: URI is not base64-encoded"));
                }
                const ENGINE: base64::engine::GeneralPurpose = base64::engine::GeneralPurpose::new(
                    &base64::alphabet::STANDARD,
                    base64::engine::GeneralPurposeConfig::new()
                        .with_decode_padding_mode(base64::engine::DecodePaddingMode::Indifferent)
                        .with_decode_allow_trailing_bits(true),
                );
                Cow::Owned(
                    ENGINE.decode(payload.trim()).map_err(|e| {
                        Error::bad(what, format!("data: URI is not valid base64: {e}"))
                    })?,
                )
            } else {
                Cow::Owned(read_uri(uri, what, base_dir)?)
            }
        }
    };
    // Its size, checked before it is decoded.
    let check = |w: u32, h: u32, budget: &mut u64| -> Result<()> {
        if w == 0 || h == 0 || w > MAX_IMAGE_SIDE || h > MAX_IMAGE_SIDE {
            return Err(Error::bad(
                what,
                format!("image size {w} × {h} is outside 1 … {MAX_IMAGE_SIDE} per side"),
            ));
        }
        let size = 4 * u64::from(w) * u64::from(h);
        if size > *budget {
            return Err(Error::bad(
                what,
                format!(
                    "the scene's images decode to more than {} GiB together (this one {w} × {h})",
                    MAX_DECODED_IMAGE_BYTES >> 30
                ),
            ));
        }
        *budget -= size;
        Ok(())
    };
    if bytes.starts_with(&crate::scene::glb::KTX2_IDENTIFIER) {
        return crate::scene::glb::decode_ktx2(&bytes, what, |w, h| check(w, h, budget));
    }
    let reader = image::ImageReader::new(Cursor::new(&*bytes))
        .with_guessed_format()
        .map_err(|e| Error::bad(what, format!("unreadable image: {e}")))?;
    if reader.format().is_none() {
        return Err(Error::bad(what, "not a PNG, JPEG or KTX2 (UASTC) image"));
    }
    let (w, h) = reader
        .into_dimensions()
        .map_err(|e| Error::bad(what, format!("unreadable image header: {e}")))?;
    check(w, h, budget)?;
    let mut reader = image::ImageReader::new(Cursor::new(&*bytes))
        .with_guessed_format()
        .map_err(|e| Error::bad(what, format!("unreadable image: {e}")))?;
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(MAX_IMAGE_SIDE);
    limits.max_image_height = Some(MAX_IMAGE_SIDE);
    limits.max_alloc = Some(512 * 1024 * 1024);
    reader.limits(limits);
    let img = reader
        .decode()
        .map_err(|e| Error::bad(what, format!("the image does not decode: {e}")))?;
    let rgba = img.to_rgba8();
    Ok((rgba.width(), rgba.height(), rgba.into_raw()))
}

/// Reads one primitive as a triangle list; `None` for points and lines.
fn read_primitive(
    prim: &gltf::Primitive,
    buffers: &[Cow<'_, [u8]>],
    what: &str,
) -> Result<Option<MeshData>> {
    if matches!(
        prim.mode(),
        Mode::Points | Mode::Lines | Mode::LineLoop | Mode::LineStrip
    ) {
        return Ok(None);
    }
    let pos_acc = prim
        .get(&gltf::Semantic::Positions)
        .ok_or_else(|| Error::bad(format!("{what} POSITION"), "is missing"))?;
    let positions: Vec<Vec3> = read_floats::<3>(
        &pos_acc,
        buffers,
        &format!("{what} POSITION"),
        Dimensions::Vec3,
    )?
    .into_iter()
    .map(Vec3::from_array)
    .collect();
    let n = positions.len();
    let elements: Vec<u32> = match prim.indices() {
        None => (0..n as u32).collect(),
        Some(idx) => {
            let w = format!("{what} indices");
            check_indices(&idx, buffers, n, &w)?;
            let data = checked_accessor(&idx, buffers, &w)?;
            (0..data.count)
                .map(|k| {
                    let e = data.element(k);
                    match idx.data_type() {
                        DataType::U8 => u32::from(e[0]),
                        DataType::U16 => u32::from(u16::from_le_bytes([e[0], e[1]])),
                        _ => u32::from_le_bytes([e[0], e[1], e[2], e[3]]),
                    }
                })
                .collect()
        }
    };
    let indices: Vec<u32> = match prim.mode() {
        Mode::TriangleStrip => (0..elements.len().saturating_sub(2))
            .flat_map(|i| {
                if i % 2 == 0 {
                    [elements[i], elements[i + 1], elements[i + 2]]
                } else {
                    [elements[i + 1], elements[i], elements[i + 2]]
                }
            })
            .collect(),
        Mode::TriangleFan => (1..elements.len().saturating_sub(1))
            .flat_map(|i| [elements[0], elements[i], elements[i + 1]])
            .collect(),
        _ => elements[..elements.len() / 3 * 3].to_vec(),
    };
    let normals = match prim.get(&gltf::Semantic::Normals) {
        Some(acc) => {
            let w = format!("{what} NORMAL");
            let v = read_floats::<3>(&acc, buffers, &w, Dimensions::Vec3)?;
            if v.len() != n {
                return Err(Error::bad(
                    w,
                    format!("has {} elements for {n} positions", v.len()),
                ));
            }
            v.into_iter()
                .map(|a| Vec3::from_array(a).normalize_or_zero())
                .collect()
        }
        None => smooth_normals(&positions, &indices),
    };
    let uvs = match prim.get(&gltf::Semantic::TexCoords(0)) {
        Some(acc) => {
            let w = format!("{what} TEXCOORD_0");
            let v = read_floats::<2>(&acc, buffers, &w, Dimensions::Vec2)?;
            if v.len() != n {
                return Err(Error::bad(
                    w,
                    format!("has {} elements for {n} positions", v.len()),
                ));
            }
            v.into_iter().map(Vec2::from_array).collect()
        }
        None => Vec::new(),
    };
    Ok(Some(MeshData {
        positions,
        normals,
        uvs,
        indices,
        material: 0,
    }))
}

/// Area-weighted vertex normals.
fn smooth_normals(positions: &[Vec3], indices: &[u32]) -> Vec<Vec3> {
    let mut n = vec![Vec3::ZERO; positions.len()];
    for t in indices.chunks_exact(3) {
        let [a, b, c] = [t[0], t[1], t[2]].map(|i| positions[i as usize]);
        let f = (b - a).cross(c - a);
        for &i in t {
            n[i as usize] += f;
        }
    }
    n.into_iter().map(Vec3::normalize_or_zero).collect()
}

impl SceneGeometry {
    /// Per object, its range of `instances` (instances of one object are
    /// contiguous); `(0, 0)` for an object without triangles.
    pub fn instance_ranges(&self) -> Vec<(usize, usize)> {
        let mut r = vec![(0usize, 0usize); self.objects];
        let mut i = 0;
        while i < self.instances.len() {
            let o = self.instances[i].object as usize;
            let mut j = i;
            while j < self.instances.len() && self.instances[j].object as usize == o {
                j += 1;
            }
            if let Some(slot) = r.get_mut(o) {
                *slot = (i, j);
            }
            i = j;
        }
        r
    }

    /// A random point on a surface of the object whose instances are
    /// `range` that `eye` could see: on a triangle facing it (or
    /// double-sided), not blended, and accepted by `keep`. `None` after
    /// `tries` draws without one.
    pub fn surface_point(
        &self,
        range: (usize, usize),
        eye: glam::DVec3,
        tries: u32,
        rng: &mut crate::math::rng::Rng,
        keep: impl Fn(glam::DVec3) -> bool,
    ) -> Option<glam::DVec3> {
        let insts = self.instances.get(range.0..range.1)?;
        let total: usize = insts
            .iter()
            .map(|i| self.meshes[i.mesh as usize].indices.len() / 3)
            .sum();
        if total == 0 {
            return None;
        }
        for _ in 0..tries {
            let mut t = (rng.next_u64() % total as u64) as usize;
            let inst = insts.iter().find(|i| {
                let n = self.meshes[i.mesh as usize].indices.len() / 3;
                if t < n {
                    true
                } else {
                    t -= n;
                    false
                }
            })?;
            let mesh = &self.meshes[inst.mesh as usize];
            let mat = &self.materials[mesh.material as usize];
            if mat.alpha_mode == AlphaMode::Blend {
                continue;
            }
            let v = |k: usize| {
                inst.transform
                    .transform_point3(mesh.positions[mesh.indices[3 * t + k] as usize].as_dvec3())
            };
            let (a, b, c) = (v(0), v(1), v(2));
            let (mut u, mut w) = (rng.f64(), rng.f64());
            if u + w > 1.0 {
                (u, w) = (1.0 - u, 1.0 - w);
            }
            let p = a + (b - a) * u + (c - a) * w;
            let facing = (b - a).cross(c - a).dot(p - eye) < 0.0;
            if (facing || mat.double_sided) && keep(p) {
                return Some(p);
            }
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::citygen::{CityParams, generate};
    use crate::scene::gltf_load::load_scene_bytes;

    #[test]
    fn city_geometry_matches_the_scene() {
        let glb = generate(&CityParams {
            seed: 2,
            scale: 0.05,
            lod: false,
            ..Default::default()
        })
        .unwrap();
        let scene = load_scene_bytes(&glb, "city").unwrap();
        let geom = load_geometry_bytes(&glb, "city").unwrap();
        assert_eq!(geom.object_count(), scene.objects.len());
        assert_eq!(geom.triangle_count(), scene.total_triangles());
        let mut lo = vec![glam::DVec3::splat(f64::INFINITY); scene.objects.len()];
        let mut hi = vec![glam::DVec3::splat(f64::NEG_INFINITY); scene.objects.len()];
        for inst in &geom.instances {
            for p in &geom.meshes[inst.mesh as usize].positions {
                let w = inst.transform.transform_point3(p.as_dvec3());
                lo[inst.object as usize] = lo[inst.object as usize].min(w);
                hi[inst.object as usize] = hi[inst.object as usize].max(w);
            }
        }
        // The scene's bounds are the box of the transformed local box, so
        // they contain the transformed vertices; triangles agree per object.
        let mut tris = vec![0u64; scene.objects.len()];
        for inst in &geom.instances {
            tris[inst.object as usize] += geom.meshes[inst.mesh as usize].indices.len() as u64 / 3;
        }
        for (o, ob) in scene.objects.iter().enumerate() {
            assert!(lo[o].cmpge(ob.min - 1e-3).all(), "object {o}");
            assert!(hi[o].cmple(ob.max + 1e-3).all(), "object {o}");
            assert_eq!(tris[o], ob.triangles, "object {o}");
        }
        // Instanced meshes are stored once.
        assert!(geom.meshes.len() < geom.instances.len());
        for m in &geom.meshes {
            assert_eq!(m.normals.len(), m.positions.len());
            assert!(m.indices.iter().all(|&i| (i as usize) < m.positions.len()));
        }
    }

    #[test]
    fn textured_quad_reads_material_texture_and_uvs() {
        use crate::scene::glb::{self, GlbBuilder, Node, Sampler};
        use crate::scene::material;
        let texels = [
            255u8, 0, 0, 255, 0, 255, 0, 255, 0, 0, 255, 255, 255, 255, 255, 128,
        ];
        let png = crate::bake::encode_png(&texels, 2, 2).unwrap();
        let mut b = GlbBuilder::new();
        let image = b.add_image_png("t", &png).unwrap();
        let sampler = b.add_sampler(&Sampler::linear_clamp()).unwrap();
        let texture = b.add_texture(image, Some(sampler)).unwrap();
        let mut m = material::Material::new("m", [0.5, 1.0, 1.0, 1.0]);
        m.base_color_texture = Some(texture);
        m.alpha_mode = AlphaMode::Mask { cutoff: 0.25 };
        m.double_sided = true;
        let material = b.add_material(&m).unwrap();
        let positions = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
        ];
        let uvs = [[0.0, 1.0], [1.0, 1.0], [1.0, 0.0], [0.0, 0.0]];
        let g = glb::Geometry {
            positions: &positions,
            normals: None,
            texcoords: Some(&uvs),
            indices: &[0, 1, 2, 0, 2, 3],
        };
        let mesh = b.add_mesh_from("quad", &[(g, Some(material))]).unwrap();
        let a = b.add_node(Node::new("a").with_mesh(mesh)).unwrap();
        let c = b
            .add_node(Node::new("b").with_mesh(mesh).with_trs(
                [5.0, 0.0, 0.0],
                [0.0, 0.0, 0.0, 1.0],
                [2.0; 3],
            ))
            .unwrap();
        b.set_scene_roots(&[a, c]).unwrap();
        let geom = load_geometry_bytes(&b.finish(), "quad.glb").unwrap();
        assert_eq!(geom.object_count(), 2);
        assert_eq!(geom.meshes.len(), 1, "the instanced quad is read once");
        assert_eq!(geom.instances.len(), 2);
        assert_eq!(
            geom.instances[1]
                .transform
                .transform_point3(glam::DVec3::new(1.0, 1.0, 0.0)),
            glam::DVec3::new(7.0, 2.0, 0.0)
        );
        let q = &geom.meshes[0];
        assert_eq!(q.uvs[2], Vec2::new(1.0, 0.0));
        // No normals in the file: computed from the faces (+z).
        assert!(q.normals.iter().all(|n| (*n - Vec3::Z).length() < 1e-6));
        let mat = &geom.materials[q.material as usize];
        assert_eq!(mat.base_color, [0.5, 1.0, 1.0, 1.0]);
        assert_eq!(mat.alpha_mode, AlphaMode::Mask { cutoff: 0.25 });
        assert!(mat.double_sided);
        assert_eq!(
            (mat.name.as_str(), mat.metallic, mat.roughness),
            ("m", 0.0, 0.9)
        );
        assert!(!mat.unlit);
        let t = &geom.textures[mat.base_color_texture.unwrap() as usize];
        assert_eq!((t.width, t.height), (2, 2));
        assert_eq!(*t.rgba, texels[..]);
        assert_eq!(t.wrap_s, Wrap::ClampToEdge);
    }

    /// A GLB with its JSON chunk changed by `edit` (the BIN chunk kept).
    fn edit_glb(glb: &[u8], edit: impl FnOnce(&mut serde_json::Value)) -> Vec<u8> {
        let n = u32::from_le_bytes(glb[12..16].try_into().unwrap()) as usize;
        let mut json: serde_json::Value = serde_json::from_slice(&glb[20..20 + n]).unwrap();
        edit(&mut json);
        let mut text = serde_json::to_vec(&json).unwrap();
        while !text.len().is_multiple_of(4) {
            text.push(b' ');
        }
        let bin = &glb[20 + n..];
        let mut out = b"glTF".to_vec();
        out.extend(2u32.to_le_bytes());
        out.extend(((12 + 8 + text.len() + bin.len()) as u32).to_le_bytes());
        out.extend((text.len() as u32).to_le_bytes());
        out.extend(b"JSON");
        out.extend(text);
        out.extend(bin);
        out
    }

    #[test]
    fn texture_transform_of_the_base_colour_texture_is_applied() {
        use crate::scene::glb::{self, GlbBuilder, Node};
        use crate::scene::material;
        let png = crate::bake::encode_png(&[200u8; 16], 2, 2).unwrap();
        let mut b = GlbBuilder::new();
        let image = b.add_image_png("t", &png).unwrap();
        let texture = b.add_texture(image, None).unwrap();
        let mut m = material::Material::new("m", [1.0; 4]);
        m.base_color_texture = Some(texture);
        let material = b.add_material(&m).unwrap();
        // Quantized texture coordinates as gltfpack writes them: integers
        // of a 12-bit grid (here 0 … 4095), scaled and offset back.
        let g = glb::Geometry {
            positions: &[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
            normals: None,
            texcoords: Some(&[[0.0, 0.0], [4095.0, 0.0], [0.0, 4095.0]]),
            indices: &[0, 1, 2],
        };
        let mesh = b.add_mesh_from("tri", &[(g, Some(material))]).unwrap();
        let n = b.add_node(Node::new("a").with_mesh(mesh)).unwrap();
        b.set_scene_roots(&[n]).unwrap();
        let plain = b.finish();
        let scale = 2.0 / 4095.0;
        let with = edit_glb(&plain, |j| {
            j["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"]["extensions"] = serde_json::json!({"KHR_texture_transform":
                    {"offset": [-1.0, 0.5], "scale": [scale, scale]}});
            j["extensionsUsed"] = serde_json::json!(["KHR_texture_transform"]);
            j["extensionsRequired"] = serde_json::json!(["KHR_texture_transform"]);
        });
        // Control: without the extension the stored integers are read.
        let g0 = load_geometry_bytes(&plain, "plain.glb").unwrap();
        assert_eq!(g0.meshes[0].uvs[1], Vec2::new(4095.0, 0.0));
        let g1 = load_geometry_bytes(&with, "with.glb").unwrap();
        let uvs = &g1.meshes[0].uvs;
        let close = |a: Vec2, b: Vec2| (a - b).length() < 1e-5;
        assert!(close(uvs[0], Vec2::new(-1.0, 0.5)), "{uvs:?}");
        assert!(close(uvs[1], Vec2::new(1.0, 0.5)), "{uvs:?}");
        assert!(close(uvs[2], Vec2::new(-1.0, 2.5)), "{uvs:?}");
        // A non-finite transform is refused, naming it.
        let bad = edit_glb(&with, |j| {
            j["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"]["extensions"]["KHR_texture_transform"]
                ["scale"] = serde_json::json!([1e39, 1.0]);
        });
        let e = load_geometry_bytes(&bad, "bad.glb")
            .unwrap_err()
            .to_string();
        assert!(e.contains("material 0 KHR_texture_transform"), "{e}");
    }

    /// Textures that share an image share its decoded pixels, whatever
    /// their samplers: the image is decoded once (24 textures over one
    /// 8192² image would otherwise hold 24 × 256 MB).
    #[test]
    fn textures_of_one_image_share_its_pixels() {
        use crate::scene::glb::{self, GlbBuilder, Node, Sampler};
        use crate::scene::material;
        let png = crate::bake::encode_png(&[9u8; 16], 2, 2).unwrap();
        let mut b = GlbBuilder::new();
        let image = b.add_image_png("t", &png).unwrap();
        let clamp = b.add_sampler(&Sampler::linear_clamp()).unwrap();
        let repeat = b.add_sampler(&Sampler::default()).unwrap();
        let positions = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0]];
        let uvs = [[0.0, 1.0], [1.0, 1.0], [1.0, 0.0]];
        let mut prims = Vec::new();
        for k in 0..24 {
            let sampler = if k % 2 == 0 { clamp } else { repeat };
            let texture = b.add_texture(image, Some(sampler)).unwrap();
            let mut m = material::Material::new(format!("m{k}"), [1.0; 4]);
            m.base_color_texture = Some(texture);
            prims.push(b.add_material(&m).unwrap());
        }
        let g = glb::Geometry {
            positions: &positions,
            normals: None,
            texcoords: Some(&uvs),
            indices: &[0, 1, 2],
        };
        let parts: Vec<_> = prims.iter().map(|&m| (g, Some(m))).collect();
        let mesh = b.add_mesh_from("tri", &parts).unwrap();
        let n = b.add_node(Node::new("n").with_mesh(mesh)).unwrap();
        b.set_scene_roots(&[n]).unwrap();
        let geom = load_geometry_bytes(&b.finish(), "shared.glb").unwrap();
        assert_eq!(geom.textures.len(), 24);
        let first = &geom.textures[0].rgba;
        assert_eq!(**first, [9u8; 16]);
        assert!(
            geom.textures
                .iter()
                .all(|t| std::sync::Arc::ptr_eq(&t.rgba, first))
        );
        assert_eq!(
            geom.textures[1].wrap_s,
            crate::scene::material::Wrap::Repeat
        );
    }

    #[test]
    fn summaries_have_no_geometry() {
        let e = load_geometry_bytes(br#"{"objects": []}"#, "s.json").unwrap_err();
        assert!(e.to_string().contains("no geometry"), "{e}");
    }

    #[test]
    fn corrupt_bytes_never_panic() {
        let glb = generate(&CityParams {
            seed: 1,
            scale: 0.01,
            lod: false,
            ..Default::default()
        })
        .unwrap();
        // Flips in the header and JSON chunk reach the parser and the
        // checks; flips anywhere else the accessor reads. Every outcome is
        // a result, and no error may be a panic the loader caught (its
        // last line of defence): each must be a check that named the problem.
        let json_end = 20 + u32::from_le_bytes(glb[12..16].try_into().unwrap()) as usize;
        let mut rng = crate::math::rng::Rng::new(7);
        let mut rejected = 0;
        for k in 0..400 {
            let mut b = glb.clone();
            let span = if k % 2 == 0 { json_end } else { b.len() };
            for _ in 0..1 + k % 3 {
                let i = (rng.next_u64() % span as u64) as usize;
                b[i] ^= 1 << (rng.next_u64() % 8);
            }
            if let Err(e) = load_geometry_bytes(&b, "x.glb") {
                let message = e.to_string();
                assert!(
                    !message.contains("parser failed"),
                    "flip {k}: a caught panic, not a check: {message}"
                );
                rejected += 1;
            }
        }
        assert!(
            rejected >= 100,
            "only {rejected} of 400 corrupt files rejected"
        );
        let half = load_geometry_bytes(&glb[..glb.len() / 2], "x.glb").unwrap_err();
        assert!(!half.to_string().contains("parser failed"), "{half}");
    }

    #[test]
    fn strips_fans_and_computed_normals() {
        let p = [Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::new(1.0, 1.0, 0.0)];
        let n = smooth_normals(&p, &[0, 1, 2, 1, 3, 2]);
        assert!(n.iter().all(|v| (*v - Vec3::Z).length() < 1e-6));
    }
}
