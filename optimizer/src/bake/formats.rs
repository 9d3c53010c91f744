//! Atlas files in the chosen texture format: PNG (the viewer makes the
//! mip chain) or KTX2 with UASTC blocks of a coverage-keeping mip chain
//! ([`super::mips`], [`super::ktx2`]) behind `KHR_texture_basisu`.

use rayon::prelude::*;

use super::ktx2::encode_ktx2;
use super::mips::mip_chain;
use super::{ALPHA_CUTOFF, BakeOptions, encode_png};
use crate::Result;
use crate::api::job::MemoryParams;
use crate::api::texture_format::TextureFormat;
use crate::scene::glb::GlbBuilder;

impl BakeOptions {
    /// The default options, with atlases in the format the memory model
    /// names (`memory.texture_format`; PNG when it names none), so that the
    /// bake writes what the placement's estimate counted.
    pub fn for_memory(memory: &MemoryParams) -> Self {
        BakeOptions {
            textures: memory.texture_format.unwrap_or_default(),
            ..BakeOptions::default()
        }
    }
}

/// Rounds atlas sizes up to what `format` needs: KTX2 (UASTC) wants both
/// sides multiples of 4 (heights already are).
pub(crate) fn fit_sizes(sizes: &mut [(u32, u32)], format: TextureFormat) {
    if format == TextureFormat::Ktx2 {
        for s in sizes {
            *s = (s.0.next_multiple_of(4), s.1.next_multiple_of(4));
        }
    }
}

/// Encodes every RGBA8 atlas as a file of `format`, in parallel.
pub(crate) fn encode_atlases(
    atlases: &[Vec<u8>],
    sizes: &[(u32, u32)],
    format: TextureFormat,
) -> Result<Vec<Vec<u8>>> {
    atlases
        .par_iter()
        .zip(sizes)
        .map(|(a, &(w, h))| match format {
            TextureFormat::Png => encode_png(a, w, h),
            TextureFormat::Ktx2 => encode_ktx2(&mip_chain(a, w, h, ALPHA_CUTOFF, true)),
        })
        .collect()
}

/// Adds an encoded atlas as an image and a texture sampled by `sampler`;
/// returns the texture.
pub(crate) fn add_atlas(
    b: &mut GlbBuilder,
    name: &str,
    file: &[u8],
    format: TextureFormat,
    sampler: u32,
) -> Result<u32> {
    match format {
        TextureFormat::Png => {
            let image = b.add_image_png(name, file)?;
            b.add_texture(image, Some(sampler))
        }
        TextureFormat::Ktx2 => {
            let image = b.add_image_ktx2(name, file)?;
            b.add_texture_basisu(image, Some(sampler))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn options_follow_the_memory_model_and_ktx2_sizes_are_whole_blocks() {
        let mut m = MemoryParams::default();
        assert_eq!(BakeOptions::for_memory(&m).textures, TextureFormat::Png);
        m.texture_format = Some(TextureFormat::Ktx2);
        assert_eq!(BakeOptions::for_memory(&m).textures, TextureFormat::Ktx2);
        let mut sizes = [(606, 604), (4096, 12)];
        fit_sizes(&mut sizes, TextureFormat::Png);
        assert_eq!(sizes, [(606, 604), (4096, 12)]);
        fit_sizes(&mut sizes, TextureFormat::Ktx2);
        assert_eq!(sizes, [(608, 604), (4096, 12)]);
    }
}
