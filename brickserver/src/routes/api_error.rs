//! The JSON error answers of the region and brick API ([`ApiError`]).

use axum::body::Body;
use axum::http::{Response, StatusCode};
use axum::response::{IntoResponse, Json};
use residency_schemas::server::ApiError;

/// A JSON error answer (logged when it is the server's fault).
pub(super) fn api_error(status: StatusCode, error: String) -> Response<Body> {
    if status.is_server_error() {
        tracing::error!("{error}");
    }
    (status, Json(ApiError { error })).into_response()
}

/// The answer for a dataset that is not served.
pub(super) fn no_dataset(name: &str) -> Response<Body> {
    api_error(StatusCode::NOT_FOUND, format!("no dataset '{name}'"))
}
