//! A small GLB (binary glTF 2.0) writer.
//!
//! [`GlbBuilder`] accumulates one binary buffer (the GLB `BIN` chunk) and the glTF
//! JSON document, then [`GlbBuilder::finish`] lays both out as a GLB file:
//!
//! - geometry ([`GlbBuilder::add_geometry`]) becomes accessors over 4-byte aligned
//!   buffer views: `POSITION` (with the `min`/`max` the specification requires),
//!   optional `NORMAL` and `TEXCOORD_0`, and triangle-list indices stored as
//!   `UNSIGNED_SHORT` when every index fits (≤ 65534, so that the primitive-restart
//!   value 65535 never appears) and as `UNSIGNED_INT` otherwise;
//! - meshes ([`GlbBuilder::add_mesh`]) are lists of primitives, each a geometry and a
//!   material; several meshes may share one geometry (colour variants cost no bytes);
//! - materials are metallic-roughness with a base colour factor, an optional base
//!   colour texture, an alpha mode (opaque, mask with cutoff, blend), double-sidedness
//!   and optionally `KHR_materials_unlit` (for baked impostors);
//! - PNG images live in buffer views, textures pair an image with a sampler;
//! - nodes carry a name, an optional mesh, a TRS or matrix transform, children,
//!   optional `extras` and `extensions`; the node graph is kept a forest by
//!   construction. Every extension used (`KHR_materials_unlit`, node
//!   extensions such as `MSFT_lod`) is listed in `extensionsUsed`, sorted;
//! - levels of detail (`MSFT_lod`): the coarser levels are nodes added before the
//!   node that names them in `MSFT_lod.ids`; they are neither scene roots nor
//!   children (the default scene roots leave them out).
//!
//! Nothing is deduplicated; every call writes what it is given.

use serde_json::{Map, Value, json};

use crate::{Error, Result};

const GLB_MAGIC: u32 = 0x4654_6C67; // "glTF"
const CHUNK_JSON: u32 = 0x4E4F_534A; // "JSON"
const CHUNK_BIN: u32 = 0x004E_4942; // "BIN\0"

const ARRAY_BUFFER: u32 = 34962;
const ELEMENT_ARRAY_BUFFER: u32 = 34963;

const COMPONENT_UNSIGNED_SHORT: u32 = 5123;
const COMPONENT_UNSIGNED_INT: u32 = 5125;
const COMPONENT_FLOAT: u32 = 5126;

/// The largest index stored as `UNSIGNED_SHORT` (65535 is the primitive-restart value).
pub const MAX_U16_INDEX: u32 = 65534;

/// The largest binary buffer the writer accepts (the GLB length field is 32 bits and
/// the JSON chunk needs room too).
const MAX_BIN_BYTES: usize = 3 << 30;

const UNLIT_EXTENSION: &str = "KHR_materials_unlit";
const LOD_EXTENSION: &str = "MSFT_lod";

/// How a material's alpha channel is interpreted.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum AlphaMode {
    /// Alpha is ignored.
    #[default]
    Opaque,
    /// Alpha-tested: fragments with alpha below `cutoff` are discarded.
    Mask {
        /// The alpha cutoff in `[0, 1]` (glTF default 0.5).
        cutoff: f32,
    },
    /// Alpha-blended.
    Blend,
}

/// A metallic-roughness material.
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    /// The material's name.
    pub name: String,
    /// Linear RGBA base colour factor, each in `[0, 1]`.
    pub base_color: [f32; 4],
    /// Index of the base colour texture (from [`GlbBuilder::add_texture`]), if any;
    /// it uses `TEXCOORD_0`.
    pub base_color_texture: Option<u32>,
    /// Metallic factor in `[0, 1]`.
    pub metallic: f32,
    /// Roughness factor in `[0, 1]`.
    pub roughness: f32,
    /// Alpha mode.
    pub alpha_mode: AlphaMode,
    /// Whether back faces are rendered too (and lit with the flipped normal).
    pub double_sided: bool,
    /// Whether the material is unlit (`KHR_materials_unlit`).
    pub unlit: bool,
}

impl Material {
    /// An opaque, single-sided, non-metallic, rough material of one colour.
    pub fn new(name: impl Into<String>, base_color: [f32; 4]) -> Self {
        Material {
            name: name.into(),
            base_color,
            base_color_texture: None,
            metallic: 0.0,
            roughness: 0.9,
            alpha_mode: AlphaMode::Opaque,
            double_sided: false,
            unlit: false,
        }
    }
}

/// Texture magnification filter.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum MagFilter {
    /// `NEAREST`.
    Nearest,
    /// `LINEAR`.
    #[default]
    Linear,
}

/// Texture minification filter.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum MinFilter {
    /// `NEAREST`.
    Nearest,
    /// `LINEAR`.
    Linear,
    /// `NEAREST_MIPMAP_NEAREST`.
    NearestMipmapNearest,
    /// `LINEAR_MIPMAP_NEAREST`.
    LinearMipmapNearest,
    /// `NEAREST_MIPMAP_LINEAR`.
    NearestMipmapLinear,
    /// `LINEAR_MIPMAP_LINEAR`.
    #[default]
    LinearMipmapLinear,
}

/// Texture coordinate wrapping.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Wrap {
    /// `CLAMP_TO_EDGE`.
    ClampToEdge,
    /// `MIRRORED_REPEAT`.
    MirroredRepeat,
    /// `REPEAT`.
    #[default]
    Repeat,
}

/// A texture sampler.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Sampler {
    /// Magnification filter.
    pub mag_filter: MagFilter,
    /// Minification filter.
    pub min_filter: MinFilter,
    /// Wrapping of the u coordinate.
    pub wrap_s: Wrap,
    /// Wrapping of the v coordinate.
    pub wrap_t: Wrap,
}

impl Sampler {
    /// Linear filtering without mipmaps, clamped to the edge: suits impostor atlases.
    pub fn linear_clamp() -> Self {
        Sampler {
            mag_filter: MagFilter::Linear,
            min_filter: MinFilter::Linear,
            wrap_s: Wrap::ClampToEdge,
            wrap_t: Wrap::ClampToEdge,
        }
    }
}

/// Vertex and index data of one triangle-list primitive.
#[derive(Clone, Copy, Debug)]
pub struct Geometry<'a> {
    /// Vertex positions (at least one).
    pub positions: &'a [[f32; 3]],
    /// Unit vertex normals, one per position.
    pub normals: Option<&'a [[f32; 3]]>,
    /// Texture coordinates (`TEXCOORD_0`), one per position.
    pub texcoords: Option<&'a [[f32; 2]]>,
    /// Triangle-list indices into `positions` (a non-zero multiple of 3).
    pub indices: &'a [u32],
}

/// Handle to geometry written by [`GlbBuilder::add_geometry`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct GeometryId(u32);

/// One primitive of a mesh: a geometry drawn with a material.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MeshPrimitive {
    /// The geometry.
    pub geometry: GeometryId,
    /// Material index (from [`GlbBuilder::add_material`]); `None` uses the glTF
    /// default material.
    pub material: Option<u32>,
}

/// A node's local transform.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum Transform {
    /// No transform.
    #[default]
    Identity,
    /// Translation, rotation (unit quaternion `[x, y, z, w]`), scale: `T · R · S`.
    Trs {
        /// Translation.
        translation: [f32; 3],
        /// Rotation as a unit quaternion `[x, y, z, w]`.
        rotation: [f32; 4],
        /// Scale.
        scale: [f32; 3],
    },
    /// A column-major 4×4 affine matrix (last row `0 0 0 1`), decomposable into TRS.
    Matrix([f32; 16]),
}

/// A scene node.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Node {
    /// The node's name (omitted when empty).
    pub name: String,
    /// Mesh index (from [`GlbBuilder::add_mesh`]), if the node carries a mesh.
    pub mesh: Option<u32>,
    /// Local transform.
    pub transform: Transform,
    /// Child node indices: nodes added earlier that have no parent yet.
    pub children: Vec<u32>,
    /// Application-specific data written as the node's `extras`.
    pub extras: Option<Value>,
    /// The node's `extensions` (omitted when empty); every key is listed in
    /// `extensionsUsed`. `MSFT_lod` must be `{"ids": [...]}` naming distinct
    /// nodes added earlier.
    pub extensions: Map<String, Value>,
}

impl Node {
    /// A node with a name, no mesh, identity transform, no children.
    pub fn new(name: impl Into<String>) -> Self {
        Node {
            name: name.into(),
            ..Node::default()
        }
    }

    /// The node with a mesh.
    pub fn with_mesh(mut self, mesh: u32) -> Self {
        self.mesh = Some(mesh);
        self
    }

    /// The node with a TRS transform.
    pub fn with_trs(mut self, translation: [f32; 3], rotation: [f32; 4], scale: [f32; 3]) -> Self {
        self.transform = Transform::Trs {
            translation,
            rotation,
            scale,
        };
        self
    }

    /// The node with a column-major matrix transform.
    pub fn with_matrix(mut self, matrix: [f32; 16]) -> Self {
        self.transform = Transform::Matrix(matrix);
        self
    }

    /// The node with children.
    pub fn with_children(mut self, children: Vec<u32>) -> Self {
        self.children = children;
        self
    }

    /// The node with `extras`.
    pub fn with_extras(mut self, extras: Value) -> Self {
        self.extras = Some(extras);
        self
    }

    /// The node with extension `name` set to `value`.
    pub fn with_extension(mut self, name: impl Into<String>, value: Value) -> Self {
        self.extensions.insert(name.into(), value);
        self
    }
}

/// Accessor indices of one written geometry.
#[derive(Clone, Copy, Debug)]
struct GeometryAccessors {
    position: u32,
    normal: Option<u32>,
    texcoord: Option<u32>,
    indices: u32,
}

/// Accumulates a glTF document and its binary buffer; [`GlbBuilder::finish`] writes
/// the GLB. Indices returned by the `add_*` methods are glTF array indices.
#[derive(Debug, Default)]
pub struct GlbBuilder {
    bin: Vec<u8>,
    buffer_views: Vec<Value>,
    accessors: Vec<Value>,
    geometries: Vec<GeometryAccessors>,
    meshes: Vec<Value>,
    materials: Vec<Value>,
    images: Vec<Value>,
    samplers: Vec<Value>,
    textures: Vec<Value>,
    nodes: Vec<Value>,
    parent: Vec<Option<u32>>,
    roots: Option<Vec<u32>>,
    /// Nodes named in some node's `MSFT_lod.ids`.
    lod_level: Vec<bool>,
    /// Extensions used so far.
    extensions_used: std::collections::BTreeSet<String>,
}

fn bad(what: &str, message: impl Into<String>) -> Error {
    Error::bad(format!("GLB writer: {what}"), message)
}

/// A JSON number that reads back as exactly `x` in `f32` and prints in its shortest
/// form (`0.1`, not `0.10000000149011612`).
fn jf(x: f32) -> Value {
    let short: f64 = x.to_string().parse().unwrap_or(f64::from(x));
    Value::from(short)
}

/// A JSON number equal to `x` exactly (for accessor bounds, which must match the
/// buffer data exactly).
fn jf_exact(x: f32) -> Value {
    Value::from(f64::from(x))
}

fn jf_array(xs: &[f32]) -> Value {
    Value::Array(xs.iter().map(|&x| jf(x)).collect())
}

fn all_finite(xs: &[f32]) -> bool {
    xs.iter().all(|x| x.is_finite())
}

fn to_u32(n: usize, what: &str) -> Result<u32> {
    u32::try_from(n).map_err(|_| bad(what, "too many elements"))
}

impl GlbBuilder {
    /// An empty document.
    pub fn new() -> Self {
        GlbBuilder::default()
    }

    /// Appends `bytes` as a new buffer view starting at a 4-byte aligned offset and
    /// pads the buffer back to a multiple of 4 with zeros.
    fn push_view(&mut self, bytes: &[u8], target: Option<u32>) -> Result<u32> {
        if self.bin.len() + bytes.len() + 3 > MAX_BIN_BYTES {
            return Err(bad("buffer", "the binary buffer would exceed 3 GiB"));
        }
        debug_assert_eq!(self.bin.len() % 4, 0);
        let offset = self.bin.len();
        self.bin.extend_from_slice(bytes);
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        let mut view = Map::new();
        view.insert("buffer".into(), json!(0));
        view.insert("byteOffset".into(), json!(offset));
        view.insert("byteLength".into(), json!(bytes.len()));
        if let Some(t) = target {
            view.insert("target".into(), json!(t));
        }
        self.buffer_views.push(Value::Object(view));
        to_u32(self.buffer_views.len() - 1, "bufferViews")
    }

    fn push_accessor(&mut self, accessor: Value) -> Result<u32> {
        self.accessors.push(accessor);
        to_u32(self.accessors.len() - 1, "accessors")
    }

    fn push_vec3_accessor(&mut self, data: &[[f32; 3]], with_bounds: bool) -> Result<u32> {
        let mut bytes = Vec::with_capacity(data.len() * 12);
        for v in data {
            for c in v {
                bytes.extend_from_slice(&c.to_le_bytes());
            }
        }
        let view = self.push_view(&bytes, Some(ARRAY_BUFFER))?;
        let mut acc = Map::new();
        acc.insert("bufferView".into(), json!(view));
        acc.insert("componentType".into(), json!(COMPONENT_FLOAT));
        acc.insert("count".into(), json!(data.len()));
        acc.insert("type".into(), json!("VEC3"));
        if with_bounds {
            let mut lo = [f32::INFINITY; 3];
            let mut hi = [f32::NEG_INFINITY; 3];
            for v in data {
                for k in 0..3 {
                    lo[k] = lo[k].min(v[k]);
                    hi[k] = hi[k].max(v[k]);
                }
            }
            acc.insert(
                "min".into(),
                Value::Array(lo.iter().map(|&x| jf_exact(x)).collect()),
            );
            acc.insert(
                "max".into(),
                Value::Array(hi.iter().map(|&x| jf_exact(x)).collect()),
            );
        }
        self.push_accessor(Value::Object(acc))
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
                let view = self.push_view(&bytes, Some(ARRAY_BUFFER))?;
                Some(self.push_accessor(json!({
                    "bufferView": view,
                    "componentType": COMPONENT_FLOAT,
                    "count": uvs.len(),
                    "type": "VEC2",
                }))?)
            }
            None => None,
        };
        let (bytes, component) = if max_index <= MAX_U16_INDEX {
            let mut bytes = Vec::with_capacity(indices.len() * 2);
            for &i in indices {
                // Lossless: every index is at most MAX_U16_INDEX.
                bytes.extend_from_slice(&(i as u16).to_le_bytes());
            }
            (bytes, COMPONENT_UNSIGNED_SHORT)
        } else {
            let mut bytes = Vec::with_capacity(indices.len() * 4);
            for &i in indices {
                bytes.extend_from_slice(&i.to_le_bytes());
            }
            (bytes, COMPONENT_UNSIGNED_INT)
        };
        let view = self.push_view(&bytes, Some(ELEMENT_ARRAY_BUFFER))?;
        let indices = self.push_accessor(json!({
            "bufferView": view,
            "componentType": component,
            "count": indices.len(),
            "type": "SCALAR",
        }))?;
        self.geometries.push(GeometryAccessors {
            position,
            normal,
            texcoord,
            indices,
        });
        Ok(GeometryId(to_u32(self.geometries.len() - 1, "geometries")?))
    }

    /// Adds a mesh of one or more primitives and returns its index.
    pub fn add_mesh(&mut self, name: &str, primitives: &[MeshPrimitive]) -> Result<u32> {
        if primitives.is_empty() {
            return Err(bad(&format!("mesh '{name}'"), "no primitives"));
        }
        let mut prims = Vec::with_capacity(primitives.len());
        for p in primitives {
            let g = self
                .geometries
                .get(p.geometry.0 as usize)
                .ok_or_else(|| bad(&format!("mesh '{name}'"), "unknown geometry"))?;
            let mut attributes = Map::new();
            attributes.insert("POSITION".into(), json!(g.position));
            if let Some(a) = g.normal {
                attributes.insert("NORMAL".into(), json!(a));
            }
            if let Some(a) = g.texcoord {
                attributes.insert("TEXCOORD_0".into(), json!(a));
            }
            let mut prim = Map::new();
            prim.insert("attributes".into(), Value::Object(attributes));
            prim.insert("indices".into(), json!(g.indices));
            if let Some(m) = p.material {
                if m as usize >= self.materials.len() {
                    return Err(bad(
                        &format!("mesh '{name}'"),
                        format!("unknown material {m}"),
                    ));
                }
                prim.insert("material".into(), json!(m));
            }
            prims.push(Value::Object(prim));
        }
        let mut mesh = Map::new();
        if !name.is_empty() {
            mesh.insert("name".into(), json!(name));
        }
        mesh.insert("primitives".into(), Value::Array(prims));
        self.meshes.push(Value::Object(mesh));
        to_u32(self.meshes.len() - 1, "meshes")
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
        let mut pbr = Map::new();
        pbr.insert("baseColorFactor".into(), jf_array(&material.base_color));
        if let Some(t) = material.base_color_texture {
            if t as usize >= self.textures.len() {
                return Err(bad(&what, format!("unknown texture {t}")));
            }
            pbr.insert("baseColorTexture".into(), json!({ "index": t }));
        }
        pbr.insert("metallicFactor".into(), jf(material.metallic));
        pbr.insert("roughnessFactor".into(), jf(material.roughness));
        let mut m = Map::new();
        if !material.name.is_empty() {
            m.insert("name".into(), json!(material.name));
        }
        m.insert("pbrMetallicRoughness".into(), Value::Object(pbr));
        match material.alpha_mode {
            AlphaMode::Opaque => {}
            AlphaMode::Mask { cutoff } => {
                if !(cutoff.is_finite() && cutoff >= 0.0) {
                    return Err(bad(&what, "alpha cutoff must be finite and ≥ 0"));
                }
                m.insert("alphaMode".into(), json!("MASK"));
                m.insert("alphaCutoff".into(), jf(cutoff));
            }
            AlphaMode::Blend => {
                m.insert("alphaMode".into(), json!("BLEND"));
            }
        }
        if material.double_sided {
            m.insert("doubleSided".into(), json!(true));
        }
        if material.unlit {
            m.insert("extensions".into(), json!({ UNLIT_EXTENSION: {} }));
            self.extensions_used.insert(UNLIT_EXTENSION.into());
        }
        self.materials.push(Value::Object(m));
        to_u32(self.materials.len() - 1, "materials")
    }

    /// Adds a PNG image stored in the binary buffer and returns its index. Fails if
    /// the bytes do not start with the PNG signature.
    pub fn add_image_png(&mut self, name: &str, png: &[u8]) -> Result<u32> {
        const SIGNATURE: [u8; 8] = [0x89, b'P', b'N', b'G', b'\r', b'\n', 0x1A, b'\n'];
        if !png.starts_with(&SIGNATURE) {
            return Err(bad(&format!("image '{name}'"), "not a PNG file"));
        }
        let view = self.push_view(png, None)?;
        let mut image = Map::new();
        if !name.is_empty() {
            image.insert("name".into(), json!(name));
        }
        image.insert("bufferView".into(), json!(view));
        image.insert("mimeType".into(), json!("image/png"));
        self.images.push(Value::Object(image));
        to_u32(self.images.len() - 1, "images")
    }

    /// Adds a sampler and returns its index.
    pub fn add_sampler(&mut self, sampler: &Sampler) -> Result<u32> {
        let mag = match sampler.mag_filter {
            MagFilter::Nearest => 9728,
            MagFilter::Linear => 9729,
        };
        let min = match sampler.min_filter {
            MinFilter::Nearest => 9728,
            MinFilter::Linear => 9729,
            MinFilter::NearestMipmapNearest => 9984,
            MinFilter::LinearMipmapNearest => 9985,
            MinFilter::NearestMipmapLinear => 9986,
            MinFilter::LinearMipmapLinear => 9987,
        };
        let wrap = |w: Wrap| match w {
            Wrap::ClampToEdge => 33071,
            Wrap::MirroredRepeat => 33648,
            Wrap::Repeat => 10497,
        };
        self.samplers.push(json!({
            "magFilter": mag,
            "minFilter": min,
            "wrapS": wrap(sampler.wrap_s),
            "wrapT": wrap(sampler.wrap_t),
        }));
        to_u32(self.samplers.len() - 1, "samplers")
    }

    /// Adds a texture of an image (from [`GlbBuilder::add_image_png`]) with an
    /// optional sampler (from [`GlbBuilder::add_sampler`]; `None` means the viewer's
    /// default, repeat with auto filtering) and returns its index.
    pub fn add_texture(&mut self, image: u32, sampler: Option<u32>) -> Result<u32> {
        if image as usize >= self.images.len() {
            return Err(bad("texture", format!("unknown image {image}")));
        }
        let mut t = Map::new();
        t.insert("source".into(), json!(image));
        if let Some(s) = sampler {
            if s as usize >= self.samplers.len() {
                return Err(bad("texture", format!("unknown sampler {s}")));
            }
            t.insert("sampler".into(), json!(s));
        }
        self.textures.push(Value::Object(t));
        to_u32(self.textures.len() - 1, "textures")
    }

    /// Adds a node and returns its index. Its mesh must exist; its children must be
    /// existing, distinct nodes without a parent (so the node graph stays a forest).
    /// The rotation of a TRS transform is normalised.
    pub fn add_node(&mut self, node: Node) -> Result<u32> {
        let what = format!("node '{}'", node.name);
        let index = to_u32(self.nodes.len(), "nodes")?;
        let mut n = Map::new();
        if !node.name.is_empty() {
            n.insert("name".into(), json!(node.name));
        }
        if let Some(m) = node.mesh {
            if m as usize >= self.meshes.len() {
                return Err(bad(&what, format!("unknown mesh {m}")));
            }
            n.insert("mesh".into(), json!(m));
        }
        match node.transform {
            Transform::Identity => {}
            Transform::Trs {
                translation,
                rotation,
                scale,
            } => {
                if !all_finite(&translation) || !all_finite(&rotation) || !all_finite(&scale) {
                    return Err(bad(&what, "transform is not finite"));
                }
                let len = rotation.iter().map(|c| c * c).sum::<f32>().sqrt();
                if len < 1e-6 {
                    return Err(bad(&what, "rotation quaternion has zero length"));
                }
                let rotation = rotation.map(|c| c / len);
                if translation != [0.0; 3] {
                    n.insert("translation".into(), jf_array(&translation));
                }
                if rotation != [0.0, 0.0, 0.0, 1.0] {
                    n.insert("rotation".into(), jf_array(&rotation));
                }
                if scale != [1.0; 3] {
                    n.insert("scale".into(), jf_array(&scale));
                }
            }
            Transform::Matrix(m) => {
                if !all_finite(&m) {
                    return Err(bad(&what, "matrix is not finite"));
                }
                if m[3] != 0.0 || m[7] != 0.0 || m[11] != 0.0 || m[15] != 1.0 {
                    return Err(bad(
                        &what,
                        "matrix is not affine (last row must be 0 0 0 1)",
                    ));
                }
                n.insert("matrix".into(), jf_array(&m));
            }
        }
        let mut levels = Vec::new();
        for (name, value) in &node.extensions {
            if name.is_empty() {
                return Err(bad(&what, "an extension name is empty"));
            }
            if name == LOD_EXTENSION {
                levels = self.lod_ids(value, index, &what)?;
            }
        }
        if !node.children.is_empty() {
            for (k, &c) in node.children.iter().enumerate() {
                if c >= index {
                    return Err(bad(&what, format!("unknown child {c}")));
                }
                if self.parent[c as usize].is_some() || node.children[..k].contains(&c) {
                    return Err(bad(&what, format!("child {c} already has a parent")));
                }
                if self.roots.as_ref().is_some_and(|r| r.contains(&c)) {
                    return Err(bad(&what, format!("child {c} is a scene root")));
                }
            }
            for &c in &node.children {
                self.parent[c as usize] = Some(index);
            }
            n.insert("children".into(), json!(node.children));
        }
        self.extensions_used.extend(node.extensions.keys().cloned());
        if !node.extensions.is_empty() {
            n.insert("extensions".into(), Value::Object(node.extensions));
        }
        if let Some(extras) = node.extras {
            n.insert("extras".into(), extras);
        }
        for l in levels {
            self.lod_level[l as usize] = true;
        }
        self.nodes.push(Value::Object(n));
        self.parent.push(None);
        self.lod_level.push(false);
        Ok(index)
    }

    /// Checks an `MSFT_lod` value of node `index`: `{"ids": [...]}` naming
    /// distinct nodes added earlier; returns them.
    fn lod_ids(&self, value: &Value, index: u32, what: &str) -> Result<Vec<u32>> {
        let ids = value
            .get("ids")
            .and_then(Value::as_array)
            .filter(|ids| !ids.is_empty())
            .ok_or_else(|| bad(what, "MSFT_lod needs a non-empty `ids` array"))?;
        let mut out: Vec<u32> = Vec::with_capacity(ids.len());
        for id in ids {
            let id = id
                .as_u64()
                .and_then(|i| u32::try_from(i).ok())
                .filter(|&i| i < index)
                .ok_or_else(|| {
                    bad(
                        what,
                        format!("MSFT_lod id {id} is not a node added before this one"),
                    )
                })?;
            if out.contains(&id) {
                return Err(bad(what, format!("MSFT_lod names node {id} twice")));
            }
            out.push(id);
        }
        Ok(out)
    }

    /// Makes `child` (which must have no parent and not be a scene root or an ancestor
    /// of `parent`) a child of `parent`.
    pub fn add_child(&mut self, parent: u32, child: u32) -> Result<()> {
        let n = self.nodes.len();
        if parent as usize >= n || child as usize >= n {
            return Err(bad(
                "add_child",
                format!("unknown node {parent} or {child}"),
            ));
        }
        if self.parent[child as usize].is_some() {
            return Err(bad(
                "add_child",
                format!("node {child} already has a parent"),
            ));
        }
        if self.roots.as_ref().is_some_and(|r| r.contains(&child)) {
            return Err(bad("add_child", format!("node {child} is a scene root")));
        }
        let mut a = Some(parent);
        while let Some(x) = a {
            if x == child {
                return Err(bad(
                    "add_child",
                    format!("node {child} is an ancestor of {parent}"),
                ));
            }
            a = self.parent[x as usize];
        }
        self.parent[child as usize] = Some(parent);
        let node = self.nodes[parent as usize]
            .as_object_mut()
            .ok_or_else(|| Error::Internal("GLB node is not an object".into()))?;
        match node.get_mut("children").and_then(Value::as_array_mut) {
            Some(children) => children.push(json!(child)),
            None => {
                node.insert("children".into(), json!([child]));
            }
        }
        Ok(())
    }

    /// Sets the root nodes of the (single) scene: existing, distinct nodes without a
    /// parent. Without this call the roots are all parentless nodes in index order,
    /// except levels of detail (nodes named in some `MSFT_lod.ids`). A
    /// document without any root node is written without a scene.
    pub fn set_scene_roots(&mut self, roots: &[u32]) -> Result<()> {
        for (k, &r) in roots.iter().enumerate() {
            if r as usize >= self.nodes.len() {
                return Err(bad("scene", format!("unknown node {r}")));
            }
            if self.parent[r as usize].is_some() {
                return Err(bad("scene", format!("node {r} has a parent")));
            }
            if roots[..k].contains(&r) {
                return Err(bad("scene", format!("node {r} listed twice")));
            }
        }
        self.roots = Some(roots.to_vec());
        Ok(())
    }

    /// Number of nodes added so far.
    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }

    /// Number of meshes added so far.
    pub fn mesh_count(&self) -> usize {
        self.meshes.len()
    }

    /// Size of the binary buffer so far, in bytes.
    pub fn bin_len(&self) -> usize {
        self.bin.len()
    }

    /// The glTF JSON document as it would be written.
    pub fn json(&self) -> Value {
        let mut root = Map::new();
        root.insert(
            "asset".into(),
            json!({ "version": "2.0", "generator": "impostor" }),
        );
        if !self.extensions_used.is_empty() {
            root.insert("extensionsUsed".into(), json!(self.extensions_used));
        }
        let roots: Vec<u32> = match &self.roots {
            Some(r) => r.clone(),
            None => (0..self.nodes.len() as u32)
                .filter(|&i| self.parent[i as usize].is_none() && !self.lod_level[i as usize])
                .collect(),
        };
        // A scene without nodes is legal glTF but rejected by some readers, so an
        // empty document has no scene at all.
        if !roots.is_empty() {
            root.insert("scene".into(), json!(0));
            root.insert("scenes".into(), json!([{ "nodes": roots }]));
        }
        let arrays = [
            ("nodes", &self.nodes),
            ("meshes", &self.meshes),
            ("materials", &self.materials),
            ("textures", &self.textures),
            ("images", &self.images),
            ("samplers", &self.samplers),
            ("accessors", &self.accessors),
            ("bufferViews", &self.buffer_views),
        ];
        for (key, items) in arrays {
            if !items.is_empty() {
                root.insert(key.into(), Value::Array(items.clone()));
            }
        }
        if !self.bin.is_empty() {
            root.insert("buffers".into(), json!([{ "byteLength": self.bin.len() }]));
        }
        Value::Object(root)
    }

    /// Lays the document out as a GLB file: 12-byte header, JSON chunk padded with
    /// spaces to 4 bytes, BIN chunk (if any data) padded with zeros to 4 bytes. The
    /// document has one scene, the default (`scene: 0`), unless it has no root node.
    ///
    /// # Panics
    ///
    /// If the JSON and binary data together exceed 4 GiB (the binary buffer alone is
    /// limited to 3 GiB by the `add_*` methods).
    pub fn finish(self) -> Vec<u8> {
        let mut json = serde_json::to_vec(&self.json()).expect("JSON values always serialize");
        while !json.len().is_multiple_of(4) {
            json.push(b' ');
        }
        // The buffer is kept padded to 4 bytes by `push_view`.
        let bin = self.bin;
        let bin_chunk = if bin.is_empty() { 0 } else { 8 + bin.len() };
        let total = 12 + 8 + json.len() + bin_chunk;
        let total = u32::try_from(total).expect("GLB larger than 4 GiB");
        let mut out = Vec::with_capacity(total as usize);
        out.extend_from_slice(&GLB_MAGIC.to_le_bytes());
        out.extend_from_slice(&2u32.to_le_bytes());
        out.extend_from_slice(&total.to_le_bytes());
        // Both lengths are below `total`, which fits in u32.
        out.extend_from_slice(&(json.len() as u32).to_le_bytes());
        out.extend_from_slice(&CHUNK_JSON.to_le_bytes());
        out.extend_from_slice(&json);
        if !bin.is_empty() {
            out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
            out.extend_from_slice(&CHUNK_BIN.to_le_bytes());
            out.extend_from_slice(&bin);
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
        assert!(mat.extensions().unwrap().contains_key(UNLIT_EXTENSION));
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
