//! Error answers: [`ApiError`] turns into a status with an `{"error": ...}`
//! JSON body (with `Retry-After` on 429 and `WWW-Authenticate` on 401), and documents itself as the
//! `ErrorBody` schema in the OpenAPI document.

use aide::generate::GenContext;
use aide::openapi::{Operation, Response, StatusCode as DocStatus};
use aide::operation::OperationOutput;
use axum::http::{HeaderValue, StatusCode, header};
use axum::response::IntoResponse;

use crate::api::types::ErrorBody;

/// An error answer: status, a JSON `{"error": ...}` body and, for an
/// internal error, the request id its details were logged under.
#[derive(Debug)]
pub struct ApiError {
    status: StatusCode,
    message: String,
    request_id: Option<String>,
    /// Seconds a client should wait before trying again (429).
    retry_after: u64,
}

/// A new id to log an internal error under: 16 random hex digits.
pub(crate) fn new_request_id() -> String {
    let mut id = uuid::Uuid::new_v4().simple().to_string();
    id.truncate(16);
    id
}

impl ApiError {
    /// An error with `status` and the message `msg`.
    pub(crate) fn new(status: StatusCode, msg: impl Into<String>) -> Self {
        ApiError {
            status,
            message: msg.into(),
            request_id: None,
            retry_after: 5,
        }
    }

    /// A 429 answer telling the client to wait `seconds` (at least 1).
    pub(crate) fn too_many(msg: impl Into<String>, seconds: u64) -> Self {
        ApiError {
            retry_after: seconds.max(1),
            ..ApiError::new(StatusCode::TOO_MANY_REQUESTS, msg)
        }
    }

    /// A 500 answer for a failure that is not the client's: its details
    /// (which may name files and internals) go to the server's log under a
    /// new request id, and the answer carries only that id.
    pub(crate) fn internal(e: impl std::fmt::Display) -> Self {
        let id = new_request_id();
        tracing::error!(request_id = id, "internal error: {e}");
        ApiError {
            request_id: Some(id.clone()),
            ..ApiError::new(
                StatusCode::INTERNAL_SERVER_ERROR,
                format!("internal error (request {id}; the server's log has the details)"),
            )
        }
    }

    /// A 404 answer for an id without a job.
    pub(crate) fn no_job(id: &str) -> Self {
        ApiError::new(StatusCode::NOT_FOUND, format!("no job {id}"))
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> axum::response::Response {
        let body = ErrorBody {
            error: self.message,
            request_id: self.request_id,
        };
        let mut r = (self.status, axum::Json(body)).into_response();
        // A full queue drains as jobs finish, a rate limit refills: tell
        // clients when to try again.
        if self.status == StatusCode::TOO_MANY_REQUESTS {
            r.headers_mut()
                .insert(header::RETRY_AFTER, HeaderValue::from(self.retry_after));
        }
        if self.status == StatusCode::UNAUTHORIZED {
            r.headers_mut()
                .insert(header::WWW_AUTHENTICATE, HeaderValue::from_static("Bearer"));
        }
        r
    }
}

impl OperationOutput for ApiError {
    type Inner = ErrorBody;

    fn operation_response(ctx: &mut GenContext, operation: &mut Operation) -> Option<Response> {
        axum::Json::<ErrorBody>::operation_response(ctx, operation)
    }

    /// Every handler that can fail can fail on the server's side, so a 500
    /// is inferred; the client errors of each route are listed with it.
    fn inferred_responses(
        ctx: &mut GenContext,
        operation: &mut Operation,
    ) -> Vec<(Option<DocStatus>, Response)> {
        Self::operation_response(ctx, operation)
            .map(|mut r| {
                r.description = "internal error".into();
                (Some(DocStatus::Code(500)), r)
            })
            .into_iter()
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An internal error's answer carries a request id, never the error's
    /// own text (which may name files of the server).
    #[tokio::test]
    async fn internal_errors_answer_with_a_request_id_only() {
        let e = ApiError::internal("cannot open /srv/impostor-data/jobs.sqlite: disk I/O error");
        let r = e.into_response();
        assert_eq!(r.status(), StatusCode::INTERNAL_SERVER_ERROR);
        let body = axum::body::to_bytes(r.into_body(), 1 << 16).await.unwrap();
        let v: serde_json::Value = serde_json::from_slice(&body).unwrap();
        let id = v["request_id"].as_str().unwrap();
        assert_eq!(id.len(), 16);
        assert!(id.bytes().all(|b| b.is_ascii_hexdigit()), "{id}");
        let text = v["error"].as_str().unwrap();
        assert!(text.contains(id), "{text}");
        assert!(
            !text.contains("jobs.sqlite") && !text.contains("disk"),
            "{text}"
        );
        // Two errors, two ids; client errors have none.
        assert_ne!(new_request_id(), new_request_id());
        let r = ApiError::no_job("x").into_response();
        let body = axum::body::to_bytes(r.into_body(), 1 << 16).await.unwrap();
        assert_eq!(&body[..], br#"{"error":"no job x"}"#);
    }
}
