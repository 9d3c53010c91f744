//! KTX2 textures with Basis Universal UASTC content, for `bake --textures ktx2`.
//!
//! UASTC rather than ETC1S: impostor layers are small detailed cut-outs whose
//! silhouettes come from alpha, and UASTC keeps colour and alpha close to
//! the RGBA8 source (above 35 dB on the bake's atlases, tested) at a fixed
//! 1 byte per texel that GPUs sample after a cheap transcode to ASTC 4×4 or
//! BC7; ETC1S is smaller on disk but blocky, in alpha too. The encoder is Binomial's (the `basis-universal` crate). It
//! writes `.basis` files, so the UASTC blocks of every level are taken out
//! of its slices and put in a KTX 2.0 container written here: header, level
//! index (largest level first), Data Format Descriptor with the UASTC colour
//! model, one `KTXwriter` key/value entry and the level data (smallest level
//! first in the file, each 16-byte aligned). No supercompression.
//!
//! The mip chain is the caller's (see [`super::mips`]): the encoder is given
//! every level and generates none.

use basis_universal::{BasisTextureFormat, ColorSpace, Compressor, CompressorParams};

use super::mips::MipLevel;
use crate::scene::glb::{BLOCK_BYTES, blocks};
pub use crate::scene::glb::{KTX2_IDENTIFIER, decode_ktx2, decode_uastc};
use crate::{Error, Result};

/// Khronos Data Format colour model of UASTC.
const KHR_DF_MODEL_UASTC: u8 = 166;
/// UASTC channel type: RGBA.
const KHR_DF_CHANNEL_UASTC_RGBA: u8 = 3;
/// UASTC channel type: RGB (no alpha).
const KHR_DF_CHANNEL_UASTC_RGB: u8 = 0;
/// Colour primaries BT.709 (as sRGB).
const KHR_DF_PRIMARIES_BT709: u8 = 1;
/// The sRGB transfer function.
const KHR_DF_TRANSFER_SRGB: u8 = 2;
/// The writer named in the `KTXwriter` entry.
const WRITER: &str = concat!("impostor ", env!("CARGO_PKG_VERSION"));

fn internal(m: impl Into<String>) -> Error {
    Error::Internal(format!("KTX2 encoding: {}", m.into()))
}

/// Encodes a mip chain (level 0 first, each level half the previous, sides
/// multiples of 4 at level 0) as a KTX2 file of UASTC blocks.
pub fn encode_ktx2(levels: &[MipLevel]) -> Result<Vec<u8>> {
    let Some(base) = levels.first() else {
        return Err(internal("no levels"));
    };
    if !base.width.is_multiple_of(4) || !base.height.is_multiple_of(4) {
        return Err(internal(format!(
            "level 0 is {}×{}: sides must be multiples of 4",
            base.width, base.height
        )));
    }
    for (k, l) in levels.iter().enumerate() {
        let want = ((base.width >> k).max(1), (base.height >> k).max(1));
        if (l.width, l.height) != want || l.rgba.len() != (l.width * l.height * 4) as usize {
            return Err(internal(format!("level {k} is not {}×{}", want.0, want.1)));
        }
    }
    let has_alpha = levels
        .iter()
        .any(|l| l.rgba.chunks_exact(4).any(|p| p[3] != 255));
    let data = encode_uastc(levels)?;
    Ok(write_container(base.width, base.height, has_alpha, &data))
}

/// UASTC blocks of every level, level 0 first, with Binomial's encoder.
fn encode_uastc(levels: &[MipLevel]) -> Result<Vec<Vec<u8>>> {
    let mut params = CompressorParams::new();
    params.set_basis_format(BasisTextureFormat::UASTC4x4);
    params.set_uastc_quality_level(basis_universal::UASTC_QUALITY_DEFAULT);
    params.set_color_space(ColorSpace::Srgb);
    params.set_generate_mipmaps(false);
    params.set_rdo_uastc(None);
    params.set_print_status_to_stdout(false);
    params
        .source_image_mut(0)
        .init(&levels[0].rgba, levels[0].width, levels[0].height, 4);
    for (k, l) in levels.iter().enumerate().skip(1) {
        params
            .source_mipmap_image_mut(0, k as u32 - 1)
            .init(&l.rgba, l.width, l.height, 4);
    }
    let threads = rayon::current_num_threads().max(1) as u32;
    let mut compressor = Compressor::new(threads);
    // SAFETY: the parameters are complete and in range: one RGBA source
    // image with its mip levels at the sizes the encoder expects (checked by
    // `encode_ktx2`), a valid UASTC quality level, no RDO and no generated
    // mipmaps; the encoder reads nothing else.
    #[allow(unsafe_code)]
    let processed = unsafe {
        if !compressor.init(&params) {
            return Err(internal("the encoder refused its parameters"));
        }
        compressor.process()
    };
    processed.map_err(|e| internal(format!("the encoder failed: {e:?}")))?;
    basis_levels(compressor.basis_file(), levels)
}

/// Little-endian unsigned integer of `n` bytes at `at`.
fn le(bytes: &[u8], at: usize, n: usize) -> Result<u64> {
    let b = bytes
        .get(at..at + n)
        .ok_or_else(|| internal("truncated .basis file"))?;
    Ok(b.iter().rev().fold(0u64, |v, &x| (v << 8) | u64::from(x)))
}

/// The raw UASTC blocks of each level of image 0 of a `.basis` file
/// (`basis_file_header` and `basis_slice_desc` of Binomial's
/// `basisu_file_headers.h`, packed little-endian).
fn basis_levels(basis: &[u8], levels: &[MipLevel]) -> Result<Vec<Vec<u8>>> {
    if le(basis, 0, 2)? != u64::from(u16::from_le_bytes(*b"sB")) {
        return Err(internal("not a .basis file"));
    }
    let total_slices = le(basis, 14, 3)? as usize;
    let tex_format = le(basis, 20, 1)?;
    let slice_desc = le(basis, 65, 4)? as usize;
    if tex_format != 1 {
        return Err(internal("the .basis file is not UASTC"));
    }
    let mut out = vec![Vec::new(); levels.len()];
    for s in 0..total_slices {
        let d = slice_desc + s * 23;
        let (image, level) = (le(basis, d, 3)?, le(basis, d + 3, 1)? as usize);
        let (bx, by) = (le(basis, d + 9, 2)?, le(basis, d + 11, 2)?);
        let (ofs, size) = (
            le(basis, d + 13, 4)? as usize,
            le(basis, d + 17, 4)? as usize,
        );
        let Some(l) = levels.get(level).filter(|_| image == 0) else {
            return Err(internal(format!("unexpected slice {s}")));
        };
        let (wx, wy) = blocks(l.width, l.height);
        if (bx, by) != (u64::from(wx), u64::from(wy)) || size != (wx * wy) as usize * BLOCK_BYTES {
            return Err(internal(format!("slice {s} does not match level {level}")));
        }
        out[level] = basis
            .get(ofs..ofs + size)
            .ok_or_else(|| internal("truncated .basis file"))?
            .to_vec();
    }
    if out.iter().any(Vec::is_empty) {
        return Err(internal("a level is missing from the .basis file"));
    }
    Ok(out)
}

fn put_u32(out: &mut Vec<u8>, v: u32) {
    out.extend_from_slice(&v.to_le_bytes());
}

fn put_u64(out: &mut Vec<u8>, v: u64) {
    out.extend_from_slice(&v.to_le_bytes());
}

/// The Data Format Descriptor of sRGB UASTC 4×4 with straight alpha.
fn dfd(has_alpha: bool) -> Vec<u8> {
    let mut b = Vec::with_capacity(44);
    put_u32(&mut b, 44); // dfdTotalSize
    put_u32(&mut b, 0); // vendorId 0 (Khronos), descriptorType 0 (basic)
    b.extend_from_slice(&2u16.to_le_bytes()); // versionNumber (1.3)
    b.extend_from_slice(&40u16.to_le_bytes()); // descriptorBlockSize: 24 + 16 · 1 sample
    b.extend_from_slice(&[
        KHR_DF_MODEL_UASTC,
        KHR_DF_PRIMARIES_BT709,
        KHR_DF_TRANSFER_SRGB,
        0, // flags: straight alpha
    ]);
    b.extend_from_slice(&[3, 3, 0, 0]); // texel block 4 × 4 (dimensions − 1)
    b.extend_from_slice(&[BLOCK_BYTES as u8, 0, 0, 0, 0, 0, 0, 0]); // bytesPlane0..7
    // The one sample: all 128 bits of the block.
    b.extend_from_slice(&0u16.to_le_bytes()); // bitOffset
    b.push(127); // bitLength − 1
    b.push(if has_alpha {
        KHR_DF_CHANNEL_UASTC_RGBA
    } else {
        KHR_DF_CHANNEL_UASTC_RGB
    });
    b.extend_from_slice(&[0, 0, 0, 0]); // samplePosition
    put_u32(&mut b, 0); // sampleLower
    put_u32(&mut b, u32::MAX); // sampleUpper
    b
}

/// The key/value data: `KTXwriter`, padded to 4 bytes.
fn kvd() -> Vec<u8> {
    let mut entry = b"KTXwriter\0".to_vec();
    entry.extend_from_slice(WRITER.as_bytes());
    entry.push(0);
    let mut b = Vec::new();
    put_u32(&mut b, entry.len() as u32);
    b.extend_from_slice(&entry);
    while !b.len().is_multiple_of(4) {
        b.push(0);
    }
    b
}

/// A KTX 2.0 file of UASTC level data (level 0 first in `data`).
fn write_container(width: u32, height: u32, has_alpha: bool, data: &[Vec<u8>]) -> Vec<u8> {
    const HEADER: usize = 80;
    let n = data.len();
    let dfd = dfd(has_alpha);
    let kvd = kvd();
    let dfd_at = HEADER + 24 * n;
    let kvd_at = dfd_at + dfd.len();
    // Level data, smallest level first, each aligned to lcm(16, 4) bytes.
    let mut offsets = vec![0usize; n];
    let mut end = kvd_at + kvd.len();
    for k in (0..n).rev() {
        end = end.next_multiple_of(BLOCK_BYTES);
        offsets[k] = end;
        end += data[k].len();
    }
    let mut out = Vec::with_capacity(end);
    out.extend_from_slice(&KTX2_IDENTIFIER);
    put_u32(&mut out, 0); // vkFormat: VK_FORMAT_UNDEFINED (Basis Universal)
    put_u32(&mut out, 1); // typeSize
    put_u32(&mut out, width);
    put_u32(&mut out, height);
    put_u32(&mut out, 0); // pixelDepth
    put_u32(&mut out, 0); // layerCount
    put_u32(&mut out, 1); // faceCount
    put_u32(&mut out, n as u32); // levelCount
    put_u32(&mut out, 0); // supercompressionScheme: none
    put_u32(&mut out, dfd_at as u32);
    put_u32(&mut out, dfd.len() as u32);
    put_u32(&mut out, kvd_at as u32);
    put_u32(&mut out, kvd.len() as u32);
    put_u64(&mut out, 0); // sgdByteOffset
    put_u64(&mut out, 0); // sgdByteLength
    for (k, d) in data.iter().enumerate() {
        put_u64(&mut out, offsets[k] as u64);
        put_u64(&mut out, d.len() as u64);
        put_u64(&mut out, d.len() as u64); // uncompressed: the same
    }
    out.extend_from_slice(&dfd);
    out.extend_from_slice(&kvd);
    for k in (0..n).rev() {
        out.resize(offsets[k], 0);
        out.extend_from_slice(&data[k]);
    }
    out
}

/// Peak signal-to-noise ratio of a decoded RGBA8 image against its source,
/// dB, over what an alpha-masked material shows: alpha everywhere, colour
/// where the source is not transparent (the quality measure of KTX2 atlases
/// in the tests).
pub fn masked_psnr_db(decoded: &[u8], source: &[u8]) -> f64 {
    let (mut sum, mut n) = (0.0, 0usize);
    for (d, s) in decoded.chunks_exact(4).zip(source.chunks_exact(4)) {
        let channels = if s[3] > 0 { 0..4 } else { 3..4 };
        for k in channels {
            sum += (f64::from(d[k]) - f64::from(s[k])).powi(2);
            n += 1;
        }
    }
    10.0 * (255.0f64.powi(2) / (sum / n.max(1) as f64).max(1e-12)).log10()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bake::mips::mip_chain;

    /// A 64 × 32 cut-out: a disc of smooth colour on transparent texels.
    fn cutout() -> (Vec<u8>, u32, u32) {
        let (w, h) = (64u32, 32u32);
        let mut px = Vec::new();
        for y in 0..h {
            for x in 0..w {
                let (dx, dy) = (x as f32 - 30.0, y as f32 - 15.0);
                let inside = dx * dx + dy * dy < 14.0 * 14.0;
                px.extend_from_slice(&[
                    (x * 4) as u8,
                    (y * 8) as u8,
                    128,
                    if inside { 255 } else { 0 },
                ]);
            }
        }
        (px, w, h)
    }

    #[test]
    fn the_container_reads_back_and_every_level_decodes_close_to_its_source() {
        let (px, w, h) = cutout();
        let chain = mip_chain(&px, w, h, 0.5, true);
        let file = encode_ktx2(&chain).unwrap();
        let r = ktx2::Reader::new(&file[..]).unwrap();
        let hd = r.header();
        assert_eq!(
            (hd.pixel_width, hd.pixel_height, hd.level_count),
            (64, 32, 7)
        );
        assert!(hd.format.is_none() && hd.supercompression_scheme.is_none());
        assert_eq!(r.color_model(), Some(ktx2::ColorModel::UASTC));
        assert_eq!(r.transfer_function(), Some(ktx2::TransferFunction::SRGB));
        assert_eq!(r.is_alpha_premultiplied(), Some(false));
        assert_eq!(r.writer().map(|w| w.trim_end_matches('\0')), Some(WRITER));
        assert_eq!(r.levels().len(), 7);
        for (k, level) in r.levels().enumerate() {
            let src = &chain[k];
            let rgba = decode_uastc(level.data, src.width, src.height).unwrap();
            // UASTC keeps 35 dB and more on such content; a wrong level,
            // order or block layout falls below 25 dB (the control below).
            // The last levels (under 32 texels wide: a few blocks, all
            // disc edge and steep gradient) only need to decode.
            if src.width >= 32 {
                let p = masked_psnr_db(&rgba, &src.rgba);
                assert!(p > 35.0, "level {k}: {p:.1} dB");
            }
        }
        // The control: the same decoded level against its source upside
        // down is far below the threshold.
        let level0 = r.levels().next().unwrap();
        let rgba = decode_uastc(level0.data, w, h).unwrap();
        let row = (w * 4) as usize;
        let flipped: Vec<u8> = px.chunks_exact(row).rev().flatten().copied().collect();
        assert!(masked_psnr_db(&rgba, &flipped) < 25.0);
    }

    #[test]
    fn a_ktx2_file_reads_as_its_level_0_and_bad_files_are_clear_errors() {
        let (px, w, h) = cutout();
        let file = encode_ktx2(&mip_chain(&px, w, h, 0.5, true)).unwrap();
        let r = ktx2::Reader::new(&file[..]).unwrap();
        let level0 = decode_uastc(r.levels().next().unwrap().data, w, h).unwrap();
        let mut asked = None;
        let read = decode_ktx2(&file, "atlas", |a, b| {
            asked = Some((a, b));
            Ok(())
        })
        .unwrap();
        assert_eq!(read, (w, h, level0));
        assert_eq!(asked, Some((64, 32)));
        // The size check runs before decoding and its refusal is the error.
        let refused = decode_ktx2(&file, "atlas", |_, _| Err(Error::bad("atlas", "too large")));
        assert!(refused.unwrap_err().to_string().contains("too large"));
        // Truncated, or with another supercompression: named, no panic.
        let e = decode_ktx2(&file[..100], "atlas", |_, _| Ok(())).unwrap_err();
        assert!(e.to_string().contains("not a readable KTX2 file"), "{e}");
        let mut zstd = file.clone();
        zstd[44..48].copy_from_slice(&2u32.to_le_bytes()); // supercompressionScheme
        let e = decode_ktx2(&zstd, "atlas", |_, _| Ok(())).unwrap_err();
        assert!(e.to_string().contains("supercompression"), "{e}");
    }

    #[test]
    fn encoding_is_deterministic_and_checks_its_levels() {
        let (px, w, h) = cutout();
        let chain = mip_chain(&px, w, h, 0.5, true);
        assert_eq!(encode_ktx2(&chain).unwrap(), encode_ktx2(&chain).unwrap());
        let odd = mip_chain(&px[..(62 * 4 * 4)], 62, 4, 0.5, true);
        assert!(encode_ktx2(&odd).is_err());
        let mut short = chain.clone();
        short[2].width += 1;
        assert!(encode_ktx2(&short).is_err());
        assert!(encode_ktx2(&[]).is_err());
        assert!(decode_uastc(&[0; 15], 4, 4).is_err());
    }
}
