//! API tokens and tenants.
//!
//! The tokens file (`--tokens FILE`, JSON) lists each token's id, tenant,
//! creation time and SHA-256, never the token itself: a token is 32 random
//! bytes from the operating system's generator, so a plain digest is as
//! strong as a slow password hash would be, and a leaked file gives no
//! token. [`add`], [`list`] and [`revoke`] are the `impostor-server token`
//! commands over it; [`Tokens`] is the set the server checks
//! `Authorization: Bearer` against, read again (by a thread of its own)
//! when the file changes, so tokens added or revoked take effect within a
//! second, without a restart.

use std::collections::HashMap;
use std::io;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::{Duration, SystemTime};

use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

/// What every token starts with, so that one is recognised in a
/// configuration or a log.
pub const TOKEN_PREFIX: &str = "imp_";

/// The largest tokens file read, bytes (about 40,000 tokens).
const MAX_FILE_BYTES: u64 = 8 << 20;

/// How often the server looks whether the tokens file changed.
const RELOAD_EVERY: Duration = Duration::from_secs(1);

/// One token of the tokens file.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TokenEntry {
    /// The token's id (8 hex digits): what `token list` shows and
    /// `token revoke` takes.
    pub id: String,
    /// The tenant the token acts for.
    pub tenant: String,
    /// The SHA-256 of the token, hex.
    pub sha256: String,
    /// When it was created, ms since the Unix epoch.
    pub created_ms: i64,
}

/// The tokens file.
#[derive(Debug, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct TokenFile {
    tokens: Vec<TokenEntry>,
}

fn invalid(path: &Path, msg: impl std::fmt::Display) -> io::Error {
    io::Error::new(
        io::ErrorKind::InvalidData,
        format!("tokens file {}: {msg}", path.display()),
    )
}

impl TokenFile {
    /// Reads and checks the file; a missing file is `NotFound`.
    fn read(path: &Path) -> io::Result<TokenFile> {
        use std::io::Read;
        let f = std::fs::File::open(path)?;
        let meta = f.metadata()?;
        if !meta.is_file() {
            return Err(invalid(path, "not a regular file"));
        }
        let mut text = String::new();
        f.take(MAX_FILE_BYTES + 1).read_to_string(&mut text)?;
        if text.len() as u64 > MAX_FILE_BYTES {
            return Err(invalid(path, format!("larger than {MAX_FILE_BYTES} bytes")));
        }
        let file: TokenFile = serde_json::from_str(&text).map_err(|e| invalid(path, e))?;
        for t in &file.tokens {
            check_tenant(&t.tenant).map_err(|e| invalid(path, e))?;
            if t.sha256.len() != 64 || !t.sha256.bytes().all(|b| b.is_ascii_hexdigit()) {
                return Err(invalid(
                    path,
                    format!("token {}: sha256 is not 64 hex digits", t.id),
                ));
            }
        }
        Ok(file)
    }

    /// Writes the file atomically, readable by its owner only.
    fn write(&self, path: &Path) -> io::Result<()> {
        use std::io::Write;
        let tmp = path.with_extension("tmp");
        {
            let mut opts = std::fs::OpenOptions::new();
            opts.write(true).create(true).truncate(true);
            #[cfg(unix)]
            std::os::unix::fs::OpenOptionsExt::mode(&mut opts, 0o600);
            let mut f = opts.open(&tmp)?;
            let mut bytes = serde_json::to_vec_pretty(self).map_err(io::Error::other)?;
            bytes.push(b'\n');
            f.write_all(&bytes)?;
            f.sync_all()?;
        }
        std::fs::rename(&tmp, path)
    }
}

/// A tenant name: 1 to 64 letters, digits, `.`, `_` or `-`.
pub fn check_tenant(name: &str) -> Result<(), String> {
    let ok = (1..=64).contains(&name.len())
        && name
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b"._-".contains(&b));
    if ok {
        Ok(())
    } else {
        Err(format!(
            "tenant {name:?}: use 1 to 64 letters, digits, '.', '_' or '-'"
        ))
    }
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

fn sha256_hex(token: &str) -> String {
    hex(&Sha256::digest(token.as_bytes()))
}

fn random_hex(n: usize) -> io::Result<String> {
    let mut bytes = vec![0u8; n];
    getrandom::fill(&mut bytes).map_err(|e| io::Error::other(e.to_string()))?;
    Ok(hex(&bytes))
}

/// Creates a token for `tenant` in the tokens file at `path` (created,
/// readable by its owner only, when missing) and returns it: the only
/// time the token exists in plain text.
pub fn add(path: &Path, tenant: &str) -> io::Result<String> {
    check_tenant(tenant).map_err(|e| io::Error::new(io::ErrorKind::InvalidInput, e))?;
    let mut file = match TokenFile::read(path) {
        Ok(f) => f,
        Err(e) if e.kind() == io::ErrorKind::NotFound => TokenFile::default(),
        Err(e) => return Err(e),
    };
    let token = format!("{TOKEN_PREFIX}{}", random_hex(32)?);
    let id = loop {
        let id = random_hex(4)?;
        if file.tokens.iter().all(|t| t.id != id) {
            break id;
        }
    };
    file.tokens.push(TokenEntry {
        id,
        tenant: tenant.to_string(),
        sha256: sha256_hex(&token),
        created_ms: crate::store::now_ms(),
    });
    file.write(path)?;
    Ok(token)
}

/// The tokens of the file at `path`, in the order they were added.
pub fn list(path: &Path) -> io::Result<Vec<TokenEntry>> {
    Ok(TokenFile::read(path)?.tokens)
}

/// Removes the token of id `id` from the file at `path`; `NotFound` when
/// there is none. Returns the removed token's entry.
pub fn revoke(path: &Path, id: &str) -> io::Result<TokenEntry> {
    let mut file = TokenFile::read(path)?;
    let at = file.tokens.iter().position(|t| t.id == id).ok_or_else(|| {
        io::Error::new(
            io::ErrorKind::NotFound,
            format!("tokens file {}: no token {id:?}", path.display()),
        )
    })?;
    let entry = file.tokens.remove(at);
    file.write(path)?;
    Ok(entry)
}

/// The tokens the server accepts: each token's SHA-256 and its tenant.
pub(crate) struct Tokens {
    path: PathBuf,
    loaded: Mutex<Loaded>,
}

struct Loaded {
    /// The file's modification time and length when it was read.
    stamp: Option<(SystemTime, u64)>,
    tenants: HashMap<String, String>,
}

fn stamp(path: &Path) -> Option<(SystemTime, u64)> {
    let m = std::fs::metadata(path).ok()?;
    Some((m.modified().ok()?, m.len()))
}

fn tenants(file: TokenFile) -> HashMap<String, String> {
    file.tokens
        .into_iter()
        .map(|t| (t.sha256.to_ascii_lowercase(), t.tenant))
        .collect()
}

impl Tokens {
    /// Reads the tokens file at `path`; an error names the file, and a
    /// missing one says how to create it.
    pub fn open(path: &Path) -> io::Result<Tokens> {
        let stamp = stamp(path);
        let file = TokenFile::read(path).map_err(|e| {
            if e.kind() == io::ErrorKind::NotFound {
                io::Error::new(
                    e.kind(),
                    format!(
                        "no tokens file {}: create a token with `impostor-server token add \
                         --tokens {} --tenant NAME`",
                        path.display(),
                        path.display()
                    ),
                )
            } else {
                e
            }
        })?;
        if file.tokens.is_empty() {
            tracing::warn!(
                "tokens file {} has no token: every request will be refused",
                path.display()
            );
        }
        Ok(Tokens {
            path: path.to_path_buf(),
            loaded: Mutex::new(Loaded {
                stamp,
                tenants: tenants(file),
            }),
        })
    }

    /// The tenant of `token`, or `None` for a token the file does not
    /// list: a lookup in memory, never a file read.
    pub fn tenant(&self, token: &str) -> Option<String> {
        let digest = sha256_hex(token);
        self.loaded.lock().ok()?.tenants.get(&digest).cloned()
    }

    /// Reads the file again if it changed since it was last read: a file
    /// that became unreadable or invalid keeps the tokens read before
    /// (logged), one that was removed none. The server calls it every
    /// [`RELOAD_EVERY`] on a thread of its own.
    pub fn refresh(&self) {
        let now = stamp(&self.path);
        let Ok(loaded) = self.loaded.lock() else {
            return;
        };
        if now == loaded.stamp {
            return;
        }
        drop(loaded);
        let read = TokenFile::read(&self.path);
        let Ok(mut loaded) = self.loaded.lock() else {
            return;
        };
        match read {
            Ok(file) => {
                loaded.tenants = tenants(file);
                loaded.stamp = now;
                tracing::info!("tokens file {} read again", self.path.display());
            }
            Err(e) if e.kind() == io::ErrorKind::NotFound => {
                loaded.tenants.clear();
                loaded.stamp = None;
                tracing::warn!(
                    "tokens file {} removed: no token is accepted",
                    self.path.display()
                );
            }
            Err(e) => {
                // Not again until the file changes once more.
                loaded.stamp = now;
                tracing::error!("{e}; the tokens read before stay in force");
            }
        }
    }

    /// Calls [`Tokens::refresh`] every [`RELOAD_EVERY`] for as long as
    /// the tokens live, on a thread of its own (file reads never run on
    /// the async runtime).
    pub fn spawn_refresh(tokens: &std::sync::Arc<Tokens>) -> io::Result<()> {
        let weak = std::sync::Arc::downgrade(tokens);
        std::thread::Builder::new()
            .name("tokens".into())
            .spawn(move || {
                loop {
                    std::thread::sleep(RELOAD_EVERY);
                    match weak.upgrade() {
                        Some(t) => t.refresh(),
                        None => return,
                    }
                }
            })?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn temp(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("impostor-auth-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d.join("tokens.json")
    }

    /// Tokens are random, kept only as their SHA-256 (the file never holds
    /// one in plain text), map to their tenant, and revoking one takes it
    /// out of the file; bad tenant names and ids are refused.
    #[test]
    fn tokens_are_stored_hashed_and_revoked_by_id() {
        let path = temp("roundtrip");
        let a = add(&path, "studio-a").unwrap();
        let b = add(&path, "studio.b_2").unwrap();
        assert!(a.starts_with(TOKEN_PREFIX) && a.len() == TOKEN_PREFIX.len() + 64);
        assert_ne!(a, b);
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(!text.contains(&a[4..]) && !text.contains(&b[4..]), "{text}");
        assert!(text.contains(&sha256_hex(&a)));
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let mode = std::fs::metadata(&path).unwrap().permissions().mode();
            assert_eq!(mode & 0o077, 0, "{mode:o}");
        }
        let entries = list(&path).unwrap();
        assert_eq!(entries.len(), 2);
        assert_eq!(entries[0].tenant, "studio-a");
        let tokens = Tokens::open(&path).unwrap();
        assert_eq!(tokens.tenant(&a).as_deref(), Some("studio-a"));
        assert_eq!(tokens.tenant(&b).as_deref(), Some("studio.b_2"));
        assert_eq!(tokens.tenant("imp_0123"), None);
        assert_eq!(tokens.tenant(&a[..a.len() - 1]), None);

        let gone = revoke(&path, &entries[0].id).unwrap();
        assert_eq!(gone.tenant, "studio-a");
        assert_eq!(list(&path).unwrap().len(), 1);
        assert_eq!(
            revoke(&path, &entries[0].id).unwrap_err().kind(),
            io::ErrorKind::NotFound
        );
        for bad in ["", "a b", "x/../y", &"t".repeat(65)] {
            assert_eq!(
                add(&path, bad).unwrap_err().kind(),
                io::ErrorKind::InvalidInput,
                "{bad:?}"
            );
        }
        // The server sees the revocation once it reads the file again.
        assert_eq!(tokens.tenant(&a).as_deref(), Some("studio-a"));
        tokens.refresh();
        assert_eq!(tokens.tenant(&a), None);
        assert_eq!(tokens.tenant(&b).as_deref(), Some("studio.b_2"));
        // A file made invalid keeps the tokens read before; a removed one
        // none.
        std::fs::write(&path, b"{not json").unwrap();
        tokens.refresh();
        assert_eq!(tokens.tenant(&b).as_deref(), Some("studio.b_2"));
        std::fs::remove_file(&path).unwrap();
        tokens.refresh();
        assert_eq!(tokens.tenant(&b), None);
        let _ = std::fs::remove_dir_all(path.parent().unwrap());
    }

    /// A missing tokens file says how to make one; a malformed one names
    /// the file and the problem.
    #[test]
    fn bad_tokens_files_are_named() {
        let path = temp("bad");
        let e = Tokens::open(&path).err().unwrap();
        assert!(e.to_string().contains("token add"), "{e}");
        std::fs::write(&path, b"{\"tokens\": [{\"id\": 1}]}").unwrap();
        let e = Tokens::open(&path).err().unwrap();
        assert!(e.to_string().contains("tokens.json"), "{e}");
        std::fs::write(
            &path,
            br#"{"tokens": [{"id": "ab", "tenant": "t", "sha256": "00", "created_ms": 0}]}"#,
        )
        .unwrap();
        let e = Tokens::open(&path).err().unwrap();
        assert!(e.to_string().contains("64 hex"), "{e}");
        assert!(add(&path, "t").is_err(), "a bad file is not overwritten");
        let _ = std::fs::remove_dir_all(path.parent().unwrap());
    }
}
