//! The HTTP routes, one module per API: Zarr keys under `/NAME/` ([`zarr`]), the region API
//! (`/NAME/regions`, `/NAME/minmax`: [`region_api`]; `/NAME/bricks`: [`bricks`]), the Residency
//! web viewer (`/NAME/view`, `/viewer/FILE`: [`viewer`]), the dataset listing ([`listing`]),
//! and health, metrics and the OpenAPI document ([`service`]); the bearer token check is
//! [`auth`]; chunk keys answered straight from the connection ([`chunk_files`]: a folder
//! store's with `sendfile`, an object store's revalidations without asking the store). Here the router is assembled, and with it the OpenAPI document, from the same
//! route list.
//!
//! The three API paths and `view` never collide with a Zarr key: a Zarr node at a store's
//! root is a folder, so its keys are `regions/zarr.json` and the like, never `regions` itself
//! (a file named `view` at a store's root would be shadowed by the viewer page). `/viewer/`
//! is no dataset's: the name `viewer` is reserved.

mod api_error;
mod auth;
mod bricks;
mod chunk_files;
mod listing;
mod params;
mod region_api;
mod service;
mod state;
mod viewer;
mod zarr;

use std::sync::Arc;
use std::time::Duration;

use aide::axum::ApiRouter;
use aide::axum::routing::get_with;
use aide::openapi::OpenApi;
use axum::Router;
use axum::http::{Method, header};
use axum::middleware;
use serde_json::Value;
use tower_http::cors::{Any, CorsLayer};

use crate::metrics::track;
use crate::openapi;

pub(crate) use chunk_files::{ChunkAnswer, DirectChunks};
pub use state::{AppState, OPEN_FILES, ServerOptions};

/// Every route, with its documentation.
fn api_routes() -> ApiRouter<Arc<AppState>> {
    // `OPTIONS` on the API paths answers which methods are allowed; it is not documented
    // (CORS preflights are answered by the CORS layer before they get here).
    let or_options = || axum::routing::options(service::allowed_methods);
    // Static segments win over captures, so `/{name}/view` wins over `/{name}/{*key}` and
    // `/viewer/...` over both.
    ApiRouter::new()
        .api_route("/viewer", get_with(viewer::redirect, viewer::redirect_docs))
        .api_route("/viewer/", get_with(viewer::viewer_file, viewer::page_docs))
        .api_route(
            "/viewer/{*file}",
            get_with(viewer::viewer_file, viewer::file_docs),
        )
        .api_route("/{name}/view", get_with(viewer::view, viewer::view_docs))
        .api_route(
            "/metrics",
            get_with(service::show_metrics, service::metrics_docs),
        )
        .api_route(
            "/openapi.json",
            get_with(service::openapi, service::openapi_docs).merge(or_options()),
        )
        .api_route(
            "/",
            get_with(listing::home, listing::home_docs).merge(or_options()),
        )
        .api_route(
            "/datasets",
            get_with(listing::list, listing::list_docs).merge(or_options()),
        )
        .api_route(
            "/healthz",
            get_with(service::health, service::health_docs).merge(or_options()),
        )
        .api_route(
            "/{name}/regions",
            get_with(region_api::regions, region_api::regions_docs).merge(or_options()),
        )
        .api_route(
            "/{name}/minmax",
            get_with(region_api::minmax, region_api::minmax_docs).merge(or_options()),
        )
        .api_route(
            "/{name}/bricks",
            get_with(bricks::bricks, bricks::docs).merge(or_options()),
        )
        .api_route(
            "/{name}/{*key}",
            get_with(zarr::serve_key, zarr::docs).merge(or_options()),
        )
}

/// The routes and their OpenAPI document.
fn documented_routes() -> (Router<Arc<AppState>>, Value) {
    // Parameters and responses are written into each operation (no schema is extracted into
    // the components, which are the documents' own), and only the responses documented.
    aide::generate::extract_schemas(false);
    aide::generate::infer_responses(false);
    let mut api: OpenApi = openapi::base();
    let routes = api_routes().finish_api(&mut api);
    (routes, openapi::finish(api))
}

/// The OpenAPI document served at `/openapi.json`.
pub fn openapi_document() -> Value {
    documented_routes().1
}

/// The CORS layer: any origin may read, with the fields a Zarr reader needs exposed. No answer
/// depends on the request's `Origin` or preflight fields (the allowed origins and headers are
/// `*`, the methods a fixed list), so none carries a `Vary` for them: 75 bytes less in every
/// head, which counts for 304s.
pub(crate) fn cors() -> CorsLayer {
    CorsLayer::new()
        .allow_origin(Any)
        .allow_methods([Method::GET, Method::HEAD, Method::OPTIONS])
        .allow_headers(Any)
        .expose_headers([
            header::ETAG,
            header::CONTENT_RANGE,
            header::CONTENT_LENGTH,
            header::ACCEPT_RANGES,
        ])
        .max_age(Duration::from_hours(24))
        .vary([] as [header::HeaderName; 0])
}

/// The router serving `state`'s datasets.
pub fn router(state: Arc<AppState>, options: &ServerOptions) -> Router {
    let metrics = state.metrics.clone();
    let router = documented_routes().0.with_state(state);
    // The token check is a layer only when a token is configured.
    let router = match &options.token {
        Some(token) => router.layer(middleware::from_fn_with_state(
            Arc::new(token.clone()),
            auth::require_token,
        )),
        None => router,
    };
    router
        .layer(middleware::from_fn_with_state(metrics, track))
        .layer(cors())
}

#[cfg(test)]
mod tests {
    use axum::extract::Query;
    use axum::http::Uri;

    use super::openapi_document;
    use super::region_api::{MinMaxParams, RegionParams};
    use crate::bricks::{BatchLimits, parse_batch};

    /// A value for each query parameter the OpenAPI document may name.
    fn example(name: &str) -> &'static str {
        match name {
            "level" | "channel" => "0",
            "min" => "0,0,0",
            "max" => "1,1,1",
            "b" => "0,0,0,0,0",
            "encoding" => "raw",
            other => panic!("no example for the documented query parameter '{other}'"),
        }
    }

    /// The query parameters the OpenAPI document gives `path`: name and whether required.
    fn documented(path: &str) -> Vec<(String, bool)> {
        let doc = openapi_document();
        doc["paths"][path]["get"]["parameters"]
            .as_array()
            .expect("parameters")
            .iter()
            .filter(|p| p["in"] == "query")
            .map(|p| {
                let name = p["name"].as_str().expect("a name").to_string();
                (name, p["required"] == true)
            })
            .collect()
    }

    /// The query string of the documented parameters of `path` but `without`.
    fn query(path: &str, without: Option<&str>) -> String {
        documented(path)
            .iter()
            .filter(|(name, _)| Some(name.as_str()) != without)
            .map(|(name, _)| format!("{name}={}", example(name)))
            .collect::<Vec<_>>()
            .join("&")
    }

    /// Whether the documented query of `path` (but `without`) parses as `T`.
    fn parses<T: serde::de::DeserializeOwned>(path: &str, without: Option<&str>) -> bool {
        let uri: Uri = format!("/d/x?{}", query(path, without)).parse().unwrap();
        Query::<T>::try_from_uri(&uri).is_ok()
    }

    /// The OpenAPI document names exactly the query parameters the handlers read, and marks
    /// required exactly those they cannot do without.
    #[test]
    fn documented_query_parameters_are_the_ones_read() {
        fn check<T: serde::de::DeserializeOwned>(path: &str) {
            let params = documented(path);
            assert!(!params.is_empty(), "{path}");
            assert!(parses::<T>(path, None), "{path}: {}", query(path, None));
            for (name, required) in params {
                let ok = parses::<T>(path, Some(&name));
                assert_eq!(ok, !required, "{path} parameter '{name}'");
            }
        }
        check::<RegionParams>("/{name}/regions");
        check::<MinMaxParams>("/{name}/minmax");
        let limits = BatchLimits::default();
        let path = "/{name}/bricks";
        parse_batch(&query(path, None), &limits).expect("the documented batch parses");
        for (name, required) in documented(path) {
            let ok = parse_batch(&query(path, Some(&name)), &limits).is_ok();
            assert_eq!(ok, !required, "{path} parameter '{name}'");
        }
    }
}
