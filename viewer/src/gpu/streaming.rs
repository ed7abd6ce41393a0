//! Brick streaming and the progressive loop.
//!
//! The policy is shared by every driver: [`StreamState`] turns a frame's requests into the
//! bricks to fetch next (coarse before fine, near before far, only what the cache can take,
//! failed bricks replaced by their coarser brick) and files each arrival into the renderer.
//! Natively, [`Fetcher`] runs worker threads that take batches of keys off a shared queue and
//! call the blocking [`BrickSource::fetch`], so requests overlap; submitting a new request
//! list replaces whatever is still queued (stale requests are cancelled; fetches already under
//! way complete). [`render_progressive`] drives render → read requests → fetch → upload →
//! insert into the octree → repeat, until a frame requests nothing, or the frame or time
//! budget runs out, or the cache cannot take any more bricks without evicting the current
//! view's working set. The web viewer drives the same [`StreamState`] from `fetch` and
//! `requestAnimationFrame`.

#[cfg(not(target_arch = "wasm32"))]
use std::collections::VecDeque;
use std::collections::{HashMap, HashSet};
#[cfg(not(target_arch = "wasm32"))]
use std::sync::{Arc, Condvar, Mutex};
#[cfg(not(target_arch = "wasm32"))]
use std::thread::JoinHandle;
#[cfg(not(target_arch = "wasm32"))]
use std::time::{Duration, Instant};

use schemars::JsonSchema;
use serde::Serialize;

use super::device::Gpu;
use super::error::GpuError;
use super::renderer::{BrickRequest, Renderer, ShaderCounts};
use super::residency::Inserted;
#[cfg(not(target_arch = "wasm32"))]
use super::{method::Method, options::RenderOptions, stop_reason::StopReason};
#[cfg(not(target_arch = "wasm32"))]
use crate::scene::Scene;
#[cfg(not(target_arch = "wasm32"))]
use crate::source::BrickSource;
use crate::source::{BrickKey, BrickVoxels, SourceError, VolumeInfo};

#[cfg(not(target_arch = "wasm32"))]
#[derive(Default)]
struct Queue {
    pending: VecDeque<BrickKey>,
    in_flight: usize,
    done: Vec<(BrickKey, Result<BrickVoxels, SourceError>)>,
    shutdown: bool,
}

#[cfg(not(target_arch = "wasm32"))]
/// A pool of fetch workers over one [`BrickSource`].
pub struct Fetcher {
    shared: Arc<(Mutex<Queue>, Condvar)>,
    workers: Vec<JoinHandle<()>>,
}

#[cfg(not(target_arch = "wasm32"))]
impl Fetcher {
    /// Starts `workers` threads fetching batches of up to `batch` keys from `source`.
    pub fn new(source: Arc<dyn BrickSource>, workers: usize, batch: usize) -> Self {
        let shared = Arc::new((Mutex::new(Queue::default()), Condvar::new()));
        let batch = batch.max(1);
        let workers = (0..workers.max(1))
            .map(|_| {
                let shared = Arc::clone(&shared);
                let source = Arc::clone(&source);
                std::thread::spawn(move || {
                    let (lock, cv) = &*shared;
                    loop {
                        let keys: Vec<BrickKey> = {
                            let mut q = lock.lock().expect("fetch queue");
                            while q.pending.is_empty() && !q.shutdown {
                                q = cv.wait(q).expect("fetch queue");
                            }
                            if q.shutdown {
                                return;
                            }
                            let n = q.pending.len().min(batch);
                            q.in_flight += n;
                            q.pending.drain(..n).collect()
                        };
                        let mut results = source.fetch(&keys);
                        results.resize_with(keys.len(), || Err(SourceError::NoResult));
                        let mut q = lock.lock().expect("fetch queue");
                        q.in_flight -= keys.len();
                        q.done.extend(keys.into_iter().zip(results));
                        cv.notify_all();
                    }
                })
            })
            .collect();
        Self { shared, workers }
    }

    /// Replaces the queued (not yet started) requests with `keys`, in priority order.
    /// Returns how many queued requests were cancelled.
    pub fn submit(&self, keys: Vec<BrickKey>) -> usize {
        let (lock, cv) = &*self.shared;
        let mut q = lock.lock().expect("fetch queue");
        let cancelled = q.pending.iter().filter(|k| !keys.contains(k)).count();
        q.pending = keys.into();
        cv.notify_all();
        cancelled
    }

    /// Waits until nothing is queued or in flight (or `deadline` passes) and returns every
    /// completed fetch.
    pub fn wait(
        &self,
        deadline: Option<Instant>,
    ) -> Vec<(BrickKey, Result<BrickVoxels, SourceError>)> {
        let (lock, cv) = &*self.shared;
        let mut q = lock.lock().expect("fetch queue");
        while !(q.pending.is_empty() && q.in_flight == 0) {
            match deadline {
                Some(d) => {
                    let now = Instant::now();
                    if now >= d {
                        break;
                    }
                    q = cv.wait_timeout(q, d - now).expect("fetch queue").0;
                }
                None => q = cv.wait(q).expect("fetch queue"),
            }
        }
        std::mem::take(&mut q.done)
    }
}

#[cfg(not(target_arch = "wasm32"))]
impl Drop for Fetcher {
    fn drop(&mut self) {
        let (lock, cv) = &*self.shared;
        lock.lock().expect("fetch queue").shutdown = true;
        cv.notify_all();
        for w in self.workers.drain(..) {
            let _ = w.join();
        }
    }
}

#[cfg(not(target_arch = "wasm32"))]
/// Budgets of a progressive render.
#[derive(Clone, Debug, PartialEq)]
pub struct Budget {
    /// Most frames rendered.
    pub max_frames: u32,
    /// Wall-clock limit.
    pub time: Option<Duration>,
    /// Fetch worker threads.
    pub workers: usize,
    /// Keys per [`BrickSource::fetch`] call.
    pub batch: usize,
}

#[cfg(not(target_arch = "wasm32"))]
impl Default for Budget {
    fn default() -> Self {
        Self {
            max_frames: 64,
            time: None,
            workers: 4,
            batch: 16,
        }
    }
}

/// Statistics of one frame (the shader's counters plus what streaming did after it).
#[derive(Clone, Debug, Default, PartialEq, Serialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct FrameStats {
    /// Frame number, from 1.
    #[schemars(range(min = 1))]
    pub frame: u32,
    /// Shader counters.
    #[serde(flatten)]
    pub shader: ShaderCounts,
    /// Bricks fetched successfully after this frame.
    pub bricks_fetched: u64,
    /// Bricks whose fetch or upload failed after this frame (never requested again).
    pub bricks_failed: u64,
    /// Bricks evicted to make room.
    pub bricks_evicted: u64,
    /// Requested bricks not fetched because the cache could not take them this frame.
    pub bricks_deferred: u64,
    /// Queued requests cancelled as stale.
    pub requests_cancelled: u64,
    /// Decoded bytes of the bricks fetched.
    pub bytes_fetched: u64,
    /// GPU time of the ray-casting pass (timestamp queries), `null` when unsupported.
    pub gpu_time_ms: Option<f64>,
    /// Wall time of the frame including fetching and uploading.
    #[schemars(range(min = 0))]
    pub wall_ms: f64,
}

#[cfg(not(target_arch = "wasm32"))]
/// Result of a progressive render.
#[derive(Clone, Debug)]
pub struct Progressive {
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// The last frame's pixels: linear RGBA, row-major from the top.
    pub pixels: Vec<[f32; 4]>,
    /// Per-frame statistics.
    pub frames: Vec<FrameStats>,
    /// Whether the last frame requested nothing (beyond bricks that failed).
    pub converged: bool,
    /// Why the loop stopped.
    pub stop_reason: StopReason,
    /// Every brick requested by the shader, in order of first request.
    pub request_log: Vec<BrickKey>,
    /// Bricks that could not be fetched or uploaded, with the error.
    pub failed: Vec<(BrickKey, String)>,
}

#[cfg(not(target_arch = "wasm32"))]
/// A brick that could not be fetched or uploaded, in the statistics document.
#[derive(Clone, Debug, PartialEq, Serialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct FailedBrick {
    /// Which brick: `level L channel C brick zZ yY xX`.
    pub brick: String,
    /// Why it failed.
    pub error: String,
}

#[cfg(not(target_arch = "wasm32"))]
/// The statistics document of one progressive render, as `viewer render --stats` writes it
/// (`schemas/json/render-stats.schema.json`).
#[derive(Clone, Debug, PartialEq, Serialize, JsonSchema)]
#[schemars(title = "Render statistics", deny_unknown_fields)]
pub struct RenderStats {
    /// The dataset's name.
    pub dataset: String,
    /// How the ray caster found data.
    pub method: Method,
    /// Whether empty space was skipped.
    pub empty_space_skipping: bool,
    /// The GPU adapter's name.
    pub adapter: String,
    /// The graphics backend (`Vulkan`, `Gl`, ...).
    pub backend: String,
    /// Image width.
    #[schemars(range(min = 1))]
    pub width: u32,
    /// Image height.
    #[schemars(range(min = 1))]
    pub height: u32,
    /// Whether the last frame requested nothing (beyond bricks that failed).
    pub converged: bool,
    /// Why the loop stopped.
    pub stop_reason: StopReason,
    /// Wall time of the whole render, seconds.
    #[schemars(range(min = 0))]
    pub wall_s: f64,
    /// Bricks fetched, over all frames.
    pub bricks_fetched: u64,
    /// Decoded bytes fetched, over all frames.
    pub bytes_fetched: u64,
    /// Bricks that could not be fetched or uploaded.
    pub bricks_failed: Vec<FailedBrick>,
    /// Per-frame statistics.
    #[schemars(length(min = 1))]
    pub frames: Vec<FrameStats>,
}

#[cfg(not(target_arch = "wasm32"))]
impl RenderStats {
    /// The statistics of `result`, a render of `dataset` on `gpu` with `method` (and empty
    /// space skipping on or off) that took `wall_s` seconds.
    #[must_use]
    pub fn new(
        dataset: &str,
        gpu: &Gpu,
        (method, empty_space_skipping): (Method, bool),
        result: &Progressive,
        wall_s: f64,
    ) -> Self {
        Self {
            dataset: dataset.to_string(),
            method,
            empty_space_skipping,
            adapter: gpu.adapter_info.name.clone(),
            backend: format!("{:?}", gpu.adapter_info.backend),
            width: result.width,
            height: result.height,
            converged: result.converged,
            stop_reason: result.stop_reason,
            wall_s,
            bricks_fetched: result.frames.iter().map(|f| f.bricks_fetched).sum(),
            bytes_fetched: result.frames.iter().map(|f| f.bytes_fetched).sum(),
            bricks_failed: result
                .failed
                .iter()
                .map(|(k, e)| FailedBrick {
                    brick: format!(
                        "level {} channel {} brick z{} y{} x{}",
                        k.level, k.channel, k.brick[0], k.brick[1], k.brick[2]
                    ),
                    error: e.clone(),
                })
                .collect(),
            frames: result.frames.clone(),
        }
    }
}

/// Decoded size of a brick's samples in bytes (0 for an empty brick).
fn decoded_bytes(v: &BrickVoxels) -> u64 {
    match v {
        BrickVoxels::Empty => 0,
        BrickVoxels::U8(v) => v.len() as u64,
        BrickVoxels::U16(v) => 2 * v.len() as u64,
        BrickVoxels::I16(v) => 2 * v.len() as u64,
        BrickVoxels::U32(v) => 4 * v.len() as u64,
        BrickVoxels::I32(v) => 4 * v.len() as u64,
        BrickVoxels::F32(v) => 4 * v.len() as u64,
    }
}

/// Orders requests coarse before fine, then near before far.
pub fn prioritise(requests: &mut [BrickRequest]) {
    requests.sort_by(|a, b| {
        b.key
            .level
            .cmp(&a.key.level)
            .then(a.distance.total_cmp(&b.distance))
            .then(a.key.cmp(&b.key))
    });
}

#[cfg(not(target_arch = "wasm32"))]
/// Renders `scene` from `source` progressively until converged or out of budget.
///
/// # Errors
/// The renderer's [`GpuError`] when it cannot be set up or a frame fails; bricks that cannot
/// be fetched are not errors (they are counted, and other levels stand in).
pub fn render_progressive(
    gpu: &Gpu,
    source: Arc<dyn BrickSource>,
    scene: &Scene,
    options: RenderOptions,
    budget: &Budget,
) -> Result<Progressive, GpuError> {
    let mut renderer = Renderer::new(gpu, source.info(), scene, options)?;
    let fetcher = Fetcher::new(Arc::clone(&source), budget.workers, budget.batch);
    converge(gpu, &mut renderer, &fetcher, budget)
}

/// Generates the volumetric depth image of `scene` with at most `supersegments` per pixel: a
/// progressive render until the view has converged (or `budget` runs out), then one frame of
/// the VDI pass over what is resident (`Renderer::generate_vdi`). Returns the VDI and the
/// progressive render that led to it.
///
/// # Errors
/// As [`render_progressive`], and the VDI pass's [`GpuError`].
#[cfg(not(target_arch = "wasm32"))]
pub fn generate_vdi(
    gpu: &Gpu,
    source: Arc<dyn BrickSource>,
    scene: &Scene,
    options: RenderOptions,
    budget: &Budget,
    supersegments: u32,
) -> Result<(super::vdi::VdiGeneration, Progressive), GpuError> {
    let mut renderer = Renderer::new(gpu, source.info(), scene, options)?;
    let fetcher = Fetcher::new(Arc::clone(&source), budget.workers, budget.batch);
    let progressive = converge(gpu, &mut renderer, &fetcher, budget)?;
    let (mut generation, _) = renderer.generate_vdi(gpu, supersegments)?;
    generation.image.header.dataset = Some(source.info().name.clone());
    Ok((generation, progressive))
}

/// The brick of the next coarser level covering `key`'s region, if there is one.
pub fn coarser_brick(info: &VolumeInfo, key: &BrickKey) -> Option<BrickKey> {
    let l = key.level as usize;
    let next = info.levels.get(l + 1)?;
    let ratio: [u64; 3] = std::array::from_fn(|a| next.factor[a] / info.levels[l].factor[a].max(1));
    Some(BrickKey {
        level: key.level + 1,
        channel: key.channel,
        brick: std::array::from_fn(|a| key.brick[a] / ratio[a].max(1)),
    })
}

/// Inserts one finished fetch of `key` into `renderer` and counts it in `stats` (fetched,
/// bytes, evicted, deferred; or failed, with a warning). Returns what the insert did and the
/// brick's decoded bytes.
///
/// # Errors
/// The fetch's [`SourceError`] (as [`GpuError::Source`]) or the upload's [`GpuError`].
pub(crate) fn insert_fetched(
    gpu: &Gpu,
    renderer: &mut Renderer,
    key: BrickKey,
    result: Result<BrickVoxels, SourceError>,
    stats: &mut FrameStats,
) -> Result<(Inserted, u64), GpuError> {
    let inserted = result.map_err(GpuError::from).and_then(|voxels| {
        let bytes = decoded_bytes(&voxels);
        renderer.insert(gpu, key, &voxels).map(|i| (i, bytes))
    });
    match &inserted {
        Ok((i, bytes)) => {
            stats.bricks_fetched += 1;
            stats.bytes_fetched += bytes;
            match i {
                Inserted::Uploaded { evicted: Some(_) } => stats.bricks_evicted += 1,
                Inserted::CacheFull => stats.bricks_deferred += 1,
                _ => {}
            }
        }
        Err(e) => {
            tracing::warn!(
                "brick {key:?}: {}; substituting other levels",
                crate::error_chain(e)
            );
            stats.bricks_failed += 1;
        }
    }
    inserted
}

/// What the progressive loop remembers between frames, whatever drives it: bricks that
/// failed (never requested again), the coarser bricks fetched in their place, and every brick
/// the shader requested, in order of first request.
#[derive(Debug, Default)]
pub struct StreamState {
    failed: HashMap<BrickKey, String>,
    fallbacks: Vec<BrickKey>,
    seen: HashSet<BrickKey>,
    request_log: Vec<BrickKey>,
}

impl StreamState {
    /// The bricks still wanted after a frame that asked for `requests`: those neither resident
    /// nor failed, plus the coarser replacements of failed bricks. `None` when nothing is
    /// wanted and no request went over the frame's cap: the view has converged.
    pub fn wanted(
        &mut self,
        renderer: &Renderer,
        requests: Vec<BrickRequest>,
        requests_over_cap: u64,
    ) -> Option<Vec<BrickRequest>> {
        let mut wanted: Vec<BrickRequest> = requests
            .into_iter()
            .filter(|r| !self.failed.contains_key(&r.key) && !renderer.is_resident(&r.key))
            .collect();
        for r in &wanted {
            if self.seen.insert(r.key) {
                self.request_log.push(r.key);
            }
        }
        let failed = &self.failed;
        self.fallbacks
            .retain(|k| !failed.contains_key(k) && !renderer.is_resident(k));
        wanted.extend(
            self.fallbacks
                .drain(..)
                .map(|key| BrickRequest { key, distance: 0.0 }),
        );
        (!wanted.is_empty() || requests_over_cap > 0).then_some(wanted)
    }

    /// The bricks to fetch now, in priority order ([`prioritise`]), as many as the cache can
    /// take without evicting the current view's working set; the rest count as deferred in
    /// `stats`. Empty when the cache can take none.
    pub fn to_fetch(
        renderer: &Renderer,
        mut wanted: Vec<BrickRequest>,
        stats: &mut FrameStats,
    ) -> Vec<BrickKey> {
        prioritise(&mut wanted);
        wanted.dedup_by_key(|r| r.key);
        let room = renderer.insertable();
        stats.bricks_deferred = wanted.len().saturating_sub(room) as u64;
        wanted.truncate(room);
        wanted.into_iter().map(|r| r.key).collect()
    }

    /// Files a finished fetch of `key` (`insert_fetched`) and returns what the insert did
    /// and the brick's decoded bytes; a failure (`None`) is remembered and the next coarser
    /// brick over its region is wanted in its place.
    pub fn arrived(
        &mut self,
        gpu: &Gpu,
        renderer: &mut Renderer,
        key: BrickKey,
        result: Result<BrickVoxels, SourceError>,
        stats: &mut FrameStats,
    ) -> Option<(Inserted, u64)> {
        match insert_fetched(gpu, renderer, key, result, stats) {
            Ok(done) => Some(done),
            Err(e) => {
                self.failed.insert(key, crate::error_chain(&e));
                let info = renderer.info();
                self.fallbacks.extend(coarser_brick(info, &key));
                None
            }
        }
    }

    /// Forgets the coarser replacements wanted for channels not in `channels` (a renderer
    /// drawing other channels); failures are kept.
    pub fn retain_channels(&mut self, channels: &[usize]) {
        self.fallbacks
            .retain(|k| channels.contains(&(k.channel as usize)));
    }

    /// Every brick the shader requested so far, in order of first request.
    pub fn request_log(&self) -> &[BrickKey] {
        &self.request_log
    }

    /// How many bricks could not be fetched or uploaded.
    pub fn failed_count(&self) -> usize {
        self.failed.len()
    }

    /// The bricks that could not be fetched or uploaded, with the error, in key order.
    pub fn failed(&self) -> Vec<(BrickKey, String)> {
        let mut failed: Vec<(BrickKey, String)> =
            self.failed.iter().map(|(k, e)| (*k, e.clone())).collect();
        failed.sort_by_key(|(k, _)| *k);
        failed
    }
}

/// Runs the progressive loop on an existing renderer (its cache and octree carry over, so a
/// new camera reuses what is resident): render, read requests, fetch what the cache can take
/// (coarse before fine, near before far), upload, insert, repeat. A brick that fails to fetch
/// or upload is never requested again; the next coarser brick over its region is fetched in
/// its place so the shader can substitute it.
///
/// # Errors
/// A frame's [`GpuError`]; failed bricks are not errors.
#[cfg(not(target_arch = "wasm32"))]
pub fn converge(
    gpu: &Gpu,
    renderer: &mut Renderer,
    fetcher: &Fetcher,
    budget: &Budget,
) -> Result<Progressive, GpuError> {
    let start = Instant::now();
    let deadline = budget.time.map(|t| start + t);
    let mut state = StreamState::default();
    let mut frames = Vec::new();
    let mut pixels = Vec::new();
    let mut converged = false;
    let mut stop_reason = StopReason::FrameBudget {
        max_frames: budget.max_frames,
    };
    for _ in 0..budget.max_frames.max(1) {
        let frame_start = Instant::now();
        let out = renderer.render(gpu)?;
        pixels = out.pixels;
        let mut stats = FrameStats {
            frame: renderer.frames(),
            shader: out.counts,
            gpu_time_ms: out.gpu_time_ms,
            ..Default::default()
        };
        let wall_ms = |t: Instant| t.elapsed().as_secs_f64() * 1e3;
        let Some(wanted) = state.wanted(renderer, out.requests, stats.shader.requests_over_cap)
        else {
            stats.wall_ms = wall_ms(frame_start);
            frames.push(stats);
            converged = true;
            stop_reason = StopReason::Converged;
            break;
        };
        if deadline.is_some_and(|d| Instant::now() >= d) {
            stats.wall_ms = wall_ms(frame_start);
            frames.push(stats);
            stop_reason = StopReason::TimeBudget;
            break;
        }
        let keys = StreamState::to_fetch(renderer, wanted, &mut stats);
        if keys.is_empty() {
            stats.wall_ms = wall_ms(frame_start);
            frames.push(stats);
            stop_reason = StopReason::CacheFull;
            break;
        }
        stats.requests_cancelled = fetcher.submit(keys) as u64;
        for (key, result) in fetcher.wait(deadline) {
            state.arrived(gpu, renderer, key, result, &mut stats);
        }
        stats.wall_ms = wall_ms(frame_start);
        frames.push(stats);
    }
    Ok(Progressive {
        width: renderer.options().width,
        height: renderer.options().height,
        pixels,
        frames,
        converged,
        stop_reason,
        request_log: state.request_log().to_vec(),
        failed: state.failed(),
    })
}
