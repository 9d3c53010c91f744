//! Vertex attributes as floats, whatever their component type:
//! `KHR_mesh_quantization` stores positions, normals and texture
//! coordinates as 8- or 16-bit integers, normalized or not (`gltfpack`'s
//! default). A normalized integer becomes a float by the glTF rules
//! (§3.11): `c / 255` and `c / 65535` unsigned, `max(c / 127, −1)` and
//! `max(c / 32767, −1)` signed; a plain integer keeps its value. The scale
//! and offset that undo the quantization are node transforms (or a
//! `KHR_texture_transform` for texture coordinates), applied where every
//! transform is.

use super::*;

/// One component of an element, as a float.
pub(crate) fn component(data_type: DataType, normalized: bool, e: &[u8], i: usize) -> f32 {
    match (data_type, normalized) {
        (DataType::F32, _) => {
            f32::from_le_bytes([e[4 * i], e[4 * i + 1], e[4 * i + 2], e[4 * i + 3]])
        }
        (DataType::U8, false) => f32::from(e[i]),
        (DataType::U8, true) => f32::from(e[i]) / 255.0,
        (DataType::I8, false) => f32::from(e[i] as i8),
        (DataType::I8, true) => (f32::from(e[i] as i8) / 127.0).max(-1.0),
        (DataType::U16, n) => {
            let c = f32::from(u16::from_le_bytes([e[2 * i], e[2 * i + 1]]));
            if n { c / 65535.0 } else { c }
        }
        (DataType::I16, n) => {
            let c = f32::from(i16::from_le_bytes([e[2 * i], e[2 * i + 1]]));
            if n { (c / 32767.0).max(-1.0) } else { c }
        }
        (DataType::U32, _) => {
            u32::from_le_bytes([e[4 * i], e[4 * i + 1], e[4 * i + 2], e[4 * i + 3]]) as f32
        }
    }
}

/// Reads a float attribute of `N` components (`dims`) stored as `FLOAT` or
/// as (normalized or plain) `BYTE`, `UNSIGNED_BYTE`, `SHORT` or
/// `UNSIGNED_SHORT`; every value must be finite.
pub(crate) fn read_floats<const N: usize>(
    acc: &gltf::Accessor,
    buffers: &[Cow<'_, [u8]>],
    what: &str,
    dims: Dimensions,
) -> Result<Vec<[f32; N]>> {
    if acc.dimensions() != dims || acc.data_type() == DataType::U32 {
        let expected = match dims {
            Dimensions::Vec2 => "VEC2",
            Dimensions::Vec3 => "VEC3",
            _ => "VEC4",
        };
        return Err(Error::bad(
            what,
            format!(
                "accessor {} is {}, expected {expected} of FLOAT, BYTE, UNSIGNED_BYTE, SHORT or \
                 UNSIGNED_SHORT",
                acc.index(),
                type_name(acc)
            ),
        ));
    }
    let (data_type, normalized) = (acc.data_type(), acc.normalized());
    let data = checked_accessor(acc, buffers, what)?;
    let mut out = Vec::with_capacity(data.count);
    for k in 0..data.count {
        let e = data.element(k);
        let v: [f32; N] = std::array::from_fn(|i| component(data_type, normalized, e, i));
        if !v.iter().all(|c| c.is_finite()) {
            return Err(Error::bad(
                what,
                format!("vertex {k} is not finite ({v:?})"),
            ));
        }
        out.push(v);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_component_type_dequantizes_by_the_gltf_rules() {
        let c = |t, n, bytes: &[u8]| component(t, n, bytes, 0);
        // Unsigned byte: plain keeps the value, normalized divides by 255.
        assert_eq!(c(DataType::U8, false, &[200]), 200.0);
        assert_eq!(c(DataType::U8, true, &[255]), 1.0);
        assert_eq!(c(DataType::U8, true, &[51]), 0.2);
        // Signed byte: −128 clamps to −1 when normalized.
        assert_eq!(c(DataType::I8, false, &[0x80]), -128.0);
        assert_eq!(c(DataType::I8, true, &[0x80]), -1.0);
        assert_eq!(c(DataType::I8, true, &[0x81]), -1.0);
        assert_eq!(c(DataType::I8, true, &[127]), 1.0);
        // Unsigned short, little-endian.
        assert_eq!(c(DataType::U16, false, &[0x34, 0x12]), 4660.0);
        assert_eq!(c(DataType::U16, true, &[0xff, 0xff]), 1.0);
        // Signed short.
        assert_eq!(c(DataType::I16, false, &[0x00, 0x80]), -32768.0);
        assert_eq!(c(DataType::I16, true, &[0x00, 0x80]), -1.0);
        assert_eq!(c(DataType::I16, true, &[0xff, 0x3f]), 16383.0 / 32767.0);
        // Float, and the second component of an element.
        assert_eq!(c(DataType::F32, false, &1.5f32.to_le_bytes()), 1.5);
        assert_eq!(
            component(DataType::I16, false, &[0, 0, 0xfe, 0xff], 1),
            -2.0
        );
    }
}
