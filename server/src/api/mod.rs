//! The HTTP API: the routes with their handlers and OpenAPI docs, and the
//! OpenAPI 3.1 document generated from them (`GET /openapi.json`).
//!
//! The document comes from the handlers' types: extractors describe the
//! parameters and request bodies, return types the success and error
//! bodies; each route adds its summary and the client errors it answers
//! with. Schemas are JSON Schema 2020-12 (the dialect of OpenAPI 3.1),
//! generated from the Rust types, the optimizer's wire types included.

mod bodies;
mod extract;
mod handlers;
pub(crate) mod types;

use aide::axum::ApiRouter;
use aide::axum::routing::get_with;
use aide::openapi::{Header, HeaderStyle, OpenApi, ParameterSchemaOrContent, ReferenceOr};
use aide::openapi::{SchemaObject, Tag};
use aide::transform::{TransformOpenApi, TransformOperation};
use axum::Router;
use axum::extract::Extension;
use schemars::generate::SchemaSettings;

use crate::AppState;
use crate::error::ApiError;
use bodies::OpenApiJson;

const JOBS: &str = "jobs";
const SERVICE: &str = "service";

/// The 404 and 409 of the result routes.
fn result_errors(op: TransformOperation<'_>) -> TransformOperation<'_> {
    op.tag(JOBS)
        .response_with::<404, ApiError, _>(|r| {
            r.description("no such job, or no such result (impostors exist only for baked jobs)")
        })
        .response_with::<409, ApiError, _>(|r| r.description("the job has not succeeded"))
}

/// The 404 of the routes of one job.
fn job_errors(op: TransformOperation<'_>) -> TransformOperation<'_> {
    op.tag(JOBS)
        .response_with::<404, ApiError, _>(|r| r.description("no such job"))
}

fn submit_docs(op: TransformOperation<'_>) -> TransformOperation<'_> {
    op.id("submit_job")
        .tag(JOBS)
        .summary("submit a job")
        .description(
            "A GLB upload (multipart parts `scene`, `job`, optional `pvs` (a PVS file, for \
             visibility \"precomputed\") and `bake` = \"true\") or an inline scene summary \
             (JSON). The job is checked before it is accepted.",
        )
        .response_with::<422, ApiError, _>(|r| {
            r.description(
                "the scene, the job or the PVS file is invalid, or the job needs geometry \
                 the scene lacks",
            )
        })
        .response_with::<429, ApiError, _>(|mut r| {
            r.inner().headers.insert(
                "Retry-After".into(),
                ReferenceOr::Item(Header {
                    description: Some("seconds to wait before submitting again".into()),
                    style: HeaderStyle::Simple,
                    required: true,
                    deprecated: None,
                    format: ParameterSchemaOrContent::Schema(SchemaObject {
                        json_schema: schemars::json_schema!({"type": "integer"}),
                        example: None,
                        external_docs: None,
                    }),
                    example: None,
                    examples: Default::default(),
                    extensions: Default::default(),
                }),
            );
            r.description("the queue is full")
        })
}

/// The routes of the service, each with its OpenAPI docs.
fn routes() -> ApiRouter<AppState> {
    ApiRouter::new()
        .api_route(
            "/healthz",
            get_with(handlers::healthz, |op| {
                op.id("health")
                    .tag(SERVICE)
                    .summary("liveness: the service and its database answer")
                    .response_with::<503, ApiError, _>(|r| {
                        r.description("the job database does not answer")
                    })
            }),
        )
        .api_route(
            "/metrics",
            get_with(handlers::metrics, |op| {
                op.id("metrics")
                    .tag(SERVICE)
                    .summary("queue depth, running jobs, workers, job durations (Prometheus)")
                    .response_with::<500, ApiError, _>(|r| {
                        r.description("the job database cannot be read")
                    })
            }),
        )
        .api_route(
            "/openapi.json",
            get_with(handlers::openapi, |op| {
                op.id("openapi").tag(SERVICE).summary("this document")
            }),
        )
        .api_route(
            "/v1/jobs",
            get_with(handlers::list, |op| {
                op.id("list_jobs")
                    .tag(JOBS)
                    .summary("list jobs, oldest first")
            })
            .post_with(handlers::submit, submit_docs),
        )
        .api_route(
            "/v1/jobs/{id}",
            get_with(handlers::status, |op| {
                job_errors(op)
                    .id("job_status")
                    .summary("job state, stage, progress, summary or error")
            })
            .delete_with(handlers::delete, |op| {
                job_errors(op).id("delete_job").summary(
                    "cancel a queued or running job; delete a finished one with its results",
                )
            }),
        )
        .api_route(
            "/v1/jobs/{id}/events",
            get_with(handlers::events, |op| {
                job_errors(op).id("job_events").summary(
                    "the job's state, stage and progress as server-sent events, ending after \
                     its final state",
                )
            }),
        )
        .api_route(
            "/v1/jobs/{id}/scene",
            get_with(handlers::scene, |op| {
                job_errors(op)
                    .id("job_scene")
                    .summary("the job's scene as submitted (the GLB upload or the scene summary)")
            }),
        )
        .api_route(
            "/v1/jobs/{id}/job",
            get_with(handlers::job, |op| {
                job_errors(op)
                    .id("job_input")
                    .summary("the job's parameters as submitted")
            }),
        )
        .api_route(
            "/v1/jobs/{id}/placement",
            get_with(handlers::placement, |op| {
                result_errors(op)
                    .id("job_placement")
                    .summary("the placement, byte-identical to `impostor place`")
            }),
        )
        .api_route(
            "/v1/jobs/{id}/evaluation",
            get_with(handlers::evaluation, |op| {
                result_errors(op)
                    .id("job_evaluation")
                    .summary("the independent frame-time check of the placement")
            }),
        )
        .api_route(
            "/v1/jobs/{id}/impostors.glb",
            get_with(handlers::impostors, |op| {
                result_errors(op)
                    .id("job_impostors")
                    .summary("the baked impostors (jobs submitted with bake)")
            }),
        )
        .api_route(
            "/v1/jobs/{id}/report",
            get_with(handlers::report, |op| {
                result_errors(op).id("job_report").summary(
                    "a self-contained HTML report of the job: its run, evaluation and \
                     walkthrough frame times",
                )
            }),
        )
}

fn describe(api: TransformOpenApi<'_>) -> TransformOpenApi<'_> {
    api.title("impostor placement service")
        .security_scheme(
            extract::BEARER,
            aide::openapi::SecurityScheme::Http {
                scheme: "bearer".into(),
                bearer_format: Some("imp_ followed by 64 hex digits".into()),
                description: Some(
                    "an API token of the server's tokens file (`impostor-server token add`); \
                     not needed by a server started with --no-auth"
                        .into(),
                ),
                extensions: Default::default(),
            },
        )
        .version(optimizer::VERSION)
        .description(
            "Submit scene jobs, follow their progress, fetch placements, evaluations, \
             reports and baked impostors. Every `/v1` route needs `Authorization: Bearer \
             <token>` and sees the token's tenant's jobs only. Errors are answered with \
             `{\"error\": ...}`.",
        )
        .tag(Tag {
            name: JOBS.into(),
            description: Some("placement jobs and their results".into()),
            ..Tag::default()
        })
        .tag(Tag {
            name: SERVICE.into(),
            description: Some("the service itself".into()),
            ..Tag::default()
        })
}

/// The routes and the OpenAPI document generated from them, served at
/// `/openapi.json`.
pub(crate) fn router() -> Router<AppState> {
    // The generator lives in a thread-local context: configure it before
    // the routes record their schemas; `finish_api_with` takes them out.
    aide::generate::in_context(|ctx| {
        ctx.schema = SchemaSettings::draft2020_12()
            .with(|s| {
                s.definitions_path = "#/components/schemas/".into();
                s.inline_subschemas = false;
            })
            .into_generator();
    });
    let mut doc = OpenApi::default();
    let router = routes().finish_api_with(&mut doc, describe);
    let bytes = serde_json::to_vec(&doc).expect("the OpenAPI document serializes");
    router.layer(Extension(OpenApiJson(bytes.into())))
}
