//! The bearer token check, a layer of the router when the server runs with a token.

use std::sync::Arc;

use axum::body::Body;
use axum::extract::{Request, State};
use axum::http::{Method, Response, StatusCode, header};
use axum::middleware::Next;
use axum::response::IntoResponse;
use residency_schemas::server::bearer_token_matches;

/// Refuses requests without the configured bearer token (401), except health checks and
/// CORS preflights, which browsers send without credentials.
pub(super) async fn require_token(
    State(token): State<Arc<String>>,
    request: Request,
    next: Next,
) -> Response<Body> {
    let preflight = request.method() == Method::OPTIONS
        && request
            .headers()
            .contains_key(header::ACCESS_CONTROL_REQUEST_METHOD);
    if request.uri().path() == "/healthz" || preflight {
        return next.run(request).await;
    }
    let given = request
        .headers()
        .get(header::AUTHORIZATION)
        .and_then(|v| v.to_str().ok());
    if bearer_token_matches(given, &token) {
        next.run(request).await
    } else {
        (
            StatusCode::UNAUTHORIZED,
            [(header::WWW_AUTHENTICATE, "Bearer")],
            "missing or wrong bearer token\n",
        )
            .into_response()
    }
}
