//! Whole-channel statistics: sums, counts, extremes and key counts of level 0, from which the
//! percentiles and the histogram binning of each channel follow.

use std::cmp::Ordering::{self, Greater, Less};

use residency_schemas::Percentile;

use super::histograms::{Binning, BrickStats};
use crate::sample_format::{FINE_KEYS, Sample};

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

/// Of two extremes, `a` where it comes `side` of `b` in the order of their keys (`Less`: the
/// smaller, so −0.0 before 0.0; `Greater`: the larger), else `b`: the same whichever comes
/// first (`f64::min` may return either zero), whatever order the bricks are added in. A NaN
/// (never an extreme) is passed over.
fn extreme(a: f64, b: f64, side: Ordering) -> f64 {
    if a.is_nan() || (!b.is_nan() && a.total_cmp(&b) != side) {
        b
    } else {
        a
    }
}

impl ChannelAccumulator {
    /// Adds the statistics of another pass over other voxels of the channel (a partition's).
    pub fn merge(&mut self, other: &Self) {
        self.sum += other.sum;
        self.count += other.count;
        self.nan += other.nan;
        self.min = extreme(self.min, other.min, Less);
        self.max = extreme(self.max, other.max, Greater);
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
        self.min = extreme(self.min, brick.min, Less);
        self.max = extreme(self.max, brick.max, Greater);
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

    /// The binning for this channel's range: from the first fine key that holds a voxel to the
    /// last, so every brick's fine histogram falls in it (a brick's extreme is the first of
    /// equal values it meets, so a channel whose smallest values are zeros of both signs may
    /// give 0.0 as its minimum though −0.0, a key lower, is among its voxels).
    pub fn binning(&self) -> Binning {
        match (
            self.keys.iter().position(|&k| k > 0),
            self.keys.iter().rposition(|&k| k > 0),
        ) {
            (Some(first), Some(last)) => Binning::spanning(first, last),
            _ => Binning::spanning(0, 0),
        }
    }
}

#[cfg(test)]
mod tests {
    use residency_schemas::HISTOGRAM_BINS;

    use super::*;
    use crate::regions::histograms::StatsScratch;

    #[test]
    fn a_channel_of_both_zeros_has_range_minus_0_to_0_whichever_brick_comes_first() {
        let mut scratch = StatsScratch::default();
        let negative = BrickStats::of_rows([&[-0.0f32][..]].into_iter(), &mut scratch, false);
        let positive = BrickStats::of_rows([&[0.0f32][..]].into_iter(), &mut scratch, false);
        // A brick that meets 0.0 first gives it as both extremes, though it holds -0.0.
        let both = BrickStats::of_rows([&[0.0f32, -0.0][..]].into_iter(), &mut scratch, false);
        assert_eq!([both.min.to_bits(), both.max.to_bits()], [0, 0]);
        let range = [(-0.0f64).to_bits(), 0];
        for order in [[&negative, &positive], [&positive, &negative]] {
            let mut acc = ChannelAccumulator::default();
            for brick in order {
                acc.add(brick);
            }
            assert_eq!([acc.min.to_bits(), acc.max.to_bits()], range);
            let mut merged = ChannelAccumulator::default();
            merged.merge(&acc);
            assert_eq!([merged.min.to_bits(), merged.max.to_bits()], range);
        }
        // The binning holds both zeros' keys even where the extremes say 0.0 to 0.0.
        let mut acc = ChannelAccumulator::default();
        acc.add(&both);
        let binning = acc.binning();
        assert_eq!(binning, Binning::spanning((-0.0f32).key(), 0.0f32.key()));
        let mut bins = [0u32; HISTOGRAM_BINS];
        binning.bin_into(&both.fine, &mut bins);
        assert_eq!(bins.iter().sum::<u32>(), 2);
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
        let b = acc.binning();
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
