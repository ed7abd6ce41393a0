//! The read-only `u32` table buffer of `raycast.wgsl` (floats stored as bits):
//!
//! - per level (12 words): `log2` downsampling factor `x, y, z`; shape `x, y, z`; bricks per
//!   axis `x, y, z`; smallest voxel edge in world units; two reserved words;
//! - page-table offsets, `slot · levels + level`;
//! - per channel slot (16 words): colour `r, g, b`; level bounds `min, max`; offset and count
//!   of its opacity control points; offset of its prefix table; TF domain `lo, hi`; opacity
//!   below and above the domain; four reserved words;
//! - control points `(value, opacity)` pairs and prefix tables of `bins + 1` counts, where
//!   `prefix[i + 1] − prefix[i]` is 1 when the opacity is non-zero somewhere in bin `i`, so
//!   "transparent over `[lo, hi]`" is one subtraction (Octree Rasterization Sec. 4.1).

use anyhow::Result;

use super::device::Gpu;
use super::renderer::RenderOptions;
use super::residency::{ResidencyState, check_binding, storage_buffer};
use crate::octree::{OctreeGeometry, f32_down, f32_up};
use crate::scene::ChannelStyle;

/// Opacity control points per channel the table buffer has room for beyond the scene's own,
/// so that [`SceneTables::rewrite`] writes a new style in place.
const HEADROOM_POINTS: usize = 64;

/// Loop iterations a CPU Vulkan driver (Mesa's lavapipe/llvmpipe) allows one invocation in
/// all, nested loops included; the shader ends a pass well before it.
const DRIVER_LOOP_LIMIT: u32 = 65_535;

/// Words per level entry.
pub const LEVEL_WORDS: usize = 12;
/// Words per channel entry.
pub const CHANNEL_WORDS: usize = 16;
/// Bins of each transfer function's prefix table.
pub const TF_BINS: usize = 1024;

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

/// The built table and where its sections start.
#[derive(Clone, Debug, PartialEq)]
pub struct Tables {
    /// The words.
    pub words: Vec<u32>,
    /// Offset of the level section.
    pub levels_offset: u32,
    /// Offset of the channel section.
    pub channels_offset: u32,
}

/// The transfer function's domain `[lo, hi]` (widened to `[v, v + 1]` for a single point).
pub fn tf_domain(style: &ChannelStyle) -> (f64, f64) {
    let pts = &style.opacity;
    match (pts.first(), pts.last()) {
        (Some(a), Some(b)) if b.value > a.value => (a.value, b.value),
        (Some(a), _) => (a.value, a.value + 1.0),
        _ => (0.0, 1.0),
    }
}

/// Prefix counts of bins (over the domain) where the opacity is non-zero somewhere.
pub fn tf_prefix(style: &ChannelStyle, bins: usize) -> Vec<u32> {
    let (lo, hi) = tf_domain(style);
    let w = (hi - lo) / bins as f64;
    let mut prefix = Vec::with_capacity(bins + 1);
    prefix.push(0u32);
    for i in 0..bins {
        let (a, b) = (lo + i as f64 * w, lo + (i + 1) as f64 * w);
        let nonzero = style.opacity_at(a) > 0.0
            || style.opacity_at(b) > 0.0
            || style
                .opacity
                .iter()
                .any(|p| p.value > a && p.value < b && p.opacity > 0.0);
        prefix.push(prefix[i] + nonzero as u32);
    }
    prefix
}

/// Builds the table for `geometry` (with voxel spacing `spacing`, `x, y, z`), page-table
/// `offsets` and `channels`.
pub fn build(
    geometry: &OctreeGeometry,
    spacing: [f64; 3],
    page_offsets: &[u32],
    channels: &[ChannelTable<'_>],
) -> Tables {
    let mut w: Vec<u32> = Vec::new();
    let f = |v: f64| (v as f32).to_bits();
    let levels_offset = 0u32;
    for (l, shift) in geometry.level_shift.iter().enumerate() {
        let shape = geometry.level_shape[l];
        w.extend(shift.iter().copied());
        w.extend(shape.iter().map(|&s| s as u32));
        w.extend((0..3).map(|a| shape[a].div_ceil(geometry.brick[a]) as u32));
        let voxel = (0..3)
            .map(|a| (1u64 << shift[a]) as f64 * spacing[a])
            .fold(f64::INFINITY, f64::min);
        w.push(f(voxel));
        w.extend([0, 0]);
    }
    w.extend_from_slice(page_offsets);
    let channels_offset = w.len() as u32;
    let tail_start = channels_offset as usize + channels.len() * CHANNEL_WORDS;
    let mut tail: Vec<u32> = Vec::new();
    for (i, ch) in channels.iter().enumerate() {
        let s = ch.style;
        let points_offset = (tail_start + tail.len()) as u32;
        for p in &s.opacity {
            tail.push(f(p.value));
            tail.push(f(p.opacity));
        }
        let prefix_offset = (tail_start + tail.len()) as u32;
        tail.extend(tf_prefix(s, TF_BINS));
        let (lo, hi) = tf_domain(s);
        let below = s.opacity.first().map_or(0.0, |p| p.opacity);
        let above = s.opacity.last().map_or(0.0, |p| p.opacity);
        w.extend(s.color.map(f));
        w.extend([
            ch.min_level,
            ch.max_level,
            points_offset,
            s.opacity.len() as u32,
        ]);
        w.push(prefix_offset);
        // Round the domain outward to f32 (exact when representable).
        w.push(f32_down(lo).to_bits());
        w.push(f32_up(hi).to_bits());
        w.extend([f(below), f(above), 0, 0, 0, 0]);
        debug_assert_eq!(
            w.len(),
            tail_start - (channels.len() - 1 - i) * CHANNEL_WORDS
        );
    }
    w.extend(tail);
    Tables {
        words: w,
        levels_offset,
        channels_offset,
    }
}

/// The scene tables on the GPU: the table buffer of the channels drawn, with room for styles
/// of more control points, and what the frame parameters take from it. A style change
/// rewrites it in place ([`SceneTables::rewrite`]); the residency state is not touched.
pub struct SceneTables {
    buffer: wgpu::Buffer,
    /// Capacity of `buffer` in words.
    capacity: usize,
    channels_offset: u32,
    steps_per_pass: u32,
}

impl SceneTables {
    /// The tables of `styles` (one per channel of `residency`, in its order) under `options`'
    /// level bounds. Errors where the buffer exceeds the device's limits.
    pub fn new(
        gpu: &Gpu,
        residency: &ResidencyState,
        options: &RenderOptions,
        styles: &[&ChannelStyle],
    ) -> Result<Self> {
        let t = residency_tables(residency, options, styles);
        let capacity = t.words.len() + styles.len() * 2 * HEADROOM_POINTS;
        check_binding(
            gpu,
            "the scene tables",
            capacity as u64 * 4,
            "use transfer functions of fewer points",
        )?;
        let buffer = storage_buffer(
            gpu,
            "tables",
            capacity as u64 * 4,
            wgpu::BufferUsages::empty(),
        );
        let mut tables = Self {
            buffer,
            capacity,
            channels_offset: 0,
            steps_per_pass: 0,
        };
        let written = tables.rewrite(gpu, residency, options, styles);
        debug_assert!(written, "a new table buffer holds its own tables");
        Ok(tables)
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
        gpu.queue
            .write_buffer(&self.buffer, 0, bytemuck::cast_slice(&t.words));
        self.channels_offset = t.channels_offset;
        self.steps_per_pass = steps_per_pass(
            styles.len(),
            residency.info().levels.len(),
            styles.iter().map(|c| c.opacity.len()).max().unwrap_or(0),
            residency.octree().geometry().depth,
        );
        true
    }

    /// The table buffer.
    pub fn buffer(&self) -> &wgpu::Buffer {
        &self.buffer
    }

    /// Word offset of the channel section.
    pub fn channels_offset(&self) -> u32 {
        self.channels_offset
    }

    /// Steps one ray may take in a pass (see [`steps_per_pass`]).
    pub fn steps_per_pass(&self) -> u32 {
        self.steps_per_pass
    }
}

/// The tables of `styles` over `residency`'s volume, octree and page tables.
fn residency_tables(
    residency: &ResidencyState,
    options: &RenderOptions,
    styles: &[&ChannelStyle],
) -> Tables {
    let info = residency.info();
    let spacing = [info.voxel_size[2], info.voxel_size[1], info.voxel_size[0]];
    build(
        residency.octree().geometry(),
        spacing,
        residency.pages().offsets(),
        &channel_tables(options, info.levels.len() as u32, styles),
    )
}

/// The table entries of `styles`: style and level bounds (from `options.level_bounds`, every
/// level where none is given).
fn channel_tables<'a>(
    options: &RenderOptions,
    levels: u32,
    styles: &[&'a ChannelStyle],
) -> Vec<ChannelTable<'a>> {
    styles
        .iter()
        .enumerate()
        .map(|(i, style)| {
            let (lo, hi) = options
                .level_bounds
                .get(i)
                .copied()
                .unwrap_or((0, levels - 1));
            ChannelTable {
                style,
                min_level: lo.min(levels - 1),
                max_level: hi.clamp(lo.min(levels - 1), levels - 1),
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
