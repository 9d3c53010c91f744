//! The JSON bodies the service answers with. Each derives `Serialize` for
//! the wire and `JsonSchema` for the OpenAPI document.
//!
//! Fields are declared in alphabetical order, the order of the keys of a
//! JSON value, in which the service writes its bodies; a test keeps every
//! body in that order. The job summary is stored as text written through a
//! JSON value, so its keys are sorted as well.

use aide::generate::GenContext;
use aide::openapi::{Operation, Response as DocResponse, StatusCode as DocStatus};
use aide::operation::OperationOutput;
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use schemars::JsonSchema;
use serde::Serialize;
use serde_json::Value;

use optimizer::api::placement::Summary;
use optimizer::api::stats::StageTime;

use crate::job::JobState;

/// What went wrong.
#[derive(Debug, Serialize, JsonSchema)]
#[schemars(rename = "Error")]
pub struct ErrorBody {
    /// What is wrong, naming the part or field.
    pub error: String,
    /// For an internal error (500): the id under which the server logged
    /// its details, which the answer does not repeat.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub request_id: Option<String>,
}

/// A job's state, stage, progress and summary or error.
#[derive(Debug, Serialize, JsonSchema)]
pub struct JobStatus {
    /// Whether the job bakes its impostors.
    pub bake: bool,
    /// When the job was accepted, ms since the Unix epoch.
    pub created_ms: i64,
    /// Why the job failed or was cancelled.
    pub error: Option<String>,
    /// When the job reached its final state, ms since the Unix epoch.
    pub finished_ms: Option<i64>,
    /// The job's id (a random UUID).
    pub id: String,
    /// Fraction of the run done: live while running, 1 once succeeded.
    #[schemars(range(min = 0.0, max = 1.0))]
    pub progress: f64,
    /// The running stage: loading, hierarchy, problem_views, candidates,
    /// greedy, placement, evaluate, bake.
    pub stage: Option<String>,
    /// When a worker started the job, ms since the Unix epoch.
    pub started_ms: Option<i64>,
    /// Where the job is in its life.
    pub state: JobState,
    /// The job's summary, once succeeded.
    #[schemars(with = "Option<JobSummary>")]
    pub summary: Option<Value>,
}

/// One event of `GET /v1/jobs/{id}/events` (`event: status`): the job's
/// state, stage and progress, sent whenever one of them changes; the last
/// event of a stream is the job's final state.
#[derive(Clone, Debug, PartialEq, Serialize, JsonSchema)]
pub struct JobEvent {
    /// Why the job failed or was cancelled (final events).
    pub error: Option<String>,
    /// Fraction of the run done.
    #[schemars(range(min = 0.0, max = 1.0))]
    pub progress: f64,
    /// The running stage, as in the job's status.
    pub stage: Option<String>,
    /// Where the job is in its life.
    pub state: JobState,
}

/// A succeeded job's summary: the placement's totals with the evaluation's
/// worst frame time, violations and parallax, and the stage timings.
#[derive(Debug, Serialize, JsonSchema)]
pub struct JobSummary {
    /// The placement's totals.
    #[serde(flatten)]
    pub placement: Summary,
    /// The evaluation's worst frame time, ms.
    pub max_ms: f64,
    /// The evaluation's over-target views inside solved CPVs.
    pub violations_in_solved: u64,
    /// The evaluation's over-target views among those sampled inside
    /// solved problem views.
    pub violations_in_cpv_views: u64,
    /// The control: over-target views inside solved CPVs of the same views
    /// with no impostor. When it is 0 the run's 0 violations prove nothing.
    pub control_violations_in_solved: u64,
    /// The evaluation's largest parallax error, pixels (when there are
    /// impostors).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub parallax_max_px: Option<f64>,
    /// Seconds per stage, in pipeline order.
    pub seconds: Vec<StageTime>,
}

/// A page of jobs, oldest first.
#[derive(Debug, Serialize, JsonSchema)]
pub struct JobList {
    /// The jobs of the page.
    pub jobs: Vec<JobStatus>,
    /// The `after` of the next page (the last job's id); null on the last
    /// page.
    pub next_after: Option<String>,
}

/// A submission accepted into the queue (answered with 202).
#[derive(Debug, Serialize, JsonSchema)]
pub struct Accepted {
    /// The new job's id (a random UUID).
    pub id: String,
    /// Always `queued`.
    pub state: JobState,
}

impl IntoResponse for Accepted {
    fn into_response(self) -> Response {
        (StatusCode::ACCEPTED, axum::Json(self)).into_response()
    }
}

impl OperationOutput for Accepted {
    type Inner = Self;

    fn operation_response(ctx: &mut GenContext, operation: &mut Operation) -> Option<DocResponse> {
        axum::Json::<Accepted>::operation_response(ctx, operation)
    }

    fn inferred_responses(
        ctx: &mut GenContext,
        operation: &mut Operation,
    ) -> Vec<(Option<DocStatus>, DocResponse)> {
        Self::operation_response(ctx, operation)
            .map(|r| (Some(DocStatus::Code(202)), r))
            .into_iter()
            .collect()
    }
}

/// What a `DELETE` did.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum DeleteOutcome {
    /// The job was queued and will not run.
    Cancelled,
    /// The job is running and stops at its next check.
    Cancelling,
    /// The job had finished; it and its results are gone.
    Deleted,
}

/// The answer to a `DELETE`.
#[derive(Debug, Serialize, JsonSchema)]
pub struct DeleteAnswer {
    /// The job's id.
    pub id: String,
    /// What happened to the job.
    pub state: DeleteOutcome,
}

/// The service is up.
#[derive(Debug, Serialize, JsonSchema)]
pub struct Health {
    /// The artifact store of the job files, which answered: `file` (a
    /// folder) or `s3`.
    pub artifacts: &'static str,
    /// The job database's engine, which answered: `sqlite` or `postgres`.
    pub database: &'static str,
    /// Always `ok` (a database that does not answer is a 503).
    pub status: &'static str,
    /// Version of the optimizer library the service runs.
    pub version: &'static str,
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The bytes of `body` equal those of its JSON value (sorted keys).
    fn assert_sorted(body: &impl Serialize) {
        let direct = serde_json::to_string(body).unwrap();
        let via_value = serde_json::to_value(body).unwrap().to_string();
        assert_eq!(direct, via_value);
    }

    #[test]
    fn bodies_list_their_fields_in_alphabetical_order() {
        let status = JobStatus {
            bake: true,
            created_ms: 1,
            error: None,
            finished_ms: Some(3),
            id: "7".into(),
            progress: 1.0,
            stage: Some("bake".into()),
            started_ms: Some(2),
            state: JobState::Succeeded,
            summary: Some(serde_json::json!({"cpvs": 1, "max_ms": 2.5})),
        };
        assert_eq!(
            serde_json::to_string(&status).unwrap(),
            r#"{"bake":true,"created_ms":1,"error":null,"finished_ms":3,"id":"7","progress":1.0,"stage":"bake","started_ms":2,"state":"succeeded","summary":{"cpvs":1,"max_ms":2.5}}"#
        );
        assert_sorted(&status);
        assert_sorted(&JobList {
            jobs: vec![status],
            next_after: None,
        });
        assert_sorted(&Accepted {
            id: "1".into(),
            state: JobState::Queued,
        });
        assert_sorted(&DeleteAnswer {
            id: "1".into(),
            state: DeleteOutcome::Cancelling,
        });
        assert_sorted(&Health {
            artifacts: "file",
            database: "sqlite",
            status: "ok",
            version: "0",
        });
        assert_sorted(&ErrorBody {
            error: "no job 1".into(),
            request_id: None,
        });
        assert_sorted(&ErrorBody {
            error: "internal error".into(),
            request_id: Some("0123".into()),
        });
    }
}
