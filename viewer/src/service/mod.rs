//! The render service behind `viewer serve` (the remote mode): an HTTP server on a machine with
//! a GPU next to the data, answering a page far away with volumetric depth images of the views
//! it asks for (`residency_schemas::vdi`).
//!
//! - `POST /vdi`: a [`VdiRequest`] (the scene, or a camera on the default scene, and the image
//!   size) answered with the encoded VDI (`application/x-residency-vdi`);
//! - `GET /info`: the dataset's [`ServiceInfo`]; `GET /healthz`: `ok`.
//!
//! One worker thread owns the GPU and a live renderer, so resident bricks carry over between
//! requests (the renderer is rebuilt only when the drawn channels, the filter or the image size
//! change). At most one generation runs at a time, and only the latest request waiting for it
//! matters: a newer one supersedes it (409). Errors are JSON `{"error": "..."}` answers
//! ([`ServiceError::status`]); the token check and CORS are brickserver's.

mod rate;
pub mod request;
mod routes;
mod worker;

use std::net::SocketAddr;
use std::sync::Arc;

use axum::http::StatusCode;

pub use crate::vdi_service::{Limits, ServiceInfo, VdiRequest};
pub use request::RequestError;

use crate::gpu::GpuError;
use crate::gpu::device::Gpu;
use crate::gpu::renderer::RenderOptions;
use crate::gpu::streaming::Budget;
use crate::scene::Scene;
use crate::source::BrickSource;

/// How the service runs: where it listens, its token, its limits and how it renders.
#[derive(Clone, Debug)]
pub struct ServiceOptions {
    /// The address to listen on.
    pub bind: SocketAddr,
    /// The bearer token every request but `/healthz` and CORS preflights must carry.
    pub token: Option<String>,
    /// The bounds of a request.
    pub limits: Limits,
    /// The scene drawn when a request gives none, or gives only a camera.
    pub default_scene: Scene,
    /// The renderer's options; width, height and the per-channel level bounds (the first
    /// one's, for every channel of the scene) are set per request.
    pub render: RenderOptions,
    /// The convergence budget of one request.
    pub budget: Budget,
}

/// Why a request got no VDI: each is answered with [`ServiceError::status`] and the error chain
/// as JSON `{"error": "..."}`.
#[derive(Debug, thiserror::Error)]
pub enum ServiceError {
    /// A malformed or refused request (400, or 413 over a limit).
    #[error(transparent)]
    Request(#[from] RequestError),
    /// No bearer token, or the wrong one (401).
    #[error("missing or wrong bearer token")]
    Unauthorized,
    /// Over `--max-requests-per-second` (429).
    #[error("over the limit of {limit} requests per second (--max-requests-per-second)")]
    RateLimited {
        /// The service's limit.
        limit: f64,
    },
    /// A newer request took this one's place before the GPU was free (409).
    #[error("superseded by a newer request")]
    Superseded,
    /// The GPU (or the brick source feeding it) failed (503).
    #[error("cannot generate the VDI")]
    Gpu(#[from] GpuError),
    /// The VDI generated could not be encoded (500).
    #[error("cannot encode the VDI")]
    Encode(#[source] residency_schemas::vdi::VdiError),
    /// The generation panicked (503). The panic's message is kept as text: a panic payload is
    /// no error type.
    #[error("the GPU worker panicked: {0}")]
    Panicked(String),
    /// The worker thread is gone (503).
    #[error("the GPU worker has stopped")]
    WorkerStopped,
}

impl ServiceError {
    /// The HTTP status the error is answered with.
    pub fn status(&self) -> StatusCode {
        match self {
            Self::Request(e) if e.over_limit() => StatusCode::PAYLOAD_TOO_LARGE,
            Self::Request(_) => StatusCode::BAD_REQUEST,
            Self::Unauthorized => StatusCode::UNAUTHORIZED,
            Self::RateLimited { .. } => StatusCode::TOO_MANY_REQUESTS,
            Self::Superseded => StatusCode::CONFLICT,
            Self::Encode(_) => StatusCode::INTERNAL_SERVER_ERROR,
            Self::Gpu(_) | Self::Panicked(_) | Self::WorkerStopped => {
                StatusCode::SERVICE_UNAVAILABLE
            }
        }
    }
}

/// Why the service could not start or stopped.
#[derive(Debug, thiserror::Error)]
pub enum ServeError {
    /// The async runtime could not start.
    #[error("cannot start the async runtime")]
    Runtime(#[source] std::io::Error),
    /// The address is taken or not ours.
    #[error("cannot listen on {addr}")]
    Bind {
        /// The address.
        addr: SocketAddr,
        /// What the system said.
        #[source]
        source: std::io::Error,
    },
    /// The server stopped on an I/O error.
    #[error("the server on {addr} stopped")]
    Serve {
        /// The address.
        addr: SocketAddr,
        /// What the system said.
        #[source]
        source: std::io::Error,
    },
}

/// Serves VDIs of `source`'s views rendered on `gpu`, on `options.bind`, until the process
/// ends. Logs `listening on http://ADDR` (the address bound, its port chosen by the system for
/// port 0) once it accepts connections.
///
/// # Errors
/// [`ServeError`]: the runtime, the address, or the server's I/O.
pub fn serve(
    gpu: Gpu,
    source: Arc<dyn BrickSource>,
    options: ServiceOptions,
) -> Result<(), ServeError> {
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .map_err(ServeError::Runtime)?;
    let bind = options.bind;
    let token = options.token.clone();
    let state = routes::AppState::start(gpu, source, options);
    let router = routes::router(state, token);
    runtime.block_on(async move {
        let listener = tokio::net::TcpListener::bind(bind)
            .await
            .map_err(|source| ServeError::Bind { addr: bind, source })?;
        let addr = listener
            .local_addr()
            .map_err(|source| ServeError::Bind { addr: bind, source })?;
        tracing::info!("listening on http://{addr}");
        axum::serve(listener, router)
            .await
            .map_err(|source| ServeError::Serve { addr, source })
    })
}
