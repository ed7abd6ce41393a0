//! The renderer of one volume and one scene: the shared [`RaycastPipeline`], the
//! `ResidencyState` (octree, page tables, cache), the `SceneTables`, and the per-frame
//! buffers, with one frame's parameters, dispatch and readback (image, capped request list,
//! slot usage, statistics, GPU time).

use schemars::JsonSchema;
use serde::Serialize;

use std::sync::Arc;

use super::brick_cache::BrickCache;
use super::brick_cut::{CutView, brick_cut};
use super::buffers::{
    check_binding, map_for_reading, readback_buffer, storage_buffer, uniform_buffer,
};
use super::clipping::clip_params;
use super::contract::{
    FLAG_SKIPPING, FLAG_SUBSTITUTION, FrameCounters, Params, RayState, image_texels,
};
use super::device::Gpu;
use super::error::GpuError;
use super::occupancy::occupancy_geometry;
use super::page_table::PageTables;
use super::pipeline::{Bindings, PipelineKey, RaycastPipeline};
use super::residency::ResidencyState;
use super::segments::SegmentStage;
use super::tables::{SceneTables, channel_level_bounds};
use super::timer::PassTimer;
use super::vdi::{VdiCompactor, VdiGeneration, VdiTarget};
use crate::octree::ResidencyOctree;
use crate::scene::{Camera, ChannelStyle, OpacityPoint, RenderMode, Scene};
use crate::source::{BrickKey, BrickVoxels, VolumeInfo};

// The names code outside `gpu` has long found here; each lives in its own module.
pub use super::contract::MAX_CHANNELS;
pub use super::method::{Method, UnknownMethod};
pub use super::options::RenderOptions;
pub use super::residency::{Inserted, is_clear};

/// Bytes of the counters at the head of the request buffer.
const COUNTER_BYTES: u64 = size_of::<FrameCounters>() as u64;

/// Bytes of one ray's state between passes.
const RAY_STATE_BYTES: u64 = size_of::<RayState>() as u64;

/// Most passes of one frame before the renderer gives up (a ray of a million steps or more).
const MAX_PASSES: u32 = 100_000;

/// What the shader counted in one frame.
#[derive(Clone, Debug, Default, PartialEq, Serialize, JsonSchema)]
pub struct ShaderCounts {
    /// Samples taken (a homogeneous node integrated analytically counts as one).
    pub samples: u64,
    /// Octree nodes skipped as empty in every channel.
    pub empty_nodes_skipped: u64,
    /// Homogeneous nodes integrated analytically.
    pub homogeneous_nodes: u64,
    /// Distinct missing bricks requested (before the cap).
    pub bricks_requested: u64,
    /// Requests over the per-frame cap (dropped; repeated next frame).
    pub requests_over_cap: u64,
    /// Distinct missing bricks for which another resident level was substituted.
    pub bricks_substituted: u64,
    /// Samples (or unmapped nodes) with no resident data in any channel.
    pub samples_without_data: u64,
    /// Distinct cache slots the frame read (usage feedback): the bricks this method needs
    /// resident for this view.
    pub bricks_used: u64,
    /// Boxes rasterised into ray segment lists before ray casting: SparseLeap's occupancy
    /// geometry or the rasterize method's cut of bricks (0 for the other methods).
    pub segment_boxes: u64,
    /// Rays whose ray segment list did not fit the pool (SparseLeap, rasterize): marched
    /// whole.
    pub rays_overflowed: u64,
    /// Compute passes the frame's ray casting took: resident-only passes while rays only run
    /// out of steps, and a full pass after any that stopped rays for it (a request, a
    /// substitute or the per-corner path needed). 1 for a converged frame whose rays fit in
    /// one pass.
    #[schemars(range(min = 1))]
    pub passes: u64,
}

/// One missing brick the shader reported.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BrickRequest {
    /// The brick.
    pub key: BrickKey,
    /// World distance along the first ray that asked for it.
    pub distance: f32,
}

/// One rendered frame, read back.
#[derive(Clone, Debug)]
pub struct FrameOutput {
    /// Linear RGBA per pixel, row-major from the top; alpha is `1 − T`. Empty for a frame
    /// rendered without its pixels ([`Renderer::render_without_pixels`]).
    pub pixels: Vec<[f32; 4]>,
    /// Missing bricks (distinct, at most the cap).
    pub requests: Vec<BrickRequest>,
    /// Shader counters.
    pub counts: ShaderCounts,
    /// GPU time of the compute pass in ms, when timestamp queries are supported.
    pub gpu_time_ms: Option<f64>,
}

/// The staging buffers one frame's results are read back through.
struct Readback {
    requests: wgpu::Buffer,
    usage: wgpu::Buffer,
    image: wgpu::Buffer,
    timer: Option<PassTimer>,
}

/// The per-frame data: the uniforms, the image, the request list, the suspended rays' states
/// between passes, and their readback.
struct FrameBuffers {
    params: wgpu::Buffer,
    requests: wgpu::Buffer,
    image: wgpu::Buffer,
    rays: wgpu::Buffer,
    readback: Readback,
}

impl FrameBuffers {
    /// Buffers for `width × height` pixels, `max_requests` requests and a cache of
    /// `cache_slots` slots, for `mode` with `channels` channels drawn: in
    /// [`RenderMode::Mip`] and [`RenderMode::Iso`] the image buffer holds after the image each
    /// pixel's state between passes ([`image_texels`]).
    fn new(
        gpu: &Gpu,
        options: &RenderOptions,
        cache_slots: u32,
        mode: RenderMode,
        channels: usize,
    ) -> Result<Self, GpuError> {
        let pixels = u64::from(options.width) * u64::from(options.height);
        let image_bytes = image_texels(pixels, mode, channels) * 16;
        check_binding(gpu, "the image", image_bytes, "render a smaller image")?;
        check_binding(
            gpu,
            "the ray states",
            pixels * RAY_STATE_BYTES,
            "render a smaller image",
        )?;
        let params = uniform_buffer(gpu, "raycast params", size_of::<Params>() as u64);
        let request_bytes = COUNTER_BYTES + 8 * u64::from(options.max_requests);
        let requests = storage_buffer(gpu, "requests", request_bytes, wgpu::BufferUsages::COPY_SRC);
        let image = storage_buffer(gpu, "image", image_bytes, wgpu::BufferUsages::COPY_SRC);
        let rays = storage_buffer(
            gpu,
            "ray states",
            pixels * RAY_STATE_BYTES,
            wgpu::BufferUsages::empty(),
        );
        let readback = Readback {
            requests: readback_buffer(gpu, "requests readback", request_bytes),
            usage: readback_buffer(gpu, "usage readback", u64::from(cache_slots) * 4),
            image: readback_buffer(gpu, "image readback", pixels * 16),
            timer: PassTimer::new(gpu, "raycast"),
        };
        Ok(Self {
            params,
            requests,
            image,
            rays,
            readback,
        })
    }
}

/// The renderer of one volume and one scene, in three parts that live as long as what they
/// depend on: the compiled pipeline (shared by every renderer of the same format and method
/// on the device), the residency state (octree, page tables, cache: as long as the channels
/// drawn), and the scene tables (rewritten in place when the style changes), plus the
/// per-frame buffers.
pub struct Renderer {
    options: RenderOptions,
    scene: Scene,
    pipeline: Arc<RaycastPipeline>,
    residency: ResidencyState,
    tables: SceneTables,
    buffers: FrameBuffers,
    bind_group: wgpu::BindGroup,
    /// The ray segment lists (SparseLeap and rasterize).
    segments: Option<SegmentStage>,
    /// The buffer of the last volumetric depth image generated, and its bind group, kept for
    /// the next of the same size.
    vdi: Option<(VdiTarget, wgpu::BindGroup)>,
    /// The compaction of a VDI before its readback, compiled at the first VDI.
    vdi_compactor: Option<VdiCompactor>,
    frame: u32,
    /// Images read back so far (one per frame that wanted its pixels).
    image_readbacks: u64,
}

/// What a frame's passes write: the image, or a volumetric depth image's target.
#[derive(Clone, Copy)]
enum FrameTarget<'a> {
    /// The image, read back into `FrameOutput::pixels` when `pixels` (once, after the
    /// frame's last pass), else left on the GPU ([`Renderer::image_buffer`]).
    Image {
        /// Whether to read the image back.
        pixels: bool,
    },
    /// A VDI target, with its bind group.
    Vdi(&'a VdiTarget, &'a wgpu::BindGroup),
}

impl Renderer {
    /// Sets up the renderer of `scene` over the volume `info`: octree (ranges from the
    /// volume's region metadata), page tables, cache, tables and pipeline. Only visible
    /// channels are rendered (and ever fetched).
    ///
    /// # Errors
    /// A [`GpuError`] naming what does not fit: an empty image, clipping that cannot be
    /// drawn, too many visible channels or levels, a volume the octree refuses, a buffer or
    /// the cache over the device's limits, or a GPU error while setting up.
    #[cfg(not(target_arch = "wasm32"))]
    pub fn new(
        gpu: &Gpu,
        info: &VolumeInfo,
        scene: &Scene,
        options: RenderOptions,
    ) -> Result<Self, GpuError> {
        pollster::block_on(Self::create(gpu, info, scene, options))
    }

    /// [`Renderer::new`], awaited (the browser).
    ///
    /// # Errors
    /// As [`Renderer::new`].
    pub async fn create(
        gpu: &Gpu,
        info: &VolumeInfo,
        scene: &Scene,
        options: RenderOptions,
    ) -> Result<Self, GpuError> {
        gpu.checked_async("setting up the renderer", async {
            Self::build(gpu, info, scene, options)
        })
        .await
    }

    fn build(
        gpu: &Gpu,
        info: &VolumeInfo,
        scene: &Scene,
        options: RenderOptions,
    ) -> Result<Self, GpuError> {
        if options.width == 0 || options.height == 0 {
            return Err(GpuError::EmptyImage {
                width: options.width,
                height: options.height,
            });
        }
        scene.clip.check()?;
        if scene.mode == RenderMode::Iso
            && matches!(options.method, Method::SparseLeap | Method::Rasterize)
        {
            return Err(GpuError::ModeMethod {
                method: options.method.name(),
                mode: scene.mode.name(),
            });
        }
        let visible: Vec<&ChannelStyle> = scene.channels.iter().filter(|c| c.visible).collect();
        if visible.len() > MAX_CHANNELS {
            return Err(GpuError::TooManyVisible {
                channels: visible.len(),
            });
        }
        let channels: Vec<usize> = visible.iter().map(|c| c.channel).collect();
        let mut residency = ResidencyState::new(gpu, info, &channels, scene.filter, &options)?;
        residency.restyle(&visible, scene.mode);
        let tables = SceneTables::new(gpu, &residency, &options, &visible)?;
        let buffers = FrameBuffers::new(
            gpu,
            &options,
            residency.cache().capacity(),
            scene.mode,
            visible.len(),
        )?;
        let pipeline = gpu.pipelines.get_or_build(
            &gpu.device,
            PipelineKey {
                kind: residency.cache().kind(),
                method: options.method,
                filter: scene.filter,
                mode: scene.mode,
            },
        );
        let atlas = residency.cache().views();
        let bind_group = pipeline.bind_group(
            &gpu.device,
            &Bindings {
                params: &buffers.params,
                nodes: residency.nodes(),
                scene: tables.uniforms(),
                tables: tables.buffer(),
                pages: residency.pages().buffer(),
                page_flags: residency.pages().flags(),
                requests: &buffers.requests,
                usage: residency.cache().usage_buffer(),
                image: &buffers.image,
                atlas: &atlas,
                rays: &buffers.rays,
            },
        );
        let segments = residency.segment_area().map(|area| {
            SegmentStage::new(
                gpu,
                options.width,
                options.height,
                &buffers.params,
                residency.nodes(),
                area,
            )
        });
        let mut renderer = Self {
            options,
            scene: scene.clone(),
            pipeline,
            residency,
            tables,
            buffers,
            bind_group,
            segments,
            vdi: None,
            vdi_compactor: None,
            frame: 0,
            image_readbacks: 0,
        };
        renderer.flush(gpu);
        Ok(renderer)
    }

    /// The volume rendered.
    pub fn info(&self) -> &VolumeInfo {
        self.residency.info()
    }

    /// The residency octree.
    pub fn octree(&self) -> &ResidencyOctree {
        self.residency.octree()
    }

    /// The page tables (CPU mirror of what the shader reads).
    pub fn pages(&self) -> &PageTables {
        self.residency.pages()
    }

    /// The brick cache.
    pub fn cache(&self) -> &BrickCache {
        self.residency.cache()
    }

    /// The compiled pipeline (shared with every renderer of its format and method).
    pub fn pipeline(&self) -> &Arc<RaycastPipeline> {
        &self.pipeline
    }

    /// The options in use.
    pub fn options(&self) -> &RenderOptions {
        &self.options
    }

    /// Number of frames rendered so far.
    pub fn frames(&self) -> u32 {
        self.frame
    }

    /// Replaces the camera (the transfer functions stay).
    pub fn set_camera(&mut self, camera: Camera) {
        self.scene.camera = camera;
    }

    /// The scene drawn.
    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    /// Replaces the scene in place when every channel it shows is one this renderer was built
    /// with: the camera, background, colours and transfer functions change, the scene tables
    /// are rewritten and the clear-brick marks redone, and the residency state (octree, page
    /// tables, cache: every resident brick) and the pipeline stay. A channel hidden since
    /// construction is drawn fully transparent, so its bricks are clear (never fetched) and
    /// showing it again finds its resident bricks. Returns `false`, changing nothing, when the
    /// scene shows a channel this renderer does not have, has another filter or mode, or its
    /// transfer functions do not fit the table (or its clipping cannot be drawn): such a
    /// scene needs a new renderer.
    pub fn restyle(&mut self, gpu: &Gpu, scene: &Scene) -> bool {
        let drawn = self.residency.octree().channels();
        if scene.filter != self.scene.filter
            || scene.mode != self.scene.mode
            || scene.clip.check().is_err()
        {
            return false;
        }
        if scene
            .channels
            .iter()
            .any(|s| s.visible && !drawn.contains(&s.channel))
        {
            return false;
        }
        let styles: Vec<ChannelStyle> = drawn
            .iter()
            .map(|&c| {
                scene
                    .channels
                    .iter()
                    .find(|s| s.channel == c && s.visible)
                    .cloned()
                    .unwrap_or(ChannelStyle {
                        channel: c,
                        visible: true,
                        color: [0.0; 3],
                        opacity: vec![OpacityPoint {
                            value: 0.0,
                            opacity: 0.0,
                        }],
                    })
            })
            .collect();
        let styles: Vec<&ChannelStyle> = styles.iter().collect();
        if !self
            .tables
            .rewrite(gpu, &self.residency, &self.options, &styles)
        {
            return false;
        }
        self.residency.restyle(&styles, scene.mode);
        self.scene = scene.clone();
        true
    }

    /// Whether `key` is resident (in a slot, or as a fill-value brick).
    pub fn is_resident(&self, key: &BrickKey) -> bool {
        self.residency.is_resident(key)
    }

    /// Cache slots free or not used by the last frame: how many bricks can be inserted now
    /// without evicting the current working set.
    pub(crate) fn insertable(&self) -> usize {
        self.residency.cache().available(self.frame)
    }

    /// Inserts a fetched brick: takes a slot (evicting the least recently used brick not used
    /// by the last frame), uploads it, and updates the page table and the octree. A brick of
    /// the wrong size or type is an error and changes nothing.
    ///
    /// # Errors
    /// As `ResidencyState::insert`: a brick not drawn, or one of the wrong size or type.
    pub fn insert(
        &mut self,
        gpu: &Gpu,
        key: BrickKey,
        voxels: &BrickVoxels,
    ) -> Result<Inserted, GpuError> {
        self.residency.insert(gpu, key, voxels, self.frame)
    }

    /// Whether the shader reads the bricks' aprons (the default; see
    /// `ResidencyState::use_aprons`).
    pub fn use_aprons(&mut self, gpu: &Gpu, used: bool) {
        self.residency.use_aprons(gpu, used);
    }

    /// Uploads changed page-table entries and octree nodes.
    pub fn flush(&mut self, gpu: &Gpu) {
        self.residency.flush(gpu);
    }

    fn params(&self) -> Params {
        let info = self.residency.info();
        let cache = self.residency.cache();
        let g = self.residency.octree().geometry();
        let cam = &self.scene.camera;
        let spacing = info.spacing_xyz();
        let leaf_world: [f64; 3] =
            std::array::from_fn(|a| (g.leaf_shift[a] as f64).exp2() * spacing[a]);
        let (forward, right, up) = cam.basis();
        let view_d = view_distance(cam.eye, forward, g.volume_voxels, spacing);
        let view_leaf: [f64; 3] =
            std::array::from_fn(|a| (cam.eye[a] + view_d * forward[a]) / leaf_world[a]);
        // The shader's fine units: a level-0 voxel where leaves are at least one, with at
        // most 2^30 of them per axis (positions are i32).
        let fine = g
            .leaf_shift
            .map(|s| s.clamp(0, (30 - g.depth as i32).max(0)));
        let tan_half = (cam.fov_y_degrees.to_radians() / 2.0).tan();
        let aspect = self.options.width as f64 / self.options.height as f64;
        let f3 = |v: [f64; 3]| v.map(|x| x as f32);
        let reference_step = spacing.iter().copied().fold(f64::INFINITY, f64::min);
        let bg = self.scene.background;
        // Slots per x and y are powers of two: the shader takes their log2.
        let slots = cache.slots_per_axis();
        let area = self.residency.segment_area();
        let mut flags = 0;
        if self.options.empty_space_skipping {
            flags |= FLAG_SKIPPING;
        }
        if self.options.substitution {
            flags |= FLAG_SUBSTITUTION;
        }
        Params {
            width: self.options.width,
            height: self.options.height,
            frame: self.frame,
            channel_count: self.residency.octree().channels().len() as u32,
            leaf_depth: g.depth,
            level_count: info.levels.len() as u32,
            request_cap: self.options.max_requests,
            start_depth: self.options.start_depth.min(g.depth),
            class_offset: self.residency.class_offset(),
            steps_per_pass: self.tables.steps_per_pass(),
            flags,
            segment_offset: area.map_or(0, |a| a.offset_words as u32),
            segment_capacity: area.map_or(0, |a| a.capacity as u32),
            view_cell: view_leaf.map(|e| e.floor().clamp(i32::MIN as f64, i32::MAX as f64) as i32),
            slots_z: slots[2],
            view_frac: f3(view_leaf.map(|e| e - e.floor())),
            reference_step: reference_step as f32,
            right: f3(right.map(|x| x * tan_half * aspect)),
            lod_bias: self.options.lod_bias,
            up: f3(up.map(|x| x * tan_half)),
            pixel_footprint: (2.0 * tan_half / f64::from(self.options.height)) as f32,
            forward: f3(forward),
            step_fraction: self.options.step_factor,
            world_to_leaf: f3(leaf_world.map(|w| 1.0 / w)),
            leaf_edge: leaf_world.iter().copied().fold(f64::INFINITY, f64::min) as f32,
            volume_leaf: f3(std::array::from_fn(|a| {
                g.volume_voxels[a] as f64 / (g.leaf_shift[a] as f64).exp2()
            })),
            view_distance: view_d as f32,
            background: f3(bg),
            slots_x_log2: slots[0].trailing_zeros(),
            unit_shift: std::array::from_fn(|a| g.leaf_shift[a] - fine[a]),
            slots_y_log2: slots[1].trailing_zeros(),
            fine,
            brick: g.brick.map(|b| b as u32),
            ..clip_params(&self.scene, leaf_world, g.volume_voxels, g.leaf_shift)
        }
    }

    /// The boxes of this frame's ray segment lists: SparseLeap's occupancy geometry, rebuilt
    /// when classes or residency changed; the rasterize method's cut of bricks, every frame.
    fn update_segment_boxes(&mut self, gpu: &Gpu) {
        let Some(stage) = &mut self.segments else {
            return;
        };
        let changed = self.residency.take_occupancy_changed();
        let boxes = match self.options.method {
            Method::SparseLeap if changed => {
                occupancy_geometry(self.residency.octree(), self.residency.classes()).boxes
            }
            Method::Rasterize => {
                let info = self.residency.info();
                let levels = info.levels.len() as u32;
                let bounds: Vec<(u32, u32)> = (0..self.residency.octree().channels().len())
                    .map(|i| channel_level_bounds(&self.options, levels, i))
                    .collect();
                let finest = bounds.iter().map(|b| b.0).min().unwrap_or(0);
                let coarsest = bounds.iter().map(|b| b.1).max().unwrap_or(levels - 1);
                let view = CutView {
                    camera: self.scene.camera.clone(),
                    aspect: f64::from(self.options.width) / f64::from(self.options.height),
                    height: f64::from(self.options.height),
                    lod_bias: f64::from(self.options.lod_bias),
                    spacing: info.spacing_xyz(),
                    levels: (finest as usize, coarsest as usize),
                };
                brick_cut(self.residency.octree(), self.residency.classes(), &view).boxes
            }
            _ => return,
        };
        stage.set_boxes(gpu, &self.buffers.params, self.residency.nodes(), &boxes);
    }

    /// Renders one frame and reads back its image, requests, usage feedback (folded into
    /// the cache's LRU order) and counters.
    ///
    /// # Errors
    /// A [`GpuError`]: a GPU error while rendering, a readback that failed, or rays still
    /// marching after the renderer's pass limit.
    #[cfg(not(target_arch = "wasm32"))]
    pub fn render(&mut self, gpu: &Gpu) -> Result<FrameOutput, GpuError> {
        pollster::block_on(self.render_async(gpu))
    }

    /// [`Renderer::render`], awaited: in the browser, buffer mapping completes on the event
    /// loop.
    ///
    /// # Errors
    /// As [`Renderer::render`].
    pub async fn render_async(&mut self, gpu: &Gpu) -> Result<FrameOutput, GpuError> {
        gpu.checked_async("rendering a frame", self.render_frame(gpu))
            .await
    }

    async fn render_frame(&mut self, gpu: &Gpu) -> Result<FrameOutput, GpuError> {
        self.run_frame(gpu, FrameTarget::Image { pixels: true })
            .await
    }

    /// [`Renderer::render`] without reading the image back: the frame's image stays in
    /// [`Renderer::image_buffer`] (for presenting on the GPU) and `FrameOutput::pixels` is
    /// empty; the requests, usage feedback and counters are read back as by `render`.
    ///
    /// # Errors
    /// As [`Renderer::render`].
    #[cfg(not(target_arch = "wasm32"))]
    pub fn render_without_pixels(&mut self, gpu: &Gpu) -> Result<FrameOutput, GpuError> {
        pollster::block_on(self.render_without_pixels_async(gpu))
    }

    /// [`Renderer::render_without_pixels`], awaited.
    ///
    /// # Errors
    /// As [`Renderer::render`].
    pub async fn render_without_pixels_async(
        &mut self,
        gpu: &Gpu,
    ) -> Result<FrameOutput, GpuError> {
        gpu.checked_async(
            "rendering a frame",
            self.run_frame(gpu, FrameTarget::Image { pixels: false }),
        )
        .await
    }

    /// The image of the last frame on the GPU: linear RGBA `vec4<f32>` per pixel, `width ×
    /// height` of the options, row-major from the top, composited over the background (what
    /// [`crate::gpu::present::Presenter::encode`] takes).
    pub fn image_buffer(&self) -> &wgpu::Buffer {
        &self.buffers.image
    }

    /// Images read back so far: one per frame rendered with its pixels, none for
    /// [`Renderer::render_without_pixels`] or a VDI.
    pub fn image_readbacks(&self) -> u64 {
        self.image_readbacks
    }

    /// Generates the volumetric depth image of the current view, with at most `supersegments`
    /// supersegments per pixel (`shaders/raycast/vdi.wgsl`): one frame of the VDI pass over
    /// the bricks resident now. Render the view until it has converged first (no requests),
    /// as `viewer vdi` does, so that the VDI holds the data the view needs.
    ///
    /// # Errors
    /// As [`Renderer::render`], and a [`GpuError`] naming the VDI when it is over the
    /// device's storage-buffer limit, `supersegments` is not in `1..=MAX_SUPERSEGMENTS` or the
    /// scene is not in the `dvr` mode.
    #[cfg(not(target_arch = "wasm32"))]
    pub fn generate_vdi(
        &mut self,
        gpu: &Gpu,
        supersegments: u32,
    ) -> Result<(VdiGeneration, FrameOutput), GpuError> {
        pollster::block_on(self.generate_vdi_async(gpu, supersegments))
    }

    /// [`Renderer::generate_vdi`], awaited.
    ///
    /// # Errors
    /// As [`Renderer::generate_vdi`].
    pub async fn generate_vdi_async(
        &mut self,
        gpu: &Gpu,
        supersegments: u32,
    ) -> Result<(VdiGeneration, FrameOutput), GpuError> {
        if self.scene.mode != RenderMode::Dvr {
            return Err(GpuError::VdiMode {
                mode: self.scene.mode.name(),
            });
        }
        let max = residency_schemas::vdi::MAX_SUPERSEGMENTS;
        if !(1..=max).contains(&supersegments) {
            return Err(GpuError::Supersegments { supersegments, max });
        }
        let pixels = u64::from(self.options.width) * u64::from(self.options.height);
        let (target, bind_group) = match self.vdi.take() {
            Some(kept) if kept.0.supersegments == supersegments && kept.0.pixels == pixels => kept,
            _ => {
                let target = VdiTarget::new(gpu, pixels, supersegments)?;
                let bind_group = self.bind_vdi(gpu, &target);
                (target, bind_group)
            }
        };
        let result = gpu
            .checked_async(
                "generating a volumetric depth image",
                self.run_frame(gpu, FrameTarget::Vdi(&target, &bind_group)),
            )
            .await;
        let header = self.vdi_header(supersegments);
        let compactor = self
            .vdi_compactor
            .get_or_insert_with(|| VdiCompactor::new(gpu));
        let generation = match result {
            Ok(out) => gpu
                .checked_async(
                    "reading a volumetric depth image back",
                    compactor.read(gpu, &target, header),
                )
                .await
                .map(|vdi| (vdi, out)),
            Err(e) => Err(e),
        };
        self.vdi = Some((target, bind_group));
        generation
    }

    /// The header of a VDI of the current view with at most `supersegments` per list.
    fn vdi_header(&self, supersegments: u32) -> residency_schemas::vdi::VdiHeader {
        let info = self.residency.info();
        let spacing = info.spacing_xyz();
        let voxels = self.residency.octree().geometry().volume_voxels;
        let extent = std::array::from_fn(|a| voxels[a] as f64 * spacing[a]);
        super::vdi::header(
            &self.scene,
            self.options.width,
            self.options.height,
            supersegments,
            extent,
            self.residency.octree().channels().len() as u32,
        )
    }

    /// The bind group of the VDI pass: this renderer's, with `target` as the image.
    fn bind_vdi(&self, gpu: &Gpu, target: &VdiTarget) -> wgpu::BindGroup {
        let atlas = self.residency.cache().views();
        self.pipeline.bind_group(
            &gpu.device,
            &Bindings {
                params: &self.buffers.params,
                nodes: self.residency.nodes(),
                scene: self.tables.uniforms(),
                tables: self.tables.buffer(),
                pages: self.residency.pages().buffer(),
                page_flags: self.residency.pages().flags(),
                requests: &self.buffers.requests,
                usage: self.residency.cache().usage_buffer(),
                image: &target.buffer,
                atlas: &atlas,
                rays: &self.buffers.rays,
            },
        )
    }

    async fn run_frame(
        &mut self,
        gpu: &Gpu,
        target: FrameTarget<'_>,
    ) -> Result<FrameOutput, GpuError> {
        self.flush(gpu);
        self.frame += 1;
        let mut params = self.params();
        if let FrameTarget::Vdi(vdi, _) = target {
            params.supersegments = vdi.supersegments;
        }
        gpu.queue
            .write_buffer(&self.buffers.params, 0, bytemuck::bytes_of(&params));
        let device = &gpu.device;
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("raycast frame"),
        });
        self.update_segment_boxes(gpu);
        if let Some(stage) = &self.segments {
            let timer = self.buffers.readback.timer.as_ref();
            stage.encode(&mut encoder, self.residency.nodes(), timer);
        }
        let buffers = &self.buffers;
        encoder.clear_buffer(&buffers.requests, 0, Some(COUNTER_BYTES));
        encoder.clear_buffer(&buffers.rays, 0, None);
        let image_bytes = self.options.width as u64 * self.options.height as u64 * 16;
        let rb = &buffers.readback;
        // The image is copied and mapped once, after the last round, and only for an image
        // frame that wants its pixels: a VDI pass reads its target back once, after its last
        // round, too.
        let mut maps: Vec<&wgpu::Buffer> = vec![&rb.requests, &rb.usage];
        if let Some(timer) = &rb.timer {
            maps.push(timer.staging());
        }
        // Passes until no ray is suspended: one round is a few passes plus the readback, whose
        // header says how many rays the last pass suspended.
        let mut passes = 0u32;
        let mut batch = 1u32;
        // A frame starts with the resident-only pass, and goes on with it while the rays it
        // suspends only ran out of steps; a pass that stopped rays for the full pass is
        // followed by one full pass.
        let mut resident_only = true;
        loop {
            for _ in 0..batch {
                for counter in [
                    std::mem::offset_of!(FrameCounters, rays_suspended),
                    std::mem::offset_of!(FrameCounters, rays_need_full),
                ] {
                    encoder.clear_buffer(&buffers.requests, counter as u64, Some(4));
                }
                // The frame starts at its first pass: the segment lists' where there are.
                let first = passes == 0 && self.segments.is_none();
                let timestamp_writes = rb.timer.as_ref().map(|t| t.writes(first));
                let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some("raycast"),
                    timestamp_writes,
                });
                match target {
                    FrameTarget::Image { .. } => {
                        pass.set_pipeline(if resident_only {
                            self.pipeline.resident_only()
                        } else {
                            self.pipeline.pipeline()
                        });
                        pass.set_bind_group(0, &self.bind_group, &[]);
                    }
                    FrameTarget::Vdi(_, bind_group) => {
                        pass.set_pipeline(self.pipeline.vdi(device));
                        pass.set_bind_group(0, bind_group, &[]);
                    }
                }
                pass.dispatch_workgroups(
                    self.options.width.div_ceil(8),
                    self.options.height.div_ceil(8),
                    1,
                );
                drop(pass);
                passes += 1;
            }
            encoder.copy_buffer_to_buffer(
                &buffers.requests,
                0,
                &rb.requests,
                0,
                rb.requests.size(),
            );
            encoder.copy_buffer_to_buffer(
                self.residency.cache().usage_buffer(),
                0,
                &rb.usage,
                0,
                u64::from(self.residency.cache().capacity()) * 4,
            );
            if let Some(timer) = &rb.timer {
                timer.resolve(&mut encoder);
            }
            gpu.queue.submit([encoder.finish()]);
            map_for_reading(device, &maps).await?;
            let (suspended, need_full) = {
                let header = rb.requests.get_mapped_range(..COUNTER_BYTES)?;
                let c = bytemuck::pod_read_unaligned::<FrameCounters>(&header);
                (c.rays_suspended, c.rays_need_full)
            };
            if suspended == 0 {
                break;
            }
            for b in &maps {
                b.unmap();
            }
            if passes >= MAX_PASSES {
                return Err(GpuError::RaysStillMarching {
                    suspended,
                    passes,
                    steps: self.tables.steps_per_pass(),
                });
            }
            // One full pass usually finishes what a resident-only pass left; rays that only
            // ran out of steps go on in batches that double (long rays).
            resident_only = need_full == 0;
            batch = if resident_only {
                (batch * 2).min(16)
            } else {
                1
            };
            encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("raycast resume"),
            });
        }

        let read_image = matches!(target, FrameTarget::Image { pixels: true });
        if read_image {
            let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("image readback"),
            });
            encoder.copy_buffer_to_buffer(&buffers.image, 0, &rb.image, 0, image_bytes);
            gpu.queue.submit([encoder.finish()]);
            map_for_reading(device, &[&rb.image]).await?;
            maps.push(&rb.image);
        }
        let words: Vec<u32> = bytemuck::cast_slice(&rb.requests.get_mapped_range(..)?).to_vec();
        let usage: Vec<u32> = bytemuck::cast_slice(&rb.usage.get_mapped_range(..)?).to_vec();
        let pixels: Vec<[f32; 4]> = match target {
            // Not read back: left on the GPU (`image_buffer`).
            FrameTarget::Image { pixels } => {
                if pixels {
                    bytemuck::cast_slice(&rb.image.get_mapped_range(0..image_bytes)?).to_vec()
                } else {
                    Vec::new()
                }
            }
            FrameTarget::Vdi(..) => Vec::new(),
        };
        let gpu_time_ms = rb.timer.as_ref().map(|t| t.read_ms(gpu)).transpose()?;
        for b in maps {
            b.unmap();
        }
        self.image_readbacks += u64::from(read_image);
        self.residency.cache_mut().note_usage(&usage);
        let bricks_used = usage.iter().filter(|&&u| u == self.frame).count() as u64;

        let (head, tail) = words.split_at(COUNTER_BYTES as usize / 4);
        let counters: FrameCounters = bytemuck::pod_read_unaligned(bytemuck::cast_slice(head));
        // (page-table id, ray distance bits) after the counters.
        let entries: &[[u32; 2]] = bytemuck::cast_slice(tail);
        let requested = counters.requests as usize;
        let n = requested.min(self.options.max_requests as usize);
        let mut requests = Vec::with_capacity(n);
        for &[id, distance] in &entries[..n] {
            let key = self
                .residency
                .pages()
                .key(id)
                .ok_or(GpuError::UnknownBrickId { id })?;
            requests.push(BrickRequest {
                key,
                distance: f32::from_bits(distance),
            });
        }
        Ok(FrameOutput {
            pixels,
            requests,
            counts: ShaderCounts {
                samples: u64::from(counters.samples),
                empty_nodes_skipped: u64::from(counters.empty_nodes_skipped),
                bricks_substituted: u64::from(counters.bricks_substituted),
                homogeneous_nodes: u64::from(counters.homogeneous_nodes),
                requests_over_cap: u64::from(counters.requests_over_cap),
                samples_without_data: u64::from(counters.samples_without_data),
                bricks_requested: requested as u64,
                bricks_used,
                segment_boxes: self
                    .segments
                    .as_ref()
                    .map_or(0, |s| u64::from(s.box_count())),
                rays_overflowed: u64::from(counters.rays_overflowed),
                passes: u64::from(passes),
            },
            gpu_time_ms,
        })
    }
}

/// Distance `D` (world) from the eye to the shader's view point `eye + D·forward`, from which
/// rays start: 0 (the eye itself) unless the volume lies more than 4 of its diagonals ahead,
/// then one diagonal short of the volume centre's depth. f32 ray arithmetic then stays
/// relative to a point near the volume, so a camera 10⁶ diagonals away keeps voxel precision.
fn view_distance(eye: [f64; 3], forward: [f64; 3], voxels: [u64; 3], spacing: [f64; 3]) -> f64 {
    let extent: [f64; 3] = std::array::from_fn(|a| voxels[a] as f64 * spacing[a]);
    let diagonal = crate::scene::box_diagonal(extent);
    let depth: f64 = (0..3)
        .map(|a| (0.5 * extent[a] - eye[a]) * forward[a])
        .sum();
    if depth > 4.0 * diagonal {
        depth - diagonal
    } else {
        0.0
    }
}
