//! Reading input files within stated limits: regular files and pipes (a
//! link is followed, but never to a device or directory: `/dev/zero` would
//! read until memory runs out), and never more bytes than the kind of file
//! may have, checked before and while reading; and the byte format of the
//! JSON files the tool writes.

use std::io::{Read, Write};
use std::path::Path;

use crate::{Error, Result};

/// Largest scene file, and largest buffer or image a glTF file refers to:
/// 4 GiB, the most a GLB's 32-bit length field can describe.
pub const MAX_SCENE_BYTES: u64 = 4 << 30;

/// Largest job file: 64 MiB (a job is a few kilobytes; a walkthrough path
/// of a million points fits).
pub const MAX_JOB_BYTES: u64 = 64 << 20;

/// Largest placement or PVS file the service takes: 4 GiB.
pub const MAX_PLACEMENT_BYTES: u64 = 4 << 30;

/// Largest placement file the command line reads (parsed as it is read,
/// never held whole): 64 GiB. Placements grow with the problem views times
/// the impostors each uses: a 42,621-object city placed at 0.7 × its slowest
/// view without visibility wrote 14 GB.
pub const MAX_LOCAL_PLACEMENT_BYTES: u64 = 64 << 30;

/// The bytes of the file at `path` (`what` names its kind in errors), at
/// most `limit` of them. A regular file or a pipe (`--job <(…)`) is read;
/// anything else (a device, socket or directory, also through a link) and a
/// regular file of more than `limit` bytes is bad input naming the path,
/// refused before it is read. A file or pipe that yields more than `limit`
/// bytes while read is refused too.
pub fn read_file(path: &Path, limit: u64, what: &str) -> Result<Vec<u8>> {
    let (mut file, len) = open_file(path, limit, what)?;
    let mut bytes = Vec::with_capacity(len.unwrap_or(0) as usize);
    file.read_to_end(&mut bytes)
        .map_err(|e| Error::io(path, e))?;
    if bytes.len() as u64 > limit {
        return Err(too_big(path, bytes.len() as u64, limit, what));
    }
    Ok(bytes)
}

/// The JSON file at `path` (`what` names its kind in errors), at most
/// `limit` bytes, parsed as it is read: never held whole as text.
pub fn read_json<T: serde::de::DeserializeOwned>(path: &Path, limit: u64, what: &str) -> Result<T> {
    let (file, _) = open_file(path, limit, what)?;
    let mut reader = std::io::BufReader::new(file);
    let parsed = serde_json::from_reader(&mut reader);
    // A pipe that yields more than the limit is cut there, so its JSON
    // ends early: name the size rather than the truncation.
    if reader.get_ref().limit() == 0 {
        return Err(too_big(path, limit + 1, limit, what));
    }
    parsed.map_err(|e| {
        Error::bad(
            path.display().to_string(),
            format!("invalid {what} JSON: {e}"),
        )
    })
}

/// `value` as pretty-printed JSON with a final newline, written to `w`:
/// the byte format of every JSON file the tool writes (the CLI and the
/// HTTP service share it, so the same placement has the same bytes
/// through either). Objects are indented as `serde_json`'s pretty printer
/// does; an array of numbers, strings or booleans is written on one line
/// (`[0.0, 1.5, 0.0]`), so a placement's per-CPV impostor lists take one
/// line each instead of one line per id (a third of the bytes).
pub fn write_json(mut w: impl Write, value: &impl serde::Serialize) -> std::io::Result<()> {
    let mut ser = serde_json::Serializer::with_formatter(&mut w, Layout::default());
    value.serialize(&mut ser)?;
    w.write_all(b"\n")
}

/// How an open array or object of [`Layout`] is laid out.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Open {
    /// An array whose first element has not been written yet.
    Array,
    /// An array of scalars: on one line.
    Line,
    /// An array of arrays or objects: one element per line.
    Block,
    /// An object; `true` once it has a member.
    Object(bool),
}

/// The formatter of [`write_json`]: `serde_json`'s pretty layout (two
/// spaces per level), except that an array whose first element is a scalar
/// stays on one line.
#[derive(Default)]
struct Layout {
    open: Vec<Open>,
    /// Set between `begin_array_value` and the value it announces: whether
    /// that value is its array's first.
    element: Option<bool>,
}

impl Layout {
    fn newline<W: ?Sized + Write>(&self, w: &mut W) -> std::io::Result<()> {
        w.write_all(b"\n")?;
        for _ in 0..self.open.len() {
            w.write_all(b"  ")?;
        }
        Ok(())
    }

    /// Called before every value: an array's element decides, if it is the
    /// first, how its array is laid out, and is separated accordingly.
    fn value<W: ?Sized + Write>(&mut self, w: &mut W, scalar: bool) -> std::io::Result<()> {
        let Some(first) = self.element.take() else {
            return Ok(());
        };
        let top = self.open.last_mut().expect("an element is inside an array");
        if *top == Open::Array {
            *top = if scalar { Open::Line } else { Open::Block };
        }
        match *top {
            Open::Line => {
                if !first {
                    w.write_all(b", ")?;
                }
                Ok(())
            }
            _ => {
                if !first {
                    w.write_all(b",")?;
                }
                self.newline(w)
            }
        }
    }
}

/// Scalars: separated as an element, then written as `serde_json` writes them.
macro_rules! scalar {
    ($($name:ident($t:ty)),* $(,)?) => {$(
        fn $name<W: ?Sized + Write>(&mut self, w: &mut W, v: $t) -> std::io::Result<()> {
            self.value(w, true)?;
            serde_json::ser::CompactFormatter.$name(w, v)
        }
    )*};
}

impl serde_json::ser::Formatter for Layout {
    scalar!(
        write_bool(bool),
        write_i8(i8),
        write_i16(i16),
        write_i32(i32),
        write_i64(i64),
        write_i128(i128),
        write_u8(u8),
        write_u16(u16),
        write_u32(u32),
        write_u64(u64),
        write_u128(u128),
        write_f32(f32),
        write_f64(f64),
        write_number_str(&str),
        write_raw_fragment(&str),
    );

    fn write_null<W: ?Sized + Write>(&mut self, w: &mut W) -> std::io::Result<()> {
        self.value(w, true)?;
        w.write_all(b"null")
    }

    fn begin_string<W: ?Sized + Write>(&mut self, w: &mut W) -> std::io::Result<()> {
        self.value(w, true)?;
        w.write_all(b"\"")
    }

    fn begin_array<W: ?Sized + Write>(&mut self, w: &mut W) -> std::io::Result<()> {
        self.value(w, false)?;
        self.open.push(Open::Array);
        w.write_all(b"[")
    }

    fn begin_array_value<W: ?Sized + Write>(
        &mut self,
        _: &mut W,
        first: bool,
    ) -> std::io::Result<()> {
        self.element = Some(first);
        Ok(())
    }

    fn end_array<W: ?Sized + Write>(&mut self, w: &mut W) -> std::io::Result<()> {
        if self.open.pop() == Some(Open::Block) {
            self.newline(w)?;
        }
        w.write_all(b"]")
    }

    fn begin_object<W: ?Sized + Write>(&mut self, w: &mut W) -> std::io::Result<()> {
        self.value(w, false)?;
        self.open.push(Open::Object(false));
        w.write_all(b"{")
    }

    fn begin_object_key<W: ?Sized + Write>(
        &mut self,
        w: &mut W,
        first: bool,
    ) -> std::io::Result<()> {
        if let Some(top) = self.open.last_mut() {
            *top = Open::Object(true);
        }
        if !first {
            w.write_all(b",")?;
        }
        self.newline(w)
    }

    fn begin_object_value<W: ?Sized + Write>(&mut self, w: &mut W) -> std::io::Result<()> {
        w.write_all(b": ")
    }

    fn end_object<W: ?Sized + Write>(&mut self, w: &mut W) -> std::io::Result<()> {
        if self.open.pop() == Some(Open::Object(true)) {
            self.newline(w)?;
        }
        w.write_all(b"}")
    }
}

/// The file at `path` opened for reading, as [`read_file`] checks it,
/// yielding at most one byte more than `limit` (a reader that gets more
/// must refuse the file), and its length when it is a regular file.
fn open_file(
    path: &Path,
    limit: u64,
    what: &str,
) -> Result<(std::io::Take<std::fs::File>, Option<u64>)> {
    let meta = std::fs::metadata(path).map_err(|e| Error::io(path, e))?;
    if !(meta.is_file() || is_pipe(&meta)) {
        let kind = if meta.is_dir() {
            "a directory"
        } else {
            "a device or socket"
        };
        return Err(Error::bad(
            path.display().to_string(),
            format!("{kind}, not a regular file: a {what} must be a file"),
        ));
    }
    if meta.is_file() && meta.len() > limit {
        return Err(too_big(path, meta.len(), limit, what));
    }
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    Ok((file.take(limit + 1), meta.is_file().then_some(meta.len())))
}

/// The error for a file of `n` bytes or more, above `limit`.
fn too_big(path: &Path, n: u64, limit: u64, what: &str) -> Error {
    Error::bad(
        path.display().to_string(),
        format!("{n} bytes or more: a {what} may have at most {limit} bytes"),
    )
}

#[cfg(unix)]
fn is_pipe(meta: &std::fs::Metadata) -> bool {
    std::os::unix::fs::FileTypeExt::is_fifo(&meta.file_type())
}

#[cfg(not(unix))]
fn is_pipe(_: &std::fs::Metadata) -> bool {
    false
}

#[cfg(test)]
mod tests {
    use super::*;

    fn message(e: Error) -> String {
        assert!(e.is_bad_input(), "{e}");
        e.to_string()
    }

    #[test]
    fn json_is_indented_with_scalar_arrays_on_one_line() {
        let value = serde_json::json!({
            "cpvs": [
                {"id": 0, "impostors": [3, 17, 250], "region": {"min": [0.0, 1.5, -2.25]}},
                {"id": 1, "impostors": [], "solved": true, "reason": null}
            ],
            "names": ["a", "b\"c"],
            "nested": [[1, 2], [], [{}]],
            "empty": {}
        });
        let mut bytes = Vec::new();
        write_json(&mut bytes, &value).unwrap();
        let text = String::from_utf8(bytes).unwrap();
        let want = r#"{
  "cpvs": [
    {
      "id": 0,
      "impostors": [3, 17, 250],
      "region": {
        "min": [0.0, 1.5, -2.25]
      }
    },
    {
      "id": 1,
      "impostors": [],
      "reason": null,
      "solved": true
    }
  ],
  "empty": {},
  "names": ["a", "b\"c"],
  "nested": [
    [1, 2],
    [],
    [
      {}
    ]
  ]
}
"#;
        assert_eq!(text, want);
        // The same value as serde_json reads it back.
        let back: serde_json::Value = serde_json::from_str(&text).unwrap();
        assert_eq!(back, value);
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
            // A pipe is read, within the limit.
            let fifo = dir.join("job.fifo");
            let made = std::process::Command::new("mkfifo").arg(&fifo).status();
            if made.is_ok_and(|s| s.success()) {
                let writer = |n: usize| {
                    let fifo = fifo.clone();
                    std::thread::spawn(move || {
                        use std::io::Write;
                        let mut f = std::fs::OpenOptions::new().write(true).open(fifo).unwrap();
                        // The reader may stop early: a broken pipe is fine.
                        let _ = f.write_all(&vec![b'x'; n]);
                    })
                };
                let w = writer(1000);
                assert_eq!(read_file(&fifo, 1000, "job").unwrap().len(), 1000);
                w.join().unwrap();
                let w = writer(1001);
                let e = message(read_file(&fifo, 1000, "job").unwrap_err());
                assert!(e.contains("at most 1000 bytes"), "{e}");
                w.join().unwrap();
            }
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// A JSON file is parsed as it is read, within its limit; one a pipe
    /// yields past the limit is refused for its size, not as cut JSON.
    #[test]
    fn json_files_are_parsed_within_the_limit() {
        let dir = std::env::temp_dir().join(format!("files-json-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("p.json");
        std::fs::write(&p, b"[1, 2, 3]").unwrap();
        assert_eq!(
            read_json::<Vec<u32>>(&p, 9, "placement").unwrap(),
            [1, 2, 3]
        );
        let e = message(read_json::<Vec<u32>>(&p, 8, "placement").unwrap_err());
        assert!(e.contains("at most 8 bytes"), "{e}");
        std::fs::write(&p, b"[1, 2").unwrap();
        let e = message(read_json::<Vec<u32>>(&p, 100, "placement").unwrap_err());
        assert!(e.contains("invalid placement JSON"), "{e}");
        #[cfg(unix)]
        {
            let fifo = dir.join("p.fifo");
            let made = std::process::Command::new("mkfifo").arg(&fifo).status();
            if made.is_ok_and(|s| s.success()) {
                let text = format!("[{}0]", "0,".repeat(999));
                let w = {
                    let fifo = fifo.clone();
                    std::thread::spawn(move || {
                        let mut f = std::fs::OpenOptions::new().write(true).open(fifo).unwrap();
                        // The reader stops at its limit: a broken pipe is fine.
                        let _ = f.write_all(text.as_bytes());
                    })
                };
                let e = message(read_json::<Vec<u32>>(&fifo, 1000, "placement").unwrap_err());
                assert!(e.contains("at most 1000 bytes"), "{e}");
                w.join().unwrap();
            }
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
