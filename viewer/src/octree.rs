//! The residency octree (paper Sec. 5): a full, pointerless octree over the volume whose nodes
//! store, per rendered channel, a 16-bit *partial-residency mask* (bit `l` set when at least one
//! cache-resident brick of level `l` overlaps the node) and a conservative value range.
//!
//! **Geometry.** Axes are `x, y, z` here (the source's `z, y, x` are swapped on the way in).
//! The root covers `2^e_a` level-0 voxels along axis `a`, the smallest power of two holding the
//! volume, so every node edge is a power of two in voxels (exact integer addressing on the GPU
//! for volumes up to 2³¹ voxels wide). The leaf depth `D` is chosen independently of the brick
//! size, so leaves may be smaller than bricks. Node `(d, x, y, z)` has the flat index
//! `(8^d − 1)/7 + (z·2^d + y)·2^d + x`.
//!
//! **Brick overlap.** A brick of level `l` covers the level-`l` voxels `[b·B, (b+1)·B)` per
//! axis; it is counted as overlapping a node when that interval, widened by one voxel on each
//! side (the voxels a trilinear sample near the brick's edge also reads), intersects the node.
//!
//! **Value ranges** come from the server's min/max grids ([`VolumeInfo::minmax`]): a node's
//! range is the union of the level-0 haloed cells its region touches, so it bounds every
//! trilinear sample of the full-resolution data inside the node. Emptiness is a property of
//! that data: a node transparent at full resolution is skipped whichever level is sampled
//! (coarser levels only approximate it; their wider halos would make every node non-empty).
//! Never computed from voxels when the server has them. A store without region metadata
//! starts every in-volume node at the unknown range `(−∞, +∞)` (no skipping), with a warning,
//! and falls back to ranges computed from level-0 bricks as they arrive
//! ([`ResidencyOctree::refine_ranges`]): a leaf gets a range once one brick holds all the
//! voxels its samples can read.

use std::collections::HashSet;
use std::ops::Range;

use crate::source::{BrickKey, BrickVoxels, VolumeInfo};

/// Why the octree refused a volume, a channel or a brick: a pyramid it cannot describe
/// (too deep, too many levels, factors that are not powers of two), region metadata that does
/// not fit, or a brick outside it. Messages name the volume or the brick.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum OctreeError {
    /// A leaf depth past [`MAX_DEPTH`].
    #[error("octree depth {depth} exceeds the maximum {}", MAX_DEPTH)]
    TooDeep {
        /// The depth asked for.
        depth: u32,
    },
    /// A volume without levels.
    #[error("{volume}: volume has no levels")]
    NoLevels {
        /// The volume.
        volume: String,
    },
    /// More levels than a residency mask holds.
    #[error(
        "{volume}: {levels} pyramid levels; a residency mask holds at most {}",
        MAX_LEVELS
    )]
    TooManyLevels {
        /// The volume.
        volume: String,
        /// Its levels.
        levels: usize,
    },
    /// A level whose downsampling factor is not a power of two along some axis.
    #[error(
        "{volume}: level {level} downsampling factor {factor:?} is not a power of two per axis"
    )]
    FactorNotPowerOfTwo {
        /// The volume.
        volume: String,
        /// The level.
        level: usize,
        /// Its factor, `z, y, x`.
        factor: [u64; 3],
    },
    /// A channel the volume does not have.
    #[error("{volume}: no channel {channel} ({channels} channels)")]
    NoChannel {
        /// The volume.
        volume: String,
        /// The channel asked for.
        channel: usize,
        /// Channels of the volume.
        channels: usize,
    },
    /// A brick of a channel the octree does not hold.
    #[error("brick {key:?}: channel not in the octree")]
    ChannelNotInOctree {
        /// The brick.
        key: BrickKey,
    },
    /// A brick of a level the octree does not have.
    #[error("brick {key:?}: no such level")]
    NoSuchLevel {
        /// The brick.
        key: BrickKey,
    },
    /// A brick outside its level's brick grid.
    #[error("brick {key:?}: outside the level's brick grid")]
    OutsideGrid {
        /// The brick.
        key: BrickKey,
    },
    /// Region metadata without min/max grids for a channel.
    #[error("{volume}: no min/max grids for channel {channel}")]
    NoMinMax {
        /// The volume.
        volume: String,
        /// The channel.
        channel: usize,
    },
    /// Region metadata without a min/max grid for a level.
    #[error("{volume}: channel {channel} level {level}: no min/max grid")]
    NoMinMaxGrid {
        /// The volume.
        volume: String,
        /// The channel.
        channel: usize,
        /// The level.
        level: usize,
    },
    /// A min/max grid whose values or cells do not fit its shape.
    #[error("{volume}: channel {channel} level {level}: malformed min/max grid")]
    MalformedMinMax {
        /// The volume.
        volume: String,
        /// The channel.
        channel: usize,
        /// The level.
        level: usize,
    },
}

/// Deepest leaf depth accepted (`(8^11 − 1)/7` ≈ 1.2 G nodes is already far too many).
pub const MAX_DEPTH: u32 = 10;

/// Most pyramid levels a 16-bit residency mask can describe.
pub const MAX_LEVELS: usize = 16;

/// `u32` words per node and channel in the flat GPU layout: `[mask, min bits, max bits]`.
pub const WORDS_PER_CHANNEL: usize = 3;

/// Number of nodes in levels `0..d` of a full octree, i.e. the index of the first node of
/// depth `d`.
pub fn depth_offset(d: u32) -> usize {
    ((1usize << (3 * d)) - 1) / 7
}

/// Flat index of node `(d, x, y, z)`.
pub fn node_index(d: u32, c: [u64; 3]) -> usize {
    depth_offset(d) + ((((c[2] << d) + c[1]) << d) + c[0]) as usize
}

/// Child `k` (`0..8`, `x` in bit 0, `y` in bit 1, `z` in bit 2) of the node at `c`, one
/// depth down.
fn child(c: [u64; 3], k: u64) -> [u64; 3] {
    [
        2 * c[0] + (k & 1),
        2 * c[1] + ((k >> 1) & 1),
        2 * c[2] + (k >> 2),
    ]
}

/// The cells `[x, y, z]` of the box `x in rx, y in ry, z in rz`, `x` fastest.
fn cells([rx, ry, rz]: [Range<u64>; 3]) -> impl Iterator<Item = [u64; 3]> {
    rz.flat_map(move |z| {
        let rx = rx.clone();
        ry.clone()
            .flat_map(move |y| rx.clone().map(move |x| [x, y, z]))
    })
}

/// Largest `f32` not above `v` (for conservative minima).
pub(crate) fn f32_down(v: f64) -> f32 {
    let f = v as f32;
    if (f as f64) > v { f.next_down() } else { f }
}

/// Smallest `f32` not below `v` (for conservative maxima).
pub(crate) fn f32_up(v: f64) -> f32 {
    let f = v as f32;
    if (f as f64) < v { f.next_up() } else { f }
}

/// The octree's spatial layout and the volume's pyramid, in `x, y, z` order.
#[derive(Clone, Debug, PartialEq)]
pub struct OctreeGeometry {
    /// Leaf depth `D` (the root is depth 0).
    pub depth: u32,
    /// `log2` of a leaf's edge in level-0 voxels, per axis (negative: sub-voxel leaves).
    pub leaf_shift: [i32; 3],
    /// Level-0 voxels per axis.
    pub volume_voxels: [u64; 3],
    /// Brick edge in voxels per axis.
    pub brick: [u64; 3],
    /// Per level: `log2` of its downsampling factor per axis.
    pub level_shift: Vec<[u32; 3]>,
    /// Per level: voxels per axis.
    pub level_shape: Vec<[u64; 3]>,
}

impl OctreeGeometry {
    /// The geometry for `info` with leaf depth `depth`. Errors if a downsampling factor is not
    /// a power of two, or the pyramid has more than [`MAX_LEVELS`] levels.
    ///
    /// # Errors
    /// [`OctreeError::TooDeep`], [`OctreeError::NoLevels`], [`OctreeError::TooManyLevels`]
    /// or [`OctreeError::FactorNotPowerOfTwo`], naming the volume.
    pub fn new(info: &VolumeInfo, depth: u32) -> Result<Self, OctreeError> {
        if depth > MAX_DEPTH {
            return Err(OctreeError::TooDeep { depth });
        }
        if info.levels.is_empty() {
            return Err(OctreeError::NoLevels {
                volume: info.name.clone(),
            });
        }
        if info.levels.len() > MAX_LEVELS {
            return Err(OctreeError::TooManyLevels {
                volume: info.name.clone(),
                levels: info.levels.len(),
            });
        }
        let xyz = |a: [u64; 3]| [a[2], a[1], a[0]];
        let volume_voxels = xyz(info.levels[0].shape);
        let mut level_shift = Vec::new();
        for (l, level) in info.levels.iter().enumerate() {
            let f = xyz(level.factor);
            if f.iter().any(|f| !f.is_power_of_two()) {
                return Err(OctreeError::FactorNotPowerOfTwo {
                    volume: info.name.clone(),
                    level: l,
                    factor: level.factor,
                });
            }
            level_shift.push(f.map(u64::trailing_zeros));
        }
        let leaf_shift = volume_voxels.map(|n| {
            let e = 64 - (n.max(1) - 1).leading_zeros() as i32; // ceil(log2 n)
            e - depth as i32
        });
        Ok(Self {
            depth,
            leaf_shift,
            volume_voxels,
            brick: xyz(info.brick_shape),
            level_shift,
            level_shape: info.levels.iter().map(|l| xyz(l.shape)).collect(),
        })
    }

    /// A leaf depth giving leaves of about `leaf_voxels` level-0 voxels along the volume's
    /// longest axis, capped at `max_depth`.
    pub fn depth_for(info: &VolumeInfo, leaf_voxels: u64, max_depth: u32) -> u32 {
        let longest = info.levels[0]
            .shape
            .iter()
            .copied()
            .max()
            .unwrap_or(1)
            .max(1);
        let e = 64 - (longest - 1).leading_zeros();
        let l = leaf_voxels.max(1).ilog2();
        e.saturating_sub(l).min(max_depth)
    }

    /// Number of nodes in the full octree.
    pub fn node_count(&self) -> usize {
        depth_offset(self.depth + 1)
    }

    /// Leaves per axis (`2^D`).
    pub fn leaves_per_axis(&self) -> u64 {
        1 << self.depth
    }

    /// Level-0 voxel interval `[lo, hi)` of leaf `k` along `axis`.
    fn leaf_interval(&self, axis: usize, k: u64) -> (f64, f64) {
        let s = (self.leaf_shift[axis] as f64).exp2();
        (k as f64 * s, (k + 1) as f64 * s)
    }

    /// Level-0 voxel interval of brick `b` of `level` along `axis`, widened by one voxel of the
    /// level on each side and clipped to the volume.
    fn brick_interval(&self, level: usize, axis: usize, b: u64) -> (f64, f64) {
        let f = (1u64 << self.level_shift[level][axis]) as f64;
        let bb = self.brick[axis] as f64;
        let lo = ((b as f64 * bb - 1.0) * f).max(0.0);
        let hi = (((b + 1) as f64 * bb + 1.0) * f).min(self.volume_voxels[axis] as f64);
        (lo, hi)
    }

    /// Leaves along `axis` that overlap brick `b` of `level`.
    pub fn leaves_of_brick_axis(&self, level: usize, axis: usize, b: u64) -> Range<u64> {
        let (lo, hi) = self.brick_interval(level, axis, b);
        if hi <= lo {
            return 0..0;
        }
        let s = (self.leaf_shift[axis] as f64).exp2();
        let n = self.leaves_per_axis();
        let first = (lo / s).floor() as u64;
        let last = ((hi / s).ceil() as u64).min(n);
        first.min(n)..last
    }

    /// Bricks along `axis` of `level` that overlap leaf `k`.
    pub fn bricks_of_leaf_axis(&self, level: usize, axis: usize, k: u64) -> Range<u64> {
        let (lo, hi) = self.leaf_interval(axis, k);
        let nb = self.level_shape[level][axis].div_ceil(self.brick[axis]);
        let f = (1u64 << self.level_shift[level][axis]) as f64;
        let bb = (self.brick[axis] as f64) * f;
        let first = ((lo / bb).floor() as i64 - 1).max(0) as u64;
        let last = (((hi / bb).floor() as i64 + 2).max(0) as u64).min(nb);
        let mut r = first.min(last)..last;
        // Trim to the exact overlap predicate.
        while r.start < r.end && !self.overlaps(level, axis, r.start, lo, hi) {
            r.start += 1;
        }
        while r.end > r.start && !self.overlaps(level, axis, r.end - 1, lo, hi) {
            r.end -= 1;
        }
        r
    }

    fn overlaps(&self, level: usize, axis: usize, b: u64, lo: f64, hi: f64) -> bool {
        let (blo, bhi) = self.brick_interval(level, axis, b);
        blo < hi && bhi > lo && blo < bhi
    }
}

/// The residency octree of the rendered channels: masks, value ranges and the set of
/// resident bricks it was built from.
#[derive(Clone, Debug)]
pub struct ResidencyOctree {
    geometry: OctreeGeometry,
    /// Source channel index of each octree channel slot.
    channels: Vec<usize>,
    /// `masks[node · m + slot]`.
    masks: Vec<u16>,
    /// `ranges[node · m + slot] = (min, max)`; `min > max` marks a node with no data.
    ranges: Vec<(f64, f64)>,
    resident: HashSet<BrickKey>,
    dirty: Option<Range<usize>>,
    unknown_ranges: bool,
    /// Voxels the filter reads beyond the trilinear footprint ([`crate::scene::Filter::reach`]).
    reach: u64,
}

impl ResidencyOctree {
    /// Builds the octree of `channels` (source channel indices) over `info` with leaf depth
    /// `depth`, seeding value ranges from the server's min/max grids. No brick is resident.
    ///
    /// # Errors
    /// The geometry's errors ([`OctreeGeometry::new`]), [`OctreeError::NoChannel`], or an
    /// error naming the channel and level of region metadata that does not fit.
    pub fn new(info: &VolumeInfo, channels: &[usize], depth: u32) -> Result<Self, OctreeError> {
        Self::for_filter(info, channels, depth, 0)
    }

    /// [`ResidencyOctree::new`] for a filter that reads `reach` voxels beyond the trilinear
    /// footprint on each side ([`crate::scene::Filter::reach`]): every node's range covers the
    /// region metadata's cells within `reach` voxels of it, so it still bounds every sample
    /// inside the node.
    ///
    /// # Errors
    /// As [`ResidencyOctree::new`].
    pub fn for_filter(
        info: &VolumeInfo,
        channels: &[usize],
        depth: u32,
        reach: u64,
    ) -> Result<Self, OctreeError> {
        let geometry = OctreeGeometry::new(info, depth)?;
        for &c in channels {
            if c >= info.channels.len() {
                return Err(OctreeError::NoChannel {
                    volume: info.name.clone(),
                    channel: c,
                    channels: info.channels.len(),
                });
            }
        }
        let m = channels.len();
        let nodes = geometry.node_count();
        let mut tree = Self {
            masks: vec![0; nodes * m],
            ranges: vec![(f64::INFINITY, f64::NEG_INFINITY); nodes * m],
            geometry,
            channels: channels.to_vec(),
            resident: HashSet::new(),
            dirty: Some(0..nodes),
            unknown_ranges: info.minmax.is_none(),
            reach,
        };
        if let Some(grids) = &info.minmax {
            tree.seed_ranges(info, grids)?;
        } else {
            tracing::warn!(
                "{}: no region metadata; octree value ranges are unknown, so no empty space \
                 is skipped",
                info.name
            );
            tree.seed_unknown();
        }
        tree.propagate_ranges();
        Ok(tree)
    }

    /// The spatial layout.
    pub fn geometry(&self) -> &OctreeGeometry {
        &self.geometry
    }

    /// Source channel indices, one per octree channel slot.
    pub fn channels(&self) -> &[usize] {
        &self.channels
    }

    /// Whether value ranges are unknown (the store had no region metadata).
    pub fn unknown_ranges(&self) -> bool {
        self.unknown_ranges
    }

    /// The channel slot of source channel `channel`, if rendered.
    pub fn slot_of(&self, channel: usize) -> Option<usize> {
        self.channels.iter().position(|&c| c == channel)
    }

    /// Residency mask of `node` for channel slot `slot`.
    pub fn mask(&self, node: usize, slot: usize) -> u16 {
        self.masks[node * self.channels.len() + slot]
    }

    /// Value range `(min, max)` of `node` for channel slot `slot` (`min > max`: no data).
    pub fn range(&self, node: usize, slot: usize) -> (f64, f64) {
        self.ranges[node * self.channels.len() + slot]
    }

    /// All masks, `node`-major.
    pub fn masks(&self) -> &[u16] {
        &self.masks
    }

    /// Whether `key` is resident.
    pub fn is_resident(&self, key: &BrickKey) -> bool {
        self.resident.contains(key)
    }

    /// Number of resident bricks.
    pub fn resident_count(&self) -> usize {
        self.resident.len()
    }

    fn leaf_coord_ranges(&self, key: &BrickKey) -> [Range<u64>; 3] {
        let l = key.level as usize;
        let b = [key.brick[2], key.brick[1], key.brick[0]];
        std::array::from_fn(|a| self.geometry.leaves_of_brick_axis(l, a, b[a]))
    }

    fn check(&self, key: &BrickKey) -> Result<usize, OctreeError> {
        let slot = self
            .slot_of(key.channel as usize)
            .ok_or(OctreeError::ChannelNotInOctree { key: *key })?;
        let l = key.level as usize;
        if l >= self.geometry.level_shape.len() {
            return Err(OctreeError::NoSuchLevel { key: *key });
        }
        let shape = &self.geometry.level_shape[l];
        for (a, (&n, &b)) in shape.iter().zip(&self.geometry.brick).enumerate() {
            let nb = n.div_ceil(b);
            if key.brick[2 - a] >= nb {
                return Err(OctreeError::OutsideGrid { key: *key });
            }
        }
        Ok(slot)
    }

    /// Marks `key` resident: sets its level's bit in every overlapping leaf and ORs the change
    /// upward, stopping where a mask is unchanged. Returns whether `key` was newly inserted.
    ///
    /// # Errors
    /// [`OctreeError::ChannelNotInOctree`], [`OctreeError::NoSuchLevel`] or
    /// [`OctreeError::OutsideGrid`] for a brick the octree does not hold.
    pub fn insert(&mut self, key: BrickKey) -> Result<bool, OctreeError> {
        let slot = self.check(&key)?;
        if !self.resident.insert(key) {
            return Ok(false);
        }
        let bit = 1u16 << key.level;
        let d = self.geometry.depth;
        let m = self.channels.len();
        for leaf in cells(self.leaf_coord_ranges(&key)) {
            let n = node_index(d, leaf);
            let i = n * m + slot;
            if self.masks[i] & bit == 0 {
                self.masks[i] |= bit;
                self.mark_dirty(n);
                self.propagate_up(leaf, slot);
            }
        }
        Ok(true)
    }

    /// Marks `key` no longer resident: clears its level's bit in each overlapping leaf that no
    /// other resident brick of the same channel and level overlaps, then updates ancestors by
    /// OR of their children, stopping where a mask is unchanged. Returns whether `key` was
    /// resident.
    ///
    /// # Errors
    /// As [`ResidencyOctree::insert`].
    pub fn evict(&mut self, key: BrickKey) -> Result<bool, OctreeError> {
        let slot = self.check(&key)?;
        if !self.resident.remove(&key) {
            return Ok(false);
        }
        let l = key.level as usize;
        let bit = 1u16 << key.level;
        let d = self.geometry.depth;
        let m = self.channels.len();
        for leaf in cells(self.leaf_coord_ranges(&key)) {
            let still = {
                let [bx, by, bz] =
                    std::array::from_fn(|a| self.geometry.bricks_of_leaf_axis(l, a, leaf[a]));
                bz.clone().any(|bz| {
                    by.clone().any(|by| {
                        bx.clone().any(|bx| {
                            self.resident.contains(&BrickKey {
                                level: key.level,
                                channel: key.channel,
                                brick: [bz, by, bx],
                            })
                        })
                    })
                })
            };
            let n = node_index(d, leaf);
            let i = n * m + slot;
            if !still && self.masks[i] & bit != 0 {
                self.masks[i] &= !bit;
                self.mark_dirty(n);
                self.propagate_up(leaf, slot);
            }
        }
        Ok(true)
    }

    /// Recomputes ancestors of leaf `leaf` as the OR of their children, stopping at the first
    /// unchanged mask.
    fn propagate_up(&mut self, leaf: [u64; 3], slot: usize) {
        let m = self.channels.len();
        let mut c = leaf;
        let mut d = self.geometry.depth;
        while d > 0 {
            c = c.map(|v| v >> 1);
            d -= 1;
            let mut or = 0u16;
            for k in 0..8u64 {
                or |= self.masks[node_index(d + 1, child(c, k)) * m + slot];
            }
            let n = node_index(d, c);
            if self.masks[n * m + slot] == or {
                break;
            }
            self.masks[n * m + slot] = or;
            self.mark_dirty(n);
        }
    }

    fn mark_dirty(&mut self, n: usize) {
        self.dirty = Some(match self.dirty.take() {
            Some(r) => r.start.min(n)..r.end.max(n + 1),
            None => n..n + 1,
        });
    }

    /// The masks recomputed from scratch from the resident set (leaves from every resident
    /// brick, interior nodes as the OR of their children); equal to [`Self::masks`] at all
    /// times.
    pub fn masks_from_scratch(&self) -> Vec<u16> {
        let m = self.channels.len();
        let d = self.geometry.depth;
        let mut masks = vec![0u16; self.masks.len()];
        for key in &self.resident {
            let slot = self
                .slot_of(key.channel as usize)
                .expect("checked on insert");
            for leaf in cells(self.leaf_coord_ranges(key)) {
                masks[node_index(d, leaf) * m + slot] |= 1 << key.level;
            }
        }
        for depth in (0..d).rev() {
            let n = 1u64 << depth;
            for z in 0..n {
                for y in 0..n {
                    for x in 0..n {
                        let parent = node_index(depth, [x, y, z]);
                        for k in 0..8u64 {
                            let ci = node_index(depth + 1, child([x, y, z], k));
                            for s in 0..m {
                                masks[parent * m + s] |= masks[ci * m + s];
                            }
                        }
                    }
                }
            }
        }
        masks
    }

    /// Fallback for a store without region metadata: sets the range of every leaf whose
    /// filter footprint (its voxels plus one on each side, plus the filter's reach, clamped
    /// to the volume) lies inside level-0 brick `key`, from `voxels`, and updates ancestors. Returns how many
    /// leaves got a range. Does nothing when the ranges came from the server.
    pub fn refine_ranges(&mut self, key: &BrickKey, voxels: &BrickVoxels) -> usize {
        if !self.unknown_ranges || key.level != 0 {
            return 0;
        }
        let Some(slot) = self.slot_of(key.channel as usize) else {
            return 0;
        };
        let g = &self.geometry;
        let brick = [key.brick[2], key.brick[1], key.brick[0]];
        let n = g.volume_voxels;
        // Per axis: leaves whose footprint lies in the brick, with that footprint.
        let mut axes: [Vec<(u64, u64, u64)>; 3] = Default::default();
        for a in 0..3 {
            let (b0, b1) = (
                brick[a] * g.brick[a],
                ((brick[a] + 1) * g.brick[a]).min(n[a]),
            );
            for k in g.leaves_of_brick_axis(0, a, brick[a]) {
                let (lo, hi) = g.leaf_interval(a, k);
                if lo >= n[a] as f64 {
                    continue;
                }
                let reach = self.reach as f64;
                let first = ((lo - 0.5 - reach).floor().max(0.0)) as u64;
                let last = ((hi - 0.5 + reach).ceil().min((n[a] - 1) as f64)) as u64;
                if first >= b0 && last < b1 {
                    axes[a].push((k, first - b0, last - b0));
                }
            }
        }
        let bs = g.brick;
        let d = g.depth;
        let m = self.channels.len();
        let mut count = 0;
        for &(kz, z0, z1) in &axes[2] {
            for &(ky, y0, y1) in &axes[1] {
                for &(kx, x0, x1) in &axes[0] {
                    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
                    for z in z0..=z1 {
                        for y in y0..=y1 {
                            for x in x0..=x1 {
                                let v = voxels.value(((z * bs[1] + y) * bs[0] + x) as usize);
                                if !v.is_nan() {
                                    lo = lo.min(v);
                                    hi = hi.max(v);
                                }
                            }
                        }
                    }
                    let leaf = [kx, ky, kz];
                    let i = node_index(d, leaf) * m + slot;
                    if self.ranges[i] != (lo, hi) {
                        self.ranges[i] = (lo, hi);
                        self.mark_dirty(node_index(d, leaf));
                        self.propagate_range_up(leaf, slot);
                    }
                    count += 1;
                }
            }
        }
        count
    }

    /// Recomputes ancestors' ranges of `leaf` as the union of their children's, stopping at
    /// the first unchanged one.
    fn propagate_range_up(&mut self, leaf: [u64; 3], slot: usize) {
        let m = self.channels.len();
        let mut c = leaf;
        let mut d = self.geometry.depth;
        while d > 0 {
            c = c.map(|v| v >> 1);
            d -= 1;
            let mut r = (f64::INFINITY, f64::NEG_INFINITY);
            for k in 0..8u64 {
                let cr = self.ranges[node_index(d + 1, child(c, k)) * m + slot];
                r = (r.0.min(cr.0), r.1.max(cr.1));
            }
            let n = node_index(d, c);
            if self.ranges[n * m + slot] == r {
                break;
            }
            self.ranges[n * m + slot] = r;
            self.mark_dirty(n);
        }
    }

    fn seed_unknown(&mut self) {
        let m = self.channels.len();
        let d = self.geometry.depth;
        let n = self.geometry.leaves_per_axis();
        for z in 0..n {
            for y in 0..n {
                for x in 0..n {
                    let inside = [x, y, z].iter().enumerate().all(|(a, &k)| {
                        self.geometry.leaf_interval(a, k).0 < self.geometry.volume_voxels[a] as f64
                    });
                    if inside {
                        let i = node_index(d, [x, y, z]) * m;
                        for s in 0..m {
                            self.ranges[i + s] = (f64::NEG_INFINITY, f64::INFINITY);
                        }
                    }
                }
            }
        }
    }

    fn seed_ranges(
        &mut self,
        info: &VolumeInfo,
        grids: &[Vec<Vec<crate::source::MinMaxGrid>>],
    ) -> Result<(), OctreeError> {
        let m = self.channels.len();
        let d = self.geometry.depth;
        let n = self.geometry.leaves_per_axis() as f64;
        for (slot, &channel) in self.channels.clone().iter().enumerate() {
            let per_level = grids.get(channel).ok_or_else(|| OctreeError::NoMinMax {
                volume: info.name.clone(),
                channel,
            })?;
            for (l, level_grids) in per_level.iter().enumerate().take(1) {
                let Some(grid) = level_grids.first() else {
                    return Err(OctreeError::NoMinMaxGrid {
                        volume: info.name.clone(),
                        channel,
                        level: l,
                    });
                };
                let cell = [grid.cell_shape[2], grid.cell_shape[1], grid.cell_shape[0]];
                let gshape = [grid.grid_shape[2], grid.grid_shape[1], grid.grid_shape[0]];
                if !(grid.min.len() as u64 == gshape.iter().product::<u64>()
                    && grid.max.len() == grid.min.len()
                    && cell.iter().all(|&c| c > 0))
                {
                    return Err(OctreeError::MalformedMinMax {
                        volume: info.name.clone(),
                        channel,
                        level: l,
                    });
                }
                // Leaf range of each cell (widened by the filter's reach) along each axis.
                let reach = self.reach;
                let leaf_ranges: [Vec<Range<u64>>; 3] = std::array::from_fn(|a| {
                    let f = (1u64 << self.geometry.level_shift[l][a]) as f64;
                    let s = (self.geometry.leaf_shift[a] as f64).exp2();
                    let vol = self.geometry.volume_voxels[a] as f64;
                    (0..gshape[a])
                        .map(|g| {
                            let lo = (g * cell[a]).saturating_sub(reach) as f64 * f;
                            let hi = (((g + 1) * cell[a] + reach) as f64 * f).min(vol);
                            if hi <= lo {
                                return 0..0;
                            }
                            let first = (lo / s).floor().min(n) as u64;
                            let last = (hi / s).ceil().min(n) as u64;
                            first..last
                        })
                        .collect()
                });
                for gz in 0..gshape[2] {
                    for gy in 0..gshape[1] {
                        for gx in 0..gshape[0] {
                            let ci = ((gz * gshape[1] + gy) * gshape[0] + gx) as usize;
                            let (lo, hi) = (grid.min[ci], grid.max[ci]);
                            if lo.is_nan() || hi.is_nan() {
                                continue;
                            }
                            for z in leaf_ranges[2][gz as usize].clone() {
                                for y in leaf_ranges[1][gy as usize].clone() {
                                    for x in leaf_ranges[0][gx as usize].clone() {
                                        let r =
                                            &mut self.ranges[node_index(d, [x, y, z]) * m + slot];
                                        r.0 = r.0.min(lo);
                                        r.1 = r.1.max(hi);
                                    }
                                }
                            }
                        }
                    }
                }
            }
        }
        Ok(())
    }

    /// Interior ranges as the union of their children's.
    fn propagate_ranges(&mut self) {
        let m = self.channels.len();
        for depth in (0..self.geometry.depth).rev() {
            let n = 1u64 << depth;
            for z in 0..n {
                for y in 0..n {
                    for x in 0..n {
                        let parent = node_index(depth, [x, y, z]);
                        for s in 0..m {
                            let mut r = (f64::INFINITY, f64::NEG_INFINITY);
                            for k in 0..8u64 {
                                let c =
                                    self.ranges[node_index(depth + 1, child([x, y, z], k)) * m + s];
                                r = (r.0.min(c.0), r.1.max(c.1));
                            }
                            self.ranges[parent * m + s] = r;
                        }
                    }
                }
            }
        }
    }

    /// `u32` words per node in the flat GPU layout (`3 ·` channels).
    pub fn words_per_node(&self) -> usize {
        WORDS_PER_CHANNEL * self.channels.len()
    }

    /// Flat GPU words of nodes `range`: per node, per channel slot, `[mask, min, max]` with
    /// min/max as `f32` bits rounded outward (a node with no data stores `+∞, −∞`).
    pub fn gpu_words(&self, range: Range<usize>) -> Vec<u32> {
        let m = self.channels.len();
        let mut out = Vec::with_capacity(range.len() * m * WORDS_PER_CHANNEL);
        for n in range {
            for s in 0..m {
                let (lo, hi) = self.ranges[n * m + s];
                out.push(self.masks[n * m + s] as u32);
                out.push(f32_down(lo).to_bits());
                out.push(f32_up(hi).to_bits());
            }
        }
        out
    }

    /// The node range changed since the last call (all nodes after construction), if any.
    pub fn take_dirty(&mut self) -> Option<Range<usize>> {
        self.dirty.take()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rounding_is_outward() {
        let v = 0.1f64;
        assert!((f32_down(v) as f64) <= v && (f32_up(v) as f64) >= v);
        assert_eq!(f32_down(3.0), 3.0);
        assert_eq!(f32_up(3.0), 3.0);
    }

    #[test]
    fn node_indices_are_dense() {
        assert_eq!(depth_offset(0), 0);
        assert_eq!(depth_offset(1), 1);
        assert_eq!(depth_offset(2), 9);
        assert_eq!(node_index(2, [3, 3, 3]), 9 + 63);
    }
}
