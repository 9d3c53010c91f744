//! Buffer resolution: the GLB `BIN` chunk, base64 `data:` URIs, and
//! relative files next to a local glTF; never absolute paths, other schemes
//! or `..`. A meshopt fallback buffer is never read: it has no bytes.

use super::*;

/// Resolves every buffer to its bytes, cut to the declared `byteLength`.
pub(crate) fn resolve_buffers<'a>(
    doc: &gltf::Document,
    blob: Option<&'a [u8]>,
    source: &str,
    base_dir: Option<&Path>,
) -> Result<Vec<Cow<'a, [u8]>>> {
    let mut out = Vec::with_capacity(doc.buffers().len());
    for buffer in doc.buffers() {
        let b = buffer.index();
        let what = format!("{source}: buffer {b}");
        let declared = buffer.length();
        if is_fallback(&buffer) {
            // Only compressed views (`EXT_meshopt_compression`) name it,
            // and they are decoded from elsewhere: never read.
            out.push(Cow::Borrowed(&[][..]));
            continue;
        }
        let data: Cow<'a, [u8]> = match buffer.source() {
            gltf::buffer::Source::Bin => Cow::Borrowed(blob.ok_or_else(|| {
                Error::bad(
                    &what,
                    "has no uri and there is no GLB BIN chunk to take its data from",
                )
            })?),
            gltf::buffer::Source::Uri(uri) => Cow::Owned(read_uri(uri, &what, base_dir)?),
        };
        if data.len() < declared {
            return Err(Error::bad(
                &what,
                format!(
                    "byteLength is {declared} but the data has only {} bytes",
                    data.len()
                ),
            ));
        }
        out.push(match data {
            Cow::Borrowed(d) => Cow::Borrowed(&d[..declared]),
            Cow::Owned(mut d) => {
                d.truncate(declared);
                Cow::Owned(d)
            }
        });
    }
    Ok(out)
}

/// Reads a buffer URI: a base64 `data:` URI, or (with a base directory) a
/// relative file path inside it.
pub(crate) fn read_uri(uri: &str, what: &str, base_dir: Option<&Path>) -> Result<Vec<u8>> {
    if let Some(rest) = strip_prefix_ignore_case(uri, "data:") {
        return decode_data_uri(rest, what);
    }
    let shown = shorten(uri);
    if let Some(scheme) = uri_scheme(uri) {
        return Err(Error::bad(
            what,
            format!(
                "uri \"{shown}\": the {scheme}: scheme is not allowed (only data: URIs and relative file paths)"
            ),
        ));
    }
    let Some(base_dir) = base_dir else {
        return Err(Error::bad(
            what,
            format!(
                "uri \"{shown}\": external buffer URIs are not allowed here; embed the buffers \
                 (a GLB or base64 data: URIs)"
            ),
        ));
    };
    let decoded = percent_decode(uri).ok_or_else(|| {
        Error::bad(
            what,
            format!("uri \"{shown}\" is not valid percent-encoded UTF-8"),
        )
    })?;
    if decoded.is_empty() {
        return Err(Error::bad(what, "uri is empty"));
    }
    if decoded.starts_with('/') || decoded.starts_with('\\') || Path::new(&decoded).has_root() {
        return Err(Error::bad(
            what,
            format!(
                "uri \"{shown}\": absolute paths are not allowed, only paths relative to the glTF file"
            ),
        ));
    }
    let relative = Path::new(&decoded);
    let escapes = decoded.split(['/', '\\']).any(|c| c == "..")
        || relative
            .components()
            .any(|c| !matches!(c, Component::Normal(_) | Component::CurDir));
    if escapes {
        return Err(Error::bad(
            what,
            format!("uri \"{shown}\": `..` path components are not allowed"),
        ));
    }
    let path = base_dir.join(relative);
    crate::files::read_file(&path, crate::files::MAX_SCENE_BYTES, "glTF resource")
}

/// Decodes the part of a `data:` URI after `data:`.
pub(super) fn decode_data_uri(rest: &str, what: &str) -> Result<Vec<u8>> {
    let Some((header, payload)) = rest.split_once(',') else {
        return Err(Error::bad(what, "data: URI has no `,` before its payload"));
    };
    let Some(media) = strip_suffix_ignore_case(header, ";base64") else {
        return Err(Error::bad(
            what,
            "data: URI is not base64-encoded (expected `;base64,`)",
        ));
    };
    let media = media.trim();
    let allowed = ["", "application/octet-stream", "application/gltf-buffer"];
    if !allowed.iter().any(|a| a.eq_ignore_ascii_case(media)) {
        return Err(Error::bad(
            what,
            format!(
                "data: URI media type \"{}\" is not a buffer type (application/octet-stream or \
                 application/gltf-buffer)",
                shorten(media)
            ),
        ));
    }
    const ENGINE: base64::engine::GeneralPurpose = base64::engine::GeneralPurpose::new(
        &base64::alphabet::STANDARD,
        base64::engine::GeneralPurposeConfig::new()
            .with_decode_padding_mode(base64::engine::DecodePaddingMode::Indifferent)
            .with_decode_allow_trailing_bits(true),
    );
    ENGINE
        .decode(payload.trim())
        .map_err(|e| Error::bad(what, format!("data: URI is not valid base64: {e}")))
}

/// The URI scheme (RFC 3986: a letter, then letters, digits, `+`, `-`, `.`,
/// then `:`), if any.
pub(super) fn uri_scheme(uri: &str) -> Option<&str> {
    let (scheme, _) = uri.split_once(':')?;
    let mut chars = scheme.chars();
    let first = chars.next()?;
    (first.is_ascii_alphabetic()
        && chars.all(|c| c.is_ascii_alphanumeric() || matches!(c, '+' | '-' | '.')))
    .then_some(scheme)
}

/// Decodes `%XX` escapes; `None` for a malformed escape or invalid UTF-8.
pub(super) fn percent_decode(s: &str) -> Option<String> {
    let bytes = s.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i] == b'%' {
            let hex = bytes.get(i + 1..i + 3)?;
            let hex = std::str::from_utf8(hex).ok()?;
            out.push(u8::from_str_radix(hex, 16).ok()?);
            i += 3;
        } else {
            out.push(bytes[i]);
            i += 1;
        }
    }
    String::from_utf8(out).ok()
}

pub(super) fn strip_prefix_ignore_case<'s>(s: &'s str, prefix: &str) -> Option<&'s str> {
    let head = s.get(..prefix.len())?;
    head.eq_ignore_ascii_case(prefix)
        .then(|| &s[prefix.len()..])
}

pub(super) fn strip_suffix_ignore_case<'s>(s: &'s str, suffix: &str) -> Option<&'s str> {
    let at = s.len().checked_sub(suffix.len())?;
    let tail = s.get(at..)?;
    tail.eq_ignore_ascii_case(suffix).then(|| &s[..at])
}

/// A URI or media type cut to a length fit for an error message.
pub(super) fn shorten(s: &str) -> String {
    const MAX: usize = 80;
    if s.chars().count() <= MAX {
        s.to_string()
    } else {
        let head: String = s.chars().take(MAX).collect();
        format!("{head}…")
    }
}

/// The document `root` with `decoded` (what a compression extension's
/// data decodes to) as one more buffer, appended to `buffers` too; the
/// views the decoder added point into it.
pub(crate) fn with_decoded_buffer<'a>(
    mut root: gltf::json::Root,
    buffers: &mut Vec<Cow<'a, [u8]>>,
    decoded: Vec<u8>,
    source: &str,
) -> Result<gltf::Document> {
    root.buffers.push(gltf::json::Buffer {
        byte_length: gltf::json::validation::USize64(decoded.len() as u64),
        name: None,
        uri: None,
        extensions: None,
        extras: Default::default(),
    });
    buffers.push(Cow::Owned(decoded));
    gltf::Document::from_json(root).map_err(|e| gltf_error(source, e))
}
