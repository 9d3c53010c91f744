//! The material model shared by the glTF reader, the GLB writer and the
//! rasterizer: a metallic-roughness material with a base colour, an alpha
//! mode and a texture wrapping mode, as glTF defines them.

/// Texture coordinate wrapping (glTF sampler modes).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Wrap {
    /// Repeat (the glTF default).
    #[default]
    Repeat,
    /// Clamp to the edge texel.
    ClampToEdge,
    /// Repeat mirrored.
    MirroredRepeat,
}

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
///
/// The texture index means what its context says: for the writer an index
/// returned by [`crate::scene::glb::GlbBuilder::add_texture`], for the
/// geometry loader an index into
/// [`crate::scene::geometry::SceneGeometry::textures`].
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    /// The material's name (empty when the file gives none).
    pub name: String,
    /// Linear RGBA base colour factor, each in `[0, 1]`.
    pub base_color: [f32; 4],
    /// Index of the base colour texture, if any; it uses `TEXCOORD_0`.
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

impl Default for Material {
    /// The glTF default material, which draws primitives that name none:
    /// white, fully metallic and fully rough, opaque, single-sided.
    fn default() -> Self {
        Material {
            name: String::new(),
            base_color: [1.0; 4],
            base_color_texture: None,
            metallic: 1.0,
            roughness: 1.0,
            alpha_mode: AlphaMode::Opaque,
            double_sided: false,
            unlit: false,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_gltf_defaults() {
        assert_eq!(Wrap::default(), Wrap::Repeat);
        assert_eq!(AlphaMode::default(), AlphaMode::Opaque);
        let m = Material::default();
        assert_eq!((m.metallic, m.roughness), (1.0, 1.0));
        assert_eq!(m.base_color, [1.0; 4]);
        assert!(!m.double_sided && !m.unlit && m.base_color_texture.is_none());
    }
}
