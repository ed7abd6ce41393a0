//! The scene tables `raycast.wgsl` consults, in two buffers:
//!
//! - the scene uniforms ([`SceneUniforms`]): per level, its downsampling shift, shape, bricks
//!   per axis and smallest voxel edge; per drawn channel, its colour, level bounds, and where
//!   its control points lie in the table buffer;
//! - the read-only `u32` table buffer (floats stored as bits): page-table offsets,
//!   `channel · levels + level`, then each channel's control points `(value, opacity)`.
//!
//! Whether a node or brick is transparent under a transfer function is not asked of the
//! shader: the CPU writes each node's (or brick's) class with the style
//! ([`super::residency::node_class`]), one word read where the shader used to test every
//! channel's range against a prefix table of the transfer function's bins.

use super::buffers::{check_binding, storage_buffer, uniform_buffer};
use super::contract::{
    ChannelEntry, LevelEntry, MAX_CHANNELS, MAX_LEVELS, SceneUniforms, gpu_iso_value,
};
use super::device::Gpu;
use super::error::GpuError;
use super::options::RenderOptions;
use super::residency::ResidencyState;
use crate::octree::OctreeGeometry;
use crate::scene::ChannelStyle;

/// Opacity control points per channel the table buffer has room for beyond the scene's own,
/// so that [`SceneTables::rewrite`] writes a new style in place.
const HEADROOM_POINTS: usize = 64;

/// Loop iterations a CPU Vulkan driver (Mesa's lavapipe/llvmpipe) allows one invocation in
/// all, nested loops included; the shader ends a pass well before it.
const DRIVER_LOOP_LIMIT: u32 = 65_535;

/// One rendered channel: its style and level bounds.
#[derive(Clone, Debug)]
pub struct ChannelTable<'a> {
    /// Colour and opacity transfer function.
    pub style: &'a ChannelStyle,
    /// Finest level the LOD choice may pick.
    pub min_level: u32,
    /// Coarsest level the LOD choice may pick.
    pub max_level: u32,
}

/// The built tables: the scene uniforms and the table buffer's words.
#[derive(Clone, Debug, PartialEq)]
pub struct Tables {
    /// Per level and per channel.
    pub uniforms: SceneUniforms,
    /// Page-table offsets, then control points.
    pub words: Vec<u32>,
}

/// Builds the tables for `geometry` (with voxel spacing `spacing`, `x, y, z`), page-table
/// `offsets` and `channels` (at most [`MAX_CHANNELS`]; the levels at most [`MAX_LEVELS`]).
pub fn build(
    geometry: &OctreeGeometry,
    spacing: [f64; 3],
    page_offsets: &[u32],
    channels: &[ChannelTable<'_>],
) -> Tables {
    assert!(
        geometry.level_shift.len() <= MAX_LEVELS && channels.len() <= MAX_CHANNELS,
        "checked by SceneTables::new"
    );
    let mut uniforms = SceneUniforms::default();
    for (l, shift) in geometry.level_shift.iter().enumerate() {
        let shape = geometry.level_shape[l];
        uniforms.levels[l] = LevelEntry {
            shift: shift.map(|s| s as i32),
            voxel_edge: (0..3)
                .map(|a| (1u64 << shift[a]) as f64 * spacing[a])
                .fold(f64::INFINITY, f64::min) as f32,
            shape: shape.map(|s| s as i32),
            bricks: std::array::from_fn(|a| shape[a].div_ceil(geometry.brick[a]) as u32),
            ..LevelEntry::default()
        };
    }
    let mut words = page_offsets.to_vec();
    for (i, ch) in channels.iter().enumerate() {
        let s = ch.style;
        let points_offset = words.len() as u32;
        for p in &s.opacity {
            words.push((p.value as f32).to_bits());
            words.push((p.opacity as f32).to_bits());
        }
        uniforms.channels[i] = ChannelEntry {
            color: s.color.map(|c| c as f32),
            point_count: s.opacity.len() as u32,
            min_level: ch.min_level,
            max_level: ch.max_level,
            points_offset,
            opacity_top: s.opacity_top() as f32,
            saturation: (s.saturation_value() as f32).clamp(-f32::MAX, f32::MAX),
            iso: gpu_iso_value(s),
            ..ChannelEntry::default()
        };
    }
    Tables { uniforms, words }
}

/// The scene tables on the GPU: the table buffer of the channels drawn, with room for styles
/// of more control points, and what the frame parameters take from it. A style change
/// rewrites it in place ([`SceneTables::rewrite`]); the residency state is not touched.
pub struct SceneTables {
    uniforms: wgpu::Buffer,
    buffer: wgpu::Buffer,
    /// Capacity of `buffer` in words.
    capacity: usize,
    steps_per_pass: u32,
}

impl SceneTables {
    /// The tables of `styles` (one per channel of `residency`, in its order) under `options`'
    /// level bounds.
    ///
    /// # Errors
    /// [`GpuError::TooManyLevels`] where the volume has more than [`MAX_LEVELS`] levels,
    /// [`GpuError::TooManyChannels`] past [`MAX_CHANNELS`], or
    /// [`GpuError::BindingTooLarge`] where the buffer exceeds the device's limits.
    pub fn new(
        gpu: &Gpu,
        residency: &ResidencyState,
        options: &RenderOptions,
        styles: &[&ChannelStyle],
    ) -> Result<Self, GpuError> {
        let levels = residency.info().levels.len();
        if levels > MAX_LEVELS {
            return Err(GpuError::TooManyLevels {
                volume: residency.info().name.clone(),
                levels,
            });
        }
        if styles.len() > MAX_CHANNELS {
            return Err(GpuError::TooManyChannels {
                channels: styles.len(),
            });
        }
        let t = residency_tables(residency, options, styles);
        let mut tables = Self::allocate(gpu, t.words.len() + styles.len() * 2 * HEADROOM_POINTS)?;
        tables.write(gpu, &t, residency_steps(residency, styles));
        Ok(tables)
    }

    /// The fixed tables of `styles` drawn at level 0 only, with no page tables and no room
    /// to restyle: the limit probe's.
    ///
    /// # Errors
    /// [`GpuError::TooManyChannels`] past [`MAX_CHANNELS`], the octree's refusal of the
    /// volume, or [`GpuError::BindingTooLarge`].
    #[cfg(not(target_arch = "wasm32"))]
    pub fn level0(
        gpu: &Gpu,
        info: &crate::source::VolumeInfo,
        styles: &[&ChannelStyle],
    ) -> Result<Self, GpuError> {
        if styles.len() > MAX_CHANNELS {
            return Err(GpuError::TooManyChannels {
                channels: styles.len(),
            });
        }
        let geometry = OctreeGeometry::new(info, 0)?;
        let channels: Vec<ChannelTable<'_>> = styles
            .iter()
            .map(|style| ChannelTable {
                style,
                min_level: 0,
                max_level: 0,
            })
            .collect();
        let t = build(&geometry, info.spacing_xyz(), &[], &channels);
        let mut tables = Self::allocate(gpu, t.words.len())?;
        let max_points = styles.iter().map(|c| c.opacity.len()).max().unwrap_or(0);
        tables.write(gpu, &t, steps_per_pass(styles.len(), 1, max_points, 0));
        Ok(tables)
    }

    /// Buffers for a table of up to `capacity` words and the scene uniforms.
    fn allocate(gpu: &Gpu, capacity: usize) -> Result<Self, GpuError> {
        check_binding(
            gpu,
            "the scene tables",
            capacity as u64 * 4,
            "use transfer functions of fewer points",
        )?;
        Ok(Self {
            uniforms: uniform_buffer(gpu, "scene uniforms", size_of::<SceneUniforms>() as u64),
            buffer: storage_buffer(
                gpu,
                "tables",
                capacity as u64 * 4,
                wgpu::BufferUsages::empty(),
            ),
            capacity,
            steps_per_pass: 0,
        })
    }

    /// Uploads `t`, which fits.
    fn write(&mut self, gpu: &Gpu, t: &Tables, steps_per_pass: u32) {
        gpu.queue
            .write_buffer(&self.buffer, 0, bytemuck::cast_slice(&t.words));
        gpu.queue
            .write_buffer(&self.uniforms, 0, bytemuck::bytes_of(&t.uniforms));
        self.steps_per_pass = steps_per_pass;
    }

    /// Writes the tables of `styles` in place. Returns `false`, writing nothing, when they do
    /// not fit the buffer (transfer functions of many more points): that needs new tables.
    pub fn rewrite(
        &mut self,
        gpu: &Gpu,
        residency: &ResidencyState,
        options: &RenderOptions,
        styles: &[&ChannelStyle],
    ) -> bool {
        let t = residency_tables(residency, options, styles);
        if t.words.len() > self.capacity {
            return false;
        }
        self.write(gpu, &t, residency_steps(residency, styles));
        true
    }

    /// The table buffer.
    pub fn buffer(&self) -> &wgpu::Buffer {
        &self.buffer
    }

    /// The scene uniforms.
    pub fn uniforms(&self) -> &wgpu::Buffer {
        &self.uniforms
    }

    /// Steps one ray may take in a pass (see [`steps_per_pass`]).
    pub fn steps_per_pass(&self) -> u32 {
        self.steps_per_pass
    }
}

/// [`steps_per_pass`] of `styles` over `residency`'s levels and octree.
fn residency_steps(residency: &ResidencyState, styles: &[&ChannelStyle]) -> u32 {
    steps_per_pass(
        styles.len(),
        residency.info().levels.len(),
        styles.iter().map(|c| c.opacity.len()).max().unwrap_or(0),
        residency.octree().geometry().depth,
    )
}

/// The tables of `styles` over `residency`'s volume, octree and page tables.
fn residency_tables(
    residency: &ResidencyState,
    options: &RenderOptions,
    styles: &[&ChannelStyle],
) -> Tables {
    let info = residency.info();
    build(
        residency.octree().geometry(),
        info.spacing_xyz(),
        residency.pages().offsets(),
        &channel_tables(options, info.levels.len() as u32, styles),
    )
}

/// The level bounds `(finest, coarsest)` of the `i`-th rendered channel of a volume of
/// `levels` levels: `options.level_bounds`, clamped to the levels that exist, every level where
/// none is given.
pub fn channel_level_bounds(options: &RenderOptions, levels: u32, i: usize) -> (u32, u32) {
    let (lo, hi) = options
        .level_bounds
        .get(i)
        .copied()
        .unwrap_or((0, levels - 1));
    let lo = lo.min(levels - 1);
    (lo, hi.clamp(lo, levels - 1))
}

/// The table entries of `styles`: style and level bounds ([`channel_level_bounds`]).
fn channel_tables<'a>(
    options: &RenderOptions,
    levels: u32,
    styles: &[&'a ChannelStyle],
) -> Vec<ChannelTable<'a>> {
    styles
        .iter()
        .enumerate()
        .map(|(i, style)| {
            let (min_level, max_level) = channel_level_bounds(options, levels, i);
            ChannelTable {
                style,
                min_level,
                max_level,
            }
        })
        .collect()
}

/// Steps one ray may take in a pass: the driver's loop limit divided by a bound on the loop
/// iterations one step takes (levels chosen per channel, transfer-function points, the octree
/// walk, the 8 voxels of a sample and the substitution candidates).
pub fn steps_per_pass(channels: usize, levels: usize, tf_points: usize, depth: u32) -> u32 {
    let c = channels.max(1);
    let per_step = 8 + c * (3 * levels + 2 * tf_points + 24) + (depth as usize + 2) * (c + 1);
    (DRIVER_LOOP_LIMIT as usize / per_step).clamp(16, 1 << 20) as u32
}
