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

use crate::octree::{OctreeGeometry, f32_down, f32_up};
use crate::scene::ChannelStyle;

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
