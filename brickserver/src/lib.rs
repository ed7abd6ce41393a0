//! `residency-brickserver`: serves OME-Zarr stores written by `ingest` (or anyone) over HTTP,
//! verbatim at their Zarr keys, so any OME-Zarr viewer reads them unchanged.
//!
//! - [`datasets`]: the configured datasets and their names;
//! - [`store_keys`]: turning a request path into a file inside a dataset, safely;
//! - [`dataset_store`]: where a dataset's keys are read from: a folder or an object store;
//! - [`responses`]: file answers with `ETag`, `Range`, `Cache-Control` and `Content-Type`;
//! - `cache`: the bounded memory cache;
//! - `open_files`: chunk files held open between requests, as nginx's `open_file_cache`;
//! - `page_cache`: what the page cache holds of a chunk file, and reading a chunk into it;
//! - `regions`: region queries and the min/max hierarchy, from the stored metadata;
//! - [`bricks`]: batched bricks;
//! - [`metrics`]: Prometheus metrics;
//! - `openapi`: the OpenAPI document's base and the helpers the routes document themselves
//!   with;
//! - [`listing`]: the dataset listing (JSON, or an HTML page) and its links, built on the
//!   server's public URL;
//! - [`neuroglancer`]: the neuroglancer link's viewer state;
//! - [`viewer_page`]: the Residency web viewer's page and files (`/NAME/view`, `/viewer/`);
//! - `routes`: the axum router, one module per API, and the OpenAPI document generated
//!   from it;
//! - [`listener`]: accepting connections, with a connection limit and graceful shutdown;
//! - `http1`: each connection's requests and answers (HTTP/1.1, header timeout), chunk keys
//!   of folder stores answered straight from the connection with `sendfile`.

pub mod bricks;
mod cache;
pub mod dataset_store;
pub mod datasets;
mod http1;
pub mod listener;
pub mod listing;
pub mod metrics;
pub mod neuroglancer;
mod open_files;
mod openapi;
mod page_cache;
mod regions;
pub mod responses;
mod routes;
pub mod store_keys;
pub mod viewer_page;

pub use datasets::{Dataset, Datasets};
pub use http1::App;
pub use listener::{ConnectionLimits, serve, serve_on_threads, shared_port_listeners};
pub use listing::PublicUrl;
pub use routes::{AppState, OPEN_FILES, ServerOptions, openapi_document, router};
