//! `residency-brickserver`: serves OME-Zarr stores written by `ingest` (or anyone) over HTTP,
//! verbatim at their Zarr keys, so any OME-Zarr viewer reads them unchanged.
//!
//! - [`datasets`]: the configured datasets and their names;
//! - [`store_keys`]: turning a request path into a file inside a dataset, safely;
//! - [`responses`]: file answers with `ETag`, `Range`, `Cache-Control` and `Content-Type`;
//! - [`metrics`]: Prometheus metrics;
//! - [`routes`]: the axum router (Zarr keys, dataset listing, health, metrics).

#![warn(missing_docs)]

pub mod datasets;
pub mod metrics;
pub mod responses;
pub mod routes;
pub mod store_keys;

pub use datasets::{Dataset, Datasets};
pub use routes::{ServerOptions, router};
