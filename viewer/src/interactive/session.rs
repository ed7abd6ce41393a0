//! The progressive render behind the window, advanced one step at a time so the event loop
//! stays responsive: each [`Session::step`] inserts whatever bricks the fetch workers have
//! finished, renders a frame when the view or the resident data changed, and hands the
//! frame's missing bricks (coarse before fine, near before far, only what the cache can
//! take) to the [`Fetcher`], which drops the queued requests of earlier views. This is the
//! loop of [`crate::gpu::streaming::converge`] without its blocking wait.
//!
//! A camera change keeps the renderer (and its resident bricks), and so does a change of
//! colours, transfer functions or background. Showing or hiding a channel, or a new image
//! size, rebuilds the renderer: its cache starts empty and the bricks are fetched again.

use std::sync::Arc;
use std::time::{Duration, Instant};

use crate::gpu::GpuError;
use crate::gpu::device::Gpu;
use crate::gpu::renderer::{Inserted, RenderOptions, Renderer};
use crate::gpu::streaming::{Fetcher, FrameStats, StreamState};
use crate::scene::{Camera, Scene};
use crate::source::{BrickKey, BrickSource, BrickVoxels, SourceError, VolumeInfo};

/// What one [`Session::step`] did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Step {
    /// A new frame is ready.
    Rendered,
    /// Waiting for bricks; nothing new to show.
    Waiting,
    /// Nothing left to do until the view changes.
    Idle,
}

/// Totals over the session.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Totals {
    /// Frames rendered.
    pub frames: u64,
    /// Bricks fetched and inserted.
    pub bricks_fetched: u64,
    /// Decoded bytes of those bricks.
    pub bytes_fetched: u64,
    /// Bricks whose fetch or upload failed.
    pub bricks_failed: u64,
    /// Renderer rebuilds (style or size changes).
    pub rebuilds: u64,
}

/// The progressive renderer of one volume for an interactive view.
pub struct Session {
    gpu: Gpu,
    info: VolumeInfo,
    fetcher: Fetcher,
    options: RenderOptions,
    scene: Scene,
    renderer: Option<Renderer>,
    /// Channels the current renderer draws.
    drawn: Vec<usize>,
    rebuild: bool,
    render_needed: bool,
    stream: StreamState,
    /// Fetched since the last frame (reported with the next one).
    pending: FrameStats,
    last: Option<FrameStats>,
    pixels: Vec<[f32; 4]>,
    /// Size of the last frame (of `pixels` where they are read back).
    image_size: (u32, u32),
    /// Whether frames are read back into `pixels` (a CPU blit), or left on the GPU.
    read_pixels: bool,
    /// With no channel visible and frames left on the GPU: the background image there.
    blank: Option<wgpu::Buffer>,
    size: (u32, u32),
    status: String,
    totals: Totals,
}

impl Session {
    /// A session over `source` drawing `scene` with `options` (whose size is the first image
    /// size), with `workers` fetch threads fetching `batch` bricks per call.
    pub fn new(
        gpu: Gpu,
        source: Arc<dyn BrickSource>,
        scene: Scene,
        options: RenderOptions,
        workers: usize,
        batch: usize,
    ) -> Self {
        let info = source.info().clone();
        let size = (options.width.max(1), options.height.max(1));
        Self {
            fetcher: Fetcher::new(source, workers, batch),
            gpu,
            info,
            options,
            scene,
            renderer: None,
            drawn: Vec::new(),
            rebuild: true,
            render_needed: true,
            stream: StreamState::default(),
            pending: FrameStats::default(),
            last: None,
            pixels: Vec::new(),
            image_size: (0, 0),
            read_pixels: true,
            blank: None,
            size,
            status: "starting".into(),
            totals: Totals::default(),
        }
    }

    /// The GPU.
    pub fn gpu(&self) -> &Gpu {
        &self.gpu
    }

    /// The volume.
    pub fn info(&self) -> &VolumeInfo {
        &self.info
    }

    /// The scene as drawn (or about to be).
    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    /// Replaces the camera; the next step renders it with the bricks already resident.
    pub fn set_camera(&mut self, camera: Camera) {
        if camera != self.scene.camera {
            self.scene.camera = camera.clone();
            if let Some(r) = &mut self.renderer {
                r.set_camera(camera);
            }
            self.render_needed = true;
        }
    }

    /// Replaces the whole scene (channel styles, background). Colours, transfer functions
    /// and the background change in place, keeping every resident brick
    /// ([`Renderer::restyle`]); the renderer is rebuilt at the next step only when the set of
    /// visible channels changed.
    pub fn set_scene(&mut self, scene: Scene) {
        if !scene.same_style(&self.scene) {
            // Nothing visible shows the background without a renderer.
            let restyled = scene.channels.iter().any(|c| c.visible)
                && self
                    .renderer
                    .as_mut()
                    .is_some_and(|r| r.restyle(&self.gpu, &scene));
            if !restyled {
                self.rebuild = true;
            }
        }
        self.set_camera(scene.camera.clone());
        self.scene = scene;
        self.render_needed = true;
    }

    /// Sets the image size; the renderer is rebuilt at the next step if it changed.
    pub fn set_size(&mut self, width: u32, height: u32) {
        let size = (width.max(1), height.max(1));
        if size != self.size {
            self.size = size;
            self.rebuild = true;
            self.render_needed = true;
        }
    }

    /// The image size the next frame will have.
    pub fn size(&self) -> (u32, u32) {
        self.size
    }

    /// The last frame: `(width, height, linear RGBA pixels)` (no pixels while frames are
    /// left on the GPU, see [`Session::set_read_pixels`]).
    pub fn image(&self) -> (u32, u32, &[[f32; 4]]) {
        (self.image_size.0, self.image_size.1, &self.pixels)
    }

    /// Whether frames are read back to [`Session::image`] (`true`, the default: a CPU blit
    /// shows them) or left on the GPU for presenting there ([`Session::gpu_image`]).
    pub fn set_read_pixels(&mut self, read: bool) {
        if read != self.read_pixels {
            self.read_pixels = read;
            self.rebuild = true;
            self.render_needed = true;
        }
    }

    /// The last frame on the GPU: the buffer (linear RGBA `vec4<f32>` per pixel, row-major
    /// from the top) and its size; `None` before the first frame.
    pub fn gpu_image(&self) -> Option<(&wgpu::Buffer, (u32, u32))> {
        match (&self.renderer, &self.blank) {
            (Some(r), _) if r.frames() > 0 => Some((r.image_buffer(), self.image_size)),
            (None, Some(blank)) => Some((blank, self.image_size)),
            _ => None,
        }
    }

    /// Statistics of the last frame rendered.
    pub fn last_frame(&self) -> Option<&FrameStats> {
        self.last.as_ref()
    }

    /// Totals over the session.
    pub fn totals(&self) -> &Totals {
        &self.totals
    }

    /// What the session is doing, in words.
    pub fn status(&self) -> &str {
        &self.status
    }

    fn build(&mut self) -> Result<(), GpuError> {
        self.rebuild = false;
        self.render_needed = true;
        self.renderer = None;
        self.blank = None;
        // Queued requests were for the old renderer; fetches under way still complete and
        // are inserted if their channel is still drawn.
        self.fetcher.submit(Vec::new());
        self.drawn = self
            .scene
            .channels
            .iter()
            .filter(|c| c.visible)
            .map(|c| c.channel)
            .collect();
        self.stream.retain_channels(&self.drawn);
        if self.drawn.is_empty() {
            let bg = self.scene.background.map(|v| v as f32);
            let (w, h) = self.size;
            self.pixels = vec![[bg[0], bg[1], bg[2], 0.0]; (w * h) as usize];
            self.image_size = (w, h);
            if !self.read_pixels {
                let bytes: &[u8] = bytemuck::cast_slice(&self.pixels);
                let blank = crate::gpu::buffers::storage_buffer(
                    &self.gpu,
                    "background image",
                    bytes.len() as u64,
                    wgpu::BufferUsages::COPY_SRC,
                );
                self.gpu.queue.write_buffer(&blank, 0, bytes);
                self.blank = Some(blank);
            }
            self.status = "no channel visible".into();
            return Ok(());
        }
        let levels = self.info.levels.len() as u32;
        let bounds = self.options.level_bounds.first().copied();
        let options = RenderOptions {
            width: self.size.0,
            height: self.size.1,
            level_bounds: vec![bounds.unwrap_or((0, levels - 1)); self.drawn.len()],
            ..self.options.clone()
        };
        self.renderer = Some(Renderer::new(&self.gpu, &self.info, &self.scene, options)?);
        self.totals.rebuilds += 1;
        Ok(())
    }

    /// Inserts finished fetches; returns whether anything changed what a frame would show.
    fn insert(&mut self, done: Vec<(BrickKey, Result<BrickVoxels, SourceError>)>) -> bool {
        let mut changed = false;
        for (key, result) in done {
            let Some(renderer) = self.renderer.as_mut() else {
                continue;
            };
            if !self.drawn.contains(&(key.channel as usize)) {
                continue; // fetched for an earlier set of channels
            }
            let arrived = self
                .stream
                .arrived(&self.gpu, renderer, key, result, &mut self.pending);
            if let Some((i, bytes)) = arrived {
                self.totals.bricks_fetched += 1;
                self.totals.bytes_fetched += bytes;
                changed |= !matches!(i, Inserted::AlreadyResident | Inserted::CacheFull);
            } else {
                self.totals.bricks_failed += 1;
                changed = true;
            }
        }
        changed
    }

    /// Advances the progressive render by one step. When there is nothing to render it
    /// waits for fetches up to `wait` (at least a millisecond).
    ///
    /// # Errors
    /// The renderer's [`GpuError`] when it cannot be (re)built or a frame fails; bricks that
    /// cannot be fetched are counted, not errors.
    pub fn step(&mut self, wait: Duration) -> Result<Step, GpuError> {
        if self.rebuild {
            self.build()?;
        }
        let start = Instant::now();
        // Nothing to render: wait for fetches (at least a moment, so that an empty queue
        // shows as drained below).
        let wait = if self.render_needed {
            Duration::ZERO
        } else {
            wait.max(Duration::from_millis(1))
        };
        let deadline = start + wait;
        let done = self.fetcher.wait(Some(deadline));
        // `wait` returns before its deadline only once nothing is queued or in flight.
        let drained = Instant::now() < deadline;
        if self.insert(done) {
            self.render_needed = true;
        }
        let Some(renderer) = self.renderer.as_mut() else {
            if std::mem::take(&mut self.render_needed) {
                self.totals.frames += 1;
                return Ok(Step::Rendered);
            }
            return Ok(Step::Idle);
        };
        if !self.render_needed {
            return Ok(if drained { Step::Idle } else { Step::Waiting });
        }
        self.render_needed = false;
        let out = if self.read_pixels {
            renderer.render(&self.gpu)?
        } else {
            renderer.render_without_pixels(&self.gpu)?
        };
        self.pixels = out.pixels;
        self.image_size = (renderer.options().width, renderer.options().height);
        self.totals.frames += 1;
        let mut stats = FrameStats {
            frame: self.totals.frames as u32,
            shader: out.counts,
            gpu_time_ms: out.gpu_time_ms,
            ..std::mem::take(&mut self.pending)
        };
        let over_cap = stats.shader.requests_over_cap > 0;
        let keys = match self
            .stream
            .wanted(renderer, out.requests, stats.shader.requests_over_cap)
        {
            None => {
                self.status = "converged".into();
                Vec::new()
            }
            Some(wanted) => {
                let any = !wanted.is_empty();
                let keys = StreamState::to_fetch(renderer, wanted, &mut stats);
                self.status = if any && keys.is_empty() {
                    "cache full".into()
                } else {
                    format!("streaming {} bricks", keys.len())
                };
                keys
            }
        };
        let fetching = !keys.is_empty();
        stats.requests_cancelled = self.fetcher.submit(keys) as u64;
        // Requests over the shader's cap show up once the first ones are resident.
        self.render_needed = over_cap && fetching;
        stats.wall_ms = start.elapsed().as_secs_f64() * 1e3;
        tracing::debug!("frame {}: {:?}", stats.frame, stats);
        self.last = Some(stats);
        Ok(Step::Rendered)
    }
}
