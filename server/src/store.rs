//! Durable job storage: the SQLite database (`jobs.sqlite`: WAL,
//! `synchronous = FULL`) and one directory of files per job, written
//! atomically. Also recovers the jobs a previous process left unfinished.
//!
//! A job has two ids: its row's integer id, internal (queue order, folder
//! name, logs), and its public id, a random UUID (`uid`), the only one the
//! API takes and answers with, so that nobody can guess or enumerate jobs.

use std::io;
use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard};
use std::time::{SystemTime, UNIX_EPOCH};

use rusqlite::Connection;

use crate::job::JobState;

/// The job database and the job directories under `<data_dir>/jobs/`;
/// uploads arrive in `<data_dir>/uploads/` (see [`Staged`]).
pub(crate) struct Store {
    db: Mutex<Connection>,
    jobs_dir: PathBuf,
    uploads_dir: PathBuf,
}

/// The names of a job's input files, in its staging folder and its job
/// folder alike.
pub(crate) const SCENE: &str = "scene";
pub(crate) const JOB: &str = "job.json";
pub(crate) const PVS: &str = "pvs.json";

/// An upload being received: a folder of its own under `uploads/`, where
/// the submission's parts are streamed as they arrive (the body is never
/// held in memory), then moved into the job's folder by renaming when the
/// job is accepted. Dropping it removes what is left, so a refused or
/// broken upload leaves nothing behind; a crash's leftovers are removed on
/// the next start.
pub(crate) struct Staged {
    dir: PathBuf,
}

impl Staged {
    /// The path of input `name` ([`SCENE`], [`JOB`], [`PVS`]).
    pub fn path(&self, name: &str) -> PathBuf {
        self.dir.join(name)
    }
}

impl Drop for Staged {
    fn drop(&mut self) {
        let dir = std::mem::take(&mut self.dir);
        // Off the async runtime when dropped on it.
        match tokio::runtime::Handle::try_current() {
            Ok(rt) => {
                rt.spawn_blocking(move || std::fs::remove_dir_all(dir));
            }
            Err(_) => {
                let _ = std::fs::remove_dir_all(dir);
            }
        }
    }
}

/// A new public job id: a random (version 4) UUID.
fn new_uid() -> String {
    uuid::Uuid::new_v4().to_string()
}

/// One row of the `jobs` table.
pub(crate) struct JobRow {
    /// The internal id.
    pub id: i64,
    /// The public id.
    pub uid: String,
    pub state: JobState,
    /// The last stage recorded (the live stage of a running job is kept in
    /// memory, not here).
    pub stage: Option<String>,
    pub error: Option<String>,
    /// The JSON text of the job's summary, once succeeded.
    pub summary: Option<String>,
    pub bake: bool,
    pub created_ms: i64,
    pub started_ms: Option<i64>,
    pub finished_ms: Option<i64>,
}

/// Milliseconds since the Unix epoch.
pub(crate) fn now_ms() -> i64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_millis() as i64)
}

fn db_err(e: rusqlite::Error) -> io::Error {
    io::Error::other(e)
}

/// Writes `bytes` to `path` atomically: temporary file, sync, rename, sync
/// of the directory. A crash leaves either the old file or the whole new
/// one, never a truncated result.
pub(crate) fn write_atomic(path: &Path, bytes: &[u8]) -> io::Result<()> {
    use std::io::Write;
    let tmp = path.with_extension("tmp");
    {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
    }
    std::fs::rename(&tmp, path)?;
    if let Some(dir) = path.parent()
        && let Ok(d) = std::fs::File::open(dir)
    {
        let _ = d.sync_all();
    }
    Ok(())
}

impl Store {
    /// Opens (or creates) the database and the job directory under
    /// `data_dir`, creating the tables a new database lacks.
    pub fn open(data_dir: &Path) -> io::Result<Store> {
        let jobs_dir = data_dir.join("jobs");
        std::fs::create_dir_all(&jobs_dir)?;
        let uploads_dir = data_dir.join("uploads");
        std::fs::create_dir_all(&uploads_dir)?;
        let db = Connection::open(data_dir.join("jobs.sqlite")).map_err(db_err)?;
        db.execute_batch(
            "PRAGMA journal_mode = WAL;
             PRAGMA synchronous = FULL;
             CREATE TABLE IF NOT EXISTS jobs (
                 id INTEGER PRIMARY KEY,
                 state TEXT NOT NULL,
                 stage TEXT,
                 error TEXT,
                 summary TEXT,
                 bake INTEGER NOT NULL,
                 scene_kind TEXT NOT NULL,
                 created_ms INTEGER NOT NULL,
                 started_ms INTEGER,
                 finished_ms INTEGER
             );
             CREATE TABLE IF NOT EXISTS meta (k TEXT PRIMARY KEY, v INTEGER NOT NULL);",
        )
        .map_err(db_err)?;
        // Public ids: a database of an older version has none; its jobs get
        // one each (their old numeric ids are then 404 like any unknown id).
        let has_uid = db
            .prepare("SELECT 1 FROM pragma_table_info('jobs') WHERE name = 'uid'")
            .and_then(|mut s| s.exists([]))
            .map_err(db_err)?;
        if !has_uid {
            db.execute_batch("ALTER TABLE jobs ADD COLUMN uid TEXT")
                .map_err(db_err)?;
        }
        let missing: Vec<i64> = db
            .prepare("SELECT id FROM jobs WHERE uid IS NULL")
            .and_then(|mut s| s.query_map([], |r| r.get(0))?.collect())
            .map_err(db_err)?;
        for id in missing {
            db.execute(
                "UPDATE jobs SET uid = ?2 WHERE id = ?1",
                rusqlite::params![id, new_uid()],
            )
            .map_err(db_err)?;
        }
        db.execute_batch("CREATE UNIQUE INDEX IF NOT EXISTS jobs_uid ON jobs (uid)")
            .map_err(db_err)?;
        // Tenants: the jobs of an older version, or of a server without
        // tokens, have none (only a server without tokens shows them).
        let has_tenant = db
            .prepare("SELECT 1 FROM pragma_table_info('jobs') WHERE name = 'tenant'")
            .and_then(|mut s| s.exists([]))
            .map_err(db_err)?;
        if !has_tenant {
            db.execute_batch("ALTER TABLE jobs ADD COLUMN tenant TEXT")
                .map_err(db_err)?;
        }
        db.execute_batch("CREATE INDEX IF NOT EXISTS jobs_tenant ON jobs (tenant, id)")
            .map_err(db_err)?;
        Ok(Store {
            db: Mutex::new(db),
            jobs_dir,
            uploads_dir,
        })
    }

    fn db(&self) -> io::Result<MutexGuard<'_, Connection>> {
        self.db.lock().map_err(|e| io::Error::other(e.to_string()))
    }

    /// Puts the jobs a previous process left `queued` or `running` back in
    /// the queue state and removes the directories of jobs that were never
    /// accepted. Returns the ids to queue, oldest first.
    pub fn recover(&self) -> io::Result<Vec<i64>> {
        let db = self.db()?;
        db.execute(
            "UPDATE jobs SET state = ?1, stage = NULL, started_ms = NULL
             WHERE state IN (?1, ?2)",
            [JobState::Queued, JobState::Running],
        )
        .map_err(db_err)?;
        let ids = |sql: &str, params: &[&dyn rusqlite::ToSql]| -> io::Result<Vec<i64>> {
            let mut st = db.prepare(sql).map_err(db_err)?;
            st.query_map(params, |r| r.get(0))
                .map_err(db_err)?
                .collect::<rusqlite::Result<_>>()
                .map_err(db_err)
        };
        let pending = ids(
            "SELECT id FROM jobs WHERE state = ?1 ORDER BY id",
            &[&JobState::Queued],
        )?;
        // Inputs are written before their row is committed: a directory
        // without a row belongs to a submission that was never accepted.
        let known = ids("SELECT id FROM jobs", &[])?;
        // Uploads a previous process was receiving were never accepted.
        for entry in std::fs::read_dir(&self.uploads_dir)? {
            let _ = std::fs::remove_dir_all(entry?.path());
        }
        for entry in std::fs::read_dir(&self.jobs_dir)? {
            let entry = entry?;
            let id = entry.file_name().to_string_lossy().parse::<i64>().ok();
            if id.is_none_or(|id| !known.contains(&id)) {
                let _ = std::fs::remove_dir_all(entry.path());
            }
        }
        Ok(pending)
    }

    /// The directory of job `id`'s inputs and results.
    pub fn job_dir(&self, id: i64) -> PathBuf {
        self.jobs_dir.join(id.to_string())
    }

    /// A new, empty staging folder for an upload.
    pub async fn stage(&self) -> io::Result<Staged> {
        let dir = self
            .uploads_dir
            .join(uuid::Uuid::new_v4().simple().to_string());
        tokio::fs::create_dir_all(&dir).await?;
        Ok(Staged { dir })
    }

    /// Stores a new job of `tenant` (`None` without tokens) from the
    /// inputs in `staged` (their files already synced): allocates its ids,
    /// moves the inputs into its folder by renaming (no copy), then commits
    /// its row as `queued`. Returns the internal and the public id.
    pub fn create(
        &self,
        staged: &Staged,
        bake: bool,
        tenant: Option<&str>,
    ) -> io::Result<(i64, String)> {
        use std::io::Read;
        let db = self.db()?;
        // Ids are never reused, not even those of deleted jobs.
        let id: i64 = db
            .query_row(
                "SELECT MAX(COALESCE((SELECT v FROM meta WHERE k = 'next_id'), 1),
                            COALESCE((SELECT MAX(id) FROM jobs), 0) + 1)",
                [],
                |r| r.get(0),
            )
            .map_err(db_err)?;
        db.execute(
            "INSERT INTO meta (k, v) VALUES ('next_id', ?1) ON CONFLICT(k) DO UPDATE SET v = ?1",
            [id + 1],
        )
        .map_err(db_err)?;
        let dir = self.job_dir(id);
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir)?;
        let mut magic = [0u8; 4];
        let glb = std::fs::File::open(staged.path(SCENE))?
            .read_exact(&mut magic)
            .is_ok()
            && &magic == b"glTF";
        for name in [SCENE, JOB, PVS] {
            match std::fs::rename(staged.path(name), dir.join(name)) {
                Err(e) if name == PVS && e.kind() == io::ErrorKind::NotFound => {}
                r => r?,
            }
        }
        if let Ok(d) = std::fs::File::open(&dir) {
            d.sync_all()?;
        }
        let kind = if glb { "glb" } else { "json" };
        let uid = new_uid();
        db.execute(
            "INSERT INTO jobs (id, uid, state, bake, scene_kind, created_ms, tenant)
             VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7)",
            rusqlite::params![
                id,
                uid,
                JobState::Queued,
                bake as i64,
                kind,
                now_ms(),
                tenant
            ],
        )
        .map_err(db_err)?;
        Ok((id, uid))
    }

    /// Stages `scene`, `job` and `pvs` (as an upload would) and creates
    /// their job.
    #[cfg(test)]
    pub fn create_from_bytes(
        &self,
        scene: &[u8],
        job: &[u8],
        pvs: Option<&[u8]>,
        tenant: Option<&str>,
    ) -> io::Result<(i64, String)> {
        let staged = tokio::runtime::Builder::new_current_thread()
            .build()?
            .block_on(self.stage())?;
        write_atomic(&staged.path(SCENE), scene)?;
        write_atomic(&staged.path(JOB), job)?;
        if let Some(p) = pvs {
            write_atomic(&staged.path(PVS), p)?;
        }
        self.create(&staged, false, tenant)
    }

    /// Records a job's new state, with its error or summary when given;
    /// stamps the start time on `running` and the finish time on a final
    /// state. A failure is logged: the job then keeps its previous row.
    pub fn set_state(&self, id: i64, state: JobState, error: Option<&str>, summary: Option<&str>) {
        let Ok(db) = self.db.lock() else { return };
        let finished = state.is_final().then(now_ms);
        let started = (state == JobState::Running).then(now_ms);
        let r = db.execute(
            "UPDATE jobs SET state = ?2, error = COALESCE(?3, error), summary = COALESCE(?4, summary),
                 finished_ms = COALESCE(?5, finished_ms), started_ms = COALESCE(?6, started_ms)
             WHERE id = ?1",
            rusqlite::params![id, state, error, summary, finished, started],
        );
        if let Err(e) = r {
            tracing::error!(job = id, "database update failed: {e}");
        }
    }

    /// The row of job `id`; `Ok(None)` when there is no such job (or its
    /// row cannot be read).
    pub fn row(&self, id: i64) -> io::Result<Option<JobRow>> {
        self.row_where("id = ?1", &[&id])
    }

    /// The row of the job of public id `uid` that belongs to `tenant`
    /// (`None`: to anyone), in one query; `Ok(None)` when there is none.
    pub fn find(&self, uid: &str, tenant: Option<&str>) -> io::Result<Option<JobRow>> {
        self.row_where("uid = ?1 AND (?2 IS NULL OR tenant = ?2)", &[&uid, &tenant])
    }

    fn row_where(
        &self,
        condition: &str,
        params: &[&dyn rusqlite::ToSql],
    ) -> io::Result<Option<JobRow>> {
        let db = self.db()?;
        Ok(db
            .query_row(
                &format!(
                    "SELECT state, stage, error, summary, bake, created_ms, started_ms, finished_ms,
                            uid, id
                     FROM jobs WHERE {condition}"
                ),
                params,
                |r| {
                    Ok(JobRow {
                        state: r.get(0)?,
                        stage: r.get(1)?,
                        error: r.get(2)?,
                        summary: r.get(3)?,
                        bake: r.get::<_, i64>(4)? != 0,
                        created_ms: r.get(5)?,
                        started_ms: r.get(6)?,
                        finished_ms: r.get(7)?,
                        uid: r.get(8)?,
                        id: r.get(9)?,
                    })
                },
            )
            .ok())
    }

    /// The jobs of `tenant` queued or running.
    pub fn active_jobs(&self, tenant: &str) -> io::Result<usize> {
        self.db()?
            .query_row(
                "SELECT COUNT(*) FROM jobs WHERE tenant = ?1 AND state IN (?2, ?3)",
                rusqlite::params![tenant, JobState::Queued, JobState::Running],
                |r| r.get::<_, i64>(0),
            )
            .map(|n| n as usize)
            .map_err(db_err)
    }

    /// Up to `limit` ids of jobs of `tenant` (`None`: of anyone) greater
    /// than `after`, ascending.
    pub fn ids_after(&self, after: i64, limit: i64, tenant: Option<&str>) -> io::Result<Vec<i64>> {
        let db = self.db()?;
        let mut stmt = db
            .prepare(
                "SELECT id FROM jobs WHERE id > ?1 AND (?3 IS NULL OR tenant = ?3)
                 ORDER BY id LIMIT ?2",
            )
            .map_err(db_err)?;
        stmt.query_map(rusqlite::params![after, limit, tenant], |r| r.get(0))
            .map_err(db_err)?
            .collect::<rusqlite::Result<_>>()
            .map_err(db_err)
    }

    /// The jobs that reached a final state before `cutoff_ms` (ms since
    /// the Unix epoch), oldest first.
    pub fn finished_before(&self, cutoff_ms: i64) -> io::Result<Vec<i64>> {
        let db = self.db()?;
        let mut stmt = db
            .prepare(
                "SELECT id FROM jobs WHERE finished_ms IS NOT NULL AND finished_ms < ?1
                 AND state IN (?2, ?3, ?4) ORDER BY id",
            )
            .map_err(db_err)?;
        stmt.query_map(
            rusqlite::params![
                cutoff_ms,
                JobState::Succeeded,
                JobState::Failed,
                JobState::Cancelled
            ],
            |r| r.get(0),
        )
        .map_err(db_err)?
        .collect::<rusqlite::Result<_>>()
        .map_err(db_err)
    }

    /// Removes job `id`'s row, then its files.
    pub fn delete(&self, id: i64) -> io::Result<()> {
        self.db()?
            .execute("DELETE FROM jobs WHERE id = ?1", [id])
            .map_err(db_err)?;
        let _ = std::fs::remove_dir_all(self.job_dir(id));
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn temp_dir(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("impostor-store-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    /// New jobs get distinct random UUIDs that lead back to them; a
    /// database of an older version, without public ids, gets one for
    /// each of its jobs on open, and its old numeric ids lead nowhere.
    #[test]
    fn jobs_have_random_public_ids_and_older_databases_get_them() {
        let dir = temp_dir("uid");
        {
            let db = Connection::open(dir.join("jobs.sqlite")).unwrap();
            db.execute_batch(
                "CREATE TABLE jobs (
                     id INTEGER PRIMARY KEY, state TEXT NOT NULL, stage TEXT, error TEXT,
                     summary TEXT, bake INTEGER NOT NULL, scene_kind TEXT NOT NULL,
                     created_ms INTEGER NOT NULL, started_ms INTEGER, finished_ms INTEGER);
                 INSERT INTO jobs (id, state, bake, scene_kind, created_ms)
                 VALUES (1, 'succeeded', 0, 'json', 5);",
            )
            .unwrap();
        }
        let store = Store::open(&dir).unwrap();
        let old = store.row(1).unwrap().unwrap().uid;
        assert_eq!(
            uuid::Uuid::parse_str(&old).unwrap().get_version(),
            Some(uuid::Version::Random)
        );
        assert_eq!(store.find(&old, None).unwrap().map(|r| r.id), Some(1));
        assert_eq!(store.find("1", None).unwrap().map(|r| r.id), None);
        let (a, ua) = store.create_from_bytes(b"{}", b"{}", None, None).unwrap();
        let (b, ub) = store.create_from_bytes(b"{}", b"{}", None, None).unwrap();
        assert_eq!((a, b), (2, 3));
        assert!(ua != ub && ua != old);
        assert_eq!(store.find(&ub, None).unwrap().map(|r| r.id), Some(3));
        assert_eq!(store.row(2).unwrap().unwrap().uid, ua);
        // Reopening keeps every id.
        drop(store);
        let store = Store::open(&dir).unwrap();
        assert_eq!(store.find(&old, None).unwrap().map(|r| r.id), Some(1));
        assert_eq!(store.find(&ua, None).unwrap().map(|r| r.id), Some(2));
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// A tenant finds and lists only its own jobs and counts its active
    /// ones; without a tenant every job is found.
    #[test]
    fn tenants_see_only_their_jobs() {
        let dir = temp_dir("tenant");
        let store = Store::open(&dir).unwrap();
        let (a, ua) = store
            .create_from_bytes(b"{}", b"{}", None, Some("a"))
            .unwrap();
        let (b, ub) = store
            .create_from_bytes(b"{}", b"{}", None, Some("b"))
            .unwrap();
        let (c, _) = store
            .create_from_bytes(b"{}", b"{}", None, Some("a"))
            .unwrap();
        let found = |uid: &str, t: Option<&str>| store.find(uid, t).unwrap().map(|r| r.id);
        assert_eq!(found(&ua, Some("a")), Some(a));
        assert_eq!(found(&ua, Some("b")), None);
        assert_eq!(found(&ub, Some("a")), None);
        assert_eq!(found(&ub, None), Some(b));
        assert_eq!(store.ids_after(0, 10, Some("a")).unwrap(), vec![a, c]);
        assert_eq!(store.ids_after(a, 10, Some("a")).unwrap(), vec![c]);
        assert_eq!(store.ids_after(0, 10, None).unwrap(), vec![a, b, c]);
        assert_eq!(store.active_jobs("a").unwrap(), 2);
        store.set_state(c, JobState::Succeeded, None, None);
        assert_eq!(store.active_jobs("a").unwrap(), 1);
        assert_eq!(store.active_jobs("nobody").unwrap(), 0);
        let _ = std::fs::remove_dir_all(&dir);
    }
}
