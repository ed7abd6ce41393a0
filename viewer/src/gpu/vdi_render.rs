//! Rendering a volumetric depth image from any nearby viewpoint on the GPU
//! (`shaders/vdi_render.wgsl`, the VDI paper's Sec. 4): the VDI uploaded once (its
//! [`VdiBuffers`]: its list starts, its supersegments as the generator packs them, and the
//! skipping grid derived from them), then one compute pass per frame for a camera; for
//! preview rendering (the paper's Sec. 4.4) rays are cast for a fraction `D_I` of the width
//! and height and a second pass upsamples them (`crate::frame_rate` picks `D_I` to hold a
//! frame time). Between lists it reads the nearest one (the paper's) or, with
//! [`VdiFilter::Linear`], the bilinear mix of the four around each point.

use std::cell::OnceCell;
use std::rc::Rc;

use residency_schemas::vdi::VdiHeader;
#[cfg(not(target_arch = "wasm32"))]
use residency_schemas::vdi::VolumetricDepthImage;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::buffers::{
    check_binding, map_for_reading, readback_buffer, storage_buffer, uniform_buffer,
};
use super::contract::{VDI_FLAG_SKIPPING, VdiView, vdi_binding, vdi_render_source};
use super::device::Gpu;
use super::error::GpuError;
use super::pipeline::{buffer_entry, storage_layout, uniform_layout};
use super::timer::PassTimer;
use super::vdi_buffers::{SKIP_TILE, VdiBuffers, VdiSlots, grid_bins};
use super::vdi_filter::VdiFilter;
use crate::scene::Camera;

/// What the rays of a VDI frame did, on average per pixel ([`VdiRenderer::work`]): the same
/// counts on any device, so that a device without a GPU's clock can still compare the work of
/// two ways of drawing.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct VdiWork {
    /// Steps through the grid of cells the rays walk (lists, or with the linear filter the
    /// cells between list centres), each skipped tile or run of empty depth bins one step.
    pub steps: f64,
    /// Of those, the steps into a cell the skipping grid could not skip (every step without
    /// skipping).
    pub cells: f64,
    /// Supersegments read.
    pub reads: f64,
}

/// One frame of a VDI rendered for a camera.
#[derive(Clone, Debug)]
pub struct VdiFrame {
    /// Linear RGBA per pixel, row-major from the top; alpha is `1 − T`.
    pub pixels: Vec<[f32; 4]>,
    /// Rays cast per row and rows (the image's size at the frame's `D_I`).
    pub rays: (u32, u32),
    /// GPU time of the pass in ms, when timestamp queries are supported.
    pub gpu_time_ms: Option<f64>,
}

/// `vdi_render.wgsl`'s entry point `name` compiled with the pipeline constants `LINEAR`
/// (the linear filter across lists) set to `linear` and `COUNT_WORK` (a frame's counts
/// instead of its colours: [`VdiRenderer::work`]) to `count_work`.
fn compile(
    gpu: &Gpu,
    module: &wgpu::ShaderModule,
    layout: &wgpu::PipelineLayout,
    name: &str,
    linear: bool,
    count_work: bool,
) -> wgpu::ComputePipeline {
    gpu.device
        .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some(name),
            layout: Some(layout),
            module,
            entry_point: Some(name),
            compilation_options: wgpu::PipelineCompilationOptions {
                constants: &[
                    ("LINEAR", f64::from(u8::from(linear))),
                    ("COUNT_WORK", f64::from(u8::from(count_work))),
                ],
                ..Default::default()
            },
            cache: None,
        })
}

/// The VDI ray caster's shader, layouts and pipelines: made once per device and shared by
/// every VDI drawn on it (the page draws a new VDI each time its render service answers;
/// compiling the shader for each would cost every answer that time).
pub struct VdiPipelines {
    module: wgpu::ShaderModule,
    layout: wgpu::BindGroupLayout,
    pipeline_layout: wgpu::PipelineLayout,
    /// The ray caster for each filter, compositing and counting its work
    /// ([`VdiRenderer::work`]), at [`VdiPipelines::variant`]: the nearest filter's compositing
    /// one compiled up front, the others the first time they are asked for.
    casters: [OnceCell<wgpu::ComputePipeline>; 4],
    upsample: wgpu::ComputePipeline,
}

impl VdiPipelines {
    /// [`VdiPipelines::new`] in an error scope, shared.
    ///
    /// # Errors
    /// A [`GpuError`] while compiling.
    pub async fn create(gpu: &Gpu) -> Result<Rc<Self>, GpuError> {
        gpu.checked_async("compiling the VDI renderer", async {
            Ok(Rc::new(Self::new(gpu)))
        })
        .await
    }

    /// Compiles `vdi_render.wgsl` for the nearest filter and the upsampling pass (the linear
    /// filter's the first time a frame asks for it).
    pub fn new(gpu: &Gpu) -> Self {
        let device = &gpu.device;
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("vdi_render.wgsl"),
            source: wgpu::ShaderSource::Wgsl(vdi_render_source().into()),
        });
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("vdi render"),
            entries: &[
                uniform_layout(vdi_binding::VIEW),
                storage_layout(vdi_binding::STARTS, true),
                storage_layout(vdi_binding::SLOTS, true),
                storage_layout(vdi_binding::TILES, true),
                storage_layout(vdi_binding::IMAGE, false),
                storage_layout(vdi_binding::DISPLAY, false),
            ],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("vdi render"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let upsample = compile(gpu, &module, &pipeline_layout, "upsample", false, false);
        let pipelines = Self {
            module,
            layout,
            pipeline_layout,
            casters: [(); 4].map(|()| OnceCell::new()),
            upsample,
        };
        pipelines.prepare(gpu, VdiFilter::Nearest);
        pipelines
    }

    /// Where the ray caster for `filter`, compositing or counting its work, is kept.
    fn variant(filter: VdiFilter, count_work: bool) -> usize {
        usize::from(filter == VdiFilter::Linear) + 2 * usize::from(count_work)
    }

    /// The ray caster for `filter`, compositing or (`count_work`) counting its work, compiled
    /// now if it was not yet.
    fn caster(&self, gpu: &Gpu, filter: VdiFilter, count_work: bool) -> &wgpu::ComputePipeline {
        self.casters[Self::variant(filter, count_work)].get_or_init(|| {
            let linear = filter == VdiFilter::Linear;
            compile(
                gpu,
                &self.module,
                &self.pipeline_layout,
                "main",
                linear,
                count_work,
            )
        })
    }

    /// Compiles the ray caster for `filter` if it is not yet, so that the first frame that
    /// uses it need not wait for it.
    pub fn prepare(&self, gpu: &Gpu, filter: VdiFilter) {
        self.caster(gpu, filter, false);
    }

    /// Whether the linear filter's ray caster has been compiled.
    pub fn linear_compiled(&self) -> bool {
        self.casters[Self::variant(VdiFilter::Linear, false)]
            .get()
            .is_some()
    }
}

/// The least `D_R` ([`VdiRenderer::set_ray_sampling`]): one list in a hundred.
pub const MIN_RAY_SAMPLING: f64 = 0.01;

/// [`GpuError::EmptyImage`] for an image without pixels.
fn nonempty(width: u32, height: u32) -> Result<(), GpuError> {
    if width == 0 || height == 0 {
        return Err(GpuError::EmptyImage { width, height });
    }
    Ok(())
}

/// A VDI on the GPU, with the image of one output size, drawn by shared [`VdiPipelines`].
pub struct VdiRenderer {
    vdi_header: VdiHeader,
    width: u32,
    height: u32,
    tiles_x: u32,
    /// The filter of `render` and `render_preview`.
    filter: VdiFilter,
    /// `D_R` of every frame ([`VdiRenderer::set_ray_sampling`]).
    ray_sampling: f64,
    pipelines: Rc<VdiPipelines>,
    view: wgpu::Buffer,
    /// The VDI's list starts, slots and skipping grids ([`VdiBuffers`]), uploaded once.
    vdi: [wgpu::Buffer; 3],
    image: wgpu::Buffer,
    display: wgpu::Buffer,
    readback: wgpu::Buffer,
    bind_group: wgpu::BindGroup,
    timer: Option<PassTimer>,
}

/// The buffers of one output size, and the bind group over them and the VDI.
struct Sized {
    image: wgpu::Buffer,
    display: wgpu::Buffer,
    readback: wgpu::Buffer,
    bind_group: wgpu::BindGroup,
}

impl VdiRenderer {
    /// Builds the buffers of `vdi`, uploads them and builds the pass for `width × height`
    /// images, with pipelines of its own ([`VdiRenderer::create`] shares them between VDIs).
    ///
    /// # Errors
    /// [`GpuError::EmptyImage`] for an empty image, a [`GpuError`] naming the buffer over the
    /// device's storage-buffer limit, or a GPU error while setting up.
    #[cfg(not(target_arch = "wasm32"))]
    pub fn new(
        gpu: &Gpu,
        vdi: &VolumetricDepthImage,
        width: u32,
        height: u32,
    ) -> Result<Self, GpuError> {
        nonempty(width, height)?;
        let pipelines = pollster::block_on(VdiPipelines::create(gpu))?;
        let buffers = VdiBuffers::of(vdi);
        pollster::block_on(Self::create(gpu, &pipelines, &buffers, width, height))
    }

    /// Uploads a VDI's `buffers` and builds the pass for `width × height` images with
    /// `pipelines`, awaited (the browser).
    ///
    /// # Errors
    /// As [`VdiRenderer::new`].
    pub async fn create<S: VdiSlots>(
        gpu: &Gpu,
        pipelines: &Rc<VdiPipelines>,
        buffers: &VdiBuffers<S>,
        width: u32,
        height: u32,
    ) -> Result<Self, GpuError> {
        nonempty(width, height)?;
        gpu.checked_async("setting up the VDI renderer", async {
            Self::build(gpu, pipelines, buffers, width, height)
        })
        .await
    }

    fn build<S: VdiSlots>(
        gpu: &Gpu,
        pipelines: &Rc<VdiPipelines>,
        buffers: &VdiBuffers<S>,
        width: u32,
        height: u32,
    ) -> Result<Self, GpuError> {
        let slot_bytes = buffers.slots.count() * 16;
        check_binding(
            gpu,
            "the VDI's supersegments",
            slot_bytes,
            "use a smaller VDI",
        )?;
        let upload = |label: &str, bytes: &[u8]| {
            let buffer =
                storage_buffer(gpu, label, bytes.len() as u64, wgpu::BufferUsages::empty());
            gpu.queue.write_buffer(&buffer, 0, bytes);
            buffer
        };
        let starts = upload("vdi list starts", bytemuck::cast_slice(&buffers.starts));
        let slots = storage_buffer(gpu, "vdi slots", slot_bytes, wgpu::BufferUsages::empty());
        buffers
            .slots
            .write_to(&gpu.queue, &slots)
            .map_err(|message| GpuError::Validation {
                what: "uploading the VDI's supersegments".to_string(),
                message,
            })?;
        let tiles = upload("vdi tiles", bytemuck::cast_slice(&buffers.tiles));
        let view = uniform_buffer(gpu, "vdi view", size_of::<VdiView>() as u64);
        let vdi_buffers = [starts, slots, tiles];
        let sized = Self::sized(gpu, &pipelines.layout, &view, &vdi_buffers, width, height)?;
        Ok(Self {
            vdi_header: buffers.header.clone(),
            width,
            height,
            tiles_x: buffers.tiles_x(),
            filter: VdiFilter::default(),
            ray_sampling: 1.0,
            pipelines: Rc::clone(pipelines),
            view,
            vdi: vdi_buffers,
            image: sized.image,
            display: sized.display,
            readback: sized.readback,
            bind_group: sized.bind_group,
            timer: PassTimer::new(gpu, "vdi render"),
        })
    }

    /// The image buffers of `width × height` images and the bind group over them, the
    /// uniforms `view` and the VDI's buffers `[starts, slots, tiles]`.
    fn sized(
        gpu: &Gpu,
        layout: &wgpu::BindGroupLayout,
        view: &wgpu::Buffer,
        [starts, slots, tiles]: &[wgpu::Buffer; 3],
        width: u32,
        height: u32,
    ) -> Result<Sized, GpuError> {
        let pixels = u64::from(width) * u64::from(height);
        check_binding(gpu, "the image", pixels * 16, "render a smaller image")?;
        let image = storage_buffer(gpu, "vdi image", pixels * 16, wgpu::BufferUsages::COPY_SRC);
        let display = storage_buffer(
            gpu,
            "vdi display",
            pixels * 16,
            wgpu::BufferUsages::COPY_SRC,
        );
        let readback = readback_buffer(gpu, "vdi image readback", pixels * 16);
        let bind_group = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("vdi render"),
            layout,
            entries: &[
                buffer_entry(vdi_binding::VIEW, view),
                buffer_entry(vdi_binding::STARTS, starts),
                buffer_entry(vdi_binding::SLOTS, slots),
                buffer_entry(vdi_binding::TILES, tiles),
                buffer_entry(vdi_binding::IMAGE, &image),
                buffer_entry(vdi_binding::DISPLAY, &display),
            ],
        });
        Ok(Sized {
            image,
            display,
            readback,
            bind_group,
        })
    }

    /// Makes this renderer draw `width × height` images, keeping the VDI where it is on the
    /// GPU (only the image buffers are made again).
    ///
    /// # Errors
    /// [`GpuError::EmptyImage`] for an empty image, or a [`GpuError`] naming the image over
    /// the device's storage-buffer limit.
    pub fn resize(&mut self, gpu: &Gpu, width: u32, height: u32) -> Result<(), GpuError> {
        nonempty(width, height)?;
        if (width, height) == (self.width, self.height) {
            return Ok(());
        }
        let sized = Self::sized(
            gpu,
            &self.pipelines.layout,
            &self.view,
            &self.vdi,
            width,
            height,
        )?;
        (self.image, self.display, self.readback, self.bind_group) =
            (sized.image, sized.display, sized.readback, sized.bind_group);
        (self.width, self.height) = (width, height);
        Ok(())
    }

    /// The uniforms of a frame for `camera` with `rays` cast: positions relative to the
    /// generating eye.
    fn view(&self, camera: &Camera, skipping: bool, rays: (u32, u32)) -> VdiView {
        let h = &self.vdi_header;
        let origin = h.camera.eye;
        let rel = |p: [f64; 3]| std::array::from_fn(|a| (p[a] - origin[a]) as f32);
        let (forward, right, up) = camera.basis();
        let tan_half = (camera.fov_y_degrees.to_radians() / 2.0).tan();
        let aspect = f64::from(self.width) / f64::from(self.height);
        let f3 = |v: [f64; 3]| v.map(|x| x as f32);
        // The generating camera's rays as the header records them: `right` and `up` scaled
        // by the tangents of the half fields of view.
        let unit = |v: [f32; 3]| {
            let v = glam::Vec3::from(v);
            (v.normalize().to_array(), v.length())
        };
        let (o_right, o_tan_x) = unit(h.rays.right);
        let (o_up, o_tan_y) = unit(h.rays.up);
        let (grid_near, grid_bin) = grid_bins(h);
        VdiView {
            width: rays.0,
            height: rays.1,
            out_width: self.width,
            out_height: self.height,
            lists_x: h.width,
            lists_y: h.height,
            eye: rel(camera.eye),
            ray_sampling: self.ray_sampling as f32,
            forward: f3(forward),
            tile: SKIP_TILE,
            right: f3(right.map(|x| x * tan_half * aspect)),
            tiles_x: self.tiles_x,
            up: f3(up.map(|x| x * tan_half)),
            flags: if skipping { VDI_FLAG_SKIPPING } else { 0 },
            o_forward: h.rays.forward,
            o_tan_x,
            o_right,
            o_tan_y,
            o_up,
            box_min: rel(h.volume_min),
            box_max: rel(h.volume_max),
            background: h.background,
            grid_near,
            grid_bin,
        }
    }

    /// Whether the frame of `view` casts the VDI's own rays (`V_O`'s eye and rays, one ray a
    /// list). Each ray then runs along its list's centre, where the linear filter weighs that
    /// list alone: it gives the nearest filter's image, which the nearest pipeline draws at
    /// its own cost (a tenth of the linear one's on lavapipe).
    fn along_lists(&self, view: &VdiView) -> bool {
        let rays = &self.vdi_header.rays;
        let close = |a: [f32; 3], b: [f32; 3]| {
            (0..3).all(|i| (a[i] - b[i]).abs() <= 1e-6 * (1.0 + b[i].abs()))
        };
        (view.width, view.height) == (view.lists_x, view.lists_y)
            && glam::Vec3::from(view.eye).length() <= 1e-6 * self.vdi_header.near
            && close(view.forward, rays.forward)
            && close(view.right, rays.right)
            && close(view.up, rays.up)
    }

    /// The pipeline that draws the frame of `camera` at `D_I` = `scale` asked with `filter`:
    /// the nearest one for a frame along the VDI's own rays ([`VdiRenderer::encode`]), else
    /// `filter`'s. What a frame's time says the filter costs.
    pub fn drawn_with(&self, camera: &Camera, scale: f64, filter: VdiFilter) -> VdiFilter {
        let view = self.view(camera, true, self.rays(scale));
        Self::pipeline_filter(self.along_lists(&view), filter)
    }

    /// [`VdiRenderer::drawn_with`] for a frame that casts the VDI's own rays (`along_lists`)
    /// or not.
    fn pipeline_filter(along_lists: bool, filter: VdiFilter) -> VdiFilter {
        if along_lists {
            VdiFilter::Nearest
        } else {
            filter
        }
    }

    /// Renders the VDI for `camera` (with or without skipping empty tiles of lists) and reads
    /// the image back.
    ///
    /// # Errors
    /// A [`GpuError`]: a GPU error while rendering, or a readback that failed.
    #[cfg(not(target_arch = "wasm32"))]
    pub fn render(&self, gpu: &Gpu, camera: &Camera, skipping: bool) -> Result<VdiFrame, GpuError> {
        self.render_preview(gpu, camera, skipping, 1.0)
    }

    /// [`VdiRenderer::render`] with rays cast for the fraction `scale` (`D_I`, clamped to
    /// `(0, 1]`, at least one ray a row and column) of the width and height, upsampled to the
    /// full image.
    ///
    /// # Errors
    /// As [`VdiRenderer::render`].
    #[cfg(not(target_arch = "wasm32"))]
    pub fn render_preview(
        &self,
        gpu: &Gpu,
        camera: &Camera,
        skipping: bool,
        scale: f64,
    ) -> Result<VdiFrame, GpuError> {
        pollster::block_on(gpu.checked_async(
            "rendering a VDI",
            self.render_async(gpu, camera, skipping, scale, self.filter),
        ))
    }

    /// The rays cast at `D_I` = `scale`.
    fn rays(&self, scale: f64) -> (u32, u32) {
        let scale = if scale > 0.0 { scale.min(1.0) } else { 1.0 };
        let of = |n: u32| ((f64::from(n) * scale).round() as u32).clamp(1, n);
        (of(self.width), of(self.height))
    }

    /// Records the passes of a frame for `camera` at `D_I` = `scale`, reading the VDI with
    /// `filter`, into `encoder`, timed where the device has timestamp queries, and returns the
    /// buffer that then holds the image (linear RGBA `vec4<f32>` per pixel, `width × height`,
    /// row-major from the top), for presenting on the GPU without a readback, and the rays
    /// cast. A frame that casts the VDI's own rays is drawn by the nearest pipeline whatever
    /// `filter` (the two coincide there), and without skipping (each ray stays in its list,
    /// where skipping only adds steps over empty depth bins); otherwise the linear filter's
    /// pipeline is compiled here the first time it is asked for.
    pub fn encode(
        &self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        camera: &Camera,
        skipping: bool,
        scale: f64,
        filter: VdiFilter,
    ) -> (&wgpu::Buffer, (u32, u32)) {
        self.record(gpu, encoder, camera, skipping, scale, filter, false)
    }

    /// [`VdiRenderer::encode`], or with `count_work` the same frame's counts per pixel
    /// ([`VdiRenderer::work`]) in place of its colours.
    #[expect(
        clippy::too_many_arguments,
        reason = "encode's frame settings, and which pipeline draws them"
    )]
    fn record(
        &self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        camera: &Camera,
        skipping: bool,
        scale: f64,
        filter: VdiFilter,
        count_work: bool,
    ) -> (&wgpu::Buffer, (u32, u32)) {
        let rays = self.rays(scale);
        let full = rays == (self.width, self.height);
        let mut view = self.view(camera, skipping, rays);
        let along_lists = self.along_lists(&view);
        let filter = Self::pipeline_filter(along_lists, filter);
        if along_lists {
            // Each ray stays in its own list, where crossing the tile's empty depth bins is
            // only extra steps (same pixels: the skipping tests).
            view.flags &= !VDI_FLAG_SKIPPING;
        }
        gpu.queue
            .write_buffer(&self.view, 0, bytemuck::bytes_of(&view));
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("vdi render"),
                timestamp_writes: self.timer.as_ref().map(|t| t.writes(true)),
            });
            pass.set_pipeline(self.pipelines.caster(gpu, filter, count_work));
            pass.set_bind_group(0, &self.bind_group, &[]);
            pass.dispatch_workgroups(rays.0.div_ceil(8), rays.1.div_ceil(8), 1);
            if !full {
                pass.set_pipeline(&self.pipelines.upsample);
                pass.dispatch_workgroups(self.width.div_ceil(8), self.height.div_ceil(8), 1);
            }
        }
        (if full { &self.image } else { &self.display }, rays)
    }

    /// [`VdiRenderer::render_preview`] reading the VDI with `filter`, awaited.
    ///
    /// # Errors
    /// As [`VdiRenderer::render`].
    pub async fn render_async(
        &self,
        gpu: &Gpu,
        camera: &Camera,
        skipping: bool,
        scale: f64,
        filter: VdiFilter,
    ) -> Result<VdiFrame, GpuError> {
        self.read_frame(gpu, camera, skipping, scale, filter, false)
            .await
    }

    /// What the rays of a frame for `camera` at full resolution with `filter` did, on
    /// average per pixel: a measure of the frame's work that is the same on any device (the
    /// frame is drawn by a pipeline that counts instead of compositing, so that the frames
    /// the user sees pay nothing for it).
    ///
    /// # Errors
    /// As [`VdiRenderer::render`].
    #[cfg(not(target_arch = "wasm32"))]
    pub fn work(
        &self,
        gpu: &Gpu,
        camera: &Camera,
        skipping: bool,
        filter: VdiFilter,
    ) -> Result<VdiWork, GpuError> {
        let frame = pollster::block_on(gpu.checked_async(
            "counting a VDI frame's work",
            self.read_frame(gpu, camera, skipping, 1.0, filter, true),
        ))?;
        let n = frame.pixels.len() as f64;
        let mean = |c: usize| frame.pixels.iter().map(|p| f64::from(p[c])).sum::<f64>() / n;
        Ok(VdiWork {
            steps: mean(0),
            cells: mean(1),
            reads: mean(2),
        })
    }

    /// [`VdiRenderer::render_async`], or with `count_work` the frame's counts per pixel.
    async fn read_frame(
        &self,
        gpu: &Gpu,
        camera: &Camera,
        skipping: bool,
        scale: f64,
        filter: VdiFilter,
        count_work: bool,
    ) -> Result<VdiFrame, GpuError> {
        let mut encoder = gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("vdi frame"),
            });
        let (shown, rays) = self.record(
            gpu,
            &mut encoder,
            camera,
            skipping,
            scale,
            filter,
            count_work,
        );
        encoder.copy_buffer_to_buffer(shown, 0, &self.readback, 0, shown.size());
        let mut maps = vec![&self.readback];
        if let Some(timer) = &self.timer {
            timer.resolve(&mut encoder);
            maps.push(timer.staging());
        }
        gpu.queue.submit([encoder.finish()]);
        map_for_reading(&gpu.device, &maps).await?;
        let pixels = bytemuck::cast_slice(&self.readback.get_mapped_range(..)?).to_vec();
        let gpu_time_ms = self.timer.as_ref().map(|t| t.read_ms(gpu)).transpose()?;
        for b in maps {
            b.unmap();
        }
        Ok(VdiFrame {
            pixels,
            rays,
            gpu_time_ms,
        })
    }

    /// Makes the frames of [`VdiRenderer::render`] and [`VdiRenderer::render_preview`] read
    /// the VDI with `filter` ([`VdiFilter::Nearest`] until this is called); the linear
    /// filter's pipeline is compiled the first time any renderer of these pipelines asks for
    /// it.
    pub fn set_filter(&mut self, gpu: &Gpu, filter: VdiFilter) {
        self.pipelines.prepare(gpu, filter);
        self.filter = filter;
    }

    /// The filter of [`VdiRenderer::render`] and [`VdiRenderer::render_preview`].
    pub fn filter(&self) -> VdiFilter {
        self.filter
    }

    /// Makes every frame drawn with the nearest filter subsample along its rays (the paper's
    /// `D_R`, Sec. 4.4, for preview rendering): a ray reads one list in `1/d_r` of those it
    /// crosses, each for the part of the ray around it (`shaders/vdi_render.wgsl`). `d_r` is clamped to
    /// [[`MIN_RAY_SAMPLING`], 1]; 1 (until this is called) reads every list, and rays that stay
    /// in their list (the camera of generation) are drawn the same whatever `d_r`. The linear
    /// filter reads every list.
    pub fn set_ray_sampling(&mut self, d_r: f64) {
        self.ray_sampling = d_r.clamp(MIN_RAY_SAMPLING, 1.0);
    }

    /// `D_R` ([`VdiRenderer::set_ray_sampling`]).
    pub fn ray_sampling(&self) -> f64 {
        self.ray_sampling
    }

    /// The pipelines this renderer draws with.
    pub fn pipelines(&self) -> &Rc<VdiPipelines> {
        &self.pipelines
    }

    /// The output size, `(width, height)`.
    pub fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }
}
