//! `EXT_meshopt_compression`: buffer views whose bytes are stored
//! compressed in another buffer, as `gltfpack -c`/`-cc` writes them.
//!
//! Every compressed view is decoded once, after the buffers are resolved,
//! into one extra buffer appended to the document; the view is then pointed
//! at its decoded bytes, so accessors read it like any other view. The
//! decoding itself is the `meshopt` crate's (the reference decoder, safe for
//! untrusted input): `ATTRIBUTES` with its `OCTAHEDRAL`, `QUATERNION` and
//! `EXPONENTIAL` filters, `TRIANGLES` and `INDICES`.
//!
//! What a view claims is checked before anything is allocated:
//! `count × byteStride` must equal the view's `byteLength`, the stride must
//! suit the mode and filter, the compressed range must lie inside its
//! buffer, and the decoded bytes of all views together are at most
//! [`MAX_DECODED_BYTES`]. A buffer marked `fallback` is never read (a GLB
//! holds no data for it; a `.gltf` may name a file that need not exist):
//! it resolves to no bytes, and a view that reads it without being
//! compressed fails the usual range check.

use super::*;
use gltf::json::validation::USize64;

/// The extension's name.
pub(crate) const EXT_MESHOPT: &str = "EXT_meshopt_compression";

/// The most bytes the compressed views of one file may decode to together:
/// 4 GiB, the size limit of a scene file.
pub const MAX_DECODED_BYTES: u64 = crate::files::MAX_SCENE_BYTES;

/// True for a buffer marked `extensions.EXT_meshopt_compression.fallback`.
pub(crate) fn is_fallback(buffer: &gltf::Buffer) -> bool {
    buffer
        .extension_value(EXT_MESHOPT)
        .and_then(|e| e.get("fallback"))
        .and_then(serde_json::Value::as_bool)
        == Some(true)
}

/// One compressed view's extension object.
#[derive(serde::Deserialize)]
#[serde(rename_all = "camelCase")]
struct Compressed {
    buffer: usize,
    #[serde(default)]
    byte_offset: u64,
    byte_length: u64,
    byte_stride: u64,
    count: u64,
    mode: String,
    #[serde(default = "no_filter")]
    filter: String,
}

fn no_filter() -> String {
    "NONE".to_string()
}

/// Decodes every compressed buffer view of `doc` (see the module notes);
/// returns the document with those views pointing at their decoded bytes,
/// which are appended to `buffers`. A document without compressed views is
/// returned unchanged.
pub(crate) fn decode_compressed_views<'a>(
    doc: gltf::Document,
    buffers: &mut Vec<Cow<'a, [u8]>>,
    source: &str,
) -> Result<gltf::Document> {
    let compressed = doc
        .views()
        .any(|v| v.extension_value(EXT_MESHOPT).is_some());
    if !compressed {
        return Ok(doc);
    }
    let mut root = doc.into_json();
    let target = root.buffers.len();
    let mut decoded: Vec<u8> = Vec::new();
    let mut total: u64 = 0;
    for (v, view) in root.buffer_views.iter_mut().enumerate() {
        let Some(ext) = view
            .extensions
            .as_mut()
            .and_then(|e| e.others.remove(EXT_MESHOPT))
        else {
            continue;
        };
        let what = format!("{source}: bufferView {v} {EXT_MESHOPT}");
        let c: Compressed = serde_json::from_value(ext)
            .map_err(|e| Error::bad(&what, format!("malformed extension object: {e}")))?;
        let size = c.count.checked_mul(c.byte_stride).ok_or_else(|| {
            Error::bad(
                &what,
                format!("count {} × byteStride {} overflows", c.count, c.byte_stride),
            )
        })?;
        total = total.saturating_add(size);
        if total > MAX_DECODED_BYTES {
            return Err(Error::bad(
                &what,
                format!(
                    "the compressed views decode to more than the limit of {MAX_DECODED_BYTES} \
                     bytes (this one claims {} × {} = {size} bytes)",
                    c.count, c.byte_stride
                ),
            ));
        }
        let view_len = view.byte_length.0;
        if size != view_len {
            return Err(Error::bad(
                &what,
                format!(
                    "count {} × byteStride {} = {size} bytes, but the bufferView's byteLength is \
                     {view_len}",
                    c.count, c.byte_stride
                ),
            ));
        }
        let data: &[u8] = buffers.get(c.buffer).ok_or_else(|| {
            Error::bad(
                &what,
                format!(
                    "buffer {} does not exist (the file has {} buffers)",
                    c.buffer,
                    buffers.len()
                ),
            )
        })?;
        let encoded = c
            .byte_offset
            .checked_add(c.byte_length)
            .filter(|&end| end <= data.len() as u64)
            .map(|end| &data[c.byte_offset as usize..end as usize])
            .ok_or_else(|| {
                Error::bad(
                    &what,
                    format!(
                        "byteOffset {} + byteLength {} lies outside buffer {} ({} bytes)",
                        c.byte_offset,
                        c.byte_length,
                        c.buffer,
                        data.len()
                    ),
                )
            })?;
        // `size` ≤ MAX_DECODED_BYTES, so these fit in memory's index type.
        let bytes = decode_view(
            encoded,
            c.count as usize,
            c.byte_stride as usize,
            &c.mode,
            &c.filter,
        )
        .map_err(|e| Error::bad(&what, e))?;
        while !decoded.len().is_multiple_of(4) {
            decoded.push(0);
        }
        view.buffer = gltf::json::Index::new(target as u32);
        view.byte_offset = Some(USize64(decoded.len() as u64));
        decoded.extend_from_slice(&bytes);
    }
    with_decoded_buffer(root, buffers, decoded, source)
}

/// Decodes one view's `encoded` bytes into `count` elements of `stride`
/// bytes; the message says what is wrong with the view or its data.
pub(crate) fn decode_view(
    encoded: &[u8],
    count: usize,
    stride: usize,
    mode: &str,
    filter: &str,
) -> std::result::Result<Vec<u8>, String> {
    let corrupt = |e: ::meshopt::Error| format!("the compressed {mode} data is corrupt ({e})");
    match mode {
        "ATTRIBUTES" => {
            if stride == 0 || !stride.is_multiple_of(4) || stride > 256 {
                return Err(format!(
                    "byteStride {stride} is not a multiple of 4 in 4 … 256 (ATTRIBUTES)"
                ));
            }
            check_filter(stride, filter)?;
            let mut bytes = decode_vertices(encoded, count, stride).map_err(corrupt)?;
            apply_filter(&mut bytes, stride, filter);
            Ok(bytes)
        }
        "TRIANGLES" | "INDICES" => {
            if filter != "NONE" {
                return Err(format!("filter {filter} is only allowed with ATTRIBUTES"));
            }
            if mode == "TRIANGLES" && !count.is_multiple_of(3) {
                return Err(format!("count {count} is not a multiple of 3 (TRIANGLES)"));
            }
            let triangles = mode == "TRIANGLES";
            match stride {
                2 => {
                    let v: Vec<u16> = if triangles {
                        ::meshopt::decode_index_buffer(encoded, count)
                    } else {
                        ::meshopt::decode_index_sequence(encoded, count)
                    }
                    .map_err(corrupt)?;
                    Ok(v.iter().flat_map(|i| i.to_le_bytes()).collect())
                }
                4 => {
                    let v: Vec<u32> = if triangles {
                        ::meshopt::decode_index_buffer(encoded, count)
                    } else {
                        ::meshopt::decode_index_sequence(encoded, count)
                    }
                    .map_err(corrupt)?;
                    Ok(v.iter().flat_map(|i| i.to_le_bytes()).collect())
                }
                s => Err(format!("byteStride {s} is not 2 or 4 ({mode})")),
            }
        }
        m => Err(format!(
            "mode {m:?} is not ATTRIBUTES, TRIANGLES or INDICES"
        )),
    }
}

/// Checks that `filter` is known and suits elements of `stride` bytes.
fn check_filter(stride: usize, filter: &str) -> std::result::Result<(), String> {
    match (filter, stride) {
        ("NONE" | "EXPONENTIAL", _) | ("OCTAHEDRAL", 4 | 8) | ("QUATERNION", 8) => Ok(()),
        ("OCTAHEDRAL", s) => Err(format!(
            "filter OCTAHEDRAL needs byteStride 4 or 8, not {s}"
        )),
        ("QUATERNION", s) => Err(format!("filter QUATERNION needs byteStride 8, not {s}")),
        (f, _) => Err(format!(
            "filter {f:?} is not NONE, OCTAHEDRAL, QUATERNION or EXPONENTIAL"
        )),
    }
}

/// Undoes an `ATTRIBUTES` filter (checked by [`check_filter`]) in place on
/// decoded elements of `stride` bytes.
fn apply_filter(bytes: &mut [u8], stride: usize, filter: &str) {
    match (filter, stride) {
        ("OCTAHEDRAL", 4) => {
            let mut v: Vec<[i8; 4]> = bytes
                .chunks_exact(4)
                .map(|c| [c[0], c[1], c[2], c[3]].map(|b| b as i8))
                .collect();
            ::meshopt::decode_filter_oct(&mut v);
            for (out, e) in bytes.chunks_exact_mut(4).zip(&v) {
                out.copy_from_slice(&e.map(|c| c as u8));
            }
        }
        ("OCTAHEDRAL", _) => {
            let mut v = to_i16x4(bytes);
            ::meshopt::decode_filter_oct(&mut v);
            from_i16x4(bytes, &v);
        }
        ("QUATERNION", _) => {
            let mut v = to_i16x4(bytes);
            ::meshopt::decode_filter_quat(&mut v);
            from_i16x4(bytes, &v);
        }
        ("EXPONENTIAL", _) => {
            // Each 32-bit component is decoded on its own.
            let mut v: Vec<[u32; 1]> = bytes
                .chunks_exact(4)
                .map(|c| [u32::from_le_bytes([c[0], c[1], c[2], c[3]])])
                .collect();
            ::meshopt::decode_filter_exp(&mut v);
            for (out, e) in bytes.chunks_exact_mut(4).zip(&v) {
                out.copy_from_slice(&e[0].to_le_bytes());
            }
        }
        _ => {}
    }
}

fn to_i16x4(bytes: &[u8]) -> Vec<[i16; 4]> {
    bytes
        .chunks_exact(8)
        .map(|c| std::array::from_fn(|i| i16::from_le_bytes([c[2 * i], c[2 * i + 1]])))
        .collect()
}

fn from_i16x4(bytes: &mut [u8], v: &[[i16; 4]]) {
    for (out, e) in bytes.chunks_exact_mut(8).zip(v) {
        for (i, c) in e.iter().enumerate() {
            out[2 * i..2 * i + 2].copy_from_slice(&c.to_le_bytes());
        }
    }
}

/// An element of `N` bytes, so the decoder is told the stride.
#[derive(Clone, Copy)]
struct Elem<const N: usize>([u8; N]);

impl<const N: usize> Default for Elem<N> {
    fn default() -> Self {
        Elem([0; N])
    }
}

fn decode_as<const N: usize>(
    encoded: &[u8],
    count: usize,
) -> std::result::Result<Vec<u8>, ::meshopt::Error> {
    let v: Vec<Elem<N>> = ::meshopt::decode_vertex_buffer(encoded, count)?;
    Ok(v.iter().flat_map(|e| e.0).collect())
}

macro_rules! by_stride {
    ($encoded:expr, $count:expr, $stride:expr; $($n:literal)*) => {
        match $stride {
            $($n => decode_as::<$n>($encoded, $count),)*
            s => Err(::meshopt::Error::Memory(format!("unsupported stride {s}").into())),
        }
    };
}

/// `meshopt`'s vertex decoder for a stride known only at run time (a
/// multiple of 4 up to 256).
fn decode_vertices(
    encoded: &[u8],
    count: usize,
    stride: usize,
) -> std::result::Result<Vec<u8>, ::meshopt::Error> {
    by_stride!(encoded, count, stride;
        4 8 12 16 20 24 28 32 36 40 44 48 52 56 60 64
        68 72 76 80 84 88 92 96 100 104 108 112 116 120 124 128
        132 136 140 144 148 152 156 160 164 168 172 176 180 184 188 192
        196 200 204 208 212 216 220 224 228 232 236 240 244 248 252 256)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn vertex_and_index_streams_round_trip() {
        let vertices: Vec<[u16; 4]> = (0..100u16).map(|i| [i, i * 3, 7, 0]).collect();
        let encoded = ::meshopt::encode_vertex_buffer(&vertices).unwrap();
        let bytes = decode_view(&encoded, 100, 8, "ATTRIBUTES", "NONE").unwrap();
        let expected: Vec<u8> = vertices
            .iter()
            .flatten()
            .flat_map(|c| c.to_le_bytes())
            .collect();
        assert_eq!(bytes, expected);

        let indices: Vec<u32> = vec![0, 1, 2, 2, 1, 3, 3, 1, 4];
        let encoded = ::meshopt::encode_index_buffer(&indices, 5).unwrap();
        let bytes = decode_view(&encoded, 9, 2, "TRIANGLES", "NONE").unwrap();
        let back: Vec<u32> = bytes
            .chunks_exact(2)
            .map(|c| u32::from(u16::from_le_bytes([c[0], c[1]])))
            .collect();
        assert_eq!(back, indices);
        let encoded = ::meshopt::encode_index_sequence(&indices, 5).unwrap();
        let bytes = decode_view(&encoded, 9, 4, "INDICES", "NONE").unwrap();
        let back: Vec<u32> = bytes
            .chunks_exact(4)
            .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect();
        assert_eq!(back, indices);
    }

    #[test]
    fn a_corrupt_stream_is_a_clear_error() {
        let vertices: Vec<[u8; 4]> = (0..64u8).map(|i| [i, 2 * i, 3, 4]).collect();
        let mut encoded = ::meshopt::encode_vertex_buffer(&vertices).unwrap();
        // Control: the intact stream decodes.
        assert!(decode_view(&encoded, 64, 4, "ATTRIBUTES", "NONE").is_ok());
        // A bad header byte, then a stream cut short.
        let mut bad_header = encoded.clone();
        bad_header[0] = 0x00;
        let e = decode_view(&bad_header, 64, 4, "ATTRIBUTES", "NONE").unwrap_err();
        assert!(e.contains("ATTRIBUTES data is corrupt"), "{e}");
        encoded.truncate(encoded.len() / 2);
        let e = decode_view(&encoded, 64, 4, "ATTRIBUTES", "NONE").unwrap_err();
        assert!(e.contains("corrupt"), "{e}");
        let e = decode_view(&[0xe1, 0, 0], 3, 2, "TRIANGLES", "NONE").unwrap_err();
        assert!(e.contains("TRIANGLES data is corrupt"), "{e}");
    }

    #[test]
    fn filters_match_hand_computed_values() {
        // OCTAHEDRAL, 8-bit (the extension's reference decoder): x = X/Z,
        // y = Y/Z with Z the stored scale (127), z = 1 − |x| − |y|; when
        // z < 0, t = −z moves x and y toward 0 by t; the vector is then
        // normalized and scaled by 127, W kept.
        // (127, 0) is +X: z = 0 → (127, 0, 0).
        // (−64, 70): z = 1 − 134/127 = −0.0551 → x = −0.4488, y = 0.4961,
        // length 0.6712 → (−84.92, 93.86, −10.43) → (−85, 94, −10).
        let elems: Vec<[u8; 4]> = vec![[127, 0, 127, 9], [(-64i8) as u8, 70, 127, 0]];
        let encoded = ::meshopt::encode_vertex_buffer(&elems).unwrap();
        let out = decode_view(&encoded, 2, 4, "ATTRIBUTES", "OCTAHEDRAL").unwrap();
        let v: Vec<i8> = out.iter().map(|&b| b as i8).collect();
        assert_eq!(v, vec![127, 0, 0, 9, -85, 94, -10, 0]);

        // EXPONENTIAL: 0x0A_000003 = 3 · 2^10 = 3072.0; 0xFF_FFFFFF =
        // −1 · 2^−1 = −0.5 (signed 24-bit mantissa, signed 8-bit exponent).
        let raw: Vec<[u32; 2]> = vec![[0x0A00_0003, 0xFFFF_FFFF]];
        let encoded = ::meshopt::encode_vertex_buffer(&raw).unwrap();
        let out = decode_view(&encoded, 1, 8, "ATTRIBUTES", "EXPONENTIAL").unwrap();
        let f = |i: usize| f32::from_le_bytes([out[i], out[i + 1], out[i + 2], out[i + 3]]);
        assert_eq!((f(0), f(4)), (3072.0, -0.5));

        // QUATERNION, 16-bit: the crate's encoder's output for the identity
        // rotation decodes back to it (w = 32767).
        let q = ::meshopt::encode_filter_quat(&[[0.0, 0.0, 0.0, 1.0]], 12);
        let encoded = ::meshopt::encode_vertex_buffer(&q).unwrap();
        let out = decode_view(&encoded, 1, 8, "ATTRIBUTES", "QUATERNION").unwrap();
        let s: Vec<i16> = out
            .chunks_exact(2)
            .map(|c| i16::from_le_bytes([c[0], c[1]]))
            .collect();
        assert_eq!(s, vec![0, 0, 0, 32767]);
    }

    #[test]
    fn views_that_cannot_be_decoded_are_named() {
        let e = decode_view(&[], 1, 6, "ATTRIBUTES", "NONE").unwrap_err();
        assert!(e.contains("byteStride 6"), "{e}");
        let e = decode_view(&[], 1, 8, "ATTRIBUTES", "COLOR").unwrap_err();
        assert!(e.contains("\"COLOR\""), "{e}");
        let e = decode_view(&[], 4, 2, "TRIANGLES", "NONE").unwrap_err();
        assert!(e.contains("multiple of 3"), "{e}");
        let e = decode_view(&[], 1, 2, "POINTS", "NONE").unwrap_err();
        assert!(e.contains("\"POINTS\""), "{e}");
    }
}
