//! The buffer kinds the GPU passes use, made one way: storage (writable from the CPU),
//! uniform, and readback (mapped after a copy), plus the device-limit check for a storage
//! binding.

use super::GpuError;
use super::device::Gpu;

/// Errors unless a buffer of `bytes` fits one storage binding and one buffer of `gpu`;
/// `what` and `hint` say which buffer and what to do.
///
/// # Errors
/// [`GpuError::BindingTooLarge`] naming the buffer, its size, the limit and the hint.
pub fn check_binding(gpu: &Gpu, what: &str, bytes: u64, hint: &str) -> Result<(), GpuError> {
    let max_binding = gpu.limits.max_storage_buffer_binding_size;
    if bytes <= max_binding && bytes <= gpu.limits.max_buffer_size {
        Ok(())
    } else {
        Err(GpuError::BindingTooLarge {
            what: what.to_string(),
            bytes,
            limit: max_binding,
            hint: hint.to_string(),
        })
    }
}

/// A storage buffer of at least 16 bytes that can be written from the CPU.
pub fn storage_buffer(
    gpu: &Gpu,
    label: &str,
    size: u64,
    extra: wgpu::BufferUsages,
) -> wgpu::Buffer {
    gpu.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: size.max(16),
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST | extra,
        mapped_at_creation: false,
    })
}

/// A uniform buffer of `size` bytes that can be written from the CPU.
pub fn uniform_buffer(gpu: &Gpu, label: &str, size: u64) -> wgpu::Buffer {
    gpu.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size,
        usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    })
}

/// A buffer of at least 16 bytes that a copy fills and the CPU maps for reading.
pub fn readback_buffer(gpu: &Gpu, label: &str, size: u64) -> wgpu::Buffer {
    gpu.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: size.max(16),
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    })
}
