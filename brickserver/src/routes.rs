//! The HTTP routes: Zarr keys under `/NAME/`, the region API (`/NAME/regions`,
//! `/NAME/minmax`, `/NAME/bricks`), the Residency web viewer (`/NAME/view`, `/viewer/FILE`),
//! the dataset listing, health, metrics and the OpenAPI document.
//!
//! Zarr keys are read from the page cache on each request (as nginx does), so nothing is
//! copied twice; the memory cache holds what is costly to make: bricks decoded, or cut out of
//! shards, for batches.
//!
//! The three API paths and `view` never collide with a Zarr key: a Zarr node at a store's
//! root is a folder, so its keys are `regions/zarr.json` and the like, never `regions` itself
//! (a file named `view` at a store's root would be shadowed by the viewer page). `/viewer/`
//! is no dataset's: the name `viewer` is reserved.

use std::fmt::Display;
use std::path::PathBuf;
use std::sync::{Arc, OnceLock};
use std::time::{Duration, Instant};

use axum::Router;
use axum::body::{Body, Bytes};
use axum::extract::rejection::QueryRejection;
use axum::extract::{Path, Query, RawQuery, Request, State};
use axum::http::{HeaderMap, Method, Response, StatusCode, Uri, header};
use axum::middleware::{self, Next};
use axum::response::Redirect;
use axum::response::{IntoResponse, Json};
use axum::routing::get;
use residency_schemas::location::ObjectStoreOptions;
use residency_schemas::location::object_store::GetRange;
use residency_schemas::server::{ApiError, DatasetList};
use residency_schemas::wire::{BRICKS_MAGIC, BRICKS_MEDIA_TYPE, MINMAX_MEDIA_TYPE, encode_framed};
use serde::Deserialize;
use subtle::ConstantTimeEq;
use tower_http::cors::{Any, CorsLayer};

use crate::bricks::{BatchError, BatchLimits, ImageArrays, parse_batch, read_batch};
use crate::cache::{ByteCache, CacheKey, Cached};
use crate::dataset_store::{DatasetStore, Keys, ObjectKeys, OpenError, requested_range};
use crate::datasets::Datasets;
use crate::listing::{self, PublicUrl};
use crate::metrics::{Metrics, track};
use crate::regions::{QueryError, RegionIndex};
use crate::responses::{
    RangeRequest, etag_of, file_response, is_metadata, not_modified, parse_range, part_response,
};
use crate::store_keys::{KeyError, RootDir, checked_key, read_cached};
use crate::viewer_page::ViewerFiles;

/// Server-wide options of the router.
#[derive(Clone, Debug)]
pub struct ServerOptions {
    /// When set, every request but `/healthz` must carry `Authorization: Bearer <token>`.
    pub token: Option<String>,
    /// Memory cache budget in bytes (0: no cache).
    pub cache_bytes: u64,
    /// Caps on batched brick requests.
    pub batch: BatchLimits,
    /// The web viewer's built files (`scripts/build-web.sh`); `None` or a folder without
    /// `index.html` answers `/NAME/view` and `/viewer/...` with 503 and how to build it.
    pub viewer_dir: Option<PathBuf>,
    /// The URL the server is reached at from outside (a reverse proxy's, path prefix
    /// included): every link in the listing is built on it. `None`: from the request's
    /// `X-Forwarded-Proto`/`X-Forwarded-Host`, else its `Host`.
    pub public_url: Option<PublicUrl>,
    /// How to reach datasets in an object store.
    pub object_store: ObjectStoreOptions,
}

impl Default for ServerOptions {
    fn default() -> Self {
        Self {
            token: None,
            cache_bytes: 256 << 20,
            batch: BatchLimits::default(),
            viewer_dir: None,
            public_url: None,
            object_store: ObjectStoreOptions::default(),
        }
    }
}

/// A part of a dataset (its region index or image arrays) that could not be loaded; kept, so
/// every later request is answered the same (500) without trying again.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("dataset '{dataset}': {reason}")]
pub struct LoadError {
    /// The dataset's name.
    pub dataset: String,
    /// Why it could not be loaded, with every cause.
    pub reason: String,
}

/// What is loaded once per dataset, on first use.
#[derive(Default)]
struct Loaded {
    regions: OnceLock<Result<Option<Arc<RegionIndex>>, LoadError>>,
    arrays: OnceLock<Result<Arc<ImageArrays>, LoadError>>,
    /// What the listing says of the store (`None`: its metadata could not be read).
    summary: OnceLock<Option<Arc<listing::StoreSummary>>>,
}

/// Shared state of the routes.
pub struct AppState {
    /// The served datasets.
    pub datasets: Datasets,
    /// The memory cache.
    pub cache: ByteCache,
    /// The metrics.
    pub metrics: Arc<Metrics>,
    batch: BatchLimits,
    viewer: ViewerFiles,
    public_url: Option<PublicUrl>,
    loaded: Vec<Loaded>,
    stores: Vec<DatasetStore>,
    etags: quick_cache::sync::Cache<(usize, String), (Arc<str>, Instant)>,
}

/// How long a remembered chunk `ETag` answers revalidations without a look at the file (as
/// nginx's `open_file_cache_valid`): chunks are immutable, but a store may be replaced.
const ETAG_VALID: Duration = Duration::from_mins(1);

impl AppState {
    /// State for `datasets` under `options`.
    ///
    /// # Errors
    /// [`OpenError`] when a dataset folder cannot be opened or an object-store client cannot
    /// be configured.
    pub fn new(datasets: Datasets, options: &ServerOptions) -> Result<Self, OpenError> {
        let metrics = Arc::new(Metrics::default());
        let cache = ByteCache::new(
            options.cache_bytes,
            metrics.cache_hits.clone(),
            metrics.cache_misses.clone(),
            metrics.cache_bytes.clone(),
        );
        let loaded = datasets.0.iter().map(|_| Loaded::default()).collect();
        let stores = datasets
            .0
            .iter()
            .map(|d| DatasetStore::open(&d.location, &options.object_store))
            .collect::<Result<_, _>>()?;
        Ok(Self {
            datasets,
            cache,
            metrics,
            batch: options.batch,
            viewer: ViewerFiles::new(options.viewer_dir.clone()),
            public_url: options.public_url.clone(),
            loaded,
            stores,
            etags: quick_cache::sync::Cache::new(1 << 16),
        })
    }

    /// The web viewer's files.
    pub fn viewer(&self) -> &ViewerFiles {
        &self.viewer
    }

    fn index_of(&self, name: &str) -> Option<usize> {
        self.datasets.0.iter().position(|d| d.name == name)
    }
}

/// Refuses requests without the configured bearer token (401), except health checks and
/// CORS preflights, which browsers send without credentials.
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
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.strip_prefix("Bearer "));
    // Compare in constant time so the token cannot be guessed byte by byte from timings
    // (only its length can be learnt).
    let ok = given.is_some_and(|g| bool::from(g.as_bytes().ct_eq(token.as_bytes())));
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

/// The router serving `state`'s datasets.
pub fn router(state: Arc<AppState>, options: &ServerOptions) -> Router {
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
        .max_age(Duration::from_hours(24));
    let metrics = state.metrics.clone();
    // Static segments win over captures, so `/{name}/view` wins over `/{name}/{*key}` and
    // `/viewer/...` over both.
    let router = Router::new()
        .route("/viewer", get(|| async { Redirect::permanent("viewer/") }))
        .route("/viewer/", get(viewer_file))
        .route("/viewer/{*file}", get(viewer_file))
        .route("/{name}/view", get(view))
        .route("/metrics", get(show_metrics))
        .route("/openapi.json", get(openapi).options(allowed_methods))
        .route("/", get(home).options(allowed_methods))
        .route("/datasets", get(list).options(allowed_methods))
        .route(
            "/healthz",
            get(|| async { "ok\n" }).options(allowed_methods),
        )
        .route("/{name}/regions", get(regions).options(allowed_methods))
        .route("/{name}/minmax", get(minmax).options(allowed_methods))
        .route("/{name}/bricks", get(bricks).options(allowed_methods))
        .route("/{name}/{*key}", get(serve_key).options(allowed_methods))
        .with_state(state);
    // The token check is a layer only when a token is configured.
    let router = match &options.token {
        Some(token) => router.layer(middleware::from_fn_with_state(
            Arc::new(token.clone()),
            require_token,
        )),
        None => router,
    };
    router
        .layer(middleware::from_fn_with_state(metrics, track))
        .layer(cors)
}

async fn allowed_methods() -> impl IntoResponse {
    (
        StatusCode::NO_CONTENT,
        [(header::ALLOW, "GET, HEAD, OPTIONS")],
    )
}

async fn show_metrics(State(state): State<Arc<AppState>>) -> impl IntoResponse {
    (
        [(
            header::CONTENT_TYPE,
            "application/openmetrics-text; version=1.0.0; charset=utf-8",
        )],
        state.metrics.render(),
    )
}

async fn openapi() -> Json<serde_json::Value> {
    Json(crate::openapi::document())
}

/// `GET /viewer/...`: the web viewer's files.
async fn viewer_file(State(state): State<Arc<AppState>>, request: Request) -> Response<Body> {
    state.viewer.file(request).await
}

/// `GET /NAME/view`: the web viewer's page, 404 (with the page, which says so) for an unknown
/// dataset.
async fn view(State(state): State<Arc<AppState>>, Path(name): Path<String>) -> Response<Body> {
    let status = if state.index_of(&name).is_some() {
        StatusCode::OK
    } else {
        StatusCode::NOT_FOUND
    };
    state.viewer.page("../viewer/", status).await
}

/// The datasets with their links. Each store's summary is read once, on the blocking pool, at
/// the first listing (a store that cannot be summarized is said so once, in the log).
async fn listed(state: &Arc<AppState>, headers: &HeaderMap) -> Vec<listing::Listed> {
    let base = listing::base_url(headers, state.public_url.as_ref());
    let st = state.clone();
    blocking(move || {
        let summaries: Vec<_> = st
            .datasets
            .0
            .iter()
            .zip(&st.loaded)
            .zip(&st.stores)
            .map(|((d, l), store)| {
                l.summary
                    .get_or_init(|| match listing::StoreSummary::read(store) {
                        Ok(s) => {
                            if let Err(e) = &s.level0 {
                                tracing::warn!(
                                    "{}: listed without size, channels or sample type: {e}",
                                    d.name
                                );
                            }
                            Some(Arc::new(s))
                        }
                        Err(e) => {
                            tracing::warn!("{}: not summarized in the listing: {e}", d.name);
                            None
                        }
                    })
                    .clone()
            })
            .collect();
        listing::list(&st.datasets.0, &summaries, &base)
    })
    .await
}

/// `GET /`: the dataset list as an HTML page for a browser (an `Accept` that prefers
/// `text/html`), else as JSON like `/datasets`.
async fn home(State(state): State<Arc<AppState>>, headers: HeaderMap) -> Response<Body> {
    let html = listing::prefers_html(headers.get(header::ACCEPT).and_then(|h| h.to_str().ok()));
    let datasets = listed(&state, &headers).await;
    let vary = [(header::VARY, "Accept")];
    if html {
        let content_type = (header::CONTENT_TYPE, "text/html; charset=utf-8");
        (vary, [content_type], listing::html(&datasets)).into_response()
    } else {
        (vary, Json(listing::json(datasets))).into_response()
    }
}

/// `GET /datasets`: the dataset list as JSON.
async fn list(State(state): State<Arc<AppState>>, headers: HeaderMap) -> Json<DatasetList> {
    Json(listing::json(listed(&state, &headers).await))
}

/// A JSON error answer.
fn api_error(status: StatusCode, error: String) -> Response<Body> {
    if status.is_server_error() {
        tracing::error!("{error}");
    }
    (status, Json(ApiError { error })).into_response()
}

fn no_dataset(name: &str) -> Response<Body> {
    api_error(StatusCode::NOT_FOUND, format!("no dataset '{name}'"))
}

/// A once-loaded part of dataset `i` (`cell` picks which): read directly once loaded, else
/// made by `load` on the blocking pool (the first caller loads, later ones wait for it). A
/// failure keeps the error's message with its causes (`{:#}`).
async fn loaded<T: Clone + Send + Sync + 'static, E: Display + 'static>(
    state: &Arc<AppState>,
    i: usize,
    cell: fn(&Loaded) -> &OnceLock<Result<T, LoadError>>,
    load: fn(&DatasetStore) -> Result<T, E>,
) -> Result<T, LoadError> {
    if let Some(done) = cell(&state.loaded[i]).get() {
        return done.clone();
    }
    let st = state.clone();
    blocking(move || {
        let d = &st.datasets.0[i];
        cell(&st.loaded[i])
            .get_or_init(|| {
                load(&st.stores[i]).map_err(|e| LoadError {
                    dataset: d.name.clone(),
                    reason: format!("{e:#}"),
                })
            })
            .clone()
    })
    .await
}

/// Runs blocking work off the async threads.
async fn blocking<T: Send + 'static>(f: impl FnOnce() -> T + Send + 'static) -> T {
    tokio::task::spawn_blocking(f)
        .await
        .expect("blocking task panicked")
}

async fn serve_key(
    State(state): State<Arc<AppState>>,
    Path((name, _)): Path<(String, String)>,
    uri: Uri,
    headers: HeaderMap,
) -> Response<Body> {
    let Some(index) = state.index_of(&name) else {
        return (StatusCode::NOT_FOUND, format!("no dataset '{name}'\n")).into_response();
    };
    // The raw, still percent-encoded key: everything after "/NAME/".
    let raw_key = uri
        .path()
        .splitn(3, '/')
        .nth(2)
        .unwrap_or_default()
        .to_string();
    // A revalidation of a chunk whose ETag is remembered needs no system call at all.
    let chunk = !is_metadata(&raw_key);
    if chunk && headers.contains_key(header::IF_NONE_MATCH) {
        let known = state.etags.get(&(index, raw_key.clone()));
        if let Some((etag, _)) = known.filter(|(_, seen)| seen.elapsed() < ETAG_VALID)
            && let Some(answer) = not_modified(&raw_key, &etag, &headers)
        {
            return answer;
        }
    }
    let answer = match &state.stores[index].keys {
        Keys::Folder(root) => folder_key(&state, index, root, &raw_key, &headers).await,
        Keys::Object(objects) => object_key(&state, index, objects, &raw_key, &headers).await,
    };
    match answer {
        Ok(response) => response,
        Err(KeyError::NotFound) => (
            StatusCode::NOT_FOUND,
            format!("no key '{raw_key}' in '{name}'\n"),
        )
            .into_response(),
        Err(KeyError::Refused(why)) => {
            (StatusCode::BAD_REQUEST, format!("refused: {why}\n")).into_response()
        }
        Err(KeyError::Unreadable(why)) => {
            let message = format!("cannot read key '{raw_key}' of '{name}': {why}");
            tracing::error!("{message}");
            (StatusCode::INTERNAL_SERVER_ERROR, format!("{message}\n")).into_response()
        }
    }
}

/// Key `raw_key` of dataset `index`, read from its folder `root`.
async fn folder_key(
    state: &AppState,
    index: usize,
    root: &RootDir,
    raw_key: &str,
    headers: &HeaderMap,
) -> Result<Response<Body>, KeyError> {
    // Open beneath the dataset root and read what the page cache holds right here, as nginx
    // does; only a read that would wait for the disk moves to the blocking pool.
    let (file, meta) = root.open_key(raw_key)?;
    let etag = etag_of(&meta);
    if !is_metadata(raw_key) {
        state.etags.insert(
            (index, raw_key.to_string()),
            (etag.as_str().into(), Instant::now()),
        );
    }
    if let Some(answer) = not_modified(raw_key, &etag, headers) {
        return Ok(answer);
    }
    let len = meta.len() as usize;
    let (bytes, whole) = read_cached(&file, len);
    let bytes = if whole {
        bytes
    } else {
        blocking(move || {
            use std::os::unix::fs::FileExt;
            let mut bytes = bytes;
            let done = bytes.len();
            bytes.resize(len, 0);
            file.read_exact_at(&mut bytes[done..], done as u64)
                .map(|()| bytes)
                .map_err(|e| KeyError::Unreadable(e.to_string()))
        })
        .await?
    };
    Ok(file_response(Bytes::from(bytes), &etag, raw_key, headers))
}

/// Key `raw_key` of dataset `index`, read from the object store: a chunk read whole in the last
/// [`ETAG_VALID`] is answered from the memory cache; a `Range` becomes a ranged read, so a
/// shard's index and chunks are read without the rest of the shard.
async fn object_key(
    state: &AppState,
    index: usize,
    objects: &ObjectKeys,
    raw_key: &str,
    headers: &HeaderMap,
) -> Result<Response<Body>, KeyError> {
    let key = checked_key(raw_key)?;
    let chunk = !is_metadata(raw_key);
    let cache_key = CacheKey::Object {
        dataset: index,
        key: raw_key.to_string(),
    };
    if chunk
        && let Some(Cached {
            bytes,
            etag: Some((etag, read)),
        }) = state.cache.get(&cache_key)
        && read.elapsed() < ETAG_VALID
    {
        let answer = not_modified(raw_key, &etag, headers);
        return Ok(answer.unwrap_or_else(|| file_response(bytes, &etag, raw_key, headers)));
    }
    let range_header = headers.get(header::RANGE).and_then(|v| v.to_str().ok());
    let range = range_header.and_then(requested_range);
    let ranged = range.is_some();
    let part = match objects.get(&key, range).await {
        Ok(part) => part,
        Err(KeyError::Unreadable(_)) if let Some(value) = range_header.filter(|_| ranged) => {
            // The store refused the range (past the end, a suffix of nothing): answer as a
            // file of the object's length would be.
            let (len, etag) = objects.head(&key).await?;
            match parse_range(value, len) {
                RangeRequest::Part(start, end) => {
                    objects
                        .get(&key, Some(GetRange::Bounded(start..end)))
                        .await?
                }
                RangeRequest::Whole => objects.get(&key, None).await?,
                unsatisfiable @ RangeRequest::Unsatisfiable => {
                    return Ok(part_response(
                        Bytes::new(),
                        len,
                        unsatisfiable,
                        &etag,
                        raw_key,
                    ));
                }
            }
        }
        Err(e) => return Err(e),
    };
    let tag: Arc<str> = part.etag.as_str().into();
    if chunk {
        state
            .etags
            .insert((index, raw_key.to_string()), (tag.clone(), Instant::now()));
    }
    if let Some(answer) = not_modified(raw_key, &part.etag, headers) {
        return Ok(answer);
    }
    let whole = part.range == (0..part.size);
    if chunk && whole {
        let cached = Cached {
            bytes: part.bytes.clone(),
            etag: Some((tag, Instant::now())),
        };
        state.cache.insert(cache_key, cached);
    }
    let served = if ranged {
        RangeRequest::Part(part.range.start, part.range.end)
    } else {
        RangeRequest::Whole
    };
    Ok(part_response(
        part.bytes, part.size, served, &part.etag, raw_key,
    ))
}

/// Parses `x,y,z`, the value of query parameter `what`.
fn parse_xyz(what: &'static str, text: &str) -> Result<[u64; 3], QueryError> {
    let not_xyz = || QueryError::NotXyz {
        parameter: what,
        text: text.to_string(),
    };
    let v: Vec<u64> = text
        .split(',')
        .map(|s| s.trim().parse::<u64>())
        .collect::<Result<_, _>>()
        .map_err(|_| not_xyz())?;
    v.try_into().map_err(|_| not_xyz())
}

/// Query of `/NAME/regions`.
#[derive(Deserialize)]
struct RegionParams {
    level: usize,
    channel: usize,
    min: String,
    max: String,
}

/// The region index of a dataset, or the error answer.
async fn region_index(
    state: &Arc<AppState>,
    name: &str,
) -> Result<Arc<RegionIndex>, Response<Body>> {
    let index = state.index_of(name).ok_or_else(|| no_dataset(name))?;
    let regions = loaded(
        state,
        index,
        |l| &l.regions,
        |store| RegionIndex::load(store).map(|r| r.map(Arc::new)),
    );
    match regions.await {
        Ok(Some(r)) => Ok(r),
        Ok(None) => Err(api_error(
            StatusCode::NOT_FOUND,
            format!(
                "dataset '{name}' has no region metadata (add it with `ingest index`); \
                 min/max and histograms are unknown"
            ),
        )),
        Err(e) => Err(api_error(StatusCode::INTERNAL_SERVER_ERROR, e.to_string())),
    }
}

/// The parsed query (or a 400 saying what was `expected`) and the dataset's region index.
async fn api_input<T>(
    state: &Arc<AppState>,
    name: &str,
    params: Result<Query<T>, QueryRejection>,
    expected: &str,
) -> Result<(T, Arc<RegionIndex>), Response<Body>> {
    let Query(p) = params.map_err(|e| {
        api_error(
            StatusCode::BAD_REQUEST,
            format!("{}; expected {expected}", e.body_text()),
        )
    })?;
    Ok((p, region_index(state, name).await?))
}

async fn regions(
    State(state): State<Arc<AppState>>,
    Path(name): Path<String>,
    params: Result<Query<RegionParams>, QueryRejection>,
) -> Response<Body> {
    let (p, index) = match api_input(
        &state,
        &name,
        params,
        "level=L&channel=C&min=x,y,z&max=x,y,z",
    )
    .await
    {
        Ok(got) => got,
        Err(r) => return r,
    };
    let bounds = parse_xyz("min", &p.min).and_then(|a| Ok((a, parse_xyz("max", &p.max)?)));
    let (min, max) = match bounds {
        Ok(b) => b,
        Err(e) => return api_error(StatusCode::BAD_REQUEST, e.to_string()),
    };
    match index.query(&name, p.level, p.channel, min, max) {
        Ok(answer) => Json(answer).into_response(),
        Err(e) => api_error(StatusCode::BAD_REQUEST, e.to_string()),
    }
}

/// Query of `/NAME/minmax`.
#[derive(Deserialize)]
struct MinMaxParams {
    channel: usize,
}

async fn minmax(
    State(state): State<Arc<AppState>>,
    Path(name): Path<String>,
    params: Result<Query<MinMaxParams>, QueryRejection>,
) -> Response<Body> {
    let (p, index) = match api_input(&state, &name, params, "channel=C").await {
        Ok(got) => got,
        Err(r) => return r,
    };
    match index.minmax_document(p.channel) {
        Ok(doc) => (
            [
                (header::CONTENT_TYPE, MINMAX_MEDIA_TYPE),
                (header::CACHE_CONTROL, "public, no-cache"),
            ],
            doc,
        )
            .into_response(),
        Err(e) => api_error(StatusCode::BAD_REQUEST, e.to_string()),
    }
}

/// The answer to a refused batch: 413 over a cap, 400 otherwise.
fn batch_error(e: &BatchError) -> Response<Body> {
    let status = if e.is_over_limit() {
        StatusCode::PAYLOAD_TOO_LARGE
    } else {
        StatusCode::BAD_REQUEST
    };
    api_error(status, e.to_string())
}

async fn bricks(
    State(state): State<Arc<AppState>>,
    Path(name): Path<String>,
    RawQuery(query): RawQuery,
) -> Response<Body> {
    let Some(index) = state.index_of(&name) else {
        return no_dataset(&name);
    };
    let (list, encoding) = match parse_batch(query.as_deref().unwrap_or(""), &state.batch) {
        Ok(b) => b,
        Err(e) => return batch_error(&e),
    };
    let arrays = loaded(
        &state,
        index,
        |l| &l.arrays,
        |store| ImageArrays::open(store).map(Arc::new),
    );
    let arrays = match arrays.await {
        Ok(a) => a,
        Err(e) => return api_error(StatusCode::INTERNAL_SERVER_ERROR, e.to_string()),
    };
    if let Err(e) = state.batch.check_bytes(list.len(), arrays.brick_bytes()) {
        return batch_error(&e);
    }
    let st = state.clone();
    let raw = encoding == residency_schemas::wire::BrickEncoding::Raw;
    let body = blocking(move || {
        let (header, payload) = read_batch(&arrays, &list, encoding, |at| {
            let key = CacheKey::Brick {
                dataset: index,
                at: (at.level, at.channel, at.brick),
                raw,
            };
            if let Some(hit) = st.cache.get(&key) {
                return Ok((!hit.bytes.is_empty()).then_some(hit.bytes));
            }
            let read = arrays.read(at, encoding)?;
            let bytes = read.map(Bytes::from).unwrap_or_default();
            let cached = Cached {
                bytes: bytes.clone(),
                etag: None,
            };
            st.cache.insert(key, cached);
            Ok((!bytes.is_empty()).then_some(bytes))
        });
        for e in header.bricks.iter().filter_map(|b| b.error.as_deref()) {
            tracing::error!(dataset = %name, "{e}");
        }
        encode_framed(BRICKS_MAGIC, &header, &payload)
    })
    .await;
    ([(header::CONTENT_TYPE, BRICKS_MEDIA_TYPE)], body).into_response()
}

#[cfg(test)]
mod tests {
    use super::*;

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
        let doc = crate::openapi::document();
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

    #[test]
    fn coordinates_parse_or_say_what_is_wrong() {
        assert_eq!(parse_xyz("min", "1, 2,3"), Ok([1, 2, 3]));
        for text in ["0,0", "0,0,0,0", "a,b,c", "-1,0,0", ""] {
            assert_eq!(
                parse_xyz("max", text).unwrap_err().to_string(),
                format!("max '{text}' is not three integers x,y,z")
            );
        }
    }
}
