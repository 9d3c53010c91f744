//! HTTP service over the [`optimizer`] library: submit scene jobs, follow
//! their progress, fetch placements, evaluations and baked impostors.
//!
//! The service is thin: it validates, schedules, stores and serves; every
//! geometric computation lives in the `optimizer` crate. CPU work runs on a
//! fixed pool of worker threads, off the async runtime; the queue is bounded.
//!
//! Durability: jobs live in an SQLite database in the data directory (WAL,
//! `synchronous = FULL`); a job's inputs are written (and synced) into
//! `jobs/<id>/` before its row is committed, and every result file is
//! written to a temporary name, synced and renamed before the row says
//! `succeeded`. On start, jobs left `queued` or `running` by a crash are
//! queued again, so every accepted job reaches a final state and no finished
//! result is ever truncated.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, mpsc};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use axum::Router;
use axum::body::Bytes;
use axum::extract::{DefaultBodyLimit, Multipart, Path as UrlPath, Query, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use serde::Deserialize;
use serde_json::{Value, json};

use optimizer::api::job::Job;

pub mod client;
pub mod openapi;
use optimizer::place::{Control, PlaceOptions, place_shared};

/// Version of the optimizer library this service is built against.
pub const OPTIMIZER_VERSION: &str = optimizer::VERSION;

/// Service configuration.
#[derive(Clone, Debug)]
pub struct Config {
    /// Where the database and the job files live.
    pub data_dir: PathBuf,
    /// Worker threads (jobs run one per worker).
    pub workers: usize,
    /// Largest request body, MiB.
    pub max_upload_mb: usize,
    /// Most jobs waiting in the queue.
    pub max_queue: usize,
    /// Views of the evaluation run after each placement.
    pub eval_views: u64,
}

impl Config {
    /// Defaults for a data directory.
    pub fn new(data_dir: impl Into<PathBuf>) -> Self {
        Config {
            data_dir: data_dir.into(),
            workers: 1,
            max_upload_mb: 256,
            max_queue: 64,
            eval_views: 10_000,
        }
    }
}

/// Live progress of a running job.
struct Live {
    stage: String,
    progress: f64,
    cancel: Arc<AtomicBool>,
}

struct Inner {
    cfg: Config,
    db: Mutex<rusqlite::Connection>,
    queue: Mutex<mpsc::Sender<i64>>,
    queued: AtomicUsize,
    live: Mutex<HashMap<i64, Live>>,
}

/// Shared state of the service.
#[derive(Clone)]
pub struct AppState(Arc<Inner>);

/// An error answer: status and a JSON `{"error": ...}` body.
#[derive(Debug)]
pub struct ApiError(StatusCode, String);

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let mut r = (self.0, axum::Json(json!({ "error": self.1 }))).into_response();
        if self.0 == StatusCode::TOO_MANY_REQUESTS {
            r.headers_mut()
                .insert(header::RETRY_AFTER, HeaderValue::from_static("5"));
        }
        r
    }
}

fn err(status: StatusCode, msg: impl Into<String>) -> ApiError {
    ApiError(status, msg.into())
}

fn internal(e: impl std::fmt::Display) -> ApiError {
    err(
        StatusCode::INTERNAL_SERVER_ERROR,
        format!("internal error: {e}"),
    )
}

fn now_ms() -> i64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_millis() as i64)
}

/// Writes `bytes` to `path` atomically: temporary file, sync, rename, sync
/// of the directory.
fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
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

impl AppState {
    /// Opens (or creates) the data directory and its database, re-queues the
    /// jobs a previous process left unfinished and starts the workers.
    pub fn open(cfg: Config) -> std::io::Result<AppState> {
        let io = |e: rusqlite::Error| std::io::Error::other(e.to_string());
        std::fs::create_dir_all(cfg.data_dir.join("jobs"))?;
        let db = rusqlite::Connection::open(cfg.data_dir.join("jobs.sqlite")).map_err(io)?;
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
        .map_err(io)?;
        // Unfinished jobs of a previous process run again.
        db.execute(
            "UPDATE jobs SET state = 'queued', stage = NULL, started_ms = NULL
             WHERE state IN ('queued', 'running')",
            [],
        )
        .map_err(io)?;
        let pending: Vec<i64> = {
            let mut st = db
                .prepare("SELECT id FROM jobs WHERE state = 'queued' ORDER BY id")
                .map_err(io)?;
            st.query_map([], |r| r.get(0))
                .map_err(io)?
                .collect::<rusqlite::Result<_>>()
                .map_err(io)?
        };
        // Job directories without a row were never accepted.
        let known: Vec<i64> = {
            let mut st = db.prepare("SELECT id FROM jobs").map_err(io)?;
            st.query_map([], |r| r.get(0))
                .map_err(io)?
                .collect::<rusqlite::Result<_>>()
                .map_err(io)?
        };
        for entry in std::fs::read_dir(cfg.data_dir.join("jobs"))? {
            let entry = entry?;
            let id = entry.file_name().to_string_lossy().parse::<i64>().ok();
            if id.is_none_or(|id| !known.contains(&id)) {
                let _ = std::fs::remove_dir_all(entry.path());
            }
        }
        let (tx, rx) = mpsc::channel::<i64>();
        let state = AppState(Arc::new(Inner {
            cfg,
            db: Mutex::new(db),
            queue: Mutex::new(tx),
            queued: AtomicUsize::new(0),
            live: Mutex::new(HashMap::new()),
        }));
        for id in pending {
            state.enqueue(id);
        }
        let rx = Arc::new(Mutex::new(rx));
        for w in 0..state.0.cfg.workers.max(1) {
            let st = state.clone();
            let rx = rx.clone();
            std::thread::Builder::new()
                .name(format!("worker-{w}"))
                .spawn(move || {
                    loop {
                        let next = rx.lock().map(|r| r.recv());
                        match next {
                            Ok(Ok(id)) => {
                                st.0.queued.fetch_sub(1, Ordering::SeqCst);
                                st.run_job(id);
                            }
                            _ => break,
                        }
                    }
                })?;
        }
        Ok(state)
    }

    fn enqueue(&self, id: i64) {
        self.0.queued.fetch_add(1, Ordering::SeqCst);
        if let Ok(tx) = self.0.queue.lock() {
            let _ = tx.send(id);
        }
    }

    fn job_dir(&self, id: i64) -> PathBuf {
        self.0.cfg.data_dir.join("jobs").join(id.to_string())
    }

    fn set_state(&self, id: i64, state: &str, error: Option<&str>, summary: Option<&str>) {
        let Ok(db) = self.0.db.lock() else { return };
        let finished = matches!(state, "succeeded" | "failed" | "cancelled").then(now_ms);
        let started = (state == "running").then(now_ms);
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

    fn row_state(&self, id: i64) -> Option<String> {
        let db = self.0.db.lock().ok()?;
        db.query_row("SELECT state FROM jobs WHERE id = ?1", [id], |r| r.get(0))
            .ok()
    }

    /// Runs one job on the calling (worker) thread.
    fn run_job(&self, id: i64) {
        if self.row_state(id).as_deref() != Some("queued") {
            return;
        }
        let cancel = Arc::new(AtomicBool::new(false));
        if let Ok(mut live) = self.0.live.lock() {
            live.insert(
                id,
                Live {
                    stage: "loading".into(),
                    progress: 0.0,
                    cancel: cancel.clone(),
                },
            );
        }
        self.set_state(id, "running", None, None);
        tracing::info!(job = id, "running");
        let outcome =
            std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| self.place_job(id, &cancel)));
        if let Ok(mut live) = self.0.live.lock() {
            live.remove(&id);
        }
        match outcome {
            Ok(Ok(summary)) => {
                tracing::info!(job = id, "succeeded");
                self.set_state(id, "succeeded", None, Some(&summary));
            }
            Ok(Err(optimizer::Error::Cancelled)) => {
                tracing::info!(job = id, "cancelled");
                self.set_state(id, "cancelled", Some("cancelled by request"), None);
            }
            Ok(Err(e)) => {
                tracing::warn!(job = id, "failed: {e}");
                self.set_state(id, "failed", Some(&e.to_string()), None);
            }
            Err(_) => {
                tracing::error!(job = id, "panicked");
                self.set_state(id, "failed", Some("internal error (a bug)"), None);
            }
        }
    }

    fn place_job(&self, id: i64, cancel: &AtomicBool) -> optimizer::Result<String> {
        let dir = self.job_dir(id);
        let io = |p: PathBuf| move |e| optimizer::Error::io(p, e);
        let scene_bytes = std::fs::read(dir.join("scene")).map_err(io(dir.join("scene")))?;
        let job_bytes = std::fs::read(dir.join("job.json")).map_err(io(dir.join("job.json")))?;
        let job = Job::from_json(&job_bytes, "job")?;
        let scene = optimizer::scene::gltf_load::load_scene_bytes(&scene_bytes, "scene")?;
        // Geometry when the job needs it, or for the evaluation's check of
        // the visible sets when the scene has any.
        let geometry = if optimizer::input::needs_geometry(&job)
            || (job.visibility.mode != optimizer::api::job::VisibilityMode::None
                && scene_bytes.starts_with(b"glTF"))
        {
            Some(optimizer::scene::geometry::load_geometry_bytes(
                &scene_bytes,
                "scene",
            )?)
        } else {
            None
        };
        let pvs_path = dir.join("pvs.json");
        let pvs = if pvs_path.exists() {
            let bytes = std::fs::read(&pvs_path).map_err(io(pvs_path.clone()))?;
            Some(optimizer::api::pvs::PvsFile::from_json(&bytes, "pvs")?)
        } else {
            None
        };
        let input = optimizer::input::SceneInput::new(scene, geometry, pvs, &job)?;
        let progress = |stage: &str, f: f64| {
            if let Ok(mut live) = self.0.live.lock()
                && let Some(l) = live.get_mut(&id)
            {
                if l.stage != stage {
                    tracing::info!(job = id, stage, "stage");
                }
                l.stage = stage.to_string();
                l.progress = f;
            }
        };
        let ctl = Control {
            cancel: Some(cancel),
            on_progress: Some(&progress),
        };
        let hierarchy = optimizer::scene::hierarchy::Hierarchy::build(&input.scene);
        let visibility = optimizer::visibility::Visibility::new(
            &job,
            &input.scene,
            &hierarchy,
            input.visibility_inputs(&job),
        )?;
        let shared = optimizer::evaluate::Shared {
            hierarchy: &hierarchy,
            visibility: visibility.as_ref(),
        };
        let start = std::time::Instant::now();
        let out = place_shared(&input, &job, &PlaceOptions::default(), &ctl, &shared)?;
        let place_seconds = start.elapsed().as_secs_f64();
        let placement = optimizer::to_json_bytes(&out.placement)?;
        write_atomic(&dir.join("placement.json"), &placement)
            .map_err(io(dir.join("placement.json")))?;
        progress("evaluate", 0.98);
        let eval = optimizer::evaluate::evaluate_shared(
            &input,
            &job,
            &out.placement,
            &optimizer::evaluate::EvalOptions {
                views: self.0.cfg.eval_views,
                seed: 1,
                ..optimizer::evaluate::EvalOptions::default()
            },
            "placement",
            &shared,
        )?;
        // A one-run report: the job's placement, evaluation and walkthrough.
        let frames = optimizer::evaluate::frame_times(
            &input,
            &job,
            &out.placement,
            &optimizer::evaluate::walkthrough_views(&job),
            "placement",
            &shared,
        )?;
        let report = one_run_report(&input, &job_bytes, &job, &out, &eval, place_seconds, frames);
        write_atomic(
            &dir.join("report.html"),
            optimizer::report::render::render_html(&report).as_bytes(),
        )
        .map_err(io(dir.join("report.html")))?;
        write_atomic(
            &dir.join("evaluation.json"),
            &optimizer::to_json_bytes(&eval)?,
        )
        .map_err(io(dir.join("evaluation.json")))?;
        let bake = {
            let db = self
                .0
                .db
                .lock()
                .map_err(|_| optimizer::Error::Internal("database lock".into()))?;
            db.query_row("SELECT bake FROM jobs WHERE id = ?1", [id], |r| {
                r.get::<_, i64>(0)
            })
            .map_err(|e| optimizer::Error::Internal(e.to_string()))?
                != 0
        };
        if bake {
            if cancel.load(Ordering::Relaxed) {
                return Err(optimizer::Error::Cancelled);
            }
            progress("bake", 0.99);
            let geom = optimizer::scene::geometry::load_geometry_bytes(&scene_bytes, "scene")?;
            let (glb, _) = optimizer::bake::bake(
                &geom,
                &job.memory,
                &out.placement,
                &optimizer::bake::BakeOptions::default(),
                "placement",
            )?;
            write_atomic(&dir.join("impostors.glb"), &glb)
                .map_err(io(dir.join("impostors.glb")))?;
        }
        let mut summary = serde_json::to_value(&out.placement.summary)
            .map_err(|e| optimizer::Error::Internal(e.to_string()))?;
        summary["max_ms"] = json!(eval.max_ms);
        summary["violations_in_solved"] = json!(eval.violations_in_solved);
        if let Some(x) = &eval.parallax {
            summary["parallax_max_px"] = json!(x.max_px);
        }
        summary["seconds"] = serde_json::to_value(&out.stats.seconds)
            .map_err(|e| optimizer::Error::Internal(e.to_string()))?;
        Ok(summary.to_string())
    }

    /// Validates and stores a job, then queues it. Returns its id.
    fn submit(
        &self,
        scene: &[u8],
        job: &[u8],
        pvs: Option<&[u8]>,
        bake: bool,
    ) -> Result<i64, ApiError> {
        let unprocessable = |e: optimizer::Error| {
            if e.is_bad_input() {
                err(StatusCode::UNPROCESSABLE_ENTITY, e.to_string())
            } else {
                internal(e)
            }
        };
        let parsed = Job::from_json(job, "job").map_err(unprocessable)?;
        let objects = optimizer::scene::gltf_load::load_scene_bytes(scene, "scene")
            .map_err(unprocessable)?
            .objects
            .len();
        if optimizer::input::needs_geometry(&parsed) && !scene.starts_with(b"glTF") {
            // A summary (or glTF JSON): check it has geometry at all.
            optimizer::scene::geometry::load_geometry_bytes(scene, "scene").map_err(|e| {
                err(
                    StatusCode::UNPROCESSABLE_ENTITY,
                    format!("the job's visibility or lod.generate needs the scene's geometry: {e}"),
                )
            })?;
        }
        match (parsed.visibility.mode, pvs) {
            (optimizer::api::job::VisibilityMode::Precomputed, None) => {
                return Err(err(
                    StatusCode::UNPROCESSABLE_ENTITY,
                    "job: visibility \"precomputed\" needs a `pvs` part (a PVS file)",
                ));
            }
            (_, Some(bytes)) => {
                optimizer::api::pvs::PvsFile::from_json(bytes, "pvs")
                    .and_then(|f| f.check(objects, "pvs"))
                    .map_err(unprocessable)?;
            }
            _ => {}
        }
        if bake && !scene.starts_with(b"glTF") && scene.first() == Some(&b'{') {
            // A summary (or glTF JSON); baking needs geometry.
            optimizer::scene::geometry::load_geometry_bytes(scene, "scene")
                .map_err(unprocessable)?;
        }
        if self.0.queued.load(Ordering::SeqCst) >= self.0.cfg.max_queue {
            return Err(err(
                StatusCode::TOO_MANY_REQUESTS,
                format!("the queue is full ({} jobs waiting)", self.0.cfg.max_queue),
            ));
        }
        let db = self.0.db.lock().map_err(internal)?;
        // Ids are never reused, not even those of deleted jobs.
        let id: i64 = db
            .query_row(
                "SELECT MAX(COALESCE((SELECT v FROM meta WHERE k = 'next_id'), 1),
                            COALESCE((SELECT MAX(id) FROM jobs), 0) + 1)",
                [],
                |r| r.get(0),
            )
            .map_err(internal)?;
        db.execute(
            "INSERT INTO meta (k, v) VALUES ('next_id', ?1) ON CONFLICT(k) DO UPDATE SET v = ?1",
            [id + 1],
        )
        .map_err(internal)?;
        let dir = self.job_dir(id);
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).map_err(internal)?;
        write_atomic(&dir.join("scene"), scene).map_err(internal)?;
        write_atomic(&dir.join("job.json"), job).map_err(internal)?;
        if let Some(p) = pvs {
            write_atomic(&dir.join("pvs.json"), p).map_err(internal)?;
        }
        let kind = if scene.starts_with(b"glTF") {
            "glb"
        } else {
            "json"
        };
        db.execute(
            "INSERT INTO jobs (id, state, bake, scene_kind, created_ms) VALUES (?1, 'queued', ?2, ?3, ?4)",
            rusqlite::params![id, bake as i64, kind, now_ms()],
        )
        .map_err(internal)?;
        drop(db);
        tracing::info!(job = id, "accepted");
        self.enqueue(id);
        Ok(id)
    }

    fn status(&self, id: i64) -> Result<Value, ApiError> {
        let db = self.0.db.lock().map_err(internal)?;
        let row = db
            .query_row(
                "SELECT state, stage, error, summary, bake, created_ms, started_ms, finished_ms
                 FROM jobs WHERE id = ?1",
                [id],
                |r| {
                    Ok((
                        r.get::<_, String>(0)?,
                        r.get::<_, Option<String>>(1)?,
                        r.get::<_, Option<String>>(2)?,
                        r.get::<_, Option<String>>(3)?,
                        r.get::<_, i64>(4)?,
                        r.get::<_, i64>(5)?,
                        r.get::<_, Option<i64>>(6)?,
                        r.get::<_, Option<i64>>(7)?,
                    ))
                },
            )
            .map_err(|_| err(StatusCode::NOT_FOUND, format!("no job {id}")))?;
        drop(db);
        let (state, stage, error, summary, bake, created, started, finished) = row;
        let (stage, progress) = match self
            .0
            .live
            .lock()
            .ok()
            .and_then(|l| l.get(&id).map(|l| (l.stage.clone(), l.progress)))
        {
            Some((s, p)) => (Some(s), p),
            None => (stage, if state == "succeeded" { 1.0 } else { 0.0 }),
        };
        Ok(json!({
            "id": id,
            "state": state,
            "stage": stage,
            "progress": progress,
            "bake": bake != 0,
            "created_ms": created,
            "started_ms": started,
            "finished_ms": finished,
            "summary": summary.and_then(|s| serde_json::from_str::<Value>(&s).ok()),
            "error": error,
        }))
    }
}

/// The report of one job: its run, its evaluation and its walkthrough.
fn one_run_report(
    input: &optimizer::input::SceneInput,
    job_bytes: &[u8],
    job: &Job,
    out: &optimizer::place::PlaceOutput,
    eval: &optimizer::api::evaluation::Evaluation,
    seconds: f64,
    frames: Vec<f64>,
) -> optimizer::report::Report {
    use optimizer::report::{EvalSummary, Report, Run, SceneInfo, Walkthrough};
    let method = job.method().name().to_string();
    let s = &out.placement.summary;
    let (lo, hi) = input.scene.bounds();
    Report {
        version: optimizer::VERSION.into(),
        created: optimizer::report::run::now_rfc3339(),
        machine: optimizer::report::run::machine(),
        scene: SceneInfo {
            name: "scene".into(),
            objects: input.scene.objects.len() as u64,
            triangles: input.scene.total_triangles(),
            min: lo.to_array(),
            max: hi.to_array(),
        },
        job: serde_json::from_slice(job_bytes).unwrap_or(Value::Null),
        methods: vec![method.clone()],
        sweeps: Vec::new(),
        runs: vec![Run {
            method: method.clone(),
            knob: None,
            value: None,
            target_frame_time_ms: job.target_frame_time_ms,
            status: "ok".into(),
            error: None,
            cpvs: s.cpvs,
            candidates: s.candidates,
            impostors: s.impostors,
            memory_bytes: s.memory_bytes,
            unsolved_cpvs: s.unsolved_cpvs,
            seconds,
            stage_seconds: out.stats.seconds.clone(),
            eval: Some(EvalSummary::from(eval)),
        }],
        walkthroughs: vec![Walkthrough {
            method,
            target_frame_time_ms: job.target_frame_time_ms,
            frame_ms: frames,
        }],
        stability: None,
    }
}

/// The JSON submission body: a scene summary inline.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct JsonSubmission {
    scene: Value,
    job: Value,
    #[serde(default)]
    pvs: Option<Value>,
    #[serde(default)]
    bake: bool,
}

async fn submit(
    State(st): State<AppState>,
    headers: HeaderMap,
    req: axum::extract::Request,
) -> Result<Response, ApiError> {
    let ctype = headers
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .unwrap_or("")
        .to_ascii_lowercase();
    let (scene, job, pvs, bake) = if ctype.starts_with("multipart/form-data") {
        let mut mp = <Multipart as axum::extract::FromRequest<AppState>>::from_request(req, &st)
            .await
            .map_err(|e| err(StatusCode::BAD_REQUEST, format!("bad multipart body: {e}")))?;
        let (mut scene, mut job, mut pvs, mut bake) = (None, None, None, false);
        loop {
            let field = mp.next_field().await.map_err(|e| {
                let status = if e.status() == StatusCode::PAYLOAD_TOO_LARGE {
                    StatusCode::PAYLOAD_TOO_LARGE
                } else {
                    StatusCode::BAD_REQUEST
                };
                err(status, format!("bad multipart body: {}", e.body_text()))
            })?;
            let Some(field) = field else { break };
            let name = field.name().unwrap_or("").to_string();
            let data = field.bytes().await.map_err(|e| {
                err(
                    if e.status() == StatusCode::PAYLOAD_TOO_LARGE {
                        StatusCode::PAYLOAD_TOO_LARGE
                    } else {
                        StatusCode::BAD_REQUEST
                    },
                    format!("multipart part `{name}`: {}", e.body_text()),
                )
            })?;
            match name.as_str() {
                "scene" => scene = Some(data),
                "job" => job = Some(data),
                "pvs" => pvs = Some(data),
                "bake" => bake = data.as_ref() == b"true",
                other => {
                    return Err(err(
                        StatusCode::BAD_REQUEST,
                        format!(
                            "unknown multipart part `{other}` (expected scene, job, pvs, bake)"
                        ),
                    ));
                }
            }
        }
        let scene = scene
            .ok_or_else(|| err(StatusCode::BAD_REQUEST, "multipart part `scene` is missing"))?;
        let job =
            job.ok_or_else(|| err(StatusCode::BAD_REQUEST, "multipart part `job` is missing"))?;
        (scene.to_vec(), job.to_vec(), pvs.map(|p| p.to_vec()), bake)
    } else if ctype.starts_with("application/json") {
        let body = <Bytes as axum::extract::FromRequest<AppState>>::from_request(req, &st)
            .await
            .map_err(|e| {
                let status = e.status();
                err(status, format!("request body: {}", e.body_text()))
            })?;
        let sub: JsonSubmission = serde_json::from_slice(&body).map_err(|e| {
            err(
                StatusCode::BAD_REQUEST,
                format!("body must be {{\"scene\": <scene summary>, \"job\": <job>}}: {e}"),
            )
        })?;
        (
            serde_json::to_vec(&sub.scene).map_err(internal)?,
            serde_json::to_vec(&sub.job).map_err(internal)?,
            match &sub.pvs {
                Some(p) => Some(serde_json::to_vec(p).map_err(internal)?),
                None => None,
            },
            sub.bake,
        )
    } else {
        return Err(err(
            StatusCode::UNSUPPORTED_MEDIA_TYPE,
            "use multipart/form-data (parts `scene`, `job`) or application/json",
        ));
    };
    let st2 = st.clone();
    let id = tokio::task::spawn_blocking(move || st2.submit(&scene, &job, pvs.as_deref(), bake))
        .await
        .map_err(internal)??;
    Ok((
        StatusCode::ACCEPTED,
        axum::Json(json!({ "id": id, "state": "queued" })),
    )
        .into_response())
}

async fn status(
    State(st): State<AppState>,
    UrlPath(id): UrlPath<i64>,
) -> Result<axum::Json<Value>, ApiError> {
    Ok(axum::Json(st.status(id)?))
}

#[derive(Deserialize)]
struct ListQuery {
    #[serde(default)]
    after: i64,
    #[serde(default = "default_limit")]
    limit: i64,
}

fn default_limit() -> i64 {
    50
}

async fn list(
    State(st): State<AppState>,
    Query(q): Query<ListQuery>,
) -> Result<axum::Json<Value>, ApiError> {
    let limit = q.limit.clamp(1, 500);
    let ids: Vec<i64> = {
        let db = st.0.db.lock().map_err(internal)?;
        let mut stmt = db
            .prepare("SELECT id FROM jobs WHERE id > ?1 ORDER BY id LIMIT ?2")
            .map_err(internal)?;
        stmt.query_map([q.after, limit], |r| r.get(0))
            .map_err(internal)?
            .collect::<rusqlite::Result<_>>()
            .map_err(internal)?
    };
    let jobs: Vec<Value> = ids.iter().filter_map(|&id| st.status(id).ok()).collect();
    let next = (ids.len() as i64 == limit)
        .then(|| ids.last().copied())
        .flatten();
    Ok(axum::Json(json!({ "jobs": jobs, "next_after": next })))
}

async fn result_file(
    st: &AppState,
    id: i64,
    file: &str,
    ctype: &str,
) -> Result<Response, ApiError> {
    let state = st.status(id)?["state"].as_str().unwrap_or("").to_string();
    if state != "succeeded" {
        return Err(err(
            StatusCode::CONFLICT,
            format!("job {id} is {state}; results exist once it has succeeded"),
        ));
    }
    let path = st.job_dir(id).join(file);
    match tokio::fs::read(&path).await {
        Ok(bytes) => Ok((
            [(
                header::CONTENT_TYPE,
                HeaderValue::from_str(ctype).map_err(internal)?,
            )],
            bytes,
        )
            .into_response()),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Err(err(
            StatusCode::NOT_FOUND,
            format!(
                "job {id} has no {file} (impostors are baked only when the job asks for it with \"bake\": true)"
            ),
        )),
        Err(e) => Err(internal(e)),
    }
}

async fn placement(
    State(st): State<AppState>,
    UrlPath(id): UrlPath<i64>,
) -> Result<Response, ApiError> {
    result_file(&st, id, "placement.json", "application/json").await
}

async fn evaluation(
    State(st): State<AppState>,
    UrlPath(id): UrlPath<i64>,
) -> Result<Response, ApiError> {
    result_file(&st, id, "evaluation.json", "application/json").await
}

async fn impostors(
    State(st): State<AppState>,
    UrlPath(id): UrlPath<i64>,
) -> Result<Response, ApiError> {
    result_file(&st, id, "impostors.glb", "model/gltf-binary").await
}

async fn report_page(
    State(st): State<AppState>,
    UrlPath(id): UrlPath<i64>,
) -> Result<Response, ApiError> {
    result_file(&st, id, "report.html", "text/html; charset=utf-8").await
}

async fn delete(
    State(st): State<AppState>,
    UrlPath(id): UrlPath<i64>,
) -> Result<axum::Json<Value>, ApiError> {
    let state = st.status(id)?["state"].as_str().unwrap_or("").to_string();
    match state.as_str() {
        "queued" => {
            st.set_state(id, "cancelled", Some("cancelled by request"), None);
            Ok(axum::Json(json!({ "id": id, "state": "cancelled" })))
        }
        "running" => {
            if let Ok(live) = st.0.live.lock()
                && let Some(l) = live.get(&id)
            {
                l.cancel.store(true, Ordering::Relaxed);
            }
            Ok(axum::Json(json!({ "id": id, "state": "cancelling" })))
        }
        _ => {
            let db = st.0.db.lock().map_err(internal)?;
            db.execute("DELETE FROM jobs WHERE id = ?1", [id])
                .map_err(internal)?;
            drop(db);
            let _ = std::fs::remove_dir_all(st.job_dir(id));
            Ok(axum::Json(json!({ "id": id, "state": "deleted" })))
        }
    }
}

async fn openapi_doc() -> axum::Json<Value> {
    axum::Json(openapi::openapi())
}

async fn healthz() -> axum::Json<Value> {
    axum::Json(json!({ "status": "ok", "version": OPTIMIZER_VERSION }))
}

/// The router of the service.
pub fn app(state: AppState) -> Router {
    let limit = state.0.cfg.max_upload_mb.saturating_mul(1024 * 1024);
    Router::new()
        .route("/healthz", get(healthz))
        .route("/openapi.json", get(openapi_doc))
        .route("/v1/jobs", get(list).post(submit))
        .route("/v1/jobs/{id}", get(status).delete(delete))
        .route("/v1/jobs/{id}/placement", get(placement))
        .route("/v1/jobs/{id}/evaluation", get(evaluation))
        .route("/v1/jobs/{id}/impostors.glb", get(impostors))
        .route("/v1/jobs/{id}/report", get(report_page))
        .layer(DefaultBodyLimit::max(limit))
        .layer(tower_http::timeout::TimeoutLayer::with_status_code(
            StatusCode::REQUEST_TIMEOUT,
            Duration::from_secs(120),
        ))
        .layer(tower_http::trace::TraceLayer::new_for_http())
        .with_state(state)
}

/// Serves `app(state)` on `listener` until `shutdown` completes.
pub async fn run(
    listener: tokio::net::TcpListener,
    state: AppState,
    shutdown: impl std::future::Future<Output = ()> + Send + 'static,
) -> std::io::Result<()> {
    axum::serve(listener, app(state))
        .with_graceful_shutdown(shutdown)
        .await
}
