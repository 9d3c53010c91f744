//! Accessors read by hand after checked arithmetic on every offset, so
//! malformed files give errors instead of panics; per-mesh bounds and
//! triangle counts.

use super::*;

/// The checked location of an accessor's elements in a resolved buffer.
pub(crate) struct AccessorBytes<'b> {
    /// The buffer view's bytes.
    view: &'b [u8],
    /// Byte offset of element 0 within `view`.
    offset: usize,
    /// Bytes from one element to the next.
    stride: usize,
    /// Number of elements.
    pub(crate) count: usize,
}

impl AccessorBytes<'_> {
    /// The bytes of element `k` (`k < count`), starting at its first byte.
    pub(crate) fn element(&self, k: usize) -> &[u8] {
        &self.view[self.offset + k * self.stride..]
    }
}

/// Validates an accessor with checked arithmetic before any byte is read:
/// no sparse storage, `count ≥ 1`, a buffer view, a stride of at least the
/// element size and at most 252, and every element inside the view and the
/// view inside its buffer.
pub(crate) fn checked_accessor<'b>(
    acc: &gltf::Accessor,
    buffers: &'b [Cow<'_, [u8]>],
    what: &str,
) -> Result<AccessorBytes<'b>> {
    let a = acc.index();
    if acc.sparse().is_some() {
        return Err(Error::bad(
            what,
            format!("accessor {a} is sparse; sparse accessors are not supported"),
        ));
    }
    let count = acc.count();
    if count == 0 {
        return Err(Error::bad(what, format!("accessor {a} has count 0")));
    }
    let Some(view) = acc.view() else {
        return Err(Error::bad(what, format!("accessor {a} has no bufferView")));
    };
    let v = view.index();
    let elem = acc.size();
    let stride = match view.stride() {
        None => elem,
        Some(s) if s < elem => {
            return Err(Error::bad(
                what,
                format!(
                    "bufferView {v} byteStride {s} is smaller than the {elem}-byte element of \
                     accessor {a}"
                ),
            ));
        }
        Some(s) if s > MAX_STRIDE => {
            return Err(Error::bad(
                what,
                format!("bufferView {v} byteStride {s} exceeds {MAX_STRIDE}"),
            ));
        }
        Some(s) => s,
    };
    let offset = acc.offset();
    let needed = stride
        .checked_mul(count - 1)
        .and_then(|n| n.checked_add(offset))
        .and_then(|n| n.checked_add(elem));
    let view_len = view.length();
    match needed {
        Some(n) if n <= view_len => {}
        _ => {
            return Err(Error::bad(
                what,
                format!(
                    "accessor {a} (byteOffset {offset}, count {count}, stride {stride}) does not \
                     fit in bufferView {v} ({view_len} bytes)"
                ),
            ));
        }
    }
    let b = view.buffer().index();
    let data: &[u8] = buffers
        .get(b)
        .ok_or_else(|| Error::Internal(format!("buffer {b} was not resolved")))?;
    let start = view.offset();
    match start.checked_add(view_len) {
        Some(end) if end <= data.len() => Ok(AccessorBytes {
            view: &data[start..end],
            offset,
            stride,
            count,
        }),
        _ => Err(Error::bad(
            what,
            format!(
                "bufferView {v} (byteOffset {start}, byteLength {view_len}) lies outside buffer \
                 {b} ({} bytes)",
                data.len()
            ),
        )),
    }
}

/// Reads a mesh once: local bounds from its vertex positions, triangle count
/// from its indices (range-checked) and modes, and its primitive count.
pub(super) fn mesh_info(
    mesh: &gltf::Mesh,
    buffers: &[Cow<'_, [u8]>],
    source: &str,
) -> Result<MeshInfo> {
    let m = mesh.index();
    let prim_count = mesh.primitives().len();
    if prim_count == 0 {
        return Err(Error::bad(
            format!("{source}: mesh {m}"),
            "has no primitives",
        ));
    }
    let draw_calls = u32::try_from(prim_count).map_err(|_| {
        Error::bad(
            format!("{source}: mesh {m}"),
            format!("{prim_count} primitives are too many"),
        )
    })?;
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    let mut triangles: u64 = 0;
    for prim in mesh.primitives() {
        let p = prim.index();
        let what = format!("{source}: mesh {m} primitive {p} POSITION");
        let pos = prim
            .get(&gltf::Semantic::Positions)
            .ok_or_else(|| Error::bad(&what, "is missing"))?;
        let points = read_floats::<3>(&pos, buffers, &what, Dimensions::Vec3)?;
        for v in &points {
            for i in 0..3 {
                lo[i] = lo[i].min(v[i]);
                hi[i] = hi[i].max(v[i]);
            }
        }
        let vertices = points.len();

        let elements = match prim.indices() {
            None => vertices,
            Some(idx) => {
                let what = format!("{source}: mesh {m} primitive {p} indices");
                check_indices(&idx, buffers, vertices, &what)?
            }
        };
        let elements = elements as u64;
        let tris = match prim.mode() {
            Mode::Triangles => elements / 3,
            Mode::TriangleStrip | Mode::TriangleFan => elements.saturating_sub(2),
            Mode::Points | Mode::Lines | Mode::LineLoop | Mode::LineStrip => 0,
        };
        triangles = triangles.checked_add(tris).ok_or_else(|| {
            Error::bad(
                format!("{source}: mesh {m}"),
                "the triangle count does not fit in 64 bits",
            )
        })?;
    }
    Ok(MeshInfo {
        min: DVec3::new(lo[0].into(), lo[1].into(), lo[2].into()),
        max: DVec3::new(hi[0].into(), hi[1].into(), hi[2].into()),
        triangles,
        draw_calls,
    })
}

/// An accessor's type as glTF spells it, e.g. `VEC3 FLOAT`.
pub(crate) fn type_name(acc: &gltf::Accessor) -> String {
    let dims = match acc.dimensions() {
        Dimensions::Scalar => "SCALAR",
        Dimensions::Vec2 => "VEC2",
        Dimensions::Vec3 => "VEC3",
        Dimensions::Vec4 => "VEC4",
        Dimensions::Mat2 => "MAT2",
        Dimensions::Mat3 => "MAT3",
        Dimensions::Mat4 => "MAT4",
    };
    let component = match acc.data_type() {
        DataType::I8 => "BYTE",
        DataType::U8 => "UNSIGNED_BYTE",
        DataType::I16 => "SHORT",
        DataType::U16 => "UNSIGNED_SHORT",
        DataType::U32 => "UNSIGNED_INT",
        DataType::F32 => "FLOAT",
    };
    format!("{dims} {component}")
}

/// Validates an indices accessor (SCALAR of U8/U16/U32) and that every index
/// is below `vertices`; returns the index count.
pub(crate) fn check_indices(
    idx: &gltf::Accessor,
    buffers: &[Cow<'_, [u8]>],
    vertices: usize,
    what: &str,
) -> Result<usize> {
    if idx.dimensions() != Dimensions::Scalar
        || !matches!(
            idx.data_type(),
            DataType::U8 | DataType::U16 | DataType::U32
        )
    {
        return Err(Error::bad(
            what,
            format!(
                "accessor {} is {}, expected SCALAR UNSIGNED_BYTE, UNSIGNED_SHORT or \
                 UNSIGNED_INT",
                idx.index(),
                type_name(idx)
            ),
        ));
    }
    let data = checked_accessor(idx, buffers, what)?;
    let width = match idx.data_type() {
        DataType::U8 => 1,
        DataType::U16 => 2,
        _ => 4,
    };
    let read = |k: usize| -> u64 {
        let e = data.element(k);
        match width {
            1 => u64::from(e[0]),
            2 => u64::from(u16::from_le_bytes([e[0], e[1]])),
            _ => u64::from(u32::from_le_bytes([e[0], e[1], e[2], e[3]])),
        }
    };
    let limit = vertices as u64;
    if let Some(k) = (0..data.count).find(|&k| read(k) >= limit) {
        return Err(Error::bad(
            what,
            format!(
                "index {k} is {}, out of range for {vertices} vertices",
                read(k)
            ),
        ));
    }
    Ok(data.count)
}
