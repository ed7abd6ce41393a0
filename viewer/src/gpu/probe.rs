//! The limit probe: what sampling alone costs on the device. `shaders/probe.wgsl` casts the
//! same rays as the renderer, with its step at level 0, transfer functions, opacity
//! correction and compositing, through one resident 3D texture holding level 0 of every drawn
//! channel: no traversal, no page tables, no residency, no substitution. `viewer bench`
//! reports the renderer's samples per second as a fraction of the probe's, with trilinear
//! filtering done by hand (8 texel loads, as the renderer does) and, where the device can
//! filter `R32Float` textures, by the texture unit.

use super::buffers::{map_for_reading, readback_buffer, storage_buffer, uniform_buffer};
use super::contract::{FILTER_HARDWARE, FILTER_MANUAL, ProbeParams, probe_binding, probe_source};
use super::device::Gpu;
use super::error::GpuError;
use super::pipeline::{
    buffer_entry, compute_layout, storage_layout, texture_3d_layout, uniform_layout, view_entry,
};
use super::tables::SceneTables;
use super::timer::PassTimer;
use crate::scene::{Camera, ChannelStyle, Scene};
use crate::source::{BrickKey, BrickSource, VolumeInfo};

/// How the probe filters; named as [`ProbeFilter::name`] says in results files.
#[derive(
    Clone,
    Copy,
    Debug,
    PartialEq,
    Eq,
    serde::Serialize,
    serde::Deserialize,
    schemars::JsonSchema,
    strum::Display,
    strum::IntoStaticStr,
)]
#[serde(rename_all = "lowercase")]
#[strum(serialize_all = "lowercase")]
pub enum ProbeFilter {
    /// 8 texel loads and trilinear weights in the shader (the renderer's way).
    Manual,
    /// One filtered sample by the texture unit.
    Hardware,
}

residency_schemas::strum_names!(ProbeFilter);

/// One probe frame, read back.
#[derive(Clone, Debug)]
pub struct ProbeFrame {
    /// Linear RGBA per pixel, row-major from the top; alpha is `1 − T`.
    pub pixels: Vec<[f32; 4]>,
    /// Samples taken (each of every drawn channel).
    pub samples: u64,
    /// GPU time of the pass in ms, when timestamp queries are supported.
    pub gpu_time_ms: Option<f64>,
}

struct ProbePipeline {
    filter: ProbeFilter,
    pipeline: wgpu::ComputePipeline,
    bind_group: wgpu::BindGroup,
}

/// The probe of one volume and scene: the level-0 texture, the scene tables and a pipeline per
/// filter the device supports.
pub struct LimitProbe {
    width: u32,
    height: u32,
    info: VolumeInfo,
    scene: Scene,
    step_fraction: f32,
    params: wgpu::Buffer,
    image: wgpu::Buffer,
    counter: wgpu::Buffer,
    image_readback: wgpu::Buffer,
    counter_readback: wgpu::Buffer,
    /// Bound by the pipelines; kept alive with them.
    _tables: SceneTables,
    timer: Option<PassTimer>,
    pipelines: Vec<ProbePipeline>,
}

/// Level 0 of `channels` as one `f32` volume, the channels stacked along z (`x` fastest).
fn level0_slabs(source: &dyn BrickSource, channels: &[usize]) -> Result<Vec<f32>, GpuError> {
    let info = source.info();
    let [sz, sy, sx] = info.levels[0].shape.map(|s| s as usize);
    let brick = info.brick_shape.map(|b| b as usize);
    let mut out = vec![0.0f32; sx * sy * sz * channels.len()];
    for (slab, &channel) in channels.iter().enumerate() {
        let [gz, gy, gx] = info.brick_grid(0);
        let keys: Vec<BrickKey> = (0..gz)
            .flat_map(|z| (0..gy).flat_map(move |y| (0..gx).map(move |x| [z, y, x])))
            .map(|brick| BrickKey {
                level: 0,
                channel: channel as u32,
                brick,
            })
            .collect();
        for (key, voxels) in keys.iter().zip(source.fetch(&keys)) {
            let voxels = voxels.map_err(|source| GpuError::ProbeLevel0 {
                volume: info.name.clone(),
                source: Box::new(source),
            })?;
            let (lo, hi) = info.brick_box(key, 0);
            let [oz, oy, ox] = lo.map(|v| v as usize);
            let [ez, ey, ex] = std::array::from_fn(|a| (hi[a] - lo[a]) as usize);
            for z in 0..ez {
                for y in 0..ey {
                    let row = ((slab * sz + oz + z) * sy + oy + y) * sx + ox;
                    for x in 0..ex {
                        let index = (z * brick[1] + y) * brick[2] + x;
                        out[row + x] = voxels.value(index) as f32;
                    }
                }
            }
        }
    }
    Ok(out)
}

impl LimitProbe {
    /// Loads level 0 of `scene`'s visible channels from `source` into one texture and builds
    /// the probe's pipelines for `width × height` pixels and the renderer's step
    /// `step_fraction`.
    ///
    /// # Errors
    /// [`GpuError::ProbeTexture`] where the volume does not fit one 3D texture of the device,
    /// [`GpuError::ProbeChannels`] for no visible channel or too many,
    /// [`GpuError::ProbeLevel0`] where a brick of level 0 cannot be read, or a GPU error.
    pub fn new(
        gpu: &Gpu,
        source: &dyn BrickSource,
        scene: &Scene,
        width: u32,
        height: u32,
        step_fraction: f32,
    ) -> Result<Self, GpuError> {
        gpu.checked("setting up the limit probe", || {
            Self::build(gpu, source, scene, width, height, step_fraction)
        })
    }

    fn build(
        gpu: &Gpu,
        source: &dyn BrickSource,
        scene: &Scene,
        width: u32,
        height: u32,
        step_fraction: f32,
    ) -> Result<Self, GpuError> {
        let info = source.info().clone();
        let device = &gpu.device;
        let visible: Vec<&ChannelStyle> = scene.channels.iter().filter(|c| c.visible).collect();
        if visible.is_empty() || visible.len() > super::contract::MAX_CHANNELS {
            return Err(GpuError::ProbeChannels {
                channels: visible.len(),
            });
        }
        let [sz, sy, sx] = info.levels[0].shape.map(|s| s as u32);
        let depth = sz * visible.len() as u32;
        let max = gpu.limits.max_texture_dimension_3d;
        if sx > max || sy > max || depth > max {
            return Err(GpuError::ProbeTexture {
                volume: info.name.clone(),
                size: [sx, sy, depth],
                channels: visible.len(),
                limit: max,
            });
        }
        let channels: Vec<usize> = visible.iter().map(|c| c.channel).collect();
        let voxels = level0_slabs(source, &channels)?;
        let size = wgpu::Extent3d {
            width: sx,
            height: sy,
            depth_or_array_layers: depth,
        };
        let texture = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("probe level 0"),
            size,
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D3,
            format: wgpu::TextureFormat::R32Float,
            usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
            view_formats: &[],
        });
        gpu.queue.write_texture(
            texture.as_image_copy(),
            bytemuck::cast_slice(&voxels),
            wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(sx * 4),
                rows_per_image: Some(sy),
            },
            size,
        );
        let view = texture.create_view(&wgpu::TextureViewDescriptor::default());

        let tables = SceneTables::level0(gpu, &info, &visible)?;
        let params = uniform_buffer(gpu, "probe params", size_of::<ProbeParams>() as u64);
        let pixels = u64::from(width) * u64::from(height);
        let image = storage_buffer(
            gpu,
            "probe image",
            pixels * 16,
            wgpu::BufferUsages::COPY_SRC,
        );
        // Samples per image row, summed in u64 on the CPU.
        let rows = u64::from(height) * 4;
        let counter = storage_buffer(gpu, "probe samples", rows, wgpu::BufferUsages::COPY_SRC);
        let image_readback = readback_buffer(gpu, "probe image readback", pixels * 16);
        let counter_readback = readback_buffer(gpu, "probe samples readback", rows);

        let filters: &[ProbeFilter] = if device
            .features()
            .contains(wgpu::Features::FLOAT32_FILTERABLE)
        {
            &[ProbeFilter::Manual, ProbeFilter::Hardware]
        } else {
            &[ProbeFilter::Manual]
        };
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("probe.wgsl"),
            source: wgpu::ShaderSource::Wgsl(probe_source().into()),
        });
        let pipelines = filters
            .iter()
            .map(|&filter| {
                let filtering = filter == ProbeFilter::Hardware;
                let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                    label: Some("probe"),
                    entries: &[
                        uniform_layout(probe_binding::PARAMS),
                        storage_layout(probe_binding::TABLES, true),
                        uniform_layout(probe_binding::SCENE),
                        texture_3d_layout(
                            probe_binding::LEVEL0,
                            wgpu::TextureSampleType::Float {
                                filterable: filtering,
                            },
                        ),
                        compute_layout(
                            probe_binding::SAMPLER,
                            wgpu::BindingType::Sampler(if filtering {
                                wgpu::SamplerBindingType::Filtering
                            } else {
                                wgpu::SamplerBindingType::NonFiltering
                            }),
                        ),
                        storage_layout(probe_binding::IMAGE, false),
                        storage_layout(probe_binding::ROW_SAMPLES, false),
                    ],
                });
                let filter_mode = if filtering {
                    wgpu::FilterMode::Linear
                } else {
                    wgpu::FilterMode::Nearest
                };
                let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
                    label: Some("probe"),
                    mag_filter: filter_mode,
                    min_filter: filter_mode,
                    ..Default::default()
                });
                let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some("probe"),
                    layout: &layout,
                    entries: &[
                        buffer_entry(probe_binding::PARAMS, &params),
                        buffer_entry(probe_binding::TABLES, tables.buffer()),
                        buffer_entry(probe_binding::SCENE, tables.uniforms()),
                        view_entry(probe_binding::LEVEL0, &view),
                        wgpu::BindGroupEntry {
                            binding: probe_binding::SAMPLER,
                            resource: wgpu::BindingResource::Sampler(&sampler),
                        },
                        buffer_entry(probe_binding::IMAGE, &image),
                        buffer_entry(probe_binding::ROW_SAMPLES, &counter),
                    ],
                });
                let pipeline_layout =
                    device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                        label: Some("probe"),
                        bind_group_layouts: &[Some(&layout)],
                        immediate_size: 0,
                    });
                let constant = if filtering {
                    FILTER_HARDWARE
                } else {
                    FILTER_MANUAL
                };
                let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                    label: Some("probe"),
                    layout: Some(&pipeline_layout),
                    module: &module,
                    entry_point: Some("main"),
                    compilation_options: wgpu::PipelineCompilationOptions {
                        constants: &[("FILTER", f64::from(constant))],
                        ..Default::default()
                    },
                    cache: None,
                });
                ProbePipeline {
                    filter,
                    pipeline,
                    bind_group,
                }
            })
            .collect();
        Ok(Self {
            width,
            height,
            info,
            scene: scene.clone(),
            step_fraction,
            params,
            image,
            counter,
            image_readback,
            counter_readback,
            _tables: tables,
            timer: PassTimer::new(gpu, "probe"),
            pipelines,
        })
    }

    /// The filters this device runs the probe with (manual always; hardware where `R32Float`
    /// is filterable).
    pub fn filters(&self) -> Vec<ProbeFilter> {
        self.pipelines.iter().map(|p| p.filter).collect()
    }

    fn params(&self, camera: &Camera) -> ProbeParams {
        let spacing = self.info.spacing_xyz();
        let shape = self.info.levels[0].shape;
        let (forward, right, up) = camera.basis();
        let tan_half = (camera.fov_y_degrees.to_radians() / 2.0).tan();
        let aspect = f64::from(self.width) / f64::from(self.height);
        let f3 = |v: [f64; 3]| v.map(|x| x as f32);
        let min_edge = self.info.voxel_edge(0);
        ProbeParams {
            width: self.width,
            height: self.height,
            channel_count: self.scene.channels.iter().filter(|c| c.visible).count() as u32,
            slab_depth: shape[0] as u32,
            eye: f3(camera.eye),
            reference_step: min_edge as f32,
            right: f3(right.map(|x| x * tan_half * aspect)),
            step: (f64::from(self.step_fraction) * min_edge) as f32,
            up: f3(up.map(|x| x * tan_half)),
            forward: f3(forward),
            world_to_voxel: f3(spacing.map(|s| 1.0 / s)),
            volume: [shape[2] as f32, shape[1] as f32, shape[0] as f32],
            background: f3(self.scene.background),
            ..ProbeParams::default()
        }
    }

    /// Renders one frame from `camera` with `filter` and reads back its image, sample count
    /// and GPU time.
    ///
    /// # Errors
    /// [`GpuError::NoProbe`] for a filter the device does not have, a GPU error, or a
    /// readback that failed.
    #[cfg(not(target_arch = "wasm32"))]
    pub fn render(
        &self,
        gpu: &Gpu,
        camera: &Camera,
        filter: ProbeFilter,
    ) -> Result<ProbeFrame, GpuError> {
        pollster::block_on(gpu.checked_async("a limit-probe frame", async {
            self.render_frame(gpu, camera, filter).await
        }))
    }

    async fn render_frame(
        &self,
        gpu: &Gpu,
        camera: &Camera,
        filter: ProbeFilter,
    ) -> Result<ProbeFrame, GpuError> {
        let p = self
            .pipelines
            .iter()
            .find(|p| p.filter == filter)
            .ok_or(GpuError::NoProbe {
                filter: filter.name(),
            })?;
        gpu.queue
            .write_buffer(&self.params, 0, bytemuck::bytes_of(&self.params(camera)));
        let mut encoder = gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("probe frame"),
            });
        encoder.clear_buffer(&self.counter, 0, None);
        {
            let timestamp_writes = self.timer.as_ref().map(|t| t.writes(true));
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("probe"),
                timestamp_writes,
            });
            pass.set_pipeline(&p.pipeline);
            pass.set_bind_group(0, &p.bind_group, &[]);
            pass.dispatch_workgroups(self.width.div_ceil(8), self.height.div_ceil(8), 1);
        }
        let image_bytes = u64::from(self.width) * u64::from(self.height) * 16;
        encoder.copy_buffer_to_buffer(&self.image, 0, &self.image_readback, 0, image_bytes);
        let rows = u64::from(self.height) * 4;
        encoder.copy_buffer_to_buffer(&self.counter, 0, &self.counter_readback, 0, rows);
        let mut maps = vec![&self.image_readback, &self.counter_readback];
        if let Some(timer) = &self.timer {
            timer.resolve(&mut encoder);
            maps.push(timer.staging());
        }
        gpu.queue.submit([encoder.finish()]);
        map_for_reading(&gpu.device, &maps).await?;
        let pixels: Vec<[f32; 4]> =
            bytemuck::cast_slice(&self.image_readback.get_mapped_range(0..image_bytes)?).to_vec();
        let samples: u64 =
            bytemuck::cast_slice::<u8, u32>(&self.counter_readback.get_mapped_range(..rows)?)
                .iter()
                .map(|&n| u64::from(n))
                .sum();
        let gpu_time_ms = self.timer.as_ref().map(|t| t.read_ms(gpu)).transpose()?;
        for b in maps {
            b.unmap();
        }
        Ok(ProbeFrame {
            pixels,
            samples,
            gpu_time_ms,
        })
    }
}
