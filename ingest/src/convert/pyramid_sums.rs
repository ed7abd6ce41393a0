//! The exact-sum downsampling: each level ≥ 1 accumulates exact sums and non-NaN counts of
//! the level-0 voxels under each of its voxels ([`Accumulator`]), from the slabs of the level
//! below ([`SlabRows`]), and its means are rounded once from them.

use rayon::prelude::*;

use crate::pyramid::LevelPlan;
use crate::sample_format::Sample;
use crate::source::PlaneRegion;

/// A level's accumulator: exact sums of level-0 voxels and their non-NaN counts,
/// `[c][depth][y][x]`, for the level's planes `z0..z0 + depth` over `window` of each.
pub(crate) struct Accumulator<T: Sample> {
    /// First plane held.
    pub(crate) z0: u64,
    /// Planes per channel.
    pub(crate) depth: u64,
    /// The part of each plane held (the whole plane, or a column).
    pub(crate) window: PlaneRegion,
    /// Exact sums.
    pub(crate) sum: Vec<T::Sum>,
    /// Non-NaN level-0 voxel counts matching `sum`.
    pub(crate) count: Vec<u32>,
}

impl<T: Sample> Accumulator<T> {
    /// An accumulator that holds nothing (level 0's, or one taken out for a while).
    pub(crate) fn empty() -> Self {
        Self::new(0, 0, 0, PlaneRegion::whole([0, 0]))
    }

    /// Zeroed sums for `depth` planes from `z0` of `channels` channels over `window` (freshly
    /// allocated zeroed memory, which the allocator gets zeroed from the kernel).
    pub(crate) fn new(channels: usize, z0: u64, depth: u64, window: PlaneRegion) -> Self {
        let len = channels * (depth * window.area()) as usize;
        Self {
            z0,
            depth,
            window,
            sum: vec![T::Sum::default(); len],
            count: vec![0; len],
        }
    }

    /// Makes this accumulator hold what [`Accumulator::new`] would, in the memory it already
    /// holds (a column's accumulator is the previous column's, not a fresh allocation).
    pub(crate) fn restart(&mut self, channels: usize, z0: u64, depth: u64, window: PlaneRegion) {
        let len = channels * (depth * window.area()) as usize;
        self.sum.clear();
        self.sum.resize(len, T::Sum::default());
        self.count.clear();
        self.count.resize(len, 0);
        (self.z0, self.depth, self.window) = (z0, depth, window);
    }
}

/// A slab of one level, as the next level's accumulator reads it: rows of `x` values.
pub(crate) trait SlabRows<T: Sample>: Sync {
    /// Adds the source row starting at `base` (length `sx`) into `sum`/`count`, summing
    /// `step_x` (1 or 2) neighbours per destination voxel.
    fn add_row(&self, base: usize, sx: usize, step_x: u64, sum: &mut [T::Sum], count: &mut [u32]);
}

/// Level-0 voxel values, `[c][nz][y][x]`.
pub(crate) struct Values<'a, T>(pub(crate) &'a [T]);

impl<T: Sample> SlabRows<T> for Values<'_, T> {
    fn add_row(&self, base: usize, sx: usize, step_x: u64, sum: &mut [T::Sum], count: &mut [u32]) {
        let row = &self.0[base..base + sx];
        if step_x == 1 {
            for ((s, n), &v) in sum.iter_mut().zip(count.iter_mut()).zip(row) {
                *s += v.to_sum();
                *n += v.counts() as u32;
            }
        } else {
            let pairs = row.chunks_exact(2);
            let tail = pairs.remainder();
            for ((s, n), p) in sum.iter_mut().zip(count.iter_mut()).zip(pairs) {
                *s += p[0].to_sum();
                *s += p[1].to_sum();
                *n += p[0].counts() as u32 + p[1].counts() as u32;
            }
            if let [v] = tail {
                let last = sx / 2;
                sum[last] += v.to_sum();
                count[last] += v.counts() as u32;
            }
        }
    }
}

/// Exact sums and counts of a level ≥ 1 accumulator, laid out `[c][oz][y][x]` while the
/// slab holds `nz ≤ oz` planes.
pub(crate) struct Sums<'a, T: Sample> {
    pub(crate) sum: &'a [T::Sum],
    pub(crate) count: &'a [u32],
    pub(crate) nz_plane: usize,
    pub(crate) oz_plane: usize,
}

impl<T: Sample> SlabRows<T> for Sums<'_, T> {
    fn add_row(&self, base: usize, sx: usize, step_x: u64, sum: &mut [T::Sum], count: &mut [u32]) {
        let j = base / self.nz_plane * self.oz_plane + base % self.nz_plane;
        let (src_sum, src_count) = (&self.sum[j..j + sx], &self.count[j..j + sx]);
        if step_x == 1 {
            for (d, &v) in sum.iter_mut().zip(src_sum) {
                *d += v;
            }
            for (d, &v) in count.iter_mut().zip(src_count) {
                *d += v;
            }
        } else {
            for (x, (&v, &n)) in src_sum.iter().zip(src_count).enumerate() {
                sum[x / 2] += v;
                count[x / 2] += n;
            }
        }
    }
}

/// Adds a slab of one level into the accumulator of the next level.
/// `src_z0..src_z0 + nz` is the slab's z range in the source level's coordinates, and
/// `window` the part of each plane it holds (its edges on voxel edges of the next level).
pub(crate) fn accumulate<T: Sample>(
    plan: &LevelPlan,
    next: &mut Accumulator<T>,
    channels: usize,
    window: PlaneRegion,
    src_z0: u64,
    nz: u64,
    src: &impl SlabRows<T>,
) {
    let step = plan.step;
    let dst = next.window;
    let oz = next.depth;
    let a0 = next.z0;
    let src_plane = window.area() as usize;
    let [src_y1, _] = window.end();
    // The first column of the destination this window sums into.
    let offset = (window.x0 / step[2] - dst.x0) as usize;
    next.sum
        .par_chunks_mut(dst.nx as usize)
        .zip(next.count.par_chunks_mut(dst.nx as usize))
        .enumerate()
        .for_each(|(row, (sum, count))| {
            let row = row as u64;
            let y = dst.y0 + row % dst.ny;
            let zi = (row / dst.ny) % oz;
            let c = (row / dst.ny / oz) as usize;
            if c >= channels {
                return;
            }
            let z = a0 + zi;
            for dz in 0..step[0] {
                let szz = z * step[0] + dz;
                if szz < src_z0 || szz >= src_z0 + nz {
                    continue;
                }
                for dy in 0..step[1] {
                    let syy = y * step[1] + dy;
                    if syy < window.y0 || syy >= src_y1 {
                        continue;
                    }
                    let base = (c as u64 * nz + (szz - src_z0)) as usize * src_plane
                        + ((syy - window.y0) * window.nx) as usize;
                    src.add_row(
                        base,
                        window.nx as usize,
                        step[2],
                        &mut sum[offset..],
                        &mut count[offset..],
                    );
                }
            }
        });
}
