//! Region metadata computed during the pass: conservative min/max cell grids, per-brick
//! histograms and whole-channel statistics.
//!
//! **Min/max cells.** Cell `(k, j, i)` of a level covers voxels `[8k, 8k+8) × [8j, 8j+8) ×
//! [8i, 8i+8)`. Two ranges are kept per cell, gathered in the same pass:
//! - the *haloed* range, over those voxels plus a one-voxel halo on every side (clipped to the
//!   volume). A trilinear sample at any position inside the cell, whichever voxel-centre
//!   convention the renderer uses, interpolates only voxels within the halo, so the
//!   interpolated value lies within `[min, max]`: this is what culling needs;
//! - the *exact* range, over the cell's own voxels only: region queries answer from it, so a
//!   box aligned to the cells gets exactly the range of its voxels.
//!
//! **Histograms.** Each sample has a fine key (see [`Sample::key`]). Bricks count keys while
//! streaming; at the end of the pass, the keys spanned by the channel's global range are
//! grouped into at most [`HISTOGRAM_BINS`] equal runs, whose lower edges become the bin edges.
//! Counts are exact: every voxel falls in exactly one bin.

use std::sync::Mutex;

use residency_schemas::{HISTOGRAM_BINS, Percentile};

use crate::sample_format::{FINE_KEYS, Sample};

/// Edge of a min/max cell in voxels of its level.
pub const CELL: u64 = 8;
/// Halo, in voxels, added around every cell.
pub const HALO: u64 = 1;

/// The cells (along one axis of extent `cells`) whose haloed range contains voxel `v`.
#[inline]
fn cells_of(v: u64, cells: u64) -> std::ops::RangeInclusive<u64> {
    let lo = (v + 1).saturating_sub(CELL + HALO).div_ceil(CELL);
    let hi = ((v + HALO) / CELL).min(cells - 1);
    lo..=hi
}

/// Per-cell minima and maxima of every channel, `[c][gz][gy][gx]`.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(bound = "")]
pub struct Ranges<T: Sample> {
    /// Minimum per cell (`T::HIGHEST` where nothing was seen).
    pub min: Vec<T>,
    /// Maximum per cell (`T::LOWEST` where nothing was seen).
    pub max: Vec<T>,
}

impl<T: Sample> Ranges<T> {
    fn new(n: usize) -> Self {
        Self {
            min: vec![T::HIGHEST; n],
            max: vec![T::LOWEST; n],
        }
    }

    #[inline]
    fn fold(&mut self, i: usize, mn: T, mx: T) {
        if mn < self.min[i] {
            self.min[i] = mn;
        }
        if mx > self.max[i] {
            self.max[i] = mx;
        }
    }

    /// Folds cells `from` of another grid's ranges onto this grid's cells from `offset`.
    fn merge_at(&mut self, other: &Self, from: std::ops::Range<usize>, offset: usize) {
        for (i, (&mn, &mx)) in other.min[from.clone()]
            .iter()
            .zip(&other.max[from])
            .enumerate()
        {
            self.fold(offset + i, mn, mx);
        }
    }
}

/// The min/max grids of all channels of one level: haloed (for culling) and exact (for
/// region queries), over the same cells.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
#[serde(bound = "")]
pub struct CellGrid<T: Sample> {
    /// Number of cells held `z, y, x`: every cell of the level, or the rows a partition
    /// reaches.
    pub grid: [u64; 3],
    /// The level's cell row held first (0 for a whole level).
    pub z0: u64,
    /// Cell rows of the whole level.
    pub depth: u64,
    /// Channels.
    pub channels: usize,
    /// Ranges over each cell plus its halo.
    pub haloed: Ranges<T>,
    /// Ranges over each cell's own voxels.
    pub exact: Ranges<T>,
}

impl<T: Sample> CellGrid<T> {
    /// Folds in the ranges another pass over other voxels of the same level found (a
    /// partition's rows, see [`CellGrid::for_rows`]), so this whole-level grid is what one
    /// pass over both would have found.
    ///
    /// # Panics
    /// When this grid is not a whole level, or the rows do not fit it.
    pub fn merge_rows(&mut self, rows: &Self) {
        let [gz, gy, gx] = self.grid;
        let z0 = rows.z0;
        assert!(
            self.z0 == 0
                && rows.channels == self.channels
                && rows.grid[1..] == self.grid[1..]
                && z0 + rows.grid[0] <= gz
        );
        let plane = (gy * gx) as usize;
        let n = rows.grid[0] as usize * plane;
        for c in 0..self.channels {
            let at = (c as u64 * gz + z0) as usize * plane;
            self.haloed.merge_at(&rows.haloed, c * n..(c + 1) * n, at);
            self.exact.merge_at(&rows.exact, c * n..(c + 1) * n, at);
        }
    }

    /// An empty grid of `grid` cells per channel.
    pub fn new(channels: usize, grid: [u64; 3]) -> Self {
        let n = channels * (grid[0] * grid[1] * grid[2]) as usize;
        Self {
            grid,
            z0: 0,
            depth: grid[0],
            channels,
            haloed: Ranges::new(n),
            exact: Ranges::new(n),
        }
    }

    /// The cell rows covering voxel planes `planes` of a level of `shape`, with the rows their
    /// halos reach (one up, one down): what a partition's planes can touch.
    pub fn for_rows(channels: usize, shape: [u64; 3], planes: std::ops::Range<u64>) -> Self {
        let full = shape.map(|s| s.div_ceil(CELL));
        let z1 = (planes.end.div_ceil(CELL) + 1).min(full[0]);
        let z0 = (planes.start / CELL).saturating_sub(1).min(z1);
        let mut grid = Self::new(channels, [z1 - z0, full[1], full[2]]);
        grid.z0 = z0;
        grid.depth = full[0];
        grid
    }

    /// The grid of cells covering a level of `shape`.
    pub fn for_shape(channels: usize, shape: [u64; 3]) -> Self {
        Self::new(channels, shape.map(|s| s.div_ceil(CELL)))
    }

    fn index(&self, c: usize, z: u64, y: u64, x: u64) -> usize {
        let [_, gy, gx] = self.grid;
        ((c as u64 * self.grid[0] + z) * gy * gx + y * gx + x) as usize
    }

    /// Folds one slab of voxels (`[c][nz][Y][X]`, starting at depth `z0` of a level of
    /// `shape`) into the cells. Slabs may arrive in any order.
    pub fn add_slab(&mut self, slab: &[T], z0: u64, nz: u64, shape: [u64; 3]) {
        use rayon::prelude::*;
        let [_, ny, nx] = shape;
        let plane = (ny * nx) as usize;
        let [_, gy, gx] = self.grid;
        let slices: Vec<(usize, u64, SliceCells<T>)> = (0..self.channels)
            .flat_map(|c| (0..nz).map(move |dz| (c, dz)))
            .collect::<Vec<_>>()
            .into_par_iter()
            .map(|(c, dz)| {
                let start = (c as u64 * nz + dz) as usize * plane;
                let cells = slice_cells(&slab[start..start + plane], ny, nx, gy, gx);
                (c, z0 + dz, cells)
            })
            .collect();
        for (c, z, cells) in slices {
            let held = self.z0..self.z0 + self.grid[0];
            for cz in cells_of(z, self.depth).filter(|cz| held.contains(cz)) {
                let base = self.index(c, cz - self.z0, 0, 0);
                for i in 0..cells.haloed.min.len() {
                    self.haloed
                        .fold(base + i, cells.haloed.min[i], cells.haloed.max[i]);
                }
            }
            let base = self.index(c, z / CELL - self.z0, 0, 0);
            for i in 0..cells.exact.min.len() {
                self.exact
                    .fold(base + i, cells.exact.min[i], cells.exact.max[i]);
            }
        }
    }

    /// The next coarser grid: each cell is the min of mins and max of maxes of 2×2×2 cells.
    pub fn coarsen(&self) -> Self {
        let g = self.grid.map(|s| s.div_ceil(2));
        let mut out = Self::new(self.channels, g);
        for c in 0..self.channels {
            for z in 0..self.grid[0] {
                for y in 0..self.grid[1] {
                    for x in 0..self.grid[2] {
                        let i = self.index(c, z, y, x);
                        let o = out.index(c, z / 2, y / 2, x / 2);
                        out.haloed.fold(o, self.haloed.min[i], self.haloed.max[i]);
                        out.exact.fold(o, self.exact.min[i], self.exact.max[i]);
                    }
                }
            }
        }
        out
    }

    /// The haloed (`exact == false`) or exact ranges as `[c][2][gz][gy][gx]`, with cells that
    /// saw no value (all NaN) as NaN.
    pub fn to_min_max_array(&self, exact: bool) -> Vec<T> {
        let ranges = if exact { &self.exact } else { &self.haloed };
        let n = (self.grid[0] * self.grid[1] * self.grid[2]) as usize;
        let nan = T::from_f64(f64::NAN);
        let mut out = Vec::with_capacity(2 * ranges.min.len());
        for c in 0..self.channels {
            let (mn, mx) = (
                &ranges.min[c * n..(c + 1) * n],
                &ranges.max[c * n..(c + 1) * n],
            );
            let empty = |i: usize| mn[i] > mx[i];
            out.extend((0..n).map(|i| if empty(i) { nan } else { mn[i] }));
            out.extend((0..n).map(|i| if empty(i) { nan } else { mx[i] }));
        }
        out
    }
}

/// The cells of one slice: haloed ranges (x and y halo; z is the caller's) and exact ranges.
struct SliceCells<T: Sample> {
    haloed: Ranges<T>,
    exact: Ranges<T>,
}

/// Min/max cells of one `ny × nx` slice, as `gy × gx` row-major grids: haloed in x and y,
/// and exact.
fn slice_cells<T: Sample>(slice: &[T], ny: u64, nx: u64, gy: u64, gx: u64) -> SliceCells<T> {
    let mut row = Ranges::<T>::new(gx as usize);
    let mut out = SliceCells {
        haloed: Ranges::new((gy * gx) as usize),
        exact: Ranges::new((gy * gx) as usize),
    };
    for y in 0..ny {
        row.min.fill(T::HIGHEST);
        row.max.fill(T::LOWEST);
        let values = &slice[(y * nx) as usize..((y + 1) * nx) as usize];
        for (cx, cell) in values.chunks(CELL as usize).enumerate() {
            let (mut mn, mut mx) = (row.min[cx], row.max[cx]);
            for &v in cell {
                if v < mn {
                    mn = v;
                }
                if v > mx {
                    mx = v;
                }
            }
            row.min[cx] = mn;
            row.max[cx] = mx;
        }
        let base = ((y / CELL) * gx) as usize;
        for i in 0..gx as usize {
            out.exact.fold(base + i, row.min[i], row.max[i]);
        }
        // Halo in x: the voxel just left of and just right of each cell.
        for cx in 0..gx {
            for x in [(cx * CELL).wrapping_sub(1), (cx + 1) * CELL] {
                if x < nx {
                    let v = values[x as usize];
                    row.fold(cx as usize, v, v);
                }
            }
        }
        for cy in cells_of(y, gy) {
            let base = (cy * gx) as usize;
            for i in 0..gx as usize {
                out.haloed.fold(base + i, row.min[i], row.max[i]);
            }
        }
    }
    out
}

/// Fine-key counts of one brick and channel, stored from the first to the last non-zero key.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FineHistogram {
    /// Key of `counts[0]`.
    pub first_key: u32,
    /// Counts of keys `first_key..first_key + counts.len()`.
    pub counts: Vec<u32>,
}

impl FineHistogram {
    fn from_keys(keys: &mut [u32; FINE_KEYS]) -> Self {
        let Some(first) = keys.iter().position(|&c| c > 0) else {
            return Self::default();
        };
        let last = keys.iter().rposition(|&c| c > 0).expect("non-empty");
        let out = Self {
            first_key: first as u32,
            counts: keys[first..=last].to_vec(),
        };
        keys[first..=last].fill(0);
        out
    }
}

/// Reusable per-thread counting tables for [`BrickStats::of_rows`].
pub struct StatsScratch {
    keys: Box<[u32; FINE_KEYS]>,
    exact: Vec<u32>,
}

impl Default for StatsScratch {
    fn default() -> Self {
        Self {
            keys: Box::new([0; FINE_KEYS]),
            exact: vec![0; 1 << 16],
        }
    }
}

/// Everything ingest records about one brick of one channel, gathered in one pass.
#[derive(Clone, Debug, Default)]
pub struct BrickStats {
    /// Fine-key counts (NaN excluded).
    pub fine: FineHistogram,
    /// Exact value counts `(first index, counts)` for formats of at most 16 bits.
    pub exact: Option<(usize, Vec<u32>)>,
    /// Sum of non-NaN values.
    pub sum: f64,
    /// Non-NaN voxels.
    pub count: u64,
    /// NaN voxels.
    pub nan: u64,
    /// Smallest non-NaN value.
    pub min: f64,
    /// Largest non-NaN value.
    pub max: f64,
    /// Whether every voxel is bit-for-bit the fill value.
    pub all_fill: bool,
}

impl BrickStats {
    /// Statistics of the voxels in `rows` (any number of row slices).
    pub fn of_rows<'a, T: Sample>(
        rows: impl Iterator<Item = &'a [T]>,
        scratch: &mut StatsScratch,
        keep_exact: bool,
    ) -> Self {
        let (mut mn, mut mx) = (T::HIGHEST, T::LOWEST);
        if T::HIGHEST.exact_index().is_some() {
            // Count exact values only; everything else follows from the counts.
            let exact = &mut scratch.exact;
            let mut total = 0u64;
            for row in rows {
                total += row.len() as u64;
                for &v in row {
                    exact[v.exact_index().unwrap_or(0)] += 1;
                    if v < mn {
                        mn = v;
                    }
                    if v > mx {
                        mx = v;
                    }
                }
            }
            if total == 0 {
                return Self {
                    all_fill: true,
                    ..Self::default()
                };
            }
            let (lo, hi) = (mn.exact_index().unwrap_or(0), mx.exact_index().unwrap_or(0));
            let mut sum = 0f64;
            for (i, &n) in exact.iter().enumerate().take(hi + 1).skip(lo) {
                if n > 0 {
                    scratch.keys[T::from_f64(T::exact_value(i)).key()] += n;
                    sum += T::exact_value(i) * n as f64;
                }
            }
            let zero = T::default().exact_index().unwrap_or(0);
            let all_fill = exact[zero] as u64 == total;
            let exact_counts = keep_exact.then(|| (lo, exact[lo..=hi].to_vec()));
            exact[lo..=hi].fill(0);
            Self {
                fine: FineHistogram::from_keys(&mut scratch.keys),
                exact: exact_counts,
                sum,
                count: total,
                nan: 0,
                min: mn.to_f64(),
                max: mx.to_f64(),
                all_fill,
            }
        } else {
            let (mut sum, mut count, mut nan, mut fill) = (T::Sum::default(), 0u64, 0u64, 0u64);
            for row in rows {
                for &v in row {
                    fill += v.is_fill() as u64;
                    if v.counts() {
                        scratch.keys[v.key()] += 1;
                        sum += v.to_sum();
                        count += 1;
                        if v < mn {
                            mn = v;
                        }
                        if v > mx {
                            mx = v;
                        }
                    } else {
                        nan += 1;
                    }
                }
            }
            Self {
                fine: FineHistogram::from_keys(&mut scratch.keys),
                exact: None,
                sum: T::sum_to_f64(sum),
                count,
                nan,
                min: if count > 0 {
                    mn.to_f64()
                } else {
                    f64::INFINITY
                },
                max: if count > 0 {
                    mx.to_f64()
                } else {
                    f64::NEG_INFINITY
                },
                all_fill: fill == count + nan,
            }
        }
    }
}

/// How a channel's fine keys group into histogram bins.
#[derive(Clone, Debug, PartialEq)]
pub struct Binning {
    /// First key of bin 0.
    pub first_key: usize,
    /// Keys per bin.
    pub keys_per_bin: usize,
    /// Number of bins in use (at most [`HISTOGRAM_BINS`]).
    pub bins: usize,
}

impl Binning {
    /// The binning spanning keys `kmin..=kmax`.
    pub fn spanning(kmin: usize, kmax: usize) -> Self {
        let span = kmax - kmin + 1;
        let keys_per_bin = span.div_ceil(HISTOGRAM_BINS);
        Self {
            first_key: kmin,
            keys_per_bin,
            bins: span.div_ceil(keys_per_bin),
        }
    }

    /// Bin edges as values of `T` (`bins + 1` ascending values).
    pub fn edges<T: Sample>(&self) -> Vec<f64> {
        (0..=self.bins)
            .map(|b| T::key_lower_edge(self.first_key + b * self.keys_per_bin))
            .collect()
    }

    /// Adds a fine histogram into `HISTOGRAM_BINS` bins.
    pub fn bin_into(&self, fine: &FineHistogram, out: &mut [u32]) {
        for (i, &n) in fine.counts.iter().enumerate() {
            if n > 0 {
                let key = fine.first_key as usize + i;
                out[(key - self.first_key) / self.keys_per_bin] += n;
            }
        }
    }
}

/// Whole-channel statistics accumulated over level 0.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct ChannelAccumulator {
    /// Sum of non-NaN values.
    pub sum: f64,
    /// Number of non-NaN values.
    pub count: u64,
    /// Number of NaN values.
    pub nan: u64,
    /// Smallest value.
    pub min: f64,
    /// Largest value.
    pub max: f64,
    /// Fine-key counts of every voxel.
    pub keys: Vec<u64>,
    /// Exact value counts, for formats of at most 16 bits (empty otherwise).
    pub exact: Vec<u64>,
}

impl Default for ChannelAccumulator {
    fn default() -> Self {
        Self {
            sum: 0.0,
            count: 0,
            nan: 0,
            min: f64::INFINITY,
            max: f64::NEG_INFINITY,
            keys: vec![0; FINE_KEYS],
            exact: Vec::new(),
        }
    }
}

impl ChannelAccumulator {
    /// Adds the statistics of another pass over other voxels of the channel (a partition's).
    pub fn merge(&mut self, other: &Self) {
        self.sum += other.sum;
        self.count += other.count;
        self.nan += other.nan;
        self.min = self.min.min(other.min);
        self.max = self.max.max(other.max);
        for (k, n) in self.keys.iter_mut().zip(&other.keys) {
            *k += n;
        }
        if !other.exact.is_empty() {
            self.exact.resize(1 << 16, 0);
            for (k, n) in self.exact.iter_mut().zip(&other.exact) {
                *k += n;
            }
        }
    }

    /// Adds a brick's statistics.
    pub fn add(&mut self, brick: &BrickStats) {
        self.sum += brick.sum;
        self.count += brick.count;
        self.nan += brick.nan;
        self.min = self.min.min(brick.min);
        self.max = self.max.max(brick.max);
        for (i, &n) in brick.fine.counts.iter().enumerate() {
            self.keys[brick.fine.first_key as usize + i] += n as u64;
        }
        if let Some((first, counts)) = &brick.exact {
            self.exact.resize(1 << 16, 0);
            for (i, &n) in counts.iter().enumerate() {
                self.exact[first + i] += n as u64;
            }
        }
    }

    /// Percentiles: for data of at most 16 bits, the smallest value with at least that
    /// fraction of voxels at or below it (exact); for 32-bit data, interpolated linearly
    /// inside the fine key that holds it and clamped to `[min, max]`.
    pub fn percentiles<T: Sample>(&self, percents: &[f64]) -> Vec<Percentile> {
        if self.count == 0 {
            return Vec::new();
        }
        if !self.exact.is_empty() {
            return percents
                .iter()
                .map(|&percent| {
                    let target = (percent / 100.0 * self.count as f64).max(1.0);
                    let mut below = 0u64;
                    let mut value = self.max;
                    for (i, &n) in self.exact.iter().enumerate() {
                        below += n;
                        if below as f64 >= target {
                            value = T::exact_value(i);
                            break;
                        }
                    }
                    Percentile { percent, value }
                })
                .collect();
        }
        percents
            .iter()
            .map(|&percent| {
                let target = percent / 100.0 * self.count as f64;
                let mut below = 0u64;
                let mut value = self.max;
                for (k, &n) in self.keys.iter().enumerate() {
                    if n > 0 && (below + n) as f64 >= target {
                        let lo = T::key_lower_edge(k).max(self.min);
                        let hi = T::key_lower_edge(k + 1).min(self.max);
                        let frac = ((target - below as f64) / n as f64).clamp(0.0, 1.0);
                        value = if lo.is_infinite() {
                            // The key of -inf or +inf holds that infinity alone.
                            lo
                        } else if T::FORMAT.is_float() {
                            // The key just below +inf ends at the largest finite f32.
                            let hi = if hi.is_infinite() {
                                f32::MAX as f64
                            } else {
                                hi
                            };
                            lo + (hi - lo) * frac
                        } else {
                            (lo + (hi - lo) * frac).round()
                        };
                        break;
                    }
                    below += n;
                }
                Percentile {
                    percent,
                    value: value.clamp(self.min, self.max),
                }
            })
            .collect()
    }

    /// The binning for this channel's range.
    pub fn binning<T: Sample>(&self) -> Binning {
        if self.count == 0 {
            return Binning::spanning(0, 0);
        }
        Binning::spanning(T::from_f64(self.min).key(), T::from_f64(self.max).key())
    }
}

/// Fine histograms of every brick of one level, filled concurrently.
#[derive(Debug)]
pub struct LevelHistograms {
    /// Bricks held per channel `z, y, x`: every brick of the level, or the brick rows a
    /// partition writes.
    pub bricks: [u64; 3],
    /// The level's brick row held first (0 for a whole level).
    pub z0: u64,
    /// `[c][bz][by][bx]` fine histograms.
    pub fine: Mutex<Vec<FineHistogram>>,
}

impl LevelHistograms {
    /// Room for `channels` channels of `bricks` bricks.
    pub fn new(channels: usize, bricks: [u64; 3]) -> Self {
        let n = channels * (bricks[0] * bricks[1] * bricks[2]) as usize;
        Self {
            bricks,
            z0: 0,
            fine: Mutex::new(vec![FineHistogram::default(); n]),
        }
    }

    /// Room for brick rows `rows` of `channels` channels of a level of `bricks` bricks.
    pub fn for_rows(channels: usize, bricks: [u64; 3], rows: std::ops::Range<u64>) -> Self {
        let z1 = rows.end.min(bricks[0]);
        let z0 = rows.start.min(z1);
        let mut held = Self::new(channels, [z1 - z0, bricks[1], bricks[2]]);
        held.z0 = z0;
        held
    }

    /// Takes the histograms of the bricks another pass wrote (a partition's rows from `z0`,
    /// `[c][z][y][x]`, see [`LevelHistograms::for_rows`]: every brick whose histogram it holds
    /// is one this pass did not see) into this whole level.
    ///
    /// # Panics
    /// When this is not a whole level, or the rows do not fit it.
    pub fn merge_rows(&self, z0: u64, rows: Vec<FineHistogram>) {
        assert_eq!(self.z0, 0);
        let [bz, by, bx] = self.bricks;
        let plane = (by * bx) as usize;
        let mut fine = self.fine.lock().expect("histograms");
        let channels = fine.len() / (bz as usize * plane).max(1);
        let depth = rows.len() / (channels * plane).max(1);
        assert!(rows.len() == channels * depth * plane && z0 as usize + depth <= bz as usize);
        for (i, theirs) in rows.into_iter().enumerate() {
            let (c, rest) = (i / (depth * plane), i % (depth * plane));
            let at = (c * bz as usize + z0 as usize) * plane + rest;
            if !theirs.counts.is_empty() {
                fine[at] = theirs;
            }
        }
    }

    /// Linear index of a brick (level coordinates; its row must be held).
    pub fn index(&self, c: usize, b: [u64; 3]) -> usize {
        let [bz, by, bx] = self.bricks;
        ((c as u64 * bz + b[0] - self.z0) * by * bx + b[1] * bx + b[2]) as usize
    }

    /// The binned histograms `[c][bz][by][bx][HISTOGRAM_BINS]`.
    pub fn binned(&self, binnings: &[Binning]) -> Vec<u32> {
        let fine = self.fine.lock().expect("histograms");
        let per_channel = fine.len() / binnings.len().max(1);
        let mut out = vec![0u32; fine.len() * HISTOGRAM_BINS];
        for (i, f) in fine.iter().enumerate() {
            binnings[i / per_channel]
                .bin_into(f, &mut out[i * HISTOGRAM_BINS..(i + 1) * HISTOGRAM_BINS]);
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A partition's rows of cells see what the whole grid sees there, and merge back into it.
    #[test]
    fn row_windows_see_and_merge_what_the_whole_grid_sees() {
        let shape = [40, 8, 8];
        let values: Vec<u16> = (0..40 * 64).map(|i| (i * 7 % 1000) as u16).collect();
        let mut whole = CellGrid::<u16>::for_shape(1, shape);
        whole.add_slab(&values, 0, 40, shape);
        let mut merged = CellGrid::<u16>::for_shape(1, shape);
        for planes in [0..16, 16..24, 24..40] {
            let mut part = CellGrid::<u16>::for_rows(1, shape, planes.clone());
            let slab = &values[(planes.start * 64) as usize..(planes.end * 64) as usize];
            part.add_slab(slab, planes.start, planes.end - planes.start, shape);
            merged.merge_rows(&part);
        }
        let rows = CellGrid::<u16>::for_rows(1, shape, 16..24);
        assert_eq!((rows.z0, rows.grid, rows.depth), (1, [3, 1, 1], 5));
        assert_eq!(merged.haloed, whole.haloed);
        assert_eq!(merged.exact, whole.exact);
        let histograms = LevelHistograms::for_rows(2, [5, 2, 2], 3..9);
        assert_eq!((histograms.z0, histograms.bricks), (3, [2, 2, 2]));
        assert_eq!(histograms.index(1, [4, 1, 0]), 14);
    }

    #[test]
    fn haloed_cells_include_neighbours() {
        assert_eq!(cells_of(0, 4), 0..=0);
        assert_eq!(cells_of(7, 4), 0..=1);
        assert_eq!(cells_of(8, 4), 0..=1);
        assert_eq!(cells_of(9, 4), 1..=1);
        assert_eq!(cells_of(31, 4), 3..=3);
    }

    #[test]
    fn cell_ranges_cover_the_halo() {
        // 1 × 1 × 20 volume: value = x.
        let slab: Vec<u16> = (0..20).collect();
        let mut g = CellGrid::<u16>::for_shape(1, [1, 1, 20]);
        g.add_slab(&slab, 0, 1, [1, 1, 20]);
        assert_eq!(g.grid, [1, 1, 3]);
        assert_eq!(g.haloed.min, [0, 7, 15]);
        assert_eq!(g.haloed.max, [8, 16, 19]);
        assert_eq!(g.exact.min, [0, 8, 16]);
        assert_eq!(g.exact.max, [7, 15, 19]);
        let c = g.coarsen();
        assert_eq!(
            (c.haloed.min.clone(), c.haloed.max.clone()),
            (vec![0, 15], vec![16, 19])
        );
        assert_eq!(
            (c.exact.min.clone(), c.exact.max.clone()),
            (vec![0, 16], vec![15, 19])
        );
    }

    #[test]
    fn percentiles_reaching_infinities_are_those_infinities() {
        let vals = [
            f32::NEG_INFINITY,
            -1.0,
            0.5,
            2.0,
            f32::INFINITY,
            f32::INFINITY,
            f32::NAN,
            3.3e38,
        ];
        let mut scratch = StatsScratch::default();
        let brick = BrickStats::of_rows([&vals[..]].into_iter(), &mut scratch, false);
        assert_eq!((brick.count, brick.nan), (7, 1));
        assert_eq!((brick.min, brick.max), (f64::NEG_INFINITY, f64::INFINITY));
        assert!(brick.sum.is_nan(), "+inf with -inf sums to NaN");
        let mut acc = ChannelAccumulator::default();
        acc.add(&brick);
        let p = acc.percentiles::<f32>(&[0.1, 50.0, 70.0, 99.9]);
        assert_eq!(p[0].value, f64::NEG_INFINITY);
        // The median (2.0) lies in its fine key; the 70th percentile (3.3e38) in the key just
        // below +inf, which ends at the largest finite f32.
        let key_of = |v: f64| (v as f32).key();
        assert_eq!(key_of(p[1].value), 2.0f32.key(), "{:?}", p[1]);
        assert_eq!(key_of(p[2].value), 3.3e38f32.key(), "{:?}", p[2]);
        assert!(p[2].value <= f32::MAX as f64, "{:?}", p[2]);
        assert_eq!(p[3].value, f64::INFINITY);
        // Only +inf: the mean is +inf.
        let pos = [1.0f32, f32::INFINITY];
        let b = BrickStats::of_rows([&pos[..]].into_iter(), &mut scratch, false);
        assert_eq!(b.sum / b.count as f64, f64::INFINITY);
    }

    #[test]
    fn binning_is_exact_and_edges_bound_values() {
        let vals: Vec<u16> = vec![100, 101, 4000, 65535, 37];
        let mut scratch = StatsScratch::default();
        let brick = BrickStats::of_rows([vals.as_slice()].into_iter(), &mut scratch, true);
        assert_eq!(
            (brick.min, brick.max, brick.count, brick.sum),
            (37.0, 65535.0, 5, 69773.0)
        );
        assert!(!brick.all_fill);
        let fine = brick.fine.clone();
        let mut acc = ChannelAccumulator::default();
        acc.add(&brick);
        assert_eq!(acc.percentiles::<u16>(&[50.0])[0].value, 101.0);
        let b = acc.binning::<u16>();
        let edges = b.edges::<u16>();
        let mut bins = vec![0u32; HISTOGRAM_BINS];
        b.bin_into(&fine, &mut bins);
        let floats = [1.5f32, f32::NAN, -2.0, 0.0];
        let f = BrickStats::of_rows([&floats[..]].into_iter(), &mut scratch, true);
        assert_eq!(
            (f.count, f.nan, f.min, f.max, f.sum),
            (3, 1, -2.0, 1.5, -0.5)
        );
        assert_eq!(f.fine.counts.iter().sum::<u32>(), 3);
        assert!(!f.all_fill);
        let zeros = [0.0f32; 4];
        assert!(BrickStats::of_rows([&zeros[..]].into_iter(), &mut scratch, false).all_fill);
        assert_eq!(bins.iter().sum::<u32>(), 5);
        for v in vals {
            let bin = (v.key() - b.first_key) / b.keys_per_bin;
            assert!(edges[bin] <= v as f64 && (v as f64) < edges[bin + 1]);
        }
    }
}
