//! The buffer kinds the GPU passes use, made one way: storage (writable from the CPU),
//! uniform, and readback (mapped after a copy), plus the device-limit check for a storage
//! binding, and the mapping of readback buffers for reading.

use super::device::Gpu;
use super::error::GpuError;

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

/// Maps `buffers` for reading and waits until they are: natively by polling the device, in
/// the browser by yielding to the event loop until WebGPU calls back.
pub(crate) async fn map_for_reading(
    device: &wgpu::Device,
    buffers: &[&wgpu::Buffer],
) -> Result<(), GpuError> {
    let mut mapped = Vec::with_capacity(buffers.len());
    for b in buffers {
        let (tx, rx) = futures_channel::oneshot::channel();
        b.map_async(wgpu::MapMode::Read, .., move |r| {
            let _ = tx.send(r);
        });
        mapped.push(rx);
    }
    #[cfg(not(target_arch = "wasm32"))]
    device
        .poll(wgpu::PollType::wait_indefinitely())
        .map_err(GpuError::Poll)?;
    #[cfg(target_arch = "wasm32")]
    let _ = device;
    for (i, rx) in mapped.into_iter().enumerate() {
        match rx.await {
            Ok(Ok(())) => {}
            Ok(Err(source)) => return Err(GpuError::Readback { buffer: i, source }),
            Err(_) => return Err(GpuError::DeviceLost { buffer: i }),
        }
    }
    Ok(())
}
