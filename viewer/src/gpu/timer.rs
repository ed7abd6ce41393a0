//! GPU time of a frame's passes, from timestamp queries where the device has them: the start
//! is written by the first pass of a frame (the segment lists' render pass where there is one,
//! else the first compute pass), the end by every compute pass, so the time spans them all.

use super::device::Gpu;
use super::error::GpuError;

/// Two timestamps, their resolve buffer and the staging buffer they are read back through.
pub struct PassTimer {
    set: wgpu::QuerySet,
    resolve: wgpu::Buffer,
    staging: wgpu::Buffer,
}

impl PassTimer {
    /// A timer labelled `label`, or `None` when the device has no timestamp queries.
    pub fn new(gpu: &Gpu, label: &str) -> Option<Self> {
        if !gpu.timestamps {
            return None;
        }
        let device = &gpu.device;
        let buffer = |what: &str, usage| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(&format!("{label} {what}")),
                size: 16,
                usage,
                mapped_at_creation: false,
            })
        };
        Some(Self {
            set: device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some(label),
                ty: wgpu::QueryType::Timestamp,
                count: 2,
            }),
            resolve: buffer(
                "timestamps",
                wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
            ),
            staging: buffer(
                "timestamps readback",
                wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            ),
        })
    }

    /// The timestamp writes of a pass: the start only for the frame's `first` pass.
    pub fn writes(&self, first: bool) -> wgpu::ComputePassTimestampWrites<'_> {
        wgpu::ComputePassTimestampWrites {
            query_set: &self.set,
            beginning_of_pass_write_index: first.then_some(0),
            end_of_pass_write_index: Some(1),
        }
    }

    /// The timestamp writes of a render pass that starts a frame (the segment lists'): the
    /// start of the frame, so that its time spans the rasterisation too.
    pub fn frame_start(&self) -> wgpu::RenderPassTimestampWrites<'_> {
        wgpu::RenderPassTimestampWrites {
            query_set: &self.set,
            beginning_of_pass_write_index: Some(0),
            end_of_pass_write_index: None,
        }
    }

    /// Resolves the timestamps and copies them into the staging buffer.
    pub fn resolve(&self, encoder: &mut wgpu::CommandEncoder) {
        encoder.resolve_query_set(&self.set, 0..2, &self.resolve, 0);
        encoder.copy_buffer_to_buffer(&self.resolve, 0, &self.staging, 0, 16);
    }

    /// The staging buffer, to map with the frame's other readbacks.
    pub fn staging(&self) -> &wgpu::Buffer {
        &self.staging
    }

    /// Milliseconds between the two timestamps, from the mapped staging buffer.
    ///
    /// # Errors
    /// [`GpuError::MapRange`] when the staging buffer is not mapped.
    pub fn read_ms(&self, gpu: &Gpu) -> Result<f64, GpuError> {
        let t: Vec<u64> = bytemuck::cast_slice(&self.staging.get_mapped_range(..)?).to_vec();
        let period = f64::from(gpu.queue.get_timestamp_period());
        Ok(t[1].saturating_sub(t[0]) as f64 * period / 1e6)
    }
}
