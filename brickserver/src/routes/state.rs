//! The options and shared state of the routes, and what every route module uses to reach a
//! dataset's lazily loaded parts off the async threads.

use std::error::Error;
use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, OnceLock, PoisonError};
use std::time::{Duration, Instant};

use crate::bricks::{BatchLimits, ImageArrays, ImagePyramid};
use crate::cache::ByteCache;
use crate::dataset_store::{DatasetStore, Keys, OpenError};
use crate::datasets::{Dataset, Datasets};
use crate::listing::{PublicUrl, StoreSummary};
use crate::metrics::Metrics;
use crate::open_files::OpenFiles;
use crate::regions::RegionIndex;
use crate::viewer_page::ViewerFiles;
use arc_swap::ArcSwap;
use residency_schemas::ome::OmeError;
use residency_store::pyramid::{Pyramid, PyramidError};

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
    /// How long a dataset's region index or image arrays that could not be loaded are
    /// answered with the same error before the next request tries again (a store that failed
    /// may recover).
    pub load_retry: Duration,
    /// The most chunk files of folder stores held open between requests, as nginx's
    /// `open_file_cache` (0: each request opens its file); lowered to a quarter of the
    /// process's open-file limit.
    pub open_files: usize,
}

impl Default for ServerOptions {
    fn default() -> Self {
        Self {
            token: None,
            cache_bytes: 256 << 20,
            batch: BatchLimits::default(),
            viewer_dir: None,
            public_url: None,
            load_retry: LOAD_RETRY,
            open_files: OPEN_FILES,
        }
    }
}

/// [`ServerOptions::open_files`] by default.
pub const OPEN_FILES: usize = 4096;

/// How long what was learnt of a chunk answers for it before the store is looked at again
/// (as nginx's `open_file_cache_valid`): an object's `ETag` and bytes in memory, and the
/// longest a chunk file is held open. Chunks are immutable, but a store may be replaced.
pub(crate) const REVALIDATE: Duration = Duration::from_mins(1);

/// [`ServerOptions::load_retry`] by default.
pub const LOAD_RETRY: Duration = Duration::from_secs(5);

/// A part of a dataset (its image pyramid, region index or image arrays) that could not be loaded; kept for
/// [`ServerOptions::load_retry`], so the requests meanwhile are answered the same (500, or
/// 502/503 when the object store failed) without trying again.
#[derive(Clone, Debug, thiserror::Error)]
#[error("dataset '{dataset}': {source}")]
pub(crate) struct LoadError {
    /// The dataset's name.
    dataset: String,
    /// Why it could not be loaded (shared: the error is kept, and cloned for each answer).
    source: Arc<dyn Error + Send + Sync>,
    /// When it failed: a part that failed because the image did (the region index, the
    /// arrays) is tried again when the image is, not later.
    at: Instant,
}

/// A part of a dataset loaded on first use: kept once loaded; a failure is kept, and tried
/// again by the first request after [`ServerOptions::load_retry`] from when it happened.
pub(crate) struct LoadCell<T>(Mutex<Option<Result<T, LoadError>>>);

impl<T> Default for LoadCell<T> {
    fn default() -> Self {
        Self(Mutex::new(None))
    }
}

impl<T: Clone> LoadCell<T> {
    /// What is held, unless it is a failure older than `retry` (or nothing is held).
    fn current(
        held: Option<&Result<T, LoadError>>,
        retry: Duration,
    ) -> Option<Result<T, LoadError>> {
        match held {
            Some(Ok(v)) => Some(Ok(v.clone())),
            Some(Err(e)) if e.at.elapsed() < retry => Some(Err(e.clone())),
            _ => None,
        }
    }
}

impl LoadError {
    /// Why dataset `i` of `state` could not be loaded, now: `source`.
    fn new(state: &AppState, i: usize, source: impl Error + Send + Sync + 'static) -> Self {
        Self {
            dataset: state.datasets.0[i].name.clone(),
            source: Arc::new(source),
            at: Instant::now(),
        }
    }

    /// Whether the store is no OME-Zarr image at all (no group metadata, or a group without
    /// multiscales): it then has no region metadata either, rather than a broken pyramid.
    fn is_not_an_image(&self) -> bool {
        matches!(
            self.source.downcast_ref::<PyramidError>(),
            Some(
                PyramidError::NotAnImage { .. }
                    | PyramidError::Ome(
                        OmeError::NotAGroup { .. } | OmeError::NoMultiscales { .. }
                    )
            )
        )
    }
}

/// What is loaded once per dataset, on first use.
#[derive(Default)]
pub(crate) struct Loaded {
    /// The image pyramid (attributes and level arrays), which the region index and the image
    /// arrays share: opened once, so an object store's metadata is read once.
    pub(crate) pyramid: LoadCell<Arc<ImagePyramid>>,
    /// The region index (`None`: the dataset has no region metadata).
    pub(crate) regions: LoadCell<Option<Arc<RegionIndex>>>,
    /// The image arrays, for batched bricks, with the generation of the dataset as served
    /// that they were loaded of ([`Served::generation`]): the bricks a batch caches are kept
    /// under it.
    pub(crate) arrays: LoadCell<(u64, Arc<ImageArrays>)>,
    /// What the listing says of the store (`None`: its metadata could not be read).
    pub(crate) summary: OnceLock<Option<Arc<StoreSummary>>>,
}

/// A dataset as it is served now: where its keys are read from, and what was loaded of it.
pub(crate) struct Served {
    /// Where its keys are read from.
    pub(crate) store: DatasetStore,
    /// What was loaded of it.
    pub(crate) loaded: Loaded,
    /// How many times its folder was opened again (0 at the start): bricks cached are kept
    /// under it, so a batch begun before a replacement cannot cache the old store's bricks
    /// for the new one.
    pub(crate) generation: u64,
}

/// How often, at most, a folder dataset's path is checked for a folder replaced whole.
pub(crate) const REPLACED_CHECK: Duration = Duration::from_secs(1);

/// A dataset as it is served now, opened again when its folder is replaced whole (a new store
/// renamed over the one served, as `ingest convert --overwrite` swaps it into place): the
/// path is checked against the folder held open at most every [`REPLACED_CHECK`], by the
/// request that finds the check due.
pub(crate) struct Current {
    /// The dataset as served now.
    now: ArcSwap<Served>,
    /// When the folder's path was last checked: milliseconds after [`AppState::started`]
    /// (`u64::MAX` for an object store, never checked).
    checked: AtomicU64,
}

impl Current {
    /// `store`, with nothing loaded yet.
    fn new(store: DatasetStore) -> Self {
        let checked = match store.keys {
            Keys::Folder(_) => 0,
            Keys::Object(_) => u64::MAX,
        };
        Self {
            now: ArcSwap::from_pointee(Served {
                store,
                loaded: Loaded::default(),
                generation: 0,
            }),
            checked: AtomicU64::new(checked),
        }
    }

    /// Whether the folder's check is due `now` (milliseconds after the start); the caller
    /// that gets `true` makes it.
    fn check_due(&self, now: u64) -> bool {
        let last = self.checked.load(Ordering::Relaxed);
        last != u64::MAX
            && now.saturating_sub(last) >= REPLACED_CHECK.as_millis() as u64
            && self
                .checked
                .compare_exchange(last, now, Ordering::Relaxed, Ordering::Relaxed)
                .is_ok()
    }

    /// Opens the dataset's folder again if another folder now has its path; whether it did.
    fn reopen_if_replaced(&self, dataset: &Dataset) -> bool {
        let served = self.now.load_full();
        let Keys::Folder(root) = &served.store.keys else {
            return false;
        };
        if !root.replaced() {
            return false;
        }
        match DatasetStore::open(&dataset.location, None) {
            Ok(store) => {
                self.now.store(Arc::new(Served {
                    store,
                    loaded: Loaded::default(),
                    generation: served.generation + 1,
                }));
                tracing::info!(
                    "{}: its folder was replaced; serving the new one",
                    dataset.name
                );
                true
            }
            Err(e) => {
                tracing::warn!(
                    "{}: its folder was replaced, but the new one cannot be opened \
                     (serving the old one): {e}",
                    dataset.name
                );
                false
            }
        }
    }
}

/// Shared state of the routes.
pub struct AppState {
    /// The served datasets.
    pub datasets: Datasets,
    /// The memory cache.
    pub(crate) cache: ByteCache,
    /// The metrics.
    pub metrics: Arc<Metrics>,
    /// Caps on batched brick requests.
    pub(crate) batch: BatchLimits,
    pub(crate) viewer: ViewerFiles,
    pub(crate) public_url: Option<PublicUrl>,
    /// How long a failed load is answered before it is tried again.
    pub(crate) load_retry: Duration,
    /// Each dataset as served now, by dataset index.
    served: Vec<Current>,
    /// When the state was made (the folders' checks count from it).
    started: Instant,
    /// The `ETag` of each chunk key of an object store served, by dataset index and raw key,
    /// with when it was seen.
    pub(crate) etags: quick_cache::sync::Cache<(usize, String), (Arc<str>, Instant)>,
    /// Chunk files of folder stores held open (`None`: each request opens its file).
    pub(crate) open_files: Option<Arc<OpenFiles>>,
}

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
        let served = datasets
            .0
            .iter()
            .map(|d| DatasetStore::open(&d.location, d.object_store.as_ref()).map(Current::new))
            .collect::<Result<_, _>>()?;
        Ok(Self {
            datasets,
            cache,
            metrics,
            batch: options.batch,
            viewer: ViewerFiles::new(options.viewer_dir.clone()),
            public_url: options.public_url.clone(),
            load_retry: options.load_retry,
            served,
            started: Instant::now(),
            etags: quick_cache::sync::Cache::new(1 << 16),
            open_files: OpenFiles::new(options.open_files, REVALIDATE),
        })
    }

    /// The web viewer's files.
    pub fn viewer(&self) -> &ViewerFiles {
        &self.viewer
    }

    /// The index of the dataset called `name`.
    pub(crate) fn index_of(&self, name: &str) -> Option<usize> {
        self.datasets.0.iter().position(|d| d.name == name)
    }

    /// Dataset `i` as served now, for a request's synchronous work. When its folder's check
    /// is due and another folder has its path, the new folder is opened first, and the files
    /// held open and the bricks cached of the old one are let go.
    pub(crate) fn served(&self, i: usize) -> arc_swap::Guard<Arc<Served>> {
        self.served_at(i, Instant::now())
    }

    /// Dataset `i` as served at `now` (a request's start, so that one reading of the clock
    /// serves all of a request's checks), as [`AppState::served`].
    pub(crate) fn served_at(&self, i: usize, now: Instant) -> arc_swap::Guard<Arc<Served>> {
        let current = &self.served[i];
        let since = now.saturating_duration_since(self.started);
        let now = u64::try_from(since.as_millis()).unwrap_or(u64::MAX - 1);
        if current.check_due(now) {
            self.reopen_if_replaced(i);
        }
        current.now.load()
    }

    /// Opens dataset `i`'s folder again now if another folder has its path, letting go of the
    /// files held open and the bricks cached of the old one; whether it did. Called when its
    /// check is due, and for a key not found (which may be a key of the new folder, swapped in
    /// since the last check, the old one already deleted).
    pub(crate) fn reopen_if_replaced(&self, i: usize) -> bool {
        let reopened = self.served[i].reopen_if_replaced(&self.datasets.0[i]);
        if reopened {
            if let Some(files) = &self.open_files {
                files.let_go_dataset(i);
            }
            self.cache.forget_dataset(i);
        }
        reopened
    }

    /// Dataset `i` as served now (see [`AppState::served`]), to hold across waits.
    pub(crate) fn served_owned(&self, i: usize) -> Arc<Served> {
        arc_swap::Guard::into_inner(self.served(i))
    }
}

/// A once-loaded part of dataset `i` (`cell` picks which): read directly once loaded, else
/// made by `load` on the blocking pool (the first caller loads, later ones wait for it). A
/// failure keeps the error, with its causes, for [`ServerOptions::load_retry`]; the first
/// request after that loads again.
pub(crate) async fn loaded<T>(
    state: &Arc<AppState>,
    i: usize,
    cell: fn(&Loaded) -> &LoadCell<T>,
    load: fn(&AppState, usize, &Served) -> Result<T, LoadError>,
) -> Result<T, LoadError>
where
    T: Clone + Send + Sync + 'static,
{
    // The dataset as served now: its cell, and the store a load reads, are of the same one.
    let served = state.served_owned(i);
    // Without waiting: a load in progress holds the lock, and is waited for below.
    if let Ok(held) = cell(&served.loaded).0.try_lock()
        && let Some(done) = LoadCell::current(held.as_ref(), state.load_retry)
    {
        return done;
    }
    let st = state.clone();
    blocking(move || load_now(&st, i, &served, cell, load)).await
}

/// [`loaded`], on the calling (blocking) thread: what `cell` of dataset `i` as `served` holds,
/// or what `load` makes of it.
fn load_now<T: Clone>(
    state: &AppState,
    i: usize,
    served: &Served,
    cell: fn(&Loaded) -> &LoadCell<T>,
    load: impl FnOnce(&AppState, usize, &Served) -> Result<T, LoadError>,
) -> Result<T, LoadError> {
    let mut held = cell(&served.loaded)
        .0
        .lock()
        .unwrap_or_else(PoisonError::into_inner);
    if let Some(done) = LoadCell::current(held.as_ref(), state.load_retry) {
        return done;
    }
    let result = load(state, i, served);
    *held = Some(result.clone());
    result
}

/// Dataset `i`'s image pyramid, as `served`, opened on first use (on the calling, blocking,
/// thread).
///
/// # Errors
/// [`LoadError`] when the store's image metadata cannot be read or is unusable.
fn pyramid_of(state: &AppState, i: usize, served: &Served) -> Result<Arc<ImagePyramid>, LoadError> {
    load_now(
        state,
        i,
        served,
        |l| &l.pyramid,
        |state, i, served| {
            let store = &served.store;
            Pyramid::open(store.zarr(), store.shown())
                .map(Arc::new)
                .map_err(|e| LoadError::new(state, i, e))
        },
    )
}

/// Loads dataset `i`'s image arrays, as `served`, with its generation (see [`loaded`]).
///
/// # Errors
/// [`LoadError`] when its pyramid cannot be opened.
pub(crate) fn load_arrays(
    state: &AppState,
    i: usize,
    served: &Served,
) -> Result<(u64, Arc<ImageArrays>), LoadError> {
    let pyramid = pyramid_of(state, i, served)?;
    let arrays = Arc::new(ImageArrays::new(&served.store, pyramid));
    Ok((served.generation, arrays))
}

/// Loads dataset `i`'s region index, as `served` (see [`loaded`]): `None` for a store
/// without region metadata, or that is no OME-Zarr image.
///
/// # Errors
/// [`LoadError`] when its pyramid or a region array cannot be read.
pub(crate) fn load_regions(
    state: &AppState,
    i: usize,
    served: &Served,
) -> Result<Option<Arc<RegionIndex>>, LoadError> {
    let pyramid = match pyramid_of(state, i, served) {
        Err(e) if e.is_not_an_image() => return Ok(None),
        other => other?,
    };
    RegionIndex::load(&pyramid)
        .map(|r| r.map(Arc::new))
        .map_err(|e| LoadError::new(state, i, e))
}

/// Runs blocking work off the async threads.
pub(crate) async fn blocking<T: Send + 'static>(f: impl FnOnce() -> T + Send + 'static) -> T {
    tokio::task::spawn_blocking(f)
        .await
        .expect("blocking task panicked")
}
