//! The HTTP routes: Zarr keys under `/NAME/`, the dataset listing, and health.

use std::sync::Arc;

use axum::Router;
use axum::body::Body;
use axum::extract::{Path, Request, State};
use axum::http::{HeaderMap, Method, Response, StatusCode, Uri, header};
use axum::middleware::{self, Next};
use axum::response::{IntoResponse, Json};
use axum::routing::get;
use serde_json::json;
use tower_http::cors::{Any, CorsLayer};

use crate::datasets::Datasets;
use crate::metrics::{Metrics, track};
use crate::responses::file_response;
use crate::store_keys::{KeyError, resolve};

/// Shared state of the routes.
pub type AppState = Arc<Datasets>;

/// Server-wide options of the router.
#[derive(Clone, Debug, Default)]
pub struct ServerOptions {
    /// When set, every request but `/healthz` must carry `Authorization: Bearer <token>`.
    pub token: Option<String>,
}

/// Refuses requests without the configured bearer token (401), except health checks and
/// CORS preflights, which browsers send without credentials.
async fn require_token(
    State(token): State<Arc<Option<String>>>,
    request: Request,
    next: Next,
) -> Response<Body> {
    let Some(token) = token.as_deref() else {
        return next.run(request).await;
    };
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
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.strip_prefix("Bearer "));
    // Compare in constant time so the token cannot be guessed byte by byte from timings.
    let ok = given.is_some_and(|g| {
        g.len() == token.len()
            && g.bytes()
                .zip(token.bytes())
                .fold(0u8, |a, (x, y)| a | (x ^ y))
                == 0
    });
    if ok {
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

/// The router serving `datasets`.
pub fn router(datasets: Datasets, options: ServerOptions) -> Router {
    let cors = CorsLayer::new()
        .allow_origin(Any)
        .allow_methods([Method::GET, Method::HEAD, Method::OPTIONS])
        .allow_headers(Any)
        .expose_headers([
            header::ETAG,
            header::CONTENT_RANGE,
            header::CONTENT_LENGTH,
            header::ACCEPT_RANGES,
        ])
        .max_age(std::time::Duration::from_secs(86400));
    let metrics = Arc::new(Metrics::default());
    let shown = metrics.clone();
    Router::new()
        .route(
            "/metrics",
            get(move || async move {
                (
                    [(
                        header::CONTENT_TYPE,
                        "application/openmetrics-text; version=1.0.0; charset=utf-8",
                    )],
                    shown.render(),
                )
            }),
        )
        .route("/", get(list).options(allowed_methods))
        .route("/datasets", get(list).options(allowed_methods))
        .route(
            "/healthz",
            get(|| async { "ok\n" }).options(allowed_methods),
        )
        .route("/{name}/{*key}", get(serve_key).options(allowed_methods))
        .with_state(Arc::new(datasets))
        .layer(middleware::from_fn_with_state(
            Arc::new(options.token),
            require_token,
        ))
        .layer(middleware::from_fn_with_state(metrics, track))
        .layer(cors)
}

async fn allowed_methods() -> impl IntoResponse {
    (
        StatusCode::NO_CONTENT,
        [(header::ALLOW, "GET, HEAD, OPTIONS")],
    )
}

async fn list(State(datasets): State<AppState>, headers: HeaderMap) -> Json<serde_json::Value> {
    let host = headers
        .get(header::HOST)
        .and_then(|h| h.to_str().ok())
        .unwrap_or("localhost");
    let items: Vec<_> = datasets
        .0
        .iter()
        .map(|d| {
            let url = format!("http://{host}/{}/", d.name);
            let layer = json!({"layers": [{"type": "image", "source": format!("zarr3://{url}"), "name": d.name}]});
            let fragment = percent_encoding::utf8_percent_encode(
                &layer.to_string(),
                percent_encoding::NON_ALPHANUMERIC,
            )
            .to_string();
            json!({
                "name": d.name,
                "url": url,
                "neuroglancer": format!("https://neuroglancer-demo.appspot.com/#!{fragment}"),
                "vizarr": format!("https://hms-dbmi.github.io/vizarr/?source={url}"),
            })
        })
        .collect();
    Json(json!({ "datasets": items }))
}

async fn serve_key(
    State(datasets): State<AppState>,
    Path((name, _)): Path<(String, String)>,
    uri: Uri,
    headers: HeaderMap,
) -> Response<Body> {
    let Some(dataset) = datasets.get(&name) else {
        return (StatusCode::NOT_FOUND, format!("no dataset '{name}'\n")).into_response();
    };
    // The raw, still percent-encoded key: everything after "/NAME/".
    let raw_key = uri
        .path()
        .splitn(3, '/')
        .nth(2)
        .unwrap_or_default()
        .to_string();
    match resolve(&dataset.root, &raw_key) {
        Ok(path) => match file_response(&path, &raw_key, &headers).await {
            Ok(response) => response,
            Err((status, message)) => {
                tracing::error!(dataset = %name, key = %raw_key, "{message}");
                (status, format!("{message}\n")).into_response()
            }
        },
        Err(KeyError::NotFound) => (
            StatusCode::NOT_FOUND,
            format!("no key '{raw_key}' in '{name}'\n"),
        )
            .into_response(),
        Err(KeyError::Refused(why)) => {
            (StatusCode::BAD_REQUEST, format!("refused: {why}\n")).into_response()
        }
    }
}
