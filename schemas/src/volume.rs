//! A volume as a renderer sees it before fetching any brick ([`VolumeInfo`]): its levels,
//! brick shape, channels with their display hints, and the min/max grids of its region
//! metadata; which bricks exist ([`BrickKey`], [`VolumeInfo::check_key`]) and the conservative
//! value range of each ([`VolumeInfo::brick_range`]). [`VolumeInfo::from_ome`] makes one from
//! a store's OME-Zarr metadata, however it was fetched. No I/O.

use crate::SampleType;

mod from_ome;

/// A brick key the volume does not have, or a volume description whose documents disagree
/// (levels with each other, or with the region metadata). Messages name the volume, store or
/// document at fault.
#[derive(Debug, thiserror::Error)]
pub enum VolumeError {
    /// A brick key past the volume's levels.
    #[error("{volume}: brick {key:?}: no level {} ({levels} levels)", key.level)]
    NoLevel {
        /// The volume.
        volume: String,
        /// The brick asked for.
        key: BrickKey,
        /// Levels of the volume.
        levels: usize,
    },
    /// A brick key past the volume's channels.
    #[error("{volume}: brick {key:?}: no channel {} ({channels} channels)", key.channel)]
    NoChannel {
        /// The volume.
        volume: String,
        /// The brick asked for.
        key: BrickKey,
        /// Channels of the volume.
        channels: usize,
    },
    /// A brick key outside its level's brick grid.
    #[error("{volume}: brick {key:?}: outside the level's brick grid {grid:?}")]
    OutsideGrid {
        /// The volume.
        volume: String,
        /// The brick asked for.
        key: BrickKey,
        /// Bricks of the level, `z, y, x`.
        grid: [u64; 3],
    },
    /// A min/max grid with the wrong number of values for its shape.
    #[error("{store}: min/max grid {grid_shape:?} needs {needed} values, got {got}")]
    MinMaxValues {
        /// The store or document.
        store: String,
        /// Cells `z, y, x`.
        grid_shape: [u64; 3],
        /// Values needed (minima then maxima).
        needed: usize,
        /// Values given.
        got: usize,
    },
    /// Fewer or more level arrays than the multiscales' datasets.
    #[error("{store}: {arrays} level arrays for {datasets} datasets")]
    LevelCount {
        /// The store or server URL.
        store: String,
        /// Level arrays read.
        arrays: usize,
        /// Datasets of the multiscales.
        datasets: usize,
    },
    /// A level array whose rank is not the number of axes.
    #[error("{store}: level '{level}' has {dimensions} dimensions for {axes} axes")]
    LevelRank {
        /// The store or server URL.
        store: String,
        /// The level's path.
        level: String,
        /// Its dimensions.
        dimensions: usize,
        /// Axes of the multiscales.
        axes: usize,
    },
    /// Levels of different sample types.
    #[error("{store}: level '{level}' is {sample_type} but level '{first}' is {first_type}")]
    LevelType {
        /// The store or server URL.
        store: String,
        /// The level's path.
        level: String,
        /// Its sample type.
        sample_type: SampleType,
        /// The first level's path.
        first: String,
        /// The first level's sample type.
        first_type: SampleType,
    },
    /// Levels of different brick shapes.
    #[error(
        "{store}: level '{level}' has bricks {brick:?} but level '{first}' has {first_brick:?}"
    )]
    LevelBricks {
        /// The store or server URL.
        store: String,
        /// The level's path.
        level: Box<str>,
        /// Its brick shape, `z, y, x`.
        brick: [u64; 3],
        /// The first level's path.
        first: Box<str>,
        /// The first level's brick shape.
        first_brick: [u64; 3],
    },
    /// A level chunked across channels (or another leading axis).
    #[error(
        "{store}: level '{level}' has chunks of {chunk} along axis '{axis}'; one brick must \
         hold one channel"
    )]
    LeadingChunk {
        /// The store or server URL.
        store: String,
        /// The level's path.
        level: String,
        /// Its chunk edge along the axis.
        chunk: u64,
        /// The axis.
        axis: String,
    },
    /// A leading axis other than `c` with several entries.
    #[error("{store}: axis '{axis}' has {entries} entries; only one is supported")]
    LeadingAxis {
        /// The store or server URL.
        store: String,
        /// The axis.
        axis: String,
        /// Its entries.
        entries: u64,
    },
    /// Region metadata describing other bricks than the arrays have.
    #[error("{store}: region metadata bricks {regions:?} differ from the arrays' {arrays:?}")]
    RegionBricks {
        /// The store or server URL.
        store: String,
        /// The region metadata's brick shape.
        regions: [u64; 3],
        /// The arrays' brick shape.
        arrays: [u64; 3],
    },
    /// Region metadata of another number of levels than the image.
    #[error("{store}: region metadata has {regions} levels, the image {levels}")]
    RegionLevelCount {
        /// The store or server URL.
        store: String,
        /// Levels of the region metadata.
        regions: usize,
        /// Levels of the image.
        levels: usize,
    },
    /// A region-metadata level that is not the image's level.
    #[error(
        "{store}: region metadata level '{region_level}' {region_shape:?} does not match image \
         level '{level}' {shape:?}"
    )]
    RegionLevel {
        /// The store or server URL.
        store: String,
        /// The region metadata's level path.
        region_level: Box<str>,
        /// Its shape.
        region_shape: [u64; 3],
        /// The image's level path.
        level: Box<str>,
        /// Its shape.
        shape: [u64; 3],
    },
}

/// One pyramid level.
#[derive(Clone, Debug, PartialEq)]
pub struct LevelInfo {
    /// Voxels `z, y, x`.
    pub shape: [u64; 3],
    /// Downsampling factor relative to level 0, `z, y, x`.
    pub factor: [u64; 3],
}

/// Conservative (haloed) min/max grids of one channel at one level, finest first: grid `k`
/// has cells of `cell_shape · 2^k` voxels of the level. Values are `f64` copies of the stored
/// values; NaN marks a cell with no non-NaN voxel.
#[derive(Clone, Debug, PartialEq)]
pub struct MinMaxGrid {
    /// Edge of one cell in voxels of the level, `z, y, x`.
    pub cell_shape: [u64; 3],
    /// Cells `z, y, x`.
    pub grid_shape: [u64; 3],
    /// Minimum per cell, `z`-major.
    pub min: Vec<f64>,
    /// Maximum per cell, `z`-major.
    pub max: Vec<f64>,
}

/// Display hints of one channel, from the store's `omero` block and region-metadata
/// statistics; used for default colours and transfer functions.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ChannelDisplay {
    /// Linear RGB colour from `omero.channels[].color`, if given.
    pub color: Option<[f64; 3]>,
    /// Display window `[start, end]` from `omero.channels[].window`, if given.
    pub window: Option<[f64; 2]>,
    /// Level-0 value range `[min, max]` (region-metadata statistics, else the `omero` window's
    /// `min`/`max`), if known.
    pub range: Option<[f64; 2]>,
    /// Level-0 median (the 50th percentile of the region-metadata statistics), if known.
    pub median: Option<f64>,
}

/// Everything a renderer needs to know about a volume before fetching any brick.
#[derive(Clone, Debug, PartialEq)]
pub struct VolumeInfo {
    /// Dataset name.
    pub name: String,
    /// Stored sample format.
    pub sample_type: SampleType,
    /// Channel labels.
    pub channels: Vec<String>,
    /// Display hints, one per channel.
    pub display: Vec<ChannelDisplay>,
    /// Level-0 voxel spacing in physical units, `z, y, x`.
    pub voxel_size: [f64; 3],
    /// The physical unit of `voxel_size` (the store's `x` axis unit: `micrometer`, ...), when
    /// the store names one.
    pub unit: Option<String>,
    /// Brick shape shared by all levels and channels, `z, y, x`.
    pub brick_shape: [u64; 3],
    /// Levels, finest first.
    pub levels: Vec<LevelInfo>,
    /// `minmax[channel][level]`: the min/max grids, or `None` for a store without region
    /// metadata (a renderer then falls back to computing ranges from bricks, and says so).
    pub minmax: Option<Vec<Vec<Vec<MinMaxGrid>>>>,
}

/// One brick of one channel at one level.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct BrickKey {
    /// Pyramid level.
    pub level: u32,
    /// Channel.
    pub channel: u32,
    /// Brick coordinates `z, y, x` (in bricks).
    pub brick: [u64; 3],
}

impl VolumeInfo {
    /// Bricks along `z, y, x` at `level`.
    pub fn brick_grid(&self, level: usize) -> [u64; 3] {
        let s = self.levels[level].shape;
        std::array::from_fn(|i| s[i].div_ceil(self.brick_shape[i]))
    }

    /// Conservative value range `(min, max)` of a brick under trilinear sampling: the union of
    /// the finest (haloed) min/max cells of its level that overlap it, so every value a
    /// sample inside the brick can interpolate lies in it. `min > max`: the brick holds only
    /// NaN. Unbounded when the store has no region metadata for this channel and level.
    pub fn brick_range(&self, key: &BrickKey) -> (f64, f64) {
        self.widened_brick_range(key, 0)
    }

    /// [`VolumeInfo::brick_range`] over the brick's box widened by `widen` voxels of its
    /// level on every side (clipped to the level): with `widen` the filter's extra reach
    /// ([`crate::scene::Filter::reach`]), it bounds every sample of a wider filter inside the
    /// brick; with twice that, every sample whose footprint reaches the brick.
    pub fn widened_brick_range(&self, key: &BrickKey, widen: u64) -> (f64, f64) {
        let level = key.level as usize;
        let (lo, hi) = self.widened_box(key, level, widen);
        self.region_range(key.channel as usize, level, lo, hi)
    }

    fn widened_box(&self, key: &BrickKey, at: usize, widen: u64) -> ([u64; 3], [u64; 3]) {
        let (lo, hi) = self.brick_box(key, at);
        let shape = self.levels[at].shape;
        (
            lo.map(|v| v.saturating_sub(widen)),
            std::array::from_fn(|a| (hi[a] + widen).min(shape[a])),
        )
    }

    /// Conservative value range of a brick *and of every finer level* over its region (each
    /// level's haloed cells under the brick's box), so that a sample of any level inside the
    /// box lies in it. A brick-granular octree culls a whole subtree with it.
    pub fn subtree_range(&self, key: &BrickKey) -> (f64, f64) {
        self.widened_subtree_range(key, 0)
    }

    /// [`VolumeInfo::subtree_range`] with each level's box widened by `widen` voxels of that
    /// level (see [`VolumeInfo::widened_brick_range`]).
    pub fn widened_subtree_range(&self, key: &BrickKey, widen: u64) -> (f64, f64) {
        (0..=key.level as usize).fold((f64::INFINITY, f64::NEG_INFINITY), |r, level| {
            let (lo, hi) = self.widened_box(key, level, widen);
            let (a, b) = self.region_range(key.channel as usize, level, lo, hi);
            (r.0.min(a), r.1.max(b))
        })
    }

    /// Decoded bytes of one brick.
    pub fn brick_bytes(&self) -> u64 {
        self.sample_type.block_bytes(self.brick_shape)
    }

    /// The level-0 voxel size in the GPU's axis order, `x, y, z` (world units).
    pub fn spacing_xyz(&self) -> [f64; 3] {
        let [z, y, x] = self.voxel_size;
        [x, y, z]
    }

    /// Smallest edge of a voxel of `level`, in world units (the level the renderer's LOD rule
    /// compares with a pixel's footprint).
    pub fn voxel_edge(&self, level: usize) -> f64 {
        (0..3)
            .map(|a| self.levels[level].factor[a] as f64 * self.voxel_size[a])
            .fold(f64::INFINITY, f64::min)
    }

    /// The voxel box `[lo, hi)` (`z, y, x`) of a brick, in voxels of level `at` (finer or
    /// equal), clipped to that level.
    pub fn brick_box(&self, key: &BrickKey, at: usize) -> ([u64; 3], [u64; 3]) {
        let l = key.level as usize;
        let (f, g) = (self.levels[l].factor, self.levels[at].factor);
        let shape = self.levels[at].shape;
        let scale = |a: usize, v: u64| v * (f[a] / g[a].max(1)).max(1);
        let lo = std::array::from_fn(|a| scale(a, key.brick[a] * self.brick_shape[a]));
        let hi = std::array::from_fn(|a| {
            scale(a, (key.brick[a] + 1) * self.brick_shape[a]).min(shape[a])
        });
        (lo, hi)
    }

    /// Union of the finest min/max cells of `channel` at `level` overlapping the voxel box
    /// `[lo, hi)`; unbounded without region metadata (or with a malformed grid).
    fn region_range(&self, channel: usize, level: usize, lo: [u64; 3], hi: [u64; 3]) -> (f64, f64) {
        let grid = self
            .minmax
            .as_ref()
            .and_then(|m| m.get(channel))
            .and_then(|c| c.get(level))
            .and_then(|g| g.first());
        let Some(g) = grid else {
            return (f64::NEG_INFINITY, f64::INFINITY);
        };
        let cells: [std::ops::Range<u64>; 3] = std::array::from_fn(|a| {
            let c = g.cell_shape[a].max(1);
            (lo[a] / c).min(g.grid_shape[a])..hi[a].div_ceil(c).min(g.grid_shape[a])
        });
        let mut r = (f64::INFINITY, f64::NEG_INFINITY);
        for z in cells[0].clone() {
            for y in cells[1].clone() {
                for x in cells[2].clone() {
                    let i = ((z * g.grid_shape[1] + y) * g.grid_shape[2] + x) as usize;
                    let (Some(&lo), Some(&hi)) = (g.min.get(i), g.max.get(i)) else {
                        return (f64::NEG_INFINITY, f64::INFINITY); // malformed: no culling
                    };
                    if !(lo.is_nan() || hi.is_nan()) {
                        r = (r.0.min(lo), r.1.max(hi));
                    }
                }
            }
        }
        r
    }

    /// Checks that `key` names an existing brick, with an error naming it otherwise.
    ///
    /// # Errors
    /// [`VolumeError::NoLevel`], [`VolumeError::NoChannel`] or [`VolumeError::OutsideGrid`],
    /// naming the volume and the key.
    pub fn check_key(&self, key: &BrickKey) -> Result<(), VolumeError> {
        let level = key.level as usize;
        if level >= self.levels.len() {
            return Err(VolumeError::NoLevel {
                volume: self.name.clone(),
                key: *key,
                levels: self.levels.len(),
            });
        }
        if key.channel as usize >= self.channels.len() {
            return Err(VolumeError::NoChannel {
                volume: self.name.clone(),
                key: *key,
                channels: self.channels.len(),
            });
        }
        let grid = self.brick_grid(level);
        if !key.brick.iter().zip(&grid).all(|(b, g)| b < g) {
            return Err(VolumeError::OutsideGrid {
                volume: self.name.clone(),
                key: *key,
                grid,
            });
        }
        Ok(())
    }
}
