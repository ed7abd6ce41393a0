//! How frames reach a window: on the GPU (a wgpu surface of the window, on the renderer's own
//! instance and adapter, drawn by the present pass [`crate::gpu::present`] straight from the
//! image buffer, no readback), or, where no surface can be made, by a CPU blit (`softbuffer`:
//! the frame read back, converted to sRGB and copied, which works on any X11 server).
//!
//! Both draw the statistics panel and the orientation strip the same way: the GPU path
//! uploads each as a small texture only when it changes.

use std::num::NonZeroU32;
use std::sync::Arc;

use winit::window::Window;

use super::overlay::{Canvas, SrgbTable, orientation_rgba, panel_rgba};
use crate::gpu::GpuError;
use crate::gpu::device::Gpu;
use crate::gpu::present::{PresentError, Presenter, surface_format};
use crate::scene::Camera;
use crate::scene::orientation::Orientation;

/// Which way frames reach the window.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, strum::EnumString, strum::Display)]
#[strum(serialize_all = "lowercase")]
pub enum PresentPath {
    /// The GPU where a surface can be made, else the CPU.
    #[default]
    Auto,
    /// The GPU only (an error where no surface can be made).
    Gpu,
    /// The CPU blit only (each frame read back).
    Cpu,
}

/// Why a window cannot show frames.
#[derive(Debug, thiserror::Error)]
pub enum DisplayError {
    /// `softbuffer` failed to set up, size, fill or present the window's frame buffer.
    #[error("{what}: {reason}")]
    Buffer {
        /// What was being done, e.g. `presenting the frame`.
        what: &'static str,
        /// What softbuffer said, as text: its error is not `Send` or `Sync`, which the
        /// binary's error report needs.
        reason: String,
    },
    /// No surface for the GPU path (with `--present gpu`).
    #[error("cannot present on the GPU: {0}")]
    NoSurface(String),
    /// The present pass refused the frame.
    #[error(transparent)]
    Present(#[from] PresentError),
    /// The surface raised a GPU error.
    #[error(transparent)]
    Gpu(Box<GpuError>),
}

/// A softbuffer error as [`DisplayError::Buffer`].
fn buffer_error(what: &'static str) -> impl FnOnce(softbuffer::SoftBufferError) -> DisplayError {
    move |e| DisplayError::Buffer {
        what,
        reason: e.to_string(),
    }
}

/// The statistics panel: text lines with their `0x00RRGGBB` colours, and the glyph scale.
pub type Panel = (Vec<(String, u32)>, usize);

/// The orientation strip: the scale bar and axes, and the glyph scale.
pub type Footer = (Orientation, usize);

/// The overlays over a frame: the statistics panel and the orientation strip, each optional.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Overlays {
    /// The statistics panel, top left.
    pub panel: Option<Panel>,
    /// The orientation strip, along the bottom edge.
    pub footer: Option<Footer>,
}

impl Overlays {
    /// The overlays of a window `height` pixels high at glyph `scale`: the statistics `lines`
    /// and the orientation of a view from `camera` of a store in `unit`, both hidden where
    /// `lines` is `None` (the window's `h`).
    pub fn shown(
        lines: Option<Vec<(String, u32)>>,
        scale: usize,
        camera: &Camera,
        unit: Option<&str>,
        height: u32,
    ) -> Self {
        let footer = lines
            .is_some()
            .then(|| Orientation::of(camera, f64::from(height), unit))
            .flatten()
            .map(|o| (o, scale));
        Self {
            panel: lines.map(|lines| (lines, scale)),
            footer,
        }
    }
}

/// What one frame shows: the image on the GPU (GPU path) or its pixels (CPU path).
pub enum Frame<'a> {
    /// Linear RGBA `vec4<f32>` per pixel in a storage buffer, and its size.
    Gpu(&'a wgpu::Buffer, (u32, u32)),
    /// Linear RGBA pixels, and their size.
    Cpu(&'a [[f32; 4]], (u32, u32)),
}

/// The GPU path's state.
pub struct GpuDisplay {
    window: Arc<Window>,
    surface: wgpu::Surface<'static>,
    config: wgpu::SurfaceConfiguration,
    presenter: Presenter,
    /// The panel uploaded, to upload again only when it changes.
    panel: Option<Panel>,
    /// The orientation strip uploaded and the window width it was drawn for.
    footer: Option<(Footer, u32)>,
}

/// The CPU path's state.
pub struct CpuDisplay {
    window: Arc<Window>,
    surface: softbuffer::Surface<Arc<Window>, Arc<Window>>,
    srgb: SrgbTable,
}

/// A window's way of showing frames.
pub enum Display {
    /// On the GPU, no readback.
    Gpu(Box<GpuDisplay>),
    /// By a CPU blit of frames read back.
    Cpu(CpuDisplay),
}

impl Display {
    /// The display of `window` by `path`: [`PresentPath::Auto`] tries the GPU, then the CPU.
    /// Logs which path is used.
    ///
    /// # Errors
    /// [`DisplayError::NoSurface`] for [`PresentPath::Gpu`] where no surface can be made,
    /// [`DisplayError::Buffer`] when `softbuffer` cannot set up.
    pub fn new(gpu: &Gpu, window: Arc<Window>, path: PresentPath) -> Result<Self, DisplayError> {
        if path == PresentPath::Cpu {
            tracing::info!("presenting by a CPU blit (--present cpu)");
        } else {
            match GpuDisplay::new(gpu, Arc::clone(&window)) {
                Ok(d) => {
                    tracing::info!(
                        "presenting on the GPU ({:?} surface, {:?})",
                        d.config.format,
                        d.config.present_mode
                    );
                    return Ok(Self::Gpu(Box::new(d)));
                }
                Err(reason) if path == PresentPath::Gpu => {
                    return Err(DisplayError::NoSurface(reason));
                }
                Err(reason) => {
                    tracing::info!("no GPU surface ({reason}): presenting by a CPU blit");
                }
            }
        }
        let context = softbuffer::Context::new(Arc::clone(&window))
            .map_err(buffer_error("softbuffer context"))?;
        let surface = softbuffer::Surface::new(&context, Arc::clone(&window))
            .map_err(buffer_error("softbuffer surface"))?;
        Ok(Self::Cpu(CpuDisplay {
            window,
            surface,
            srgb: SrgbTable::default(),
        }))
    }

    /// Whether frames are presented on the GPU (no readback wanted).
    pub fn on_gpu(&self) -> bool {
        matches!(self, Self::Gpu(_))
    }

    /// Shows `frame` scaled to the window, with the overlays' panel over its top-left corner
    /// and orientation strip along its bottom edge. Returns
    /// whether the frame was shown (a GPU surface that is outdated, lost, occluded or timed
    /// out is set up again and the frame skipped).
    ///
    /// # Errors
    /// A [`DisplayError`]: the blit or the present pass failed, or a frame of the other
    /// path's kind was given.
    pub fn show(
        &mut self,
        gpu: &Gpu,
        frame: Frame<'_>,
        overlays: Overlays,
    ) -> Result<bool, DisplayError> {
        match (self, frame) {
            (Self::Gpu(d), Frame::Gpu(image, size)) => d.show(gpu, image, size, overlays),
            (Self::Cpu(d), Frame::Cpu(pixels, size)) => d.show(pixels, size, overlays),
            (Self::Gpu(_), Frame::Cpu(..)) | (Self::Cpu(_), Frame::Gpu(..)) => Err(
                DisplayError::NoSurface("a frame for the other way of presenting".into()),
            ),
        }
    }
}

impl GpuDisplay {
    /// A surface of `window` configured for the present pass, or why there is none.
    fn new(gpu: &Gpu, window: Arc<Window>) -> Result<Self, String> {
        let surface = gpu
            .instance
            .create_surface(Arc::clone(&window))
            .map_err(|e| e.to_string())?;
        let caps = surface.get_capabilities(&gpu.adapter);
        let format = surface_format(&caps.formats).ok_or_else(|| {
            format!(
                "the adapter cannot present to this window in an 8-bit format (formats {:?})",
                caps.formats
            )
        })?;
        let size = window.inner_size();
        let mut config = surface
            .get_default_config(&gpu.adapter, size.width.max(1), size.height.max(1))
            .ok_or("the surface is not supported by the adapter")?;
        config.format = format;
        // Vsync: FIFO is always there; mailbox where the surface offers it.
        config.present_mode = if caps.present_modes.contains(&wgpu::PresentMode::Mailbox) {
            wgpu::PresentMode::Mailbox
        } else {
            wgpu::PresentMode::Fifo
        };
        config.view_formats = Vec::new();
        gpu.checked("configuring the window surface", || {
            surface.configure(&gpu.device, &config);
            Ok(())
        })
        .map_err(|e| e.to_string())?;
        let presenter = Presenter::new(gpu, format).map_err(|e| e.to_string())?;
        Ok(Self {
            window,
            surface,
            config,
            presenter,
            panel: None,
            footer: None,
        })
    }

    /// Configures the surface for the window's size now.
    fn reconfigure(&mut self, gpu: &Gpu) {
        let size = self.window.inner_size();
        self.config.width = size.width.max(1);
        self.config.height = size.height.max(1);
        self.surface.configure(&gpu.device, &self.config);
    }

    fn show(
        &mut self,
        gpu: &Gpu,
        image: &wgpu::Buffer,
        image_size: (u32, u32),
        Overlays { panel, footer }: Overlays,
    ) -> Result<bool, DisplayError> {
        let size = self.window.inner_size();
        if size.width == 0 || size.height == 0 {
            return Ok(false);
        }
        if (size.width, size.height) != (self.config.width, self.config.height) {
            self.reconfigure(gpu);
        }
        if panel != self.panel {
            match &panel {
                Some((lines, scale)) => {
                    let (w, h, rgba) = panel_rgba(lines, *scale);
                    self.presenter.set_panel(gpu, w, h, &rgba)?;
                }
                None => self.presenter.clear_panel(gpu),
            }
            self.panel = panel;
        }
        let footer = footer.map(|f| (f, size.width));
        if footer != self.footer {
            match &footer {
                Some(((orientation, scale), width)) => {
                    let (w, h, rgba) = orientation_rgba(orientation, *width as usize, *scale);
                    self.presenter.set_footer(gpu, w, h, &rgba)?;
                }
                None => self.presenter.clear_footer(gpu),
            }
            self.footer = footer;
        }
        let (texture, suboptimal) = match self.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(t) => (t, false),
            wgpu::CurrentSurfaceTexture::Suboptimal(t) => (t, true),
            wgpu::CurrentSurfaceTexture::Timeout | wgpu::CurrentSurfaceTexture::Occluded => {
                return Ok(false);
            }
            wgpu::CurrentSurfaceTexture::Outdated => {
                self.reconfigure(gpu);
                return Ok(false);
            }
            wgpu::CurrentSurfaceTexture::Lost => {
                self.surface = gpu
                    .instance
                    .create_surface(Arc::clone(&self.window))
                    .map_err(|e| DisplayError::NoSurface(e.to_string()))?;
                self.reconfigure(gpu);
                return Ok(false);
            }
            wgpu::CurrentSurfaceTexture::Validation => {
                return Err(DisplayError::Gpu(Box::new(GpuError::Validation {
                    what: "acquiring the window's surface texture".into(),
                    message: "a validation error (see the log)".into(),
                })));
            }
        };
        let mut encoder = gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("present"),
            });
        self.presenter
            .encode_to_surface(gpu, &mut encoder, image, image_size, &texture)?;
        gpu.queue.submit([encoder.finish()]);
        self.window.pre_present_notify();
        gpu.queue.present(texture);
        if suboptimal {
            self.reconfigure(gpu);
        }
        Ok(true)
    }
}

impl CpuDisplay {
    fn show(
        &mut self,
        pixels: &[[f32; 4]],
        (iw, ih): (u32, u32),
        Overlays { panel, footer }: Overlays,
    ) -> Result<bool, DisplayError> {
        let size = self.window.inner_size();
        let (Some(w), Some(h)) = (NonZeroU32::new(size.width), NonZeroU32::new(size.height)) else {
            return Ok(false);
        };
        self.surface
            .resize(w, h)
            .map_err(buffer_error("resizing the window buffer"))?;
        let mut buffer = self
            .surface
            .buffer_mut()
            .map_err(buffer_error("window buffer"))?;
        let mut canvas = Canvas {
            pixels: &mut buffer,
            width: size.width as usize,
            height: size.height as usize,
        };
        canvas.blit(pixels, iw as usize, ih as usize, &self.srgb);
        if let Some((lines, scale)) = panel {
            canvas.panel(&lines, scale);
        }
        if let Some((orientation, scale)) = footer {
            canvas.orientation(&orientation, scale);
        }
        buffer
            .present()
            .map_err(buffer_error("presenting the frame"))?;
        Ok(true)
    }
}
