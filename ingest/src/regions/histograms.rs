//! Brick histograms: fine-key counts of every brick, gathered with the rest of a brick's
//! statistics ([`BrickStats`]) while streaming, and grouped into bins ([`Binning`]) once the
//! channel's range is known.

use std::sync::Mutex;

use residency_schemas::HISTOGRAM_BINS;

use crate::sample_format::{FINE_KEYS, Sample, max_of, min_of};

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
    /// Tables whose zeros are written, not lent zeroed by the kernel: the counts read and
    /// write each entry, and a page first read as the shared zero page faults again, with a
    /// TLB flush on every core, when it is written.
    fn default() -> Self {
        let (mut exact, mut keys) = (Vec::new(), Vec::new());
        crate::memory::filled(&mut exact, 1 << 16, 0);
        crate::memory::filled(&mut keys, FINE_KEYS, 0);
        let keys = keys
            .into_boxed_slice()
            .try_into()
            .expect("FINE_KEYS counts");
        Self { keys, exact }
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
    #[multiversion::multiversion(targets("x86_64+avx2"))]
    pub fn of_rows<'a, T: Sample>(
        rows: impl Iterator<Item = &'a [T]>,
        scratch: &mut StatsScratch,
        keep_exact: bool,
    ) -> BrickStats {
        let (mut mn, mut mx) = (T::HIGHEST, T::LOWEST);
        if T::HIGHEST.exact_index().is_some() {
            // Count exact values only; everything else follows from the counts.
            let exact = &mut scratch.exact;
            let mut total = 0u64;
            for row in rows {
                let Some(&first) = row.first() else {
                    continue;
                };
                total += row.len() as u64;
                // A row of one value (the background of most bricks) is one count.
                if row
                    .chunks(64)
                    .all(|part| part.iter().filter(|&&v| v != first).count() == 0)
                {
                    exact[first.exact_index().unwrap_or(0)] += row.len() as u32;
                    (mn, mx) = (min_of(mn, first), max_of(mx, first));
                    continue;
                }
                for &v in row {
                    exact[v.exact_index().unwrap_or(0)] += 1;
                }
                for &v in row {
                    (mn, mx) = (min_of(mn, v), max_of(mx, v));
                }
            }
            if total == 0 {
                return BrickStats {
                    all_fill: true,
                    ..BrickStats::default()
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
            BrickStats {
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
            BrickStats {
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

/// Fine histograms of every brick of one level, filled concurrently.
#[derive(Debug)]
pub struct LevelHistograms {
    /// Bricks held per channel `z, y, x`: every brick of the level, the brick rows a
    /// partition writes, or the bricks of one column.
    pub bricks: [u64; 3],
    /// The level's brick row held first (0 for a whole level).
    pub z0: u64,
    /// The first brick held along `y` and `x` (0 but in a column).
    pub yx0: [u64; 2],
    /// Channels.
    pub channels: usize,
    /// `[c][bz][by][bx]` fine histograms.
    pub fine: Mutex<Vec<FineHistogram>>,
}

/// Fine histograms of a block of bricks: `[c][z][y][x]` over `bricks` from brick `origin`
/// (`z, y, x`).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct HistogramBlock {
    /// The first brick `z, y, x`.
    pub origin: [u64; 3],
    /// Bricks per channel `z, y, x`.
    pub bricks: [u64; 3],
    /// The histograms.
    pub fine: Vec<FineHistogram>,
}

impl LevelHistograms {
    /// Room for `channels` channels of `bricks` bricks.
    pub fn new(channels: usize, bricks: [u64; 3]) -> Self {
        let n = channels * (bricks[0] * bricks[1] * bricks[2]) as usize;
        Self {
            bricks,
            z0: 0,
            yx0: [0, 0],
            channels,
            fine: Mutex::new(vec![FineHistogram::default(); n]),
        }
    }

    /// Room for brick rows `rows` of `channels` channels of a level of `bricks` bricks.
    pub fn for_rows(channels: usize, bricks: [u64; 3], rows: std::ops::Range<u64>) -> Self {
        let z1 = rows.end.min(bricks[0]);
        Self::block(channels, rows.start.min(z1)..z1, 0..bricks[1], 0..bricks[2])
    }

    /// Room for the bricks `rows × ys × xs` (a column's).
    pub fn block(
        channels: usize,
        rows: std::ops::Range<u64>,
        ys: std::ops::Range<u64>,
        xs: std::ops::Range<u64>,
    ) -> Self {
        let mut held = Self::new(
            channels,
            [rows.end - rows.start, ys.end - ys.start, xs.end - xs.start],
        );
        held.z0 = rows.start;
        held.yx0 = [ys.start, xs.start];
        held
    }

    /// Holds brick rows up to `end` as well (capped at the level's `depth` rows), empty.
    pub fn extend_to(&mut self, end: u64, depth: u64) {
        let end = end.min(depth);
        let [bz, by, bx] = self.bricks;
        if end <= self.z0 + bz {
            return;
        }
        let fine = self.fine.get_mut().expect("histograms");
        let plane = (by * bx) as usize;
        let rows = (end - self.z0) as usize;
        let mut grown = vec![FineHistogram::default(); self.channels * rows * plane];
        for (i, h) in fine.drain(..).enumerate() {
            let (c, rest) = (i / (bz as usize * plane), i % (bz as usize * plane));
            grown[c * rows * plane + rest] = h;
        }
        *fine = grown;
        self.bricks[0] = end - self.z0;
    }

    /// Takes the rows before `end` out (they are final), with the window then starting at
    /// `end`.
    pub fn split_before(&mut self, end: u64) -> HistogramBlock {
        let [bz, by, bx] = self.bricks;
        let end = end.clamp(self.z0, self.z0 + bz);
        let taken = (end - self.z0) as usize;
        let fine = self.fine.get_mut().expect("histograms");
        let plane = (by * bx) as usize;
        let (mut front, mut back) = (Vec::new(), Vec::new());
        for (i, h) in fine.drain(..).enumerate() {
            if i / plane % (bz as usize).max(1) < taken {
                front.push(h);
            } else {
                back.push(h);
            }
        }
        *fine = back;
        let block = HistogramBlock {
            origin: [self.z0, self.yx0[0], self.yx0[1]],
            bricks: [taken as u64, by, bx],
            fine: front,
        };
        self.z0 = end;
        self.bricks[0] = bz - taken as u64;
        block
    }

    /// Linear index of a brick (level coordinates; it must be held).
    pub fn index(&self, c: usize, b: [u64; 3]) -> usize {
        let [bz, by, bx] = self.bricks;
        let [y0, x0] = self.yx0;
        ((c as u64 * bz + b[0] - self.z0) * by * bx + (b[1] - y0) * bx + b[2] - x0) as usize
    }
}
