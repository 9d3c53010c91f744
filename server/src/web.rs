//! The web page: `GET /` (the index) and `GET /assets/{file}` (its script
//! and style sheet, the Basis Universal transcoder and Draco's decoder in
//! folders of their own, `assets/basis-HASH/` and `assets/draco-HASH/`),
//! embedded in the binary. `build.rs` bundles `web/`
//! with esbuild into `OUT_DIR/web`; the assets are named by their content's
//! hash, so they are cached for good while the index is checked each time.
//! The page talks to the `/v1` API like any client.

use axum::Router;
use axum::extract::Path;
use axum::http::{HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use include_dir::{Dir, include_dir};

static WEB: Dir<'static> = include_dir!("$OUT_DIR/web");

/// The routes of the page (outside the API and its OpenAPI document).
pub(crate) fn router<S: Clone + Send + Sync + 'static>() -> Router<S> {
    Router::new()
        .route("/", get(index))
        .route("/assets/{*file}", get(asset))
}

/// The content type of a file of the page, from its extension.
fn content_type(name: &str) -> &'static str {
    match name.rsplit_once('.').map(|(_, ext)| ext) {
        Some("html") => "text/html; charset=utf-8",
        Some("js") => "text/javascript; charset=utf-8",
        Some("css") => "text/css; charset=utf-8",
        Some("json") => "application/json",
        Some("svg") => "image/svg+xml",
        Some("png") => "image/png",
        Some("wasm") => "application/wasm",
        _ => "application/octet-stream",
    }
}

/// 404, in plain text.
fn not_found(path: &str) -> Response {
    (
        StatusCode::NOT_FOUND,
        [(
            header::CONTENT_TYPE,
            HeaderValue::from_static("text/plain; charset=utf-8"),
        )],
        format!("no such file: /{path}"),
    )
        .into_response()
}

/// The embedded file at `path` with its content type and `cache`.
fn file(path: &str, cache: &'static str) -> Response {
    match WEB.get_file(path) {
        Some(f) => (
            [
                (
                    header::CONTENT_TYPE,
                    HeaderValue::from_static(content_type(path)),
                ),
                (header::CACHE_CONTROL, HeaderValue::from_static(cache)),
                (
                    header::X_CONTENT_TYPE_OPTIONS,
                    HeaderValue::from_static("nosniff"),
                ),
            ],
            f.contents(),
        )
            .into_response(),
        None => not_found(path),
    }
}

/// `GET /`: the page (it names the current assets, so it is revalidated).
async fn index() -> Response {
    file("index.html", "no-cache")
}

/// `GET /assets/{file}`: a script or style sheet of the page, named by its
/// hash (so never changed under the same name), or a file of a folder so
/// named.
async fn asset(Path(name): Path<String>) -> Response {
    // The assets and one level of folders: no `..`, nothing hidden.
    let parts: Vec<&str> = name.split('/').collect();
    if parts.len() > 2 || parts.iter().any(|p| p.is_empty() || p.starts_with('.')) {
        return not_found(&format!("assets/{name}"));
    }
    file(
        &format!("assets/{name}"),
        "public, max-age=31536000, immutable",
    )
}
