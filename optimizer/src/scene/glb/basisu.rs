//! KTX2 images and the `KHR_texture_basisu` textures that use them.
//!
//! A texture whose image is KTX2 has no `source` (no PNG fallback): its
//! image is named by `extensions.KHR_texture_basisu.source`, and the
//! extension is listed in both `extensionsUsed` and `extensionsRequired`, as
//! the extension's specification asks of files without a fallback.
//!
//! Reading: [`decode_ktx2`] decodes level 0 of a KTX2 file of UASTC content
//! to RGBA8 with Binomial's transcoder (the `basis-universal` crate), for
//! the geometry loader; the container is parsed by the `ktx2` crate.

use basis_universal::{
    DecodeFlags, LowLevelUastcTranscoder, SliceParametersUastc, TranscoderBlockFormat,
};
use gltf::json as gj;
use serde_json::json;

use super::{GlbBuilder, bad, last_index};
use crate::{Error, Result};

/// The glTF extension for KTX2 (Basis Universal) textures.
pub const BASISU_EXTENSION: &str = "KHR_texture_basisu";

/// The KTX 2.0 file identifier.
pub const KTX2_IDENTIFIER: [u8; 12] = [
    0xAB, b'K', b'T', b'X', b' ', b'2', b'0', 0xBB, b'\r', b'\n', 0x1A, b'\n',
];
/// Bytes of one UASTC 4×4 block.
pub(crate) const BLOCK_BYTES: usize = 16;

/// Blocks of a `w × h` level.
pub(crate) fn blocks(w: u32, h: u32) -> (u32, u32) {
    (w.div_ceil(4), h.div_ceil(4))
}

fn internal(m: impl Into<String>) -> Error {
    Error::Internal(format!("KTX2 decoding: {}", m.into()))
}

impl GlbBuilder {
    /// Adds a KTX2 image (`image/ktx2`) stored in the binary buffer and
    /// returns its index. Fails if the bytes do not start with the KTX 2.0
    /// identifier.
    pub fn add_image_ktx2(&mut self, name: &str, ktx2: &[u8]) -> Result<u32> {
        if !ktx2.starts_with(&KTX2_IDENTIFIER) {
            return Err(bad(&format!("image '{name}'"), "not a KTX2 file"));
        }
        self.push_image(name, ktx2, "image/ktx2")
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

/// Decodes the UASTC blocks of a `width × height` level to RGBA8 texels
/// (rows from the top) with Binomial's transcoder.
pub fn decode_uastc(blocks_data: &[u8], width: u32, height: u32) -> Result<Vec<u8>> {
    let (bx, by) = blocks(width, height);
    if blocks_data.len() != (bx * by) as usize * BLOCK_BYTES {
        return Err(internal(format!(
            "{} bytes are not the UASTC blocks of {width}×{height} texels",
            blocks_data.len()
        )));
    }
    // `basis-universal` 0.3 passes the output row pitch of an uncompressed
    // target as `original_width / 4` (in blocks) while the transcoder reads
    // it in pixels, and sizes the buffer by that pitch; a width of 4 × the
    // real one gives the transcoder the right pitch and the buffer the right
    // size (the transcoder reads no other use of the width for RGBA32).
    let t = LowLevelUastcTranscoder::new();
    let rgba = t
        .transcode_slice(
            blocks_data,
            SliceParametersUastc {
                num_blocks_x: bx,
                num_blocks_y: by,
                has_alpha: true,
                original_width: width * 4,
                original_height: height,
            },
            DecodeFlags::HIGH_QUALITY,
            TranscoderBlockFormat::RGBA32,
        )
        .map_err(|e| internal(format!("UASTC decoding failed: {e:?}")))?;
    if rgba.len() != (width * height * 4) as usize {
        return Err(internal("the transcoder returned a wrong size"));
    }
    Ok(rgba)
}

/// Level 0 of a KTX2 file of UASTC content (as `bake --textures ktx2`
/// writes, or any 2D KTX2 file with UASTC blocks and no
/// supercompression) decoded to RGBA8 texels, rows from the top, once its
/// size has passed `check(width, height)`. `what` names the image in
/// errors.
pub fn decode_ktx2(
    bytes: &[u8],
    what: &str,
    check: impl FnOnce(u32, u32) -> Result<()>,
) -> Result<(u32, u32, Vec<u8>)> {
    let bad = |m: String| Error::bad(what, m);
    let r = ktx2::Reader::new(bytes).map_err(|e| bad(format!("not a readable KTX2 file: {e}")))?;
    let h = r.header();
    if r.color_model() != Some(ktx2::ColorModel::UASTC) || h.format.is_some() {
        return Err(bad(format!(
            "KTX2 content {:?} is not supported (only Basis Universal UASTC is read)",
            h.format
                .map_or_else(|| format!("{:?}", r.color_model()), |f| format!("{f:?}"))
        )));
    }
    if let Some(scheme) = h.supercompression_scheme {
        return Err(bad(format!(
            "KTX2 supercompression {scheme:?} is not supported (only uncompressed UASTC levels are read)"
        )));
    }
    if h.pixel_depth > 1 || h.layer_count > 1 || h.face_count != 1 || h.pixel_height == 0 {
        return Err(bad("only a single 2D KTX2 image is read".into()));
    }
    let (w, ht) = (h.pixel_width, h.pixel_height);
    check(w, ht)?;
    let level = r
        .levels()
        .next()
        .ok_or_else(|| bad("the KTX2 file has no levels".into()))?;
    let rgba = decode_uastc(level.data, w, ht)
        .map_err(|e| bad(format!("its UASTC level 0 does not decode: {e}")))?;
    Ok((w, ht, rgba))
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
