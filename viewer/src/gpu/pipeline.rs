//! The long-lived part of the renderer: `raycast.wgsl` compiled into a compute pipeline for one
//! atlas format and one method, with its bind group layout. Building one compiles the shader
//! (seconds on lavapipe), so a device keeps each pipeline it has built ([`PipelineCache`]) and
//! every renderer of the same format and method, however its scene or volume changes, shares
//! it.

use std::sync::{Arc, Mutex, OnceLock};

use super::brick_cache::AtlasKind;
use super::contract::{binding, raycast_source};
use super::method::Method;
use crate::scene::{Filter, RenderMode};

/// A compute-stage layout entry of binding `binding`.
pub(super) fn compute_layout(binding: u32, ty: wgpu::BindingType) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty,
        count: None,
    }
}

fn buffer_layout(binding: u32, ty: wgpu::BufferBindingType) -> wgpu::BindGroupLayoutEntry {
    compute_layout(
        binding,
        wgpu::BindingType::Buffer {
            ty,
            has_dynamic_offset: false,
            min_binding_size: None,
        },
    )
}

/// A uniform buffer's layout entry.
pub(super) fn uniform_layout(binding: u32) -> wgpu::BindGroupLayoutEntry {
    buffer_layout(binding, wgpu::BufferBindingType::Uniform)
}

/// A storage buffer's layout entry.
pub(super) fn storage_layout(binding: u32, read_only: bool) -> wgpu::BindGroupLayoutEntry {
    buffer_layout(binding, wgpu::BufferBindingType::Storage { read_only })
}

/// A 3D texture's layout entry.
pub(super) fn texture_3d_layout(
    binding: u32,
    sample_type: wgpu::TextureSampleType,
) -> wgpu::BindGroupLayoutEntry {
    compute_layout(
        binding,
        wgpu::BindingType::Texture {
            sample_type,
            view_dimension: wgpu::TextureViewDimension::D3,
            multisampled: false,
        },
    )
}

/// A whole buffer bound at `binding`.
pub(super) fn buffer_entry(binding: u32, buffer: &wgpu::Buffer) -> wgpu::BindGroupEntry<'_> {
    wgpu::BindGroupEntry {
        binding,
        resource: buffer.as_entire_binding(),
    }
}

/// A texture view bound at `binding`.
pub(super) fn view_entry(binding: u32, view: &wgpu::TextureView) -> wgpu::BindGroupEntry<'_> {
    wgpu::BindGroupEntry {
        binding,
        resource: wgpu::BindingResource::TextureView(view),
    }
}

/// The buffers and atlas views one renderer binds to the pipeline.
pub(crate) struct Bindings<'a> {
    /// The per-frame uniforms.
    pub params: &'a wgpu::Buffer,
    /// The residency octree's nodes, then the baselines' per-brick ranges.
    pub nodes: &'a wgpu::Buffer,
    /// The scene uniforms (levels, channels).
    pub scene: &'a wgpu::Buffer,
    /// The table buffer (page-table offsets, transfer functions).
    pub tables: &'a wgpu::Buffer,
    /// The page tables.
    pub pages: &'a wgpu::Buffer,
    /// The page tables' per-brick request flags.
    pub page_flags: &'a wgpu::Buffer,
    /// The capped request list and the frame's counters.
    pub requests: &'a wgpu::Buffer,
    /// The cache's per-slot usage feedback.
    pub usage: &'a wgpu::Buffer,
    /// The image, linear RGBA `f32` per pixel.
    pub image: &'a wgpu::Buffer,
    /// The atlas views: unsigned, signed and float (the unused two are 1-texel dummies).
    pub atlas: &'a [wgpu::TextureView; 3],
    /// The suspended rays' states, between passes.
    pub rays: &'a wgpu::Buffer,
}

/// What a ray-casting pipeline is compiled for (its pipeline constants, so that the driver
/// compiles only the code it runs): one per combination a device has drawn.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PipelineKey {
    /// The atlas's sample format.
    pub kind: AtlasKind,
    /// The traversal method.
    pub method: Method,
    /// The reconstruction filter.
    pub filter: Filter,
    /// What a ray makes of its samples.
    pub mode: RenderMode,
}

/// `raycast.wgsl` compiled for one [`PipelineKey`], as the full pass and as the resident-only
/// pass, and on first use as the pass that writes volumetric depth images.
pub struct RaycastPipeline {
    key: PipelineKey,
    layout: wgpu::BindGroupLayout,
    module: wgpu::ShaderModule,
    pipeline_layout: wgpu::PipelineLayout,
    pipeline: wgpu::ComputePipeline,
    resident_only: wgpu::ComputePipeline,
    vdi: OnceLock<wgpu::ComputePipeline>,
}

/// Which pass of `raycast.wgsl` a pipeline runs (its pipeline constants beyond format,
/// method and filter).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Pass {
    /// The full pass.
    Full,
    /// The resident-only pass.
    ResidentOnly,
    /// The full pass writing volumetric depth images (`shaders/raycast/vdi.wgsl`).
    Vdi,
}

impl Pass {
    fn label(self) -> &'static str {
        match self {
            Self::Full => "raycast",
            Self::ResidentOnly => "raycast resident-only",
            Self::Vdi => "raycast vdi",
        }
    }
}

impl RaycastPipeline {
    /// Compiles the shader for `key` (pipeline constants, so that the driver compiles only the
    /// code this pipeline runs).
    pub fn new(device: &wgpu::Device, key: PipelineKey) -> Self {
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("raycast.wgsl"),
            source: wgpu::ShaderSource::Wgsl(raycast_source().into()),
        });
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("raycast"),
            entries: &[
                uniform_layout(binding::PARAMS),
                uniform_layout(binding::SCENE),
                storage_layout(binding::NODES, true),
                storage_layout(binding::TABLES, true),
                storage_layout(binding::PAGES, true),
                storage_layout(binding::PAGE_FLAGS, false),
                storage_layout(binding::REQUESTS, false),
                storage_layout(binding::USAGE, false),
                storage_layout(binding::IMAGE, false),
                texture_3d_layout(binding::ATLAS_UINT, wgpu::TextureSampleType::Uint),
                texture_3d_layout(binding::ATLAS_SINT, wgpu::TextureSampleType::Sint),
                texture_3d_layout(
                    binding::ATLAS_FLOAT,
                    wgpu::TextureSampleType::Float { filterable: false },
                ),
                storage_layout(binding::RAYS, false),
            ],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("raycast"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        Self {
            key,
            layout,
            pipeline: compile(device, &module, &pipeline_layout, key, Pass::Full),
            resident_only: compile(device, &module, &pipeline_layout, key, Pass::ResidentOnly),
            module,
            pipeline_layout,
            vdi: OnceLock::new(),
        }
    }

    /// The pass that writes volumetric depth images (`VDI` in `raycast.wgsl`), compiled the
    /// first time it is asked for.
    pub(crate) fn vdi(&self, device: &wgpu::Device) -> &wgpu::ComputePipeline {
        self.vdi.get_or_init(|| {
            compile(
                device,
                &self.module,
                &self.pipeline_layout,
                self.key,
                Pass::Vdi,
            )
        })
    }

    /// The full pass's compute pipeline.
    pub fn pipeline(&self) -> &wgpu::ComputePipeline {
        &self.pipeline
    }

    /// The resident-only pass's compute pipeline (`RESIDENT_ONLY` in `raycast.wgsl`): a frame's
    /// first pass, which samples only bricks one cache slot serves whole and leaves every
    /// ray that needs a request, a substitute or a brick's neighbours suspended for the full
    /// pass.
    pub(crate) fn resident_only(&self) -> &wgpu::ComputePipeline {
        &self.resident_only
    }

    /// Binds one renderer's buffers and atlas.
    pub(crate) fn bind_group(&self, device: &wgpu::Device, b: &Bindings<'_>) -> wgpu::BindGroup {
        device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("raycast"),
            layout: &self.layout,
            entries: &[
                buffer_entry(binding::PARAMS, b.params),
                buffer_entry(binding::NODES, b.nodes),
                buffer_entry(binding::TABLES, b.tables),
                buffer_entry(binding::PAGES, b.pages),
                buffer_entry(binding::PAGE_FLAGS, b.page_flags),
                buffer_entry(binding::REQUESTS, b.requests),
                buffer_entry(binding::USAGE, b.usage),
                buffer_entry(binding::IMAGE, b.image),
                view_entry(binding::ATLAS_UINT, &b.atlas[0]),
                view_entry(binding::ATLAS_SINT, &b.atlas[1]),
                view_entry(binding::ATLAS_FLOAT, &b.atlas[2]),
                buffer_entry(binding::SCENE, b.scene),
                buffer_entry(binding::RAYS, b.rays),
            ],
        })
    }
}

/// `raycast.wgsl`'s entry point compiled with the pipeline constants of `pass`.
fn compile(
    device: &wgpu::Device,
    module: &wgpu::ShaderModule,
    layout: &wgpu::PipelineLayout,
    key: PipelineKey,
    pass: Pass,
) -> wgpu::ComputePipeline {
    device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(pass.label()),
        layout: Some(layout),
        module,
        entry_point: Some("main"),
        compilation_options: wgpu::PipelineCompilationOptions {
            constants: &[
                ("SAMPLE_KIND", f64::from(key.kind as u32)),
                ("METHOD", f64::from(key.method as u32)),
                ("FILTER", f64::from(key.filter as u32)),
                ("MODE", f64::from(key.mode as u32)),
                (
                    "RESIDENT_ONLY",
                    f64::from(u8::from(pass == Pass::ResidentOnly)),
                ),
                ("VDI", f64::from(u8::from(pass == Pass::Vdi))),
            ],
            ..Default::default()
        },
        cache: None,
    })
}

/// The pipelines a device has built, one per [`PipelineKey`].
#[derive(Default)]
pub struct PipelineCache {
    built: Mutex<Vec<Arc<RaycastPipeline>>>,
}

impl PipelineCache {
    /// The pipeline of `key` on `device`: the one built before, else a new one.
    pub(crate) fn get_or_build(
        &self,
        device: &wgpu::Device,
        key: PipelineKey,
    ) -> Arc<RaycastPipeline> {
        let mut built = self
            .built
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if let Some(p) = built.iter().find(|p| p.key == key) {
            return Arc::clone(p);
        }
        let p = Arc::new(RaycastPipeline::new(device, key));
        built.push(Arc::clone(&p));
        p
    }

    /// How many pipelines have been built.
    pub fn len(&self) -> usize {
        self.built
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .len()
    }

    /// Whether none has been built yet.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

impl std::fmt::Debug for PipelineCache {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PipelineCache")
            .field("built", &self.len())
            .finish()
    }
}
