//! HTTP service over the [`optimizer`] library: submit scene jobs, follow
//! their progress, fetch placements, evaluations and baked impostors.
//!
//! The service is thin: it validates, schedules, stores and serves; every
//! geometric computation lives in the `optimizer` crate. CPU work runs on a
//! fixed pool of worker threads, off the async runtime; the queue is bounded.
//!
//! Durability: jobs live in a database (SQLite in the data directory, WAL
//! and `synchronous = FULL`, by default; or a PostgreSQL shared by many API
//! and worker processes); a job's files live in the artifact store (a
//! folder, `<data-dir>/jobs/<id>/` by default, or an S3-compatible bucket):
//! its inputs are written before its row is committed, and every result
//! file is written whole (a folder's: to a temporary name, synced and
//! renamed) before the row says `succeeded`. Workers claim jobs under leases they renew; a job whose
//! worker died is claimed again when its lease runs out (with SQLite, on
//! the next start), so every accepted job reaches a final state and no
//! finished result is ever truncated.
//!
//! Modules: `db` (the two database engines behind one interface),
//! `artifacts` (the job files' object store), `store` (jobs and their files), `worker` (claims, leases, worker threads, live
//! progress), `pipeline` (the calls into the optimizer),
//! `api` (routes, handlers, bodies, the OpenAPI document), `web` (the
//! embedded web page at `/`), `error`
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
mod artifacts;
pub mod auth;
mod db;
mod error;
mod job;
mod pipeline;
mod store;
mod web;
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
    /// Worker threads (jobs run one per worker; none: jobs are accepted
    /// and queued but not run).
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
    /// more is placed in tiles that fit; one no tiling fits ends `failed`
    /// before the memory is allocated.
    pub job_max_memory_bytes: Option<u64>,
    /// How long a finished job (succeeded, failed or cancelled) and its
    /// files are kept, days (`--retain-days`; default: for ever).
    pub retain_days: Option<f64>,
    /// The tokens file (`--tokens`): every `/v1` request then needs a
    /// token of it, and sees only its tenant's jobs. `None`: no
    /// authentication, one tenant (`--no-auth`, loopback only).
    pub tokens: Option<PathBuf>,
    /// The most jobs a tenant may have queued or running at once
    /// (`--tenant-max-jobs`; default: no limit but the queue's).
    pub tenant_max_jobs: Option<usize>,
    /// The most `/v1` requests per second a tenant may make, in bursts of
    /// as many (`--rate-limit`; default: no limit).
    pub rate_limit: Option<u32>,
    /// The job database (`--database`): `sqlite:PATH` or `postgres://…`;
    /// `None`: `<data_dir>/jobs.sqlite`.
    pub database: Option<String>,
    /// The artifact store of the job files (`--artifacts`): a folder,
    /// `file://…` or `s3://bucket/prefix`; `None`: `<data_dir>/jobs`.
    pub artifacts: Option<String>,
    /// How long a worker's claim on a job lasts without renewal
    /// (`--lease-seconds`); a job whose worker died runs again after it.
    pub lease: Duration,
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
            tokens: None,
            tenant_max_jobs: None,
            rate_limit: None,
            database: None,
            artifacts: None,
            lease: Duration::from_secs(30),
        }
    }
}

struct Inner {
    cfg: Config,
    store: store::Store,
    /// This process's worker name (`host:pid:tag`); its workers are
    /// `name/0`, `name/1`, ….
    name: String,
    wakeup: worker::Wakeup,
    /// Set by [`AppState::shutdown`]: workers claim nothing more.
    stopping: std::sync::atomic::AtomicBool,
    workers: std::sync::Mutex<Vec<std::thread::JoinHandle<()>>>,
    live: worker::LiveJobs,
    tokens: Option<Arc<auth::Tokens>>,
    limiter: Option<governor::DefaultKeyedRateLimiter<String>>,
}

/// Shared state of the service: configuration, job store, queue and the
/// running jobs' progress.
#[derive(Clone)]
pub struct AppState(Arc<Inner>);

impl AppState {
    /// Opens (or creates) the data directory and its database, re-queues the
    /// jobs a previous process left unfinished and starts the workers.
    pub fn open(cfg: Config) -> std::io::Result<AppState> {
        let tokens = match cfg.tokens.as_deref() {
            Some(path) => {
                let tokens = Arc::new(auth::Tokens::open(path)?);
                auth::Tokens::spawn_refresh(&tokens)?;
                Some(tokens)
            }
            None => None,
        };
        let limiter = cfg
            .rate_limit
            .and_then(std::num::NonZeroU32::new)
            .map(|n| governor::RateLimiter::keyed(governor::Quota::per_second(n)));
        let store = store::Store::open(
            &cfg.data_dir,
            cfg.database.as_deref(),
            cfg.artifacts.as_deref(),
        )?;
        store.recover()?;
        let workers = cfg.workers;
        let state = AppState(Arc::new(Inner {
            cfg,
            store,
            name: worker::process_name(),
            wakeup: worker::Wakeup::default(),
            stopping: std::sync::atomic::AtomicBool::new(false),
            workers: std::sync::Mutex::new(Vec::new()),
            live: worker::LiveJobs::default(),
            tokens,
            limiter,
        }));
        let handles = worker::spawn_workers(&state, workers)?;
        if let Ok(mut w) = state.0.workers.lock() {
            *w = handles;
        }
        if let Some(days) = state.0.cfg.retain_days {
            spawn_retention(&state, days)?;
        }
        Ok(state)
    }

    /// Stops this process's workers: they claim nothing more, running jobs
    /// stop at their next check and their leases are given back (queued
    /// again for any worker). Waits for them.
    pub fn shutdown(&self) {
        worker::shutdown(self);
        let handles = self
            .0
            .workers
            .lock()
            .map(|mut w| std::mem::take(&mut *w))
            .unwrap_or_default();
        for h in handles {
            let _ = h.join();
        }
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

/// Who makes a request: with a tokens file, the tenant of its token;
/// without (`--no-auth`), anyone, who sees every job.
#[derive(Clone, Debug)]
pub(crate) enum Access {
    All,
    Tenant(String),
}

impl Access {
    /// The tenant whose jobs the request may see; `None`: all jobs.
    pub fn tenant(&self) -> Option<&str> {
        match self {
            Access::All => None,
            Access::Tenant(t) => Some(t),
        }
    }
}

/// Every `/v1` request passes here, and is decided from its headers alone,
/// before any of its body is read: 401 without a valid token, 429 over the
/// tenant's rate limit; a submission 413 when its `Content-Length` is over
/// the upload limit, 429 when the queue is full or the tenant has its
/// most jobs. So a large upload that will be refused costs the server
/// nothing (the handler checks the queue and the quota again once it has
/// parsed the submission, as jobs may have arrived meanwhile, and the body
/// limit still holds for a body sent without a length). The request goes
/// on with its [`Access`].
async fn guard(State(st): State<AppState>, mut req: Request, next: Next) -> Response {
    if !req.uri().path().starts_with("/v1/") {
        return next.run(req).await;
    }
    let access = match st.authenticate(req.headers()) {
        Ok(a) => a,
        Err(e) => return e.into_response(),
    };
    if let Some(limiter) = &st.0.limiter {
        let key = access.tenant().unwrap_or("").to_string();
        if let Err(not_until) = limiter.check_key(&key) {
            use governor::clock::Clock;
            let wait = not_until.wait_time_from(limiter.clock().now());
            let per_s = st.0.cfg.rate_limit.unwrap_or(0);
            return ApiError::too_many(
                format!("more than {per_s} requests per second (the server's --rate-limit)"),
                wait.as_secs_f64().ceil() as u64,
            )
            .into_response();
        }
    }
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
        let (st2, access2) = (st.clone(), access.clone());
        let quota = tokio::task::spawn_blocking(move || {
            st2.check_queue()?;
            st2.check_quota(&access2)
        })
        .await;
        match quota {
            Ok(Ok(())) => {}
            Ok(Err(e)) => return e.into_response(),
            Err(e) => return ApiError::internal(e).into_response(),
        }
    }
    req.extensions_mut().insert(access);
    next.run(req).await
}

impl AppState {
    /// The [`Access`] of a request from its `Authorization` header: 401
    /// without a token, or with one the tokens file does not list.
    fn authenticate(&self, headers: &axum::http::HeaderMap) -> Result<Access, ApiError> {
        let Some(tokens) = &self.0.tokens else {
            return Ok(Access::All);
        };
        let unauthorized = |msg: &str| ApiError::new(StatusCode::UNAUTHORIZED, msg);
        let value = headers
            .get(axum::http::header::AUTHORIZATION)
            .ok_or_else(|| {
                unauthorized("this server needs an API token: send `Authorization: Bearer <token>`")
            })?;
        let token = value
            .to_str()
            .ok()
            .and_then(|v| {
                let (scheme, token) = v.split_once(' ')?;
                scheme.eq_ignore_ascii_case("bearer").then(|| token.trim())
            })
            .ok_or_else(|| unauthorized("the Authorization header must be `Bearer <token>`"))?;
        tokens
            .tenant(token)
            .map(Access::Tenant)
            .ok_or_else(|| unauthorized("the token is not valid (unknown or revoked)"))
    }

    /// 429 when the queue is full: checked from a submission's headers and
    /// again once it is parsed (jobs may have arrived meanwhile); blocking,
    /// a database read (the queue is shared by every process).
    pub(crate) fn check_queue(&self) -> Result<(), ApiError> {
        let max_queue = self.0.cfg.max_queue;
        if self.0.store.queued().map_err(ApiError::internal)? >= max_queue {
            return Err(ApiError::new(
                StatusCode::TOO_MANY_REQUESTS,
                format!("the queue is full ({max_queue} jobs waiting)"),
            ));
        }
        Ok(())
    }

    /// 429 when the tenant of `access` has `--tenant-max-jobs` jobs queued
    /// or running (blocking: a database read).
    pub(crate) fn check_quota(&self, access: &Access) -> Result<(), ApiError> {
        let (Some(max), Some(tenant)) = (self.0.cfg.tenant_max_jobs, access.tenant()) else {
            return Ok(());
        };
        let active = self
            .0
            .store
            .active_jobs(tenant)
            .map_err(ApiError::internal)?;
        if active >= max {
            return Err(ApiError::new(
                StatusCode::TOO_MANY_REQUESTS,
                format!(
                    "tenant {tenant} has {active} jobs queued or running, its most (the \
                     server's --tenant-max-jobs)"
                ),
            ));
        }
        Ok(())
    }
}

/// The router of the service.
pub fn app(state: AppState) -> Router {
    let limit = state.0.cfg.max_upload_mb.saturating_mul(1024 * 1024);
    api::router()
        .merge(web::router())
        .layer(middleware::from_fn_with_state(state.clone(), guard))
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
