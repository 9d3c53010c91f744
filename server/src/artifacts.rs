//! The job files: each job's inputs (`scene`, `job.json`, `pvs.json`) and
//! results (`placement.json`, `evaluation.json`, `report.html`,
//! `impostors.glb`), kept in an object store through the `object_store`
//! crate under `<root>/<job id>/<name>`.
//!
//! `--artifacts URL` chooses it: a folder (`file:///srv/impostor/jobs`, or
//! a plain path; by default `<data-dir>/jobs`), local or shared between
//! machines, or an S3-compatible bucket (`s3://bucket/prefix`, configured
//! by the usual `AWS_*` variables: `AWS_ENDPOINT`, `AWS_REGION`,
//! `AWS_ACCESS_KEY_ID`, `AWS_SECRET_ACCESS_KEY`, `AWS_ALLOW_HTTP`, …).
//!
//! Every write is atomic (a folder's files are written aside, synced and
//! renamed into place; a bucket's objects appear whole or not at all), and
//! a job's row in the database is committed only after the files it points
//! to are written: a reader that finds a row finds its files.
//!
//! The store's client is asynchronous; it runs on a small runtime of its
//! own, so that the workers' threads (no runtime) and the HTTP handlers
//! (the server's runtime) call it alike.

use std::future::Future;
use std::io;
use std::path::Path as FsPath;
use std::sync::Arc;

use futures_util::StreamExt;
use object_store::buffered::BufWriter;
use object_store::local::LocalFileSystem;
use object_store::path::Path;
use object_store::{ObjectStore, ObjectStoreExt, PutPayload};
use tokio::io::{AsyncReadExt, AsyncWriteExt};

/// The object store of the job files.
pub(crate) struct Artifacts {
    store: Arc<dyn ObjectStore>,
    /// The prefix of every key (empty for a folder: the folder is the root).
    root: Path,
    /// Where the store is, for logs and `/healthz` (no credentials).
    shown: String,
    /// The runtime the store's calls run on (`None` once dropped).
    rt: Option<tokio::runtime::Runtime>,
}

/// Chunks in which an uploaded file is streamed into the store.
const CHUNK: usize = 8 << 20;

fn store_err(e: object_store::Error) -> io::Error {
    match e {
        object_store::Error::NotFound { .. } => io::Error::new(io::ErrorKind::NotFound, e),
        e => io::Error::other(e),
    }
}

impl Artifacts {
    /// Opens the store at `url` (see the module docs); `None`: the folder
    /// `default_dir`. A folder is created when missing.
    pub fn open(url: Option<&str>, default_dir: &FsPath) -> io::Result<Artifacts> {
        let bad = |why: String| io::Error::new(io::ErrorKind::InvalidInput, why);
        let rt = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .thread_name("artifacts")
            .enable_all()
            .build()?;
        let (store, root, shown): (Arc<dyn ObjectStore>, Path, String) = match url {
            Some(u) if u.contains("://") && !u.starts_with("file://") => {
                let parsed = url_parse(u).map_err(|e| bad(format!("--artifacts {u:?}: {e}")))?;
                if parsed.0 != "s3" {
                    return Err(bad(format!(
                        "--artifacts {u:?}: unsupported scheme {:?} (a folder, file://… or s3://…)",
                        parsed.0
                    )));
                }
                // The client starts its connection pool on the runtime it
                // is built in: build it on the store's.
                let _guard = rt.enter();
                let s3 = object_store::aws::AmazonS3Builder::from_env()
                    .with_url(u)
                    .build()
                    .map_err(|e| bad(format!("--artifacts {u:?}: {e}")))?;
                let root = Path::parse(parsed.2.trim_matches('/'))
                    .map_err(|e| bad(format!("--artifacts {u:?}: {e}")))?;
                let shown = format!("s3://{}/{root}", parsed.1);
                (Arc::new(s3), root, shown)
            }
            _ => {
                let dir = match url {
                    Some(u) => std::path::PathBuf::from(u.strip_prefix("file://").unwrap_or(u)),
                    None => default_dir.to_path_buf(),
                };
                if dir.as_os_str().is_empty() {
                    return Err(bad("--artifacts: an empty folder name".into()));
                }
                std::fs::create_dir_all(&dir).map_err(|e| {
                    io::Error::new(e.kind(), format!("artifacts folder {}: {e}", dir.display()))
                })?;
                let local = LocalFileSystem::new_with_prefix(&dir)
                    .map_err(store_err)?
                    .with_fsync(true)
                    .with_automatic_cleanup(true);
                let shown = format!("file://{}", std::fs::canonicalize(&dir)?.display());
                (Arc::new(local), Path::default(), shown)
            }
        };
        Ok(Artifacts {
            store,
            root,
            shown,
            rt: Some(rt),
        })
    }

    /// Where the store is (`file:///…` or `s3://bucket/prefix`).
    pub fn location(&self) -> &str {
        &self.shown
    }

    /// The kind of store: `file` or `s3`.
    pub fn kind(&self) -> &'static str {
        if self.shown.starts_with("s3://") {
            "s3"
        } else {
            "file"
        }
    }

    /// Whether the store answers (a lookup of a key that need not exist).
    pub fn ping(&self) -> io::Result<()> {
        let (store, key) = (self.store.clone(), self.root.clone().join(".healthz"));
        match self.block(async move { store.head(&key).await }) {
            Ok(_) | Err(object_store::Error::NotFound { .. }) => Ok(()),
            Err(e) => Err(store_err(e)),
        }
    }

    fn key(&self, id: i64, name: &str) -> Path {
        self.job_prefix(id).join(name)
    }

    fn job_prefix(&self, id: i64) -> Path {
        self.root.clone().join(id.to_string())
    }

    /// Runs `f` on the store's runtime and waits for it (from a thread
    /// that is not running async tasks).
    fn block<T: Send + 'static>(&self, f: impl Future<Output = T> + Send + 'static) -> T {
        let (tx, rx) = std::sync::mpsc::sync_channel(1);
        self.runtime().spawn(async move {
            let _ = tx.send(f.await);
        });
        rx.recv().expect("the artifact store's runtime stopped")
    }

    fn runtime(&self) -> &tokio::runtime::Runtime {
        self.rt.as_ref().expect("the artifact store is open")
    }

    /// Writes file `name` of job `id`.
    pub fn put(&self, id: i64, name: &str, bytes: Vec<u8>) -> io::Result<()> {
        let (store, key) = (self.store.clone(), self.key(id, name));
        self.block(async move { store.put(&key, PutPayload::from(bytes)).await })
            .map(|_| ())
            .map_err(store_err)
    }

    /// Writes file `name` of job `id` from the local file `path`, streamed
    /// in chunks (never whole in memory). `Ok(false)`: there is no such file.
    pub fn put_file(&self, id: i64, name: &str, path: &FsPath) -> io::Result<bool> {
        let (store, key, path) = (self.store.clone(), self.key(id, name), path.to_path_buf());
        self.block(async move {
            let mut file = match tokio::fs::File::open(&path).await {
                Ok(f) => f,
                Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(false),
                Err(e) => return Err(e),
            };
            let mut out = BufWriter::with_capacity(store, key, CHUNK);
            let mut buf = vec![0u8; CHUNK];
            loop {
                let n = file.read(&mut buf).await?;
                if n == 0 {
                    break;
                }
                if let Err(e) = out.write_all(&buf[..n]).await {
                    let _ = out.abort().await;
                    return Err(e);
                }
            }
            out.shutdown().await?;
            Ok(true)
        })
    }

    /// File `name` of job `id`; `None` when it does not exist.
    pub fn get(&self, id: i64, name: &str) -> io::Result<Option<Vec<u8>>> {
        let (store, key) = (self.store.clone(), self.key(id, name));
        self.block(read(store, key))
    }

    /// [`Artifacts::get`] from async code.
    pub async fn get_async(&self, id: i64, name: &str) -> io::Result<Option<Vec<u8>>> {
        let (store, key) = (self.store.clone(), self.key(id, name));
        self.runtime()
            .spawn(read(store, key))
            .await
            .map_err(io::Error::other)?
    }

    /// Copies file `name` of job `from` to job `to` (a hard link in a
    /// folder, a server-side copy in a bucket). `Ok(false)`: `from` has no
    /// such file.
    pub fn copy(&self, from: i64, to: i64, name: &str) -> io::Result<bool> {
        let (store, a, b) = (self.store.clone(), self.key(from, name), self.key(to, name));
        match self.block(async move { store.copy(&a, &b).await }) {
            Ok(()) => Ok(true),
            Err(object_store::Error::NotFound { .. }) => Ok(false),
            Err(e) => Err(store_err(e)),
        }
    }

    /// Removes every file of job `id`.
    pub fn delete_job(&self, id: i64) -> io::Result<()> {
        let (store, prefix) = (self.store.clone(), self.job_prefix(id));
        self.block(async move {
            let keys = store
                .list(Some(&prefix))
                .map(|m| m.map(|m| m.location))
                .boxed();
            let mut gone = store.delete_stream(keys);
            while let Some(r) = gone.next().await {
                match r {
                    Ok(_) | Err(object_store::Error::NotFound { .. }) => {}
                    Err(e) => return Err(store_err(e)),
                }
            }
            Ok(())
        })
    }

    /// The ids of the jobs that have files.
    pub fn job_ids(&self) -> io::Result<Vec<i64>> {
        let (store, root) = (self.store.clone(), self.root.clone());
        let listed = self.block(async move {
            let root = (!root.as_ref().is_empty()).then_some(root);
            store.list_with_delimiter(root.as_ref()).await
        });
        Ok(listed
            .map_err(store_err)?
            .common_prefixes
            .iter()
            .filter_map(|p| p.filename()?.parse().ok())
            .collect())
    }
}

impl Drop for Artifacts {
    fn drop(&mut self) {
        // Without waiting: an artifact store may be dropped on an async thread.
        if let Some(rt) = self.rt.take() {
            rt.shutdown_background();
        }
    }
}

async fn read(store: Arc<dyn ObjectStore>, key: Path) -> io::Result<Option<Vec<u8>>> {
    match store.get(&key).await {
        Ok(r) => Ok(Some(r.bytes().await.map_err(store_err)?.into())),
        Err(object_store::Error::NotFound { .. }) => Ok(None),
        Err(e) => Err(store_err(e)),
    }
}

/// `scheme://host/path` split in three; an error names what is missing.
fn url_parse(u: &str) -> Result<(&str, &str, &str), String> {
    let (scheme, rest) = u.split_once("://").ok_or("no scheme")?;
    let (host, path) = rest.split_once('/').unwrap_or((rest, ""));
    if host.is_empty() {
        return Err("no bucket".into());
    }
    Ok((scheme, host, path))
}

/// The files of one job.
#[derive(Clone, Copy)]
pub(crate) struct JobFiles<'a> {
    pub artifacts: &'a Artifacts,
    pub id: i64,
}

impl JobFiles<'_> {
    /// File `name`; `None` when the job has no such file.
    pub fn read(&self, name: &str) -> optimizer::Result<Option<Vec<u8>>> {
        self.artifacts
            .get(self.id, name)
            .map_err(|e| optimizer::Error::io(self.describe(name), e))
    }

    /// File `name`, which must exist.
    pub fn read_required(&self, name: &str) -> optimizer::Result<Vec<u8>> {
        self.read(name)?.ok_or_else(|| {
            optimizer::Error::io(
                self.describe(name),
                io::Error::new(io::ErrorKind::NotFound, "missing"),
            )
        })
    }

    /// Writes file `name` atomically.
    pub fn write(&self, name: &str, bytes: Vec<u8>) -> optimizer::Result<()> {
        self.artifacts
            .put(self.id, name, bytes)
            .map_err(|e| optimizer::Error::io(self.describe(name), e))
    }

    fn describe(&self, name: &str) -> std::path::PathBuf {
        format!("{}/{}/{name}", self.artifacts.location(), self.id).into()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_folder_store_writes_reads_copies_lists_and_deletes() {
        let dir = std::env::temp_dir().join(format!("impostor-artifacts-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let a = Artifacts::open(None, &dir).unwrap();
        assert_eq!(a.get(7, "job.json").unwrap(), None);
        a.put(7, "job.json", b"{}".to_vec()).unwrap();
        // The layout is the folder's: one folder per job.
        assert_eq!(std::fs::read(dir.join("7/job.json")).unwrap(), b"{}");
        let big: Vec<u8> = (0..(CHUNK * 2 + 5)).map(|i| (i % 251) as u8).collect();
        let src = dir.join("upload");
        std::fs::write(&src, &big).unwrap();
        assert!(a.put_file(7, "scene", &src).unwrap());
        assert!(!a.put_file(7, "pvs.json", &dir.join("none")).unwrap());
        assert_eq!(a.get(7, "scene").unwrap().as_deref(), Some(&big[..]));
        assert!(a.copy(7, 8, "scene").unwrap());
        assert!(!a.copy(7, 8, "pvs.json").unwrap());
        assert_eq!(a.get(8, "scene").unwrap().as_deref(), Some(&big[..]));
        let mut ids = a.job_ids().unwrap();
        ids.sort();
        assert_eq!(ids, [7, 8]);
        a.delete_job(7).unwrap();
        assert_eq!(a.get(7, "scene").unwrap(), None);
        assert!(!dir.join("7").exists(), "an emptied job folder is removed");
        assert_eq!(a.get(8, "scene").unwrap().as_deref(), Some(&big[..]));
        assert_eq!(a.job_ids().unwrap(), [8]);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn unsupported_urls_are_named() {
        let dir = std::env::temp_dir();
        for (url, says) in [
            ("gs://bucket/x", "unsupported scheme"),
            ("s3:///x", "no bucket"),
            ("", "empty folder"),
        ] {
            let e = Artifacts::open(Some(url), &dir).err().unwrap().to_string();
            assert!(e.contains(says), "{url}: {e}");
        }
    }
}
