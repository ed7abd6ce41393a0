//! `viewer bench vdi`: volumetric depth images against direct volume rendering on one
//! dataset, one device, one run (issue 30's evidence, the VDI paper's Sec. 5 and Table 2).
//!
//! From one camera of generation `V_O` (the scene's), for each supersegment count `N_S` the
//! renderer converges the view and generates a VDI (timed: the VDI pass alone, bricks
//! resident). Then, for each deviation (the camera turned about its target, around its own
//! up axis), the DVR image of the deviated camera is converged and timed, and the VDI is ray
//! cast from it with and without empty-space skipping (timed), and with the linear filter
//! across lists (timed, with skipping); each VDI image is compared with the DVR image (SSIM,
//! PSNR). Sizes: the slots as the GPU holds them (16 bytes each,
//! `N_S` per pixel), the paper's raw layout (24 bytes a slot: RGBA and two depths in `f32`),
//! and the file (`residency_schemas::vdi`, LZ4), beside the volume's bytes.

use std::fmt::Write;
use std::sync::Arc;
use std::time::Instant;

use residency_schemas::vdi::Compression;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::driver::{median, to_image};
use super::plots::{Line, PlotError, panels};
use super::records::DeviceInfo;
use crate::gpu::device::Gpu;
use crate::gpu::error::GpuError;
use crate::gpu::renderer::{RenderOptions, Renderer};
use crate::gpu::streaming::{Budget, Fetcher, converge};
use crate::gpu::vdi_buffers::VdiBuffers;
use crate::gpu::vdi_filter::VdiFilter;
use crate::gpu::vdi_render::{VdiPipelines, VdiRenderer, VdiWork};
use crate::metrics::{self, MetricsError};
use crate::scene::{Camera, Scene};
use crate::source::BrickSource;

/// Bytes of one slot in the paper's raw VDIs: RGBA and front and back depth in `f32` (950 MiB
/// at 1920×1080 with 20 supersegments).
pub const PAPER_SLOT_BYTES: u64 = 24;

/// The paper's compressed VDI at 1920×1080 and `N_S` = 20: 225 MiB (Sec. 5), per pixel.
pub const PAPER_COMPRESSED_BYTES_PER_PIXEL: f64 = 225.0 * 1048576.0 / (1920.0 * 1080.0);

/// The image-space sampling `D_I` of the preview measurement.
pub const PREVIEW_SCALE: f64 = 0.5;

/// The sampling along the ray `D_R` measured by default ([`VdiPlan::ray_sampling`]).
pub const RAY_SAMPLING: f64 = 0.5;

/// What `viewer bench vdi` measures.
#[derive(Clone, Debug)]
pub struct VdiPlan {
    /// Supersegment counts (`N_S`).
    pub supersegments: Vec<u32>,
    /// Deviations from the camera of generation, degrees.
    pub deviations: Vec<f64>,
    /// Frames timed per measurement (the median is kept).
    pub timed_frames: usize,
    /// Most frames to converge a view.
    pub max_frames: u32,
    /// Fetch workers.
    pub workers: usize,
    /// The sampling along the ray `D_R` of the frames measured beside the full walk
    /// ([`VdiRenderer::set_ray_sampling`]).
    pub ray_sampling: f64,
}

/// A bench failure.
#[derive(Debug, thiserror::Error)]
pub enum VdiBenchError {
    /// The renderer failed.
    #[error(transparent)]
    Gpu(#[from] GpuError),
    /// Two images could not be compared.
    #[error(transparent)]
    Metrics(#[from] MetricsError),
    /// A view did not converge within the frame budget.
    #[error("the view at {degrees}° did not converge in {frames} frames ({reason})")]
    NotConverged {
        /// The deviation.
        degrees: f64,
        /// The frame budget.
        frames: u32,
        /// Why the loop stopped.
        reason: String,
    },
    /// The VDI could not be encoded.
    #[error(transparent)]
    Vdi(#[from] residency_schemas::vdi::VdiError),
}

/// One VDI of the run: its size and generation.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct VdiSizeRecord {
    /// Most supersegments per pixel.
    pub supersegments: u32,
    /// Mean supersegments per pixel.
    pub mean_supersegments: f64,
    /// Marches per ray of the generation (1 where every ray fits at the first `γ`).
    pub marches_per_ray: f64,
    /// Wall milliseconds of the VDI pass (bricks resident, readback included).
    pub generation_ms: f64,
    /// GPU milliseconds of its compute passes, where the device has timestamp queries: the
    /// rest of `generation_ms` is the readback and the unpacking on the CPU.
    pub generation_gpu_ms: Option<f64>,
    /// Bytes of the slots as the GPU holds them (16 a slot, `N_S` per pixel).
    pub gpu_bytes: u64,
    /// Bytes of the same VDI in the paper's raw layout (24 a slot).
    pub paper_raw_bytes: u64,
    /// Bytes of the `.vdi` file (compression `shuffled_lz4`, what `viewer serve` sends by
    /// default).
    pub file_bytes: u64,
    /// Bytes of the same file with compression `shuffled_zstd` (absent in results written
    /// before 2026-12-07).
    #[serde(default)]
    pub zstd_file_bytes: Option<u64>,
}

/// One deviation of one VDI: its image against DVR there, and the frame times.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct VdiViewRecord {
    /// Most supersegments per pixel.
    pub supersegments: u32,
    /// Degrees from the camera of generation.
    pub deviation_degrees: f64,
    /// SSIM of the VDI's image (the nearest filter, the paper's) against the DVR image of the
    /// same camera.
    pub ssim: f64,
    /// PSNR of the same, dB (`null` for identical images).
    #[schemars(with = "Option<f64>")]
    pub psnr_db: f64,
    /// Median wall ms of a VDI frame with empty-space skipping (readback included).
    pub vdi_ms: f64,
    /// Median GPU ms of the same, where timestamps exist.
    pub vdi_gpu_ms: Option<f64>,
    /// Median wall ms of a VDI frame without skipping.
    pub vdi_no_skip_ms: f64,
    /// Median GPU ms of the same.
    pub vdi_no_skip_gpu_ms: Option<f64>,
    /// What the rays of the VDI frame with skipping did, per pixel (the same on any device;
    /// absent in results written before 2026-12-06).
    #[serde(default)]
    pub work: Option<VdiWork>,
    /// The same without skipping.
    #[serde(default)]
    pub work_no_skip: Option<VdiWork>,
    /// SSIM against DVR of the VDI's image with the linear filter across lists
    /// ([`VdiFilter::Linear`]).
    pub linear_ssim: f64,
    /// PSNR of the same, dB (`null` for identical images).
    #[schemars(with = "Option<f64>")]
    pub linear_psnr_db: f64,
    /// Median wall ms of a frame with the linear filter (with skipping).
    pub linear_ms: f64,
    /// Median GPU ms of the same.
    pub linear_gpu_ms: Option<f64>,
    /// SSIM against DVR of the preview (rays at `D_I` = [`PREVIEW_SCALE`], upsampled).
    pub preview_ssim: f64,
    /// Median wall ms of a preview frame (with skipping).
    pub preview_ms: f64,
    /// Median GPU ms of the same.
    pub preview_gpu_ms: Option<f64>,
    /// Median wall ms of a converged DVR frame of the same camera.
    pub dvr_ms: f64,
    /// Median GPU ms of the same.
    pub dvr_gpu_ms: Option<f64>,
    /// SSIM against DVR of the frame sampled along its rays at `D_R` =
    /// [`VdiBenchResults::ray_sampling`] (nearest filter, full resolution, with skipping).
    #[serde(default)]
    pub ray_sampled_ssim: Option<f64>,
    /// Median wall ms of that frame.
    #[serde(default)]
    pub ray_sampled_ms: Option<f64>,
    /// Median GPU ms of the same.
    #[serde(default)]
    pub ray_sampled_gpu_ms: Option<f64>,
    /// Its work per pixel ([`VdiRenderer::work`]).
    #[serde(default)]
    pub ray_sampled_work: Option<VdiWork>,
}

/// The results of `viewer bench vdi` on one dataset.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct VdiBenchResults {
    /// The dataset's label.
    pub label: String,
    /// The device.
    pub device: DeviceInfo,
    /// Image width (lists per row).
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Channels drawn into the VDIs.
    pub channels: usize,
    /// Bytes of the volume's level 0, every channel.
    pub volume_bytes: u64,
    /// One per supersegment count.
    pub sizes: Vec<VdiSizeRecord>,
    /// One per supersegment count and deviation.
    pub views: Vec<VdiViewRecord>,
    /// The sampling along the ray `D_R` of the views' `ray_sampled_*` columns (`null` in runs
    /// before it was measured).
    #[serde(default)]
    pub ray_sampling: Option<f64>,
}

/// `camera` turned by `degrees` about its target, around its own up axis: `viewer view`'s
/// orbit by a horizontal drag.
pub fn turned(camera: &Camera, degrees: f64) -> Camera {
    crate::interactive::camera_control::orbit(camera, -degrees.to_radians(), 0.0, 1.0)
}

/// The median wall ms and median GPU ms (where reported) of `frames` runs of `frame` after an
/// untimed one, and the last run's output.
fn timed<T>(
    frames: usize,
    mut frame: impl FnMut() -> Result<(T, Option<f64>), GpuError>,
) -> Result<(T, f64, Option<f64>), GpuError> {
    let (mut wall, mut gpu) = (Vec::new(), Vec::new());
    // One frame untimed: the first dispatch of a pipeline pays for its compilation.
    let mut last = Some(frame()?.0);
    for _ in 0..frames.max(1) {
        let start = Instant::now();
        let (out, gpu_ms) = frame()?;
        wall.push(start.elapsed().as_secs_f64() * 1e3);
        gpu.extend(gpu_ms);
        last = Some(out);
    }
    let gpu = (!gpu.is_empty()).then(|| median(&mut gpu));
    Ok((last.expect("at least one frame"), median(&mut wall), gpu))
}

/// Runs the VDI experiment: `scene` (its camera is `V_O`) over `source`, at the size and with
/// the settings of `options`.
///
/// # Errors
/// A [`VdiBenchError`]: the renderer failed, a view did not converge, or two images could not
/// be compared.
pub fn run(
    gpu: &Gpu,
    source: Arc<dyn BrickSource>,
    scene: &Scene,
    options: RenderOptions,
    plan: &VdiPlan,
    label: &str,
) -> Result<VdiBenchResults, VdiBenchError> {
    let (width, height) = (options.width, options.height);
    let info = source.info().clone();
    let mut renderer = Renderer::new(gpu, &info, scene, options)?;
    let fetcher = Fetcher::new(Arc::clone(&source), plan.workers, 16);
    let budget = Budget {
        max_frames: plan.max_frames,
        workers: plan.workers,
        ..Default::default()
    };
    let settle = |renderer: &mut Renderer, camera: &Camera, degrees: f64| {
        renderer.set_camera(camera.clone());
        let p = converge(gpu, renderer, &fetcher, &budget)?;
        if p.converged {
            Ok(())
        } else {
            Err(VdiBenchError::NotConverged {
                degrees,
                frames: plan.max_frames,
                reason: p.stop_reason.to_string(),
            })
        }
    };
    // The truth at every deviation: converged DVR, timed.
    let mut truths = Vec::new();
    for &degrees in &plan.deviations {
        let camera = turned(&scene.camera, degrees);
        settle(&mut renderer, &camera, degrees)?;
        let (pixels, ms, gpu_ms) = timed(plan.timed_frames, || {
            let out = renderer.render(gpu)?;
            Ok((out.pixels, out.gpu_time_ms))
        })?;
        truths.push((camera, to_image(width, height, &pixels), ms, gpu_ms));
    }
    let mut sizes = Vec::new();
    let mut views = Vec::new();
    // The ray caster's pipelines, compiled once for every VDI.
    let pipelines = pollster::block_on(VdiPipelines::create(gpu))?;
    // The VDI pass is compiled on first use: once before anything is timed.
    settle(&mut renderer, &scene.camera, 0.0)?;
    renderer.generate_vdi(gpu, plan.supersegments.first().copied().unwrap_or(1))?;
    for &n in &plan.supersegments {
        settle(&mut renderer, &scene.camera, 0.0)?;
        let start = Instant::now();
        let (mut generation, out) = renderer.generate_vdi(gpu, n)?;
        let generation_ms = start.elapsed().as_secs_f64() * 1e3;
        // The file's size as generated (LZ4), then as zstd: the same image, another header.
        let file_bytes = generation.image.encode()?.len() as u64;
        generation.image.header.compression = Compression::ShuffledZstd;
        let zstd_file_bytes = generation.image.encode()?.len() as u64;
        let vdi = &generation.image;
        let pixels = vdi.counts.len() as u64;
        let used: u64 = vdi.counts.iter().map(|&c| u64::from(c)).sum();
        sizes.push(VdiSizeRecord {
            supersegments: n,
            mean_supersegments: used as f64 / pixels as f64,
            marches_per_ray: generation.marches as f64 / pixels as f64,
            generation_ms,
            generation_gpu_ms: out.gpu_time_ms,
            gpu_bytes: pixels * u64::from(n) * 16,
            paper_raw_bytes: pixels * u64::from(n) * PAPER_SLOT_BYTES,
            file_bytes,
            zstd_file_bytes: Some(zstd_file_bytes),
        });
        let mut vdi_renderer = pollster::block_on(VdiRenderer::create(
            gpu,
            &pipelines,
            &VdiBuffers::of(vdi),
            width,
            height,
        ))?;
        for (&degrees, (camera, truth, dvr_ms, dvr_gpu_ms)) in plan.deviations.iter().zip(&truths) {
            // A frame with `filter`, skipping or not, at `D_I` = `scale` and `D_R` = `d_r`.
            let cast = |r: &mut VdiRenderer, filter: VdiFilter, skipping: bool, scale: f64, d_r| {
                r.set_filter(gpu, filter);
                r.set_ray_sampling(d_r);
                timed(plan.timed_frames, || {
                    let frame = r.render_preview(gpu, camera, skipping, scale)?;
                    Ok((frame.pixels, frame.gpu_time_ms))
                })
            };
            let r = &mut vdi_renderer;
            let (image, vdi_ms, vdi_gpu_ms) = cast(r, VdiFilter::Nearest, true, 1.0, 1.0)?;
            let (_, vdi_no_skip_ms, vdi_no_skip_gpu_ms) =
                cast(r, VdiFilter::Nearest, false, 1.0, 1.0)?;
            let (preview, preview_ms, preview_gpu_ms) =
                cast(r, VdiFilter::Nearest, true, PREVIEW_SCALE, 1.0)?;
            let (linear, linear_ms, linear_gpu_ms) = cast(r, VdiFilter::Linear, true, 1.0, 1.0)?;
            let work = r.work(gpu, camera, true, VdiFilter::Nearest)?;
            let work_no_skip = r.work(gpu, camera, false, VdiFilter::Nearest)?;
            let (sampled, sampled_ms, sampled_gpu_ms) =
                cast(r, VdiFilter::Nearest, true, 1.0, plan.ray_sampling)?;
            let sampled_work = r.work(gpu, camera, true, VdiFilter::Nearest)?;
            let d = metrics::compare(&to_image(width, height, &sampled), truth)?;
            let m = metrics::compare(&to_image(width, height, &image), truth)?;
            let p = metrics::compare(&to_image(width, height, &preview), truth)?;
            let l = metrics::compare(&to_image(width, height, &linear), truth)?;
            views.push(VdiViewRecord {
                supersegments: n,
                deviation_degrees: degrees,
                ssim: m.ssim,
                psnr_db: m.psnr_db,
                vdi_ms,
                vdi_gpu_ms,
                vdi_no_skip_ms,
                vdi_no_skip_gpu_ms,
                work: Some(work),
                work_no_skip: Some(work_no_skip),
                linear_ssim: l.ssim,
                linear_psnr_db: l.psnr_db,
                linear_ms,
                linear_gpu_ms,
                preview_ssim: p.ssim,
                preview_ms,
                preview_gpu_ms,
                dvr_ms: *dvr_ms,
                dvr_gpu_ms: *dvr_gpu_ms,
                ray_sampled_ssim: Some(d.ssim),
                ray_sampled_ms: Some(sampled_ms),
                ray_sampled_gpu_ms: sampled_gpu_ms,
                ray_sampled_work: Some(sampled_work),
            });
        }
    }
    let channels = renderer.octree().channels().len();
    let level0 = &info.levels[0];
    let volume_bytes = info.sample_type.block_bytes(level0.shape) * info.channels.len() as u64;
    Ok(VdiBenchResults {
        label: label.to_string(),
        device: DeviceInfo::of(gpu),
        width,
        height,
        channels,
        volume_bytes,
        sizes,
        views,
        ray_sampling: Some(plan.ray_sampling),
    })
}

/// A count of the VDI frame's work with and without skipping, as `3.71 (14.72)`; `–` for
/// results without counts.
fn work_pair(v: &VdiViewRecord, count: impl Fn(&VdiWork) -> f64) -> String {
    match (&v.work, &v.work_no_skip) {
        (Some(a), Some(b)) => format!("{:.2} ({:.2})", count(a), count(b)),
        _ => "–".to_owned(),
    }
}

/// The results as markdown: the size table and the quality and speed table, with the paper's
/// figures beside ours.
pub fn markdown(r: &VdiBenchResults) -> String {
    let mut out = String::new();
    let pixels = f64::from(r.width) * f64::from(r.height);
    write!(
        out,
        "### {} ({}×{}, {} channel{}, volume {:.1} MiB; {})\n\n",
        r.label,
        r.width,
        r.height,
        r.channels,
        if r.channels == 1 { "" } else { "s" },
        r.volume_bytes as f64 / 1048576.0,
        r.device.adapter
    )
    .expect("writing to a String cannot fail");
    write!(
        out,
        "| N_S | supersegments / pixel | marches / ray | generation ms | of which GPU ms | GPU B/px | \
         paper raw B/px | file B/px (paper: {PAPER_COMPRESSED_BYTES_PER_PIXEL:.1} at N_S 20) | \
         file / volume | zstd file B/px | LZ4 / zstd |\n|---|---|---|---|---|---|---|---|---|---|---|\n",
    )
    .expect("writing to a String cannot fail");
    for s in &r.sizes {
        writeln!(
            out,
            "| {} | {:.2} | {:.2} | {:.1} | {} | {:.1} | {:.1} | {:.1} | {:.3} | {} | {} |",
            s.supersegments,
            s.mean_supersegments,
            s.marches_per_ray,
            s.generation_ms,
            s.generation_gpu_ms
                .map_or_else(|| "–".to_owned(), |ms| format!("{ms:.1}")),
            s.gpu_bytes as f64 / pixels,
            s.paper_raw_bytes as f64 / pixels,
            s.file_bytes as f64 / pixels,
            s.file_bytes as f64 / r.volume_bytes.max(1) as f64,
            s.zstd_file_bytes
                .map_or_else(|| "–".to_owned(), |b| format!("{:.1}", b as f64 / pixels)),
            s.zstd_file_bytes.map_or_else(
                || "–".to_owned(),
                |b| format!("{:.2}×", s.file_bytes as f64 / b.max(1) as f64)
            ),
        )
        .expect("writing to a String cannot fail");
    }
    let dr = r
        .ray_sampling
        .map_or_else(|| "D_R".to_owned(), |d| format!("D_R = {d}"));
    write!(
        out,
        "\n| N_S | deviation | SSIM (goal ≥ 0.97 within 10°, ≥ 0.94 at 30°) | PSNR dB | VDI ms | \
         VDI ms, no skipping | steps / px (no skipping) | reads / px (no skipping) | DVR ms | \
         DVR / VDI (goal ≥ 3 within 10°) | linear filter: SSIM | linear filter: PSNR dB | \
         linear filter: ms | DVR / linear | preview SSIM | preview ms | {dr}: SSIM | {dr}: ms | \
         {dr}: DVR / VDI | {dr}: reads / px \
         |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    )
    .expect("writing to a String cannot fail");
    let dash = |cell: Option<String>| cell.unwrap_or_else(|| "–".to_owned());
    for v in &r.views {
        let ms = |wall: f64, gpu: Option<f64>| gpu.unwrap_or(wall);
        let (vdi, dvr) = (ms(v.vdi_ms, v.vdi_gpu_ms), ms(v.dvr_ms, v.dvr_gpu_ms));
        let sampled = v.ray_sampled_ms.map(|wall| ms(wall, v.ray_sampled_gpu_ms));
        let linear = ms(v.linear_ms, v.linear_gpu_ms);
        writeln!(
            out,
            "| {} | {}° | {:.4} | {:.2} | {:.3} | {:.3} | {} | {} | {:.3} | {:.2}× | {:.4} | {:.2} | \
             {:.3} | {:.2}× | {:.4} | {:.3} | {} | {} | {} | {} |",
            v.supersegments,
            v.deviation_degrees,
            v.ssim,
            v.psnr_db,
            vdi,
            ms(v.vdi_no_skip_ms, v.vdi_no_skip_gpu_ms),
            work_pair(v, |w| w.steps),
            work_pair(v, |w| w.reads),
            dvr,
            dvr / vdi.max(1e-9),
            v.linear_ssim,
            v.linear_psnr_db,
            linear,
            dvr / linear.max(1e-9),
            v.preview_ssim,
            ms(v.preview_ms, v.preview_gpu_ms),
            dash(v.ray_sampled_ssim.map(|x| format!("{x:.4}"))),
            dash(sampled.map(|x| format!("{x:.3}"))),
            dash(sampled.map(|x| format!("{:.2}×", dvr / x.max(1e-9)))),
            dash(v.ray_sampled_work.map(|w| format!("{:.2}", w.reads))),
        )
        .expect("writing to a String cannot fail");
    }
    let timing = if r.views.iter().all(|v| v.vdi_gpu_ms.is_some()) {
        "GPU time (timestamp queries)"
    } else {
        "wall time, readback included"
    };
    write!(
        out,
        "\nTimes are medians of {timing}. The preview casts rays for D_I = {PREVIEW_SCALE} of the \
         width and height and upsamples them (the paper's Sec. 4.4: 150 fps at SSIM 0.94 with \
         D_I = 0.6 and D_R = 0.14). Steps and reads are per pixel of the VDI frame, the same on \
         any device: steps through the grid of lists (a skipped tile or run of empty depth bins \
         is one), supersegments read. The linear filter reads the bilinear mix of the four lists \
         around each point instead of the nearest list (the paper's). The D_R columns sample \
         along the ray: each step covers the part of the ray that crosses 1/D_R lists, read in \
         the list at its middle (nearest filter, full resolution, with skipping). The paper (RTX 3090, \
         1920×1080, N_S = 20): SSIM 0.97 near the viewpoint of generation, a minor loss up to \
         40°, about 45 fps.\n"
    )
    .expect("writing to a String cannot fail");
    out
}

/// The plot of `r`: SSIM against deviation (one line per `N_S`, the linear filter at the
/// first `N_S`, and the goals) and ms per frame (the VDI per `N_S`, the linear filter, and
/// DVR), written as PNG to `path`.
///
/// # Errors
/// A [`PlotError`] when the plot cannot be drawn or written.
pub fn plot(r: &VdiBenchResults, path: &std::path::Path) -> Result<(), PlotError> {
    let ms = |wall: f64, gpu: Option<f64>| gpu.unwrap_or(wall);
    let per_count = |value: &dyn Fn(&VdiViewRecord) -> f64| -> Vec<Line> {
        r.sizes
            .iter()
            .map(|s| Line {
                label: format!("VDI, N_S {}", s.supersegments),
                points: r
                    .views
                    .iter()
                    .filter(|v| v.supersegments == s.supersegments)
                    .map(|v| (v.deviation_degrees, value(v)))
                    .collect(),
            })
            .collect()
    };
    // The first N_S's views, for the linear filter's and DVR's lines.
    let first: Vec<&VdiViewRecord> = r.sizes.first().map_or_else(Vec::new, |first| {
        r.views
            .iter()
            .filter(|v| v.supersegments == first.supersegments)
            .collect()
    });
    let of_first = |label: String, value: &dyn Fn(&VdiViewRecord) -> f64| Line {
        label,
        points: first
            .iter()
            .map(|v| (v.deviation_degrees, value(v)))
            .collect(),
    };
    let linear_label = || {
        r.sizes.first().map_or_else(String::new, |s| {
            format!("VDI, linear filter, N_S {}", s.supersegments)
        })
    };
    let mut ssim = per_count(&|v| v.ssim);
    ssim.push(of_first(linear_label(), &|v| v.linear_ssim));
    ssim.push(Line {
        label: "goal".into(),
        points: vec![(0.0, 0.97), (10.0, 0.97), (30.0, 0.94), (40.0, 0.94)],
    });
    let mut times = per_count(&|v| ms(v.vdi_ms, v.vdi_gpu_ms));
    if !first.is_empty() {
        times.push(of_first(linear_label(), &|v| {
            ms(v.linear_ms, v.linear_gpu_ms)
        }));
        times.push(of_first("DVR".into(), &|v| ms(v.dvr_ms, v.dvr_gpu_ms)));
    }
    panels(
        path,
        &format!("{}: VDI against DVR ({}×{})", r.label, r.width, r.height),
        "degrees from the camera of generation",
        &[("SSIM against DVR", ssim), ("ms per frame", times)],
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn turning_keeps_the_distance_and_the_target() {
        let camera = Camera {
            eye: [10.0, 0.0, 0.0],
            target: [0.0; 3],
            up: [0.0, 0.0, 1.0],
            fov_y_degrees: 30.0,
        };
        let t = turned(&camera, 90.0);
        assert!((t.eye[0]).abs() < 1e-12 && (t.eye[1].abs() - 10.0).abs() < 1e-12);
        assert_eq!(t.eye[2], 0.0);
        assert_eq!(t.target, camera.target);
        assert_eq!(turned(&camera, 0.0).eye, camera.eye);
    }
}
