//! Putting a rendered image on screen on the GPU (`shaders/present.wgsl`): a full-screen
//! triangle that reads the renderer's image buffer (linear RGBA `vec4<f32>` per pixel,
//! `width × height`, row-major from the top, composited over the background already: the
//! layout of [`super::renderer::Renderer::image_buffer`] and of
//! [`super::vdi_render::VdiRenderer::encode`]'s output), scales it to the target by nearest
//! neighbour and encodes it to 8-bit sRGB with the CPU path's table
//! ([`srgb_table`], which `interactive::overlay::SrgbTable` uses too), so both paths show the
//! same bytes. On a `*Srgb` target the hardware encodes (the pass writes the linear light of
//! the table's code); on a `*Unorm` target the pass writes the code. An optional statistics
//! panel (text colours as 8-bit sRGB, uploaded only when it changes) covers the top-left
//! corner: text in its colour, the rest darkened to a quarter, as the CPU panel is drawn. An
//! optional orientation strip (a scale bar and axes, uploaded when the camera or the window
//! changes) covers the bottom edge: marks in their colour, the image showing through elsewhere.
//!
//! Nothing here reads back: the target is a surface texture, or a texture a test copies out.
//! Target-agnostic (a canvas surface in the browser works the same).

use super::buffers::{storage_buffer, uniform_buffer};
use super::contract::{gpu_struct, present_source};
use super::device::Gpu;
use crate::image::linear_to_srgb8;

/// Entries of the linear-to-sRGB table (under one 8-bit step of error).
pub const SRGB_TABLE_ENTRIES: usize = 4096;

/// The 8-bit sRGB code of linear value `i / (SRGB_TABLE_ENTRIES − 1)` for each entry `i`:
/// the one table of the CPU and GPU paths.
pub fn srgb_table() -> Vec<u8> {
    (0..SRGB_TABLE_ENTRIES)
        .map(|i| linear_to_srgb8(i as f32 / (SRGB_TABLE_ENTRIES - 1) as f32))
        .collect()
}

gpu_struct! {
    /// The present pass's uniforms (`PresentParams` in `shaders/present.wgsl`).
    pub struct PresentParams {
        /// The image's width in pixels.
        pub image_width: u32,
        /// The image's height in pixels.
        pub image_height: u32,
        /// The target's width in pixels.
        pub target_width: u32,
        /// The target's height in pixels.
        pub target_height: u32,
        /// The panel's width in pixels (0: no panel).
        pub panel_width: u32,
        /// The panel's height in pixels.
        pub panel_height: u32,
        /// 1: write sRGB codes (a `*Unorm` target); 0: write linear light (a `*Srgb` target).
        pub encode: u32,
        /// Entries of the sRGB table ([`SRGB_TABLE_ENTRIES`]).
        pub table_entries: u32,
        /// The orientation strip's width in pixels (0: none), from the target's left edge.
        pub footer_width: u32,
        /// The orientation strip's height in pixels, up from the target's bottom edge.
        pub footer_height: u32,
        /// Padding to 16 bytes.
        pub pad0: u32,
        /// Padding to 16 bytes.
        pub pad1: u32,
    }
}

/// Why a frame cannot be presented.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum PresentError {
    /// A target format the pass does not write: it needs 8-bit RGBA or BGRA.
    #[error("cannot present to a {format:?} target (8-bit RGBA or BGRA, sRGB or not, only)")]
    Format {
        /// The format.
        format: wgpu::TextureFormat,
    },
    /// An empty image or target.
    #[error(
        "cannot present a {image_width}×{image_height} image to a {target_width}×{target_height} target: one is empty"
    )]
    Empty {
        /// The image's width.
        image_width: u32,
        /// The image's height.
        image_height: u32,
        /// The target's width.
        target_width: u32,
        /// The target's height.
        target_height: u32,
    },
    /// An image buffer smaller than its size says.
    #[error("the image buffer holds {bytes} bytes, under the {needed} of a {width}×{height} image")]
    ImageBuffer {
        /// Bytes of the buffer.
        bytes: u64,
        /// Bytes the image needs (16 a pixel).
        needed: u64,
        /// The image's width.
        width: u32,
        /// The image's height.
        height: u32,
    },
    /// Overlay pixels (the panel's or the orientation strip's) that do not fill it.
    #[error("the {what} has {bytes} bytes for {width}×{height} RGBA pixels")]
    Overlay {
        /// `panel` or `orientation strip`.
        what: &'static str,
        /// Bytes given.
        bytes: usize,
        /// Width.
        width: u32,
        /// Height.
        height: u32,
    },
}

/// The binding numbers of `present.wgsl`'s group 0.
mod binding {
    pub const PARAMS: u32 = 0;
    pub const IMAGE: u32 = 1;
    pub const TABLE: u32 = 2;
    pub const PANEL: u32 = 3;
    pub const FOOTER: u32 = 4;
}

/// The present pass's overlays.
#[derive(Clone, Copy)]
enum Overlay {
    /// The statistics panel, top left.
    Panel,
    /// The orientation strip, along the bottom edge.
    Footer,
}

/// An overlay texture (`Rgba8Uint`), at least 1 × 1, and the size of what it holds (0 × 0:
/// nothing).
struct Layer {
    texture: wgpu::Texture,
    view: wgpu::TextureView,
    size: (u32, u32),
}

impl Layer {
    /// An empty layer.
    fn empty(gpu: &Gpu, label: &'static str) -> Self {
        let (texture, view) = overlay_texture(gpu, label, 1, 1, &[0; 4]);
        Self {
            texture,
            view,
            size: (0, 0),
        }
    }

    /// Holds `rgba` (`width × height` pixels) from now on: written into the texture it has
    /// when that is the same size, else into a new one. Returns whether the texture is new
    /// (bind groups holding the old one are stale).
    ///
    /// # Errors
    /// [`PresentError::Overlay`] when `rgba` does not hold `width × height` pixels.
    fn set(
        &mut self,
        gpu: &Gpu,
        what: &'static str,
        (width, height): (u32, u32),
        rgba: &[u8],
    ) -> Result<bool, PresentError> {
        if rgba.len() != width as usize * height as usize * 4 {
            return Err(PresentError::Overlay {
                what,
                bytes: rgba.len(),
                width,
                height,
            });
        }
        if width == 0 || height == 0 {
            return Ok(self.clear(gpu, what));
        }
        if (self.texture.width(), self.texture.height()) == (width, height) {
            write_rgba(gpu, &self.texture, rgba);
            self.size = (width, height);
            return Ok(false);
        }
        (self.texture, self.view) = overlay_texture(gpu, what, width, height, rgba);
        self.size = (width, height);
        Ok(true)
    }

    /// Holds nothing from now on. Returns whether the texture is new.
    fn clear(&mut self, gpu: &Gpu, what: &'static str) -> bool {
        if self.size == (0, 0) {
            return false;
        }
        *self = Self::empty(gpu, what);
        true
    }
}

/// The present pass for one target format.
pub struct Presenter {
    format: wgpu::TextureFormat,
    pipeline: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
    params: wgpu::Buffer,
    table: wgpu::Buffer,
    /// The panel (alpha 0 where the panel is only darkened).
    panel: Layer,
    /// The orientation strip (alpha 0 where the image shows through).
    footer: Layer,
    /// The bind group of the last image presented (its buffer and bytes read), made again only
    /// when the image buffer, its size or an overlay's texture changes.
    bound: std::sync::Mutex<Option<(wgpu::Buffer, u64, wgpu::BindGroup)>>,
}

impl std::fmt::Debug for Presenter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Presenter")
            .field("format", &self.format)
            .field("panel", &self.panel.size)
            .field("footer", &self.footer.size)
            .finish_non_exhaustive()
    }
}

/// The format a surface with `formats` is presented in: an 8-bit sRGB format (the hardware
/// encodes) before an 8-bit unorm one (the pass encodes); `None` when it offers neither.
pub fn surface_format(formats: &[wgpu::TextureFormat]) -> Option<wgpu::TextureFormat> {
    use wgpu::TextureFormat as F;
    [
        F::Bgra8UnormSrgb,
        F::Rgba8UnormSrgb,
        F::Bgra8Unorm,
        F::Rgba8Unorm,
    ]
    .into_iter()
    .find(|f| formats.contains(f))
}

impl Presenter {
    /// The pass for targets of `format` (8-bit RGBA or BGRA, sRGB or not).
    ///
    /// # Errors
    /// [`PresentError::Format`] for any other format.
    pub fn new(gpu: &Gpu, format: wgpu::TextureFormat) -> Result<Self, PresentError> {
        if surface_format(&[format]).is_none() {
            return Err(PresentError::Format { format });
        }
        let device = &gpu.device;
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("present.wgsl"),
            source: wgpu::ShaderSource::Wgsl(present_source().into()),
        });
        let fragment = wgpu::ShaderStages::FRAGMENT;
        let storage = |b: u32| wgpu::BindGroupLayoutEntry {
            binding: b,
            visibility: fragment,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Storage { read_only: true },
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        };
        let texture = |b: u32| wgpu::BindGroupLayoutEntry {
            binding: b,
            visibility: fragment,
            ty: wgpu::BindingType::Texture {
                sample_type: wgpu::TextureSampleType::Uint,
                view_dimension: wgpu::TextureViewDimension::D2,
                multisampled: false,
            },
            count: None,
        };
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("present"),
            entries: &[
                wgpu::BindGroupLayoutEntry {
                    binding: binding::PARAMS,
                    visibility: fragment,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Uniform,
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                    count: None,
                },
                storage(binding::IMAGE),
                storage(binding::TABLE),
                texture(binding::PANEL),
                texture(binding::FOOTER),
            ],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("present"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("present"),
            layout: Some(&pipeline_layout),
            vertex: wgpu::VertexState {
                module: &module,
                entry_point: Some("vs_main"),
                compilation_options: wgpu::PipelineCompilationOptions::default(),
                buffers: &[],
            },
            primitive: wgpu::PrimitiveState::default(),
            depth_stencil: None,
            multisample: wgpu::MultisampleState::default(),
            fragment: Some(wgpu::FragmentState {
                module: &module,
                entry_point: Some("fs_main"),
                compilation_options: wgpu::PipelineCompilationOptions::default(),
                targets: &[Some(wgpu::ColorTargetState {
                    format,
                    blend: None,
                    write_mask: wgpu::ColorWrites::ALL,
                })],
            }),
            multiview_mask: None,
            cache: None,
        });
        let params = uniform_buffer(gpu, "present params", size_of::<PresentParams>() as u64);
        let codes: Vec<u32> = srgb_table().into_iter().map(u32::from).collect();
        let table = storage_buffer(
            gpu,
            "srgb table",
            (codes.len() * 4) as u64,
            wgpu::BufferUsages::empty(),
        );
        gpu.queue
            .write_buffer(&table, 0, bytemuck::cast_slice(&codes));
        Ok(Self {
            format,
            pipeline,
            layout,
            params,
            table,
            panel: Layer::empty(gpu, "panel"),
            footer: Layer::empty(gpu, "orientation strip"),
            bound: std::sync::Mutex::new(None),
        })
    }

    /// The target format.
    pub fn format(&self) -> wgpu::TextureFormat {
        self.format
    }

    /// Sets the panel over the top-left corner: `width × height` pixels of `[r, g, b, a]`,
    /// row-major from the top, `r, g, b` an 8-bit sRGB text colour where `a` is not 0, and
    /// `a` = 0 where the image shows through darkened to a quarter. Uploaded now, once.
    ///
    /// # Errors
    /// [`PresentError::Overlay`] when `rgba` does not hold `width × height` pixels.
    pub fn set_panel(
        &mut self,
        gpu: &Gpu,
        width: u32,
        height: u32,
        rgba: &[u8],
    ) -> Result<(), PresentError> {
        self.set_overlay(gpu, Overlay::Panel, (width, height), rgba)
    }

    /// Removes the panel.
    pub fn clear_panel(&mut self, gpu: &Gpu) {
        self.clear_overlay(gpu, Overlay::Panel);
    }

    /// Sets the orientation strip along the bottom edge, from the left: `width × height`
    /// pixels of `[r, g, b, a]`, row-major from the top, `r, g, b` an 8-bit sRGB colour where
    /// `a` is not 0, and `a` = 0 where the image shows through. Uploaded now, once.
    ///
    /// # Errors
    /// [`PresentError::Overlay`] when `rgba` does not hold `width × height` pixels.
    pub fn set_footer(
        &mut self,
        gpu: &Gpu,
        width: u32,
        height: u32,
        rgba: &[u8],
    ) -> Result<(), PresentError> {
        self.set_overlay(gpu, Overlay::Footer, (width, height), rgba)
    }

    /// Removes the orientation strip.
    pub fn clear_footer(&mut self, gpu: &Gpu) {
        self.clear_overlay(gpu, Overlay::Footer);
    }

    /// An overlay's layer and its name in errors.
    fn layer(&mut self, which: Overlay) -> (&mut Layer, &'static str) {
        match which {
            Overlay::Panel => (&mut self.panel, "panel"),
            Overlay::Footer => (&mut self.footer, "orientation strip"),
        }
    }

    /// [`Layer::set`] of an overlay; a new texture unbinds the old.
    fn set_overlay(
        &mut self,
        gpu: &Gpu,
        which: Overlay,
        size: (u32, u32),
        rgba: &[u8],
    ) -> Result<(), PresentError> {
        let (layer, what) = self.layer(which);
        if layer.set(gpu, what, size, rgba)? {
            self.unbind();
        }
        Ok(())
    }

    /// [`Layer::clear`] of an overlay; a new texture unbinds the old.
    fn clear_overlay(&mut self, gpu: &Gpu, which: Overlay) {
        let (layer, what) = self.layer(which);
        if layer.clear(gpu, what) {
            self.unbind();
        }
    }

    /// Forgets the bind group (an overlay texture it binds is gone).
    fn unbind(&mut self) {
        *self
            .bound
            .get_mut()
            .unwrap_or_else(std::sync::PoisonError::into_inner) = None;
    }

    /// [`Presenter::encode`] onto a surface's texture (a window's or a canvas's), at its size.
    ///
    /// # Errors
    /// As [`Presenter::encode`].
    pub fn encode_to_surface(
        &self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        image: &wgpu::Buffer,
        image_size: (u32, u32),
        surface: &wgpu::SurfaceTexture,
    ) -> Result<(), PresentError> {
        let view = surface
            .texture
            .create_view(&wgpu::TextureViewDescriptor::default());
        let size = (surface.texture.width(), surface.texture.height());
        self.encode(gpu, encoder, image, image_size, &view, size)
    }

    /// Records the pass drawing `image` (`image_size`, linear RGBA `vec4<f32>` per pixel) onto
    /// `target` (`target_size`, of this presenter's format) into `encoder`.
    ///
    /// # Errors
    /// [`PresentError::Empty`] for an empty image or target, [`PresentError::ImageBuffer`]
    /// for a buffer smaller than the image.
    pub fn encode(
        &self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        image: &wgpu::Buffer,
        image_size: (u32, u32),
        target: &wgpu::TextureView,
        target_size: (u32, u32),
    ) -> Result<(), PresentError> {
        let ((iw, ih), (tw, th)) = (image_size, target_size);
        if iw == 0 || ih == 0 || tw == 0 || th == 0 {
            return Err(PresentError::Empty {
                image_width: iw,
                image_height: ih,
                target_width: tw,
                target_height: th,
            });
        }
        let needed = u64::from(iw) * u64::from(ih) * 16;
        if image.size() < needed {
            return Err(PresentError::ImageBuffer {
                bytes: image.size(),
                needed,
                width: iw,
                height: ih,
            });
        }
        let (pw, ph) = self.panel.size;
        let (fw, fh) = self.footer.size;
        let params = PresentParams {
            image_width: iw,
            image_height: ih,
            target_width: tw,
            target_height: th,
            panel_width: pw,
            panel_height: ph,
            encode: u32::from(!self.format.is_srgb()),
            table_entries: SRGB_TABLE_ENTRIES as u32,
            footer_width: fw,
            footer_height: fh,
            pad0: 0,
            pad1: 0,
        };
        gpu.queue
            .write_buffer(&self.params, 0, bytemuck::bytes_of(&params));
        let mut bound = self
            .bound
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        let bind_group = match &*bound {
            Some((buffer, bytes, group)) if buffer == image && *bytes == needed => group.clone(),
            _ => {
                let group = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some("present"),
                    layout: &self.layout,
                    entries: &[
                        wgpu::BindGroupEntry {
                            binding: binding::PARAMS,
                            resource: self.params.as_entire_binding(),
                        },
                        wgpu::BindGroupEntry {
                            binding: binding::IMAGE,
                            resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                                buffer: image,
                                offset: 0,
                                size: std::num::NonZeroU64::new(needed),
                            }),
                        },
                        wgpu::BindGroupEntry {
                            binding: binding::TABLE,
                            resource: self.table.as_entire_binding(),
                        },
                        wgpu::BindGroupEntry {
                            binding: binding::PANEL,
                            resource: wgpu::BindingResource::TextureView(&self.panel.view),
                        },
                        wgpu::BindGroupEntry {
                            binding: binding::FOOTER,
                            resource: wgpu::BindingResource::TextureView(&self.footer.view),
                        },
                    ],
                });
                *bound = Some((image.clone(), needed, group.clone()));
                group
            }
        };
        drop(bound);
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("present"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: target,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Clear(wgpu::Color::BLACK),
                    store: wgpu::StoreOp::Store,
                },
            })],
            depth_stencil_attachment: None,
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &bind_group, &[]);
        pass.draw(0..3, 0..1);
        Ok(())
    }
}

/// An `Rgba8Uint` texture of `width × height` holding `rgba`, and its view.
fn overlay_texture(
    gpu: &Gpu,
    label: &'static str,
    width: u32,
    height: u32,
    rgba: &[u8],
) -> (wgpu::Texture, wgpu::TextureView) {
    let texture = gpu.device.create_texture(&wgpu::TextureDescriptor {
        label: Some(label),
        size: wgpu::Extent3d {
            width,
            height,
            depth_or_array_layers: 1,
        },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: wgpu::TextureFormat::Rgba8Uint,
        usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        view_formats: &[],
    });
    write_rgba(gpu, &texture, rgba);
    let view = texture.create_view(&wgpu::TextureViewDescriptor::default());
    (texture, view)
}

/// Writes `rgba` over the whole of `texture` (`Rgba8Uint`).
fn write_rgba(gpu: &Gpu, texture: &wgpu::Texture, rgba: &[u8]) {
    gpu.queue.write_texture(
        texture.as_image_copy(),
        rgba,
        wgpu::TexelCopyBufferLayout {
            offset: 0,
            bytes_per_row: Some(texture.width() * 4),
            rows_per_image: Some(texture.height()),
        },
        texture.size(),
    );
}
