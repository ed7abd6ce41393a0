//! The window: a winit 0.30 event loop that steps the [`Session`], shows each new frame under a
//! statistics panel ([`super::display`]: on the GPU through a surface, no readback; else by a
//! `softbuffer` CPU blit, which works on any X11 server), and turns pointer and key input into
//! camera and channel-style changes.

use std::io::Write;
use std::sync::Arc;
use std::time::{Duration, Instant};

use winit::application::ApplicationHandler;
use winit::dpi::{PhysicalPosition, PhysicalSize};
use winit::error::{EventLoopError, OsError};
use winit::event::{ElementState, MouseButton, MouseScrollDelta, WindowEvent};
use winit::event_loop::{ActiveEventLoop, ControlFlow, EventLoop};
use winit::keyboard::{Key, ModifiersState, NamedKey};
use winit::window::{Window, WindowId};

use super::camera_control::{orbit, pan, zoom};
use super::controls::{self, End, KEY_STEP};
use super::display::{Display, DisplayError, Frame, Overlays, PresentPath};
use super::overlay::text_colour;
use super::session::{Session, Step};
use crate::defaults::volume_extent;
use crate::gpu::GpuError;
use crate::gpu::device::Gpu;
use crate::scene::{Camera, Scene};

/// Why the window stopped with an error: no X11 display, a window or frame buffer that cannot
/// be made, or the renderer's error.
#[derive(Debug, thiserror::Error)]
pub enum ViewError {
    /// No event loop (no display to open a window on).
    #[error("cannot open a window (is DISPLAY set? `viewer view` needs an X11 server; Xvfb works)")]
    NoDisplay(#[source] EventLoopError),
    /// The event loop failed.
    #[error("window event loop")]
    EventLoop(#[source] EventLoopError),
    /// The window cannot be created.
    #[error("cannot create the window")]
    CreateWindow(#[source] OsError),
    /// Frames cannot be shown (no surface or frame buffer, or presenting failed).
    #[error(transparent)]
    Display(#[from] DisplayError),
    /// The renderer failed.
    #[error(transparent)]
    Gpu(Box<GpuError>),
}

impl From<GpuError> for ViewError {
    fn from(e: GpuError) -> Self {
        Self::Gpu(Box::new(e))
    }
}

/// Window settings.
#[derive(Clone, Debug)]
pub struct ViewConfig {
    /// Initial window size in pixels.
    pub window_size: (u32, u32),
    /// Rendered image size relative to the window (nearest-neighbour scaled to fit).
    pub render_scale: f64,
    /// Print a summary line on standard output whenever the view settles (converged, or
    /// this many frames shown since the last input), and quit when no input follows within
    /// `exit_delay`.
    pub exit_after_frames: Option<u64>,
    /// How long a settled view waits for input before quitting (with `exit_after_frames`).
    pub exit_delay: Duration,
    /// How frames reach the window.
    pub present: PresentPath,
}

/// How long one step waits for bricks when there is nothing new to render.
const FETCH_WAIT: Duration = Duration::from_millis(15);
/// Horizontal ctrl-drag pixels that double the window width.
const WIDTH_DOUBLING_PIXELS: f64 = 200.0;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum DragMode {
    Orbit,
    Pan,
    WindowLevel,
}

struct App {
    session: Session,
    config: ViewConfig,
    home: Camera,
    window: Option<Arc<Window>>,
    display: Option<Display>,
    modifiers: ModifiersState,
    cursor: Option<PhysicalPosition<f64>>,
    drag: Option<(MouseButton, DragMode)>,
    /// Styles being changed by a ctrl-drag, applied on release (a style change rebuilds the
    /// renderer).
    window_level: Option<Scene>,
    selected: usize,
    overlay: bool,
    /// Frames shown since the last settling (or input).
    frames_shown: u64,
    last_shown: u64,
    /// When the view last settled (`exit_after_frames` only).
    settled_at: Option<Instant>,
    /// Input changed the view since the last step.
    input: bool,
    idle: bool,
    message: Option<(String, Instant)>,
    error: Option<ViewError>,
}

/// Opens the window and runs until it is closed, or quit by `q`, or by the
/// `exit_after_frames` rule.
///
/// # Errors
/// A [`ViewError`]: no display, a window or frame buffer that cannot be made, or the
/// renderer's error that stopped the session.
pub fn run(session: Session, config: ViewConfig) -> Result<(), ViewError> {
    let event_loop = EventLoop::new().map_err(ViewError::NoDisplay)?;
    let home = session.scene().camera.clone();
    let selected = session
        .scene()
        .channels
        .iter()
        .find(|s| s.visible)
        .map_or(0, |s| s.channel);
    let mut app = App {
        session,
        config,
        home,
        window: None,
        display: None,
        modifiers: ModifiersState::empty(),
        cursor: None,
        drag: None,
        window_level: None,
        selected,
        overlay: true,
        frames_shown: 0,
        last_shown: 0,
        settled_at: None,
        input: false,
        idle: false,
        message: None,
        error: None,
    };
    event_loop.run_app(&mut app).map_err(ViewError::EventLoop)?;
    match app.error {
        Some(e) => Err(e),
        None => Ok(()),
    }
}

/// Zoom steps of a wheel turn: lines as they come, pixels (touchpads) 40 to a step.
pub(super) fn wheel_steps(delta: MouseScrollDelta) -> f64 {
    match delta {
        MouseScrollDelta::LineDelta(_, y) => f64::from(y),
        MouseScrollDelta::PixelDelta(p) => p.y / 40.0,
    }
}

/// A value in at most about six characters.
/// The image size for a window of `size` at `scale` render pixels per window pixel (at least
/// one pixel each way).
pub(super) fn render_size(size: PhysicalSize<u32>, scale: f64) -> (u32, u32) {
    (
        ((f64::from(size.width) * scale).round() as u32).max(1),
        ((f64::from(size.height) * scale).round() as u32).max(1),
    )
}

/// Opens a window titled `title` of `size` (at least 1×1) and how frames reach it.
pub(super) fn open_window(
    event_loop: &ActiveEventLoop,
    title: String,
    (w, h): (u32, u32),
    gpu: &Gpu,
    present: PresentPath,
) -> Result<(Arc<Window>, Display), ViewError> {
    let attributes = Window::default_attributes()
        .with_title(title)
        .with_inner_size(PhysicalSize::new(w.max(1), h.max(1)));
    let window = Arc::new(
        event_loop
            .create_window(attributes)
            .map_err(ViewError::CreateWindow)?,
    );
    let display = Display::new(gpu, Arc::clone(&window), present)?;
    Ok((window, display))
}

fn short(v: f64) -> String {
    let a = v.abs();
    if a == 0.0 || (1e-3..1e5).contains(&a) {
        let digits = if a >= 100.0 || v.fract() == 0.0 {
            0
        } else if a >= 1.0 {
            2
        } else {
            4
        };
        format!("{v:.digits$}")
    } else {
        format!("{v:.2e}")
    }
}

/// The panel's glyph scale in a window of `size`: doubled on large windows.
pub(super) fn panel_scale(size: PhysicalSize<u32>) -> usize {
    if size.width >= 1400 && size.height >= 900 {
        2
    } else {
        1
    }
}

fn mib(bytes: u64) -> f64 {
    bytes as f64 / (1u64 << 20) as f64
}

impl App {
    fn fail(&mut self, event_loop: &ActiveEventLoop, e: ViewError) {
        if self.error.is_none() {
            self.error = Some(e);
        }
        event_loop.exit();
    }

    fn render_size(&self, size: PhysicalSize<u32>) -> (u32, u32) {
        render_size(size, self.config.render_scale)
    }

    fn window_height(&self) -> f64 {
        self.window
            .as_ref()
            .map_or(1.0, |w| w.inner_size().height.max(1) as f64)
    }

    fn say(&mut self, text: impl Into<String>) {
        self.message = Some((text.into(), Instant::now() + Duration::from_secs(3)));
    }

    /// The scene shown in the panel: the one being window/levelled, else the session's.
    fn shown_scene(&self) -> &Scene {
        self.window_level
            .as_ref()
            .unwrap_or_else(|| self.session.scene())
    }

    fn stats_lines(&self) -> Vec<(String, u32)> {
        const WHITE: u32 = 0x00ff_ffff;
        const GREY: u32 = 0x00b0_b0b0;
        let info = self.session.info();
        let t = self.session.totals();
        let mut lines = Vec::new();
        let (frame, shader, fetched, gpu, wall) = match self.session.last_frame() {
            Some(f) => (
                f.frame,
                f.shader.clone(),
                f.bricks_fetched,
                f.gpu_time_ms,
                f.wall_ms,
            ),
            None => (
                0,
                crate::gpu::renderer::ShaderCounts::default(),
                0,
                None,
                0.0,
            ),
        };
        let gpu = gpu.map_or("n/a".to_string(), |g| format!("{g:.1} ms"));
        let name: String = info.name.chars().take(16).collect();
        lines.push((
            format!("{name}  frame {frame}  {}", self.session.status()),
            WHITE,
        ));
        lines.push((
            format!(
                "samples {}  requested {}",
                shader.samples, shader.bricks_requested
            ),
            WHITE,
        ));
        lines.push((
            format!(
                "fetched {fetched} ({} in all)  substituted {}",
                t.bricks_fetched, shader.bricks_substituted
            ),
            WHITE,
        ));
        lines.push((
            format!(
                "{:.1} MiB fetched  GPU {gpu}  step {wall:.0} ms",
                mib(t.bytes_fetched)
            ),
            WHITE,
        ));
        let scene = self.shown_scene();
        for (c, name) in info.channels.iter().enumerate() {
            let style = scene.channels.iter().find(|s| s.channel == c);
            let visible = style.is_some_and(|s| s.visible);
            let window = style
                .and_then(|s| controls::window(&s.opacity))
                .map_or(String::new(), |(lo, hi)| {
                    format!(" {} .. {}", short(lo), short(hi))
                });
            let mark = if c == self.selected { '>' } else { ' ' };
            let key = if c < 9 {
                char::from(b'1' + c as u8)
            } else {
                ' '
            };
            let colour = match style {
                Some(s) if visible => text_colour(s.color),
                _ => GREY,
            };
            let name: String = name.chars().take(10).collect();
            lines.push((
                format!(
                    "{mark}{key} [{}] {name:<10}{window}",
                    if visible { 'x' } else { ' ' }
                ),
                colour,
            ));
        }
        lines.push(("drag orbit, shift/right pan, wheel zoom".into(), GREY));
        lines.push(("1-9 Tab c [ ] { } ctrl-drag r h q".into(), GREY));
        if let Some((text, until)) = &self.message
            && Instant::now() < *until
        {
            lines.push((text.clone(), 0x00ff_d060));
        }
        lines
    }

    fn title(&self) -> String {
        let info = self.session.info();
        let t = self.session.totals();
        match self.session.last_frame() {
            Some(f) => format!(
                "viewer: {} | frame {} | samples {} | requested {} fetched {} substituted {} | \
                 {:.1} MiB | GPU {} | {}",
                info.name,
                f.frame,
                f.shader.samples,
                f.shader.bricks_requested,
                t.bricks_fetched,
                f.shader.bricks_substituted,
                mib(t.bytes_fetched),
                f.gpu_time_ms
                    .map_or("n/a".to_string(), |g| format!("{g:.2} ms")),
                self.session.status()
            ),
            None => format!("viewer: {}", info.name),
        }
    }

    fn present(&mut self) -> Result<(), ViewError> {
        let lines = self.overlay.then(|| self.stats_lines());
        let (Some(window), Some(display)) = (&self.window, &mut self.display) else {
            return Ok(());
        };
        let size = window.inner_size();
        let overlays = Overlays::shown(
            lines,
            panel_scale(size),
            &self.session.scene().camera,
            self.session.info().unit.as_deref(),
            size.height,
        );
        let frame = if display.on_gpu() {
            match self.session.gpu_image() {
                Some((buffer, size)) => Frame::Gpu(buffer, size),
                None => return Ok(()),
            }
        } else {
            let (iw, ih, pixels) = self.session.image();
            Frame::Cpu(pixels, (iw, ih))
        };
        if !display.show(self.session.gpu(), frame, overlays)? {
            window.request_redraw();
            return Ok(());
        }
        let frame = self.session.totals().frames;
        if frame != self.last_shown {
            self.last_shown = frame;
            self.frames_shown += 1;
        }
        Ok(())
    }

    fn update_scene(&mut self, f: impl FnOnce(&mut Self, &mut Scene)) {
        let mut scene = self.session.scene().clone();
        f(self, &mut scene);
        self.session.set_scene(scene);
        self.idle = false;
    }

    fn key(&mut self, event_loop: &ActiveEventLoop, key: &Key) {
        let info = self.session.info().clone();
        let n = info.channels.len();
        let width = controls::reference_width(&info, self.selected);
        let step = KEY_STEP * width;
        let min_width = 1e-3 * width;
        let selected = self.selected;
        let ramp = |app: &mut Self, end: End, delta: f64| {
            app.update_scene(|_, scene| {
                if let Some(s) = controls::style_mut(scene, &info, selected) {
                    controls::move_end(&mut s.opacity, end, delta, min_width);
                }
            });
        };
        match key {
            Key::Named(NamedKey::Escape) => event_loop.exit(),
            Key::Named(NamedKey::Tab) if n > 0 => {
                self.selected = if self.modifiers.shift_key() {
                    (self.selected + n - 1) % n
                } else {
                    (self.selected + 1) % n
                };
            }
            Key::Character(s) => match s.as_str() {
                "q" | "Q" => event_loop.exit(),
                "h" | "H" => self.overlay = !self.overlay,
                "f" | "F" => {
                    let filter = controls::next_variant(self.session.scene().filter);
                    self.update_scene(|_, scene| scene.filter = filter);
                    self.say(format!("{} filter", filter.name()));
                }
                "m" | "M" => {
                    let mode = controls::next_variant(self.session.scene().mode);
                    self.update_scene(|_, scene| scene.mode = mode);
                    self.say(format!("{} mode", mode.name()));
                }
                "r" | "R" => {
                    let home = self.home.clone();
                    self.session.set_camera(home);
                    self.idle = false;
                }
                "c" | "C" => self.update_scene(|_, scene| {
                    if let Some(s) = controls::style_mut(scene, &info, selected) {
                        s.color = controls::next_colour(s.color);
                    }
                }),
                "[" => ramp(self, End::Low, -step),
                "]" => ramp(self, End::Low, step),
                "{" => ramp(self, End::High, -step),
                "}" => ramp(self, End::High, step),
                d if d.len() == 1 && ("1"..="9").contains(&d) => {
                    let c = (d.as_bytes()[0] - b'1') as usize;
                    if c >= n {
                        self.say(format!("no channel {c}: the volume has {n}"));
                        return;
                    }
                    self.selected = c;
                    let mut scene = self.session.scene().clone();
                    let Some(s) = controls::style_mut(&mut scene, &info, c) else {
                        return;
                    };
                    s.visible = !s.visible;
                    let max = crate::gpu::renderer::MAX_CHANNELS;
                    if controls::visible_count(&scene) > max {
                        self.say(format!("at most {max} channels show at once"));
                        return;
                    }
                    self.session.set_scene(scene);
                    self.idle = false;
                }
                _ => {}
            },
            _ => {}
        }
    }

    fn drag(&mut self, mode: DragMode, dx: f64, dy: f64) {
        let h = self.window_height();
        let cam = self.session.scene().camera.clone();
        match mode {
            DragMode::Orbit => {
                self.session
                    .set_camera(orbit(&cam, dx, dy, std::f64::consts::PI / h));
            }
            DragMode::Pan => self.session.set_camera(pan(&cam, dx, dy, h)),
            DragMode::WindowLevel => {
                let info = self.session.info().clone();
                let c = self.selected;
                let width = controls::reference_width(&info, c);
                let mut scene = self
                    .window_level
                    .take()
                    .unwrap_or_else(|| self.session.scene().clone());
                if let Some(s) = controls::style_mut(&mut scene, &info, c) {
                    controls::window_level(
                        &mut s.opacity,
                        (dx / WIDTH_DOUBLING_PIXELS).exp2(),
                        dy / h * width,
                        1e-3 * width,
                    );
                }
                self.window_level = Some(scene);
            }
        }
        self.idle = false;
    }
}

impl ApplicationHandler for App {
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        if self.window.is_some() {
            return;
        }
        let title = format!("viewer: {}", self.session.info().name);
        let result = (|| -> Result<(), ViewError> {
            let (window, display) = open_window(
                event_loop,
                title,
                self.config.window_size,
                self.session.gpu(),
                self.config.present,
            )?;
            self.session.set_read_pixels(!display.on_gpu());
            let size = self.render_size(window.inner_size());
            self.session.set_size(size.0, size.1);
            self.window = Some(window);
            self.display = Some(display);
            Ok(())
        })();
        if let Err(e) = result {
            self.fail(event_loop, e);
        }
    }

    fn window_event(&mut self, event_loop: &ActiveEventLoop, _: WindowId, event: WindowEvent) {
        match event {
            WindowEvent::CloseRequested | WindowEvent::Destroyed => event_loop.exit(),
            WindowEvent::Resized(size) => {
                let (w, h) = self.render_size(size);
                self.session.set_size(w, h);
                self.idle = false;
                if let Some(window) = &self.window {
                    window.request_redraw();
                }
            }
            WindowEvent::RedrawRequested => {
                if let Err(e) = self.present() {
                    self.fail(event_loop, e);
                }
            }
            WindowEvent::ModifiersChanged(m) => self.modifiers = m.state(),
            WindowEvent::MouseInput { state, button, .. } => match state {
                ElementState::Pressed if self.drag.is_none() => {
                    let mode = match button {
                        MouseButton::Left if self.modifiers.control_key() => DragMode::WindowLevel,
                        MouseButton::Left if self.modifiers.shift_key() => DragMode::Pan,
                        MouseButton::Left => DragMode::Orbit,
                        MouseButton::Right | MouseButton::Middle => DragMode::Pan,
                        _ => return,
                    };
                    self.drag = Some((button, mode));
                    self.input = true;
                }
                ElementState::Released if self.drag.is_some_and(|(b, _)| b == button) => {
                    self.drag = None;
                    self.input = true;
                    if let Some(scene) = self.window_level.take() {
                        self.session.set_scene(scene);
                        self.idle = false;
                    }
                }
                _ => {}
            },
            WindowEvent::CursorMoved { position, .. } => {
                if let (Some(last), Some((_, mode))) = (self.cursor, self.drag) {
                    self.drag(mode, position.x - last.x, position.y - last.y);
                    self.input = true;
                }
                self.cursor = Some(position);
            }
            WindowEvent::CursorLeft { .. } => self.cursor = None,
            WindowEvent::MouseWheel { delta, .. } => {
                let steps = wheel_steps(delta);
                let e = volume_extent(self.session.info());
                let diagonal = (e[0] * e[0] + e[1] * e[1] + e[2] * e[2]).sqrt();
                let cam = zoom(&self.session.scene().camera, steps, 1e-3 * diagonal);
                self.session.set_camera(cam);
                self.input = true;
            }
            WindowEvent::KeyboardInput { event, .. } if event.state == ElementState::Pressed => {
                self.key(event_loop, &event.logical_key);
                self.input = true;
                if let Some(window) = &self.window {
                    window.request_redraw();
                }
            }
            _ => {}
        }
    }

    fn about_to_wait(&mut self, event_loop: &ActiveEventLoop) {
        if self.window.is_none() {
            return;
        }
        if std::mem::take(&mut self.input) {
            self.idle = false;
            self.settled_at = None;
            self.frames_shown = 0;
        }
        let wait = if self.idle {
            Duration::ZERO
        } else {
            FETCH_WAIT
        };
        match self.session.step(wait) {
            Ok(Step::Rendered) => {
                self.idle = false;
                if let Some(window) = &self.window {
                    window.set_title(&self.title());
                }
                if let Err(e) = self.present() {
                    return self.fail(event_loop, e);
                }
            }
            Ok(Step::Waiting) => self.idle = false,
            Ok(Step::Idle) => self.idle = true,
            Err(e) => return self.fail(event_loop, e.into()),
        }
        let mut wake = self.message.as_ref().map(|(_, until)| *until);
        if let Some(n) = self.config.exit_after_frames {
            // Not while a drag goes on: the motion is still to come.
            let settled = self.drag.is_none()
                && (self.frames_shown >= n || (self.idle && self.session.totals().frames > 0));
            if self.settled_at.is_none() && settled {
                let t = self.session.totals();
                // A status line: nobody reading it (a closed pipe) is no error.
                let _ = writeln!(
                    std::io::stdout(),
                    "view: {} frames shown, {} bricks fetched ({:.2} MiB), {}",
                    t.frames,
                    t.bricks_fetched,
                    mib(t.bytes_fetched),
                    self.session.status()
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
        let now = Instant::now();
        event_loop.set_control_flow(match (self.idle, wake) {
            (false, _) => ControlFlow::Poll,
            (true, Some(at)) if at > now => ControlFlow::WaitUntil(at),
            (true, _) => ControlFlow::Wait,
        });
        if self.idle
            && self.message.as_ref().is_some_and(|(_, u)| *u <= now)
            && let Some(window) = &self.window
        {
            self.message = None;
            window.request_redraw();
        }
    }
}
