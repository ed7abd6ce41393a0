//! The long-lived part of the renderer: `raycast.wgsl` compiled into a compute pipeline for one
//! atlas format and one method, with its bind group layout. Building one compiles the shader
//! (seconds on lavapipe), so a device keeps each pipeline it has built ([`PipelineCache`]) and
//! every renderer of the same format and method, however its scene or volume changes, shares
//! it.

use std::sync::{Arc, Mutex};

use super::brick_cache::AtlasKind;
use super::contract::{binding, raycast_source};
use super::device::Gpu;
use super::renderer::Method;

/// The buffers and atlas views one renderer binds to the pipeline.
pub struct Bindings<'a> {
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

/// `raycast.wgsl` compiled for one atlas format and one method.
pub struct RaycastPipeline {
    kind: AtlasKind,
    method: Method,
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::ComputePipeline,
}

impl RaycastPipeline {
    /// Compiles the shader for atlas `kind` and `method` (pipeline constants, so that the
    /// driver compiles only the code this pipeline runs).
    pub fn new(device: &wgpu::Device, kind: AtlasKind, method: Method) -> Self {
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("raycast.wgsl"),
            source: wgpu::ShaderSource::Wgsl(raycast_source().into()),
        });
        let entry = |binding, ty| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty,
            count: None,
        };
        let storage = |binding, read_only| {
            entry(
                binding,
                wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Storage { read_only },
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
            )
        };
        let atlas = |binding, sample_type| {
            entry(
                binding,
                wgpu::BindingType::Texture {
                    sample_type,
                    view_dimension: wgpu::TextureViewDimension::D3,
                    multisampled: false,
                },
            )
        };
        let uniform = |binding| {
            entry(
                binding,
                wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Uniform,
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
            )
        };
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("raycast"),
            entries: &[
                uniform(binding::PARAMS),
                uniform(binding::SCENE),
                storage(binding::NODES, true),
                storage(binding::TABLES, true),
                storage(binding::PAGES, true),
                storage(binding::PAGE_FLAGS, false),
                storage(binding::REQUESTS, false),
                storage(binding::USAGE, false),
                storage(binding::IMAGE, false),
                atlas(binding::ATLAS_UINT, wgpu::TextureSampleType::Uint),
                atlas(binding::ATLAS_SINT, wgpu::TextureSampleType::Sint),
                atlas(
                    binding::ATLAS_FLOAT,
                    wgpu::TextureSampleType::Float { filterable: false },
                ),
                storage(binding::RAYS, false),
            ],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("raycast"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("raycast"),
            layout: Some(&pipeline_layout),
            module: &module,
            entry_point: Some("main"),
            compilation_options: wgpu::PipelineCompilationOptions {
                constants: &[
                    ("SAMPLE_KIND", f64::from(kind as u32)),
                    ("METHOD", f64::from(method as u32)),
                ],
                ..Default::default()
            },
            cache: None,
        });
        Self {
            kind,
            method,
            layout,
            pipeline,
        }
    }

    /// The pipeline of `kind` and `method` on `gpu`: the one built before, else a new one.
    pub fn shared(gpu: &Gpu, kind: AtlasKind, method: Method) -> Arc<Self> {
        gpu.pipelines.get_or_build(&gpu.device, kind, method)
    }

    /// The compute pipeline.
    pub fn pipeline(&self) -> &wgpu::ComputePipeline {
        &self.pipeline
    }

    /// The atlas format it reads.
    pub fn kind(&self) -> AtlasKind {
        self.kind
    }

    /// The method it runs.
    pub fn method(&self) -> Method {
        self.method
    }

    /// Binds one renderer's buffers and atlas.
    pub fn bind_group(&self, device: &wgpu::Device, b: &Bindings<'_>) -> wgpu::BindGroup {
        fn buffer(binding: u32, buffer: &wgpu::Buffer) -> wgpu::BindGroupEntry<'_> {
            wgpu::BindGroupEntry {
                binding,
                resource: buffer.as_entire_binding(),
            }
        }
        fn view(binding: u32, view: &wgpu::TextureView) -> wgpu::BindGroupEntry<'_> {
            wgpu::BindGroupEntry {
                binding,
                resource: wgpu::BindingResource::TextureView(view),
            }
        }
        device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("raycast"),
            layout: &self.layout,
            entries: &[
                buffer(binding::PARAMS, b.params),
                buffer(binding::NODES, b.nodes),
                buffer(binding::TABLES, b.tables),
                buffer(binding::PAGES, b.pages),
                buffer(binding::PAGE_FLAGS, b.page_flags),
                buffer(binding::REQUESTS, b.requests),
                buffer(binding::USAGE, b.usage),
                buffer(binding::IMAGE, b.image),
                view(binding::ATLAS_UINT, &b.atlas[0]),
                view(binding::ATLAS_SINT, &b.atlas[1]),
                view(binding::ATLAS_FLOAT, &b.atlas[2]),
                buffer(binding::SCENE, b.scene),
                buffer(binding::RAYS, b.rays),
            ],
        })
    }
}

/// The pipelines a device has built, one per (atlas format, method).
#[derive(Default)]
pub struct PipelineCache {
    built: Mutex<Vec<Arc<RaycastPipeline>>>,
}

impl PipelineCache {
    /// The pipeline of `kind` and `method`, built on first use.
    fn get_or_build(
        &self,
        device: &wgpu::Device,
        kind: AtlasKind,
        method: Method,
    ) -> Arc<RaycastPipeline> {
        let mut built = self
            .built
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if let Some(p) = built.iter().find(|p| p.kind == kind && p.method == method) {
            return Arc::clone(p);
        }
        let p = Arc::new(RaycastPipeline::new(device, kind, method));
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
