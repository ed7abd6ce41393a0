//! The experiments of the suite on the [`Bench`] driver: Table 1 (with the limit probe), the
//! time–error sweep, skipped work against the naive loader and the scaling point, and
//! [`Bench::run_all`], which runs a plan's experiments into a [`BenchResults`].

use std::time::Instant;

use super::driver::{Bench, finite_psnr, median, to_image};
use super::error::BenchError;
use super::experiment::Experiment;
use super::naive;
use super::plan::SweepValues;
use super::records::{
    BenchResults, DatasetInfo, DeviceInfo, FORMAT, ProbeRecord, RunRecord, Settings, SkippedRecord,
    SweepParam, SweptParameter,
};
use crate::gpu::probe::LimitProbe;
use crate::gpu::renderer::{Method, RenderOptions};
use crate::metrics;
use crate::octree::OctreeGeometry;
use crate::scene::RenderMode;

impl Bench {
    /// Table 1: every configured method over the orbit.
    ///
    /// # Errors
    /// The first failed run's, as [`Bench::run`].
    pub(crate) fn table1(&self) -> Result<Vec<RunRecord>, BenchError> {
        self.plan
            .methods
            .iter()
            .map(|&config| {
                let options = RenderOptions {
                    method: config.method,
                    empty_space_skipping: config.skipping,
                    ..self.base.clone()
                };
                self.run(Experiment::Table1, config.label(), options, None)
            })
            .collect()
    }

    /// Time against error: the defaults, then each parameter swept alone.
    ///
    /// # Errors
    /// The first failed run's, as [`Bench::run`].
    pub(crate) fn sweep(&self) -> Result<Vec<RunRecord>, BenchError> {
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
    pub(crate) fn scaling(&self) -> Result<Vec<RunRecord>, BenchError> {
        Ok(vec![self.run(
            Experiment::Scaling,
            "residency".into(),
            self.base.clone(),
            None,
        )?])
    }

    /// Skipped work: per view, ours from a cold cache against the naive frustum loader.
    ///
    /// # Errors
    /// A renderer's or frame's [`GpuError`](crate::gpu::GpuError), or a
    /// [`MetricsError`](crate::metrics::MetricsError) comparing an image with its reference.
    pub(crate) fn skipped(&self) -> Result<Vec<SkippedRecord>, BenchError> {
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
    /// The probe's [`GpuError`](crate::gpu::GpuError) (say, a volume over one 3D texture), or
    /// [`BenchError::Probe`] naming the view whose image cannot be compared.
    pub(crate) fn probe(&self) -> Result<Vec<ProbeRecord>, BenchError> {
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
                    let probed = if self.scene.mode == RenderMode::Dvr {
                        self.probe()
                    } else {
                        Err(BenchError::ProbeMode {
                            mode: self.scene.mode.name(),
                        })
                    };
                    match probed {
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
                mode: self.scene.mode,
            },
            experiments: self.plan.experiments.clone(),
            runs,
            skipped,
            probe,
            probe_error,
        })
    }
}
