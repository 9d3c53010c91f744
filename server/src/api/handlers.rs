//! The route handlers: submit, list, status, inputs, results and delete of jobs;
//! health and the OpenAPI document.

use axum::Json;
use axum::extract::{Extension, Query, State};
use axum::http::StatusCode;
use schemars::JsonSchema;
use serde::Deserialize;

use optimizer::api::evaluation::Evaluation;
use optimizer::api::placement::Placement;

use axum::response::IntoResponse;

use super::bodies::{EventStream, Glb, HtmlPage, MetricsText, OpenApiJson, SceneFile, StoredJson};
use super::extract::{Caller, JobId, Submission};
use super::types::{Accepted, DeleteAnswer, DeleteOutcome, Health, JobEvent, JobList, JobStatus};
use crate::error::ApiError;
use crate::job::JobState;
use crate::pipeline::{check_submission, tile_jobs};
use crate::store::{self, JobRow};
use crate::{Access, AppState, OPTIMIZER_VERSION};

/// `POST /v1/jobs`: checks and stores a submission, then queues it.
pub(crate) async fn submit(
    State(st): State<AppState>,
    Caller(access): Caller,
    sub: Submission,
) -> Result<Accepted, ApiError> {
    // Parsing the scene and writing the files is blocking work.
    let id = tokio::task::spawn_blocking(move || accept(&st, &access, sub))
        .await
        .map_err(ApiError::internal)??;
    Ok(Accepted {
        id,
        state: JobState::Queued,
    })
}

/// Checks, stores and queues a submission of the caller's tenant. Returns
/// the new job's public id.
fn accept(st: &AppState, access: &Access, sub: Submission) -> Result<String, ApiError> {
    {
        // The inputs are read back for the check only while it runs.
        let read = |name| std::fs::read(sub.staged.path(name)).map_err(ApiError::internal);
        let pvs = if sub.has_pvs {
            Some(read(store::PVS)?)
        } else {
            None
        };
        check_submission(
            &read(store::SCENE)?,
            &read(store::JOB)?,
            pvs.as_deref(),
            sub.bake,
        )?;
    }
    st.check_queue()?;
    st.check_quota(access)?;
    let tenant = access.tenant();
    let tiles = std::fs::read(sub.staged.path(store::JOB))
        .map_err(ApiError::internal)
        .and_then(|job| tile_jobs(&job))?;
    let (id, uid) =
        st.0.store
            .create(&sub.staged, sub.bake, tenant, &tiles)
            .map_err(ApiError::internal)?;
    tracing::info!(job = id, uid, tenant, "accepted");
    st.0.wakeup.notify();
    Ok(uid)
}

/// Runs `f` on the blocking pool, off the async runtime: the database
/// and the job folders are read and written with blocking calls, which
/// must not hold up the runtime's threads (and so every other request).
async fn blocking<T: Send + 'static>(
    st: &AppState,
    f: impl FnOnce(&AppState) -> Result<T, ApiError> + Send + 'static,
) -> Result<T, ApiError> {
    let st = st.clone();
    tokio::task::spawn_blocking(move || f(&st))
        .await
        .map_err(ApiError::internal)?
}

/// The row of the caller's job of public id `uid` (read on the blocking
/// pool); 404 when there is none (another tenant's job, numeric ids of
/// older versions included).
async fn find(st: &AppState, access: &Access, uid: &str) -> Result<JobRow, ApiError> {
    let (uid, access) = (uid.to_string(), access.clone());
    blocking(st, move |st| {
        st.0.store
            .find(&uid, access.tenant())
            .map_err(ApiError::internal)?
            .ok_or_else(|| ApiError::no_job(&uid))
    })
    .await
}

/// The status of the job of `row`, with the live stage and progress while
/// it runs (blocking: a tiled job's tiles are read from the database).
fn job_status(st: &AppState, row: JobRow) -> JobStatus {
    let (stage, progress) = match st.0.live.progress(row.id) {
        Some((stage, progress)) => (Some(stage), progress),
        // Run by a worker of another process: its last renewal.
        None if row.state == JobState::Running => (row.stage, row.progress.unwrap_or(0.0)),
        // A tiled job whose tiles run: the share of them finished.
        None if row.state == JobState::Queued && row.tiles.is_some() => {
            let tiles = st.0.store.children(row.id).unwrap_or_default();
            let done = tiles.iter().filter(|t| t.state.is_final()).count();
            let n = row.tiles.unwrap_or(1).max(1) as f64;
            (Some("tiles".into()), 0.95 * done as f64 / n)
        }
        None => (
            row.stage,
            if row.state == JobState::Succeeded {
                1.0
            } else {
                0.0
            },
        ),
    };
    JobStatus {
        bake: row.bake,
        created_ms: row.created_ms,
        error: row.error,
        finished_ms: row.finished_ms,
        id: row.uid,
        progress,
        stage,
        started_ms: row.started_ms,
        state: row.state,
        summary: row.summary.and_then(|s| serde_json::from_str(&s).ok()),
    }
}

/// `GET /v1/jobs/{id}`.
pub(crate) async fn status(
    State(st): State<AppState>,
    Caller(access): Caller,
    JobId(uid): JobId,
) -> Result<Json<JobStatus>, ApiError> {
    let row = find(&st, &access, &uid).await?;
    // A tiled job's status reads its tiles' rows: on the blocking pool.
    blocking(&st, move |st| Ok(Json(job_status(st, row)))).await
}

/// The query of `GET /v1/jobs`.
#[derive(Deserialize, JsonSchema)]
#[schemars(inline)]
pub(crate) struct ListQuery {
    /// List the jobs submitted after this one (a job's id, as in
    /// `next_after`); from the first when absent.
    #[serde(default)]
    after: Option<String>,
    /// Jobs per page, clamped to 1..=500.
    #[serde(default = "default_limit")]
    limit: i64,
}

fn default_limit() -> i64 {
    50
}

/// `GET /v1/jobs`: a page of the caller's jobs, oldest first.
pub(crate) async fn list(
    State(st): State<AppState>,
    Caller(access): Caller,
    Query(q): Query<ListQuery>,
) -> Result<Json<JobList>, ApiError> {
    blocking(&st, move |st| list_page(st, access.tenant(), q))
        .await
        .map(Json)
}

/// A page of `GET /v1/jobs` of `tenant`'s jobs (`None`: everyone's;
/// blocking: database reads).
fn list_page(st: &AppState, tenant: Option<&str>, q: ListQuery) -> Result<JobList, ApiError> {
    let limit = q.limit.clamp(1, 500);
    let after = match &q.after {
        None => 0,
        Some(uid) => {
            st.0.store
                .find(uid, tenant)
                .map_err(ApiError::internal)?
                .ok_or_else(|| {
                    ApiError::new(
                        StatusCode::BAD_REQUEST,
                        format!("after: no job {uid} (a job's id, as in next_after)"),
                    )
                })?
                .id
        }
    };
    let ids =
        st.0.store
            .ids_after(after, limit, tenant)
            .map_err(ApiError::internal)?;
    // A job deleted between the two reads is left out of the page.
    let jobs: Vec<JobStatus> = ids
        .iter()
        .filter_map(|&id| st.0.store.row(id).ok().flatten())
        .map(|row| job_status(st, row))
        .collect();
    let next_after = (ids.len() as i64 == limit)
        .then(|| jobs.last().map(|j| j.id.clone()))
        .flatten();
    Ok(JobList { jobs, next_after })
}

/// The bytes of result `file` of the job of public id `id`: 409 until the
/// job has succeeded, 404 when the job has no such file.
async fn result_file(
    st: &AppState,
    access: &Access,
    id: &str,
    file: &str,
) -> Result<Vec<u8>, ApiError> {
    let row = find(st, access, id).await?;
    let state = row.state;
    if state != JobState::Succeeded {
        return Err(ApiError::new(
            StatusCode::CONFLICT,
            format!("job {id} is {state}; results exist once it has succeeded"),
        ));
    }
    match st.0.store.artifacts().get_async(row.id, file).await {
        Ok(Some(bytes)) => Ok(bytes),
        Ok(None) => Err(ApiError::new(
            StatusCode::NOT_FOUND,
            format!(
                "job {id} has no {file} (impostors are baked only when the job asks for it with \"bake\": true)"
            ),
        )),
        Err(e) => Err(ApiError::internal(e)),
    }
}

/// How often an event stream looks at its job.
const EVENT_POLL: std::time::Duration = std::time::Duration::from_millis(100);

/// The event of the job of internal id `id` now; `None` once it is gone.
fn job_event(st: &AppState, id: i64) -> Option<JobEvent> {
    let row = st.0.store.row(id).ok().flatten()?;
    let status = job_status(st, row);
    Some(JobEvent {
        error: status.error,
        progress: status.progress,
        stage: status.stage,
        state: status.state,
    })
}

/// `GET /v1/jobs/{id}/events`: the job's state, stage and progress as
/// server-sent events, one whenever they change (looked at every 100 ms),
/// ending after its final state (or when the job is deleted).
pub(crate) async fn events(
    State(st): State<AppState>,
    Caller(access): Caller,
    JobId(uid): JobId,
) -> Result<EventStream, ApiError> {
    use axum::response::sse::{Event, KeepAlive, Sse};
    let id = find(&st, &access, &uid).await?.id;
    let stream = futures_util::stream::unfold(
        (st, None::<JobEvent>, false),
        move |(st, last, done)| async move {
            if done {
                return None;
            }
            loop {
                let now = blocking(&st, move |st| Ok(job_event(st, id)))
                    .await
                    .ok()
                    .flatten()?;
                if last.as_ref() != Some(&now) {
                    let event = Event::default().event("status").json_data(&now);
                    let done = now.state.is_final();
                    return Some((event, (st, Some(now), done)));
                }
                tokio::time::sleep(EVENT_POLL).await;
            }
        },
    );
    Ok(EventStream(
        Sse::new(stream)
            .keep_alive(KeepAlive::default())
            .into_response(),
    ))
}

/// `GET /v1/jobs/{id}/placement`.
pub(crate) async fn placement(
    State(st): State<AppState>,
    Caller(access): Caller,
    JobId(id): JobId,
) -> Result<StoredJson<Placement>, ApiError> {
    Ok(StoredJson::new(
        result_file(&st, &access, &id, "placement.json").await?,
    ))
}

/// `GET /v1/jobs/{id}/evaluation`.
pub(crate) async fn evaluation(
    State(st): State<AppState>,
    Caller(access): Caller,
    JobId(id): JobId,
) -> Result<StoredJson<Evaluation>, ApiError> {
    Ok(StoredJson::new(
        result_file(&st, &access, &id, "evaluation.json").await?,
    ))
}

/// `GET /v1/jobs/{id}/impostors.glb`.
pub(crate) async fn impostors(
    State(st): State<AppState>,
    Caller(access): Caller,
    JobId(id): JobId,
) -> Result<Glb, ApiError> {
    Ok(Glb(result_file(&st, &access, &id, "impostors.glb").await?))
}

/// `GET /v1/jobs/{id}/report`.
pub(crate) async fn report(
    State(st): State<AppState>,
    Caller(access): Caller,
    JobId(id): JobId,
) -> Result<HtmlPage, ApiError> {
    Ok(HtmlPage(
        result_file(&st, &access, &id, "report.html").await?,
    ))
}

/// Input `file` ([`store::SCENE`] or [`store::JOB`]) of the caller's job of
/// public id `id`, in any state.
async fn input_file(
    st: &AppState,
    access: &Access,
    id: &str,
    file: &'static str,
) -> Result<Vec<u8>, ApiError> {
    let row = find(st, access, id).await?;
    match st.0.store.artifacts().get_async(row.id, file).await {
        Ok(Some(bytes)) => Ok(bytes),
        // Deleted between the two reads.
        Ok(None) => Err(ApiError::no_job(id)),
        Err(e) => Err(ApiError::internal(e)),
    }
}

/// `GET /v1/jobs/{id}/scene`: the scene as submitted.
pub(crate) async fn scene(
    State(st): State<AppState>,
    Caller(access): Caller,
    JobId(id): JobId,
) -> Result<SceneFile, ApiError> {
    Ok(SceneFile(
        input_file(&st, &access, &id, store::SCENE).await?,
    ))
}

/// `GET /v1/jobs/{id}/job`: the job as submitted.
pub(crate) async fn job(
    State(st): State<AppState>,
    Caller(access): Caller,
    JobId(id): JobId,
) -> Result<StoredJson<optimizer::api::job::Job>, ApiError> {
    Ok(StoredJson::new(
        input_file(&st, &access, &id, store::JOB).await?,
    ))
}

/// `DELETE /v1/jobs/{id}`: cancels a queued job, asks a running one to
/// stop, deletes a finished one with its files.
pub(crate) async fn delete(
    State(st): State<AppState>,
    Caller(access): Caller,
    JobId(uid): JobId,
) -> Result<Json<DeleteAnswer>, ApiError> {
    let row = find(&st, &access, &uid).await?;
    let id = row.id;
    // Removing a job's folder may take a while: on the blocking pool.
    let outcome = blocking(&st, move |st| {
        Ok(match row.state {
            // One statement: a worker's claim and the cancel never both win.
            JobState::Queued if st.0.store.cancel_queued(id).map_err(ApiError::internal)? => {
                DeleteOutcome::Cancelled
            }
            // Running here or in another process (or claimed meanwhile):
            // its worker sees the request at its next lease renewal.
            JobState::Queued | JobState::Running => {
                st.0.live.cancel(id);
                st.0.store.request_cancel(id).map_err(ApiError::internal)?;
                DeleteOutcome::Cancelling
            }
            JobState::Succeeded | JobState::Failed | JobState::Cancelled => {
                st.0.store.delete(id).map_err(ApiError::internal)?;
                DeleteOutcome::Deleted
            }
        })
    })
    .await?;
    Ok(Json(DeleteAnswer {
        id: uid,
        state: outcome,
    }))
}

/// `GET /healthz`: the service, its database and its artifact store answer
/// (503 when either does not).
pub(crate) async fn healthz(State(st): State<AppState>) -> Result<Json<Health>, ApiError> {
    blocking(&st, |st| {
        st.0.store.ping().map_err(|e| {
            tracing::warn!("health: the database does not answer: {e}");
            ApiError::new(
                StatusCode::SERVICE_UNAVAILABLE,
                "the job database does not answer",
            )
        })?;
        st.0.store.artifacts().ping().map_err(|e| {
            tracing::warn!("health: the artifact store does not answer: {e}");
            ApiError::new(
                StatusCode::SERVICE_UNAVAILABLE,
                "the artifact store does not answer",
            )
        })?;
        Ok(Json(Health {
            artifacts: st.0.store.artifacts().kind(),
            status: "ok",
            version: OPTIMIZER_VERSION,
            database: match st.0.store.backend() {
                crate::db::Backend::Sqlite => "sqlite",
                crate::db::Backend::Postgres => "postgres",
            },
        }))
    })
    .await
}

/// `GET /metrics`: queue depth, jobs per state, workers seen in the last
/// minute and finished jobs' durations, in Prometheus' text format.
pub(crate) async fn metrics(State(st): State<AppState>) -> Result<MetricsText, ApiError> {
    let f = blocking(&st, |st| st.0.store.figures().map_err(ApiError::internal)).await?;
    Ok(MetricsText(metrics_text(&f)))
}

/// The text of `/metrics` for `f`.
fn metrics_text(f: &store::Figures) -> String {
    use std::fmt::Write;
    let mut out = String::new();
    let by = |s: JobState| f.by_state[JobState::ALL.iter().position(|&x| x == s).unwrap_or(0)];
    let _ = writeln!(
        out,
        "# HELP impostor_queue_depth Jobs waiting for a worker."
    );
    let _ = writeln!(out, "# TYPE impostor_queue_depth gauge");
    let _ = writeln!(out, "impostor_queue_depth {}", by(JobState::Queued));
    let _ = writeln!(
        out,
        "# HELP impostor_jobs_running Jobs a worker is running."
    );
    let _ = writeln!(out, "# TYPE impostor_jobs_running gauge");
    let _ = writeln!(out, "impostor_jobs_running {}", by(JobState::Running));
    let _ = writeln!(out, "# HELP impostor_jobs Jobs in the database, by state.");
    let _ = writeln!(out, "# TYPE impostor_jobs gauge");
    for (s, n) in JobState::ALL.iter().zip(f.by_state) {
        let _ = writeln!(out, "impostor_jobs{{state=\"{s}\"}} {n}");
    }
    let _ = writeln!(
        out,
        "# HELP impostor_workers Worker threads (of every process) seen in the last minute."
    );
    let _ = writeln!(out, "# TYPE impostor_workers gauge");
    let _ = writeln!(out, "impostor_workers {}", f.workers);
    let name = "impostor_job_duration_seconds";
    let _ = writeln!(out, "# HELP {name} Finished jobs' run time, start to end.");
    let _ = writeln!(out, "# TYPE {name} histogram");
    for (le, n) in store::DURATION_BUCKETS.iter().zip(&f.buckets) {
        let _ = writeln!(out, "{name}_bucket{{le=\"{le}\"}} {n}");
    }
    let _ = writeln!(out, "{name}_bucket{{le=\"+Inf\"}} {}", f.finished);
    let _ = writeln!(out, "{name}_sum {}", f.finished_seconds);
    let _ = writeln!(out, "{name}_count {}", f.finished);
    out
}

/// `GET /openapi.json`.
pub(crate) async fn openapi(Extension(doc): Extension<OpenApiJson>) -> OpenApiJson {
    doc
}
