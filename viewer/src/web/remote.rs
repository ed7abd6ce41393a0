//! The page's remote mode: instead of streaming bricks, the page asks a render service
//! (`viewer serve`, `crate::service` natively) for volumetric depth images of its view, and
//! ray casts the newest one it holds for its own camera on its own WebGPU device.
//!
//! The page's JavaScript owns the network (`fetch` with an `AbortController`, the token); this
//! module owns the decisions and the drawing:
//!
//! - [`Viewer::remote_request`] says when to ask and what: at once when there is no VDI or the
//!   scene's style (channels, background, filter) changed, when the camera has moved past a
//!   threshold from the camera of the latest request ([`ORBIT_DEGREES`], [`ZOOM_FRACTION`],
//!   [`PAN_FRACTION`]) and none is in flight, or when the camera has rested for [`REST_MS`]
//!   away from it. A new request supersedes the one in flight (the page aborts its fetch).
//!   It asks for the planes compressed as [`Viewer::set_vdi_compression`] chose: under
//!   `auto`, zstd where the last answer crossed the link slower than
//!   [`ZSTD_BELOW_MBIT_PER_S`](crate::vdi_compression_choice::ZSTD_BELOW_MBIT_PER_S).
//! - [`Viewer::remote_received`] counts an answer's body and measures the link with it;
//!   [`Viewer::remote_answer`] files the answer, as the page's VDI reader read it off the main
//!   thread (`super::vdi_reader`): only the answer to the latest request is kept, and never
//!   one older than the VDI drawn; [`Viewer::remote_failed`] files the service's
//!   error, which the page shows. A request answered 429 or 503 (the service busy or its GPU
//!   unavailable for a while) is sent again after the answer's `Retry-After` while
//!   [`Viewer::remote_retry`] allows, at most [`MAX_RETRIES`] times, and never once a newer
//!   request has superseded it.
//! - [`step`] draws: the newest VDI ray cast for the current camera, as a [`VdiFramePlanner`]
//!   plans each frame from the choice of [`Viewer::set_vdi_filter`]: while the camera moves,
//!   at the image-space sampling `D_I` that holds the target frame time (under `auto`, with
//!   the nearest list, or with the linear filter at full resolution where its last frame held
//!   the target); once it rests, at full resolution with the filter the choice gives at rest
//!   (under `auto`, the linear filter).
//!   Every VDI is drawn by the same [`VdiPipelines`], compiled when the first one arrives.

use std::cell::RefCell;
use std::rc::Rc;

use residency_schemas::vdi::Compression;
use serde::Serialize;
use wasm_bindgen::prelude::*;

use super::vdi_reader::{ReadAnswer, ReaderError, take_answer};
use super::{Inner, Viewer, now_ms, present};
use crate::error_chain;
use crate::gpu::GpuError;
use crate::gpu::vdi_buffers::VdiBuffers;
use crate::gpu::vdi_filter::VdiFilter;
use crate::gpu::vdi_render::{VdiFrame, VdiPipelines, VdiRenderer};
use crate::scene::{Camera, RenderMode, Scene};
use crate::vdi_compression_choice::{LinkRate, VdiCompressionChoice};
use crate::vdi_filter_choice::VdiFilterChoice;
use crate::vdi_frame_plan::{VdiFramePlan, VdiFramePlanner};
use crate::vdi_service::{Adapter, DEFAULT_SUPERSEGMENTS, ServiceInfo, VdiRequest};

/// A camera this many degrees of orbit (or roll) away from the latest request's asks again.
pub const ORBIT_DEGREES: f64 = 10.0;

/// A camera whose distance to its target changed by more than this fraction asks again.
pub const ZOOM_FRACTION: f64 = 0.1;

/// A camera whose target moved by more than this fraction of its distance asks again.
pub const PAN_FRACTION: f64 = 0.1;

/// The camera rests once it has not moved for this long (ms): a rested view away from the
/// latest request's asks again, and is drawn at full resolution.
pub const REST_MS: f64 = 250.0;

/// The least time between two requests (ms): a slider dragged through many styles asks at
/// most this often, well within the service's default rate.
const MIN_INTERVAL_MS: f64 = 100.0;

/// The frame time the controller holds while the camera moves unless the page says otherwise
/// (ms): 60 frames a second.
pub const TARGET_FRAME_MS: f64 = 1000.0 / 60.0;

/// How many times one request answered 429 or 503 is sent again before its failure is the
/// remote mode's error.
pub const MAX_RETRIES: u32 = 3;

/// Why the remote mode cannot use the service or an answer of it. Shown on the page as the
/// service's own errors are.
#[derive(Debug, thiserror::Error)]
pub enum RemoteError {
    /// `GET /info` did not answer a service description.
    #[error("its /info is not a render service description")]
    Info(#[source] serde_json::Error),
    /// The service (or a VDI of it) renders another dataset.
    #[error("it serves dataset '{served}', not '{page}'")]
    OtherDataset {
        /// The service's dataset.
        served: String,
        /// The page's.
        page: String,
    },
    /// The page's image is over the service's `--max-pixels`.
    #[error(
        "this page draws {width} × {height} = {pixels} pixels, over the service's limit of \
         {limit} (--max-pixels): open it with a smaller ?width=&height="
    )]
    TooManyPixels {
        /// The page's width.
        width: u32,
        /// The page's height.
        height: u32,
        /// Their product.
        pixels: u64,
        /// The service's limit.
        limit: u64,
    },
    /// The answer is not a VDI: the decoder's message, from the page's VDI reader.
    #[error("its answer is not a VDI: {0}")]
    Decode(String),
    /// The page's VDI reader sent a message this side cannot take (a reader of another build).
    #[error("the page's VDI reader (vdi_worker.js) failed")]
    Reader(#[source] ReaderError),
    /// The VDI answered has another size than the page's image.
    #[error("its VDI is {vdi_width} × {vdi_height}, the page draws {width} × {height}")]
    WrongSize {
        /// The VDI's width.
        vdi_width: u32,
        /// The VDI's height.
        vdi_height: u32,
        /// The page's width.
        width: u32,
        /// The page's height.
        height: u32,
    },
    /// The VDI cannot be drawn on the page's device.
    #[error("cannot draw its VDI")]
    Gpu(#[source] Box<GpuError>),
}

/// A request sent and not yet answered.
#[derive(Clone, Debug)]
struct Flight {
    sequence: u32,
    scene: Scene,
    /// Times it was sent again after a 429 or 503.
    retries: u32,
}

/// An answer read, waiting for the next step to upload it.
struct Arrived {
    sequence: u32,
    scene: Scene,
    buffers: VdiBuffers<js_sys::Float32Array>,
    /// The main thread's time taking the reader's message (its starts and skipping grids
    /// copied in, checked), ms.
    taken_ms: f64,
}

/// The VDI drawn.
struct Drawn {
    sequence: u32,
    /// The scene it was requested for (its camera is the camera of generation).
    scene: Scene,
    renderer: Rc<VdiRenderer>,
}

/// Where the remote mode stands.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum RemoteMode {
    /// The switch is off: the page streams bricks and renders them itself.
    Off,
    /// On, waiting for the service's `/info` (or refused by it: `last_error` says why).
    #[default]
    Starting,
    /// On, asking the service for VDIs and drawing them.
    On,
}

/// What `state()` reports of the remote mode (`remote` in [`Viewer::state_json`]).
#[derive(Clone, Debug, Default, Serialize)]
#[expect(
    clippy::struct_excessive_bools,
    reason = "a report of independent facts, read by the page and its tests"
)]
pub struct RemoteReport {
    /// The render service's base URL.
    service: String,
    /// The switch and the service's state.
    mode: RemoteMode,
    /// The GPU adapter the service renders on (its `/info`), once read.
    service_adapter: Option<Adapter>,
    /// `POST /vdi` requests sent (each counted once, however often it was retried).
    requests_sent: u64,
    /// Requests sent again after an answer 429 or 503 ([`Viewer::remote_retry`]).
    requests_retried: u64,
    /// Requests superseded by a newer one while in flight (the page aborted their fetch).
    requests_aborted: u64,
    /// Answers not drawn: not the latest request's, older than the VDI drawn, or superseded
    /// at the service (409).
    answers_dropped: u64,
    /// VDIs received and drawn.
    vdis_received: u64,
    /// Bytes of the VDI answers received (their bodies, as encoded), drawn or dropped.
    vdi_bytes_received: u64,
    /// The compression the user chose for the VDIs ([`Viewer::set_vdi_compression`]).
    vdi_compression: VdiCompressionChoice,
    /// The link's rate as the last answer large enough to weigh it crossed it, Mbit/s (what
    /// `auto` weighs).
    link_mbit_per_s: Option<LinkRate>,
    /// The link's rate that `auto` weighed when the latest request was sent (what
    /// `link_mbit_per_s` was then; none before an answer measured it).
    request_link_mbit_per_s: Option<LinkRate>,
    /// The compression of the last VDI answer read.
    answer_compression: Option<Compression>,
    /// Frames ray cast from VDIs.
    frames: u64,
    /// Of those, the frames cast at `D_I` below 1 (while the camera moved).
    frames_subsampled: u64,
    /// The sequence number of the request in flight.
    in_flight: Option<u32>,
    /// The sequence number of the request whose VDI is drawn.
    drawn_request: Option<u32>,
    /// The last error of the service or of its answers, until a VDI is drawn again.
    last_error: Option<String>,
    /// `D_I` of the last frame.
    d_i: f64,
    /// How the VDIs are read between their lists, as the user chose (`auto`: the linear
    /// filter at rest, and while the camera moves where its last frame at full resolution held
    /// the target frame time, else the nearest list); the planner's, filled in by `report()`.
    vdi_filter: VdiFilterChoice,
    /// The filter the last frame read its VDI with.
    frame_filter: Option<VdiFilter>,
    /// Frames drawn while the camera moved with the linear filter.
    moving_frames_linear: u64,
    /// Time of the last frame the linear filter's pipeline drew at full resolution, ms (what
    /// `auto` weighs against the target frame time while the camera moves).
    linear_frame_ms: Option<f64>,
    /// Time of the last frame (ray cast, then presented and the GPU done, or read back), ms.
    frame_ms: Option<f64>,
    /// Time the page's VDI reader (a worker, off the main thread) took on the last VDI answer
    /// it could read: decompressed, converted, its values checked, its slots packed and its
    /// skipping grids built (its size and dataset are checked after), ms. This side's share
    /// of each answer's latency, with `vdi_setup_ms`.
    vdi_decode_ms: Option<f64>,
    /// Time from the page's main thread taking the last VDI it drew from the reader to its
    /// buffers uploaded and checked (the browser's GPU process answering for them), ms.
    vdi_setup_ms: Option<f64>,
    /// The linear filter's pipeline is compiled (the page compiles it while the view rests).
    linear_compiled: bool,
    /// The camera of generation of the VDI drawn.
    vdi_camera: Option<Camera>,
    /// The last frame drew the VDI held for the current camera at full resolution, with the
    /// current filter (whether or not a newer VDI is asked for).
    frame_current: bool,
    /// The VDI drawn was made for the page's current style (channels, background, filter).
    scene_current: bool,
    /// The VDI drawn was made for the page's current scene, camera included, and the last
    /// frame drew it at full resolution with the current filter; no request is in flight and
    /// no VDI waits to be uploaded.
    converged: bool,
}

/// The remote mode's state, in the page's viewer.
pub(super) struct Remote {
    report: RemoteReport,
    /// The service's `/info` was read and fits the page.
    ready: bool,
    supersegments: u32,
    next_sequence: u32,
    in_flight: Option<Flight>,
    /// The scene of the latest request answered (a VDI or an error): no need to ask for it
    /// again.
    settled: Option<Scene>,
    arrived: Option<Arrived>,
    drawn: Option<Drawn>,
    planner: VdiFramePlanner,
    /// The ray caster's pipelines, compiled when the first VDI arrives.
    pipelines: Option<Rc<VdiPipelines>>,
    /// The camera last seen, and when it last changed (ms, `performance.now()`).
    camera: Option<Camera>,
    changed_ms: f64,
    last_sent_ms: f64,
    /// The camera, `D_I` and filter of the last frame.
    frame: Option<(Camera, f64, VdiFilter)>,
    pub(super) need_frame: bool,
}

/// The angle between `a` and `b` in degrees (0 for a zero vector).
fn degrees_between(a: [f64; 3], b: [f64; 3]) -> f64 {
    let dot: f64 = (0..3).map(|i| a[i] * b[i]).sum();
    let norm = |v: [f64; 3]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
    let n = norm(a) * norm(b);
    if n == 0.0 {
        return 0.0;
    }
    (dot / n).clamp(-1.0, 1.0).acos().to_degrees()
}

/// Whether `now` has moved past a threshold from `then`: orbit or roll beyond
/// [`ORBIT_DEGREES`], the distance changed beyond [`ZOOM_FRACTION`], the target beyond
/// [`PAN_FRACTION`] of the distance, or another field of view.
fn moved_past_threshold(then: &Camera, now: &Camera) -> bool {
    let offset = |c: &Camera| std::array::from_fn::<f64, 3, _>(|i| c.eye[i] - c.target[i]);
    let length = |v: [f64; 3]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
    let (a, b) = (offset(then), offset(now));
    let distance = length(a);
    let pan = length(std::array::from_fn(|i| now.target[i] - then.target[i]));
    degrees_between(a, b) > ORBIT_DEGREES
        || degrees_between(then.up, now.up) > ORBIT_DEGREES
        || (length(b) / distance - 1.0).abs() > ZOOM_FRACTION
        || pan > PAN_FRACTION * distance
        || then.fov_y_degrees != now.fov_y_degrees
}

impl Remote {
    fn new(service: String, target_frame_ms: f64) -> Self {
        Self {
            report: RemoteReport {
                service,
                d_i: 1.0,
                ..RemoteReport::default()
            },
            ready: false,
            supersegments: DEFAULT_SUPERSEGMENTS,
            next_sequence: 0,
            in_flight: None,
            settled: None,
            arrived: None,
            drawn: None,
            planner: VdiFramePlanner::new(VdiFilterChoice::default(), target_frame_ms),
            pipelines: None,
            camera: None,
            changed_ms: f64::NEG_INFINITY,
            last_sent_ms: f64::NEG_INFINITY,
            frame: None,
            need_frame: false,
        }
    }

    /// Notes the camera at `now`: when it last changed decides whether it rests.
    fn observe(&mut self, camera: &Camera, now: f64) {
        if self.camera.as_ref() != Some(camera) {
            self.camera = Some(camera.clone());
            self.changed_ms = now;
        }
    }

    fn resting(&self, now: f64) -> bool {
        now - self.changed_ms >= REST_MS
    }

    /// Whether to ask for a VDI of `scene` at `now` (see the module documentation).
    fn wants(&self, scene: &Scene, now: f64) -> bool {
        if now - self.last_sent_ms < MIN_INTERVAL_MS {
            return false;
        }
        let latest = self
            .in_flight
            .as_ref()
            .map(|f| &f.scene)
            .or(self.settled.as_ref());
        let Some(latest) = latest else {
            return true;
        };
        if !latest.same_style(scene) {
            return true;
        }
        if latest.camera == scene.camera {
            return false;
        }
        self.resting(now)
            || (self.in_flight.is_none() && moved_past_threshold(&latest.camera, &scene.camera))
    }

    /// Forgets the request in flight (its fetch is aborted).
    fn abort(&mut self) {
        if self.in_flight.take().is_some() {
            self.report.requests_aborted += 1;
        }
    }

    /// The request `sequence`, when it is the one in flight: it is answered now.
    fn settle(&mut self, sequence: u32) -> Option<Flight> {
        match &self.in_flight {
            Some(f) if f.sequence == sequence => {
                let flight = self.in_flight.take();
                self.settled = flight.as_ref().map(|f| f.scene.clone());
                flight
            }
            _ => {
                self.report.answers_dropped += 1;
                None
            }
        }
    }

    fn fail(&mut self, error: &(dyn std::error::Error + 'static)) {
        self.report.last_error = Some(error_chain(error));
    }

    /// Whether the last frame drew the VDI held for `camera` at full resolution with the
    /// current filter, and none is waiting to be drawn.
    fn frame_current(&self, camera: &Camera) -> bool {
        self.frame.as_ref().is_some_and(|(c, s, f)| {
            c == camera && *s == 1.0 && *f == self.planner.filter_at_rest()
        }) && !self.need_frame
    }

    /// Whether the VDI drawn is of `scene` at full resolution, nothing in flight or pending.
    fn converged(&self, scene: &Scene) -> bool {
        self.drawn.as_ref().is_some_and(|d| d.scene == *scene)
            && self.frame_current(&scene.camera)
            && self.in_flight.is_none()
            && self.arrived.is_none()
    }

    /// The report, brought up to date for `scene`.
    fn report(&self, scene: &Scene) -> RemoteReport {
        RemoteReport {
            in_flight: self.in_flight.as_ref().map(|f| f.sequence),
            drawn_request: self.drawn.as_ref().map(|d| d.sequence),
            vdi_camera: self.drawn.as_ref().map(|d| d.scene.camera.clone()),
            frame_current: self.frame_current(&scene.camera),
            linear_compiled: self.pipelines.as_ref().is_some_and(|p| p.linear_compiled()),
            frame_filter: self.frame.as_ref().map(|(_, _, filter)| *filter),
            vdi_filter: self.planner.choice(),
            linear_frame_ms: self.planner.linear_ms(),
            scene_current: self
                .drawn
                .as_ref()
                .is_some_and(|d| d.scene.same_style(scene)),
            converged: self.converged(scene),
            ..self.report.clone()
        }
    }
}

impl Inner {
    /// The remote mode, when a service is given, the switch is on and the scene is in the
    /// `dvr` mode.
    pub(super) fn remote_on(&self) -> bool {
        // VDIs hold composited colour: a scene in another mode is drawn here, from bricks.
        self.scene.mode == RenderMode::Dvr
            && self
                .remote
                .as_ref()
                .is_some_and(|r| r.report.mode != RemoteMode::Off)
    }

    /// The remote mode's report for `state()`.
    pub(super) fn remote_report(&self) -> Option<RemoteReport> {
        self.remote.as_ref().map(|r| r.report(&self.scene))
    }
}

#[wasm_bindgen]
impl Viewer {
    /// Uses the render service at `service` (its base URL, for the report): the remote mode,
    /// switched on, its frame-rate controller holding `target_frame_ms` per frame while the
    /// camera moves ([`TARGET_FRAME_MS`] when it is not a positive number). It asks nothing
    /// until [`Viewer::remote_info`] has the service's description.
    pub fn remote_begin(&self, service: String, target_frame_ms: f64) {
        let target = if target_frame_ms > 0.0 && target_frame_ms.is_finite() {
            target_frame_ms
        } else {
            TARGET_FRAME_MS
        };
        let mut inner = self.inner.borrow_mut();
        inner.remote = Some(Remote::new(service, target));
        inner.totals.converged = false;
    }

    /// Takes the service's `GET /info` answer (JSON): it must serve the page's dataset and
    /// take the page's image size; N_S is capped at its limit.
    ///
    /// # Errors
    /// The [`RemoteError`]'s message (also the remote mode's `last_error`): not a service
    /// description, another dataset, an image over its `--max-pixels`; or without
    /// [`Viewer::remote_begin`].
    pub fn remote_info(&self, json: &str) -> Result<(), JsValue> {
        let mut inner = self.inner.borrow_mut();
        let (width, height) = (inner.options.width, inner.options.height);
        let page = inner.info.name.clone();
        let Some(remote) = inner.remote.as_mut() else {
            return Err(JsValue::from_str("no render service given"));
        };
        let checked = serde_json::from_str::<ServiceInfo>(json)
            .map_err(RemoteError::Info)
            .and_then(|info| {
                let pixels = u64::from(width) * u64::from(height);
                if info.dataset != page {
                    Err(RemoteError::OtherDataset {
                        served: info.dataset,
                        page,
                    })
                } else if pixels > info.limits.max_pixels {
                    Err(RemoteError::TooManyPixels {
                        width,
                        height,
                        pixels,
                        limit: info.limits.max_pixels,
                    })
                } else {
                    Ok((info.limits.max_supersegments, info.adapter))
                }
            });
        match checked {
            Ok((most, adapter)) => {
                remote.supersegments = DEFAULT_SUPERSEGMENTS.min(most).max(1);
                remote.report.service_adapter = Some(adapter);
                remote.ready = true;
                remote.report.mode = RemoteMode::On;
                Ok(())
            }
            Err(e) => {
                remote.fail(&e);
                Err(JsValue::from_str(&error_chain(&e)))
            }
        }
    }

    /// Switches the remote mode on or off (off: the page streams bricks and renders them
    /// itself; a request in flight is forgotten, and the page aborts it). Returns whether it
    /// is on: never without a render service.
    pub fn set_remote(&self, on: bool) -> bool {
        let mut inner = self.inner.borrow_mut();
        let Some(remote) = inner.remote.as_mut() else {
            return false;
        };
        remote.report.mode = match (on, remote.ready) {
            (false, _) => RemoteMode::Off,
            (true, false) => RemoteMode::Starting,
            (true, true) => RemoteMode::On,
        };
        remote.need_frame = true;
        if !on {
            remote.abort();
        }
        inner.render_needed = true;
        inner.totals.converged = false;
        on
    }

    /// Reads the VDIs between their lists with the filter choice named `name` (`auto`, the
    /// default: the linear filter at rest, and while the camera moves where its last frame at
    /// full resolution held the target frame time, else the nearest list; `nearest`; or
    /// `linear`): the VDI drawn is drawn again with it where the filter of its frame
    /// changes, and so are those that follow; the service is not asked again (the filter is the
    /// page's, not the VDI's).
    ///
    /// # Errors
    /// The [`UnknownName`](residency_schemas::names::UnknownName) message, the filter
    /// unchanged; or
    /// without [`Viewer::remote_begin`].
    pub fn set_vdi_filter(&self, name: &str) -> Result<(), JsValue> {
        let filter: VdiFilterChoice = name.parse().map_err(|e| super::js_error(&e))?;
        let mut inner = self.inner.borrow_mut();
        let on = inner.remote_on();
        let Some(remote) = inner.remote.as_mut() else {
            return Err(JsValue::from_str("no render service given"));
        };
        if remote.planner.choice() == filter {
            return Ok(());
        }
        // The next frame draws with it (its pipeline compiled then, in that frame's error
        // scope), if the last frame's filter differs from the one it gives.
        remote.planner.set_choice(filter);
        if on {
            inner.render_needed = true;
            inner.totals.converged = false;
        }
        Ok(())
    }

    /// Asks for the VDIs compressed as `name` says from the next request on: `auto`,
    /// `shuffled_lz4` or `shuffled_zstd` ([`VdiCompressionChoice`]).
    ///
    /// # Errors
    /// Another name (the message lists the known ones); or without
    /// [`Viewer::remote_begin`].
    pub fn set_vdi_compression(&self, name: &str) -> Result<(), JsValue> {
        let choice: VdiCompressionChoice = name.parse().map_err(|e| super::js_error(&e))?;
        let mut inner = self.inner.borrow_mut();
        let Some(remote) = inner.remote.as_mut() else {
            return Err(JsValue::from_str("no render service given"));
        };
        remote.report.vdi_compression = choice;
        Ok(())
    }

    /// The body of the `POST /vdi` request to send now (JSON, its `request` the sequence
    /// number to answer with), or nothing to ask. A request in flight is superseded: the page
    /// aborts its fetch.
    pub fn remote_request(&self) -> Option<String> {
        let now = now_ms();
        let mut inner = self.inner.borrow_mut();
        let inner = &mut *inner;
        let (width, height) = (inner.options.width, inner.options.height);
        let scene = &inner.scene;
        let remote = inner.remote.as_mut()?;
        if remote.report.mode != RemoteMode::On {
            return None;
        }
        remote.observe(&scene.camera, now);
        if !remote.wants(scene, now) {
            return None;
        }
        remote.abort();
        remote.next_sequence += 1;
        let sequence = remote.next_sequence;
        let report = &remote.report;
        let body = VdiRequest {
            scene: Some(scene.clone()),
            camera: None,
            width,
            height,
            supersegments: Some(remote.supersegments),
            request: Some(u64::from(sequence)),
            compression: Some(report.vdi_compression.compression(report.link_mbit_per_s)),
        };
        remote.report.request_link_mbit_per_s = remote.report.link_mbit_per_s;
        let json = serde_json::to_string(&body).expect("requests serialize");
        remote.in_flight = Some(Flight {
            sequence,
            scene: scene.clone(),
            retries: 0,
        });
        remote.last_sent_ms = now;
        remote.report.requests_sent += 1;
        Some(json)
    }

    /// Counts a VDI answer's body of `body_bytes` bytes, received whole, which took
    /// `transfer_ms` on the link from its first byte to its last (NaN: not timed), before the
    /// page's VDI reader reads it: any answer of at least
    /// [`crate::vdi_compression_choice::MIN_MEASURED_BYTES`] measures the link.
    pub fn remote_received(&self, body_bytes: f64, transfer_ms: f64) {
        let mut inner = self.inner.borrow_mut();
        let Some(remote) = inner.remote.as_mut() else {
            return;
        };
        // A body's length, as JavaScript counts it: a whole number below 2⁵³.
        let body_bytes = body_bytes as u64;
        remote.report.vdi_bytes_received += body_bytes;
        if let Some(rate) = LinkRate::measured(body_bytes, transfer_ms) {
            remote.report.link_mbit_per_s = Some(rate);
        }
    }

    /// Files the VDI answering request `sequence`: `read`, the message of the page's VDI
    /// reader (`read_vdi_answer`, in `vdi_worker.js`) for the answer's body. Kept when it
    /// answers the request in flight, uploaded and drawn at the next step; else dropped. An
    /// answer that is no VDI, or a VDI of another size or dataset, becomes the remote mode's
    /// error.
    pub fn remote_answer(&self, sequence: u32, read: &JsValue) {
        let mut inner = self.inner.borrow_mut();
        let (width, height) = (inner.options.width, inner.options.height);
        let page = inner.info.name.clone();
        let Some(remote) = inner.remote.as_mut() else {
            return;
        };
        let Some(flight) = remote.settle(sequence) else {
            return;
        };
        let started = now_ms();
        let taken = match take_answer(read) {
            Ok(ReadAnswer::Vdi { buffers, read_ms }) => {
                remote.report.vdi_decode_ms = Some(read_ms);
                remote.report.answer_compression = Some(buffers.header.compression);
                Ok(*buffers)
            }
            Ok(ReadAnswer::NotVdi(message)) => Err(RemoteError::Decode(message)),
            Err(e) => Err(RemoteError::Reader(e)),
        };
        let taken_ms = now_ms() - started;
        let checked = taken.and_then(|buffers| {
            let h = &buffers.header;
            if (h.width, h.height) != (width, height) {
                return Err(RemoteError::WrongSize {
                    vdi_width: h.width,
                    vdi_height: h.height,
                    width,
                    height,
                });
            }
            match &h.dataset {
                Some(served) if *served != page => Err(RemoteError::OtherDataset {
                    served: served.clone(),
                    page,
                }),
                _ => Ok(buffers),
            }
        });
        match checked {
            Ok(buffers) => {
                if remote.arrived.is_some() {
                    // An earlier answer not yet uploaded: this newer one takes its place.
                    remote.report.answers_dropped += 1;
                }
                remote.arrived = Some(Arrived {
                    sequence,
                    scene: flight.scene,
                    buffers,
                    taken_ms,
                });
            }
            Err(e) => remote.fail(&e),
        }
    }

    /// Whether to send request `sequence` again, answered 429 or 503: only while it is the
    /// request in flight and has been sent again fewer than [`MAX_RETRIES`] times. A retry is
    /// counted (`requests_retried`); the page waits the answer's `Retry-After` first, and
    /// files the failure with [`Viewer::remote_failed`] when this says no.
    pub fn remote_retry(&self, sequence: u32) -> bool {
        let mut inner = self.inner.borrow_mut();
        let Some(remote) = inner.remote.as_mut() else {
            return false;
        };
        match remote.in_flight.as_mut() {
            Some(flight) if flight.sequence == sequence && flight.retries < MAX_RETRIES => {
                flight.retries += 1;
                remote.report.requests_retried += 1;
                true
            }
            _ => false,
        }
    }

    /// Files the failure of request `sequence` (0: the `GET /info` request): HTTP `status`
    /// (0 when the service could not be reached) and the service's `message`. A request
    /// superseded at the service (409) is a dropped answer, asked for again; any other failure
    /// of the latest request becomes the remote mode's error, shown by the page.
    pub fn remote_failed(&self, sequence: u32, status: u16, message: String) {
        let mut inner = self.inner.borrow_mut();
        let Some(remote) = inner.remote.as_mut() else {
            return;
        };
        if sequence == 0 {
            remote.report.last_error = Some(message);
            return;
        }
        if status == 409 {
            if remote
                .in_flight
                .as_ref()
                .is_some_and(|f| f.sequence == sequence)
            {
                remote.in_flight = None;
            }
            remote.report.answers_dropped += 1;
            return;
        }
        if remote.settle(sequence).is_some() {
            remote.report.last_error = Some(message);
        }
    }
}

/// One step of the remote mode: uploads a VDI that arrived, then ray casts the newest VDI for
/// the current camera when the camera, the VDI or the resolution changed. Resolves to whether
/// a new frame is ready.
///
/// # Errors
/// A [`GpuError`] while rendering (a VDI that cannot be uploaded is the remote mode's error
/// instead, and the previous one stays drawn).
pub(super) async fn step(inner: &Rc<RefCell<Inner>>) -> Result<bool, GpuError> {
    upload(inner).await;
    let now = now_ms();
    let (gpu, renderer, camera, plan, moving) = {
        let mut i = inner.borrow_mut();
        let i = &mut *i;
        let scene = &i.scene;
        let Some(remote) = i.remote.as_mut() else {
            return Ok(false);
        };
        remote.observe(&scene.camera, now);
        let moving = !remote.resting(now);
        let Some(drawn) = &remote.drawn else {
            i.totals.converged = false;
            return Ok(false);
        };
        let plan = remote.planner.next(moving);
        let due = remote.need_frame
            || match &remote.frame {
                // A frame of this camera at full resolution with the filter at rest is as good
                // as any the plan could draw now (a moving linear frame over the target is
                // followed by the nearest list's, but not of the same view).
                Some((c, s, f)) => {
                    let best = *s >= 1.0 && *f == remote.planner.filter_at_rest();
                    *c != scene.camera || (!moving && *s < 1.0) || (*f != plan.filter && !best)
                }
                None => true,
            };
        if !due {
            i.totals.converged = remote.converged(scene);
            return Ok(false);
        }
        // Taken now: what changes while this frame is drawn is drawn by the next.
        remote.need_frame = false;
        (
            Rc::clone(&i.gpu),
            Rc::clone(&drawn.renderer),
            scene.camera.clone(),
            plan,
            moving,
        )
    };
    let VdiFramePlan { filter, scale, .. } = plan;
    let start = now_ms();
    let on_gpu = inner.borrow().canvas.is_some();
    let drawn = if on_gpu {
        // Presented from the VDI renderer's image, no readback: the frame time waits for the
        // GPU's work instead.
        gpu.checked_async("rendering a VDI", async {
            let mut encoder = present::frame_encoder(&gpu);
            let (image, _) = renderer.encode(&gpu, &mut encoder, &camera, true, scale, filter);
            let size = renderer.size();
            {
                let mut i = inner.borrow_mut();
                if let Some(canvas) = i.canvas.as_mut() {
                    canvas
                        .show(&gpu, encoder, image, size)
                        .map_err(|e| super::present_failed(&e))?;
                }
                i.shown = Some(present::Shown::Remote(
                    Rc::clone(&renderer),
                    camera.clone(),
                    scale,
                    filter,
                ));
            }
            present::work_done(&gpu).await;
            Ok(None)
        })
        .await
    } else {
        gpu.checked_async(
            "rendering a VDI",
            renderer.render_async(&gpu, &camera, true, scale, filter),
        )
        .await
        .map(Some)
    };
    let ms = now_ms() - start;
    let frame = match drawn {
        Ok(frame) => frame,
        Err(e) => {
            // Not drawn: due again at the next step.
            if let Some(remote) = inner.borrow_mut().remote.as_mut() {
                remote.need_frame = true;
            }
            return Err(e);
        }
    };
    if !moving && filter == VdiFilter::Linear && !renderer.pipelines().linear_compiled() {
        // A frame at rest from the VDI's own camera is drawn by the nearest pipeline: have the
        // linear one compiled now, while the view rests, rather than in the first frame that
        // reads it away from that camera (before the frame is filed, so that the page is
        // converged only then).
        let compiled = gpu
            .checked_async("compiling the VDI renderer", async {
                renderer.pipelines().prepare(&gpu, filter);
                Ok(())
            })
            .await;
        if let (Err(e), Some(remote)) = (compiled, inner.borrow_mut().remote.as_mut()) {
            remote.fail(&RemoteError::Gpu(Box::new(e)));
        }
    }
    let drawn = renderer.drawn_with(&camera, scale, filter);
    record_frame(inner, frame, camera, plan, drawn, moving, ms);
    Ok(true)
}

/// Files a frame drawn for `camera` as `plan` planned, by the pipeline of `drawn`, in `ms`
/// (its pixels when read back): the page's image and totals, the remote mode's report, and
/// the planner's measures.
fn record_frame(
    inner: &Rc<RefCell<Inner>>,
    frame: Option<VdiFrame>,
    camera: Camera,
    plan: VdiFramePlan,
    drawn: VdiFilter,
    moving: bool,
    ms: f64,
) {
    let VdiFramePlan { filter, scale, .. } = plan;
    let mut i = inner.borrow_mut();
    let i = &mut *i;
    if let Some(frame) = frame {
        present::srgb_rgba(&frame.pixels, &mut i.rgba);
        i.totals.image_readbacks += 1;
        i.totals.gpu_time_ms = frame.gpu_time_ms;
    } else {
        i.totals.gpu_time_ms = None;
    }
    let Some(remote) = i.remote.as_mut() else {
        return;
    };
    remote.planner.record(plan, drawn, ms);
    if moving && filter == VdiFilter::Linear {
        remote.report.moving_frames_linear += 1;
    }
    remote.frame = Some((camera, scale, filter));
    remote.report.frames += 1;
    if scale < 1.0 {
        remote.report.frames_subsampled += 1;
    }
    remote.report.d_i = scale;
    remote.report.frame_ms = Some(ms);
    i.totals.converged = remote.converged(&i.scene);
}

/// Uploads the VDI that arrived, if any, in place of the one drawn.
async fn upload(inner: &Rc<RefCell<Inner>>) {
    let (gpu, arrived, pipelines, width, height) = {
        let mut i = inner.borrow_mut();
        let i = &mut *i;
        let Some(remote) = i.remote.as_mut() else {
            return;
        };
        let Some(arrived) = remote.arrived.take() else {
            return;
        };
        (
            Rc::clone(&i.gpu),
            arrived,
            remote.pipelines.clone(),
            i.options.width,
            i.options.height,
        )
    };
    let pipelines = if let Some(p) = pipelines {
        p
    } else {
        let created = VdiPipelines::create(&gpu).await;
        let mut i = inner.borrow_mut();
        let Some(remote) = i.remote.as_mut() else {
            return;
        };
        match created {
            Ok(p) => {
                remote.pipelines = Some(Rc::clone(&p));
                p
            }
            Err(e) => {
                remote.fail(&RemoteError::Gpu(Box::new(e)));
                return;
            }
        }
    };
    let started = now_ms();
    let created = VdiRenderer::create(&gpu, &pipelines, &arrived.buffers, width, height).await;
    let setup_ms = arrived.taken_ms + (now_ms() - started);
    let mut i = inner.borrow_mut();
    let Some(remote) = i.remote.as_mut() else {
        return;
    };
    match created {
        Ok(renderer) => {
            if remote
                .drawn
                .as_ref()
                .is_some_and(|d| d.sequence >= arrived.sequence)
            {
                remote.report.answers_dropped += 1;
                return;
            }
            remote.drawn = Some(Drawn {
                sequence: arrived.sequence,
                scene: arrived.scene,
                renderer: Rc::new(renderer),
            });
            remote.report.vdi_setup_ms = Some(setup_ms);
            remote.report.vdis_received += 1;
            remote.report.last_error = None;
            remote.need_frame = true;
        }
        Err(e) => remote.fail(&RemoteError::Gpu(Box::new(e))),
    }
}
