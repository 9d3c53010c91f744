//! KTX2 images and the `KHR_texture_basisu` textures that use them.
//!
//! A texture whose image is KTX2 has no `source` (no PNG fallback): its
//! image is named by `extensions.KHR_texture_basisu.source`, and the
//! extension is listed in both `extensionsUsed` and `extensionsRequired`, as
//! the extension's specification asks of files without a fallback.

use gltf::json as gj;
use serde_json::json;

use super::{GlbBuilder, bad, last_index};
use crate::Result;

/// The glTF extension for KTX2 (Basis Universal) textures.
pub const BASISU_EXTENSION: &str = "KHR_texture_basisu";

/// The KTX 2.0 file identifier.
const KTX2_IDENTIFIER: [u8; 12] = [
    0xAB, b'K', b'T', b'X', b' ', b'2', b'0', 0xBB, b'\r', b'\n', 0x1A, b'\n',
];

impl GlbBuilder {
    /// Adds a KTX2 image (`image/ktx2`) stored in the binary buffer and
    /// returns its index. Fails if the bytes do not start with the KTX 2.0
    /// identifier.
    pub fn add_image_ktx2(&mut self, name: &str, ktx2: &[u8]) -> Result<u32> {
        if !ktx2.starts_with(&KTX2_IDENTIFIER) {
            return Err(bad(&format!("image '{name}'"), "not a KTX2 file"));
        }
        let view = self.push_view(ktx2, None)?;
        self.root.images.push(gj::Image {
            buffer_view: Some(gj::Index::new(view)),
            mime_type: Some(gj::image::MimeType("image/ktx2".into())),
            name: (!name.is_empty()).then(|| name.to_string()),
            uri: None,
            extensions: None,
            extras: None,
        });
        last_index(&self.root.images, "images")
    }

    /// Adds a `KHR_texture_basisu` texture of a KTX2 image (from
    /// [`GlbBuilder::add_image_ktx2`]) with an optional sampler and returns
    /// its index.
    pub fn add_texture_basisu(&mut self, image: u32, sampler: Option<u32>) -> Result<u32> {
        let is_ktx2 = self
            .root
            .images
            .get(image as usize)
            .is_some_and(|i| i.mime_type.as_ref().is_some_and(|m| m.0 == "image/ktx2"));
        if !is_ktx2 {
            return Err(bad("texture", format!("image {image} is not a KTX2 image")));
        }
        if let Some(s) = sampler
            && s as usize >= self.root.samplers.len()
        {
            return Err(bad("texture", format!("unknown sampler {s}")));
        }
        let mut extensions = gj::extensions::texture::Texture::default();
        extensions
            .others
            .insert(BASISU_EXTENSION.into(), json!({ "source": image }));
        self.root.textures.push(gj::Texture {
            name: None,
            sampler: sampler.map(gj::Index::new),
            // `u32::MAX` is `gltf-json`'s "no source": the field is omitted.
            source: gj::Index::new(u32::MAX),
            extensions: Some(extensions),
            extras: None,
        });
        self.extensions_used.insert(BASISU_EXTENSION.into());
        self.extensions_required.insert(BASISU_EXTENSION.into());
        last_index(&self.root.textures, "textures")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::material::Material;

    #[test]
    fn basisu_textures_name_their_image_in_the_extension_and_require_it() {
        let mut b = GlbBuilder::new();
        let mut ktx2 = KTX2_IDENTIFIER.to_vec();
        ktx2.extend_from_slice(&[0; 20]);
        let image = b.add_image_ktx2("atlas", &ktx2).unwrap();
        let texture = b.add_texture_basisu(image, None).unwrap();
        let mut m = Material::new("m", [1.0; 4]);
        m.base_color_texture = Some(texture);
        b.add_material(&m).unwrap();
        let j = b.json();
        assert_eq!(j["images"][0]["mimeType"], "image/ktx2");
        assert!(j["textures"][0].get("source").is_none(), "{j}");
        assert_eq!(
            j["textures"][0]["extensions"][BASISU_EXTENSION]["source"],
            0
        );
        assert_eq!(j["extensionsUsed"], json!([BASISU_EXTENSION]));
        assert_eq!(j["extensionsRequired"], json!([BASISU_EXTENSION]));
        // A PNG image cannot be a basisu texture, nor PNG bytes a KTX2 image.
        let png = crate::bake::encode_png(&[0; 4], 1, 1).unwrap();
        let p = b.add_image_png("png", &png).unwrap();
        assert!(b.add_texture_basisu(p, None).is_err());
        assert!(b.add_image_ktx2("png", &png).is_err());
        assert!(b.add_texture_basisu(image, Some(3)).is_err());
    }
}
