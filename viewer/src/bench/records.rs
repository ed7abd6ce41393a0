//! The records of a results file (`schemas/json/render-bench.schema.json`): [`BenchResults`]
//! with the device, dataset and settings it was measured with, one [`RunRecord`] per
//! configuration (with its [`ViewRecord`]s), the skipped-work and limit-probe records.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::experiment::Experiment;
use crate::gpu::device::Gpu;
use crate::gpu::probe::ProbeFilter;
use crate::gpu::renderer::Method;
use crate::gpu::stop_reason::StopReason;
use crate::scene::{RenderMode, Scene};
use crate::source::{SampleType, VolumeInfo};
use residency_schemas::SampleKind;

/// Format tag of a results file.
pub const FORMAT: &str = "residency-render-bench/1";

/// The machine a result was measured on.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
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
    #[schemars(range(min = 1))]
    pub cores: usize,
    /// Whether GPU times come from timestamp queries (else they are `null`).
    pub timestamps: bool,
}

impl DeviceInfo {
    /// The description of `gpu` and of this machine's CPU.
    pub(crate) fn of(gpu: &Gpu) -> Self {
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
#[schemars(deny_unknown_fields)]
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
    #[schemars(range(min = 1))]
    pub levels: usize,
    /// Channels in the store.
    #[schemars(range(min = 1))]
    pub channels: usize,
    /// Channels rendered (visible in the scene).
    #[schemars(range(min = 1))]
    pub visible_channels: usize,
    /// Level-0 voxels per channel.
    pub voxels: u64,
}

impl DatasetInfo {
    /// The synthetic specimen [`Self::kind`] names, if it names one.
    pub(crate) fn sample_kind(&self) -> Option<SampleKind> {
        self.kind.parse().ok()
    }

    /// The description of `info` as drawn in `scene`, labelled `label` (else its name).
    pub(crate) fn of(info: &VolumeInfo, scene: &Scene, label: Option<&str>, kind: &str) -> Self {
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
#[schemars(deny_unknown_fields)]
pub struct Settings {
    /// Image width.
    #[schemars(range(min = 1))]
    pub width: u32,
    /// Image height.
    #[schemars(range(min = 1))]
    pub height: u32,
    /// Views of the orbit.
    #[schemars(range(min = 1))]
    pub views: usize,
    /// Frames timed per view after convergence.
    #[schemars(range(min = 1))]
    pub timed_frames: usize,
    /// Most frames to converge one view.
    pub max_frames: u32,
    /// Orbit elevation, degrees.
    pub elevation: f64,
    /// Orbit distance, volume diagonals.
    #[schemars(range(min = 0))]
    pub distance: f64,
    /// Azimuth of the first view, degrees (the others follow at equal steps around 360°).
    pub first_azimuth: f64,
    /// Reference step as a fraction of the finest level-0 voxel.
    #[schemars(range(min = 0))]
    pub reference_step: f64,
    /// Seconds spent computing the reference images.
    #[schemars(range(min = 0))]
    pub reference_s: f64,
    /// What each ray made of its samples (the scene's mode) in every run.
    pub mode: RenderMode,
}

/// The renderer options of one run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct OptionsRecord {
    /// Step as a fraction of the voxel of the level in use.
    #[schemars(range(min = 0))]
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
    #[schemars(range(min = 0))]
    pub leaf_edge: f64,
    /// Empty-space skipping on.
    pub skipping: bool,
    /// Substitution of missing bricks on.
    pub substitution: bool,
}

/// One view of one run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct ViewRecord {
    /// Camera azimuth, degrees.
    pub azimuth: f64,
    /// Whether the view converged (a frame requested nothing).
    pub converged: bool,
    /// Why converging stopped.
    pub stop_reason: StopReason,
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
    #[schemars(range(min = 0))]
    pub wall_ms: f64,
    /// Median wall ms per converged frame rendered without reading the image back (as
    /// `viewer view` renders for presenting on the GPU), timed alternately with `wall_ms`'s
    /// frames on the same view; `wall_ms` minus this is the readback's cost. Absent from
    /// results files older than this field.
    #[serde(default)]
    #[schemars(range(min = 0))]
    pub wall_ms_without_readback: Option<f64>,
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
    #[schemars(range(min = 0))]
    pub max_abs_error: f64,
}

/// A parameter a sweep varies, named in results files as `default`, `step`, `lod_bias`,
/// `cache_fraction` or `leaf_voxels`.
#[derive(
    Clone,
    Copy,
    Debug,
    PartialEq,
    Eq,
    Hash,
    Serialize,
    Deserialize,
    JsonSchema,
    strum::Display,
    strum::IntoStaticStr,
)]
#[serde(rename_all = "snake_case")]
#[strum(serialize_all = "snake_case")]
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
}

residency_schemas::strum_names!(SweptParameter);

/// A swept parameter and its value.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct SweepParam {
    /// The parameter ([`SweptParameter::Default`] for the defaults).
    pub name: SweptParameter,
    /// The value.
    pub value: f64,
}

/// One configuration measured over the whole orbit.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub struct RunRecord {
    /// [`Experiment::Table1`], [`Experiment::Sweep`] or [`Experiment::Scaling`].
    pub experiment: Experiment,
    /// Short label (`residency`, `step 0.25`, …).
    pub label: String,
    /// Traversal method, serialized as its name (`residency`, `page-table`, `octree`).
    pub method: Method,
    /// Rendered channels.
    #[schemars(range(min = 1))]
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
    #[schemars(range(min = 0))]
    pub wall_ms: f64,
    /// Mean over views of the median wall ms per converged frame rendered without reading
    /// the image back (`null` when a view lacks it: results files older than this field).
    #[serde(default)]
    #[schemars(range(min = 0))]
    pub wall_ms_without_readback: Option<f64>,
    /// Mean over views of the bytes the cache needs resident.
    #[schemars(range(min = 0))]
    pub resident_bytes: f64,
    /// Mean over views of the bricks the frame read.
    #[schemars(range(min = 0))]
    pub bricks_used: f64,
    /// Bytes fetched to converge the first view from a cold cache.
    pub cold_bytes_fetched: u64,
    /// Bytes fetched over the whole orbit.
    pub bytes_fetched: u64,
    /// Bricks fetched over the whole orbit.
    pub bricks_fetched: u64,
    /// Mean samples per converged frame.
    #[schemars(range(min = 0))]
    pub samples: f64,
    /// Mean PSNR over views, dB (`null` if every view was identical to the reference).
    pub psnr_db: Option<f64>,
    /// Mean SSIM over views.
    pub ssim: f64,
    /// Largest max abs error over views.
    #[schemars(range(min = 0))]
    pub max_abs_error: f64,
    /// Per view.
    #[schemars(length(min = 1))]
    pub views: Vec<ViewRecord>,
}

/// Skipped work for one view: the naive frustum loader against ours, each from a cold cache.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
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
#[schemars(deny_unknown_fields)]
pub struct ProbeRecord {
    /// `manual` (8 texel loads, as the renderer) or `hardware` (the texture unit filters).
    pub filter: ProbeFilter,
    /// Samples per frame (each of every drawn channel), mean over views.
    #[schemars(range(min = 0))]
    pub samples: f64,
    /// GPU ms per frame, mean over views of the median per view (`null`: no timestamps).
    #[schemars(range(min = 0))]
    pub gpu_ms: Option<f64>,
    /// Wall ms per frame (submit to readback), mean over views of the median per view.
    #[schemars(range(min = 0))]
    pub wall_ms: f64,
    /// `samples / time` per second, GPU time where there is one.
    #[schemars(range(min = 0))]
    pub samples_per_s: f64,
    /// PSNR of the probe's image against the reference, mean over views (`null`: identical).
    pub psnr_db: Option<f64>,
}

/// A results file: one dataset, one device, any experiments.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(title = "Renderer benchmark results", deny_unknown_fields)]
pub struct BenchResults {
    /// [`FORMAT`].
    #[schemars(extend("const" = FORMAT))]
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
            wall_ms_without_readback: Some(0.5),
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
