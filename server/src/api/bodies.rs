//! Bodies served from bytes rather than built from typed values: stored
//! results (placement and evaluation JSON, the impostor GLB, the HTML
//! report) and the OpenAPI document. Each sets its content type and
//! describes itself in the OpenAPI document.

use std::marker::PhantomData;

use aide::generate::GenContext;
use aide::openapi::{MediaType, Operation, Response as DocResponse, SchemaObject, StatusCode};
use aide::operation::OperationOutput;
use axum::body::Bytes;
use axum::http::{HeaderValue, header};
use axum::response::{IntoResponse, Response};
use schemars::JsonSchema;

/// `bytes` with `Content-Type: content_type`.
fn with_type(content_type: &'static str, bytes: impl IntoResponse) -> Response {
    (
        [(header::CONTENT_TYPE, HeaderValue::from_static(content_type))],
        bytes,
    )
        .into_response()
}

/// A 200 response of `media_type` with an optional schema.
fn ok_response(
    description: &str,
    media_type: &str,
    schema: Option<schemars::Schema>,
) -> Vec<(Option<StatusCode>, DocResponse)> {
    let mut response = DocResponse {
        description: description.into(),
        ..DocResponse::default()
    };
    response.content.insert(
        media_type.into(),
        MediaType {
            schema: schema.map(|json_schema| SchemaObject {
                json_schema,
                example: None,
                external_docs: None,
            }),
            ..MediaType::default()
        },
    );
    vec![(Some(StatusCode::Code(200)), response)]
}

/// A result file holding the JSON of a `T`, served byte for byte (the same
/// bytes as the CLI writes) and documented with `T`'s schema.
pub struct StoredJson<T> {
    bytes: Vec<u8>,
    of: PhantomData<fn() -> T>,
}

impl<T> StoredJson<T> {
    /// The stored bytes of a `T`.
    pub fn new(bytes: Vec<u8>) -> Self {
        StoredJson {
            bytes,
            of: PhantomData,
        }
    }
}

impl<T> IntoResponse for StoredJson<T> {
    fn into_response(self) -> Response {
        with_type("application/json", self.bytes)
    }
}

impl<T: JsonSchema> OperationOutput for StoredJson<T> {
    type Inner = T;

    fn operation_response(ctx: &mut GenContext, operation: &mut Operation) -> Option<DocResponse> {
        axum::Json::<T>::operation_response(ctx, operation)
    }

    fn inferred_responses(
        ctx: &mut GenContext,
        operation: &mut Operation,
    ) -> Vec<(Option<StatusCode>, DocResponse)> {
        Self::operation_response(ctx, operation)
            .map(|r| (Some(StatusCode::Code(200)), r))
            .into_iter()
            .collect()
    }
}

/// A stream of server-sent events, each `event: status` with a
/// [`JobEvent`](super::types::JobEvent) as its JSON data.
pub struct EventStream(pub Response);

impl IntoResponse for EventStream {
    fn into_response(self) -> Response {
        self.0
    }
}

impl OperationOutput for EventStream {
    type Inner = super::types::JobEvent;

    fn inferred_responses(
        ctx: &mut GenContext,
        _operation: &mut Operation,
    ) -> Vec<(Option<StatusCode>, DocResponse)> {
        let schema = ctx.schema.subschema_for::<super::types::JobEvent>();
        ok_response(
            "server-sent events (`event: status`, data: a JobEvent as JSON) whenever the \
             job's state, stage or progress changes; the stream ends after the final state",
            "text/event-stream",
            Some(schema),
        )
    }
}

/// The baked impostors: a GLB file.
pub struct Glb(pub Vec<u8>);

impl IntoResponse for Glb {
    fn into_response(self) -> Response {
        with_type("model/gltf-binary", self.0)
    }
}

impl OperationOutput for Glb {
    type Inner = Vec<u8>;

    fn inferred_responses(
        _ctx: &mut GenContext,
        _operation: &mut Operation,
    ) -> Vec<(Option<StatusCode>, DocResponse)> {
        ok_response(
            "the baked impostors: one GLB of alpha-masked quads per impostor layer",
            "model/gltf-binary",
            None,
        )
    }
}

/// A self-contained HTML page.
pub struct HtmlPage(pub Vec<u8>);

impl IntoResponse for HtmlPage {
    fn into_response(self) -> Response {
        with_type("text/html; charset=utf-8", self.0)
    }
}

impl OperationOutput for HtmlPage {
    type Inner = String;

    fn inferred_responses(
        _ctx: &mut GenContext,
        _operation: &mut Operation,
    ) -> Vec<(Option<StatusCode>, DocResponse)> {
        ok_response(
            "a self-contained HTML page",
            "text/html",
            Some(schemars::json_schema!({"type": "string"})),
        )
    }
}

/// Metrics in Prometheus' text format.
pub struct MetricsText(pub String);

impl IntoResponse for MetricsText {
    fn into_response(self) -> Response {
        with_type(
            "text/plain; version=0.0.4; charset=utf-8",
            self.0.into_bytes(),
        )
    }
}

impl OperationOutput for MetricsText {
    type Inner = String;

    fn inferred_responses(
        _ctx: &mut GenContext,
        _operation: &mut Operation,
    ) -> Vec<(Option<StatusCode>, DocResponse)> {
        ok_response(
            "metrics in Prometheus' text exposition format",
            "text/plain",
            Some(schemars::json_schema!({"type": "string"})),
        )
    }
}

/// The OpenAPI document, serialized once when the router is built.
#[derive(Clone)]
pub struct OpenApiJson(pub Bytes);

impl IntoResponse for OpenApiJson {
    fn into_response(self) -> Response {
        with_type("application/json", self.0)
    }
}

impl OperationOutput for OpenApiJson {
    type Inner = Self;

    fn inferred_responses(
        _ctx: &mut GenContext,
        _operation: &mut Operation,
    ) -> Vec<(Option<StatusCode>, DocResponse)> {
        ok_response(
            "an OpenAPI 3.1 document",
            "application/json",
            Some(schemars::json_schema!({"type": "object"})),
        )
    }
}

/// A job's scene as it was submitted: a GLB upload, or the JSON scene
/// summary of an inline submission (told apart by the GLB's magic).
pub struct SceneFile(pub Vec<u8>);

impl IntoResponse for SceneFile {
    fn into_response(self) -> Response {
        let kind = if self.0.starts_with(b"glTF") {
            "model/gltf-binary"
        } else {
            "application/json"
        };
        with_type(kind, self.0)
    }
}

impl OperationOutput for SceneFile {
    type Inner = Vec<u8>;

    fn inferred_responses(
        _ctx: &mut GenContext,
        _operation: &mut Operation,
    ) -> Vec<(Option<StatusCode>, DocResponse)> {
        let mut out = ok_response(
            "the scene as submitted: the GLB upload, byte for byte",
            "model/gltf-binary",
            None,
        );
        out[0].1.description = "the scene as submitted: the GLB upload byte for byte, or the \
                                JSON scene summary of an inline submission"
            .into();
        out[0].1.content.insert(
            "application/json".into(),
            MediaType {
                schema: Some(SchemaObject {
                    json_schema: schemars::json_schema!({"type": "object"}),
                    example: None,
                    external_docs: None,
                }),
                ..MediaType::default()
            },
        );
        out
    }
}
