//! The renderer benchmark suite (`viewer bench`): the records it writes
//! (`schemas/json/render-bench.schema.json`) and the experiment driver.
//!
//! Every measurement renders the same scene from the same camera path, an orbit of `K` views
//! about the vertical (`y`) axis, in one process on one device. For each view a method first
//! converges (fetches until a frame requests nothing: a warm cache), then `R` further frames
//! are timed: the median GPU time (timestamp queries) and median wall time per converged
//! frame, the bricks the frame read (`bricks_used`, times the slot size: the bytes the cache
//! needs resident), the samples taken, and the error of the converged image against the f64
//! reference of the same view ([`crate::reference`]: PSNR, SSIM, max abs).
//!
//! - [`naive`]: the naive frustum loader of the skipped-work comparison;
//! - [`pareto`]: the Pareto front of time against error;
//! - [`plots`]: PNG plots (plotters); [`report`]: markdown tables.

pub mod naive;
pub mod pareto;
pub mod plots;
pub mod report;

use std::sync::Arc;
use std::time::Instant;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::defaults::CameraSpec;
use crate::gpu::GpuError;
use crate::gpu::device::Gpu;
use crate::gpu::probe::{LimitProbe, ProbeFilter};
use crate::gpu::renderer::{Method, RenderOptions, Renderer};
use crate::gpu::streaming::{Budget, Fetcher, Progressive, converge};
use crate::image::RgbImage;
use crate::metrics::{self, MetricsError};
use crate::octree::OctreeGeometry;
use crate::reference::{self, ReferenceError, ReferenceOptions};
use crate::scene::{Camera, Scene};
use crate::source::{BrickSource, SampleType, VolumeInfo};

/// Format tag of a results file.
pub const FORMAT: &str = "residency-render-bench/1";

/// Why a benchmark stopped: a plan that measures nothing, no device, or a view whose
/// reference, frame or comparison failed. Messages name the dataset, view and configuration
/// at fault; the renderer's, the reference's and the metrics' errors are theirs, unchanged.
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    /// `--views 0`.
    #[error("--views must be at least 1")]
    NoViews,
    /// `--timed-frames 0`.
    #[error("--timed-frames must be at least 1")]
    NoTimedFrames,
    /// The device, a renderer, a frame or the limit probe failed.
    #[error(transparent)]
    Gpu(Box<GpuError>),
    /// Two images could not be compared.
    #[error(transparent)]
    Metrics(#[from] MetricsError),
    /// The reference image of a view could not be rendered.
    #[error("{dataset}: reference of view {view}")]
    Reference {
        /// The dataset.
        dataset: String,
        /// The view, from 1.
        view: usize,
        /// Why.
        #[source]
        source: Box<ReferenceError>,
    },
    /// No frame was timed (a bug: the plan asks for at least one).
    #[error("no frame timed")]
    NoFrameTimed,
    /// A converged frame could not be compared with its reference.
    #[error("{dataset}: view {view} against its reference")]
    Compare {
        /// The dataset.
        dataset: String,
        /// The view, from 0.
        view: usize,
        /// Why.
        #[source]
        source: MetricsError,
    },
    /// A configuration's renderer could not be set up.
    #[error("{dataset}: {label}")]
    Renderer {
        /// The dataset.
        dataset: String,
        /// The configuration.
        label: String,
        /// Why.
        #[source]
        source: Box<GpuError>,
    },
    /// A view of a configuration failed.
    #[error("{dataset}: {experiment} {label}")]
    Run {
        /// The dataset.
        dataset: String,
        /// The experiment.
        experiment: Experiment,
        /// The configuration.
        label: String,
        /// Why.
        #[source]
        source: Box<BenchError>,
    },
    /// A limit-probe frame could not be compared with its reference.
    #[error("{dataset}: probe of view {view}")]
    Probe {
        /// The dataset.
        dataset: String,
        /// The view, from 0.
        view: usize,
        /// Why.
        #[source]
        source: MetricsError,
    },
}

impl From<GpuError> for BenchError {
    fn from(e: GpuError) -> Self {
        Self::Gpu(Box::new(e))
    }
}

/// The machine a result was measured on.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct DeviceInfo {
    /// GPU adapter name (`llvmpipe (LLVM …)` for Mesa's lavapipe).
    pub adapter: String,
    /// wgpu backend.
    pub backend: String,
    /// Driver name and version, as the adapter reports them.
    pub driver: String,
    /// CPU model (`/proc/cpuinfo`).
    pub cpu: String,
    /// Logical cores available to the process.
    pub cores: usize,
    /// Whether GPU times come from timestamp queries (else they are `null`).
    pub timestamps: bool,
}

impl DeviceInfo {
    /// The description of `gpu` and of this machine's CPU.
    pub fn of(gpu: &Gpu) -> Self {
        let cpu = std::fs::read_to_string("/proc/cpuinfo")
            .ok()
            .and_then(|s| {
                s.lines()
                    .find(|l| l.starts_with("model name"))
                    .and_then(|l| l.split_once(':'))
                    .map(|(_, v)| v.trim().to_string())
            })
            .unwrap_or_else(|| std::env::consts::ARCH.to_string());
        let info = &gpu.adapter_info;
        Self {
            adapter: info.name.clone(),
            backend: format!("{:?}", info.backend),
            driver: format!("{} {}", info.driver, info.driver_info)
                .trim()
                .to_string(),
            cpu,
            cores: std::thread::available_parallelism().map_or(1, std::num::NonZero::get),
            timestamps: gpu.timestamps,
        }
    }
}

/// The dataset measured.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct DatasetInfo {
    /// Label given on the command line (e.g. `sparse 128³`), else the dataset name.
    pub label: String,
    /// Kind of data (`sparse`, `dense`, `cycif`, `fluorescence`, …), as given.
    pub kind: String,
    /// Dataset name from the store.
    pub name: String,
    /// Stored sample format, serialized as its Zarr v3 name (`uint16`, …).
    pub sample_type: SampleType,
    /// Level-0 shape `z, y, x`.
    pub shape: [u64; 3],
    /// Brick shape `z, y, x`.
    pub brick_shape: [u64; 3],
    /// Pyramid levels.
    pub levels: usize,
    /// Channels in the store.
    pub channels: usize,
    /// Channels rendered (visible in the scene).
    pub visible_channels: usize,
    /// Level-0 voxels per channel.
    pub voxels: u64,
}

impl DatasetInfo {
    fn of(info: &VolumeInfo, scene: &Scene, label: Option<&str>, kind: &str) -> Self {
        Self {
            label: label.map_or_else(|| info.name.clone(), str::to_string),
            kind: kind.to_string(),
            name: info.name.clone(),
            sample_type: info.sample_type,
            shape: info.levels[0].shape,
            brick_shape: info.brick_shape,
            levels: info.levels.len(),
            channels: info.channels.len(),
            visible_channels: scene.channels.iter().filter(|c| c.visible).count(),
            voxels: info.levels[0].shape.iter().product(),
        }
    }
}

/// How the suite ran.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Settings {
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Views of the orbit.
    pub views: usize,
    /// Frames timed per view after convergence.
    pub timed_frames: usize,
    /// Most frames to converge one view.
    pub max_frames: u32,
    /// Orbit elevation, degrees.
    pub elevation: f64,
    /// Orbit distance, volume diagonals.
    pub distance: f64,
    /// Azimuth of the first view, degrees (the others follow at equal steps around 360°).
    pub first_azimuth: f64,
    /// Reference step as a fraction of the finest level-0 voxel.
    pub reference_step: f64,
    /// Seconds spent computing the reference images.
    pub reference_s: f64,
}

/// The renderer options of one run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct OptionsRecord {
    /// Step as a fraction of the voxel of the level in use.
    pub step: f64,
    /// LOD bias.
    pub lod_bias: f64,
    /// Cache budget asked for, bytes.
    pub cache_bytes: u64,
    /// Cache capacity obtained, bytes (slots × slot bytes).
    pub cache_capacity_bytes: u64,
    /// Leaf target in level-0 voxels (when the depth is not given).
    pub leaf_voxels: u64,
    /// Octree leaf depth in use.
    pub octree_depth: u32,
    /// Leaf edge in level-0 voxels along the longest axis.
    pub leaf_edge: f64,
    /// Empty-space skipping on.
    pub skipping: bool,
    /// Substitution of missing bricks on.
    pub substitution: bool,
}

/// One view of one run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct ViewRecord {
    /// Camera azimuth, degrees.
    pub azimuth: f64,
    /// Whether the view converged (a frame requested nothing).
    pub converged: bool,
    /// Why converging stopped.
    pub stop_reason: String,
    /// Frames rendered to converge.
    pub frames_to_converge: usize,
    /// Bricks fetched while converging this view (after the previous views).
    pub bricks_fetched: u64,
    /// Decoded bytes fetched while converging this view.
    pub bytes_fetched: u64,
    /// Distinct bricks the shader requested while converging this view.
    pub bricks_requested: u64,
    /// Of those, bricks transparent under the transfer function (by their conservative range).
    pub requested_empty: u64,
    /// Median GPU ms per converged frame (`null` without timestamp queries).
    pub gpu_ms: Option<f64>,
    /// Median wall ms per converged frame (render, read back).
    pub wall_ms: f64,
    /// Distinct cache slots the converged frame read.
    pub bricks_used: u64,
    /// `bricks_used` × slot bytes.
    pub resident_bytes: u64,
    /// Samples per converged frame.
    pub samples: u64,
    /// Boxes the converged frame rasterised into ray segment lists (SparseLeap, rasterize;
    /// 0 for the other methods).
    pub segment_boxes: u64,
    /// PSNR against the reference, dB (`null`: identical).
    pub psnr_db: Option<f64>,
    /// SSIM against the reference.
    pub ssim: f64,
    /// Max abs error against the reference.
    pub max_abs_error: f64,
}

/// A parameter a sweep varies, named in results files as `default`, `step`, `lod_bias`,
/// `cache_fraction` or `leaf_voxels`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum SweptParameter {
    /// None: the run with the default options (value 0).
    Default,
    /// The step factor.
    Step,
    /// The LOD bias.
    LodBias,
    /// The cache budget, as a fraction of the default run's working set.
    CacheFraction,
    /// The octree leaf target, level-0 voxels.
    LeafVoxels,
}

impl SweptParameter {
    /// The parameters actually swept (all but [`Self::Default`]), in the order a sweep runs.
    pub const SWEPT: [Self; 4] = [
        Self::Step,
        Self::LodBias,
        Self::CacheFraction,
        Self::LeafVoxels,
    ];

    /// The name in results files.
    pub fn name(self) -> &'static str {
        match self {
            Self::Default => "default",
            Self::Step => "step",
            Self::LodBias => "lod_bias",
            Self::CacheFraction => "cache_fraction",
            Self::LeafVoxels => "leaf_voxels",
        }
    }
}

impl std::fmt::Display for SweptParameter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// A swept parameter and its value.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct SweepParam {
    /// The parameter ([`SweptParameter::Default`] for the defaults).
    pub name: SweptParameter,
    /// The value.
    pub value: f64,
}

/// One configuration measured over the whole orbit.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct RunRecord {
    /// [`Experiment::Table1`], [`Experiment::Sweep`] or [`Experiment::Scaling`].
    pub experiment: Experiment,
    /// Short label (`residency`, `step 0.25`, …).
    pub label: String,
    /// Traversal method, serialized as its name (`residency`, `page-table`, `octree`).
    pub method: Method,
    /// Rendered channels.
    pub channels: usize,
    /// The swept parameter, for sweep runs.
    pub sweep: Option<SweepParam>,
    /// Whether every option equals the renderer's default.
    pub is_default: bool,
    /// The options.
    pub options: OptionsRecord,
    /// Views that converged.
    pub converged_views: usize,
    /// Mean over views of the median GPU ms per converged frame.
    pub gpu_ms: Option<f64>,
    /// Mean over views of the median wall ms per converged frame.
    pub wall_ms: f64,
    /// Mean over views of the bytes the cache needs resident.
    pub resident_bytes: f64,
    /// Mean over views of the bricks the frame read.
    pub bricks_used: f64,
    /// Bytes fetched to converge the first view from a cold cache.
    pub cold_bytes_fetched: u64,
    /// Bytes fetched over the whole orbit.
    pub bytes_fetched: u64,
    /// Bricks fetched over the whole orbit.
    pub bricks_fetched: u64,
    /// Mean samples per converged frame.
    pub samples: f64,
    /// Mean PSNR over views, dB (`null` if every view was identical to the reference).
    pub psnr_db: Option<f64>,
    /// Mean SSIM over views.
    pub ssim: f64,
    /// Largest max abs error over views.
    pub max_abs_error: f64,
    /// Per view.
    pub views: Vec<ViewRecord>,
}

/// Skipped work for one view: the naive frustum loader against ours, each from a cold cache.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct SkippedRecord {
    /// Camera azimuth, degrees.
    pub azimuth: f64,
    /// Level the naive loader picks (LOD rule at the volume centre's distance).
    pub naive_level: u32,
    /// Bricks of that level in the frustum, over the visible channels.
    pub naive_bricks: u64,
    /// Of those, bricks holding only the fill value (no chunk stored; nothing to transfer).
    pub naive_fill_bricks: u64,
    /// Of those, bricks transparent under the transfer function (fill bricks included).
    pub naive_empty_bricks: u64,
    /// Decoded bytes of the naive loader's non-fill bricks.
    pub naive_bytes: u64,
    /// Samples of a ray caster without skipping, pinned to the naive level.
    pub naive_samples: u64,
    /// PSNR of that render against the reference (`null`: identical).
    pub naive_psnr_db: Option<f64>,
    /// SSIM of that render.
    pub naive_ssim: f64,
    /// Bricks ours fetched from a cold cache to convergence.
    pub ours_bricks_fetched: u64,
    /// Decoded bytes ours fetched.
    pub ours_bytes_fetched: u64,
    /// Distinct bricks ours requested.
    pub ours_bricks_requested: u64,
    /// Of those, bricks transparent under the transfer function.
    pub ours_requested_empty: u64,
    /// Samples of our converged frame.
    pub ours_samples: u64,
    /// PSNR of our converged frame (`null`: identical).
    pub ours_psnr_db: Option<f64>,
    /// SSIM of our converged frame.
    pub ours_ssim: f64,
    /// `naive_bytes / ours_bytes_fetched` (`null` when ours fetched nothing).
    pub bytes_ratio: Option<f64>,
    /// Bricks holding data that our converged frame read (its distinct cache slots, with every
    /// brick of a sample's footprint looked up rather than read from an apron): what any
    /// loader must deliver to draw this image, whatever it skips.
    pub ours_bricks_read: u64,
    /// `naive_bytes / (ours_bricks_read × brick bytes)`: the most bytes any loader that
    /// delivers the bricks this image reads can save against the naive one (`null` when the
    /// image reads no brick).
    pub bytes_ceiling: Option<f64>,
}

/// The limit probe with one filter over the orbit (`gpu::probe`): the same rays and step as
/// the renderer at level 0, through one resident texture, no traversal.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct ProbeRecord {
    /// `manual` (8 texel loads, as the renderer) or `hardware` (the texture unit filters).
    pub filter: ProbeFilter,
    /// Samples per frame (each of every drawn channel), mean over views.
    pub samples: f64,
    /// GPU ms per frame, mean over views of the median per view (`null`: no timestamps).
    pub gpu_ms: Option<f64>,
    /// Wall ms per frame (submit to readback), mean over views of the median per view.
    pub wall_ms: f64,
    /// `samples / time` per second, GPU time where there is one.
    pub samples_per_s: f64,
    /// PSNR of the probe's image against the reference, mean over views (`null`: identical).
    pub psnr_db: Option<f64>,
}

/// A results file: one dataset, one device, any experiments.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct BenchResults {
    /// [`FORMAT`].
    pub format: String,
    /// When it ran (seconds since the Unix epoch).
    pub unix_time: u64,
    /// The device.
    pub device: DeviceInfo,
    /// The dataset.
    pub dataset: DatasetInfo,
    /// Settings.
    pub settings: Settings,
    /// Experiments run, in order.
    pub experiments: Vec<Experiment>,
    /// Runs of `table1`, `sweep` and `scaling`.
    pub runs: Vec<RunRecord>,
    /// Views of `skipped`.
    pub skipped: Vec<SkippedRecord>,
    /// The limit probe, run with `table1`, one record per filter the device has.
    #[serde(default)]
    pub probe: Vec<ProbeRecord>,
    /// Why the probe did not run with `table1` (say, a volume over one 3D texture), if so.
    #[serde(default)]
    pub probe_error: Option<String>,
}

/// An experiment of `viewer bench run`, named `table1`, `sweep`, `skipped` or `scaling` on the
/// command line and in results files.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum Experiment {
    /// Table 1 of the paper: every method, GPU and wall ms per converged frame, resident bytes.
    Table1,
    /// Time against error: step, LOD bias, cache budget and leaf size, one at a time.
    Sweep,
    /// Skipped work against a naive frustum loader.
    Skipped,
    /// One residency run (frame time, resident and fetched bytes) for the scaling plots.
    Scaling,
}

impl Experiment {
    /// Every experiment, in the order `viewer bench run` lists them.
    pub const ALL: [Self; 4] = [Self::Table1, Self::Sweep, Self::Skipped, Self::Scaling];

    /// The name in results files.
    pub fn name(self) -> &'static str {
        match self {
            Self::Table1 => "table1",
            Self::Sweep => "sweep",
            Self::Skipped => "skipped",
            Self::Scaling => "scaling",
        }
    }
}

/// An experiment name that is not one of [`Experiment::ALL`]'s.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("unknown experiment '{name}' (table1, sweep, skipped or scaling)")]
pub struct UnknownExperiment {
    /// The name given.
    pub name: String,
}

impl std::str::FromStr for Experiment {
    type Err = UnknownExperiment;

    fn from_str(s: &str) -> Result<Self, UnknownExperiment> {
        Self::ALL
            .into_iter()
            .find(|e| e.name() == s)
            .ok_or_else(|| UnknownExperiment {
                name: s.to_string(),
            })
    }
}

impl std::fmt::Display for Experiment {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// The values a sweep visits.
#[derive(Clone, Debug, PartialEq)]
pub struct SweepValues {
    /// Step factors.
    pub steps: Vec<f32>,
    /// LOD biases.
    pub lod_biases: Vec<f32>,
    /// Cache budgets as fractions of the default run's working set (largest `bricks_used`).
    pub cache_fractions: Vec<f64>,
    /// Leaf targets in level-0 voxels.
    pub leaf_voxels: Vec<u64>,
    /// Other methods swept too, each at its defaults and over `steps` and `lod_biases`, so
    /// that the time–error front holds every renderer, not only ours.
    pub methods: Vec<Method>,
}

/// What to measure and how.
#[derive(Clone, Debug)]
pub struct Plan {
    /// Experiments, in order.
    pub experiments: Vec<Experiment>,
    /// Dataset label.
    pub label: Option<String>,
    /// Dataset kind.
    pub kind: String,
    /// Views of the orbit.
    pub views: usize,
    /// Frames timed per view.
    pub timed_frames: usize,
    /// Most frames to converge a view.
    pub max_frames: u32,
    /// Orbit elevation, degrees.
    pub elevation: f64,
    /// Orbit distance, volume diagonals.
    pub distance: f64,
    /// First azimuth, degrees.
    pub first_azimuth: f64,
    /// Reference step fraction.
    pub reference_step: f64,
    /// Fetch workers.
    pub workers: usize,
    /// Table-1 configurations: `(method, skipping)`.
    pub methods: Vec<(Method, bool)>,
    /// Sweep values.
    pub sweep: SweepValues,
    /// Show a progress bar.
    pub progress: bool,
}

/// The label of a method configuration.
pub fn method_label(method: Method, skipping: bool) -> String {
    if skipping {
        method.name().to_string()
    } else {
        format!("{} (no skipping)", method.name())
    }
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n == 0 {
        f64::NAN
    } else if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

fn finite_psnr(m: &metrics::Metrics) -> Option<f64> {
    m.psnr_db.is_finite().then_some(m.psnr_db)
}

fn to_image(width: u32, height: u32, pixels: &[[f32; 4]]) -> RgbImage {
    RgbImage {
        width: width as usize,
        height: height as usize,
        pixels: pixels.iter().map(|p| [p[0], p[1], p[2]]).collect(),
    }
}

/// The driver: one source, scene, device, orbit and set of reference images.
pub struct Bench {
    gpu: Gpu,
    /// A second device for the methods that rasterise ray segment lists. On lavapipe, once a
    /// render pass has run on a device, every later compute pass's timestamps on it come out
    /// nearly equal (measured: the residency renderer's GPU time fell from 5.5 ms to 0.006 ms
    /// after a SparseLeap renderer had run, its wall time unchanged), so those methods get a
    /// device of their own and the others keep honest GPU times.
    raster_gpu: std::sync::OnceLock<Gpu>,
    source: Arc<dyn BrickSource>,
    scene: Scene,
    base: RenderOptions,
    plan: Plan,
    cameras: Vec<(f64, Camera)>,
    references: Vec<RgbImage>,
    reference_s: f64,
    bar: indicatif::ProgressBar,
}

impl Bench {
    /// Opens the device, lays out the orbit and renders the reference of every view.
    ///
    /// # Errors
    /// [`BenchError::NoViews`] or [`BenchError::NoTimedFrames`] for a plan that measures
    /// nothing, the device's [`GpuError`], or [`BenchError::Reference`] naming the view whose
    /// reference failed.
    pub fn new(
        source: Arc<dyn BrickSource>,
        scene: Scene,
        base: RenderOptions,
        plan: Plan,
    ) -> Result<Self, BenchError> {
        if plan.views == 0 {
            return Err(BenchError::NoViews);
        }
        if plan.timed_frames == 0 {
            return Err(BenchError::NoTimedFrames);
        }
        let gpu = Gpu::new()?;
        let info = source.info().clone();
        let fov = scene.camera.fov_y_degrees;
        let cameras: Vec<(f64, Camera)> = (0..plan.views)
            .map(|k| {
                let azimuth = plan.first_azimuth + 360.0 * k as f64 / plan.views as f64;
                let spec = CameraSpec::Orbit {
                    azimuth,
                    elevation: plan.elevation,
                    distance: plan.distance,
                };
                (azimuth, spec.camera(&info, fov))
            })
            .collect();
        let bar = if plan.progress {
            let bar = indicatif::ProgressBar::new(0);
            bar.set_style(
                indicatif::ProgressStyle::with_template(
                    "{prefix} [{elapsed_precise}] {wide_bar} {pos}/{len} views, ETA {eta} {msg}",
                )
                .expect("progress template"),
            );
            bar.set_prefix(info.name.clone());
            bar
        } else {
            indicatif::ProgressBar::hidden()
        };
        let start = Instant::now();
        let mut references = Vec::new();
        for (k, (_, cam)) in cameras.iter().enumerate() {
            bar.set_message(format!("reference of view {}", k + 1));
            let mut s = scene.clone();
            s.camera = cam.clone();
            let options = ReferenceOptions {
                width: base.width as usize,
                height: base.height as usize,
                step_fraction: plan.reference_step,
                min_transmittance: 0.0,
            };
            references.push(reference::render(source.as_ref(), &s, &options).map_err(
                |source| BenchError::Reference {
                    dataset: info.name.clone(),
                    view: k + 1,
                    source: Box::new(source),
                },
            )?);
        }
        let reference_s = start.elapsed().as_secs_f64();
        tracing::info!(
            "{}: {} reference images in {reference_s:.1} s",
            info.name,
            references.len()
        );
        Ok(Self {
            gpu,
            raster_gpu: std::sync::OnceLock::new(),
            source,
            scene,
            base,
            plan,
            cameras,
            references,
            reference_s,
            bar,
        })
    }

    fn info(&self) -> &VolumeInfo {
        self.source.info()
    }

    fn budget(&self) -> Budget {
        Budget {
            max_frames: self.plan.max_frames,
            time: None,
            workers: self.plan.workers,
            ..Default::default()
        }
    }

    fn options_record(options: &RenderOptions, renderer: &Renderer) -> OptionsRecord {
        let g = renderer.octree().geometry();
        let longest = (0..3).max_by_key(|&a| g.volume_voxels[a]).unwrap_or(0);
        OptionsRecord {
            step: options.step_factor as f64,
            lod_bias: options.lod_bias as f64,
            cache_bytes: options.cache_bytes,
            cache_capacity_bytes: renderer.cache().capacity() as u64
                * renderer.cache().slot_bytes(),
            leaf_voxels: options.leaf_voxels,
            octree_depth: g.depth,
            leaf_edge: (g.leaf_shift[longest] as f64).exp2(),
            skipping: options.empty_space_skipping,
            substitution: options.substitution,
        }
    }

    fn requested_empty(&self, p: &Progressive) -> u64 {
        p.request_log
            .iter()
            .filter(|k| naive::transparent(self.info(), &self.scene, k))
            .count() as u64
    }

    /// The device the renderers of `method` run on (see `raster_gpu`).
    fn device_for(&self, method: Method) -> Result<&Gpu, GpuError> {
        if !method.uses_segment_lists() {
            return Ok(&self.gpu);
        }
        if let Some(gpu) = self.raster_gpu.get() {
            return Ok(gpu);
        }
        let gpu = Gpu::new()?;
        Ok(self.raster_gpu.get_or_init(|| gpu))
    }

    /// Converges `renderer` on view `k`, times the converged frames and compares the image.
    fn measure_view(
        &self,
        renderer: &mut Renderer,
        fetcher: &Fetcher,
        k: usize,
    ) -> Result<ViewRecord, BenchError> {
        let (azimuth, cam) = &self.cameras[k];
        renderer.set_camera(cam.clone());
        let gpu = self.device_for(renderer.options().method)?;
        let p = converge(gpu, renderer, fetcher, &self.budget())?;
        let mut gpu_ms = Vec::new();
        let mut wall_ms = Vec::new();
        let mut last = None;
        for _ in 0..self.plan.timed_frames {
            let t = Instant::now();
            let out = renderer.render(gpu)?;
            wall_ms.push(t.elapsed().as_secs_f64() * 1e3);
            if let Some(g) = out.gpu_time_ms {
                gpu_ms.push(g);
            }
            last = Some(out);
        }
        let out = last.ok_or(BenchError::NoFrameTimed)?;
        let o = renderer.options();
        let image = to_image(o.width, o.height, &out.pixels);
        let m = metrics::compare(&image, &self.references[k]).map_err(|source| {
            BenchError::Compare {
                dataset: self.info().name.clone(),
                view: k,
                source,
            }
        })?;
        let slot = renderer.cache().slot_bytes();
        self.bar.inc(1);
        Ok(ViewRecord {
            azimuth: *azimuth,
            converged: p.converged,
            stop_reason: p.stop_reason.clone(),
            frames_to_converge: p.frames.len(),
            bricks_fetched: p.frames.iter().map(|f| f.bricks_fetched).sum(),
            bytes_fetched: p.frames.iter().map(|f| f.bytes_fetched).sum(),
            bricks_requested: p.request_log.len() as u64,
            requested_empty: self.requested_empty(&p),
            gpu_ms: (!gpu_ms.is_empty()).then(|| median(&mut gpu_ms)),
            wall_ms: median(&mut wall_ms),
            bricks_used: out.counts.bricks_used,
            resident_bytes: out.counts.bricks_used * slot,
            samples: out.counts.samples,
            segment_boxes: out.counts.segment_boxes,
            psnr_db: finite_psnr(&m),
            ssim: m.ssim,
            max_abs_error: m.max_abs_error,
        })
    }

    /// Measures one configuration over the orbit with one renderer (cold at the first view,
    /// warm after).
    ///
    /// # Errors
    /// [`BenchError::Renderer`] naming the configuration when its renderer cannot be set up,
    /// [`BenchError::Run`] naming the experiment and configuration when a view fails.
    pub fn run(
        &self,
        experiment: Experiment,
        label: String,
        options: RenderOptions,
        sweep: Option<SweepParam>,
    ) -> Result<RunRecord, BenchError> {
        self.bar.set_message(format!("{experiment}: {label}"));
        let mut renderer = self
            .device_for(options.method)
            .and_then(|gpu| Renderer::new(gpu, self.info(), &self.scene, options.clone()))
            .map_err(|source| BenchError::Renderer {
                dataset: self.info().name.clone(),
                label: label.clone(),
                source: Box::new(source),
            })?;
        let fetcher = Fetcher::new(Arc::clone(&self.source), self.plan.workers, 16);
        let record = Self::options_record(&options, &renderer);
        let views = (0..self.cameras.len())
            .map(|k| self.measure_view(&mut renderer, &fetcher, k))
            .collect::<Result<Vec<_>, BenchError>>()
            .map_err(|source| BenchError::Run {
                dataset: self.info().name.clone(),
                experiment,
                label: label.clone(),
                source: Box::new(source),
            })?;
        let n = views.len() as f64;
        let mean = |f: &dyn Fn(&ViewRecord) -> f64| views.iter().map(f).sum::<f64>() / n;
        let gpu: Vec<f64> = views.iter().filter_map(|v| v.gpu_ms).collect();
        let psnr: Vec<f64> = views.iter().filter_map(|v| v.psnr_db).collect();
        let defaults = RenderOptions {
            width: options.width,
            height: options.height,
            level_bounds: options.level_bounds.clone(),
            cache_bytes: self.base.cache_bytes,
            ..Default::default()
        };
        let is_default = options == defaults;
        Ok(RunRecord {
            experiment,
            label,
            method: options.method,
            channels: self.scene.channels.iter().filter(|c| c.visible).count(),
            sweep,
            is_default,
            options: record,
            converged_views: views.iter().filter(|v| v.converged).count(),
            gpu_ms: (gpu.len() == views.len()).then(|| gpu.iter().sum::<f64>() / n),
            wall_ms: mean(&|v| v.wall_ms),
            resident_bytes: mean(&|v| v.resident_bytes as f64),
            bricks_used: mean(&|v| v.bricks_used as f64),
            cold_bytes_fetched: views[0].bytes_fetched,
            bytes_fetched: views.iter().map(|v| v.bytes_fetched).sum(),
            bricks_fetched: views.iter().map(|v| v.bricks_fetched).sum(),
            samples: mean(&|v| v.samples as f64),
            psnr_db: (!psnr.is_empty()).then(|| psnr.iter().sum::<f64>() / psnr.len() as f64),
            ssim: mean(&|v| v.ssim),
            max_abs_error: views.iter().map(|v| v.max_abs_error).fold(0.0, f64::max),
            views,
        })
    }

    /// Table 1: every configured method over the orbit.
    ///
    /// # Errors
    /// The first failed run's, as [`Bench::run`].
    pub fn table1(&self) -> Result<Vec<RunRecord>, BenchError> {
        self.plan
            .methods
            .iter()
            .map(|&(method, skipping)| {
                let options = RenderOptions {
                    method,
                    empty_space_skipping: skipping,
                    ..self.base.clone()
                };
                self.run(
                    Experiment::Table1,
                    method_label(method, skipping),
                    options,
                    None,
                )
            })
            .collect()
    }

    /// Time against error: the defaults, then each parameter swept alone.
    ///
    /// # Errors
    /// The first failed run's, as [`Bench::run`].
    pub fn sweep(&self) -> Result<Vec<RunRecord>, BenchError> {
        let param = |name: SweptParameter, value: f64| Some(SweepParam { name, value });
        let default = self.run(
            Experiment::Sweep,
            "defaults".into(),
            self.base.clone(),
            param(SweptParameter::Default, 0.0),
        )?;
        let working_set = default
            .views
            .iter()
            .map(|v| v.bricks_used)
            .max()
            .unwrap_or(1)
            .max(1);
        let slot = self.info().brick_bytes();
        let mut runs = vec![default];
        let sv = self.plan.sweep.clone();
        runs.extend(self.step_and_bias_runs(&self.base, "", &sv)?);
        for &f in &sv.cache_fractions {
            let slots = ((working_set as f64 * f).round() as u64).max(1);
            let o = RenderOptions {
                cache_bytes: slots * slot,
                ..self.base.clone()
            };
            runs.push(self.run(
                Experiment::Sweep,
                format!("cache {f}× working set ({slots} bricks)"),
                o,
                param(SweptParameter::CacheFraction, f),
            )?);
        }
        for &method in &sv.methods {
            runs.extend(self.method_sweep(method, &sv)?);
        }
        let default_depth = OctreeGeometry::depth_for(self.info(), self.base.leaf_voxels, 7);
        for l in sv.leaf_voxels {
            let depth = OctreeGeometry::depth_for(self.info(), l, 7);
            if self.base.octree_depth.is_none() && depth == default_depth {
                continue;
            }
            let o = RenderOptions {
                leaf_voxels: l,
                octree_depth: None,
                ..self.base.clone()
            };
            runs.push(self.run(
                Experiment::Sweep,
                format!("leaf {l} voxels"),
                o,
                param(SweptParameter::LeafVoxels, l as f64),
            )?);
        }
        Ok(runs)
    }

    /// Another method over the time–error sweep: its defaults, then each step and LOD bias
    /// alone (labels start with the method's name).
    fn method_sweep(&self, method: Method, sv: &SweepValues) -> Result<Vec<RunRecord>, BenchError> {
        let name = method.name();
        let base = RenderOptions {
            method,
            ..self.base.clone()
        };
        let mut runs = vec![self.run(
            Experiment::Sweep,
            format!("{name} defaults"),
            base.clone(),
            Some(SweepParam {
                name: SweptParameter::Default,
                value: 0.0,
            }),
        )?];
        runs.extend(self.step_and_bias_runs(&base, &format!("{name} "), sv)?);
        Ok(runs)
    }

    /// The sweep runs of `base` with each step of `sv` and then each LOD bias alone (those
    /// equal to `base`'s skipped), labelled `{prefix}step S` and `{prefix}LOD bias B`.
    fn step_and_bias_runs(
        &self,
        base: &RenderOptions,
        prefix: &str,
        sv: &SweepValues,
    ) -> Result<Vec<RunRecord>, BenchError> {
        let param = |name: SweptParameter, value: f64| Some(SweepParam { name, value });
        let mut runs = Vec::new();
        for &s in sv.steps.iter().filter(|&&s| s != base.step_factor) {
            let o = RenderOptions {
                step_factor: s,
                ..base.clone()
            };
            runs.push(self.run(
                Experiment::Sweep,
                format!("{prefix}step {s}"),
                o,
                param(SweptParameter::Step, f64::from(s)),
            )?);
        }
        for &b in sv.lod_biases.iter().filter(|&&b| b != base.lod_bias) {
            let o = RenderOptions {
                lod_bias: b,
                ..base.clone()
            };
            runs.push(self.run(
                Experiment::Sweep,
                format!("{prefix}LOD bias {b}"),
                o,
                param(SweptParameter::LodBias, f64::from(b)),
            )?);
        }
        Ok(runs)
    }

    /// Scaling: one residency run with the base options.
    ///
    /// # Errors
    /// As [`Bench::run`].
    pub fn scaling(&self) -> Result<Vec<RunRecord>, BenchError> {
        Ok(vec![self.run(
            Experiment::Scaling,
            "residency".into(),
            self.base.clone(),
            None,
        )?])
    }

    /// Converges a fresh renderer (cold cache) on view `k` and returns it with the result.
    fn cold(&self, k: usize, options: RenderOptions) -> Result<(Renderer, Progressive), GpuError> {
        let mut scene = self.scene.clone();
        scene.camera = self.cameras[k].1.clone();
        let mut renderer = Renderer::new(&self.gpu, self.info(), &scene, options)?;
        let fetcher = Fetcher::new(Arc::clone(&self.source), self.plan.workers, 16);
        let p = converge(&self.gpu, &mut renderer, &fetcher, &self.budget())?;
        self.bar.inc(1);
        Ok((renderer, p))
    }

    /// Skipped work: per view, ours from a cold cache against the naive frustum loader.
    ///
    /// # Errors
    /// A renderer's or frame's [`GpuError`], or a [`MetricsError`] comparing an image with
    /// its reference.
    pub fn skipped(&self) -> Result<Vec<SkippedRecord>, BenchError> {
        let info = self.info().clone();
        let brick_bytes = info.brick_bytes();
        (0..self.cameras.len())
            .map(|k| {
                self.bar
                    .set_message(format!("skipped work, view {}", k + 1));
                let mut scene = self.scene.clone();
                scene.camera = self.cameras[k].1.clone();
                let naive = naive::naive_fetch(&info, &scene, &self.base);
                // Equal error: ours converges to the level the naive loader chose (a LOD
                // bias far below any footprint always wants the finest allowed level), so the
                // two differ only in what skipping leaves out; coarser levels may stand in
                // while bricks stream, as they do in any view.
                let at_naive_level = vec![(naive.level, naive.level); self.scene.channels.len()];
                let coarsest = info.levels.len() as u32 - 1;
                let o = RenderOptions {
                    level_bounds: vec![(naive.level, coarsest); self.scene.channels.len()],
                    lod_bias: -64.0,
                    ..self.base.clone()
                };
                let (mut renderer, p) = self.cold(k, o.clone())?;
                // The bricks this image reads, those copied into aprons included: one more
                // frame with every brick of a footprint looked up.
                renderer.use_aprons(&self.gpu, false);
                let read = renderer.render(&self.gpu)?.counts.bricks_used;
                let ours_image = to_image(o.width, o.height, &p.pixels);
                let ours_m = metrics::compare(&ours_image, &self.references[k])?;
                let fill = naive
                    .bricks
                    .iter()
                    .filter(|b| naive::fill_only(&info, b))
                    .count() as u64;
                let empty = naive
                    .bricks
                    .iter()
                    .filter(|b| naive::transparent(&info, &scene, b))
                    .count() as u64;
                let ours_bytes: u64 = p.frames.iter().map(|f| f.bytes_fetched).sum();
                let naive_bytes = (naive.bricks.len() as u64 - fill) * brick_bytes;
                let pinned = RenderOptions {
                    empty_space_skipping: false,
                    level_bounds: at_naive_level,
                    ..self.base.clone()
                };
                let (_, np) = self.cold(k, pinned)?;
                let naive_image = to_image(o.width, o.height, &np.pixels);
                let naive_m = metrics::compare(&naive_image, &self.references[k])?;
                Ok(SkippedRecord {
                    azimuth: self.cameras[k].0,
                    naive_level: naive.level,
                    naive_bricks: naive.bricks.len() as u64,
                    naive_fill_bricks: fill,
                    naive_empty_bricks: empty,
                    naive_bytes,
                    naive_samples: np.frames.last().map_or(0, |f| f.shader.samples),
                    naive_psnr_db: finite_psnr(&naive_m),
                    naive_ssim: naive_m.ssim,
                    ours_bricks_fetched: p.frames.iter().map(|f| f.bricks_fetched).sum(),
                    ours_bytes_fetched: ours_bytes,
                    ours_bricks_requested: p.request_log.len() as u64,
                    ours_requested_empty: self.requested_empty(&p),
                    ours_samples: p.frames.last().map_or(0, |f| f.shader.samples),
                    ours_psnr_db: finite_psnr(&ours_m),
                    ours_ssim: ours_m.ssim,
                    bytes_ratio: (ours_bytes > 0).then(|| naive_bytes as f64 / ours_bytes as f64),
                    ours_bricks_read: read,
                    bytes_ceiling: (read > 0)
                        .then(|| naive_bytes as f64 / (read * brick_bytes) as f64),
                })
            })
            .collect()
    }

    /// The limit probe over the orbit, with every filter the device has: per view one frame
    /// to warm up, then the timed frames.
    ///
    /// # Errors
    /// The probe's [`GpuError`] (say, a volume over one 3D texture), or
    /// [`BenchError::Probe`] naming the view whose image cannot be compared.
    pub fn probe(&self) -> Result<Vec<ProbeRecord>, BenchError> {
        let probe = LimitProbe::new(
            &self.gpu,
            self.source.as_ref(),
            &self.scene,
            self.base.width,
            self.base.height,
            self.base.step_factor,
        )?;
        let mut records = Vec::new();
        for filter in probe.filters() {
            self.bar
                .set_message(format!("limit probe, {} filtering", filter.name()));
            let mut samples = 0.0;
            let mut gpu = Vec::new();
            let mut wall = Vec::new();
            let mut psnr = Vec::new();
            for (k, (_, camera)) in self.cameras.iter().enumerate() {
                let frame = probe.render(&self.gpu, camera, filter)?;
                let o = &self.base;
                let m = metrics::compare(
                    &to_image(o.width, o.height, &frame.pixels),
                    &self.references[k],
                )
                .map_err(|source| BenchError::Probe {
                    dataset: self.info().name.clone(),
                    view: k,
                    source,
                })?;
                psnr.extend(finite_psnr(&m));
                let mut g = Vec::new();
                let mut w = Vec::new();
                for _ in 0..self.plan.timed_frames {
                    let t = Instant::now();
                    let frame = probe.render(&self.gpu, camera, filter)?;
                    w.push(t.elapsed().as_secs_f64() * 1e3);
                    g.extend(frame.gpu_time_ms);
                    samples += frame.samples as f64;
                }
                wall.push(median(&mut w));
                if !g.is_empty() {
                    gpu.push(median(&mut g));
                }
            }
            let views = self.cameras.len() as f64;
            let samples = samples / views / self.plan.timed_frames as f64;
            let gpu_ms = (gpu.len() == self.cameras.len()).then(|| gpu.iter().sum::<f64>() / views);
            let wall_ms = wall.iter().sum::<f64>() / views;
            records.push(ProbeRecord {
                filter,
                samples,
                gpu_ms,
                wall_ms,
                samples_per_s: samples / gpu_ms.unwrap_or(wall_ms) * 1e3,
                psnr_db: (!psnr.is_empty()).then(|| psnr.iter().sum::<f64>() / psnr.len() as f64),
            });
        }
        Ok(records)
    }

    /// Runs every experiment of the plan and gathers the results.
    ///
    /// # Errors
    /// The first failed experiment's [`BenchError`]; a limit probe that cannot run is no
    /// error (its reason is kept in [`BenchResults::probe_error`]).
    pub fn run_all(&self) -> Result<BenchResults, BenchError> {
        let views = self.cameras.len() as u64;
        let mut total = 0;
        for e in &self.plan.experiments {
            total += match e {
                Experiment::Table1 => self.plan.methods.len() as u64 * views,
                Experiment::Sweep => {
                    let s = &self.plan.sweep;
                    (1 + s.steps.len()
                        + s.lod_biases.len()
                        + s.cache_fractions.len()
                        + s.leaf_voxels.len()
                        + s.methods.len() * (1 + s.steps.len() + s.lod_biases.len()))
                        as u64
                        * views
                }
                Experiment::Skipped => 2 * views,
                Experiment::Scaling => views,
            };
        }
        self.bar.set_length(total);
        let mut runs = Vec::new();
        let mut skipped = Vec::new();
        let mut probe = Vec::new();
        let mut probe_error = None;
        for e in &self.plan.experiments {
            let t = Instant::now();
            match e {
                Experiment::Table1 => {
                    runs.extend(self.table1()?);
                    match self.probe() {
                        Ok(p) => probe = p,
                        Err(e) => {
                            let e = crate::error_chain(&e);
                            tracing::warn!("{}: no limit probe: {e}", self.info().name);
                            probe_error = Some(e);
                        }
                    }
                }
                Experiment::Sweep => runs.extend(self.sweep()?),
                Experiment::Skipped => skipped.extend(self.skipped()?),
                Experiment::Scaling => runs.extend(self.scaling()?),
            }
            tracing::info!(
                "{}: {} done in {:.1} s",
                self.info().name,
                e.name(),
                t.elapsed().as_secs_f64()
            );
        }
        self.bar.finish_and_clear();
        Ok(BenchResults {
            format: FORMAT.to_string(),
            unix_time: std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.as_secs()),
            device: DeviceInfo::of(&self.gpu),
            dataset: DatasetInfo::of(
                self.info(),
                &self.scene,
                self.plan.label.as_deref(),
                &self.plan.kind,
            ),
            settings: Settings {
                width: self.base.width,
                height: self.base.height,
                views: self.cameras.len(),
                timed_frames: self.plan.timed_frames,
                max_frames: self.plan.max_frames,
                elevation: self.plan.elevation,
                distance: self.plan.distance,
                first_azimuth: self.plan.first_azimuth,
                reference_step: self.plan.reference_step,
                reference_s: self.reference_s,
            },
            experiments: self.plan.experiments.clone(),
            runs,
            skipped,
            probe,
            probe_error,
        })
    }
}

/// Gives the visible channels after the first distinct transfer functions, as the paper does
/// for simulated channels ("duplicating the volume n times, rendering channels with different
/// transfer functions"): channel `i`'s ramp starts `i/(2n)` of the way further up its range.
pub fn vary_transfer_functions(scene: &mut Scene) {
    let n = scene.channels.len().max(1) as f64;
    for (i, style) in scene.channels.iter_mut().enumerate().skip(1) {
        if let (Some(first), Some(last)) = (style.opacity.first(), style.opacity.last()) {
            let (lo, hi) = (first.value, last.value);
            let shift = (hi - lo) * i as f64 / (2.0 * n);
            for p in &mut style.opacity {
                if p.value < hi {
                    p.value = (p.value + shift).min(hi);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run_record(experiment: Experiment, method: Method, sweep: Option<SweepParam>) -> RunRecord {
        RunRecord {
            experiment,
            label: "label".into(),
            method,
            channels: 1,
            sweep,
            is_default: false,
            options: OptionsRecord {
                step: 0.5,
                lod_bias: -1.0,
                cache_bytes: 1 << 20,
                cache_capacity_bytes: 1 << 20,
                leaf_voxels: 4096,
                octree_depth: 3,
                leaf_edge: 16.0,
                skipping: true,
                substitution: true,
            },
            converged_views: 0,
            gpu_ms: None,
            wall_ms: 1.0,
            resident_bytes: 0.0,
            bricks_used: 0.0,
            cold_bytes_fetched: 0,
            bytes_fetched: 0,
            bricks_fetched: 0,
            samples: 0.0,
            psnr_db: None,
            ssim: 1.0,
            max_abs_error: 0.0,
            views: Vec::new(),
        }
    }

    #[test]
    fn enums_serialize_as_their_names_on_the_command_line_and_in_results() {
        for e in Experiment::ALL {
            let json = serde_json::to_value(e).unwrap();
            assert_eq!(json, e.name());
            assert_eq!(serde_json::from_value::<Experiment>(json).unwrap(), e);
            assert_eq!(e.name().parse::<Experiment>(), Ok(e));
            assert_eq!(e.to_string(), e.name());
        }
        let names: Vec<_> = std::iter::once(SweptParameter::Default)
            .chain(SweptParameter::SWEPT)
            .map(|p| {
                let json = serde_json::to_value(p).unwrap();
                assert_eq!(
                    serde_json::from_value::<SweptParameter>(json.clone()).unwrap(),
                    p
                );
                assert_eq!(p.to_string(), p.name());
                json
            })
            .collect();
        assert_eq!(
            names,
            [
                "default",
                "step",
                "lod_bias",
                "cache_fraction",
                "leaf_voxels"
            ]
        );
        for m in Method::ALL {
            let r = run_record(Experiment::Table1, m, None);
            let json = serde_json::to_value(&r).unwrap();
            assert_eq!(json["method"], m.name());
            assert_eq!(serde_json::from_value::<RunRecord>(json).unwrap(), r);
        }
    }

    #[test]
    fn a_run_record_keeps_its_json_strings_and_refuses_unknown_names() {
        let r = run_record(
            Experiment::Sweep,
            Method::PageTable,
            Some(SweepParam {
                name: SweptParameter::LodBias,
                value: 0.5,
            }),
        );
        let json = serde_json::to_value(&r).unwrap();
        assert_eq!(json["experiment"], "sweep");
        assert_eq!(json["method"], "page-table");
        assert_eq!(json["sweep"]["name"], "lod_bias");
        assert_eq!(
            serde_json::from_value::<RunRecord>(json.clone()).unwrap(),
            r
        );
        for (field, bad) in [("method", "page_table"), ("experiment", "Sweep")] {
            let mut j = json.clone();
            j[field] = bad.into();
            let e = serde_json::from_value::<RunRecord>(j)
                .unwrap_err()
                .to_string();
            assert!(e.contains(bad), "{e}");
        }
    }

    #[test]
    fn a_probe_filter_is_its_name_in_json() {
        for filter in [ProbeFilter::Manual, ProbeFilter::Hardware] {
            let json = serde_json::to_value(filter).unwrap();
            assert_eq!(json, filter.name());
            assert_eq!(serde_json::from_value::<ProbeFilter>(json).unwrap(), filter);
        }
        assert!(serde_json::from_value::<ProbeFilter>("Manual".into()).is_err());
    }

    #[test]
    fn the_sample_type_is_its_zarr_name() {
        let d = DatasetInfo {
            label: "l".into(),
            kind: "sparse".into(),
            name: "n".into(),
            sample_type: SampleType::U16,
            shape: [1, 2, 3],
            brick_shape: [1, 1, 1],
            levels: 1,
            channels: 1,
            visible_channels: 1,
            voxels: 6,
        };
        let json = serde_json::to_value(&d).unwrap();
        assert_eq!(json["sample_type"], "uint16");
        assert_eq!(
            serde_json::from_value::<DatasetInfo>(json.clone()).unwrap(),
            d
        );
        let mut j = json;
        j["sample_type"] = "uint64".into();
        assert!(serde_json::from_value::<DatasetInfo>(j).is_err());
    }
}
