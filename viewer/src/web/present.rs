//! How the page's frames reach its canvas: on the GPU (a WebGPU canvas context, made as a
//! wgpu surface of the page's `<canvas>` on the renderer's own instance and adapter, drawn by
//! the present pass [`crate::gpu::present`] straight from the frame's image buffer, no
//! readback), or, where no surface can be made or the page asks for it (`?present=cpu`), by
//! the CPU path: each frame read back, encoded to 8-bit sRGB here ([`srgb_rgba`]) and drawn
//! by the page with `putImageData` on a 2D canvas.
//!
//! On the GPU path an image is read back only on demand ([`read_image`]): for the page's
//! `snapshot()`.

use std::rc::Rc;

use crate::gpu::GpuError;
use crate::gpu::buffers::{map_for_reading, readback_buffer};
use crate::gpu::device::Gpu;
use crate::gpu::present::{PresentError, Presenter, surface_format};
use crate::gpu::vdi_filter::VdiFilter;
use crate::gpu::vdi_render::VdiRenderer;
use crate::image::linear_to_srgb8;
use crate::scene::Camera;

/// Why the page cannot present on the GPU (it then draws by the CPU path).
#[derive(Debug, thiserror::Error)]
pub enum CanvasError {
    /// The browser made no WebGPU context of the canvas.
    #[error("cannot make a WebGPU surface of the canvas: {0}")]
    Surface(#[from] wgpu::CreateSurfaceError),
    /// The canvas offers no 8-bit RGBA or BGRA format.
    #[error("the canvas offers no 8-bit RGBA or BGRA format (formats {formats:?})")]
    Format {
        /// The formats it offers.
        formats: Vec<wgpu::TextureFormat>,
    },
    /// The adapter cannot present to the canvas.
    #[error("the canvas surface is not supported by the adapter")]
    Unsupported,
    /// Configuring the surface or acquiring its texture raised a GPU error.
    #[error(transparent)]
    Gpu(Box<GpuError>),
    /// The present pass refused the frame.
    #[error(transparent)]
    Present(#[from] PresentError),
}

impl From<GpuError> for CanvasError {
    fn from(e: GpuError) -> Self {
        Self::Gpu(Box::new(e))
    }
}

/// The page's canvas as a wgpu surface, configured for the present pass.
pub(super) struct CanvasPresenter {
    surface: wgpu::Surface<'static>,
    config: wgpu::SurfaceConfiguration,
    presenter: Presenter,
}

/// The frame on the canvas, to read back for `snapshot()`.
pub(super) enum Shown {
    /// The local renderer's image buffer.
    Local,
    /// A VDI ray cast for `camera` at `D_I` = `scale` with a filter.
    Remote(Rc<VdiRenderer>, Camera, f64, VdiFilter),
}

impl CanvasPresenter {
    /// A surface of `canvas` (its `width × height` as the canvas says now), configured in
    /// [`surface_format`]'s choice of the formats it offers, alpha opaque.
    ///
    /// # Errors
    /// A [`CanvasError`] naming why no surface can be made.
    pub(super) async fn new(
        gpu: &Gpu,
        canvas: web_sys::HtmlCanvasElement,
    ) -> Result<Self, CanvasError> {
        let (width, height) = (canvas.width().max(1), canvas.height().max(1));
        let surface = gpu
            .instance
            .create_surface(wgpu::SurfaceTarget::Canvas(canvas))?;
        let caps = surface.get_capabilities(&gpu.adapter);
        let format = surface_format(&caps.formats).ok_or_else(|| CanvasError::Format {
            formats: caps.formats.clone(),
        })?;
        let mut config = surface
            .get_default_config(&gpu.adapter, width, height)
            .ok_or(CanvasError::Unsupported)?;
        config.format = format;
        config.usage = wgpu::TextureUsages::RENDER_ATTACHMENT;
        config.present_mode = wgpu::PresentMode::Fifo;
        config.view_formats = Vec::new();
        if caps.alpha_modes.contains(&wgpu::CompositeAlphaMode::Opaque) {
            config.alpha_mode = wgpu::CompositeAlphaMode::Opaque;
        }
        gpu.checked_async("configuring the canvas surface", async {
            surface.configure(&gpu.device, &config);
            Ok(())
        })
        .await?;
        let presenter = Presenter::new(gpu, format)?;
        Ok(Self {
            surface,
            config,
            presenter,
        })
    }

    /// The surface's format.
    pub(super) fn format(&self) -> wgpu::TextureFormat {
        self.config.format
    }

    /// Submits `encoder` (the frame's passes) with the present pass drawing `image`
    /// (`image_size`, linear RGBA `vec4<f32>` per pixel) onto the canvas. Returns whether the
    /// frame reached the canvas: a surface that is outdated or lost is configured again and
    /// the frame's passes run without it.
    ///
    /// # Errors
    /// [`CanvasError::Present`] when the pass refuses the image, [`CanvasError::Gpu`] when
    /// the surface's texture cannot be had.
    pub(super) fn show(
        &mut self,
        gpu: &Gpu,
        mut encoder: wgpu::CommandEncoder,
        image: &wgpu::Buffer,
        image_size: (u32, u32),
    ) -> Result<bool, CanvasError> {
        let texture = match self.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(t)
            | wgpu::CurrentSurfaceTexture::Suboptimal(t) => t,
            wgpu::CurrentSurfaceTexture::Timeout | wgpu::CurrentSurfaceTexture::Occluded => {
                gpu.queue.submit([encoder.finish()]);
                return Ok(false);
            }
            wgpu::CurrentSurfaceTexture::Outdated | wgpu::CurrentSurfaceTexture::Lost => {
                gpu.queue.submit([encoder.finish()]);
                self.surface.configure(&gpu.device, &self.config);
                return Ok(false);
            }
            wgpu::CurrentSurfaceTexture::Validation => {
                return Err(CanvasError::Gpu(Box::new(GpuError::Validation {
                    what: "acquiring the canvas's surface texture".into(),
                    message: "a validation error (see the console)".into(),
                })));
            }
        };
        self.presenter
            .encode_to_surface(gpu, &mut encoder, image, image_size, &texture)?;
        gpu.queue.submit([encoder.finish()]);
        gpu.queue.present(texture);
        Ok(true)
    }
}

/// A command encoder for one frame.
pub(super) fn frame_encoder(gpu: &Gpu) -> wgpu::CommandEncoder {
    gpu.device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("page frame"),
        })
}

/// Resolves once the GPU has done the work submitted so far (no readback: for timing frames).
pub(super) async fn work_done(gpu: &Gpu) {
    let (tx, rx) = futures_channel::oneshot::channel();
    gpu.queue.on_submitted_work_done(move || {
        let _ = tx.send(());
    });
    let _ = rx.await;
}

/// Reads back `pixels` pixels of `image` (linear RGBA `vec4<f32>` each).
///
/// # Errors
/// A [`GpuError`]: the copy or the mapping failed.
pub(super) async fn read_image(
    gpu: &Gpu,
    image: &wgpu::Buffer,
    pixels: u64,
) -> Result<Vec<[f32; 4]>, GpuError> {
    let bytes = pixels * 16;
    let readback = readback_buffer(gpu, "snapshot readback", bytes);
    gpu.checked_async("reading the frame back", async {
        let mut encoder = frame_encoder(gpu);
        encoder.copy_buffer_to_buffer(image, 0, &readback, 0, bytes);
        gpu.queue.submit([encoder.finish()]);
        map_for_reading(&gpu.device, &[&readback]).await?;
        let out = bytemuck::cast_slice(&readback.get_mapped_range(..bytes)?).to_vec();
        readback.unmap();
        Ok(out)
    })
    .await
}

/// Linear RGBA pixels as 8-bit sRGB RGBA, alpha 255, as `viewer render`'s PNG encodes them.
pub(super) fn srgb_rgba(pixels: &[[f32; 4]], out: &mut Vec<u8>) {
    out.clear();
    out.extend(pixels.iter().flat_map(|p| {
        [
            linear_to_srgb8(p[0]),
            linear_to_srgb8(p[1]),
            linear_to_srgb8(p[2]),
            255,
        ]
    }));
}
