//! The exact-sum downsampling: each level ≥ 1 accumulates exact sums and non-NaN counts of
//! the level-0 voxels under each of its voxels ([`Accumulator`]), from the slabs of the level
//! below ([`SlabRows`]), and its means are rounded once from them. A level whose voxels cover
//! few enough level-0 voxels keeps its sums in the sample type's narrow sum
//! ([`Sample::Narrow`]): half the memory, and twice the sums per vector instruction.

use rayon::prelude::*;

use crate::memory::filled;
use crate::pyramid::LevelPlan;
use crate::sample_format::{Sample, SumOf};
use crate::source::PlaneRegion;

/// A level's exact sums, in the sample type's narrow or wide sum.
pub(crate) enum SumBuffer<T: Sample> {
    /// [`Sample::Narrow`] sums, for levels whose voxels cover at most
    /// [`Sample::NARROW_TERMS`] level-0 voxels (see [`narrow_sums`]).
    Narrow(Vec<T::Narrow>),
    /// [`Sample::Sum`] sums.
    Wide(Vec<T::Sum>),
}

/// Calls `$body` with `$v` bound to the sums of `$buffer`, whichever their width.
macro_rules! with_sums {
    ($buffer:expr, $v:ident => $body:expr) => {
        match $buffer {
            $crate::convert::pyramid_sums::SumBuffer::Narrow($v) => $body,
            $crate::convert::pyramid_sums::SumBuffer::Wide($v) => $body,
        }
    };
}
pub(crate) use with_sums;

impl<T: Sample> SumBuffer<T> {
    /// Makes every sum 0.
    pub(crate) fn zero(&mut self) {
        with_sums!(self, v => v.fill(Default::default()));
    }

    /// The sums in the wide type (a narrow buffer is widened, exactly).
    pub(crate) fn into_wide(self) -> Vec<T::Sum> {
        match self {
            Self::Narrow(v) => v.into_iter().map(SumOf::widened).collect(),
            Self::Wide(v) => v,
        }
    }

    /// Sets the sums from `at` on to the wide sums `wide` of the same level (exact: the plan
    /// that made this buffer narrow bounds every sum of the level).
    pub(crate) fn set_from_wide(&mut self, at: usize, wide: &[T::Sum]) {
        with_sums!(self, v => {
            for (d, &w) in v[at..at + wide.len()].iter_mut().zip(wide) {
                *d = SumOf::narrowed(w);
                debug_assert!(d.widened() == w, "a sum of {w:?} does not fit this level's sums");
            }
        });
    }
}

/// Whether `level` keeps its sums narrow: each of its voxels covers at most
/// `factor_z · factor_y · factor_x` level-0 voxels, and [`Sample::NARROW_TERMS`] of them fit.
pub(crate) fn narrow_sums<T: Sample>(level: &LevelPlan) -> bool {
    level.factor.iter().product::<u64>() <= T::NARROW_TERMS
}

/// Bytes of one of `level`'s exact sums: narrow or wide (see [`narrow_sums`]).
pub(crate) fn sum_bytes<T: Sample>(level: &LevelPlan) -> u64 {
    if narrow_sums::<T>(level) {
        size_of::<T::Narrow>() as u64
    } else {
        size_of::<T::Sum>() as u64
    }
}

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
    pub(crate) sum: SumBuffer<T>,
    /// Non-NaN level-0 voxel counts matching `sum`.
    pub(crate) count: Vec<u32>,
}

impl<T: Sample> Accumulator<T> {
    /// An accumulator that holds nothing (level 0's, or one taken out for a while).
    pub(crate) fn empty() -> Self {
        Self::new(false, 0, 0, 0, PlaneRegion::whole([0, 0]))
    }

    /// Zeroed sums (narrow ones when `narrow`, see [`narrow_sums`]) for `depth` planes from
    /// `z0` of `channels` channels over `window`, and their counts when the sample type has
    /// NaN (see [`Sample::HAS_NAN`]).
    pub(crate) fn new(
        narrow: bool,
        channels: usize,
        z0: u64,
        depth: u64,
        window: PlaneRegion,
    ) -> Self {
        let mut acc = Self {
            z0,
            depth,
            window,
            sum: if narrow {
                SumBuffer::Narrow(Vec::new())
            } else {
                SumBuffer::Wide(Vec::new())
            },
            count: Vec::new(),
        };
        acc.restart(channels, z0, depth, window);
        acc
    }

    /// Makes this accumulator hold what [`Accumulator::new`] would (sums as narrow as they
    /// were), in the memory it already holds (a column's accumulator is the previous
    /// column's, not a fresh allocation).
    ///
    /// The zeros are written, never taken from the allocator as zeroed memory: the first
    /// `+=` on a page the kernel lent zeroed reads it (the shared zero page) and then writes
    /// it, a second fault that flushes every core's TLB.
    pub(crate) fn restart(&mut self, channels: usize, z0: u64, depth: u64, window: PlaneRegion) {
        let len = channels * (depth * window.area()) as usize;
        with_sums!(&mut self.sum, v => filled(v, len, Default::default()));
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
    /// z`) into `sum`/`count` (sums of either width), summing `step_x` (1 or 2) neighbours
    /// per destination voxel.
    fn add_row<S: SumOf<T::Sum>>(
        &self,
        plane: usize,
        offset: usize,
        sx: usize,
        step_x: u64,
        sum: &mut [S],
        count: &mut [u32],
    );
}

/// Level-0 voxel values, plane by plane (`[c][nz]`, each `[y][x]`).
pub(crate) struct Values<'a, T>(pub(crate) &'a [&'a [T]]);

impl<T: Sample> SlabRows<T> for Values<'_, T> {
    fn add_row<S: SumOf<T::Sum>>(
        &self,
        plane: usize,
        offset: usize,
        sx: usize,
        step_x: u64,
        sum: &mut [S],
        count: &mut [u32],
    ) {
        add_values(&self.0[plane][offset..offset + sx], step_x, sum, count);
    }
}

/// Adds a row of level-0 values into `sum`/`count` (see [`SlabRows::add_row`]).
#[multiversion::multiversion(targets("x86_64+avx2"))]
fn add_values<T: Sample, S: SumOf<T::Sum>>(
    row: &[T],
    step_x: u64,
    sum: &mut [S],
    count: &mut [u32],
) {
    let sx = row.len();
    let term = |v: T| S::narrowed(v.to_sum());
    if step_x == 1 {
        for (s, &v) in sum.iter_mut().zip(row) {
            *s += term(v);
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
            let mut pair = term(p[0]);
            pair += term(p[1]);
            *s += pair;
        }
        if T::HAS_NAN {
            for (n, p) in count.iter_mut().zip(pairs) {
                *n += p[0].counts() as u32 + p[1].counts() as u32;
            }
        }
        if let [v] = tail {
            let last = sx / 2;
            sum[last] += term(*v);
            if T::HAS_NAN {
                count[last] += v.counts() as u32;
            }
        }
    }
}

/// Exact sums (of type `S`, narrow or wide) and counts of a level ≥ 1 accumulator, laid out
/// `[c][oz][y][x]` (planes of `plane` voxels) while the slab holds `nz ≤ oz` planes.
pub(crate) struct Sums<'a, S> {
    pub(crate) sum: &'a [S],
    pub(crate) count: &'a [u32],
    pub(crate) nz: usize,
    pub(crate) oz: usize,
    pub(crate) plane: usize,
}

impl<T: Sample, S: SumOf<T::Sum>> SlabRows<T> for Sums<'_, S> {
    fn add_row<D: SumOf<T::Sum>>(
        &self,
        plane: usize,
        offset: usize,
        sx: usize,
        step_x: u64,
        sum: &mut [D],
        count: &mut [u32],
    ) {
        let j = (plane / self.nz * self.oz + plane % self.nz) * self.plane + offset;
        let src_sum = &self.sum[j..j + sx];
        let src_count = if T::HAS_NAN {
            &self.count[j..j + sx]
        } else {
            &[]
        };
        // Exact whatever the two widths: a source voxel's level-0 voxels are some of the
        // destination voxel's, so every source sum fits the destination's type.
        let term = |v: S| D::narrowed(v.widened());
        if step_x == 1 {
            for (d, &v) in sum.iter_mut().zip(src_sum) {
                *d += term(v);
            }
            for (d, &v) in count.iter_mut().zip(src_count) {
                *d += v;
            }
        } else {
            add_pairs(sum, src_sum, term);
            add_pairs(count, src_count, |n| n);
        }
    }
}

/// Adds each pair of `src`, each term made a `D` by `term`, into one element of `dst` (a lone
/// last element into the last).
fn add_pairs<S: Copy, D: Copy + std::ops::AddAssign>(
    dst: &mut [D],
    src: &[S],
    term: impl Fn(S) -> D,
) {
    let pairs = src.chunks_exact(2);
    let tail = pairs.remainder();
    for (d, p) in dst.iter_mut().zip(pairs) {
        let mut pair = term(p[0]);
        pair += term(p[1]);
        *d += pair;
    }
    if let [v] = tail {
        dst[src.len() / 2] += term(*v);
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
    let target = Target::new(plan, next, channels, window, src_z0, nz);
    let count = &mut next.count;
    with_sums!(&mut next.sum, sum => accumulate_into(target, (sum, count), src));
}

/// Where the rows of a slab of one level go in the next level's accumulator: what
/// [`accumulate`] and [`BandSums`] share.
#[derive(Clone, Copy)]
pub(crate) struct Target {
    /// Source voxels per destination voxel, `z, y, x`.
    step: [u64; 3],
    /// The accumulator's window, planes held and first plane.
    dst: PlaneRegion,
    oz: u64,
    a0: u64,
    channels: usize,
    /// The slab's window, first plane (in the source level) and planes.
    window: PlaneRegion,
    src_z0: u64,
    nz: u64,
}

impl Target {
    /// Where a slab of `channels` channels over `window`, planes `src_z0..src_z0 + nz` of the
    /// level below, goes in `next`, the accumulator of the level `plan` plans.
    pub(crate) fn new<T: Sample>(
        plan: &LevelPlan,
        next: &Accumulator<T>,
        channels: usize,
        window: PlaneRegion,
        src_z0: u64,
        nz: u64,
    ) -> Self {
        Self {
            step: plan.step,
            dst: next.window,
            oz: next.depth,
            a0: next.z0,
            channels,
            window,
            src_z0,
            nz,
        }
    }

    /// The channel, accumulator plane and level row of destination row `row` (rows are
    /// `[c][oz][y]`), or none past the channels.
    fn row(&self, row: u64) -> Option<(usize, u64, u64)> {
        let c = (row / self.dst.ny / self.oz) as usize;
        (c < self.channels).then(|| {
            let y = self.dst.y0 + row % self.dst.ny;
            (c, self.a0 + (row / self.dst.ny) % self.oz, y)
        })
    }

    /// Whether any source plane of destination plane `z` is in the slab.
    fn reaches(&self, z: u64) -> bool {
        let first = z * self.step[0];
        first < self.src_z0 + self.nz && first + self.step[0] > self.src_z0
    }

    /// Adds the slab's rows under destination row `row` into its sums `sum` (of either
    /// width) and counts `count` (empty for sample types without NaN).
    fn add_row<T: Sample, S: SumOf<T::Sum>>(
        &self,
        row: u64,
        sum: &mut [S],
        count: &mut [u32],
        src: &impl SlabRows<T>,
    ) {
        let Some((c, z, y)) = self.row(row) else {
            return;
        };
        let step = self.step;
        let (window, src_z0, nz) = (self.window, self.src_z0, self.nz);
        let [src_y1, _] = window.end();
        // The first column of the destination this window sums into.
        let offset = (window.x0 / step[2] - self.dst.x0) as usize;
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
    }
}

/// [`accumulate`] into the sums `sum` (of either width) and counts `count` of an accumulator,
/// row by row on every thread.
fn accumulate_into<T: Sample, S: SumOf<T::Sum>>(
    target: Target,
    (next_sum, next_count): (&mut [S], &mut [u32]),
    src: &impl SlabRows<T>,
) {
    let row_len = target.dst.nx as usize;
    if T::HAS_NAN {
        next_sum
            .par_chunks_mut(row_len)
            .zip(next_count.par_chunks_mut(row_len))
            .enumerate()
            .for_each(|(row, (sum, count))| target.add_row(row as u64, sum, count, src));
    } else {
        next_sum
            .par_chunks_mut(row_len)
            .enumerate()
            .for_each(|(row, sum)| target.add_row(row as u64, sum, &mut [], src));
    }
}

/// Rows of an accumulator's sums and counts (`row`, sums, counts) that one band sums into.
type BandRows<'a, S> = Vec<(u64, &'a mut [S], &'a mut [u32])>;

/// A level-0 slab's sums into the next level's accumulator, band by band: the worker that
/// gathers the chunks of a band (one chunk row of one channel, whole) adds its rows while they
/// are in its cache (see [`SlabSink::process`](super::sink::SlabSink::process)), instead of a
/// pass over the whole slab after it is written. The bands' rows of the accumulator are
/// apart, so each band's are lent to its worker alone.
pub(crate) struct BandSums<'a, S> {
    target: Target,
    /// Level-0 rows per band.
    band_rows: u64,
    /// Bands per channel.
    bands: usize,
    /// The rows each band sums into, `[c][band]`.
    rows: Vec<std::sync::Mutex<BandRows<'a, S>>>,
}

impl<'a, S: Send> BandSums<'a, S> {
    /// Lends the rows of `target`'s accumulator (`sum`, `count`: its sums, of either width,
    /// and counts) that each band of `band_rows` level-0 rows of the slab sums into.
    pub(crate) fn new(
        target: Target,
        (sum, count): (&'a mut [S], &'a mut [u32]),
        band_rows: u64,
    ) -> Self {
        let window = target.window;
        let bands = window.ny.div_ceil(band_rows).max(1) as usize;
        let mut rows: Vec<_> = (0..target.channels * bands).map(|_| Vec::new()).collect();
        let row_len = target.dst.nx as usize;
        let mut counts = count.chunks_mut(row_len);
        for (r, sum) in sum.chunks_mut(row_len).enumerate() {
            let count = counts.next().unwrap_or_default();
            let Some((c, z, y)) = target.row(r as u64) else {
                continue;
            };
            if !target.reaches(z) {
                continue;
            }
            // The band of the destination row's first source row (its others are in the same
            // band when the band's edge is a multiple of the step; either way `add_row` reads
            // them from the whole slab, so only where the work is done depends on it).
            let band = ((y * target.step[1]).max(window.y0) - window.y0) / band_rows;
            let band = (band as usize).min(bands - 1);
            rows[c * bands + band].push((r as u64, sum, count));
        }
        Self {
            target,
            band_rows,
            bands,
            rows: rows.into_iter().map(std::sync::Mutex::new).collect(),
        }
    }
}

/// Work a worker does on each band of a slab besides writing it: see [`BandSums`].
pub(crate) trait BandWork<T: Sample>: Sync {
    /// Level-0 rows per band (the chunk's edge `y`).
    fn band_rows(&self) -> u64;

    /// Does the work of channel `c`'s band `band` (counted from the window's first row) of
    /// the slab whose planes are `planes` (`[c · nz + z]`, each `[y][x]` over the window).
    fn band(&self, c: usize, band: usize, planes: &[&[T]]);
}

impl<T: Sample, S: SumOf<T::Sum>> BandWork<T> for BandSums<'_, S> {
    fn band_rows(&self) -> u64 {
        self.band_rows
    }

    fn band(&self, c: usize, band: usize, planes: &[&[T]]) {
        let mut rows = self.rows[c * self.bands + band].lock().expect("band rows");
        for (r, sum, count) in rows.iter_mut() {
            self.target.add_row(*r, sum, count, &Values(planes));
        }
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

    /// Sums a slab of `channels` channels (`nz` planes from `z0`, over `window`) into a level
    /// of `step` with `accumulate`, and band by band (bands of `band_rows` rows, in reverse
    /// order); both accumulators' sums and counts.
    fn both_ways<T: Sample>(
        values: &[T],
        channels: usize,
        (z0, nz, window): (u64, u64, PlaneRegion),
        step: [u64; 3],
        band_rows: u64,
    ) -> [(Vec<T::Sum>, Vec<u32>); 2] {
        let plan = LevelPlan {
            shape: [0; 3],
            step,
            factor: step,
            voxel_size: [1.0; 3],
        };
        let dst = crate::columns::at_level(window, step, [u64::MAX; 3]);
        let new = || Accumulator::<T>::new(false, channels, 0, 3, dst);
        let planes =
            crate::convert::sink::planes_of(values, channels * nz as usize, window.area() as usize);
        let mut whole = new();
        accumulate(
            &plan,
            &mut whole,
            channels,
            window,
            z0,
            nz,
            &Values(&planes),
        );
        let mut banded = new();
        let target = Target::new(&plan, &banded, channels, window, z0, nz);
        let SumBuffer::Wide(sum) = &mut banded.sum else {
            unreachable!("wide sums")
        };
        let bands = BandSums::new(target, (sum, &mut banded.count), band_rows);
        for c in 0..channels {
            for band in (0..window.ny.div_ceil(band_rows) as usize).rev() {
                BandWork::<T>::band(&bands, c, band, &planes);
            }
        }
        drop(bands);
        [whole, banded].map(|a| (a.sum.into_wide(), a.count))
    }

    #[test]
    fn sums_added_band_by_band_are_the_sums_added_row_by_row() {
        // A column window 12 rows down and 4 across, 3 bands of 6 rows (the last 2), odd
        // extents, two channels; planes 2..6 of the level below.
        let window = PlaneRegion {
            y0: 12,
            x0: 4,
            ny: 14,
            nx: 9,
        };
        let n = 2 * 4 * 14 * 9;
        let ints: Vec<u16> = (0..n).map(|i| (i * 7919 % 65521) as u16).collect();
        let [a, b] = both_ways(&ints, 2, (2, 4, window), [2, 2, 2], 6);
        assert_eq!(a, b);
        assert!(a.0.iter().any(|&s| s != 0));
        // Anisotropic steps, and floats with NaN (counted).
        let floats: Vec<f32> = (0..n)
            .map(|i| {
                if i % 13 == 0 {
                    f32::NAN
                } else {
                    i as f32 * 0.25
                }
            })
            .collect();
        let [a, b] = both_ways(&floats, 2, (2, 4, window), [1, 2, 2], 6);
        assert_eq!(a.0.len(), b.0.len());
        assert!(
            a.0.iter()
                .zip(&b.0)
                .all(|(x, y)| x.to_bits() == y.to_bits())
        );
        assert_eq!(a.1, b.1);
        assert!(a.1.iter().any(|&n| n > 0 && n < 4));
    }

    #[test]
    fn integer_accumulators_keep_no_counts_and_floats_do() {
        let w = PlaneRegion::whole([3, 5]);
        let a = Accumulator::<u16>::new(true, 2, 0, 4, w);
        let narrow = matches!(a.sum, SumBuffer::Narrow(_));
        assert_eq!(
            (with_sums!(&a.sum, v => v.len()), a.count.len(), narrow),
            (120, 0, true)
        );
        let f = Accumulator::<f32>::new(false, 2, 0, 4, w);
        assert_eq!(
            (with_sums!(&f.sum, v => v.len()), f.count.len()),
            (120, 120)
        );
    }
}
