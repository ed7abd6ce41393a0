//! The driver of the suite ([`Bench`]): one source, scene and device, the orbit of views and
//! their f64 reference images, and one configuration measured over the orbit
//! ([`Bench::run`]). The experiments built on it are in `experiments`.

use std::sync::Arc;
use std::time::Instant;

use super::error::BenchError;
use super::experiment::Experiment;
use super::naive;
use super::plan::Plan;
use super::records::{OptionsRecord, RunRecord, SweepParam, ViewRecord};
use crate::defaults::CameraSpec;
use crate::gpu::GpuError;
use crate::gpu::device::Gpu;
use crate::gpu::renderer::{Method, RenderOptions, Renderer};
use crate::gpu::streaming::{Budget, Fetcher, Progressive, converge};
use crate::image::RgbImage;
use crate::metrics;
use crate::reference::{self, ReferenceOptions};
use crate::scene::{Camera, Scene};
use crate::source::{BrickSource, VolumeInfo};

/// The median of `v` (sorted in place; NaN when empty).
pub(super) fn median(v: &mut [f64]) -> f64 {
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

/// The PSNR of `m`, `None` when the images are identical.
pub(super) fn finite_psnr(m: &metrics::Metrics) -> Option<f64> {
    m.psnr_db.is_finite().then_some(m.psnr_db)
}

/// The RGB image of RGBA `pixels`.
pub(super) fn to_image(width: u32, height: u32, pixels: &[[f32; 4]]) -> RgbImage {
    RgbImage::from_rgba(width, height, pixels)
}

/// The driver: one source, scene, device, orbit and set of reference images.
pub struct Bench {
    pub(super) gpu: Gpu,
    /// A second device for the methods that rasterise ray segment lists. On lavapipe, once a
    /// render pass has run on a device, every later compute pass's timestamps on it come out
    /// nearly equal (measured: the residency renderer's GPU time fell from 5.5 ms to 0.006 ms
    /// after a SparseLeap renderer had run, its wall time unchanged), so those methods get a
    /// device of their own and the others keep honest GPU times.
    pub(super) raster_gpu: std::sync::OnceLock<Gpu>,
    pub(super) source: Arc<dyn BrickSource>,
    pub(super) scene: Scene,
    pub(super) base: RenderOptions,
    pub(super) plan: Plan,
    pub(super) cameras: Vec<(f64, Camera)>,
    pub(super) references: Vec<RgbImage>,
    pub(super) reference_s: f64,
    pub(super) bar: indicatif::ProgressBar,
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

    pub(super) fn info(&self) -> &VolumeInfo {
        self.source.info()
    }

    pub(super) fn budget(&self) -> Budget {
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

    pub(super) fn requested_empty(&self, p: &Progressive) -> u64 {
        p.request_log
            .iter()
            .filter(|k| naive::transparent(self.info(), &self.scene, k))
            .count() as u64
    }

    /// The device the renderers of `method` run on (see `raster_gpu`).
    pub(super) fn device_for(&self, method: Method) -> Result<&Gpu, GpuError> {
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
        let mut without_readback_ms = Vec::new();
        let mut last = None;
        for _ in 0..self.plan.timed_frames {
            let t = Instant::now();
            let out = renderer.render(gpu)?;
            wall_ms.push(t.elapsed().as_secs_f64() * 1e3);
            if let Some(g) = out.gpu_time_ms {
                gpu_ms.push(g);
            }
            last = Some(out);
            // The same frame again, its image left on the GPU.
            let t = Instant::now();
            renderer.render_without_pixels(gpu)?;
            without_readback_ms.push(t.elapsed().as_secs_f64() * 1e3);
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
            stop_reason: p.stop_reason,
            frames_to_converge: p.frames.len(),
            bricks_fetched: p.frames.iter().map(|f| f.bricks_fetched).sum(),
            bytes_fetched: p.frames.iter().map(|f| f.bytes_fetched).sum(),
            bricks_requested: p.request_log.len() as u64,
            requested_empty: self.requested_empty(&p),
            gpu_ms: (!gpu_ms.is_empty()).then(|| median(&mut gpu_ms)),
            wall_ms: median(&mut wall_ms),
            wall_ms_without_readback: Some(median(&mut without_readback_ms)),
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
    pub(crate) fn run(
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
            wall_ms_without_readback: views
                .iter()
                .map(|v| v.wall_ms_without_readback)
                .sum::<Option<f64>>()
                .map(|sum| sum / n),
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

    /// Converges a fresh renderer (cold cache) on view `k` and returns it with the result.
    pub(super) fn cold(
        &self,
        k: usize,
        options: RenderOptions,
    ) -> Result<(Renderer, Progressive), GpuError> {
        let mut scene = self.scene.clone();
        scene.camera = self.cameras[k].1.clone();
        let mut renderer = Renderer::new(&self.gpu, self.info(), &scene, options)?;
        let fetcher = Fetcher::new(Arc::clone(&self.source), self.plan.workers, 16);
        let p = converge(&self.gpu, &mut renderer, &fetcher, &self.budget())?;
        self.bar.inc(1);
        Ok((renderer, p))
    }
}
