//! The material model shared by the glTF reader, the GLB writer and the
//! rasterizer: a metallic-roughness material with a base colour, an alpha
//! mode and a texture wrapping mode, as glTF defines them; and the
//! `KHR_texture_transform` of texture coordinates.

use glam::Vec2;

use crate::{Error, Result};

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

/// A `KHR_texture_transform`: `uv′ = offset + R(rotation) · (scale ∘ uv)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UvTransform {
    /// Added last.
    pub offset: [f32; 2],
    /// Radians, counter-clockwise in texture space.
    pub rotation: f32,
    /// Applied first.
    pub scale: [f32; 2],
}

impl UvTransform {
    /// The glTF extension's matrix `T · R · S` applied to `uv`.
    pub fn apply(&self, uv: Vec2) -> Vec2 {
        let (sin, cos) = self.rotation.sin_cos();
        let (x, y) = (uv.x * self.scale[0], uv.y * self.scale[1]);
        Vec2::new(
            cos * x + sin * y + self.offset[0],
            -sin * x + cos * y + self.offset[1],
        )
    }
}

/// A texture reference's `KHR_texture_transform`, if it has one; every
/// number must be finite.
pub(crate) fn uv_transform(info: &gltf::texture::Info, what: &str) -> Result<Option<UvTransform>> {
    #[derive(serde::Deserialize)]
    struct Raw {
        #[serde(default)]
        offset: Option<[f32; 2]>,
        #[serde(default)]
        rotation: Option<f32>,
        #[serde(default)]
        scale: Option<[f32; 2]>,
    }
    let Some(value) = info.extension_value("KHR_texture_transform") else {
        return Ok(None);
    };
    let what = format!("{what} KHR_texture_transform");
    let raw: Raw = serde_json::from_value(value.clone())
        .map_err(|e| Error::bad(&what, format!("malformed: {e}")))?;
    let t = UvTransform {
        offset: raw.offset.unwrap_or([0.0, 0.0]),
        rotation: raw.rotation.unwrap_or(0.0),
        scale: raw.scale.unwrap_or([1.0, 1.0]),
    };
    let numbers = [t.offset[0], t.offset[1], t.rotation, t.scale[0], t.scale[1]];
    if !numbers.iter().all(|v| v.is_finite()) {
        return Err(Error::bad(&what, "a value is not finite"));
    }
    Ok(Some(t))
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

    #[test]
    fn texture_transform_is_offset_rotation_scale() {
        // gltfpack's dequantization: scale then offset.
        let t = UvTransform {
            offset: [0.25, -1.0],
            rotation: 0.0,
            scale: [2.0, 0.5],
        };
        assert_eq!(t.apply(Vec2::new(1.0, 2.0)), Vec2::new(2.25, 0.0));
        // A quarter turn maps u to −v (the extension's matrix
        // [cos sin; −sin cos]).
        let r = UvTransform {
            offset: [0.0, 0.0],
            rotation: std::f32::consts::FRAC_PI_2,
            scale: [1.0, 1.0],
        };
        let p = r.apply(Vec2::new(1.0, 0.0));
        assert!((p - Vec2::new(0.0, -1.0)).length() < 1e-6, "{p:?}");
    }
}
