//! The glTF document before anything is read: the GLB header, the
//! `gltf` crate's errors, and the checks of the JSON root the crate lacks
//! (extensions, counts, strides).

use super::*;

/// Checks the GLB header ourselves (a `length` below 12 overflows inside
/// `gltf`), with clearer messages for truncated files; the header's length
/// must be the file's (glTF 2.0 §4.4.2: the total length of the GLB).
pub(crate) fn check_glb_header(bytes: &[u8], source: &str) -> Result<()> {
    if !bytes.starts_with(b"glTF") {
        return Ok(());
    }
    if bytes.len() < 12 {
        return Err(Error::bad(
            source,
            format!(
                "truncated GLB: {} bytes, shorter than the 12-byte header",
                bytes.len()
            ),
        ));
    }
    let word =
        |at: usize| u32::from_le_bytes([bytes[at], bytes[at + 1], bytes[at + 2], bytes[at + 3]]);
    let version = word(4);
    if version != 2 {
        return Err(Error::bad(
            source,
            format!("GLB version {version} is not supported (only glTF 2.0)"),
        ));
    }
    let length = word(8) as usize;
    if length < 20 {
        return Err(Error::bad(
            source,
            format!("GLB header length {length} is too small for a header and a JSON chunk"),
        ));
    }
    if length > bytes.len() {
        return Err(Error::bad(
            source,
            format!(
                "truncated GLB: the header says {length} bytes but there are only {}",
                bytes.len()
            ),
        ));
    }
    if length < bytes.len() {
        return Err(Error::bad(
            source,
            format!(
                "malformed GLB: the header says {length} bytes but the file has {} \
                 (data after the GLB's end)",
                bytes.len()
            ),
        ));
    }
    Ok(())
}

/// Formats a `gltf` crate error, keeping long validation reports short.
pub(crate) fn gltf_error(source: &str, e: gltf::Error) -> Error {
    match e {
        gltf::Error::Validation(errors) => {
            let shown: Vec<String> = errors
                .iter()
                .take(5)
                .map(|(path, err)| format!("{path}: {err}"))
                .collect();
            let more = errors.len().saturating_sub(shown.len());
            let mut message = format!("invalid glTF: {}", shown.join("; "));
            if more > 0 {
                message.push_str(&format!(" (and {more} more)"));
            }
            Error::bad(source, message)
        }
        gltf::Error::Binary(e) => Error::bad(source, format!("malformed GLB: {e}")),
        gltf::Error::Deserialize(e) => Error::bad(source, format!("malformed glTF JSON: {e}")),
        e => Error::bad(source, format!("malformed glTF: {e}")),
    }
}

/// Checks what `gltf`'s own validation would panic on, and handles
/// `extensionsRequired`, before running that validation.
pub(crate) fn precheck_root(root: &mut gltf::json::Root, source: &str) -> Result<()> {
    precheck_root_with(root, source, false)
}

/// [`precheck_root`]; with `keep_base_color`, materials, base colour
/// textures, their images and samplers are kept (every other texture slot
/// is cleared, a KTX2 texture without a fallback reads the image its
/// `KHR_texture_basisu` names, and a base colour texture without a usable
/// `source` is dropped from its material).
pub(crate) fn precheck_root_with(
    root: &mut gltf::json::Root,
    source: &str,
    keep_base_color: bool,
) -> Result<()> {
    use gltf::json::mesh::Semantic;
    use gltf::json::validation::Checked;

    if root.nodes.len() > MAX_NODES {
        return Err(Error::bad(
            format!("{source}: nodes"),
            format!(
                "{} nodes, more than the limit of {MAX_NODES}",
                root.nodes.len()
            ),
        ));
    }
    for ext in &root.extensions_required {
        let read_here = [
            "MSFT_lod",
            "KHR_mesh_quantization",
            EXT_MESHOPT,
            EXT_INSTANCING,
            KHR_DRACO,
        ];
        if !APPEARANCE_EXTENSIONS.contains(&ext.as_str()) && !read_here.contains(&ext.as_str()) {
            return Err(Error::bad(
                format!("{source}: extensionsRequired"),
                format!("the file requires the unknown extension {ext}"),
            ));
        }
    }
    // Placement ignores appearance, so these need not be understood
    // (`MSFT_lod` is read by `walk_scene`, quantized attributes by
    // `read_floats`, compressed views by `decode_compressed_views`), and
    // materials, textures and images are dropped before validation: a
    // KTX2-only texture (no `source`) or a broken image then cannot reject
    // a scene whose geometry is fine.
    root.extensions_required.clear();
    if keep_base_color {
        let (textures, images, samplers, materials) = (
            root.textures.len(),
            root.images.len(),
            root.samplers.len(),
            root.materials.len(),
        );
        // A KTX2 texture (`KHR_texture_basisu`) without a fallback names
        // its image in the extension: read that one.
        for t in &mut root.textures {
            let basisu = t
                .extensions
                .as_ref()
                .and_then(|e| e.others.get("KHR_texture_basisu"))
                .and_then(|b| b.get("source"))
                .and_then(serde_json::Value::as_u64)
                .and_then(|i| u32::try_from(i).ok());
            if let Some(i) = basisu
                && t.source.value() >= images
                && (i as usize) < images
            {
                t.source = gltf::json::Index::new(i);
            }
        }
        let usable: Vec<bool> = root
            .textures
            .iter()
            .map(|t| t.source.value() < images && t.sampler.is_none_or(|s| s.value() < samplers))
            .collect();
        for m in &mut root.materials {
            m.normal_texture = None;
            m.occlusion_texture = None;
            m.emissive_texture = None;
            m.pbr_metallic_roughness.metallic_roughness_texture = None;
            if let Some(t) = &m.pbr_metallic_roughness.base_color_texture
                && (t.index.value() >= textures || !usable[t.index.value()])
            {
                m.pbr_metallic_roughness.base_color_texture = None;
            }
        }
        for mesh in &mut root.meshes {
            for prim in &mut mesh.primitives {
                if prim.material.is_some_and(|m| m.value() >= materials) {
                    prim.material = None;
                }
            }
        }
    } else {
        root.materials.clear();
        root.textures.clear();
        root.images.clear();
        root.samplers.clear();
        for mesh in &mut root.meshes {
            for prim in &mut mesh.primitives {
                prim.material = None;
            }
        }
    }

    let accessors = root.accessors.len();
    // The accessors of a Draco-compressed primitive have no data of their
    // own until `decode_draco_primitives` decodes them, which validation
    // would refuse: they point at the compressed view meanwhile (their
    // bytes are never read from there).
    let views = root.buffer_views.len();
    for mesh in &root.meshes {
        for prim in &mesh.primitives {
            let Some(view) = prim
                .extensions
                .as_ref()
                .and_then(|e| e.others.get(KHR_DRACO))
                .and_then(|d| d.get("bufferView"))
                .and_then(serde_json::Value::as_u64)
                .and_then(|v| u32::try_from(v).ok())
                .filter(|&v| (v as usize) < views)
            else {
                continue;
            };
            for a in prim.attributes.values().chain(&prim.indices) {
                if let Some(acc) = root.accessors.get_mut(a.value())
                    && acc.buffer_view.is_none()
                    && acc.sparse.is_none()
                {
                    acc.buffer_view = Some(gltf::json::Index::new(view));
                }
            }
        }
    }
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, prim) in mesh.primitives.iter().enumerate() {
            if let Some(index) = prim.attributes.get(&Checked::Valid(Semantic::Positions))
                && index.value() >= accessors
            {
                return Err(Error::bad(
                    format!("{source}: mesh {m} primitive {p} POSITION"),
                    format!(
                        "accessor {} does not exist (the file has {accessors} accessors)",
                        index.value()
                    ),
                ));
            }
        }
    }
    Ok(())
}
