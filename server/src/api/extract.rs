//! Request extractors of the job routes: [`JobId`] (the `{id}` path
//! parameter), [`Caller`] (who asks) and [`Submission`] (the body of
//! `POST /v1/jobs`, multipart or JSON, streamed to a staging folder).
//! Each describes its part of the request in the OpenAPI document.

use aide::generate::GenContext;
use aide::openapi::{MediaType, Operation, RequestBody, Response, SchemaObject, StatusCode};
use aide::operation::{OperationInput, OperationOutput, set_body};
use axum::body::Bytes;
use axum::extract::multipart::Field;
use axum::extract::rejection::PathRejection;
use axum::extract::{FromRequest, FromRequestParts, Multipart, Path, Request};
use axum::http::{StatusCode as HttpStatus, header, request::Parts};
use schemars::JsonSchema;
use serde::Deserialize;
use serde_json::Value;

use optimizer::api::job::Job;
use optimizer::api::pvs::PvsFile;
use optimizer::api::scene::SceneSummary;

use crate::error::ApiError;
use crate::store::{self, Staged};
use crate::{Access, AppState};

/// The documented error answers `(status, description)` an extractor may
/// give before its handler runs, each with the error body.
fn error_responses(
    ctx: &mut GenContext,
    operation: &mut Operation,
    codes: &[(u16, &str)],
) -> Vec<(Option<StatusCode>, Response)> {
    codes
        .iter()
        .filter_map(|&(code, description)| {
            let mut r = ApiError::operation_response(ctx, operation)?;
            r.description = description.into();
            Some((Some(StatusCode::Code(code)), r))
        })
        .collect()
}

/// The name of the bearer-token security scheme in the OpenAPI document.
pub(crate) const BEARER: &str = "bearer";

/// Who makes the request (the [`Access`] the guard found from its token):
/// the job routes see and act on that tenant's jobs only.
pub struct Caller(pub Access);

impl<S: Send + Sync> FromRequestParts<S> for Caller {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, _: &S) -> Result<Self, ApiError> {
        parts
            .extensions
            .get::<Access>()
            .cloned()
            .map(Caller)
            .ok_or_else(|| ApiError::internal("a /v1 request reached its handler unguarded"))
    }
}

impl OperationInput for Caller {
    /// The route needs a bearer token (when the server has tokens), and
    /// may answer 401 and 429 before its handler runs.
    fn operation_input(_: &mut GenContext, operation: &mut Operation) {
        let mut requirement = aide::openapi::SecurityRequirement::default();
        requirement.insert(BEARER.into(), Vec::new());
        operation.security.push(requirement);
    }

    fn inferred_early_responses(
        ctx: &mut GenContext,
        operation: &mut Operation,
    ) -> Vec<(Option<StatusCode>, Response)> {
        error_responses(
            ctx,
            operation,
            &[
                (
                    401,
                    "no token, or one the server does not know (or has revoked)",
                ),
                (
                    429,
                    "over the tenant's rate limit (`Retry-After` says when to try again)",
                ),
            ],
        )
    }
}

/// The `{id}` of a job route, as given (the handlers look it up: an id
/// that is not a job's, numeric ids of older versions included, is 404).
pub struct JobId(pub String);

/// The documented shape of the `{id}` path parameter; only its schema is
/// used, as [`JobId`] reads the parameter with the same rules as
/// `Path<String>` (and answers with the same rejections).
#[derive(JsonSchema)]
#[schemars(inline)]
struct JobIdParam {
    /// The job's id (a UUID).
    #[allow(dead_code)]
    id: String,
}

impl<S: Send + Sync> FromRequestParts<S> for JobId {
    type Rejection = PathRejection;

    async fn from_request_parts(parts: &mut Parts, state: &S) -> Result<Self, Self::Rejection> {
        let Path(id) = Path::<String>::from_request_parts(parts, state).await?;
        Ok(JobId(id))
    }
}

impl OperationInput for JobId {
    fn operation_input(ctx: &mut GenContext, operation: &mut Operation) {
        Path::<JobIdParam>::operation_input(ctx, operation);
    }
}

/// A job submission: the scene (a GLB, glTF JSON or scene summary), the job
/// JSON, an optional PVS file, staged on disk, and whether to bake the
/// impostors.
pub struct Submission {
    /// The inputs' files ([`store::SCENE`], [`store::JOB`], [`store::PVS`]).
    pub staged: Staged,
    /// Whether a PVS file was given.
    pub has_pvs: bool,
    /// Whether to bake the impostors after the placement.
    pub bake: bool,
}

/// The JSON submission body: a scene summary inline.
#[derive(Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
#[schemars(rename = "Submission")]
struct JsonSubmission {
    /// The scene summary.
    #[schemars(with = "SceneSummary")]
    scene: Value,
    /// The job.
    #[schemars(with = "Job")]
    job: Value,
    /// A PVS file, for visibility `precomputed`.
    #[serde(default)]
    #[schemars(with = "Option<PvsFile>")]
    pvs: Option<Value>,
    /// Also bake the impostors (`impostors.glb`).
    #[serde(default)]
    bake: bool,
}

/// A multipart error's status: 413 when the body is over the limit, 400
/// otherwise.
fn multipart_status(status: HttpStatus) -> HttpStatus {
    if status == HttpStatus::PAYLOAD_TOO_LARGE {
        HttpStatus::PAYLOAD_TOO_LARGE
    } else {
        HttpStatus::BAD_REQUEST
    }
}

/// Streams a multipart part into the file at `path`, chunk by chunk as
/// it arrives, and syncs it.
async fn stream_to(
    mut field: Field<'_>,
    name: &str,
    path: &std::path::Path,
) -> Result<(), ApiError> {
    use tokio::io::AsyncWriteExt;
    let mut file = tokio::fs::File::create(path)
        .await
        .map_err(ApiError::internal)?;
    while let Some(chunk) = field.chunk().await.map_err(|e| {
        ApiError::new(
            multipart_status(e.status()),
            format!("multipart part `{name}`: {}", e.body_text()),
        )
    })? {
        file.write_all(&chunk).await.map_err(ApiError::internal)?;
    }
    // Not synced: the upload is copied (and synced) into the artifact
    // store when it is accepted, and removed after.
    file.flush().await.map_err(ApiError::internal)
}

impl Submission {
    async fn from_multipart(mut mp: Multipart, staged: Staged) -> Result<Self, ApiError> {
        let (mut scene, mut job, mut has_pvs, mut bake) = (false, false, false, false);
        loop {
            let field = mp.next_field().await.map_err(|e| {
                ApiError::new(
                    multipart_status(e.status()),
                    format!("bad multipart body: {}", e.body_text()),
                )
            })?;
            let Some(mut field) = field else { break };
            let name = field.name().unwrap_or("").to_string();
            let file = match name.as_str() {
                "scene" => {
                    scene = true;
                    store::SCENE
                }
                "job" => {
                    job = true;
                    store::JOB
                }
                "pvs" => {
                    has_pvs = true;
                    store::PVS
                }
                "bake" => {
                    // A word: read it, at most a few bytes of it.
                    let mut value = Vec::new();
                    while let Some(chunk) = field.chunk().await.map_err(|e| {
                        ApiError::new(
                            multipart_status(e.status()),
                            format!("multipart part `bake`: {}", e.body_text()),
                        )
                    })? {
                        value.extend_from_slice(&chunk);
                        if value.len() > 16 {
                            return Err(ApiError::new(
                                HttpStatus::BAD_REQUEST,
                                "multipart part `bake` must be \"true\" or \"false\"",
                            ));
                        }
                    }
                    bake = value == b"true";
                    continue;
                }
                other => {
                    return Err(ApiError::new(
                        HttpStatus::BAD_REQUEST,
                        format!(
                            "unknown multipart part `{other}` (expected scene, job, pvs, bake)"
                        ),
                    ));
                }
            };
            stream_to(field, &name, &staged.path(file)).await?;
        }
        let missing = |part: &str| {
            ApiError::new(
                HttpStatus::BAD_REQUEST,
                format!("multipart part `{part}` is missing"),
            )
        };
        if !scene {
            return Err(missing("scene"));
        }
        if !job {
            return Err(missing("job"));
        }
        Ok(Submission {
            staged,
            has_pvs,
            bake,
        })
    }

    async fn from_json(body: &[u8], staged: Staged) -> Result<Self, ApiError> {
        let sub: JsonSubmission = serde_json::from_slice(body).map_err(|e| {
            ApiError::new(
                HttpStatus::BAD_REQUEST,
                format!("body must be {{\"scene\": <scene summary>, \"job\": <job>}}: {e}"),
            )
        })?;
        let parts = [
            (store::SCENE, Some(&sub.scene)),
            (store::JOB, Some(&sub.job)),
            (store::PVS, sub.pvs.as_ref()),
        ];
        for (file, value) in parts {
            if let Some(v) = value {
                let bytes = serde_json::to_vec(v).map_err(ApiError::internal)?;
                let mut f = tokio::fs::File::create(staged.path(file))
                    .await
                    .map_err(ApiError::internal)?;
                use tokio::io::AsyncWriteExt;
                f.write_all(&bytes).await.map_err(ApiError::internal)?;
                f.flush().await.map_err(ApiError::internal)?;
            }
        }
        Ok(Submission {
            staged,
            has_pvs: sub.pvs.is_some(),
            bake: sub.bake,
        })
    }
}

impl FromRequest<AppState> for Submission {
    type Rejection = ApiError;

    async fn from_request(req: Request, state: &AppState) -> Result<Self, ApiError> {
        let ctype = req
            .headers()
            .get(header::CONTENT_TYPE)
            .and_then(|v| v.to_str().ok())
            .unwrap_or("")
            .to_ascii_lowercase();
        if ctype.starts_with("multipart/form-data") {
            let mp = Multipart::from_request(req, state).await.map_err(|e| {
                ApiError::new(HttpStatus::BAD_REQUEST, format!("bad multipart body: {e}"))
            })?;
            let staged = state.0.store.stage().await.map_err(ApiError::internal)?;
            Submission::from_multipart(mp, staged).await
        } else if ctype.starts_with("application/json") {
            let body = Bytes::from_request(req, state).await.map_err(|e| {
                ApiError::new(e.status(), format!("request body: {}", e.body_text()))
            })?;
            let staged = state.0.store.stage().await.map_err(ApiError::internal)?;
            Submission::from_json(&body, staged).await
        } else {
            Err(ApiError::new(
                HttpStatus::UNSUPPORTED_MEDIA_TYPE,
                "use multipart/form-data (parts `scene`, `job`) or application/json",
            ))
        }
    }
}

impl OperationInput for Submission {
    fn operation_input(ctx: &mut GenContext, operation: &mut Operation) {
        let described = |mut schema: schemars::Schema, description: &str| {
            schema.insert("description".into(), description.into());
            schema
        };
        let job = described(
            ctx.schema.subschema_for::<Job>(),
            "the job (JSON, as `impostor place` reads it)",
        );
        let pvs = described(
            ctx.schema.subschema_for::<PvsFile>(),
            "a PVS file, for visibility \"precomputed\"",
        );
        let multipart = schemars::json_schema!({
            "type": "object",
            "required": ["scene", "job"],
            "properties": {
                "scene": {
                    "type": "string",
                    "format": "binary",
                    "description": "the scene: a GLB (or glTF JSON, or a scene summary)"
                },
                "job": job,
                "pvs": pvs,
                "bake": {
                    "type": "string",
                    "enum": ["true", "false"],
                    "description": "\"true\" to also bake the impostors (`impostors.glb`)"
                }
            }
        });
        let json = ctx.schema.subschema_for::<JsonSubmission>();
        let media = |json_schema| MediaType {
            schema: Some(SchemaObject {
                json_schema,
                example: None,
                external_docs: None,
            }),
            ..MediaType::default()
        };
        let mut body = RequestBody {
            description: Some("a GLB upload (multipart) or an inline scene summary (JSON)".into()),
            required: true,
            ..RequestBody::default()
        };
        body.content
            .insert("multipart/form-data".into(), media(multipart));
        body.content.insert("application/json".into(), media(json));
        set_body(ctx, operation, body);
    }

    fn inferred_early_responses(
        ctx: &mut GenContext,
        operation: &mut Operation,
    ) -> Vec<(Option<StatusCode>, Response)> {
        error_responses(
            ctx,
            operation,
            &[
                (
                    400,
                    "a malformed body: bad multipart or JSON, a missing or unknown part",
                ),
                (413, "the body is larger than the upload limit"),
                (415, "neither multipart/form-data nor application/json"),
            ],
        )
    }
}
