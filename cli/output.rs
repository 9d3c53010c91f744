//! Writing outputs: atomically to files (temporary file, then rename), into
//! devices and pipes as they are, or to standard output.

use std::io::{BufWriter, Write};
use std::path::Path;

use optimizer::{Error, Result};

/// Writes `bytes` to `path` atomically (temporary file + rename), or to
/// standard output.
pub fn write_output(path: Option<&Path>, bytes: &[u8]) -> Result<()> {
    write_with(path, |w| w.write_all(bytes))
}

/// Writes what `write` writes to `path` like [`write_output`], streamed
/// through a buffer: a large output is never held whole in memory.
pub fn write_with(
    path: Option<&Path>,
    write: impl FnOnce(&mut dyn Write) -> std::io::Result<()>,
) -> Result<()> {
    let buffered = |f: &mut dyn Write| {
        let mut w = BufWriter::new(f);
        write(&mut w)?;
        w.flush()
    };
    match path {
        None => buffered(&mut std::io::stdout().lock()).map_err(|e| Error::io("<stdout>", e)),
        Some(p) => {
            // Through a symbolic link to its target; into anything that is
            // not a regular file (a device such as /dev/null, a pipe) write
            // directly: replacing it would destroy it.
            // Special files (/dev/stdout, /dev/null, /proc/self/fd/N) are
            // written into, whatever they lead to.
            if p.starts_with("/dev") || p.starts_with("/proc") {
                return std::fs::OpenOptions::new()
                    .append(true)
                    .open(p)
                    .and_then(|mut f| buffered(&mut f))
                    .map_err(|e| Error::io(p, e));
            }
            let resolved = match std::fs::metadata(p) {
                Ok(m) if m.is_dir() => {
                    return Err(Error::bad(p.display().to_string(), "is a directory"));
                }
                Ok(m) if !m.is_file() => {
                    return std::fs::OpenOptions::new()
                        .write(true)
                        .open(p)
                        .and_then(|mut f| buffered(&mut f))
                        .map_err(|e| Error::io(p, e));
                }
                Ok(_) => std::fs::canonicalize(p).unwrap_or_else(|_| p.to_path_buf()),
                // Not there yet: a dangling link is followed to where its
                // target will be.
                Err(_) => {
                    let mut r = p.to_path_buf();
                    for _ in 0..32 {
                        match std::fs::read_link(&r) {
                            Ok(target) => {
                                r = match r.parent() {
                                    Some(dir) if target.is_relative() => dir.join(target),
                                    _ => target,
                                }
                            }
                            Err(_) => break,
                        }
                    }
                    r
                }
            };
            let p = resolved.as_path();
            let dir = p
                .parent()
                .filter(|d| !d.as_os_str().is_empty())
                .unwrap_or(Path::new("."));
            let name = p
                .file_name()
                .ok_or_else(|| Error::bad(p.display().to_string(), "not a file path"))?;
            let tmp = dir.join(format!(
                ".{}.tmp{}",
                name.to_string_lossy(),
                std::process::id()
            ));
            if let Err(e) = std::fs::File::create(&tmp).and_then(|mut f| buffered(&mut f)) {
                let _ = std::fs::remove_file(&tmp);
                return Err(Error::io(p, e));
            }
            std::fs::rename(&tmp, p).map_err(|e| {
                let _ = std::fs::remove_file(&tmp);
                Error::io(p, e)
            })
        }
    }
}

/// `value` as the tool's JSON bytes ([`optimizer::files::write_json`]),
/// written like [`write_output`] but streamed: a placement of many
/// gigabytes is not held a second time as text.
pub fn write_json(path: Option<&Path>, value: &impl serde::Serialize) -> Result<()> {
    write_with(path, |w| optimizer::files::write_json(w, value))
}
