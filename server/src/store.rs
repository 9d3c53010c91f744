//! Durable job storage: the job database ([`crate::db`]: SQLite's
//! `jobs.sqlite` with WAL and `synchronous = FULL` by default, or a shared
//! PostgreSQL) and the files of each job in the artifact store
//! ([`crate::artifacts`]: `<data_dir>/jobs/<id>/` by default), written
//! before the row that points to them is committed.
//! Jobs are claimed by workers under leases (see [`Store::claim`]).
//!
//! A job has two ids: its row's integer id, internal (queue order, folder
//! name, logs), and its public id, a random UUID (`uid`), the only one the
//! API takes and answers with, so that nobody can guess or enumerate jobs.

use std::io;
use std::path::{Path, PathBuf};
use std::time::{SystemTime, UNIX_EPOCH};

use crate::artifacts::{Artifacts, JobFiles};
use crate::db::{Backend, Db, Value};
use crate::job::JobState;

/// The job database and the job files; uploads arrive in
/// `<data_dir>/uploads/` (see [`Staged`]).
pub(crate) struct Store {
    db: Db,
    artifacts: Artifacts,
    uploads_dir: PathBuf,
}

/// The names of a job's input files, in its staging folder and its job
/// folder alike.
pub(crate) const SCENE: &str = "scene";
pub(crate) const JOB: &str = "job.json";
pub(crate) const PVS: &str = "pvs.json";

/// An upload being received: a folder of its own under `uploads/`, where
/// the submission's parts are streamed as they arrive (the body is never
/// held in memory), then streamed into the artifact store when the job is
/// accepted. Dropping it removes what is left, so a refused or
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

/// A job a worker claimed.
pub(crate) struct Claimed {
    pub id: i64,
    /// Whether it bakes its impostors.
    pub bake: bool,
    /// What its run is.
    pub run: Run,
}

/// What a claimed job's run is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Run {
    /// A job: placed, evaluated, reported (and baked).
    Whole,
    /// A tile of a tiled job: placed only (the merge evaluates the whole).
    Tile,
    /// A tiled job whose tiles are final: their merge, evaluated, reported
    /// (and baked).
    Merge,
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
    /// The stored progress of a running job (its worker's last renewal).
    pub progress: Option<f64>,
    /// A tiled job's number of tiles (each a job of its own).
    pub tiles: Option<i64>,
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

/// What a worker's lease renewal found.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Renewal {
    /// The worker still holds the job's lease (renewed).
    pub held: bool,
    /// A `DELETE` asked the job to stop.
    pub cancel: bool,
}

/// Figures for `/metrics`.
#[derive(Clone, Debug, Default)]
pub(crate) struct Figures {
    /// Jobs per state, in [`JobState::ALL`]'s order.
    pub by_state: [u64; 5],
    /// Workers seen within the last [`WORKER_SEEN_MS`].
    pub workers: u64,
    /// Finished jobs' run times (start to finish), seconds: count and sum.
    pub finished: u64,
    pub finished_seconds: f64,
    /// How many finished jobs ran at most each of [`DURATION_BUCKETS`] s.
    pub buckets: Vec<u64>,
}

/// The upper bounds of the job-duration histogram, seconds.
pub(crate) const DURATION_BUCKETS: [f64; 8] = [1.0, 5.0, 15.0, 60.0, 300.0, 900.0, 3600.0, 14400.0];

/// A worker not seen for this long is not counted.
pub(crate) const WORKER_SEEN_MS: i64 = 60_000;

/// The final states, as SQL text.
const FINAL: &str = "'succeeded', 'failed', 'cancelled'";

fn int(v: i64) -> Value {
    Value::from(v)
}

fn text(v: &str) -> Value {
    Value::from(v)
}

fn state(s: JobState) -> Value {
    Value::from(s.as_str())
}

impl Store {
    /// Opens (or creates) the artifact store (`artifacts`, by default the
    /// folder `<data_dir>/jobs`), the uploads folder under `data_dir` and the
    /// database (`database`: `sqlite:PATH` or `postgres://…`; default
    /// `<data_dir>/jobs.sqlite`), applying the migrations it lacks.
    pub fn open(
        data_dir: &Path,
        database: Option<&str>,
        artifacts: Option<&str>,
    ) -> io::Result<Store> {
        let artifacts = Artifacts::open(artifacts, &data_dir.join("jobs"))?;
        let uploads_dir = data_dir.join("uploads");
        std::fs::create_dir_all(&uploads_dir)?;
        let db = Db::open(database, data_dir, sqlite_setup)?;
        Ok(Store {
            db,
            artifacts,
            uploads_dir,
        })
    }

    /// The database engine.
    pub fn backend(&self) -> Backend {
        self.db.backend()
    }

    /// Whether the database answers.
    pub fn ping(&self) -> io::Result<()> {
        self.db.ping()
    }

    /// On a process's start. SQLite (one process owns the database): puts
    /// the jobs a previous process left `running` back in the queue and
    /// removes the files of jobs that were never accepted and the uploads
    /// it was receiving. PostgreSQL (shared): nothing; a job whose
    /// worker died is claimed again when its lease runs out.
    pub fn recover(&self) -> io::Result<()> {
        if self.backend() == Backend::Postgres {
            return Ok(());
        }
        self.db.execute(
            "UPDATE jobs SET state = ?1, stage = NULL, started_ms = NULL, progress = NULL,
                 lease_owner = NULL, lease_until_ms = NULL
             WHERE state IN (?1, ?2)",
            &[state(JobState::Queued), state(JobState::Running)],
        )?;
        // Inputs are written before their row is committed: files without
        // a row belong to a submission that was never accepted.
        let known: Vec<i64> = self
            .db
            .query("SELECT id FROM jobs", &[])?
            .iter()
            .filter_map(|r| r.int(0))
            .collect();
        // Uploads a previous process was receiving were never accepted.
        for entry in std::fs::read_dir(&self.uploads_dir)? {
            let _ = std::fs::remove_dir_all(entry?.path());
        }
        for id in self.artifacts.job_ids()? {
            if !known.contains(&id) {
                self.artifacts.delete_job(id)?;
            }
        }
        Ok(())
    }

    /// Job `id`'s inputs and results.
    pub fn files(&self, id: i64) -> JobFiles<'_> {
        JobFiles {
            artifacts: &self.artifacts,
            id,
        }
    }

    /// The artifact store.
    pub fn artifacts(&self) -> &Artifacts {
        &self.artifacts
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
    /// inputs in `staged`: allocates its ids, writes the inputs to the
    /// artifact store, then commits its row as `queued`. Returns the
    /// internal and the public id.
    pub fn create(
        &self,
        staged: &Staged,
        bake: bool,
        tenant: Option<&str>,
        tiles: &[Vec<u8>],
    ) -> io::Result<(i64, String)> {
        use std::io::Read;
        let id = self.next_id()?;
        let mut magic = [0u8; 4];
        let glb = std::fs::File::open(staged.path(SCENE))?
            .read_exact(&mut magic)
            .is_ok()
            && &magic == b"glTF";
        for name in [SCENE, JOB, PVS] {
            if !self.artifacts.put_file(id, name, &staged.path(name))? && name != PVS {
                return Err(io::Error::new(
                    io::ErrorKind::NotFound,
                    format!("the upload has no {name}"),
                ));
            }
        }
        let kind = if glb { "glb" } else { "json" };
        let uid = new_uid();
        let row = |id: i64, uid: &str, bake: bool, parent: Option<i64>, tiles: Option<i64>| {
            self.db.execute(
                "INSERT INTO jobs (id, uid, state, bake, scene_kind, created_ms, tenant,
                                   parent_id, tiles)
                 VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9)",
                &[
                    int(id),
                    text(uid),
                    state(JobState::Queued),
                    int(bake as i64),
                    text(kind),
                    int(now_ms()),
                    Value::from(tenant),
                    Value::from(parent),
                    Value::from(tiles),
                ],
            )
        };
        // A tiled job: the parent's row first (it waits until all its
        // tiles' rows exist and are final), then one job per tile, its
        // inputs copied from the parent's (hard links in a folder).
        let n = (!tiles.is_empty()).then_some(tiles.len() as i64);
        row(id, &uid, bake, None, n)?;
        for t in tiles {
            let child = self.next_id()?;
            for name in [SCENE, PVS] {
                self.artifacts.copy(id, child, name)?;
            }
            self.artifacts.put(child, JOB, t.clone())?;
            row(child, &new_uid(), false, Some(id), None)?;
        }
        Ok((id, uid))
    }

    /// A new internal id. Ids are never reused, not even those of deleted
    /// jobs; the update is atomic, so processes sharing the database never
    /// get the same.
    fn next_id(&self) -> io::Result<i64> {
        self.db
            .query_one(
                "UPDATE meta SET v = v + 1 WHERE k = 'next_id' RETURNING v - 1",
                &[],
            )?
            .and_then(|r| r.int(0))
            .ok_or_else(|| io::Error::other("the database has no next_id"))
    }

    /// The rows of the tiles of job `id`, in tile order.
    pub fn children(&self, id: i64) -> io::Result<Vec<JobRow>> {
        self.rows_where("parent_id = ?1 ORDER BY id", &[int(id)])
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
        std::fs::write(staged.path(SCENE), scene)?;
        std::fs::write(staged.path(JOB), job)?;
        if let Some(p) = pvs {
            std::fs::write(staged.path(PVS), p)?;
        }
        self.create(&staged, false, tenant, &[])
    }

    /// Claims the oldest job that is queued (a tiled job's merge once all
    /// its tiles are final), or running with a lease that ran out (its
    /// worker died: the job runs again from its inputs), for worker
    /// `owner` with a lease of `lease_ms`. Returns its id, whether it bakes
    /// and whether it is a tiled job's merge. On PostgreSQL, concurrent claims skip each
    /// other's rows (`FOR UPDATE SKIP LOCKED`), so no two workers take the
    /// same job.
    pub fn claim(&self, owner: &str, lease_ms: i64) -> io::Result<Option<Claimed>> {
        let now = now_ms();
        let lock = match self.backend() {
            Backend::Postgres => "FOR UPDATE SKIP LOCKED",
            Backend::Sqlite => "",
        };
        let row = self.db.query_one(
            &format!(
                "UPDATE jobs SET state = ?3, lease_owner = ?1, lease_until_ms = ?2 + ?4,
                     started_ms = ?2, stage = 'loading', progress = 0, attempts = attempts + 1
                 WHERE id = (SELECT id FROM jobs j
                             WHERE (state = ?5 AND (tiles IS NULL OR tiles =
                                       (SELECT COUNT(*) FROM jobs c WHERE c.parent_id = j.id
                                        AND c.state IN ({FINAL}))))
                                OR (state = ?3 AND lease_until_ms < ?2)
                             ORDER BY id LIMIT 1 {lock})
                 RETURNING id, bake, tiles, parent_id"
            ),
            &[
                text(owner),
                int(now),
                state(JobState::Running),
                int(lease_ms),
                state(JobState::Queued),
            ],
        )?;
        Ok(row.and_then(|r| {
            Some(Claimed {
                id: r.int(0)?,
                bake: r.int(1)? != 0,
                run: match (r.int(2), r.int(3)) {
                    (Some(_), _) => Run::Merge,
                    (None, Some(_)) => Run::Tile,
                    (None, None) => Run::Whole,
                },
            })
        }))
    }

    /// Renews `owner`'s lease of running job `id` for `lease_ms` more and
    /// records its live stage and progress.
    pub fn renew(
        &self,
        id: i64,
        owner: &str,
        lease_ms: i64,
        stage: &str,
        progress: f64,
    ) -> io::Result<Renewal> {
        let row = self.db.query_one(
            "UPDATE jobs SET lease_until_ms = ?3, stage = ?4, progress = ?5
             WHERE id = ?1 AND lease_owner = ?2 AND state = ?6
             RETURNING cancel_requested",
            &[
                int(id),
                text(owner),
                int(now_ms() + lease_ms),
                text(stage),
                Value::from(progress),
                state(JobState::Running),
            ],
        )?;
        Ok(Renewal {
            held: row.is_some(),
            cancel: row.and_then(|r| r.int(0)).is_some_and(|c| c != 0),
        })
    }

    /// Records the final state of job `id` run by `owner`, with its error or
    /// summary, if `owner` still holds its lease (false otherwise: another
    /// worker took the job over, and this run's end is not recorded).
    pub fn finish(
        &self,
        id: i64,
        owner: &str,
        end: JobState,
        error: Option<&str>,
        summary: Option<&str>,
    ) -> io::Result<bool> {
        let n = self.db.execute(
            "UPDATE jobs SET state = ?3, error = ?4, summary = ?5, finished_ms = ?6,
                 stage = NULL, progress = NULL, lease_owner = NULL, lease_until_ms = NULL, completions = completions + 1
             WHERE id = ?1 AND lease_owner = ?2 AND state = ?7",
            &[
                int(id),
                text(owner),
                state(end),
                Value::from(error),
                Value::from(summary),
                int(now_ms()),
                state(JobState::Running),
            ],
        )?;
        Ok(n == 1)
    }

    /// Gives job `id`'s lease back (a worker shutting down): the job is
    /// queued again for any worker.
    pub fn release(&self, id: i64, owner: &str) -> io::Result<bool> {
        let n = self.db.execute(
            "UPDATE jobs SET state = ?3, stage = NULL, progress = NULL, started_ms = NULL,
                 lease_owner = NULL, lease_until_ms = NULL
             WHERE id = ?1 AND lease_owner = ?2 AND state = ?4",
            &[
                int(id),
                text(owner),
                state(JobState::Queued),
                state(JobState::Running),
            ],
        )?;
        Ok(n == 1)
    }

    /// Cancels job `id` if it is still queued (true), in one statement, so a
    /// worker's claim and the cancel never both succeed.
    pub fn cancel_queued(&self, id: i64) -> io::Result<bool> {
        // A tiled job's tiles first (queued ones end, running ones are
        // asked to stop), then the job.
        for c in self.children(id)? {
            if !self.cancel_queued(c.id)? && c.state == JobState::Running {
                self.request_cancel(c.id)?;
            }
        }
        let n = self.db.execute(
            "UPDATE jobs SET state = ?2, error = ?3, finished_ms = ?4 WHERE id = ?1 AND state = ?5",
            &[
                int(id),
                state(JobState::Cancelled),
                text(crate::job::CANCELLED_BY_REQUEST),
                int(now_ms()),
                state(JobState::Queued),
            ],
        )?;
        Ok(n == 1)
    }

    /// Asks running job `id` to stop: its worker sees it at its next
    /// lease renewal.
    pub fn request_cancel(&self, id: i64) -> io::Result<()> {
        self.db.execute(
            "UPDATE jobs SET cancel_requested = 1 WHERE id = ?1",
            &[int(id)],
        )?;
        Ok(())
    }

    /// Records that worker `id` is alive (`/metrics` counts workers seen
    /// lately).
    pub fn worker_seen(&self, id: &str) -> io::Result<()> {
        let now = now_ms();
        self.db.execute(
            "INSERT INTO workers (id, started_ms, seen_ms) VALUES (?1, ?2, ?2)
             ON CONFLICT (id) DO UPDATE SET seen_ms = ?2",
            &[text(id), int(now)],
        )?;
        Ok(())
    }

    /// Forgets worker `id` (it stopped).
    pub fn worker_gone(&self, id: &str) -> io::Result<()> {
        self.db
            .execute("DELETE FROM workers WHERE id = ?1", &[text(id)])?;
        Ok(())
    }

    /// Jobs waiting for a worker.
    pub fn queued(&self) -> io::Result<usize> {
        Ok(self
            .db
            .query_one(
                "SELECT COUNT(*) FROM jobs WHERE state = ?1 AND parent_id IS NULL",
                &[state(JobState::Queued)],
            )?
            .and_then(|r| r.int(0))
            .unwrap_or(0) as usize)
    }

    /// The figures `/metrics` reports.
    pub fn figures(&self) -> io::Result<Figures> {
        let mut f = Figures {
            buckets: vec![0; DURATION_BUCKETS.len()],
            ..Figures::default()
        };
        for r in self
            .db
            .query("SELECT state, COUNT(*) FROM jobs GROUP BY state", &[])?
        {
            if let (Some(s), Some(n)) = (r.text(0), r.int(1))
                && let Some(i) = JobState::ALL.iter().position(|x| x.as_str() == s)
            {
                f.by_state[i] = n as u64;
            }
        }
        f.workers = self
            .db
            .query_one(
                "SELECT COUNT(*) FROM workers WHERE seen_ms >= ?1",
                &[int(now_ms() - WORKER_SEEN_MS)],
            )?
            .and_then(|r| r.int(0))
            .unwrap_or(0) as u64;
        for r in self.db.query(
            "SELECT finished_ms - started_ms FROM jobs
             WHERE finished_ms IS NOT NULL AND started_ms IS NOT NULL",
            &[],
        )? {
            let s = r.int(0).unwrap_or(0).max(0) as f64 / 1000.0;
            f.finished += 1;
            f.finished_seconds += s;
            for (b, &le) in f.buckets.iter_mut().zip(&DURATION_BUCKETS) {
                *b += u64::from(s <= le);
            }
        }
        Ok(f)
    }

    /// The row of job `id`; `Ok(None)` when there is no such job (or its
    /// row cannot be read).
    pub fn row(&self, id: i64) -> io::Result<Option<JobRow>> {
        self.row_where("id = ?1", &[int(id)])
    }

    /// The row of the job of public id `uid` that belongs to `tenant`
    /// (`None`: to anyone), in one query; `Ok(None)` when there is none.
    pub fn find(&self, uid: &str, tenant: Option<&str>) -> io::Result<Option<JobRow>> {
        self.row_where(
            "uid = ?1 AND (CAST(?2 AS TEXT) IS NULL OR tenant = ?2)",
            &[text(uid), Value::from(tenant)],
        )
    }

    fn row_where(&self, condition: &str, params: &[Value]) -> io::Result<Option<JobRow>> {
        Ok(self.rows_where(condition, params)?.into_iter().next())
    }

    /// The rows `condition` selects, in one query (unreadable ones left out).
    fn rows_where(&self, condition: &str, params: &[Value]) -> io::Result<Vec<JobRow>> {
        let rows = self.db.query(
            &format!(
                "SELECT state, stage, error, summary, bake, created_ms, started_ms, finished_ms,
                        uid, id, progress, tiles
                 FROM jobs WHERE {condition}"
            ),
            params,
        )?;
        Ok(rows
            .iter()
            .filter_map(|r| {
                Some(JobRow {
                    state: r.text(0)?.parse().ok()?,
                    stage: r.text(1),
                    error: r.text(2),
                    summary: r.text(3),
                    bake: r.int(4)? != 0,
                    created_ms: r.int(5)?,
                    started_ms: r.int(6),
                    finished_ms: r.int(7),
                    uid: r.text(8)?,
                    id: r.int(9)?,
                    progress: r.real(10),
                    tiles: r.int(11),
                })
            })
            .collect())
    }

    /// The jobs of `tenant` queued or running.
    pub fn active_jobs(&self, tenant: &str) -> io::Result<usize> {
        Ok(self
            .db
            .query_one(
                "SELECT COUNT(*) FROM jobs WHERE tenant = ?1 AND state IN (?2, ?3)
                 AND parent_id IS NULL",
                &[
                    text(tenant),
                    state(JobState::Queued),
                    state(JobState::Running),
                ],
            )?
            .and_then(|r| r.int(0))
            .unwrap_or(0) as usize)
    }

    /// Up to `limit` ids of jobs of `tenant` (`None`: of anyone) greater
    /// than `after`, ascending.
    pub fn ids_after(&self, after: i64, limit: i64, tenant: Option<&str>) -> io::Result<Vec<i64>> {
        Ok(self
            .db
            .query(
                "SELECT id FROM jobs WHERE id > ?1 AND (CAST(?3 AS TEXT) IS NULL OR tenant = ?3)
                 AND parent_id IS NULL ORDER BY id LIMIT ?2",
                &[int(after), int(limit), Value::from(tenant)],
            )?
            .iter()
            .filter_map(|r| r.int(0))
            .collect())
    }

    /// The jobs that reached a final state before `cutoff_ms` (ms since
    /// the Unix epoch), oldest first.
    pub fn finished_before(&self, cutoff_ms: i64) -> io::Result<Vec<i64>> {
        Ok(self
            .db
            .query(
                "SELECT id FROM jobs WHERE finished_ms IS NOT NULL AND finished_ms < ?1
                 AND state IN (?2, ?3, ?4) AND parent_id IS NULL ORDER BY id",
                &[
                    int(cutoff_ms),
                    state(JobState::Succeeded),
                    state(JobState::Failed),
                    state(JobState::Cancelled),
                ],
            )?
            .iter()
            .filter_map(|r| r.int(0))
            .collect())
    }

    /// Removes job `id`'s row and its tiles', then their files (a file left
    /// by a failure here is removed by the next start's recovery, SQLite).
    pub fn delete(&self, id: i64) -> io::Result<()> {
        let children: Vec<i64> = self.children(id)?.iter().map(|c| c.id).collect();
        self.db.execute(
            "DELETE FROM jobs WHERE id = ?1 OR parent_id = ?1",
            &[int(id)],
        )?;
        for c in children.into_iter().chain([id]) {
            if let Err(e) = self.artifacts.delete_job(c) {
                tracing::warn!(job = c, "files not removed: {e}");
            }
        }
        Ok(())
    }

    /// Sets job `id`'s state as it is, whoever runs it (tests).
    #[cfg(test)]
    pub fn set_state(&self, id: i64, end: JobState) {
        let _ = self.db.execute(
            "UPDATE jobs SET state = ?2 WHERE id = ?1",
            &[int(id), state(end)],
        );
    }
}

/// The tables of a SQLite database from before migrations existed, and
/// the columns its older versions lacked (their own small upgrades).
fn sqlite_setup(db: &rusqlite::Connection) -> io::Result<()> {
    db.execute_batch(
        "CREATE TABLE IF NOT EXISTS jobs (
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
    let has = |column: &str| {
        db.prepare("SELECT 1 FROM pragma_table_info('jobs') WHERE name = ?1")
            .and_then(|mut s| s.exists([column]))
            .map_err(db_err)
    };
    if !has("uid")? {
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
    if !has("tenant")? {
        db.execute_batch("ALTER TABLE jobs ADD COLUMN tenant TEXT")
            .map_err(db_err)?;
    }
    db.execute_batch("CREATE INDEX IF NOT EXISTS jobs_tenant ON jobs (tenant, id)")
        .map_err(db_err)?;
    // The next id of versions that kept it only after the first job.
    db.execute_batch(
        "INSERT INTO meta (k, v) SELECT 'next_id', COALESCE(MAX(id), 0) + 1 FROM jobs
             WHERE true ON CONFLICT (k) DO UPDATE SET v = MAX(v, excluded.v)",
    )
    .map_err(db_err)?;
    Ok(())
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
            let db = rusqlite::Connection::open(dir.join("jobs.sqlite")).unwrap();
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
        let store = Store::open(&dir, None, None).unwrap();
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
        let store = Store::open(&dir, None, None).unwrap();
        assert_eq!(store.find(&old, None).unwrap().map(|r| r.id), Some(1));
        assert_eq!(store.find(&ua, None).unwrap().map(|r| r.id), Some(2));
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// A tenant finds and lists only its own jobs and counts its active
    /// ones; without a tenant every job is found.
    #[test]
    fn tenants_see_only_their_jobs() {
        let dir = temp_dir("tenant");
        let store = Store::open(&dir, None, None).unwrap();
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
        store.set_state(c, JobState::Succeeded);
        assert_eq!(store.active_jobs("a").unwrap(), 1);
        assert_eq!(store.active_jobs("nobody").unwrap(), 0);
        let _ = std::fs::remove_dir_all(&dir);
    }
}
