//! GLB (binary glTF 2.0) files as this tool writes and reads them.
//!
//! [`GlbBuilder`] accumulates one binary buffer (the GLB `BIN` chunk) and a
//! [`gltf::json::Root`] document, then [`GlbBuilder::finish`] lays both out as
//! a GLB file:
//!
//! - geometry ([`GlbBuilder::add_geometry`]) becomes accessors over 4-byte aligned
//!   buffer views: `POSITION` (with the `min`/`max` the specification requires),
//!   optional `NORMAL` and `TEXCOORD_0`, and triangle-list indices stored as
//!   `UNSIGNED_SHORT` when every index fits (≤ 65534, so that the primitive-restart
//!   value 65535 never appears) and as `UNSIGNED_INT` otherwise;
//! - meshes ([`GlbBuilder::add_mesh`]) are lists of primitives, each a geometry and a
//!   material; several meshes may share one geometry (colour variants cost no bytes);
//! - materials ([`crate::scene::material::Material`]) are metallic-roughness with a
//!   base colour factor, an optional base colour texture, an alpha mode (opaque,
//!   mask with cutoff, blend), double-sidedness and optionally
//!   `KHR_materials_unlit` (for baked impostors);
//! - PNG images live in buffer views, textures pair an image with a sampler;
//! - nodes carry a name, an optional mesh, a TRS or matrix transform, children,
//!   optional `extras` and `extensions`; the node graph is kept a forest by
//!   construction. Every extension used (`KHR_materials_unlit`, node
//!   extensions such as `MSFT_lod`) is listed in `extensionsUsed`, sorted;
//! - levels of detail (`MSFT_lod`): the coarser levels are nodes added before the
//!   node that names them in `MSFT_lod.ids`; they are neither scene roots nor
//!   children (the default scene roots leave them out).
//!
//! `gltf-json` gives the document its shape; the builder adds the checks the
//! format demands and `gltf-json` does not make (finite data, index ranges,
//! alignment, a forest of nodes, level ids, accessor bounds equal to the
//! data, size limits). Nothing is deduplicated; every call writes what it is
//! given.
//!
//! Reading goes through the same safe loader as every other glTF input
//! ([`crate::scene::gltf_load`]); `object_extras` reads the node `extras`
//! that the writer attaches to objects.

mod basisu;
mod nodes;
mod read;
mod write;

pub(crate) use basisu::{BLOCK_BYTES, blocks};
pub use basisu::{KTX2_IDENTIFIER, decode_ktx2, decode_uastc};
pub(crate) use read::{object_extras, scene_extras};
pub use write::encode_png;

use std::collections::BTreeSet;

use gltf::json as gj;
use serde_json::{Map, Value};

use crate::scene::material::Wrap;
use crate::{Error, Result};

const UNLIT_EXTENSION: &str = "KHR_materials_unlit";
const LOD_EXTENSION: &str = "MSFT_lod";

/// The largest index stored as `UNSIGNED_SHORT` (65535 is the primitive-restart value).
pub const MAX_U16_INDEX: u32 = 65534;

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
///
/// Buffers, geometry, meshes, materials, textures and the file layout are
/// written in `write.rs`; nodes and the scene in `nodes.rs`.
#[derive(Debug, Default)]
pub struct GlbBuilder {
    /// The binary buffer, kept padded to a multiple of 4 bytes.
    bin: Vec<u8>,
    /// The document without its asset, scene, buffer and `extensionsUsed`,
    /// which depend on everything added and are filled in when it is written.
    root: gj::Root,
    /// The accessors of every geometry written, by [`GeometryId`].
    geometries: Vec<GeometryAccessors>,
    /// Per node, its parent.
    parent: Vec<Option<u32>>,
    /// The scene roots, when set explicitly.
    roots: Option<Vec<u32>>,
    /// Nodes named in some node's `MSFT_lod.ids`.
    lod_level: Vec<bool>,
    /// Extensions used so far.
    extensions_used: BTreeSet<String>,
    /// The scene's `extras`, if set.
    scene_extras: Option<Value>,
    /// Extensions a reader must support (a subset of `extensions_used`).
    extensions_required: BTreeSet<String>,
}

impl GlbBuilder {
    /// Writes a loaded scene texture (its RGBA8 texels as a PNG image, its
    /// wrapping as a sampler) and returns the new texture's index; `name`
    /// names the image.
    pub fn add_loaded_texture(
        &mut self,
        name: &str,
        tex: &crate::scene::geometry::Texture,
    ) -> Result<u32> {
        let png = encode_png(&tex.rgba, tex.width, tex.height)?;
        let image = self.add_image_png(name, &png)?;
        let sampler = self.add_sampler(&Sampler {
            wrap_s: tex.wrap_s,
            wrap_t: tex.wrap_t,
            ..Sampler::default()
        })?;
        self.add_texture(image, Some(sampler))
    }
}

fn bad(what: &str, message: impl Into<String>) -> Error {
    Error::bad(format!("GLB writer: {what}"), message)
}

fn all_finite(xs: &[f32]) -> bool {
    xs.iter().all(|x| x.is_finite())
}

fn to_u32(n: usize, what: &str) -> Result<u32> {
    u32::try_from(n).map_err(|_| bad(what, "too many elements"))
}

/// The index of the element just pushed onto `items`.
fn last_index<T>(items: &[T], what: &str) -> Result<u32> {
    to_u32(items.len() - 1, what)
}
