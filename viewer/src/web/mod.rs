//! The browser driver: the same [`Renderer`], octree, page tables, streaming policy
//! ([`StreamState`]) and compositing as `viewer render`, driven by `fetch` and the page's
//! `requestAnimationFrame` loop instead of worker threads.
//!
//! JavaScript sees one class, [`Viewer`] (built by `wasm-bindgen`; the page's `main.js`
//! drives it and defines `window.residency`). A [`Viewer::step`] files the bricks that
//! arrived, renders a frame when the view or the resident data changed, and sends the frame's
//! missing bricks to the server in batches, without waiting for them. Camera, style and
//! visibility changes rewrite the scene tables in place ([`Renderer::restyle`]): nothing is
//! rebuilt or fetched again.
//!
//! - [`fetch`]: the browser's `fetch` as the protocol's transport;
//! - [`present`]: frames onto the page's canvas, on the GPU (WebGPU canvas context) or by
//!   the CPU path;
//! - [`remote`]: the remote mode, VDIs of a render service (`viewer serve`) ray cast for the
//!   page's camera instead of bricks streamed;
//! - [`vdi_reader`]: the render service's answers read in the page's worker
//!   (`vdi_worker.js`), off the main thread.

pub mod fetch;
pub mod present;
pub mod remote;
pub mod vdi_reader;

use std::cell::RefCell;
use std::collections::HashSet;
use std::rc::Rc;

use serde::Serialize;
use wasm_bindgen::prelude::*;

use self::fetch::BrowserFetch;
use crate::defaults::{check_channel, default_scene, volume_extent};
use crate::error_chain;
use crate::gpu::GpuError;
use crate::gpu::device::Gpu;
use crate::gpu::renderer::{RenderOptions, Renderer};
use crate::gpu::streaming::{FrameStats, StreamState};
use crate::interactive::{camera_control, controls};
use crate::scene::orientation::Orientation;
use crate::scene::{Clip, Filter, RenderMode, Scene};
use crate::source::{BrickKey, BrickVoxels, SourceError, VolumeInfo, server};

/// Bricks per `/bricks` request from the page: small batches refine the image sooner.
const PAGE_BATCH: usize = 32;

/// Most `/bricks` requests in flight at once (a browser's connections per host).
const MAX_REQUESTS_IN_FLIGHT: usize = 6;

/// Orbit speed of a drag.
const RADIANS_PER_PIXEL: f64 = 0.01;

/// Largest canvas side the page renders.
const MAX_SIDE: u32 = 4096;

/// Why the page's viewer could not open: an image size out of range, no WebGPU device, or a
/// dataset that cannot be opened. The page shows the whole chain ([`error_chain`]), as it does
/// for the renderer's and the scene's errors.
#[derive(Debug, thiserror::Error)]
pub enum WebError {
    /// A canvas side outside `1..=MAX_SIDE`.
    #[error("image size {width}×{height}: each side must lie in 1..={}", MAX_SIDE)]
    ImageSize {
        /// Width asked for.
        width: u32,
        /// Height asked for.
        height: u32,
    },
    /// The device failed.
    #[error(transparent)]
    Gpu(Box<GpuError>),
    /// The dataset cannot be opened.
    #[error(transparent)]
    Source(Box<SourceError>),
}

impl From<GpuError> for WebError {
    fn from(e: GpuError) -> Self {
        Self::Gpu(Box::new(e))
    }
}

impl From<SourceError> for WebError {
    fn from(e: SourceError) -> Self {
        Self::Source(Box::new(e))
    }
}

/// The page's clock (`performance.now()`, ms), on its main thread and in its workers alike; 0
/// where there is none.
fn now_ms() -> f64 {
    js_sys::Reflect::get(&js_sys::global(), &JsValue::from_str("performance"))
        .ok()
        .and_then(|p| p.dyn_into::<web_sys::Performance>().ok())
        .map_or(0.0, |p| p.now())
}

/// An error as the text JavaScript sees: its whole chain.
fn js_error(e: &(dyn std::error::Error + 'static)) -> JsValue {
    JsValue::from_str(&error_chain(e))
}

/// Totals over the page's life, and the last frame's counters, as `state()` reports them.
#[derive(Clone, Debug, Default, Serialize)]
struct Totals {
    frame: u32,
    converged: bool,
    bricks_requested: u64,
    bricks_fetched: u64,
    bytes_fetched: u64,
    bricks_failed: u64,
    bricks_resident: u64,
    requests_in_flight: usize,
    gpu_time_ms: Option<f64>,
    renderer_builds: u32,
    error: Option<String>,
    /// How frames reach the canvas: `"gpu"` (presented from the image buffer) or `"cpu"`
    /// (read back and drawn with `putImageData`).
    present: &'static str,
    /// Why the page presents by the CPU path where it tried the GPU.
    present_error: Option<String>,
    /// Images read back from the GPU so far: one a frame by the CPU path, one a
    /// `snapshot()` on the GPU path.
    image_readbacks: u64,
    /// The remote mode's counters, when a render service is given.
    remote: Option<remote::RemoteReport>,
}

/// What the viewer of one dataset holds between steps.
struct Inner {
    gpu: Rc<Gpu>,
    base: String,
    info: Rc<VolumeInfo>,
    options: RenderOptions,
    /// The scene wanted; the renderer catches up at the next step.
    scene: Scene,
    /// The wanted style differs from the renderer's: restyle or rebuild at the next step.
    scene_changed: bool,
    /// `None` before the first step and while a step holds it.
    renderer: Option<Renderer>,
    stepping: bool,
    stream: StreamState,
    /// Fetches finished since the last step.
    arrived: Vec<(BrickKey, Result<BrickVoxels, SourceError>)>,
    in_flight: HashSet<BrickKey>,
    requests_in_flight: usize,
    /// Fetch results filed since the last frame (reported with the next one).
    pending: FrameStats,
    render_needed: bool,
    /// The last frame as 8-bit sRGB RGBA (alpha 255), ready for `putImageData` (the CPU
    /// path only).
    rgba: Vec<u8>,
    /// The canvas surface, when frames are presented on the GPU.
    canvas: Option<present::CanvasPresenter>,
    /// The frame on the canvas (the GPU path), for `snapshot()`.
    shown: Option<present::Shown>,
    totals: Totals,
    /// The remote mode, when the page has a render service.
    remote: Option<remote::Remote>,
}

/// The residency-octree viewer of one brickserver dataset, drawn by the page.
#[wasm_bindgen]
pub struct Viewer {
    inner: Rc<RefCell<Inner>>,
}

/// Installs the panic hook (panics show in the console with their message).
#[wasm_bindgen(start)]
pub fn start() {
    console_error_panic_hook::set_once();
}

#[wasm_bindgen]
impl Viewer {
    /// Opens dataset `dataset` on the brickserver at `server` (`""`: this page's origin),
    /// rendering `width × height` pixels: WebGPU device, then the dataset's metadata and
    /// region metadata.
    ///
    /// # Errors
    /// Rejects with a message for people, the [`WebError`]'s whole chain: no WebGPU, an image
    /// size out of range, no such dataset, server unreachable.
    pub async fn open(
        server: String,
        dataset: String,
        width: u32,
        height: u32,
    ) -> Result<Viewer, JsValue> {
        Self::try_open(&server, &dataset, width, height)
            .await
            .map_err(|e| js_error(&e))
    }

    async fn try_open(
        server: &str,
        dataset: &str,
        width: u32,
        height: u32,
    ) -> Result<Viewer, WebError> {
        if !((1..=MAX_SIDE).contains(&width) && (1..=MAX_SIDE).contains(&height)) {
            return Err(WebError::ImageSize { width, height });
        }
        let gpu = Gpu::open().await?;
        let base = server::dataset_url(server, dataset);
        let info = server::open(&BrowserFetch, &base, dataset).await?;
        let scene = default_scene(&info);
        let options = RenderOptions {
            width,
            height,
            // A share of what the device can hold, as `viewer render` sizes its default.
            cache_bytes: RenderOptions::default()
                .cache_bytes
                .min(gpu.limits.max_buffer_size / 2),
            ..RenderOptions::default()
        };
        Ok(Viewer {
            inner: Rc::new(RefCell::new(Inner {
                gpu: Rc::new(gpu),
                base,
                info: Rc::new(info),
                options,
                scene,
                scene_changed: false,
                renderer: None,
                stepping: false,
                stream: StreamState::default(),
                arrived: Vec::new(),
                in_flight: HashSet::new(),
                requests_in_flight: 0,
                pending: FrameStats::default(),
                render_needed: true,
                rgba: Vec::new(),
                canvas: None,
                shown: None,
                totals: Totals {
                    present: "cpu",
                    ..Totals::default()
                },
                remote: None,
            })),
        })
    }

    /// The image width in pixels.
    pub fn width(&self) -> u32 {
        self.inner.borrow().options.width
    }

    /// The image height in pixels.
    pub fn height(&self) -> u32 {
        self.inner.borrow().options.height
    }

    /// The orientation of the scene's camera on a view `height` CSS pixels high, JSON
    /// ([`Orientation`]: `{scale: {length, unit, pixels}, axes: {x, y, z}}`, each axis the
    /// screen direction `[right, down]` of its unit vector), or `null` for a camera at its
    /// target or a view with no height: what the page's overlay draws, worked out by the rule
    /// `viewer view` draws by.
    pub fn orientation_json(&self, height: f64) -> String {
        let inner = self.inner.borrow();
        let o = Orientation::of(&inner.scene.camera, height, inner.info.unit.as_deref());
        serde_json::to_string(&o).expect("orientations serialize")
    }

    /// The dataset as the page's controls need it, JSON: name, sample type, channel names
    /// and display hints (`omero` window, range, colour), levels and adapter.
    pub fn info_json(&self) -> String {
        let inner = self.inner.borrow();
        let info = &inner.info;
        serde_json::json!({
            "name": info.name,
            "data_type": info.sample_type.zarr_name(),
            "channels": info.channels,
            "display": info.display.iter().map(|d| serde_json::json!({
                "window": d.window, "range": d.range, "color": d.color,
            })).collect::<Vec<_>>(),
            "levels": info.levels.iter().map(|l| l.shape).collect::<Vec<_>>(),
            "brick_shape": info.brick_shape,
            "region_metadata": info.minmax.is_some(),
            "extent": volume_extent(info),
            "unit": info.unit,
            "adapter": inner.gpu.adapter_info.name,
            "timestamps": inner.gpu.timestamps,
        })
        .to_string()
    }

    /// The scene drawn (or about to be), as scene-file JSON.
    pub fn scene_json(&self) -> String {
        serde_json::to_string(&self.inner.borrow().scene).expect("scenes serialize")
    }

    /// Replaces the scene with scene-file JSON (`schemas/json/scene.schema.json`).
    ///
    /// # Errors
    /// The [`SceneDocumentError`](crate::scene::SceneDocumentError) or
    /// [`SceneError`](crate::defaults::SceneError) message, scene unchanged, for JSON
    /// that is not a scene or draws a channel the dataset does not have.
    pub fn set_scene_json(&self, json: &str) -> Result<(), JsValue> {
        let scene = Scene::from_json(json.as_bytes(), "scene").map_err(|e| js_error(&e))?;
        let mut inner = self.inner.borrow_mut();
        for s in &scene.channels {
            check_channel(&inner.info, s.channel, "scene").map_err(|e| js_error(&e))?;
        }
        inner.set_scene(scene);
        Ok(())
    }

    /// Orbits the camera by a drag of `(dx, dy)` pixels.
    pub fn orbit(&self, dx: f64, dy: f64) {
        self.inner.borrow_mut().edit(|scene, _, _| {
            scene.camera = camera_control::orbit(&scene.camera, dx, dy, RADIANS_PER_PIXEL);
        });
    }

    /// Pans the camera by a drag of `(dx, dy)` pixels.
    pub fn pan(&self, dx: f64, dy: f64) {
        self.inner.borrow_mut().edit(|scene, _, height| {
            scene.camera = camera_control::pan(&scene.camera, dx, dy, f64::from(height));
        });
    }

    /// Zooms by `steps` wheel steps (positive: closer; four halve the distance).
    pub fn zoom(&self, steps: f64) {
        self.inner.borrow_mut().edit(|scene, info, _| {
            let min = info
                .voxel_size
                .iter()
                .copied()
                .fold(f64::INFINITY, f64::min);
            scene.camera = camera_control::zoom(&scene.camera, steps, min);
        });
    }

    /// Back to the default view of the dataset.
    pub fn reset(&self) {
        self.inner.borrow_mut().edit(|scene, info, _| {
            *scene = default_scene(info);
        });
    }

    /// Sets the reconstruction filter by name (`trilinear` or `tricubic`): a new renderer at
    /// the next step, since the filter's culling ranges differ.
    ///
    /// # Errors
    /// The [`UnknownFilter`](crate::scene::UnknownFilter) message, scene unchanged.
    pub fn set_filter(&self, name: &str) -> Result<(), JsValue> {
        let filter: Filter = name.parse().map_err(|e| js_error(&e))?;
        self.inner
            .borrow_mut()
            .edit(|scene, _, _| scene.filter = filter);
        Ok(())
    }

    /// Sets what each ray makes of its samples by name (`dvr`, `mip` or `iso`): a new renderer at the
    /// next step (the mode is compiled into its pipeline). The remote mode's VDIs are `dvr`
    /// only: in another mode the page draws from bricks.
    ///
    /// # Errors
    /// The [`UnknownMode`](crate::scene::UnknownMode) message, scene unchanged.
    pub fn set_mode(&self, name: &str) -> Result<(), JsValue> {
        let mode: RenderMode = name.parse().map_err(|e| js_error(&e))?;
        self.inner
            .borrow_mut()
            .edit(|scene, _, _| scene.mode = mode);
        Ok(())
    }

    /// Sets what part of the volume is drawn: scene-file JSON of the scene's `clip`
    /// (`{"box": {"min": [...], "max": [...]}, "planes": [...], "near": D}`, any part left out).
    /// The residency state stays: bricks outside are no longer fetched, those inside are kept.
    ///
    /// # Errors
    /// serde's message for JSON that is no clip, or the [`ClipError`](crate::scene::ClipError)
    /// message; scene unchanged.
    pub fn set_clip(&self, json: &str) -> Result<(), JsValue> {
        let clip: Clip = serde_json::from_str(json).map_err(|e| js_error(&e))?;
        clip.check().map_err(|e| js_error(&e))?;
        self.inner
            .borrow_mut()
            .edit(|scene, _, _| scene.clip = clip);
        Ok(())
    }

    /// Shows or hides channel `channel`.
    pub fn set_visible(&self, channel: usize, visible: bool) {
        self.inner.borrow_mut().edit(|scene, info, _| {
            if let Some(s) = controls::style_mut(scene, info, channel) {
                s.visible = visible;
            }
        });
    }

    /// Sets channel `channel`'s colour (linear RGB in `[0, 1]`).
    pub fn set_color(&self, channel: usize, r: f64, g: f64, b: f64) {
        self.inner.borrow_mut().edit(|scene, info, _| {
            if let Some(s) = controls::style_mut(scene, info, channel) {
                s.color = [r, g, b].map(|v| v.clamp(0.0, 1.0));
            }
        });
    }

    /// Moves channel `channel`'s window (the span of its opacity ramp) to `[lo, hi]`.
    pub fn set_window(&self, channel: usize, lo: f64, hi: f64) {
        if !(lo.is_finite() && hi.is_finite() && hi > lo) {
            return;
        }
        self.inner.borrow_mut().edit(|scene, info, _| {
            if let Some(s) = controls::style_mut(scene, info, channel) {
                controls::set_window(&mut s.opacity, lo, hi);
            }
        });
    }

    /// Scales channel `channel`'s opacity ramp so that its highest point is `opacity`.
    pub fn set_opacity(&self, channel: usize, opacity: f64) {
        let opacity = opacity.clamp(0.0, 1.0);
        self.inner.borrow_mut().edit(|scene, info, _| {
            if let Some(s) = controls::style_mut(scene, info, channel) {
                controls::set_top_opacity(&mut s.opacity, opacity);
            }
        });
    }

    /// One step of the progressive loop; resolves to whether a new frame is ready
    /// ([`Viewer::rgba`]). Never runs two at once (a second call resolves to `false`).
    pub fn step(&self) -> js_sys::Promise {
        let inner = Rc::clone(&self.inner);
        wasm_bindgen_futures::future_to_promise(async move {
            let rendered = step(&inner).await;
            let mut i = inner.borrow_mut();
            i.stepping = false;
            match rendered {
                Ok(r) => Ok(JsValue::from_bool(r)),
                Err(e) => {
                    let message = error_chain(&e);
                    i.totals.error = Some(message.clone());
                    Err(JsValue::from_str(&message))
                }
            }
        })
    }

    /// The last frame as 8-bit sRGB RGBA, row-major from the top, as `viewer render`'s PNG
    /// encodes it (alpha 255): the CPU path's frame (empty while presenting on the GPU).
    pub fn rgba(&self) -> js_sys::Uint8Array {
        js_sys::Uint8Array::from(&self.inner.borrow().rgba[..])
    }

    /// Presents frames on `canvas` on the GPU from now on (a WebGPU canvas context of the
    /// canvas, its size as it is now); resolves to the surface's format, e.g. `"Bgra8Unorm"`.
    /// Once it has resolved, [`Viewer::rgba`] stays empty: read frames with
    /// [`Viewer::snapshot_rgba`].
    ///
    /// # Errors
    /// Rejects with the [`present::CanvasError`]'s message (also `state().present_error`);
    /// frames then go on by the CPU path, on a canvas that may hold a WebGPU context now.
    pub fn present_on(&self, canvas: web_sys::HtmlCanvasElement) -> js_sys::Promise {
        let inner = Rc::clone(&self.inner);
        wasm_bindgen_futures::future_to_promise(async move {
            let gpu = Rc::clone(&inner.borrow().gpu);
            let made = present::CanvasPresenter::new(&gpu, canvas).await;
            let mut i = inner.borrow_mut();
            match made {
                Ok(c) => {
                    let format = format!("{:?}", c.format());
                    i.canvas = Some(c);
                    i.totals.present = "gpu";
                    i.totals.present_error = None;
                    i.render_needed = true;
                    if let Some(r) = i.remote.as_mut() {
                        r.need_frame = true;
                    }
                    Ok(JsValue::from_str(&format))
                }
                Err(e) => {
                    let message = error_chain(&e);
                    i.totals.present_error = Some(message.clone());
                    Err(JsValue::from_str(&message))
                }
            }
        })
    }

    /// Presents the frame on show again, now (the GPU path): what the page's canvas shows
    /// until the browser composites it, for a test to copy it in the same task. Returns
    /// whether there was a frame to present.
    ///
    /// # Errors
    /// The [`present::CanvasError`]'s message when presenting fails.
    pub fn repaint(&self) -> Result<bool, JsValue> {
        let mut i = self.inner.borrow_mut();
        let i = &mut *i;
        let gpu = Rc::clone(&i.gpu);
        let size = (i.options.width, i.options.height);
        let (Some(canvas), Some(shown)) = (i.canvas.as_mut(), i.shown.as_ref()) else {
            return Ok(false);
        };
        let mut encoder = present::frame_encoder(&gpu);
        let shown = match shown {
            present::Shown::Local => match &i.renderer {
                Some(r) => canvas.show(&gpu, encoder, r.image_buffer(), size),
                None => return Ok(false),
            },
            present::Shown::Remote(vdi, camera, scale, filter) => {
                let (image, _) = vdi.encode(&gpu, &mut encoder, camera, true, *scale, *filter);
                canvas.show(&gpu, encoder, image, size)
            }
        };
        shown.map_err(|e| js_error(&e))
    }

    /// The frame on show as 8-bit sRGB RGBA (as [`Viewer::rgba`]): on the GPU path read back
    /// now (the local renderer's image buffer, or the VDI ray cast again for the frame's
    /// camera, `D_I` and filter, which gives the same pixels), one readback; on the CPU path the last
    /// frame's pixels, no readback. Resolves to an empty array before the first frame.
    ///
    /// # Errors
    /// Rejects with the [`GpuError`]'s message when the readback fails.
    pub fn snapshot_rgba(&self) -> js_sys::Promise {
        let inner = Rc::clone(&self.inner);
        wasm_bindgen_futures::future_to_promise(async move {
            let read = snapshot(&inner).await;
            match read {
                Ok(()) => {
                    let i = inner.borrow();
                    Ok(js_sys::Uint8Array::from(&i.rgba[..]).into())
                }
                Err(e) => Err(js_error(&e)),
            }
        })
    }

    /// `{frame, converged, bricks_requested, bricks_fetched, bytes_fetched, bricks_failed,
    /// bricks_resident, requests_in_flight, gpu_time_ms, renderer_builds, error, remote}` as
    /// JSON. `converged`: the last frame requested no brick and none is on its way, as
    /// `viewer render` means it; in the remote mode, the VDI drawn is of the current view at
    /// full resolution ([`remote::RemoteReport`], `remote`).
    pub fn state_json(&self) -> String {
        let inner = self.inner.borrow();
        let totals = Totals {
            remote: inner.remote_report(),
            ..inner.totals.clone()
        };
        serde_json::to_string(&totals).expect("totals serialize")
    }
}

impl Inner {
    /// Edits the wanted scene with `f(scene, info, image height)`.
    fn edit(&mut self, f: impl FnOnce(&mut Scene, &VolumeInfo, u32)) {
        let mut scene = self.scene.clone();
        f(&mut scene, &self.info, self.options.height);
        self.set_scene(scene);
    }

    /// Wants `scene`. Only a change of style (channels, background, filter, mode, clipping)
    /// goes through the renderer at the next step; the camera is set on every frame anyway.
    fn set_scene(&mut self, scene: Scene) {
        if scene != self.scene {
            if !scene.same_style(&self.scene) {
                self.scene_changed = true;
            }
            self.scene = scene;
            self.render_needed = true;
            self.totals.converged = false;
        }
    }

    /// Files the fetches that arrived into `renderer`.
    fn file_arrivals(&mut self, renderer: &mut Renderer) {
        let arrived = std::mem::take(&mut self.arrived);
        for (key, result) in arrived {
            self.in_flight.remove(&key);
            if !renderer
                .octree()
                .channels()
                .contains(&(key.channel as usize))
            {
                continue; // fetched for an earlier renderer
            }
            if let Err(e) = &result {
                self.totals.error = Some(error_chain(e));
            }
            if let Some((_, bytes)) =
                self.stream
                    .arrived(&self.gpu, renderer, key, result, &mut self.pending)
            {
                self.totals.bricks_fetched += 1;
                self.totals.bytes_fetched += bytes;
            }
            self.render_needed = true;
        }
        self.totals.bricks_failed = self.stream.failed_count() as u64;
    }
}

/// The renderer for `inner`'s wanted scene: the current one restyled in place when it can
/// be, else a new one.
async fn renderer_for(
    inner: &Rc<RefCell<Inner>>,
    current: Option<Renderer>,
) -> Result<Renderer, GpuError> {
    let (gpu, info, scene, options) = {
        let i = inner.borrow();
        (
            Rc::clone(&i.gpu),
            Rc::clone(&i.info),
            i.scene.clone(),
            i.options.clone(),
        )
    };
    if let Some(mut r) = current
        && (r.scene().same_style(&scene) || r.restyle(&gpu, &scene))
    {
        return Ok(r);
    }
    let renderer = Renderer::create(&gpu, &info, &scene, options).await?;
    let mut i = inner.borrow_mut();
    i.totals.renderer_builds += 1;
    // Fetches under way were for the old renderer's channels; they are filed only if drawn.
    // Failed bricks stay failed (never asked for again), as in the native session; only the
    // coarser stand-ins wanted for channels no longer drawn are forgotten.
    let drawn: Vec<usize> = scene
        .channels
        .iter()
        .filter(|c| c.visible)
        .map(|c| c.channel)
        .collect();
    i.stream.retain_channels(&drawn);
    Ok(renderer)
}

async fn step(inner: &Rc<RefCell<Inner>>) -> Result<bool, GpuError> {
    let remote_on = {
        let mut i = inner.borrow_mut();
        if i.stepping {
            return Ok(false);
        }
        i.stepping = true;
        i.remote_on()
    };
    if remote_on {
        return remote::step(inner).await;
    }
    let (current, rebuild) = {
        let mut i = inner.borrow_mut();
        let rebuild = i.renderer.is_none() || std::mem::take(&mut i.scene_changed);
        (i.renderer.take(), rebuild)
    };
    let mut renderer = match (current, rebuild) {
        (Some(r), false) => r,
        (current, _) => renderer_for(inner, current).await?,
    };
    let result = render_and_request(inner, &mut renderer).await;
    inner.borrow_mut().renderer = Some(renderer);
    result
}

/// Files arrivals, renders when needed, and sends the frame's missing bricks.
async fn render_and_request(
    inner: &Rc<RefCell<Inner>>,
    renderer: &mut Renderer,
) -> Result<bool, GpuError> {
    let gpu = {
        let mut i = inner.borrow_mut();
        i.file_arrivals(renderer);
        if !std::mem::take(&mut i.render_needed) {
            i.totals.requests_in_flight = i.requests_in_flight;
            return Ok(false);
        }
        Rc::clone(&i.gpu)
    };
    let camera = inner.borrow().scene.camera.clone();
    renderer.set_camera(camera);
    let on_gpu = inner.borrow().canvas.is_some();
    let out = if on_gpu {
        renderer.render_without_pixels_async(&gpu).await?
    } else {
        renderer.render_async(&gpu).await?
    };
    let mut i = inner.borrow_mut();
    let i = &mut *i;
    match i.canvas.as_mut() {
        Some(canvas) if on_gpu => {
            let size = (i.options.width, i.options.height);
            let encoder = present::frame_encoder(&gpu);
            canvas
                .show(&gpu, encoder, renderer.image_buffer(), size)
                .map_err(|e| present_failed(&e))?;
            i.shown = Some(present::Shown::Local);
        }
        _ => {
            present::srgb_rgba(&out.pixels, &mut i.rgba);
            i.totals.image_readbacks += 1;
        }
    }
    let mut stats = FrameStats {
        frame: renderer.frames(),
        shader: out.counts,
        gpu_time_ms: out.gpu_time_ms,
        ..std::mem::take(&mut i.pending)
    };
    i.totals.frame = stats.frame;
    i.totals.gpu_time_ms = out.gpu_time_ms;
    i.totals.bricks_resident = renderer.octree().resident_count() as u64;
    let over_cap = stats.shader.requests_over_cap;
    let wanted = i.stream.wanted(renderer, out.requests, over_cap);
    i.totals.bricks_requested = i.stream.request_log().len() as u64;
    let Some(mut wanted) = wanted else {
        // Bricks of an earlier view may still be arriving, and the view may have changed while
        // this frame rendered: then the next frame decides.
        i.totals.converged = i.in_flight.is_empty() && !i.render_needed && !i.scene_changed;
        i.totals.requests_in_flight = i.requests_in_flight;
        return Ok(true);
    };
    i.totals.converged = false;
    // Bricks already on their way are not asked for twice.
    wanted.retain(|r| !i.in_flight.contains(&r.key));
    let keys = StreamState::to_fetch(renderer, wanted, &mut stats);
    // Requests of `batch` bricks each, at most MAX_REQUESTS_IN_FLIGHT at once (a store of
    // large bricks has smaller batches, so room counts in its batches).
    let batch = PAGE_BATCH.min(server::batch_size(&i.info));
    let room = MAX_REQUESTS_IN_FLIGHT.saturating_sub(i.requests_in_flight) * batch;
    for chunk in keys[..keys.len().min(room)].chunks(batch) {
        send(inner, i, chunk.to_vec());
    }
    if keys.len() > room || over_cap > 0 {
        // More to ask for once these arrive: the next frame asks again.
        i.render_needed = i.requests_in_flight == 0;
    }
    i.totals.requests_in_flight = i.requests_in_flight;
    Ok(true)
}

/// A failure to present as the [`GpuError`] a step reports.
fn present_failed(e: &present::CanvasError) -> GpuError {
    GpuError::Validation {
        what: "presenting the frame on the canvas".into(),
        message: error_chain(e),
    }
}

/// Reads the frame on show into `rgba` (see [`Viewer::snapshot_rgba`]). Holds the step
/// (`stepping`) while it reads.
async fn snapshot(inner: &Rc<RefCell<Inner>>) -> Result<(), GpuError> {
    let (gpu, shown, renderer, pixels) = {
        let mut i = inner.borrow_mut();
        if i.canvas.is_none() || i.stepping {
            return Ok(());
        }
        let Some(shown) = i.shown.take() else {
            return Ok(());
        };
        i.stepping = true;
        let pixels = u64::from(i.options.width) * u64::from(i.options.height);
        (Rc::clone(&i.gpu), shown, i.renderer.take(), pixels)
    };
    let read = match (&shown, &renderer) {
        (present::Shown::Local, Some(r)) => {
            Some(present::read_image(&gpu, r.image_buffer(), pixels).await)
        }
        (present::Shown::Remote(vdi, camera, scale, filter), _) => Some(
            gpu.checked_async(
                "rendering a VDI",
                vdi.render_async(&gpu, camera, true, *scale, *filter),
            )
            .await
            .map(|f| f.pixels),
        ),
        (present::Shown::Local, None) => None,
    };
    let mut i = inner.borrow_mut();
    i.stepping = false;
    if i.renderer.is_none() {
        i.renderer = renderer;
    }
    if i.shown.is_none() {
        i.shown = Some(shown);
    }
    if let Some(read) = read {
        let pixels = read?;
        present::srgb_rgba(&pixels, &mut i.rgba);
        i.totals.image_readbacks += 1;
    }
    Ok(())
}

/// Sends one `/bricks` request; its answer lands in `arrived` and asks for a frame.
fn send(inner: &Rc<RefCell<Inner>>, i: &mut Inner, keys: Vec<BrickKey>) {
    i.in_flight.extend(keys.iter().copied());
    i.requests_in_flight += 1;
    let base = i.base.clone();
    let info = Rc::clone(&i.info);
    let inner = Rc::clone(inner);
    wasm_bindgen_futures::spawn_local(async move {
        let results = server::fetch_batch(&BrowserFetch, &base, &info, &keys).await;
        let mut i = inner.borrow_mut();
        i.requests_in_flight -= 1;
        i.arrived.extend(keys.into_iter().zip(results));
        i.render_needed = true;
    });
}
