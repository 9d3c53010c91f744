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
//!
//! Modules: `store` (database and job files), `worker` (queue, worker
//! threads, live progress), `pipeline` (the calls into the optimizer),
//! `api` (routes, handlers, bodies, the OpenAPI document), `error`
//! (`ApiError`), `job` ([`JobState`]).

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use axum::Router;
use axum::extract::{DefaultBodyLimit, Request, State};
use axum::http::{Method, StatusCode};
use axum::middleware::{self, Next};
use axum::response::{IntoResponse, Response};

mod api;
mod error;
mod job;
mod pipeline;
mod store;
mod worker;

pub use error::ApiError;
pub use job::{JobState, UnknownState};

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
    /// The longest a job may run, seconds (`--job-max-seconds`): it is
    /// stopped at its next check after that and ends `failed`.
    pub job_max_seconds: Option<u64>,
    /// The most memory a job's placement may be predicted to need, bytes
    /// (`--job-max-memory`; default: the machine's): a job predicted to need
    /// more ends `failed` before the memory is allocated.
    pub job_max_memory_bytes: Option<u64>,
    /// How long a finished job (succeeded, failed or cancelled) and its
    /// files are kept, days (`--retain-days`; default: for ever).
    pub retain_days: Option<f64>,
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
            job_max_seconds: None,
            job_max_memory_bytes: None,
            retain_days: None,
        }
    }
}

struct Inner {
    cfg: Config,
    store: store::Store,
    queue: worker::Queue,
    live: worker::LiveJobs,
}

/// Shared state of the service: configuration, job store, queue and the
/// running jobs' progress.
#[derive(Clone)]
pub struct AppState(Arc<Inner>);

impl AppState {
    /// Opens (or creates) the data directory and its database, re-queues the
    /// jobs a previous process left unfinished and starts the workers.
    pub fn open(cfg: Config) -> std::io::Result<AppState> {
        let store = store::Store::open(&cfg.data_dir)?;
        let pending = store.recover()?;
        let (queue, rx) = worker::Queue::new();
        let workers = cfg.workers;
        let state = AppState(Arc::new(Inner {
            cfg,
            store,
            queue,
            live: worker::LiveJobs::default(),
        }));
        for id in pending {
            state.0.queue.push(id);
        }
        worker::spawn_workers(&state, rx, workers)?;
        if let Some(days) = state.0.cfg.retain_days {
            spawn_retention(&state, days)?;
        }
        Ok(state)
    }
}

/// Removes the jobs that finished more than `days` ago, with their files,
/// now and then (a tenth of the retention, between 0.2 s and an hour), on
/// a thread of its own.
fn spawn_retention(state: &AppState, days: f64) -> std::io::Result<()> {
    let keep_ms = days * 86_400_000.0;
    let every = Duration::from_secs_f64((keep_ms / 10_000.0).clamp(0.2, 3600.0));
    let st = state.clone();
    std::thread::Builder::new()
        .name("retention".into())
        .spawn(move || {
            loop {
                let cutoff = store::now_ms() - keep_ms as i64;
                match st.0.store.finished_before(cutoff) {
                    Ok(ids) => {
                        for id in ids {
                            match st.0.store.delete(id) {
                                Ok(()) => tracing::info!(job = id, "removed after --retain-days"),
                                Err(e) => tracing::warn!(job = id, "not removed: {e}"),
                            }
                        }
                    }
                    Err(e) => tracing::warn!("retention: {e}"),
                }
                std::thread::sleep(every);
            }
        })?;
    Ok(())
}

/// Admission from the headers alone: a submission while the queue is
/// full is answered 429, one whose `Content-Length` is over the upload
/// limit 413, before any of its body is read, so a large upload costs the
/// server nothing (the handler checks the queue again once it has parsed
/// the submission, as jobs may have arrived meanwhile, and the body limit
/// still holds for a body sent without a length).
async fn admit(State(st): State<AppState>, req: Request, next: Next) -> Response {
    if req.method() == Method::POST && req.uri().path() == "/v1/jobs" {
        let max_mb = st.0.cfg.max_upload_mb;
        let length = req
            .headers()
            .get(axum::http::header::CONTENT_LENGTH)
            .and_then(|v| v.to_str().ok()?.parse::<u64>().ok());
        if let Some(n) = length
            && n > (max_mb as u64).saturating_mul(1024 * 1024)
        {
            return ApiError::new(
                StatusCode::PAYLOAD_TOO_LARGE,
                format!("the body is {n} bytes, larger than the upload limit ({max_mb} MiB)"),
            )
            .into_response();
        }
        if let Err(e) = st.check_queue() {
            return e.into_response();
        }
    }
    next.run(req).await
}

impl AppState {
    /// 429 when the queue is full: checked from a submission's headers and
    /// again once it is parsed (jobs may have arrived meanwhile).
    pub(crate) fn check_queue(&self) -> Result<(), ApiError> {
        let max_queue = self.0.cfg.max_queue;
        if self.0.queue.waiting() >= max_queue {
            return Err(ApiError::new(
                StatusCode::TOO_MANY_REQUESTS,
                format!("the queue is full ({max_queue} jobs waiting)"),
            ));
        }
        Ok(())
    }
}

/// The router of the service.
pub fn app(state: AppState) -> Router {
    let limit = state.0.cfg.max_upload_mb.saturating_mul(1024 * 1024);
    api::router()
        .layer(middleware::from_fn_with_state(state.clone(), admit))
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
