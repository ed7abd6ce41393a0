//! Volumetric depth images from the renderer (the VDI paper, Sec. 3): the buffer the VDI pass
//! of `shaders/raycast/vdi.wgsl` writes, what it holds per pixel, and the
//! [`VolumetricDepthImage`] read back from it with the header of its view.
//!
//! The pass marches the same rays over the same data as an image frame, so a VDI is generated
//! from a converged view; [`super::renderer::Renderer::generate_vdi`] runs it.

use residency_schemas::vdi::{
    ColourFormat, Compression, DepthFormat, RayBasis, VDI_VERSION, VdiHeader, VolumetricDepthImage,
};

use super::buffers::{
    check_binding, map_for_reading, readback_buffer, storage_buffer, uniform_buffer,
};
use super::contract::{
    VDI_STATE_SLOTS, VdiCompactParams, vdi_compact_binding, vdi_compact_source, vdi_slot_parts,
};
use super::device::Gpu;
use super::error::GpuError;
use super::pipeline::buffer_entry;
use crate::scene::Scene;

/// Bytes of one slot of the VDI target (a `vec4<f32>`).
const SLOT_BYTES: u64 = 16;

/// The buffer the VDI pass writes (bound as the image), for one image size and supersegment
/// count, and the buffers of the same size that its compaction reads it through ([`VdiCompactor`]),
/// made once with it and kept while the renderer keeps the target.
pub(crate) struct VdiTarget {
    /// Most supersegments per pixel.
    pub supersegments: u32,
    /// Pixels.
    pub pixels: u64,
    /// Per pixel `supersegments + VDI_STATE_SLOTS` slots.
    pub buffer: wgpu::Buffer,
    /// Each pixel's two state slots, gathered.
    state: wgpu::Buffer,
    /// Where `state` is read back.
    state_readback: wgpu::Buffer,
    /// Each pixel's first slot in the packed supersegments.
    starts: wgpu::Buffer,
}

impl VdiTarget {
    /// The target of `pixels` pixels of at most `supersegments` supersegments.
    ///
    /// # Errors
    /// A [`GpuError`] naming the target, or the pixels' state, when it is over the device's
    /// storage-buffer limit.
    pub fn new(gpu: &Gpu, pixels: u64, supersegments: u32) -> Result<Self, GpuError> {
        let bytes = pixels * u64::from(supersegments + VDI_STATE_SLOTS) * SLOT_BYTES;
        check_binding(
            gpu,
            "the volumetric depth image",
            bytes,
            "generate a smaller image or with fewer supersegments",
        )?;
        let state_bytes = pixels * 2 * SLOT_BYTES;
        check_binding(
            gpu,
            "the VDI's pixel state",
            state_bytes,
            "generate a smaller image",
        )?;
        Ok(Self {
            supersegments,
            pixels,
            buffer: storage_buffer(gpu, "vdi target", bytes, wgpu::BufferUsages::empty()),
            state: storage_buffer(gpu, "vdi state", state_bytes, wgpu::BufferUsages::COPY_SRC),
            state_readback: readback_buffer(gpu, "vdi state readback", state_bytes),
            starts: storage_buffer(gpu, "vdi starts", pixels * 4, wgpu::BufferUsages::empty()),
        })
    }
}

/// Threads per workgroup of `vdi_compact.wgsl`.
const COMPACT_WORKGROUP: u64 = 256;

/// The compaction of a VDI target on the GPU (`shaders/vdi_compact.wgsl`), so that only each
/// pixel's state and its used supersegments are read back: compiled once per renderer.
pub(crate) struct VdiCompactor {
    gather: wgpu::ComputePipeline,
    scatter: wgpu::ComputePipeline,
    params: wgpu::Buffer,
}

impl VdiCompactor {
    /// Compiles the two passes.
    pub fn new(gpu: &Gpu) -> Self {
        let module = gpu
            .device
            .create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("vdi_compact.wgsl"),
                source: wgpu::ShaderSource::Wgsl(vdi_compact_source().into()),
            });
        let entry = |name: &str| {
            gpu.device
                .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                    label: Some(name),
                    layout: None,
                    module: &module,
                    entry_point: Some(name),
                    compilation_options: wgpu::PipelineCompilationOptions::default(),
                    cache: None,
                })
        };
        Self {
            gather: entry("gather"),
            scatter: entry("scatter"),
            params: uniform_buffer(
                gpu,
                "vdi compact params",
                size_of::<VdiCompactParams>() as u64,
            ),
        }
    }

    /// Reads `target`, as the VDI pass left it, into the VDI of `header`: the pixels' state
    /// first, then only the supersegments in use.
    ///
    /// # Errors
    /// A [`GpuError`] naming a buffer over the device's limits, or a readback that failed.
    pub async fn read(
        &self,
        gpu: &Gpu,
        target: &VdiTarget,
        header: VdiHeader,
    ) -> Result<VdiGeneration, GpuError> {
        let pixels = target.pixels;
        let n = target.supersegments;
        let groups = pixels.div_ceil(COMPACT_WORKGROUP).max(1);
        let groups_x = groups.min(u64::from(gpu.limits.max_compute_workgroups_per_dimension));
        let grid = (groups_x as u32, groups.div_ceil(groups_x) as u32);
        let params = VdiCompactParams {
            pixels: pixels as u32,
            supersegments: n,
            stride: n + VDI_STATE_SLOTS,
            row: (groups_x * COMPACT_WORKGROUP) as u32,
        };
        gpu.queue
            .write_buffer(&self.params, 0, bytemuck::bytes_of(&params));
        let bind = |pipeline: &wgpu::ComputePipeline, entries: &[wgpu::BindGroupEntry<'_>]| {
            gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("vdi compact"),
                layout: &pipeline.get_bind_group_layout(0),
                entries,
            })
        };
        let gather = bind(
            &self.gather,
            &[
                buffer_entry(vdi_compact_binding::PARAMS, &self.params),
                buffer_entry(vdi_compact_binding::TARGET, &target.buffer),
                buffer_entry(vdi_compact_binding::STATE, &target.state),
            ],
        );
        let (state, readback) = (&target.state, &target.state_readback);
        let mut generation = VdiGeneration {
            image: VolumetricDepthImage::new(header),
            dvr: Vec::with_capacity(pixels as usize),
            gamma: Vec::with_capacity(pixels as usize),
            marches: 0,
        };
        let mut starts = Vec::with_capacity(pixels as usize);
        let mut used = 0u32;
        read_back(gpu, &self.gather, &gather, grid, state, readback, |slots| {
            for (p, pair) in slots.chunks_exact(2).enumerate() {
                let count = pair[1][0].to_bits().min(n);
                generation.dvr.push(pair[0]);
                generation.gamma.push(pair[1][1]);
                generation.marches += u64::from(pair[1][2].to_bits());
                generation.image.counts[p] = count as u8;
                starts.push(used);
                used += count;
            }
        })
        .await?;
        gpu.queue
            .write_buffer(&target.starts, 0, bytemuck::cast_slice(&starts));
        let packed_bytes = u64::from(used) * SLOT_BYTES;
        check_binding(
            gpu,
            "the VDI's supersegments",
            packed_bytes,
            "generate a smaller image",
        )?;
        let packed = storage_buffer(
            gpu,
            "vdi packed",
            packed_bytes,
            wgpu::BufferUsages::COPY_SRC,
        );
        let scatter = bind(
            &self.scatter,
            &[
                buffer_entry(vdi_compact_binding::PARAMS, &self.params),
                buffer_entry(vdi_compact_binding::TARGET, &target.buffer),
                buffer_entry(vdi_compact_binding::STARTS, &target.starts),
                buffer_entry(vdi_compact_binding::PACKED, &packed),
            ],
        );
        let readback = readback_buffer(gpu, "vdi packed readback", packed.size());
        let image = &mut generation.image;
        read_back(
            gpu,
            &self.scatter,
            &scatter,
            grid,
            &packed,
            &readback,
            |slots| {
                unpack_slots(&slots[..used as usize], &mut image.colour, &mut image.depth);
            },
        )
        .await?;
        Ok(generation)
    }
}

/// Runs `pipeline` over the grid, copies `output` into `readback` (of its size), maps it and
/// hands its slots to `read` where they lie (the mapped memory, no copy of it).
async fn read_back(
    gpu: &Gpu,
    pipeline: &wgpu::ComputePipeline,
    bind_group: &wgpu::BindGroup,
    grid: (u32, u32),
    output: &wgpu::Buffer,
    readback: &wgpu::Buffer,
    read: impl FnOnce(&[[f32; 4]]),
) -> Result<(), GpuError> {
    let mut encoder = gpu
        .device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("vdi compact"),
        });
    {
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("vdi compact"),
            timestamp_writes: None,
        });
        pass.set_pipeline(pipeline);
        pass.set_bind_group(0, bind_group, &[]);
        pass.dispatch_workgroups(grid.0, grid.1, 1);
    }
    encoder.copy_buffer_to_buffer(output, 0, readback, 0, output.size());
    gpu.queue.submit([encoder.finish()]);
    map_for_reading(&gpu.device, &[readback]).await?;
    read(bytemuck::cast_slice(&readback.get_mapped_range(..)?));
    readback.unmap();
    Ok(())
}

/// The packed slots ([`vdi_slot`](super::contract::vdi_slot)) as the VDI holds them: each
/// slot's colour (its half floats as they are) and its front and back depths. Native builds
/// unpack on rayon's threads.
fn unpack_slots(slots: &[[f32; 4]], colour: &mut Vec<[half::f16; 4]>, depth: &mut Vec<[f32; 2]>) {
    #[cfg(not(target_arch = "wasm32"))]
    {
        use rayon::prelude::*;
        slots
            .par_iter()
            .map(vdi_slot_parts)
            .unzip_into_vecs(colour, depth);
    }
    #[cfg(target_arch = "wasm32")]
    {
        (*colour, *depth) = slots.iter().map(vdi_slot_parts).unzip();
    }
}

/// What the VDI pass found for one image, beside the VDI itself.
#[derive(Clone, Debug, PartialEq)]
pub struct VdiGeneration {
    /// The volumetric depth image.
    pub image: VolumetricDepthImage,
    /// The DVR image the same rays composited (linear RGBA, row-major from the top): what
    /// the VDI gives back from its own viewpoint, up to the supersegments' half-float colour.
    pub dvr: Vec<[f32; 4]>,
    /// Per pixel, the `γ` its supersegments were cut with.
    pub gamma: Vec<f32>,
    /// Marches the rays took in all (one per ray when every ray fits at the first `γ`).
    pub marches: u64,
}

/// The header of a VDI of `scene` at `width × height` with at most `supersegments` per list,
/// over a volume whose world box is `[0, extent]`, mixing `channels` channels.
pub(crate) fn header(
    scene: &Scene,
    width: u32,
    height: u32,
    supersegments: u32,
    extent: [f64; 3],
    channels: u32,
) -> VdiHeader {
    let cam = &scene.camera;
    let (forward, right, up) = cam.basis();
    let tan_half = (cam.fov_y_degrees.to_radians() / 2.0).tan();
    let aspect = f64::from(width) / f64::from(height);
    let f3 = |v: [f64; 3]| v.map(|x| x as f32);
    // The depth range: the volume's corners along the view, in front of the eye.
    let depths = (0..8).map(|corner: usize| {
        (0..3)
            .map(|a| {
                let x = if corner >> a & 1 == 1 { extent[a] } else { 0.0 };
                (x - cam.eye[a]) * forward[a]
            })
            .sum::<f64>()
    });
    let (lo, hi) = depths.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), d| {
        (lo.min(d), hi.max(d))
    });
    let far = hi.max(1e-6);
    let near = lo.clamp(far * 1e-6, far * (1.0 - 1e-6));
    let eye = glam::DVec3::from(cam.eye);
    let view = glam::DMat4::look_to_rh(eye, glam::DVec3::from(forward), glam::DVec3::from(up));
    let projection = glam::DMat4::perspective_rh(cam.fov_y_degrees.to_radians(), aspect, near, far);
    VdiHeader {
        version: VDI_VERSION,
        width,
        height,
        supersegments,
        camera: cam.clone(),
        rays: RayBasis {
            forward: f3(forward),
            right: f3(right.map(|x| x * tan_half * aspect)),
            up: f3(up.map(|x| x * tan_half)),
        },
        view: view.as_mat4().to_cols_array(),
        projection: projection.as_mat4().to_cols_array(),
        near: near as f32,
        far: far as f32,
        volume_min: [0.0; 3],
        volume_max: extent,
        background: f3(scene.background),
        channels,
        colour: ColourFormat::F16,
        depth: DepthFormat::F32,
        compression: Compression::default(),
        scene_hash: scene_hash(scene),
        dataset: None,
    }
}

/// 16 hex digits naming `scene`: FNV-1a (64 bits) of its JSON.
pub fn scene_hash(scene: &Scene) -> String {
    let json = serde_json::to_vec(scene).expect("a scene always serializes");
    let hash = json.iter().fold(0xcbf2_9ce4_8422_2325_u64, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
    });
    format!("{hash:016x}")
}
