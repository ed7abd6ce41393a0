//! The ray segment lists of the SparseLeap and rasterize methods on the GPU:
//! `shaders/segments.wgsl` compiled into a render pipeline, the box buffer, and the per-frame
//! pass that clears the lists and rasterises the boxes into them ([`SegmentStage::encode`])
//! before the ray caster runs. The lists lie in the renderer's node buffer
//! ([`super::residency::SegmentArea`]), which the ray caster reads.

use super::buffers::storage_buffer;
use super::contract::{SegmentBox, segment_binding, segments_source};
use super::device::Gpu;
use super::pipeline::{buffer_entry, storage_layout, uniform_layout};
use super::residency::SegmentArea;
use super::timer::PassTimer;

/// Vertices of one box (12 triangles).
const BOX_VERTICES: u32 = 36;

/// The format of the colour target the pass needs but never writes.
const TARGET_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::R8Unorm;

/// The render pipeline, box buffer, target and bind group of one renderer's segment lists.
pub struct SegmentStage {
    pipeline: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
    boxes: wgpu::Buffer,
    box_capacity: u64,
    box_count: u32,
    target: wgpu::TextureView,
    bind_group: wgpu::BindGroup,
    area: SegmentArea,
}

/// A layout entry visible to the vertex and fragment stages.
fn raster_entry(
    entry: wgpu::BindGroupLayoutEntry,
    stages: wgpu::ShaderStages,
) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        visibility: stages,
        ..entry
    }
}

impl SegmentStage {
    /// The stage for an image of `width × height` whose lists lie at `area` of `nodes`, drawn
    /// with the per-frame uniforms `params`.
    pub fn new(
        gpu: &Gpu,
        width: u32,
        height: u32,
        params: &wgpu::Buffer,
        nodes: &wgpu::Buffer,
        area: SegmentArea,
    ) -> Self {
        let device = &gpu.device;
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("segments.wgsl"),
            source: wgpu::ShaderSource::Wgsl(segments_source().into()),
        });
        let both = wgpu::ShaderStages::VERTEX | wgpu::ShaderStages::FRAGMENT;
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("segments"),
            entries: &[
                raster_entry(uniform_layout(segment_binding::PARAMS), both),
                raster_entry(storage_layout(segment_binding::BOXES, true), both),
                raster_entry(
                    storage_layout(segment_binding::AREA, false),
                    wgpu::ShaderStages::FRAGMENT,
                ),
            ],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("segments"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("segments"),
            layout: Some(&pipeline_layout),
            vertex: wgpu::VertexState {
                module: &module,
                entry_point: Some("box_vertex"),
                compilation_options: wgpu::PipelineCompilationOptions::default(),
                buffers: &[],
            },
            primitive: wgpu::PrimitiveState {
                topology: wgpu::PrimitiveTopology::TriangleList,
                front_face: wgpu::FrontFace::Ccw,
                cull_mode: Some(wgpu::Face::Front),
                ..Default::default()
            },
            depth_stencil: None,
            multisample: wgpu::MultisampleState::default(),
            fragment: Some(wgpu::FragmentState {
                module: &module,
                entry_point: Some("box_fragment"),
                compilation_options: wgpu::PipelineCompilationOptions::default(),
                targets: &[Some(wgpu::ColorTargetState {
                    format: TARGET_FORMAT,
                    blend: None,
                    write_mask: wgpu::ColorWrites::empty(),
                })],
            }),
            multiview_mask: None,
            cache: None,
        });
        let target = device
            .create_texture(&wgpu::TextureDescriptor {
                label: Some("segments target"),
                size: wgpu::Extent3d {
                    width,
                    height,
                    depth_or_array_layers: 1,
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format: TARGET_FORMAT,
                usage: wgpu::TextureUsages::RENDER_ATTACHMENT,
                view_formats: &[],
            })
            .create_view(&wgpu::TextureViewDescriptor::default());
        let box_capacity = 1024;
        let boxes = box_buffer(gpu, box_capacity);
        let bind_group = bind(device, &layout, params, &boxes, nodes, area);
        Self {
            pipeline,
            layout,
            boxes,
            box_capacity,
            box_count: 0,
            target,
            bind_group,
            area,
        }
    }

    /// Replaces the boxes drawn (growing the box buffer when needed).
    pub fn set_boxes(
        &mut self,
        gpu: &Gpu,
        params: &wgpu::Buffer,
        nodes: &wgpu::Buffer,
        boxes: &[SegmentBox],
    ) {
        let n = boxes.len() as u64;
        if n > self.box_capacity {
            self.box_capacity = n.next_power_of_two();
            self.boxes = box_buffer(gpu, self.box_capacity);
            self.bind_group = bind(
                &gpu.device,
                &self.layout,
                params,
                &self.boxes,
                nodes,
                self.area,
            );
        }
        if !boxes.is_empty() {
            gpu.queue
                .write_buffer(&self.boxes, 0, bytemuck::cast_slice(boxes));
        }
        self.box_count = boxes.len() as u32;
    }

    /// Boxes drawn per frame.
    pub fn box_count(&self) -> u32 {
        self.box_count
    }

    /// Clears the lists in `nodes` and rasterises the boxes into them; with `timer`, the pass
    /// writes the frame's start time.
    pub fn encode(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        nodes: &wgpu::Buffer,
        timer: Option<&PassTimer>,
    ) {
        encoder.clear_buffer(
            nodes,
            self.area.offset_words * 4,
            Some(self.area.header_bytes()),
        );
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("segments"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: &self.target,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT),
                    store: wgpu::StoreOp::Discard,
                },
            })],
            depth_stencil_attachment: None,
            timestamp_writes: timer.map(PassTimer::frame_start),
            occlusion_query_set: None,
            multiview_mask: None,
        });
        if self.box_count > 0 {
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &self.bind_group, &[]);
            pass.draw(0..BOX_VERTICES, 0..self.box_count);
        }
    }
}

fn box_buffer(gpu: &Gpu, boxes: u64) -> wgpu::Buffer {
    storage_buffer(
        gpu,
        "segment boxes",
        boxes * size_of::<SegmentBox>() as u64,
        wgpu::BufferUsages::empty(),
    )
}

fn bind(
    device: &wgpu::Device,
    layout: &wgpu::BindGroupLayout,
    params: &wgpu::Buffer,
    boxes: &wgpu::Buffer,
    nodes: &wgpu::Buffer,
    area: SegmentArea,
) -> wgpu::BindGroup {
    device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("segments"),
        layout,
        entries: &[
            buffer_entry(segment_binding::PARAMS, params),
            buffer_entry(segment_binding::BOXES, boxes),
            wgpu::BindGroupEntry {
                binding: segment_binding::AREA,
                resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                    buffer: nodes,
                    offset: area.offset_words * 4,
                    size: wgpu::BufferSize::new(area.end_bytes() - area.offset_words * 4),
                }),
            },
        ],
    })
}
