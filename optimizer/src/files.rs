//! Reading input files within stated limits: only regular files (a link is
//! followed, but never to a device, pipe or directory: `/dev/zero` would
//! read until memory runs out), and never more bytes than the kind of file
//! may have, checked before and while reading.

use std::io::Read;
use std::path::Path;

use crate::{Error, Result};

/// Largest scene file, and largest buffer or image a glTF file refers to:
/// 4 GiB, the most a GLB's 32-bit length field can describe.
pub const MAX_SCENE_BYTES: u64 = 4 << 30;

/// Largest job file: 64 MiB (a job is a few kilobytes; a walkthrough path
/// of a million points fits).
pub const MAX_JOB_BYTES: u64 = 64 << 20;

/// Largest placement or PVS file: 4 GiB.
pub const MAX_PLACEMENT_BYTES: u64 = 4 << 30;

/// The bytes of the regular file at `path` (`what` names its kind in
/// errors), at most `limit` of them. A path that is not a regular file (a
/// device, pipe, socket or directory, also through a link) or holds more
/// than `limit` bytes is bad input naming the path; the file is not read
/// then. A file that grows past the limit while read is refused too.
pub fn read_file(path: &Path, limit: u64, what: &str) -> Result<Vec<u8>> {
    let meta = std::fs::metadata(path).map_err(|e| Error::io(path, e))?;
    let shown = path.display().to_string();
    if !meta.is_file() {
        let kind = if meta.is_dir() {
            "a directory"
        } else {
            "a device, pipe or socket"
        };
        return Err(Error::bad(
            shown,
            format!("{kind}, not a regular file: a {what} must be a file"),
        ));
    }
    let too_big = |n: u64| {
        Error::bad(
            path.display().to_string(),
            format!("{n} bytes or more: a {what} may have at most {limit} bytes"),
        )
    };
    if meta.len() > limit {
        return Err(too_big(meta.len()));
    }
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let mut bytes = Vec::with_capacity(meta.len() as usize);
    file.take(limit + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| Error::io(path, e))?;
    if bytes.len() as u64 > limit {
        return Err(too_big(bytes.len() as u64));
    }
    Ok(bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn message(e: Error) -> String {
        assert!(e.is_bad_input(), "{e}");
        e.to_string()
    }

    #[test]
    fn regular_files_within_the_limit_are_read() {
        let dir = std::env::temp_dir().join(format!("files-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("a.json");
        std::fs::write(&p, b"0123456789").unwrap();
        assert_eq!(read_file(&p, 10, "job").unwrap(), b"0123456789");
        let e = message(read_file(&p, 9, "job").unwrap_err());
        assert!(e.contains("a.json") && e.contains("at most 9 bytes"), "{e}");
        let e = message(read_file(&dir, 100, "job").unwrap_err());
        assert!(e.contains("a directory"), "{e}");
        // A link to a device is refused without reading from it.
        #[cfg(unix)]
        {
            let link = dir.join("zero.glb");
            let _ = std::fs::remove_file(&link);
            std::os::unix::fs::symlink("/dev/zero", &link).unwrap();
            let e = message(read_file(&link, MAX_SCENE_BYTES, "scene").unwrap_err());
            assert!(e.contains("zero.glb") && e.contains("device"), "{e}");
            let e = message(read_file(Path::new("/dev/zero"), MAX_JOB_BYTES, "job").unwrap_err());
            assert!(e.contains("not a regular file"), "{e}");
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
