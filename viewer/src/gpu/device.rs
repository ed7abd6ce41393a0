//! GPU device creation. Works on any Vulkan/Metal/DX12/GL adapter wgpu finds, including Mesa's
//! lavapipe software rasteriser (set `XDG_RUNTIME_DIR` when there is no session).

use super::error::GpuError;
use super::pipeline::PipelineCache;

/// A device, its queue and what the adapter supports, with the instance and adapter they
/// came from (a window's surface is made on the same instance and checked against the same
/// adapter).
pub struct Gpu {
    /// The instance the adapter was found on.
    pub instance: wgpu::Instance,
    /// The adapter the device was opened on.
    pub adapter: wgpu::Adapter,
    /// The logical device.
    pub device: wgpu::Device,
    /// Its queue.
    pub queue: wgpu::Queue,
    /// The adapter's description (name, backend, driver).
    pub adapter_info: wgpu::AdapterInfo,
    /// The limits the device was created with (the adapter's own).
    pub limits: wgpu::Limits,
    /// Whether compute-pass timestamp queries are available (GPU time in frame statistics).
    pub timestamps: bool,
    /// The ray-casting pipelines built on this device, shared by every renderer.
    pub pipelines: PipelineCache,
}

impl std::fmt::Debug for Gpu {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Gpu")
            .field("adapter", &self.adapter_info.name)
            .field("backend", &self.adapter_info.backend)
            .field("timestamps", &self.timestamps)
            .field("pipelines", &self.pipelines)
            .finish_non_exhaustive()
    }
}

impl Gpu {
    /// Opens the best adapter the environment offers (`WGPU_BACKEND`, `WGPU_ADAPTER_NAME` and
    /// the other `wgpu` environment variables apply) with the adapter's full limits and, when
    /// supported, `TIMESTAMP_QUERY` and `FLOAT32_FILTERABLE`.
    ///
    /// # Errors
    /// [`GpuError::NoAdapter`] (saying what to install) or [`GpuError::NoDevice`].
    #[cfg(not(target_arch = "wasm32"))]
    pub fn new() -> Result<Self, GpuError> {
        pollster::block_on(Self::open())
    }

    /// [`Gpu::new`], awaited: the only way in the browser (WebGPU there).
    ///
    /// # Errors
    /// As [`Gpu::new`].
    pub async fn open() -> Result<Self, GpuError> {
        #[cfg(not(target_arch = "wasm32"))]
        let descriptor = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
        #[cfg(target_arch = "wasm32")]
        let descriptor = wgpu::InstanceDescriptor::new_without_display_handle();
        let instance = wgpu::Instance::new(descriptor);
        let adapter = instance
            .request_adapter(&wgpu::RequestAdapterOptions {
                power_preference: wgpu::PowerPreference::HighPerformance,
                force_fallback_adapter: false,
                compatible_surface: None,
                ..Default::default()
            })
            .await
            .map_err(GpuError::NoAdapter)?;
        let adapter_info = adapter.get_info();
        let timestamps = adapter.features().contains(wgpu::Features::TIMESTAMP_QUERY);
        // Timestamps for frame statistics; filterable f32 textures for the limit probe's
        // hardware-filtered path. Each only where the adapter has it.
        let required_features = adapter.features()
            & (wgpu::Features::TIMESTAMP_QUERY | wgpu::Features::FLOAT32_FILTERABLE);
        let limits = adapter.limits();
        let (device, queue) = adapter
            .request_device(&wgpu::DeviceDescriptor {
                label: Some("residency-viewer"),
                required_features,
                required_limits: limits.clone(),
                experimental_features: wgpu::ExperimentalFeatures::disabled(),
                memory_hints: wgpu::MemoryHints::Performance,
                trace: wgpu::Trace::Off,
            })
            .await
            .map_err(|source| GpuError::NoDevice {
                adapter: adapter_info.name.clone(),
                source,
            })?;
        tracing::debug!(
            "GPU: {} ({:?}), timestamps: {timestamps}",
            adapter_info.name,
            adapter_info.backend
        );
        Ok(Self {
            instance,
            adapter,
            device,
            queue,
            adapter_info,
            limits,
            timestamps,
            pipelines: PipelineCache::default(),
        })
    }

    /// Runs `f`, turning any GPU validation or out-of-memory error it raises into an error
    /// naming `what` (instead of wgpu's default panic).
    ///
    /// # Errors
    /// [`GpuError::Validation`] naming `what` when the GPU raised an error, else `f`'s error.
    #[cfg(not(target_arch = "wasm32"))]
    pub fn checked<T>(
        &self,
        what: &str,
        f: impl FnOnce() -> Result<T, GpuError>,
    ) -> Result<T, GpuError> {
        pollster::block_on(self.checked_async(what, async { f() }))
    }

    /// [`Gpu::checked`] for work that awaits (the browser's buffer mapping).
    ///
    /// # Errors
    /// As [`Gpu::checked`].
    pub async fn checked_async<T>(
        &self,
        what: &str,
        work: impl Future<Output = Result<T, GpuError>>,
    ) -> Result<T, GpuError> {
        let oom = self.device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let validation = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let result = work.await;
        let v = validation.pop().await;
        let o = oom.pop().await;
        if let Some(e) = v.or(o) {
            return Err(GpuError::Validation {
                what: what.to_string(),
                message: e.to_string(),
            });
        }
        result
    }
}
