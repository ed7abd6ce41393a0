//! The service's own routes: health (`/healthz`), metrics (`/metrics`), the OpenAPI document
//! (`/openapi.json`), and the answer to `OPTIONS`.

use std::sync::{Arc, OnceLock};

use aide::transform::TransformOperation;
use axum::body::Body;
use axum::body::Bytes;
use axum::extract::State;
use axum::http::{Response, StatusCode, header};
use axum::response::IntoResponse;
use schemars::json_schema;
use serde_json::Value;

use super::state::AppState;
use crate::openapi::{answer, responses, string, text, with_content};

/// The media type of the metrics.
const OPENMETRICS: &str = "application/openmetrics-text";

/// The `Content-Type` of the metrics.
const OPENMETRICS_CONTENT_TYPE: &str = "application/openmetrics-text; version=1.0.0; charset=utf-8";

/// The documentation of `GET /healthz`.
pub(super) fn health_docs(mut op: TransformOperation<'_>) -> TransformOperation<'_> {
    // An empty `security` list says that no token is needed; aide leaves empty lists out, so
    // it is written as is.
    op.inner_mut()
        .extensions
        .insert("security".into(), Value::Array(Vec::new()));
    let op = op.summary("Liveness");
    responses(op, [(200, text("ok"))])
}

/// The documentation of `GET /metrics`.
pub(super) fn metrics_docs(op: TransformOperation<'_>) -> TransformOperation<'_> {
    let op = op.summary(
        "Prometheus metrics: requests by status class, bytes, latency histogram, cache \
         hits/misses/bytes, connections",
    );
    let metrics = with_content(answer("OpenMetrics text"), OPENMETRICS, string());
    responses(op, [(200, metrics)])
}

/// The documentation of `GET /openapi.json`.
pub(super) fn openapi_docs(op: TransformOperation<'_>) -> TransformOperation<'_> {
    let op = op.summary("This document");
    let document = with_content(
        answer("OpenAPI 3.1"),
        "application/json",
        json_schema!({"type": "object"}),
    );
    responses(op, [(200, document)])
}

/// `GET /healthz`.
pub(super) async fn health() -> &'static str {
    "ok\n"
}

/// `GET /metrics`: the metrics as OpenMetrics text.
pub(super) async fn show_metrics(State(state): State<Arc<AppState>>) -> Response<Body> {
    let content_type = [(header::CONTENT_TYPE, OPENMETRICS_CONTENT_TYPE)];
    (content_type, state.metrics.render()).into_response()
}

/// `GET /openapi.json`: the document, generated and serialized on the first request.
pub(super) async fn openapi() -> Response<Body> {
    static DOCUMENT: OnceLock<Bytes> = OnceLock::new();
    let document = DOCUMENT.get_or_init(|| {
        serde_json::to_vec(&super::openapi_document())
            .expect("a JSON value always serializes")
            .into()
    });
    let content_type = [(header::CONTENT_TYPE, "application/json")];
    (content_type, document.clone()).into_response()
}

/// `OPTIONS` on the API paths: the methods allowed.
pub(super) async fn allowed_methods() -> Response<Body> {
    (
        StatusCode::NO_CONTENT,
        [(header::ALLOW, "GET, HEAD, OPTIONS")],
    )
        .into_response()
}
