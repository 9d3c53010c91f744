//! The GLB writer's buffers, geometry, meshes, materials and textures, each
//! checked before it enters the `gltf-json` document, and the layout of the
//! finished file.

use std::collections::BTreeMap;

use gltf::json as gj;
use gltf::json::validation::{Checked::Valid, USize64};
use serde_json::Value;

use super::{
    Geometry, GeometryAccessors, GeometryId, GlbBuilder, MAX_U16_INDEX, MagFilter, MeshPrimitive,
    MinFilter, Sampler, UNLIT_EXTENSION, all_finite, bad, last_index,
};
use crate::Result;
use crate::scene::material::{AlphaMode, Material, Wrap};

/// The largest binary buffer the writer accepts (the GLB length field is 32 bits and
/// the JSON chunk needs room too).
const MAX_BIN_BYTES: usize = 3 << 30;

/// A JSON number equal to `x` exactly: accessor bounds must match the buffer
/// data exactly, and `gltf-json` keeps them as JSON values.
fn jf_exact(x: f32) -> Value {
    Value::from(f64::from(x))
}

fn wrapping(w: Wrap) -> gj::texture::WrappingMode {
    match w {
        Wrap::ClampToEdge => gj::texture::WrappingMode::ClampToEdge,
        Wrap::MirroredRepeat => gj::texture::WrappingMode::MirroredRepeat,
        Wrap::Repeat => gj::texture::WrappingMode::Repeat,
    }
}

/// An accessor over a whole buffer view, without bounds.
fn accessor(
    view: u32,
    count: usize,
    component: gj::accessor::ComponentType,
    type_: gj::accessor::Type,
) -> gj::Accessor {
    gj::Accessor {
        buffer_view: Some(gj::Index::new(view)),
        byte_offset: None,
        count: USize64::from(count),
        component_type: Valid(gj::accessor::GenericComponentType(component)),
        extensions: None,
        extras: None,
        type_: Valid(type_),
        min: None,
        max: None,
        name: None,
        normalized: false,
        sparse: None,
    }
}

impl GlbBuilder {
    /// An empty document.
    pub fn new() -> Self {
        GlbBuilder::default()
    }

    /// Appends `bytes` as a buffer view starting at a 4-byte aligned offset and
    /// pads the buffer back to a multiple of 4 with zeros.
    pub(super) fn push_view(
        &mut self,
        bytes: &[u8],
        target: Option<gj::buffer::Target>,
    ) -> Result<u32> {
        if self.bin.len() + bytes.len() + 3 > MAX_BIN_BYTES {
            return Err(bad("buffer", "the binary buffer would exceed 3 GiB"));
        }
        debug_assert_eq!(self.bin.len() % 4, 0);
        let offset = self.bin.len();
        self.bin.extend_from_slice(bytes);
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        // The offset is written even when it is 0, as glTF allows.
        self.root.buffer_views.push(gj::buffer::View {
            buffer: gj::Index::new(0),
            byte_length: USize64::from(bytes.len()),
            byte_offset: Some(USize64::from(offset)),
            byte_stride: None,
            name: None,
            target: target.map(Valid),
            extensions: None,
            extras: None,
        });
        last_index(&self.root.buffer_views, "bufferViews")
    }

    fn push_accessor(&mut self, accessor: gj::Accessor) -> Result<u32> {
        self.root.accessors.push(accessor);
        last_index(&self.root.accessors, "accessors")
    }

    fn push_vec3_accessor(&mut self, data: &[[f32; 3]], with_bounds: bool) -> Result<u32> {
        let mut bytes = Vec::with_capacity(data.len() * 12);
        for v in data {
            for c in v {
                bytes.extend_from_slice(&c.to_le_bytes());
            }
        }
        let view = self.push_view(&bytes, Some(gj::buffer::Target::ArrayBuffer))?;
        let mut acc = accessor(
            view,
            data.len(),
            gj::accessor::ComponentType::F32,
            gj::accessor::Type::Vec3,
        );
        if with_bounds {
            let mut lo = [f32::INFINITY; 3];
            let mut hi = [f32::NEG_INFINITY; 3];
            for v in data {
                for k in 0..3 {
                    lo[k] = lo[k].min(v[k]);
                    hi[k] = hi[k].max(v[k]);
                }
            }
            acc.min = Some(Value::Array(lo.iter().map(|&x| jf_exact(x)).collect()));
            acc.max = Some(Value::Array(hi.iter().map(|&x| jf_exact(x)).collect()));
        }
        self.push_accessor(acc)
    }

    /// Writes one triangle-list geometry (its accessors and buffer views) and returns
    /// a handle for [`GlbBuilder::add_mesh`]. Fails when the data is empty, not finite,
    /// of mismatched lengths, not a whole number of triangles or indexes out of range.
    pub fn add_geometry(&mut self, geometry: &Geometry<'_>) -> Result<GeometryId> {
        let n = geometry.positions.len();
        if n == 0 {
            return Err(bad("geometry", "no positions"));
        }
        if !geometry.positions.iter().all(|p| all_finite(p)) {
            return Err(bad("geometry", "a position is not finite"));
        }
        if let Some(normals) = geometry.normals {
            if normals.len() != n {
                return Err(bad(
                    "geometry",
                    format!("{} normals for {n} positions", normals.len()),
                ));
            }
            if !normals.iter().all(|v| all_finite(v)) {
                return Err(bad("geometry", "a normal is not finite"));
            }
        }
        if let Some(uvs) = geometry.texcoords {
            if uvs.len() != n {
                return Err(bad(
                    "geometry",
                    format!("{} texture coordinates for {n} positions", uvs.len()),
                ));
            }
            if !uvs.iter().all(|v| all_finite(v)) {
                return Err(bad("geometry", "a texture coordinate is not finite"));
            }
        }
        let indices = geometry.indices;
        if indices.is_empty() || !indices.len().is_multiple_of(3) {
            return Err(bad(
                "geometry",
                format!(
                    "{} indices: need a non-zero multiple of 3 (a triangle list)",
                    indices.len()
                ),
            ));
        }
        let max_index = indices.iter().copied().max().unwrap_or(0);
        if max_index as usize >= n {
            return Err(bad(
                "geometry",
                format!("index {max_index} out of range for {n} positions"),
            ));
        }

        let position = self.push_vec3_accessor(geometry.positions, true)?;
        let normal = match geometry.normals {
            Some(normals) => Some(self.push_vec3_accessor(normals, false)?),
            None => None,
        };
        let texcoord = match geometry.texcoords {
            Some(uvs) => {
                let mut bytes = Vec::with_capacity(uvs.len() * 8);
                for v in uvs {
                    bytes.extend_from_slice(&v[0].to_le_bytes());
                    bytes.extend_from_slice(&v[1].to_le_bytes());
                }
                let view = self.push_view(&bytes, Some(gj::buffer::Target::ArrayBuffer))?;
                Some(self.push_accessor(accessor(
                    view,
                    uvs.len(),
                    gj::accessor::ComponentType::F32,
                    gj::accessor::Type::Vec2,
                ))?)
            }
            None => None,
        };
        let (bytes, component) = if max_index <= MAX_U16_INDEX {
            let mut bytes = Vec::with_capacity(indices.len() * 2);
            for &i in indices {
                // Lossless: every index is at most MAX_U16_INDEX.
                bytes.extend_from_slice(&(i as u16).to_le_bytes());
            }
            (bytes, gj::accessor::ComponentType::U16)
        } else {
            let mut bytes = Vec::with_capacity(indices.len() * 4);
            for &i in indices {
                bytes.extend_from_slice(&i.to_le_bytes());
            }
            (bytes, gj::accessor::ComponentType::U32)
        };
        let view = self.push_view(&bytes, Some(gj::buffer::Target::ElementArrayBuffer))?;
        let indices = self.push_accessor(accessor(
            view,
            indices.len(),
            component,
            gj::accessor::Type::Scalar,
        ))?;
        self.geometries.push(GeometryAccessors {
            position,
            normal,
            texcoord,
            indices,
        });
        Ok(GeometryId(last_index(&self.geometries, "geometries")?))
    }

    /// Adds a mesh of one or more primitives and returns its index.
    pub fn add_mesh(&mut self, name: &str, primitives: &[MeshPrimitive]) -> Result<u32> {
        use gj::mesh::Semantic;
        if primitives.is_empty() {
            return Err(bad(&format!("mesh '{name}'"), "no primitives"));
        }
        let mut prims = Vec::with_capacity(primitives.len());
        for p in primitives {
            let g = self
                .geometries
                .get(p.geometry.0 as usize)
                .ok_or_else(|| bad(&format!("mesh '{name}'"), "unknown geometry"))?;
            let mut attributes = BTreeMap::new();
            attributes.insert(Valid(Semantic::Positions), gj::Index::new(g.position));
            if let Some(a) = g.normal {
                attributes.insert(Valid(Semantic::Normals), gj::Index::new(a));
            }
            if let Some(a) = g.texcoord {
                attributes.insert(Valid(Semantic::TexCoords(0)), gj::Index::new(a));
            }
            if let Some(m) = p.material
                && m as usize >= self.root.materials.len()
            {
                return Err(bad(
                    &format!("mesh '{name}'"),
                    format!("unknown material {m}"),
                ));
            }
            prims.push(gj::mesh::Primitive {
                attributes,
                extensions: None,
                extras: None,
                indices: Some(gj::Index::new(g.indices)),
                material: p.material.map(gj::Index::new),
                mode: Valid(gj::mesh::Mode::Triangles),
                targets: None,
            });
        }
        self.root.meshes.push(gj::Mesh {
            extensions: None,
            extras: None,
            name: (!name.is_empty()).then(|| name.to_string()),
            primitives: prims,
            weights: None,
        });
        last_index(&self.root.meshes, "meshes")
    }

    /// Writes the geometries and adds a mesh with one primitive per `(geometry,
    /// material)` pair; returns the mesh index.
    pub fn add_mesh_from(
        &mut self,
        name: &str,
        primitives: &[(Geometry<'_>, Option<u32>)],
    ) -> Result<u32> {
        let mut prims = Vec::with_capacity(primitives.len());
        for (g, material) in primitives {
            prims.push(MeshPrimitive {
                geometry: self.add_geometry(g)?,
                material: *material,
            });
        }
        self.add_mesh(name, &prims)
    }

    /// Adds a material and returns its index.
    pub fn add_material(&mut self, material: &Material) -> Result<u32> {
        use gj::material::{AlphaCutoff, PbrBaseColorFactor, StrengthFactor};
        let what = format!("material '{}'", material.name);
        if !all_finite(&material.base_color)
            || material.base_color.iter().any(|c| !(0.0..=1.0).contains(c))
        {
            return Err(bad(&what, "base colour components must be in [0, 1]"));
        }
        for (field, v) in [
            ("metallic", material.metallic),
            ("roughness", material.roughness),
        ] {
            if !(0.0..=1.0).contains(&v) {
                return Err(bad(&what, format!("{field} must be in [0, 1]")));
            }
        }
        let base_color_texture = match material.base_color_texture {
            Some(t) if t as usize >= self.root.textures.len() => {
                return Err(bad(&what, format!("unknown texture {t}")));
            }
            Some(t) => Some(gj::texture::Info {
                index: gj::Index::new(t),
                tex_coord: 0,
                extensions: None,
                extras: None,
            }),
            None => None,
        };
        let (alpha_mode, alpha_cutoff) = match material.alpha_mode {
            AlphaMode::Opaque => (gj::material::AlphaMode::Opaque, None),
            AlphaMode::Mask { cutoff } => {
                if !(cutoff.is_finite() && cutoff >= 0.0) {
                    return Err(bad(&what, "alpha cutoff must be finite and ≥ 0"));
                }
                (gj::material::AlphaMode::Mask, Some(AlphaCutoff(cutoff)))
            }
            AlphaMode::Blend => (gj::material::AlphaMode::Blend, None),
        };
        let extensions = material.unlit.then(|| {
            self.extensions_used.insert(UNLIT_EXTENSION.into());
            gj::extensions::material::Material {
                unlit: Some(gj::extensions::material::Unlit {}),
                ..Default::default()
            }
        });
        self.root.materials.push(gj::Material {
            alpha_cutoff,
            alpha_mode: Valid(alpha_mode),
            double_sided: material.double_sided,
            name: (!material.name.is_empty()).then(|| material.name.clone()),
            pbr_metallic_roughness: gj::material::PbrMetallicRoughness {
                base_color_factor: PbrBaseColorFactor(material.base_color),
                base_color_texture,
                metallic_factor: StrengthFactor(material.metallic),
                roughness_factor: StrengthFactor(material.roughness),
                ..Default::default()
            },
            extensions,
            ..Default::default()
        });
        last_index(&self.root.materials, "materials")
    }

    /// Adds a PNG image stored in the binary buffer and returns its index. Fails if
    /// the bytes do not start with the PNG signature.
    pub fn add_image_png(&mut self, name: &str, png: &[u8]) -> Result<u32> {
        const SIGNATURE: [u8; 8] = [0x89, b'P', b'N', b'G', b'\r', b'\n', 0x1A, b'\n'];
        if !png.starts_with(&SIGNATURE) {
            return Err(bad(&format!("image '{name}'"), "not a PNG file"));
        }
        self.push_image(name, png, "image/png")
    }

    /// Adds an image of `mime` type whose `bytes` are stored in the binary
    /// buffer and returns its index (the callers check the bytes).
    pub(super) fn push_image(&mut self, name: &str, bytes: &[u8], mime: &str) -> Result<u32> {
        let view = self.push_view(bytes, None)?;
        self.root.images.push(gj::Image {
            buffer_view: Some(gj::Index::new(view)),
            mime_type: Some(gj::image::MimeType(mime.into())),
            name: (!name.is_empty()).then(|| name.to_string()),
            uri: None,
            extensions: None,
            extras: None,
        });
        last_index(&self.root.images, "images")
    }

    /// Adds a sampler and returns its index.
    pub fn add_sampler(&mut self, sampler: &Sampler) -> Result<u32> {
        use gj::texture::{MagFilter as Mag, MinFilter as Min};
        let mag = match sampler.mag_filter {
            MagFilter::Nearest => Mag::Nearest,
            MagFilter::Linear => Mag::Linear,
        };
        let min = match sampler.min_filter {
            MinFilter::Nearest => Min::Nearest,
            MinFilter::Linear => Min::Linear,
            MinFilter::NearestMipmapNearest => Min::NearestMipmapNearest,
            MinFilter::LinearMipmapNearest => Min::LinearMipmapNearest,
            MinFilter::NearestMipmapLinear => Min::NearestMipmapLinear,
            MinFilter::LinearMipmapLinear => Min::LinearMipmapLinear,
        };
        self.root.samplers.push(gj::texture::Sampler {
            mag_filter: Some(Valid(mag)),
            min_filter: Some(Valid(min)),
            name: None,
            wrap_s: Valid(wrapping(sampler.wrap_s)),
            wrap_t: Valid(wrapping(sampler.wrap_t)),
            extensions: None,
            extras: None,
        });
        last_index(&self.root.samplers, "samplers")
    }

    /// Adds a texture of an image (from [`GlbBuilder::add_image_png`]) with an
    /// optional sampler (from [`GlbBuilder::add_sampler`]; `None` means the viewer's
    /// default, repeat with auto filtering) and returns its index.
    pub fn add_texture(&mut self, image: u32, sampler: Option<u32>) -> Result<u32> {
        if image as usize >= self.root.images.len() {
            return Err(bad("texture", format!("unknown image {image}")));
        }
        if let Some(s) = sampler
            && s as usize >= self.root.samplers.len()
        {
            return Err(bad("texture", format!("unknown sampler {s}")));
        }
        self.root.textures.push(gj::Texture {
            name: None,
            sampler: sampler.map(gj::Index::new),
            source: gj::Index::new(image),
            extensions: None,
            extras: None,
        });
        last_index(&self.root.textures, "textures")
    }

    /// Number of meshes added so far.
    pub fn mesh_count(&self) -> usize {
        self.root.meshes.len()
    }

    /// Size of the binary buffer so far, in bytes.
    pub fn bin_len(&self) -> usize {
        self.bin.len()
    }

    /// Completes `root` (this builder's document) with what depends on
    /// everything added: the asset, `extensionsUsed`, the scene and the buffer.
    fn complete(&self, mut root: gj::Root) -> gj::Root {
        root.asset = gj::Asset {
            generator: Some("impostor".into()),
            ..gj::Asset::default()
        };
        root.extensions_used = self.extensions_used.iter().cloned().collect();
        root.extensions_required = self.extensions_required.iter().cloned().collect();
        let roots = self.scene_roots();
        // A scene without nodes is legal glTF but rejected by some readers, so an
        // empty document has no scene at all.
        if !roots.is_empty() {
            root.scene = Some(gj::Index::new(0));
            root.scenes = vec![gj::Scene {
                extensions: None,
                // `gltf-json` keeps extras as raw JSON text.
                extras: self.scene_extras.as_ref().map(|e| {
                    serde_json::value::to_raw_value(e).expect("a JSON value always serializes")
                }),
                name: None,
                nodes: roots.into_iter().map(gj::Index::new).collect(),
            }];
        }
        if !self.bin.is_empty() {
            root.buffers = vec![gj::Buffer {
                byte_length: USize64::from(self.bin.len()),
                name: None,
                uri: None,
                extensions: None,
                extras: None,
            }];
        }
        root
    }

    /// The glTF document as it would be written.
    pub fn document(&self) -> gj::Root {
        self.complete(self.root.clone())
    }

    /// The glTF JSON document as it would be written.
    pub fn json(&self) -> Value {
        serde_json::to_value(self.document()).expect("a glTF document always serializes")
    }

    /// Lays the document out as a GLB file: 12-byte header, JSON chunk padded with
    /// spaces to 4 bytes, BIN chunk (if any data) padded with zeros to 4 bytes. The
    /// document has one scene, the default (`scene: 0`), unless it has no root node.
    ///
    /// # Panics
    ///
    /// If the JSON and binary data together exceed 4 GiB (the binary buffer alone is
    /// limited to 3 GiB by the `add_*` methods).
    pub fn finish(mut self) -> Vec<u8> {
        let root = std::mem::take(&mut self.root);
        let root = self.complete(root);
        let json = serde_json::to_vec(&root).expect("a glTF document always serializes");
        // The buffer is kept padded to 4 bytes by `push_view`.
        let bin = std::mem::take(&mut self.bin);
        let bin_chunk = if bin.is_empty() { 0 } else { 8 + bin.len() };
        let total = 12 + 8 + json.len().next_multiple_of(4) + bin_chunk;
        let total = u32::try_from(total).expect("GLB larger than 4 GiB");
        let glb = gltf::binary::Glb {
            header: gltf::binary::Header {
                magic: *b"glTF",
                version: 2,
                length: total,
            },
            json: json.into(),
            bin: (!bin.is_empty()).then_some(bin.into()),
        };
        glb.to_vec().expect("writing to memory cannot fail")
    }
}

/// Encodes RGBA8 pixels as PNG (fast compression, adaptive filters).
pub fn encode_png(rgba: &[u8], w: u32, h: u32) -> Result<Vec<u8>> {
    use image::ImageEncoder;
    let mut out = Vec::new();
    image::codecs::png::PngEncoder::new_with_quality(
        &mut out,
        image::codecs::png::CompressionType::Fast,
        image::codecs::png::FilterType::Adaptive,
    )
    .write_image(rgba, w, h, image::ExtendedColorType::Rgba8)
    .map_err(|e| crate::Error::Internal(format!("PNG encoding: {e}")))?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::glb::{LOD_EXTENSION, Node};
    use serde_json::json;

    /// A valid 1×1 RGBA PNG.
    const PNG_1X1: [u8; 70] = [
        0x89, 0x50, 0x4E, 0x47, 0x0D, 0x0A, 0x1A, 0x0A, 0x00, 0x00, 0x00, 0x0D, 0x49, 0x48, 0x44,
        0x52, 0x00, 0x00, 0x00, 0x01, 0x00, 0x00, 0x00, 0x01, 0x08, 0x06, 0x00, 0x00, 0x00, 0x1F,
        0x15, 0xC4, 0x89, 0x00, 0x00, 0x00, 0x0D, 0x49, 0x44, 0x41, 0x54, 0x78, 0x9C, 0x63, 0x60,
        0x60, 0x60, 0xF8, 0x0F, 0x00, 0x01, 0x04, 0x01, 0x00, 0x5F, 0xE5, 0xC3, 0x4B, 0x00, 0x00,
        0x00, 0x00, 0x49, 0x45, 0x4E, 0x44, 0xAE, 0x42, 0x60, 0x82,
    ];

    type TriangleData = (Vec<[f32; 3]>, Vec<[f32; 3]>, Vec<[f32; 2]>, Vec<u32>);

    fn triangle() -> TriangleData {
        (
            vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.1]],
            vec![[0.0, 0.0, 1.0]; 3],
            vec![[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]],
            vec![0, 1, 2],
        )
    }

    fn u32_at(b: &[u8], at: usize) -> u32 {
        u32::from_le_bytes(b[at..at + 4].try_into().unwrap())
    }

    #[test]
    fn one_triangle_round_trips() {
        let (p, n, _, i) = triangle();
        let mut b = GlbBuilder::new();
        let mat = b
            .add_material(&Material::new("red", [0.8, 0.1, 0.2, 1.0]))
            .unwrap();
        let mesh = b
            .add_mesh_from(
                "tri",
                &[(
                    Geometry {
                        positions: &p,
                        normals: Some(&n),
                        texcoords: None,
                        indices: &i,
                    },
                    Some(mat),
                )],
            )
            .unwrap();
        let rot = [0.0, (0.25f32).sin(), 0.0, (0.25f32).cos()];
        let node = b
            .add_node(
                Node::new("tri_node")
                    .with_mesh(mesh)
                    .with_trs([1.5, 2.0, -3.25], rot, [2.0, 3.0, 4.0])
                    .with_extras(json!({ "kind": "test", "n": 7 })),
            )
            .unwrap();
        b.set_scene_roots(&[node]).unwrap();
        let bytes = b.finish();

        assert_eq!(&bytes[0..4], b"glTF");
        assert_eq!(u32_at(&bytes, 4), 2);
        assert_eq!(u32_at(&bytes, 8) as usize, bytes.len());

        let g = gltf::Gltf::from_slice(&bytes).unwrap();
        assert_eq!(g.document.default_scene().unwrap().index(), 0);
        let asset = &g.document.as_json().asset;
        assert_eq!(asset.version, "2.0");
        assert_eq!(asset.generator.as_deref(), Some("impostor"));
        let node = g.document.nodes().next().unwrap();
        assert_eq!(node.name(), Some("tri_node"));
        let (t, r, s) = node.transform().decomposed();
        assert_eq!(t, [1.5, 2.0, -3.25]);
        for k in 0..4 {
            assert!((r[k] - rot[k]).abs() < 1e-6);
        }
        assert_eq!(s, [2.0, 3.0, 4.0]);
        let extras: Value = serde_json::from_str(node.extras().as_ref().unwrap().get()).unwrap();
        assert_eq!(extras, json!({ "kind": "test", "n": 7 }));

        let mesh = node.mesh().unwrap();
        assert_eq!(mesh.name(), Some("tri"));
        let prim = mesh.primitives().next().unwrap();
        assert_eq!(prim.mode(), gltf::mesh::Mode::Triangles);
        let material = prim.material();
        assert_eq!(material.name(), Some("red"));
        assert_eq!(
            material.pbr_metallic_roughness().base_color_factor(),
            [0.8, 0.1, 0.2, 1.0]
        );
        assert_eq!(material.alpha_mode(), gltf::material::AlphaMode::Opaque);
        let bb = prim.bounding_box();
        assert_eq!(bb.min, [0.0, 0.0, 0.0]);
        assert_eq!(bb.max, [1.0, 1.0, 0.1]);
        let reader = prim.reader(|buf| match buf.source() {
            gltf::buffer::Source::Bin => g.blob.as_deref(),
            gltf::buffer::Source::Uri(_) => None,
        });
        let pos: Vec<[f32; 3]> = reader.read_positions().unwrap().collect();
        assert_eq!(pos, p);
        let nor: Vec<[f32; 3]> = reader.read_normals().unwrap().collect();
        assert_eq!(nor, n);
        assert!(reader.read_tex_coords(0).is_none());
        let idx: Vec<u32> = reader.read_indices().unwrap().into_u32().collect();
        assert_eq!(idx, i);
    }

    #[test]
    fn index_width_follows_the_largest_index() {
        for (vertices, wide) in [(65535usize, false), (65536, true)] {
            let p: Vec<[f32; 3]> = (0..vertices).map(|k| [k as f32, 0.0, 0.0]).collect();
            let last = vertices as u32 - 1;
            let i = vec![0, 1, last];
            let mut b = GlbBuilder::new();
            let mesh = b
                .add_mesh_from(
                    "m",
                    &[(
                        Geometry {
                            positions: &p,
                            normals: None,
                            texcoords: None,
                            indices: &i,
                        },
                        None,
                    )],
                )
                .unwrap();
            b.add_node(Node::new("n").with_mesh(mesh)).unwrap();
            let bytes = b.finish();
            let g = gltf::Gltf::from_slice(&bytes).unwrap();
            let prim = g
                .document
                .meshes()
                .next()
                .unwrap()
                .primitives()
                .next()
                .unwrap();
            let acc = prim.indices().unwrap();
            assert_eq!(acc.count(), 3);
            assert_eq!(acc.dimensions(), gltf::accessor::Dimensions::Scalar);
            let expected = if wide {
                gltf::accessor::DataType::U32
            } else {
                gltf::accessor::DataType::U16
            };
            assert_eq!(acc.data_type(), expected);
            let reader = prim.reader(|_| g.blob.as_deref());
            let idx: Vec<u32> = reader.read_indices().unwrap().into_u32().collect();
            assert_eq!(idx, i);
        }
    }

    #[test]
    fn every_buffer_view_and_chunk_is_aligned() {
        let (p, n, uv, i) = triangle();
        let mut b = GlbBuilder::new();
        let image = b.add_image_png("atlas", &PNG_1X1).unwrap();
        let sampler = b.add_sampler(&Sampler::linear_clamp()).unwrap();
        let texture = b.add_texture(image, Some(sampler)).unwrap();
        let mut m = Material::new("impostor", [1.0; 4]);
        m.base_color_texture = Some(texture);
        m.alpha_mode = AlphaMode::Mask { cutoff: 0.5 };
        m.double_sided = true;
        m.unlit = true;
        let mat = b.add_material(&m).unwrap();
        let g1 = Geometry {
            positions: &p,
            normals: Some(&n),
            texcoords: Some(&uv),
            indices: &i,
        };
        let id1 = b.add_geometry(&g1).unwrap();
        let id2 = b.add_geometry(&g1).unwrap();
        let mesh = b
            .add_mesh(
                "quad",
                &[
                    MeshPrimitive {
                        geometry: id1,
                        material: Some(mat),
                    },
                    MeshPrimitive {
                        geometry: id2,
                        material: None,
                    },
                ],
            )
            .unwrap();
        let child = b.add_node(Node::new("child").with_mesh(mesh)).unwrap();
        let parent = b
            .add_node(
                Node::new("parent")
                    .with_matrix([
                        1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 5.0, 0.0, 0.0,
                        1.0,
                    ])
                    .with_children(vec![child]),
            )
            .unwrap();
        let other = b.add_node(Node::new("other").with_mesh(mesh)).unwrap();
        b.add_child(parent, other).unwrap();
        let bytes = b.finish();

        let json_len = u32_at(&bytes, 12) as usize;
        assert_eq!(json_len % 4, 0);
        assert_eq!(&bytes[16..20], b"JSON");
        let bin_at = 20 + json_len;
        let bin_len = u32_at(&bytes, bin_at) as usize;
        assert_eq!(bin_len % 4, 0);
        assert_eq!(&bytes[bin_at + 4..bin_at + 8], b"BIN\0");
        assert_eq!(bin_at + 8 + bin_len, bytes.len());

        let g = gltf::Gltf::from_slice(&bytes).unwrap();
        for view in g.document.views() {
            assert_eq!(view.offset() % 4, 0, "view {}", view.index());
            assert!(view.offset() + view.length() <= bin_len);
        }
        let img = g.document.images().next().unwrap();
        match img.source() {
            gltf::image::Source::View { view, mime_type } => {
                assert_eq!(mime_type, "image/png");
                let blob = g.blob.as_deref().unwrap();
                assert_eq!(&blob[view.offset()..view.offset() + view.length()], PNG_1X1);
            }
            gltf::image::Source::Uri { .. } => panic!("image should live in the buffer"),
        }
        let mat = g.document.materials().next().unwrap();
        assert_eq!(mat.alpha_mode(), gltf::material::AlphaMode::Mask);
        assert_eq!(mat.alpha_cutoff(), Some(0.5));
        assert!(mat.double_sided());
        assert!(mat.unlit());
        let info = mat.pbr_metallic_roughness().base_color_texture().unwrap();
        assert_eq!(info.texture().source().index(), image as usize);
        assert_eq!(
            g.document.extensions_used().collect::<Vec<_>>(),
            vec![UNLIT_EXTENSION]
        );
        let scene = g.document.default_scene().unwrap();
        let roots: Vec<usize> = scene.nodes().map(|n| n.index()).collect();
        assert_eq!(roots, vec![parent as usize]);
        let kids: Vec<usize> = g
            .document
            .nodes()
            .nth(parent as usize)
            .unwrap()
            .children()
            .map(|n| n.index())
            .collect();
        assert_eq!(kids, vec![child as usize, other as usize]);
    }

    #[test]
    fn lod_levels_are_listed_and_are_not_roots() {
        let (p, n, _, i) = triangle();
        let mut b = GlbBuilder::new();
        let mut m = Material::new("unlit", [1.0; 4]);
        m.unlit = true;
        let mat = b.add_material(&m).unwrap();
        let g = Geometry {
            positions: &p,
            normals: Some(&n),
            texcoords: None,
            indices: &i,
        };
        let mesh = b.add_mesh_from("quad", &[(g, Some(mat))]).unwrap();
        let coarse = b.add_mesh_from("tri", &[(g, None)]).unwrap();
        let l1 = b.add_node(Node::new("l1").with_mesh(coarse)).unwrap();
        let l2 = b.add_node(Node::new("l2").with_mesh(coarse)).unwrap();
        let base = b
            .add_node(
                Node::new("base")
                    .with_mesh(mesh)
                    .with_extension("MSFT_lod", json!({ "ids": [l1, l2] }))
                    .with_extras(json!({ "MSFT_screencoverage": [0.5, 0.1, 0.0] })),
            )
            .unwrap();
        let plain = b.add_node(Node::new("plain").with_mesh(mesh)).unwrap();
        // Bad MSFT_lod values: later or unknown nodes, repeats, no ids.
        for ids in [json!([l1, 99]), json!([l1, l1]), json!([]), json!("x")] {
            let node = Node::new("x").with_extension("MSFT_lod", json!({ "ids": ids }));
            let e = b.add_node(node).unwrap_err().to_string();
            assert!(e.contains("node 'x'") && e.contains("MSFT_lod"), "{e}");
        }
        let e = b
            .add_node(Node::new("y").with_extension("", json!({})))
            .unwrap_err();
        assert!(e.to_string().contains("empty"), "{e}");
        let bytes = b.finish();

        let g = gltf::Gltf::from_slice(&bytes).unwrap();
        assert_eq!(
            g.document.extensions_used().collect::<Vec<_>>(),
            vec![UNLIT_EXTENSION, LOD_EXTENSION]
        );
        // Default roots: parentless nodes except the levels.
        let scene = g.document.default_scene().unwrap();
        let roots: Vec<u32> = scene.nodes().map(|n| n.index() as u32).collect();
        assert_eq!(roots, vec![base, plain]);
        let node = g.document.nodes().nth(base as usize).unwrap();
        assert_eq!(
            node.extensions().unwrap()["MSFT_lod"],
            json!({ "ids": [l1, l2] })
        );
        // The scene loader reads the chain back.
        let loaded = crate::scene::gltf_load::load_scene_bytes(&bytes, "lod.glb").unwrap();
        assert_eq!(loaded.objects.len(), 2);
        let levels: Vec<(f64, u64)> = loaded.objects[0]
            .lods
            .iter()
            .map(|l| (l.min_coverage, l.triangles))
            .collect();
        assert_eq!(levels, [(0.5, 1), (0.1, 1), (0.0, 1)]);
    }

    #[test]
    fn empty_document_is_valid() {
        let bytes = GlbBuilder::new().finish();
        assert_eq!(bytes.len() % 4, 0);
        let g = gltf::Gltf::from_slice(&bytes).unwrap();
        assert_eq!(g.document.nodes().count(), 0);
        assert!(g.document.default_scene().is_none());
        assert!(g.blob.is_none());
    }

    #[test]
    fn bad_input_is_rejected() {
        let (p, _, _, _) = triangle();
        let mut b = GlbBuilder::new();
        let geom = |indices: &'static [u32]| Geometry {
            positions: &[[0.0; 3]; 3],
            normals: None,
            texcoords: None,
            indices,
        };
        assert!(b.add_geometry(&geom(&[0, 1, 3])).is_err());
        assert!(b.add_geometry(&geom(&[0, 1])).is_err());
        assert!(b.add_geometry(&geom(&[])).is_err());
        let short_normals = [[0.0, 0.0, 1.0]];
        assert!(
            b.add_geometry(&Geometry {
                positions: &p,
                normals: Some(&short_normals),
                texcoords: None,
                indices: &[0, 1, 2],
            })
            .is_err()
        );
        let nan = [[f32::NAN, 0.0, 0.0], [0.0; 3], [0.0; 3]];
        assert!(
            b.add_geometry(&Geometry {
                positions: &nan,
                normals: None,
                texcoords: None,
                indices: &[0, 1, 2],
            })
            .is_err()
        );
        assert!(b.add_mesh("empty", &[]).is_err());
        assert!(b.add_image_png("x", b"not a png").is_err());
        assert!(b.add_texture(0, None).is_err());
        assert!(b.add_node(Node::new("n").with_mesh(0)).is_err());
        let a = b.add_node(Node::new("a")).unwrap();
        let c = b.add_node(Node::new("c").with_children(vec![a])).unwrap();
        assert!(b.add_node(Node::new("d").with_children(vec![a])).is_err());
        assert!(b.add_child(a, c).is_err(), "cycle");
        assert!(b.add_child(c, c).is_err(), "self");
        assert!(b.set_scene_roots(&[a]).is_err(), "root with a parent");
        b.set_scene_roots(&[c]).unwrap();
        let e = b.add_node(Node::new("e")).unwrap();
        assert!(b.add_child(e, c).is_err(), "root becomes a child");
        assert!(
            b.add_mesh_from("bad", &[(geom(&[0, 1, 2]), Some(3))])
                .is_err()
        );
        let err = b.add_geometry(&geom(&[0, 1, 9])).unwrap_err();
        assert!(err.is_bad_input());
    }
}
