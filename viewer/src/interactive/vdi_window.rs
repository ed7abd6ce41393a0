//! `viewer view --vdi`: a volumetric depth image in a window, ray cast for the window's camera
//! on the GPU ([`VdiRenderer::encode`]) and presented there with no readback
//! ([`super::display`]; where no surface can be made, each frame is read back and blitted).
//! A [`VdiFramePlanner`] plans each frame: while the camera moves, the image-space sampling
//! `D_I` that holds the target frame time (or, under `auto` where the linear filter held the
//! target, that filter at full resolution); once input stops for [`REST`], one frame at full
//! resolution with the filter the user's [`VdiFilterChoice`] gives at rest.

use std::io::Write;
use std::sync::Arc;
use std::time::{Duration, Instant};

use residency_schemas::vdi::VolumetricDepthImage;
use winit::application::ApplicationHandler;
use winit::dpi::{PhysicalPosition, PhysicalSize};
use winit::event::{ElementState, MouseButton, WindowEvent};
use winit::event_loop::{ActiveEventLoop, ControlFlow, EventLoop};
use winit::keyboard::{Key, ModifiersState, NamedKey};
use winit::window::{Window, WindowId};

use super::camera_control::{orbit, pan, zoom};
use super::display::{Display, Frame, Overlays, PresentPath};
use super::window::{ViewError, open_window, panel_scale, render_size, wheel_steps};
use crate::gpu::device::Gpu;
use crate::gpu::vdi_filter::VdiFilter;
use crate::gpu::vdi_render::VdiRenderer;
use crate::scene::Camera;
use crate::vdi_filter_choice::VdiFilterChoice;
use crate::vdi_frame_plan::{VdiFramePlan, VdiFramePlanner};

/// How long after the last input the view counts as at rest (and renders at full resolution).
pub const REST: Duration = Duration::from_millis(150);

/// Settings of the VDI window.
#[derive(Clone, Debug)]
pub struct VdiViewConfig {
    /// Initial window size in pixels.
    pub window_size: (u32, u32),
    /// Rendered image size relative to the window (scaled to fit by nearest neighbour).
    pub render_scale: f64,
    /// The frame time the controller holds while the camera moves, in milliseconds.
    pub target_ms: f64,
    /// Cross the VDI's empty tiles of lists in one step.
    pub skipping: bool,
    /// How rays read the VDI between its lists, moving and at rest.
    pub filter: VdiFilterChoice,
    /// The sampling along the ray `D_R` of previews (frames at the controller's `D_I` while the
    /// camera moves: `VdiRenderer::set_ray_sampling`); 1 reads every list.
    pub ray_sampling: f64,
    /// Print a summary line on standard output whenever the view settles (at rest with a
    /// frame at full resolution, or this many frames shown since the last input), and quit
    /// when no input follows within `exit_delay`.
    pub exit_after_frames: Option<u64>,
    /// How long a settled view waits for input before quitting (with `exit_after_frames`).
    pub exit_delay: Duration,
    /// How frames reach the window.
    pub present: PresentPath,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Drag {
    Orbit,
    Pan,
}

/// The last frame shown.
#[derive(Clone, Copy, Debug, Default)]
struct Shown {
    /// Wall-clock time of the frame (ray casting and presenting, to the GPU's end), in ms.
    ms: f64,
    /// Its `D_I`.
    scale: f64,
    /// The filter it read the VDI with.
    filter: VdiFilter,
    /// Rays cast per row and rows.
    rays: (u32, u32),
}

struct App {
    gpu: Gpu,
    vdi: VolumetricDepthImage,
    name: String,
    config: VdiViewConfig,
    camera: Camera,
    home: Camera,
    /// The VDI's volume diagonal (the least zoom distance is a thousandth of it).
    diagonal: f64,
    renderer: Option<VdiRenderer>,
    planner: VdiFramePlanner,
    window: Option<Arc<Window>>,
    display: Option<Display>,
    modifiers: ModifiersState,
    cursor: Option<PhysicalPosition<f64>>,
    drag: Option<(MouseButton, Drag)>,
    last_input: Option<Instant>,
    /// The view changed since the last frame.
    dirty: bool,
    overlay: bool,
    frames: u64,
    /// Frames shown since the last input.
    frames_since_input: u64,
    shown: Shown,
    settled_at: Option<Instant>,
    error: Option<ViewError>,
}

/// Opens a window showing `vdi` (named `name`) from `camera` and runs until it is closed,
/// quit by `q`, or by the `exit_after_frames` rule.
///
/// # Errors
/// A [`ViewError`]: no display, a window, surface or frame buffer that cannot be made, or the
/// VDI renderer's error.
pub fn run(
    gpu: Gpu,
    vdi: VolumetricDepthImage,
    name: String,
    camera: Camera,
    config: VdiViewConfig,
) -> Result<(), ViewError> {
    let event_loop = EventLoop::new().map_err(ViewError::NoDisplay)?;
    let h = &vdi.header;
    let diagonal =
        crate::scene::box_diagonal(std::array::from_fn(|a| h.volume_max[a] - h.volume_min[a]));
    let planner = VdiFramePlanner::new(config.filter, config.target_ms);
    let mut app = App {
        gpu,
        vdi,
        name,
        config,
        home: camera.clone(),
        camera,
        diagonal,
        renderer: None,
        planner,
        window: None,
        display: None,
        modifiers: ModifiersState::empty(),
        cursor: None,
        drag: None,
        last_input: None,
        dirty: true,
        overlay: true,
        frames: 0,
        frames_since_input: 0,
        shown: Shown::default(),
        settled_at: None,
        error: None,
    };
    event_loop.run_app(&mut app).map_err(ViewError::EventLoop)?;
    match app.error {
        Some(e) => Err(e),
        None => Ok(()),
    }
}

impl App {
    /// Whether the last frame was the one at rest: at full resolution, with the filter at rest.
    fn full(&self) -> bool {
        self.shown.scale >= 1.0 && self.shown.filter == self.planner.filter_at_rest()
    }

    fn fail(&mut self, event_loop: &ActiveEventLoop, e: ViewError) {
        if self.error.is_none() {
            self.error = Some(e);
        }
        event_loop.exit();
    }

    /// Whether the camera is moving: a drag goes on, or input came within [`REST`].
    fn moving(&self) -> bool {
        self.drag.is_some() || self.last_input.is_some_and(|t| t.elapsed() < REST)
    }

    fn render_size(&self, size: PhysicalSize<u32>) -> (u32, u32) {
        render_size(size, self.config.render_scale)
    }

    /// The panel's lines while the frame of `filter` is drawn (its `D_I` and time are the last
    /// frame's).
    fn panel_lines(&self, filter: VdiFilter) -> Vec<(String, u32)> {
        const WHITE: u32 = 0x00ff_ffff;
        const GREY: u32 = 0x00b0_b0b0;
        let h = &self.vdi.header;
        let name: String = self.name.chars().take(16).collect();
        let s = &self.shown;
        let mut lines = vec![
            (format!("{name}  VDI frame {}", self.frames), WHITE),
            (
                format!(
                    "{}x{} lists, N_S {}  skipping {}  {}",
                    h.width,
                    h.height,
                    h.supersegments,
                    if self.config.skipping { "on" } else { "off" },
                    filter.name()
                ),
                WHITE,
            ),
            (
                format!(
                    "D_I {:.2}  rays {}x{}  {:.1} ms (target {:.1})",
                    s.scale, s.rays.0, s.rays.1, s.ms, self.config.target_ms
                ),
                WHITE,
            ),
            ("drag orbit, shift/right pan, wheel zoom".into(), GREY),
            ("r h q".into(), GREY),
        ];
        // What decides `auto`'s filter while the camera moves.
        if let (VdiFilterChoice::Auto, Some(ms)) = (self.config.filter, self.planner.linear_ms()) {
            lines.insert(3, (format!("last linear frame {ms:.1} ms"), GREY));
        }
        lines
    }

    /// Renders and shows the frame of `plan`, and files its time with the planner.
    fn frame(&mut self, plan: VdiFramePlan) -> Result<(), ViewError> {
        let VdiFramePlan { filter, scale, .. } = plan;
        let Some(win) = self.window.as_ref().map(|w| w.inner_size()) else {
            return Ok(());
        };
        let size = self.render_size(win);
        if let Some(renderer) = &mut self.renderer {
            renderer.resize(&self.gpu, size.0, size.1)?;
        } else {
            self.renderer = Some(VdiRenderer::new(&self.gpu, &self.vdi, size.0, size.1)?);
        }
        let overlays = Overlays::shown(
            self.overlay.then(|| self.panel_lines(filter)),
            panel_scale(win),
            &self.camera,
            None,
            win.height,
        );
        let (Some(window), Some(display), Some(renderer)) =
            (&self.window, &mut self.display, &mut self.renderer)
        else {
            return Ok(());
        };
        let gpu = &self.gpu;
        let skipping = self.config.skipping;
        renderer.set_ray_sampling(if plan.preview() {
            self.config.ray_sampling
        } else {
            1.0
        });
        let start = Instant::now();
        let (shown, rays) = if display.on_gpu() {
            let mut encoder = gpu
                .device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                    label: Some("vdi view"),
                });
            let (image, rays) =
                renderer.encode(gpu, &mut encoder, &self.camera, skipping, scale, filter);
            gpu.queue.submit([encoder.finish()]);
            let shown = display.show(gpu, Frame::Gpu(image, size), overlays)?;
            // The frame's time to the GPU's end: what the controller holds.
            gpu.device
                .poll(wgpu::PollType::wait_indefinitely())
                .map_err(|e| ViewError::from(crate::gpu::GpuError::Poll(e)))?;
            (shown, rays)
        } else {
            renderer.set_filter(gpu, filter);
            let frame = renderer.render_preview(gpu, &self.camera, skipping, scale)?;
            let shown = display.show(gpu, Frame::Cpu(&frame.pixels, size), overlays)?;
            (shown, frame.rays)
        };
        if !shown {
            window.request_redraw();
            return Ok(());
        }
        let ms = start.elapsed().as_secs_f64() * 1e3;
        self.planner
            .record(plan, renderer.drawn_with(&self.camera, scale, filter), ms);
        self.shown = Shown {
            ms,
            scale,
            filter,
            rays,
        };
        self.frames += 1;
        self.frames_since_input += 1;
        self.dirty = false;
        Ok(())
    }

    fn key(&mut self, event_loop: &ActiveEventLoop, key: &Key) {
        match key {
            Key::Named(NamedKey::Escape) => event_loop.exit(),
            Key::Character(s) => match s.as_str() {
                "q" | "Q" => event_loop.exit(),
                "h" | "H" => self.overlay = !self.overlay,
                "r" | "R" => self.camera = self.home.clone(),
                _ => return,
            },
            _ => return,
        }
        self.dirty = true;
    }

    fn input(&mut self) {
        self.last_input = Some(Instant::now());
        self.settled_at = None;
        self.frames_since_input = 0;
        self.dirty = true;
    }
}

impl ApplicationHandler for App {
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        if self.window.is_some() {
            return;
        }
        match open_window(
            event_loop,
            format!("viewer: {} (VDI)", self.name),
            self.config.window_size,
            &self.gpu,
            self.config.present,
        ) {
            Ok((window, display)) => {
                self.window = Some(window);
                self.display = Some(display);
            }
            Err(e) => self.fail(event_loop, e),
        }
    }

    fn window_event(&mut self, event_loop: &ActiveEventLoop, _: WindowId, event: WindowEvent) {
        match event {
            WindowEvent::CloseRequested | WindowEvent::Destroyed => event_loop.exit(),
            WindowEvent::Resized(_) | WindowEvent::RedrawRequested => self.dirty = true,
            WindowEvent::ModifiersChanged(m) => self.modifiers = m.state(),
            WindowEvent::MouseInput { state, button, .. } => match state {
                ElementState::Pressed if self.drag.is_none() => {
                    let mode = match button {
                        MouseButton::Left if self.modifiers.shift_key() => Drag::Pan,
                        MouseButton::Left => Drag::Orbit,
                        MouseButton::Right | MouseButton::Middle => Drag::Pan,
                        _ => return,
                    };
                    self.drag = Some((button, mode));
                    self.input();
                }
                ElementState::Released if self.drag.is_some_and(|(b, _)| b == button) => {
                    self.drag = None;
                    self.input();
                }
                _ => {}
            },
            WindowEvent::CursorMoved { position, .. } => {
                if let (Some(last), Some((_, mode))) = (self.cursor, self.drag) {
                    let (dx, dy) = (position.x - last.x, position.y - last.y);
                    let h = self
                        .window
                        .as_ref()
                        .map_or(1.0, |w| f64::from(w.inner_size().height.max(1)));
                    self.camera = match mode {
                        Drag::Orbit => orbit(&self.camera, dx, dy, std::f64::consts::PI / h),
                        Drag::Pan => pan(&self.camera, dx, dy, h),
                    };
                    self.input();
                }
                self.cursor = Some(position);
            }
            WindowEvent::CursorLeft { .. } => self.cursor = None,
            WindowEvent::MouseWheel { delta, .. } => {
                self.camera = zoom(&self.camera, wheel_steps(delta), 1e-3 * self.diagonal);
                self.input();
            }
            WindowEvent::KeyboardInput { event, .. } if event.state == ElementState::Pressed => {
                self.key(event_loop, &event.logical_key);
                self.input();
            }
            _ => {}
        }
    }

    fn about_to_wait(&mut self, event_loop: &ActiveEventLoop) {
        if self.window.is_none() {
            return;
        }
        let moving = self.moving();
        if (self.dirty || !self.full() && !moving)
            && let Err(e) = self.frame(self.planner.next(moving))
        {
            return self.fail(event_loop, e);
        }
        let now = Instant::now();
        // At the end of the rest period: the frame at full resolution.
        let mut wake = self.last_input.map(|t| t + REST).filter(|&at| at > now);
        if let Some(n) = self.config.exit_after_frames {
            // At rest with a frame at full resolution, or `n` frames shown since the last
            // input (not while a drag goes on: the motion is still to come).
            let at_rest = self.full() && !self.moving();
            let settled =
                self.drag.is_none() && self.frames > 0 && (at_rest || self.frames_since_input >= n);
            if self.settled_at.is_none() && settled {
                // A status line: nobody reading it (a closed pipe) is no error.
                let _ = writeln!(
                    std::io::stdout(),
                    "view: {} VDI frames shown, last {:.1} ms at D_I {:.2} ({}x{} rays, {} filter), \
                     target {:.1} ms",
                    self.frames,
                    self.shown.ms,
                    self.shown.scale,
                    self.shown.rays.0,
                    self.shown.rays.1,
                    self.shown.filter.name(),
                    self.config.target_ms
                );
                let _ = std::io::stdout().flush();
                self.settled_at = Some(Instant::now());
            }
            if let Some(at) = self.settled_at.map(|t| t + self.config.exit_delay) {
                if Instant::now() >= at {
                    return event_loop.exit();
                }
                wake = Some(wake.map_or(at, |w| w.min(at)));
            }
        }
        let busy = self.dirty || (!self.full() && !self.moving());
        event_loop.set_control_flow(match wake {
            _ if busy => ControlFlow::Poll,
            Some(at) => ControlFlow::WaitUntil(at),
            None => ControlFlow::Wait,
        });
    }
}
