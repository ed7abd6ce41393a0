//! The service's HTTP routes, token check and CORS: `POST /vdi`, `GET /info`, `GET /healthz`.

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use axum::Router;
use axum::body::{Body, Bytes};
use axum::extract::{Request, State};
use axum::http::{HeaderName, HeaderValue, Method, Response, StatusCode, header};
use axum::middleware::{self, Next};
use axum::response::{IntoResponse, Json};
use axum::routing::{get, post};
use residency_schemas::server::{ApiError, bearer_token_matches};
use tower_http::cors::{Any, CorsLayer};
use tower_http::set_header::SetResponseHeaderLayer;

use super::rate::Bucket;
use super::request::{RequestError, ServiceInfo, VdiRequest, check};
use super::worker::{Generated, Job, Latest, Worker};
use super::{ServiceError, ServiceOptions};
use crate::defaults::volume_extent;
use crate::error_chain;
use crate::gpu::device::Gpu;
use crate::source::{BrickSource, VolumeInfo};
use crate::vdi_service::Adapter;

/// The media type of an encoded VDI.
const VDI_MEDIA_TYPE: &str = "application/x-residency-vdi";
/// The header echoing a request's sequence number.
const REQUEST_HEADER: HeaderName = HeaderName::from_static("x-residency-request");
/// The header giving a VDI's generation time in milliseconds.
const GENERATION_HEADER: HeaderName = HeaderName::from_static("x-residency-generation-ms");
/// The header that lets pages on any origin see the network timing of the answers (Resource
/// Timing's `responseStart` and `responseEnd`).
const TIMING_ALLOW_ORIGIN: HeaderName = HeaderName::from_static("timing-allow-origin");

/// What every handler shares: the dataset, the limits, the rate bucket and the worker's queue.
pub(crate) struct AppState {
    info: ServiceInfo,
    volume: VolumeInfo,
    queue: Arc<Latest<Job>>,
    rate: Mutex<Bucket>,
}

impl AppState {
    /// The state of a service of `source` on `gpu`, its worker thread started.
    pub(crate) fn start(
        gpu: Gpu,
        source: Arc<dyn BrickSource>,
        options: ServiceOptions,
    ) -> Arc<Self> {
        let volume = source.info().clone();
        let info = ServiceInfo {
            dataset: volume.name.clone(),
            extent: volume_extent(&volume),
            channels: volume.channels.clone(),
            levels: volume.levels.len(),
            scene: options.default_scene,
            limits: options.limits,
            adapter: Adapter::from(&gpu.adapter_info),
        };
        let queue = Arc::new(Latest::new());
        let worker = Worker::new(gpu, source, options.render, options.budget);
        let jobs = Arc::clone(&queue);
        std::thread::Builder::new()
            .name("vdi-worker".into())
            .spawn(move || worker.run(&jobs))
            .expect("the system starts a thread");
        Arc::new(Self {
            rate: Mutex::new(Bucket::new(info.limits.max_requests_per_second)),
            info,
            volume,
            queue,
        })
    }
}

impl Drop for AppState {
    fn drop(&mut self) {
        // The worker thread ends once the queue is closed; a job still waiting is answered.
        if let Some(job) = self.queue.close() {
            let _ = job.reply.send(Err(ServiceError::WorkerStopped));
        }
    }
}

/// The JSON answer of `error` (logged when it is the service's fault), with the request's
/// sequence number when it had one.
fn error_answer(error: &ServiceError, request: Option<u64>) -> Response<Body> {
    let status = error.status();
    let message = error_chain(error);
    if status.is_server_error() {
        tracing::error!("{message}");
    }
    let mut answer = (status, Json(ApiError { error: message })).into_response();
    if let Some(n) = request {
        answer
            .headers_mut()
            .insert(REQUEST_HEADER, HeaderValue::from(n));
    }
    if status == StatusCode::UNAUTHORIZED {
        answer
            .headers_mut()
            .insert(header::WWW_AUTHENTICATE, HeaderValue::from_static("Bearer"));
    }
    answer
}

/// `POST /vdi`: the VDI of the view asked for, or the JSON error.
async fn vdi(State(state): State<Arc<AppState>>, body: Bytes) -> Response<Body> {
    let refused = {
        let mut rate = state
            .rate
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        (!rate.take(Instant::now())).then(|| rate.retry_after_s())
    };
    if let Some(seconds) = refused {
        let limit = state.info.limits.max_requests_per_second;
        let mut answer = error_answer(&ServiceError::RateLimited { limit }, None);
        answer
            .headers_mut()
            .insert(header::RETRY_AFTER, HeaderValue::from(seconds));
        return answer;
    }
    let request: VdiRequest = match serde_json::from_slice(&body) {
        Ok(r) => r,
        Err(e) => return error_answer(&RequestError::Body(e).into(), None),
    };
    let sequence = request.request;
    let checked = match check(
        request,
        &state.volume,
        &state.info.scene,
        &state.info.limits,
    ) {
        Ok(c) => c,
        Err(e) => return error_answer(&e.into(), sequence),
    };
    let (reply, answer) = futures_channel::oneshot::channel();
    let job = Job {
        request: checked,
        reply,
    };
    if let Some(older) = state.queue.put(job) {
        let _ = older.reply.send(Err(ServiceError::Superseded));
    }
    match answer.await {
        Ok(Ok(generated)) => vdi_answer(generated, sequence),
        Ok(Err(e)) => error_answer(&e, sequence),
        Err(_) => error_answer(&ServiceError::WorkerStopped, sequence),
    }
}

/// The 200 answer carrying a VDI.
fn vdi_answer(generated: Generated, request: Option<u64>) -> Response<Body> {
    let Generated { bytes, elapsed } = generated;
    let mut answer = (
        [(
            header::CONTENT_TYPE,
            HeaderValue::from_static(VDI_MEDIA_TYPE),
        )],
        bytes,
    )
        .into_response();
    let headers = answer.headers_mut();
    if let Some(n) = request {
        headers.insert(REQUEST_HEADER, HeaderValue::from(n));
    }
    let ms = u64::try_from(elapsed.as_millis()).unwrap_or(u64::MAX);
    headers.insert(GENERATION_HEADER, HeaderValue::from(ms));
    answer
}

/// `GET /info`: the dataset, its box, channels, levels, default scene, the limits and the GPU
/// adapter.
async fn info(State(state): State<Arc<AppState>>) -> Json<ServiceInfo> {
    Json(state.info.clone())
}

/// `GET /healthz`.
async fn healthz() -> &'static str {
    "ok"
}

/// Refuses requests without the bearer token `token` (401), but health checks and CORS
/// preflights, which browsers send without credentials (brickserver's rule and comparison).
async fn require_token(
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
        error_answer(&ServiceError::Unauthorized, None)
    }
}

/// The service's router: its routes, the token check when `token` is set, CORS from any
/// origin (exposing the `x-residency-*` headers and `Retry-After`), and `Timing-Allow-Origin:
/// *`, so that a page on another origin sees its answers' network timing (when each body's
/// first and last bytes arrived: how fast the link is, which the page's `auto` compression
/// weighs).
pub(crate) fn router(state: Arc<AppState>, token: Option<String>) -> Router {
    let cors = CorsLayer::new()
        .allow_origin(Any)
        .allow_methods([Method::GET, Method::POST, Method::OPTIONS])
        .allow_headers(Any)
        .expose_headers([
            REQUEST_HEADER,
            GENERATION_HEADER,
            header::CONTENT_LENGTH,
            header::RETRY_AFTER,
        ])
        .max_age(Duration::from_hours(24));
    let router = Router::new()
        .route("/vdi", post(vdi))
        .route("/info", get(info))
        .route("/healthz", get(healthz))
        .with_state(state);
    let router = match token {
        Some(token) => router.layer(middleware::from_fn_with_state(
            Arc::new(token),
            require_token,
        )),
        None => router,
    };
    router.layer(cors).layer(SetResponseHeaderLayer::overriding(
        TIMING_ALLOW_ORIGIN,
        HeaderValue::from_static("*"),
    ))
}
