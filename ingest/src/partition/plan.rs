//! What the partitions of one conversion agree on: which partition a process is
//! ([`Partition`]), where the partitions cut ([`Cuts`]), and the plan of the store they write
//! ([`PartitionPlan`]).

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use crate::pyramid::LevelPlan;
use crate::sample_format::SampleType;
use crate::store::OmeZarrVersion;

/// One partition of a conversion: `index` counts from 0 and is below `count`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Partition {
    /// Which partition, from 0.
    pub index: usize,
    /// How many partitions.
    pub count: usize,
}

/// A `--partition` argument that is not `I/N` with `0 ≤ I < N`.
#[derive(Debug, PartialEq, Eq, thiserror::Error)]
#[error(
    "--partition {text}: expected I/N, partition I (counted from 0) of N, with I below N (0/N to N-1/N)"
)]
pub struct PartitionParseError {
    /// The argument.
    pub text: String,
}

impl FromStr for Partition {
    type Err = PartitionParseError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let bad = || PartitionParseError {
            text: s.to_string(),
        };
        let (i, n) = s.split_once('/').ok_or_else(bad)?;
        let index: usize = i.trim().parse().map_err(|_| bad())?;
        let count: usize = n.trim().parse().map_err(|_| bad())?;
        if count == 0 || index >= count {
            return Err(bad());
        }
        Ok(Self { index, count })
    }
}

impl fmt::Display for Partition {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

impl Partition {
    /// The hand-over file's name under [`HANDOFF_FOLDER`](super::HANDOFF_FOLDER).
    pub fn file_name(&self) -> String {
        format!("{}-of-{}", self.index, self.count)
    }
}

/// Where the partitions of a conversion cut, the same for every partition and for `finalize`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Cuts {
    /// The first level the partitions do not write (the hand-over level H); the number of
    /// levels when they write them all.
    pub handoff_level: usize,
    /// Level-0 planes in one unit: partitions start and end on multiples of it.
    pub unit: u64,
    /// Units in the volume (the last one may be shorter).
    pub units: u64,
    /// Partitions.
    pub count: usize,
}

fn gcd(a: u64, b: u64) -> u64 {
    if b == 0 { a } else { gcd(b, a % b) }
}

impl Cuts {
    /// The cuts of a volume `depth` planes deep into `count` partitions, for the pyramid
    /// `plans` written in slabs `slab_depth` planes deep (the chunk or shard depth).
    pub fn plan(plans: &[LevelPlan], slab_depth: u64, count: usize) -> Self {
        let depth = plans[0].shape[0];
        let unit_of = |h: usize| {
            let whole = slab_depth * plans[h - 1].factor[0];
            match plans.get(h) {
                Some(level) => {
                    let voxel = level.factor[0];
                    whole / gcd(whole, voxel) * voxel
                }
                None => whole,
            }
        };
        let handoff_level = (1..=plans.len())
            .rev()
            .find(|&h| depth.div_ceil(unit_of(h)) >= count as u64)
            .unwrap_or(1);
        let unit = unit_of(handoff_level);
        Self {
            handoff_level,
            unit,
            units: depth.div_ceil(unit),
            count,
        }
    }

    /// The level-0 planes `start..end` of partition `index` (empty when the volume has fewer
    /// units than partitions and this one gets none).
    pub fn planes(&self, index: usize, depth: u64) -> std::ops::Range<u64> {
        let unit_at = |i: usize| (i as u64 * self.units / self.count as u64) * self.unit;
        unit_at(index).min(depth)..unit_at(index + 1).min(depth)
    }
}

/// What every partition of one conversion must agree on, and what `finalize` needs to know
/// to write the store: the inputs' shape, type and metadata, the options, and the cuts.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PartitionPlan {
    /// Sample type.
    pub format: SampleType,
    /// Level-0 shape `z, y, x`.
    pub shape: [u64; 3],
    /// Channel labels (one per channel).
    pub labels: Vec<String>,
    /// Voxel size `z, y, x`.
    pub voxel_size: [f64; 3],
    /// Physical unit.
    pub unit: Option<String>,
    /// Brick shape `z, y, x` (clamped to the volume).
    pub brick: [u64; 3],
    /// Zarr chunk (shard) shape `z, y, x`.
    pub outer: [u64; 3],
    /// Whether bricks are inner chunks of shards.
    pub sharded: bool,
    /// OME-Zarr version.
    pub version: OmeZarrVersion,
    /// The level plan.
    pub levels: Vec<LevelPlan>,
    /// Where the partitions cut.
    pub cuts: Cuts,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pyramid::plan_levels;

    #[test]
    fn partitions_parse_from_zero() {
        assert_eq!(
            "2/7".parse::<Partition>(),
            Ok(Partition { index: 2, count: 7 })
        );
        for bad in ["7/7", "1/0", "a/2", "3", "-1/2"] {
            assert_eq!(
                bad.parse::<Partition>().unwrap_err().to_string(),
                format!(
                    "--partition {bad}: expected I/N, partition I (counted from 0) of N, with I below N (0/N to N-1/N)"
                )
            );
        }
    }

    #[test]
    fn cuts_fall_on_whole_slabs_of_every_written_level() {
        // 45 planes, 4-deep slabs, halving z every level: 45, 23, 12, 6, 3, 2, 1.
        let plans = plan_levels([45, 40, 40], [1.0; 3], [4, 4, 4], None);
        let factors: Vec<u64> = plans.iter().map(|p| p.factor[0]).collect();
        assert_eq!(factors, [1, 2, 4, 8, 16]);
        // One partition writes every level.
        let one = Cuts::plan(&plans, 4, 1);
        assert_eq!((one.handoff_level, one.unit, one.units), (5, 64, 1));
        assert_eq!(one.planes(0, 45), 0..45);
        // Two: levels 0 to 3 (level 3's slabs are 32 planes deep, level 4's voxels 16).
        let two = Cuts::plan(&plans, 4, 2);
        assert_eq!((two.handoff_level, two.unit, two.units), (4, 32, 2));
        assert_eq!([two.planes(0, 45), two.planes(1, 45)], [0..32, 32..45]);
        // Seven: level 0 only, in 4-plane units (level 1's voxels are 2 planes deep).
        let seven = Cuts::plan(&plans, 4, 7);
        assert_eq!((seven.handoff_level, seven.unit, seven.units), (1, 4, 12));
        let ranges: Vec<_> = (0..7).map(|i| seven.planes(i, 45)).collect();
        assert_eq!(
            ranges,
            [0..4, 4..12, 12..20, 20..24, 24..32, 32..40, 40..45]
        );
        // More partitions than units: some get nothing.
        let many = Cuts::plan(&plans, 4, 20);
        assert_eq!(many.handoff_level, 1);
        assert_eq!(many.planes(0, 45), 0..0);
        assert_eq!(many.planes(19, 45), 44..45);
        // An odd slab depth: units hold whole slabs of level 1 (6 planes) and whole voxels of
        // level 2 (4 planes): 12 planes.
        let plans = plan_levels([30, 8, 8], [1.0; 3], [3, 8, 8], None);
        let cuts = Cuts::plan(&plans, 3, 3);
        assert_eq!((cuts.handoff_level, cuts.unit, cuts.units), (2, 12, 3));
    }
}
