//! The exact-sum downsampling: each level ≥ 1 accumulates exact sums and non-NaN counts of
//! the level-0 voxels under each of its voxels ([`Accumulator`]), from the slabs of the level
//! below ([`SlabRows`]), and its means are rounded once from them.

use rayon::prelude::*;

use crate::memory::filled;
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

    /// Zeroed sums for `depth` planes from `z0` of `channels` channels over `window`, and
    /// their counts when the sample type has NaN (see [`Sample::HAS_NAN`]).
    pub(crate) fn new(channels: usize, z0: u64, depth: u64, window: PlaneRegion) -> Self {
        let mut acc = Self {
            z0,
            depth,
            window,
            sum: Vec::new(),
            count: Vec::new(),
        };
        acc.restart(channels, z0, depth, window);
        acc
    }

    /// Makes this accumulator hold what [`Accumulator::new`] would, in the memory it already
    /// holds (a column's accumulator is the previous column's, not a fresh allocation).
    ///
    /// The zeros are written, never taken from the allocator as zeroed memory: the first
    /// `+=` on a page the kernel lent zeroed reads it (the shared zero page) and then writes
    /// it, a second fault that flushes every core's TLB.
    pub(crate) fn restart(&mut self, channels: usize, z0: u64, depth: u64, window: PlaneRegion) {
        let len = channels * (depth * window.area()) as usize;
        filled(&mut self.sum, len, T::Sum::default());
        self.count.clear();
        if T::HAS_NAN {
            filled(&mut self.count, len, 0);
        }
        (self.z0, self.depth, self.window) = (z0, depth, window);
    }
}

/// Level-0 voxels under each voxel of a level, along one axis: a voxel `i` of a level with
/// factor `f` covers level-0 voxels `i·f..(i + 1)·f`, cut at the level-0 extent `n0`.
pub(crate) fn covered(i: u64, f: u64, n0: u64) -> u32 {
    ((i + 1) * f).min(n0).saturating_sub(i * f) as u32
}

/// A slab of one level, as the next level's accumulator reads it: rows of `x` values.
pub(crate) trait SlabRows<T: Sample>: Sync {
    /// Adds the row starting at `offset` (length `sx`) of the slab's plane `plane` (`c · nz +
    /// z`) into `sum`/`count`, summing `step_x` (1 or 2) neighbours per destination voxel.
    fn add_row(
        &self,
        plane: usize,
        offset: usize,
        sx: usize,
        step_x: u64,
        sum: &mut [T::Sum],
        count: &mut [u32],
    );
}

/// Level-0 voxel values, plane by plane (`[c][nz]`, each `[y][x]`).
pub(crate) struct Values<'a, T>(pub(crate) &'a [&'a [T]]);

impl<T: Sample> SlabRows<T> for Values<'_, T> {
    fn add_row(
        &self,
        plane: usize,
        offset: usize,
        sx: usize,
        step_x: u64,
        sum: &mut [T::Sum],
        count: &mut [u32],
    ) {
        add_values(&self.0[plane][offset..offset + sx], step_x, sum, count);
    }
}

/// Adds a row of level-0 values into `sum`/`count` (see [`SlabRows::add_row`]).
#[multiversion::multiversion(targets("x86_64+avx2"))]
fn add_values<T: Sample>(row: &[T], step_x: u64, sum: &mut [T::Sum], count: &mut [u32]) {
    let sx = row.len();
    if step_x == 1 {
        for (s, &v) in sum.iter_mut().zip(row) {
            *s += v.to_sum();
        }
        if T::HAS_NAN {
            for (n, &v) in count.iter_mut().zip(row) {
                *n += v.counts() as u32;
            }
        }
    } else {
        let pairs = row.chunks_exact(2);
        let tail = pairs.remainder();
        for (s, p) in sum.iter_mut().zip(pairs.clone()) {
            let mut pair = p[0].to_sum();
            pair += p[1].to_sum();
            *s += pair;
        }
        if T::HAS_NAN {
            for (n, p) in count.iter_mut().zip(pairs) {
                *n += p[0].counts() as u32 + p[1].counts() as u32;
            }
        }
        if let [v] = tail {
            let last = sx / 2;
            sum[last] += v.to_sum();
            if T::HAS_NAN {
                count[last] += v.counts() as u32;
            }
        }
    }
}

/// Exact sums and counts of a level ≥ 1 accumulator, laid out `[c][oz][y][x]` (planes of
/// `plane` voxels) while the slab holds `nz ≤ oz` planes.
pub(crate) struct Sums<'a, T: Sample> {
    pub(crate) sum: &'a [T::Sum],
    pub(crate) count: &'a [u32],
    pub(crate) nz: usize,
    pub(crate) oz: usize,
    pub(crate) plane: usize,
}

impl<T: Sample> SlabRows<T> for Sums<'_, T> {
    fn add_row(
        &self,
        plane: usize,
        offset: usize,
        sx: usize,
        step_x: u64,
        sum: &mut [T::Sum],
        count: &mut [u32],
    ) {
        let j = (plane / self.nz * self.oz + plane % self.nz) * self.plane + offset;
        let src_sum = &self.sum[j..j + sx];
        let src_count = if T::HAS_NAN {
            &self.count[j..j + sx]
        } else {
            &[]
        };
        if step_x == 1 {
            for (d, &v) in sum.iter_mut().zip(src_sum) {
                *d += v;
            }
            for (d, &v) in count.iter_mut().zip(src_count) {
                *d += v;
            }
        } else {
            add_pairs(sum, src_sum);
            add_pairs(count, src_count);
        }
    }
}

/// Adds each pair of `src` into one element of `dst` (a lone last element into the last).
fn add_pairs<S: Copy + std::ops::AddAssign>(dst: &mut [S], src: &[S]) {
    let pairs = src.chunks_exact(2);
    let tail = pairs.remainder();
    for (d, p) in dst.iter_mut().zip(pairs) {
        let mut pair = p[0];
        pair += p[1];
        *d += pair;
    }
    if let [v] = tail {
        dst[src.len() / 2] += *v;
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
    let [src_y1, _] = window.end();
    // The first column of the destination this window sums into.
    let offset = (window.x0 / step[2] - dst.x0) as usize;
    let add_rows = |row: usize, sum: &mut [T::Sum], count: &mut [u32]| {
        let row = row as u64;
        let y = dst.y0 + row % dst.ny;
        let zi = (row / dst.ny) % oz;
        let c = (row / dst.ny / oz) as usize;
        if c >= channels {
            return;
        }
        let z = a0 + zi;
        // Counts are kept only for sample types with NaN.
        let count = if count.is_empty() {
            count
        } else {
            &mut count[offset..]
        };
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
                let plane = (c as u64 * nz + (szz - src_z0)) as usize;
                let at = ((syy - window.y0) * window.nx) as usize;
                let (sx, step_x) = (window.nx as usize, step[2]);
                src.add_row(plane, at, sx, step_x, &mut sum[offset..], count);
            }
        }
    };
    let row_len = dst.nx as usize;
    if T::HAS_NAN {
        next.sum
            .par_chunks_mut(row_len)
            .zip(next.count.par_chunks_mut(row_len))
            .enumerate()
            .for_each(|(row, (sum, count))| add_rows(row, sum, count));
    } else {
        next.sum
            .par_chunks_mut(row_len)
            .enumerate()
            .for_each(|(row, sum)| add_rows(row, sum, &mut []));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn covered_counts_the_level0_voxels_under_a_voxel() {
        // 10 level-0 voxels, factor 4: voxels 0..4, 4..8 and 8..10.
        assert_eq!([0, 1, 2].map(|i| covered(i, 4, 10)), [4, 4, 2]);
        // Factor 1 (an axis never halved) and an exact fit.
        assert_eq!([covered(5, 1, 6), covered(1, 8, 16)], [1, 8]);
        // Past the extent: nothing.
        assert_eq!(covered(3, 4, 10), 0);
    }

    #[test]
    fn integer_accumulators_keep_no_counts_and_floats_do() {
        let w = PlaneRegion::whole([3, 5]);
        let a = Accumulator::<u16>::new(2, 0, 4, w);
        assert_eq!((a.sum.len(), a.count.len()), (120, 0));
        let f = Accumulator::<f32>::new(2, 0, 4, w);
        assert_eq!((f.sum.len(), f.count.len()), (120, 120));
    }
}
