//! `KHR_draco_mesh_compression`: primitives whose indices and attributes
//! are stored as one Draco bitstream in a buffer view, as `gltf-transform
//! draco`, `gltf-pipeline -d` and most web pipelines write them.
//!
//! Every compressed primitive is decoded once, after the buffers are
//! resolved (and meshopt views decoded), into one extra buffer appended to
//! the document: its indices accessor becomes `UNSIGNED_INT` over the
//! decoded faces, each attribute the extension names becomes `FLOAT` over
//! the decoded values (integers the stream marks normalized are converted
//! by the glTF rules), and the extension is removed, so the loaders read
//! the primitive like any other. The decoding is the `draco-core` crate's
//! (pure Rust, the Draco bitstream: sequential and EdgeBreaker meshes,
//! quantized and predicted attributes); panics inside it are caught with
//! the rest of the loader (`guarded`).
//!
//! Checked: the extension object's shape, its buffer view inside its
//! buffer, every named attribute present in the primitive and in the
//! stream with the accessor's component count, and the decoded bytes of all
//! primitives together at most [`MAX_DECODED_BYTES`].

use super::*;
use draco_core::{DataType as DracoType, DecoderBuffer, Mesh, MeshDecoder, PointIndex};
use gltf::json::accessor::{ComponentType, GenericComponentType};
use gltf::json::validation::{Checked, USize64};

/// The extension's name.
pub(crate) const KHR_DRACO: &str = "KHR_draco_mesh_compression";

/// One primitive's extension object.
#[derive(serde::Deserialize)]
#[serde(rename_all = "camelCase")]
struct Compressed {
    buffer_view: usize,
    attributes: std::collections::BTreeMap<String, u32>,
}

/// Decodes every Draco-compressed primitive of `doc` (see the module
/// notes); returns the document with their accessors pointing at the
/// decoded data, which is appended to `buffers`. A document without such
/// primitives is returned unchanged.
pub(crate) fn decode_draco_primitives<'a>(
    doc: gltf::Document,
    buffers: &mut Vec<Cow<'a, [u8]>>,
    source: &str,
) -> Result<gltf::Document> {
    let compressed = doc
        .meshes()
        .flat_map(|m| m.primitives())
        .any(|p| p.extension_value(KHR_DRACO).is_some());
    if !compressed {
        return Ok(doc);
    }
    let mut root = doc.into_json();
    let target = gltf::json::Index::new(root.buffers.len() as u32);
    let mut decoded: Vec<u8> = Vec::new();
    for m in 0..root.meshes.len() {
        for p in 0..root.meshes[m].primitives.len() {
            let prim = &mut root.meshes[m].primitives[p];
            let Some(ext) = prim
                .extensions
                .as_mut()
                .and_then(|e| e.others.remove(KHR_DRACO))
            else {
                continue;
            };
            let what = format!("{source}: mesh {m} primitive {p} {KHR_DRACO}");
            let c: Compressed = serde_json::from_value(ext)
                .map_err(|e| Error::bad(&what, format!("malformed extension object: {e}")))?;
            let mesh = decode_stream(&root, buffers, &c, &what)?;
            let prim = &root.meshes[m].primitives[p];
            let indices = prim.indices.map(|i| i.value());
            let attributes: Vec<(String, usize)> = c
                .attributes
                .keys()
                .map(|name| {
                    let key: Option<Checked<gltf::json::mesh::Semantic>> =
                        serde_json::from_value(serde_json::Value::String(name.clone())).ok();
                    key.and_then(|k| prim.attributes.get(&k))
                        .map(|a| (name.clone(), a.value()))
                        .ok_or_else(|| {
                            Error::bad(
                                &what,
                                format!(
                                    "names attribute {name}, which the primitive does not have"
                                ),
                            )
                        })
                })
                .collect::<Result<_>>()?;

            // Faces as UNSIGNED_INT indices.
            let faces = mesh.num_faces();
            let mut bytes = Vec::with_capacity(faces * 12);
            for f in 0..faces {
                for v in mesh.face(draco_core::FaceIndex(f as u32)) {
                    bytes.extend_from_slice(&v.0.to_le_bytes());
                }
            }
            let index_accessor = match indices {
                Some(i) => i,
                None => {
                    // Faces the primitive did not index: a new accessor.
                    root.accessors.push(gltf::json::Accessor {
                        buffer_view: None,
                        byte_offset: None,
                        count: USize64(0),
                        component_type: Checked::Valid(GenericComponentType(ComponentType::U32)),
                        extensions: None,
                        extras: Default::default(),
                        type_: Checked::Valid(gltf::json::accessor::Type::Scalar),
                        min: None,
                        max: None,
                        name: None,
                        normalized: false,
                        sparse: None,
                    });
                    let i = root.accessors.len() - 1;
                    root.meshes[m].primitives[p].indices = Some(gltf::json::Index::new(i as u32));
                    i
                }
            };
            let view = push_view(&mut root, &mut decoded, target, &bytes, &what)?;
            set_accessor(
                &mut root,
                index_accessor,
                view,
                ComponentType::U32,
                faces * 3,
            );

            // Attributes as FLOAT values, one per decoded point.
            let points = mesh.num_points();
            for ((name, accessor), &id) in attributes.iter().zip(c.attributes.values()) {
                let att = mesh.attribute_by_unique_id(id).ok_or_else(|| {
                    Error::bad(
                        &what,
                        format!(
                            "attribute {name} names Draco attribute {id}, which the stream lacks"
                        ),
                    )
                })?;
                let n = usize::from(att.num_components());
                let want = match root.accessors[*accessor].type_ {
                    Checked::Valid(t) => t.multiplicity(),
                    Checked::Invalid => 0,
                };
                if n != want {
                    return Err(Error::bad(
                        &what,
                        format!(
                            "attribute {name} has {n} components in the stream, accessor \
                             {accessor} {want}"
                        ),
                    ));
                }
                let floats = attribute_floats(att, points, n)
                    .map_err(|e| Error::bad(&what, format!("attribute {name}: {e}")))?;
                let bytes: Vec<u8> = floats.iter().flat_map(|v| v.to_le_bytes()).collect();
                let view = push_view(&mut root, &mut decoded, target, &bytes, &what)?;
                set_accessor(&mut root, *accessor, view, ComponentType::F32, points);
            }
        }
    }
    with_decoded_buffer(root, buffers, decoded, source)
}

/// Decodes the Draco stream in the buffer view `c` names.
fn decode_stream(
    root: &gltf::json::Root,
    buffers: &[Cow<'_, [u8]>],
    c: &Compressed,
    what: &str,
) -> Result<Mesh> {
    let view = root.buffer_views.get(c.buffer_view).ok_or_else(|| {
        Error::bad(
            what,
            format!(
                "bufferView {} does not exist (the file has {})",
                c.buffer_view,
                root.buffer_views.len()
            ),
        )
    })?;
    let data: &[u8] = buffers.get(view.buffer.value()).ok_or_else(|| {
        Error::bad(
            what,
            format!("bufferView {} names a missing buffer", c.buffer_view),
        )
    })?;
    let start = view.byte_offset.map_or(0, |o| o.0);
    let stream = start
        .checked_add(view.byte_length.0)
        .filter(|&end| end <= data.len() as u64)
        .map(|end| &data[start as usize..end as usize])
        .ok_or_else(|| {
            Error::bad(
                what,
                format!(
                    "bufferView {} ({} bytes at {start}) lies outside its buffer ({} bytes)",
                    c.buffer_view,
                    view.byte_length.0,
                    data.len()
                ),
            )
        })?;
    let mut mesh = Mesh::new();
    MeshDecoder::new()
        .decode(&mut DecoderBuffer::new(stream), &mut mesh)
        .map_err(|e| Error::bad(what, format!("the Draco stream does not decode: {e}")))?;
    Ok(mesh)
}

/// Appends `bytes` (4-byte aligned) to the decoded buffer as a new buffer
/// view; returns its index.
fn push_view(
    root: &mut gltf::json::Root,
    decoded: &mut Vec<u8>,
    target: gltf::json::Index<gltf::json::Buffer>,
    bytes: &[u8],
    what: &str,
) -> Result<gltf::json::Index<gltf::json::buffer::View>> {
    while !decoded.len().is_multiple_of(4) {
        decoded.push(0);
    }
    if (decoded.len() + bytes.len()) as u64 > MAX_DECODED_BYTES {
        return Err(Error::bad(
            what,
            format!(
                "the Draco primitives decode to more than the limit of {MAX_DECODED_BYTES} bytes"
            ),
        ));
    }
    root.buffer_views.push(gltf::json::buffer::View {
        buffer: target,
        byte_length: USize64(bytes.len() as u64),
        byte_offset: Some(USize64(decoded.len() as u64)),
        byte_stride: None,
        target: None,
        name: None,
        extensions: None,
        extras: Default::default(),
    });
    decoded.extend_from_slice(bytes);
    Ok(gltf::json::Index::new(root.buffer_views.len() as u32 - 1))
}

/// Points accessor `a` at `count` tightly packed elements of `view`.
fn set_accessor(
    root: &mut gltf::json::Root,
    a: usize,
    view: gltf::json::Index<gltf::json::buffer::View>,
    component: ComponentType,
    count: usize,
) {
    let acc = &mut root.accessors[a];
    acc.buffer_view = Some(view);
    acc.byte_offset = Some(USize64(0));
    acc.component_type = Checked::Valid(GenericComponentType(component));
    acc.normalized = false;
    acc.count = USize64(count as u64);
    acc.sparse = None;
}

/// The values of a decoded attribute at each of `points` points, `n`
/// components each, as floats (normalized integers by the glTF rules).
fn attribute_floats(
    att: &draco_core::PointAttribute,
    points: usize,
    n: usize,
) -> std::result::Result<Vec<f32>, String> {
    let (dt, normalized) = (att.data_type(), att.normalized());
    let size = dt.byte_length();
    let stride = usize::try_from(att.byte_stride()).map_err(|_| "a negative stride")?;
    if size == 0 || stride < n * size {
        return Err(format!("unreadable values ({dt:?}, stride {stride})"));
    }
    let data = att.buffer().data();
    let mut out = Vec::with_capacity(points * n);
    for p in 0..points {
        let v = att.mapped_index(PointIndex(p as u32)).0 as usize;
        let at = v
            .checked_mul(stride)
            .filter(|&at| at + n * size <= data.len())
            .ok_or_else(|| format!("point {p} maps to value {v}, outside the decoded values"))?;
        for k in 0..n {
            let e = &data[at + k * size..at + (k + 1) * size];
            let x = match dt {
                DracoType::Float32 => f32::from_le_bytes([e[0], e[1], e[2], e[3]]),
                DracoType::Float64 => f64::from_le_bytes(e.try_into().expect("8 bytes")) as f32,
                DracoType::Uint8 => component(DataType::U8, normalized, e, 0),
                DracoType::Int8 => component(DataType::I8, normalized, e, 0),
                DracoType::Uint16 => component(DataType::U16, normalized, e, 0),
                DracoType::Int16 => component(DataType::I16, normalized, e, 0),
                DracoType::Uint32 => u32::from_le_bytes([e[0], e[1], e[2], e[3]]) as f32,
                DracoType::Int32 => i32::from_le_bytes([e[0], e[1], e[2], e[3]]) as f32,
                other => return Err(format!("values of type {other:?}")),
            };
            if !x.is_finite() {
                return Err(format!("point {p} is not finite"));
            }
            out.push(x);
        }
    }
    Ok(out)
}
