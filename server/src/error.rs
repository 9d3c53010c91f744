//! Error answers: [`ApiError`] turns into a status with an `{"error": ...}`
//! JSON body (and `Retry-After` on 429), and documents itself as the
//! `ErrorBody` schema in the OpenAPI document.

use aide::generate::GenContext;
use aide::openapi::{Operation, Response, StatusCode as DocStatus};
use aide::operation::OperationOutput;
use axum::http::{HeaderValue, StatusCode, header};
use axum::response::IntoResponse;

use crate::api::types::ErrorBody;

/// An error answer: status and a JSON `{"error": ...}` body.
#[derive(Debug)]
pub struct ApiError(StatusCode, String);

impl ApiError {
    /// An error with `status` and the message `msg`.
    pub(crate) fn new(status: StatusCode, msg: impl Into<String>) -> Self {
        ApiError(status, msg.into())
    }

    /// A 500 answer for a failure that is not the client's.
    pub(crate) fn internal(e: impl std::fmt::Display) -> Self {
        ApiError::new(
            StatusCode::INTERNAL_SERVER_ERROR,
            format!("internal error: {e}"),
        )
    }

    /// A 404 answer for an id without a job.
    pub(crate) fn no_job(id: &str) -> Self {
        ApiError::new(StatusCode::NOT_FOUND, format!("no job {id}"))
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> axum::response::Response {
        let mut r = (self.0, axum::Json(ErrorBody { error: self.1 })).into_response();
        // A full queue drains as jobs finish: tell clients when to try again.
        if self.0 == StatusCode::TOO_MANY_REQUESTS {
            r.headers_mut()
                .insert(header::RETRY_AFTER, HeaderValue::from_static("5"));
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
