//! GPU device creation. Works on any Vulkan/Metal/DX12/GL adapter wgpu finds, including Mesa's
//! lavapipe software rasteriser (set `XDG_RUNTIME_DIR` when there is no session).

use anyhow::{Context, Result, bail};

/// A device, its queue and what the adapter supports.
pub struct Gpu {
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
}

impl std::fmt::Debug for Gpu {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Gpu")
            .field("adapter", &self.adapter_info.name)
            .field("backend", &self.adapter_info.backend)
            .field("timestamps", &self.timestamps)
            .finish_non_exhaustive()
    }
}

impl Gpu {
    /// Opens the best adapter the environment offers (`WGPU_BACKEND`, `WGPU_ADAPTER_NAME` and
    /// the other `wgpu` environment variables apply) with the adapter's full limits and, when
    /// supported, `TIMESTAMP_QUERY`.
    pub fn new() -> Result<Self> {
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            force_fallback_adapter: false,
            compatible_surface: None,
            ..Default::default()
        }))
        .context(
            "no GPU adapter found (without a GPU, install Mesa's lavapipe Vulkan driver and set \
             XDG_RUNTIME_DIR)",
        )?;
        let adapter_info = adapter.get_info();
        let timestamps = adapter.features().contains(wgpu::Features::TIMESTAMP_QUERY);
        let required_features = if timestamps {
            wgpu::Features::TIMESTAMP_QUERY
        } else {
            wgpu::Features::empty()
        };
        let limits = adapter.limits();
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("residency-viewer"),
            required_features,
            required_limits: limits.clone(),
            experimental_features: wgpu::ExperimentalFeatures::disabled(),
            memory_hints: wgpu::MemoryHints::Performance,
            trace: wgpu::Trace::Off,
        }))
        .with_context(|| format!("cannot open a device on {}", adapter_info.name))?;
        tracing::debug!(
            "GPU: {} ({:?}), timestamps: {timestamps}",
            adapter_info.name,
            adapter_info.backend
        );
        Ok(Self {
            device,
            queue,
            adapter_info,
            limits,
            timestamps,
        })
    }

    /// Runs `f`, turning any GPU validation or out-of-memory error it raises into an error
    /// naming `what` (instead of wgpu's default panic).
    pub fn checked<T>(&self, what: &str, f: impl FnOnce() -> Result<T>) -> Result<T> {
        let oom = self.device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let validation = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let result = f();
        let v = pollster::block_on(validation.pop());
        let o = pollster::block_on(oom.pop());
        if let Some(e) = v.or(o) {
            bail!("{what}: GPU error: {e}");
        }
        result
    }
}
