//! Where a volume comes from: its description (levels, bricks, channels, region metadata) and
//! its bricks, from a brick server over HTTP or from a local OME-Zarr store, behind one trait.
//!
//! - [`local`]: [`LocalSource`], a local OME-Zarr store read with zarrs (native);
//! - [`server`]: the `brickserver` protocol (URLs, metadata, batched bricks, framed min/max),
//!   with no I/O of its own;
//! - [`http`]: [`HttpSource`], that protocol over blocking HTTP (native; the web viewer
//!   speaks it through the browser's `fetch`);
//! - [`ome`]: the volume description both build from `residency_schemas`' format model.

use anyhow::Result;

#[cfg(not(target_arch = "wasm32"))]
pub mod http;
#[cfg(not(target_arch = "wasm32"))]
pub mod local;
pub mod ome;
pub mod server;

#[cfg(not(target_arch = "wasm32"))]
pub use http::{HttpSource, read_token_file};
#[cfg(not(target_arch = "wasm32"))]
pub use local::LocalSource;

pub use residency_schemas::SampleType;

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

/// Decoded voxels of a full brick (`brick_shape`, `z`-major; voxels past the volume's edge
/// hold the fill value).
#[derive(Clone, Debug, PartialEq)]
pub enum BrickVoxels {
    /// The brick equals the fill value (0) everywhere; nothing was transferred.
    Empty,
    /// Unsigned 8-bit samples.
    U8(Vec<u8>),
    /// Unsigned 16-bit samples.
    U16(Vec<u16>),
    /// Signed 16-bit samples.
    I16(Vec<i16>),
    /// Unsigned 32-bit samples.
    U32(Vec<u32>),
    /// Signed 32-bit samples.
    I32(Vec<i32>),
    /// 32-bit float samples.
    F32(Vec<f32>),
}

impl BrickVoxels {
    /// Voxel `index` (`z`-major within the brick) as `f64`; an [`BrickVoxels::Empty`] brick
    /// reads as the fill value 0.
    ///
    /// # Panics
    /// If `index` is outside a non-empty brick.
    pub fn value(&self, index: usize) -> f64 {
        match self {
            Self::Empty => 0.0,
            Self::U8(v) => v[index] as f64,
            Self::U16(v) => v[index] as f64,
            Self::I16(v) => v[index] as f64,
            Self::U32(v) => v[index] as f64,
            Self::I32(v) => v[index] as f64,
            Self::F32(v) => v[index] as f64,
        }
    }

    /// Number of samples held (0 for [`BrickVoxels::Empty`]).
    pub fn len(&self) -> usize {
        match self {
            Self::Empty => 0,
            Self::U8(v) => v.len(),
            Self::U16(v) => v.len(),
            Self::I16(v) => v.len(),
            Self::U32(v) => v.len(),
            Self::I32(v) => v.len(),
            Self::F32(v) => v.len(),
        }
    }

    /// Whether no samples are held (the brick is [`BrickVoxels::Empty`]).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
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
        let level = key.level as usize;
        let (lo, hi) = self.brick_box(key, level);
        self.region_range(key.channel as usize, level, lo, hi)
    }

    /// Conservative value range of a brick *and of every finer level* over its region (each
    /// level's haloed cells under the brick's box), so that a sample of any level inside the
    /// box lies in it. A brick-granular octree culls a whole subtree with it.
    pub fn subtree_range(&self, key: &BrickKey) -> (f64, f64) {
        (0..=key.level as usize).fold((f64::INFINITY, f64::NEG_INFINITY), |r, level| {
            let (lo, hi) = self.brick_box(key, level);
            let (a, b) = self.region_range(key.channel as usize, level, lo, hi);
            (r.0.min(a), r.1.max(b))
        })
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
    pub fn check_key(&self, key: &BrickKey) -> Result<()> {
        let level = key.level as usize;
        anyhow::ensure!(
            level < self.levels.len(),
            "{}: brick {key:?}: no level {level} ({} levels)",
            self.name,
            self.levels.len()
        );
        anyhow::ensure!(
            (key.channel as usize) < self.channels.len(),
            "{}: brick {key:?}: no channel {} ({} channels)",
            self.name,
            key.channel,
            self.channels.len()
        );
        let grid = self.brick_grid(level);
        anyhow::ensure!(
            key.brick.iter().zip(&grid).all(|(b, g)| b < g),
            "{}: brick {key:?}: outside the level's brick grid {grid:?}",
            self.name
        );
        Ok(())
    }
}

/// A source of volume metadata and bricks. Implementations are thread-safe; `fetch` blocks,
/// so callers run it on worker threads to overlap requests.
pub trait BrickSource: Send + Sync {
    /// The volume's description, loaded once.
    fn info(&self) -> &VolumeInfo;
    /// Fetches the given bricks, one result per key, in order. A brick that cannot be read
    /// gives an error naming it; the others are still returned.
    fn fetch(&self, keys: &[BrickKey]) -> Vec<Result<BrickVoxels>>;
}
