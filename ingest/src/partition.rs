//! Partitioned conversion: `ingest convert --partition I/N` converts one range of level-0
//! planes, and `ingest finalize` finishes the store from what the N partitions hand over.
//!
//! **Where partitions cut.** Every level below the *hand-over level* H is written whole by the
//! partitions: a partition's planes are whole slabs (one chunk deep) of each of those levels,
//! so its range starts and ends on a multiple of `chunk depth × level H−1's z factor`, and also
//! on a multiple of level H's z factor, so that no voxel of level H draws on two partitions.
//! H is the coarsest level for which there are at least N such units (at least 1); a level
//! with fewer units than partitions leaves some partitions with nothing to do.
//!
//! **What a partition hands over** ([`Handoff`]): for each level below H, its bricks' written
//! and empty counts, and where its records of min/max cell rows and brick histograms are
//! (files in `.partitions/.records/`, written slab by slab, so a partition holds a few rows
//! at a time); the whole-channel statistics; and, for level H, the exact sums and counts of
//! level-0 voxels of its planes (level H's accumulator, before any rounding). `finalize`
//! merges the cells (min and max) chunk of rows by chunk of rows as the partitions come, in
//! z order, the histograms (each brick comes from one partition) and statistics (sums of
//! integers and counts), feeds
//! the sums into level H plane by plane in z order, and from there runs the same code as one
//! process: the same sums are added in the same order, so the store is byte for byte the one
//! a single process writes.
//!
//! Hand-over files lie in the store's folder under `.partitions/` while the partitions run
//! (`I-of-N`, postcard-encoded: transient files between processes of the same build), beside
//! the plan the first partition recorded (`plan`, which later partitions must match), and are
//! removed by `finalize` before the root metadata is written.

use std::fmt;
use std::path::{Path, PathBuf};
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use crate::pyramid::LevelPlan;
use crate::region_scratch::LevelRecords;
use crate::regions::ChannelAccumulator;
use crate::sample_format::{Sample, SampleType};
use crate::store::OmeZarrVersion;

/// The folder, under a store's root, where partitions leave their hand-over files.
pub const HANDOFF_FOLDER: &str = ".partitions";

/// Bumped whenever [`Handoff`] changes: `finalize` refuses files of another version.
const HANDOFF_VERSION: u32 = 2;

/// The file under [`HANDOFF_FOLDER`] holding the plan the first partition to start followed.
const PLAN_FILE: &str = "plan";

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
    /// The hand-over file's name under [`HANDOFF_FOLDER`].
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

/// What a partition hands over of one level below the hand-over level: its brick counts,
/// and where its records of cells and brick histograms are (files in
/// [`RECORDS_FOLDER`], see [`records_stem`]), written as its slabs were done, so a partition
/// holds a few rows at a time, never all its rows.
#[derive(Debug, Serialize, Deserialize)]
pub struct LevelPart {
    /// Bricks written.
    pub written: u64,
    /// Bricks found empty.
    pub empty: u64,
    /// Its records.
    pub records: LevelRecords,
}

/// The folder, in [`HANDOFF_FOLDER`], of the partitions' records of region metadata (hidden,
/// so listing the hand-over files passes it by).
pub const RECORDS_FOLDER: &str = ".records";

/// The stem of a partition's record files of a level: `I-of-N.LEVEL`.
pub fn records_stem(partition: Partition, level: usize) -> String {
    format!("{}.{level}", partition.file_name())
}

/// Level H's accumulator over a partition's planes: exact sums and counts of level-0 voxels,
/// `[c][z][y][x]` for level-H planes `z0..z0 + depth`.
#[derive(Debug, Serialize, Deserialize)]
#[serde(bound = "")]
pub struct LevelSums<T: Sample> {
    /// First level-H plane.
    pub z0: u64,
    /// Level-H planes held.
    pub depth: u64,
    /// Sums.
    pub sum: Vec<T::Sum>,
    /// Counts of non-NaN voxels.
    pub count: Vec<u32>,
}

/// The file one partition hands to `finalize`.
#[derive(Debug, Serialize, Deserialize)]
#[serde(bound = "")]
pub struct Handoff<T: Sample> {
    /// The levels below the hand-over level.
    pub levels: Vec<LevelPart>,
    /// Whole-channel statistics of this partition's level-0 voxels.
    pub stats: Vec<ChannelAccumulator>,
    /// Level H's sums, when there is a level H.
    pub sums: Option<LevelSums<T>>,
}

/// The untyped head of a hand-over file, read before its sample type is known.
#[derive(Debug, Serialize, Deserialize)]
pub struct HandoffHead {
    /// [`HANDOFF_VERSION`] of the build that wrote it.
    pub version: u32,
    /// Which partition wrote it.
    pub partition: Partition,
    /// The plan it followed.
    pub plan: PartitionPlan,
}

/// A hand-over file that cannot be written, found or read.
#[derive(Debug, thiserror::Error)]
pub enum HandoffError {
    /// A file cannot be written or read.
    #[error("{}: {what}", path.display())]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// What was being done.
        what: &'static str,
        /// What the file system said.
        #[source]
        source: std::io::Error,
    },
    /// A file that is not a hand-over file of this build.
    #[error("{}: not a partition hand-over file of this ingest version: {reason}", path.display())]
    Unreadable {
        /// The file.
        path: PathBuf,
        /// What postcard said.
        reason: String,
    },
    /// No partition has handed anything over.
    #[error(
        "{store}: no partition has finished (no hand-over file in {HANDOFF_FOLDER}/; run `ingest convert --partition I/N -o {store}` first)"
    )]
    NoPartitions {
        /// The store, as the command line names it.
        store: String,
    },
    /// Some partitions have not finished.
    #[error(
        "{store}: partitions {missing} of {count} have not finished (no {HANDOFF_FOLDER}/I-of-{count}); run them, then finalize"
    )]
    Missing {
        /// The store, as the command line names it.
        store: String,
        /// The missing partitions, comma-separated.
        missing: String,
        /// Partitions.
        count: usize,
    },
    /// A partition started in a temporary folder that holds another conversion's partitions.
    #[error("{store}: its temporary folder {} holds partitions of a conversion with other inputs, options or partition count; rerun with the same command line, or remove that folder to start over", partial.display())]
    OtherConversion {
        /// The store, as the command line names it.
        store: String,
        /// The temporary folder.
        partial: PathBuf,
    },
    /// Partitions that followed different plans (other inputs, options or counts).
    #[error("{}: partition {} was converted with other inputs or options than partition {} (rerun it with the same command line)", path.display(), partition, first)]
    Disagree {
        /// The file that differs.
        path: PathBuf,
        /// Its partition.
        partition: Partition,
        /// The first partition's.
        first: Partition,
    },
}

/// Records `plan` as the plan of the partitions writing into `partial` (the temporary folder of
/// the store `shown`), or checks it against the one recorded by the first partition to start,
/// before anything is written: a partition never mixes its bricks with those of a conversion
/// with other inputs or options left there.
///
/// # Errors
/// [`HandoffError::OtherConversion`] when the recorded plan differs, [`HandoffError::Io`] or
/// [`HandoffError::Unreadable`] when it cannot be written or read.
pub fn claim_plan(partial: &Path, shown: &str, plan: &PartitionPlan) -> Result<(), HandoffError> {
    let folder = partial.join(HANDOFF_FOLDER);
    let path = folder.join(PLAN_FILE);
    let unreadable = |e: postcard::Error| HandoffError::Unreadable {
        path: path.clone(),
        reason: e.to_string(),
    };
    let encoded = postcard::to_stdvec(&(HANDOFF_VERSION, plan)).map_err(unreadable)?;
    match std::fs::read(&path) {
        Ok(recorded) if recorded == encoded => Ok(()),
        Ok(_) => Err(HandoffError::OtherConversion {
            store: shown.to_string(),
            partial: partial.to_path_buf(),
        }),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            let io = |what| {
                let path = path.clone();
                move |source| HandoffError::Io { path, what, source }
            };
            std::fs::create_dir_all(&folder).map_err(io("cannot create the folder"))?;
            // Partitions starting together write the same bytes: whichever rename lands last
            // leaves the same plan.
            let tmp = folder.join(format!(".{PLAN_FILE}.{}.partial", std::process::id()));
            std::fs::write(&tmp, &encoded).map_err(io("cannot write"))?;
            std::fs::rename(&tmp, &path).map_err(io("cannot rename into place"))
        }
        Err(source) => Err(HandoffError::Io {
            path,
            what: "cannot read",
            source,
        }),
    }
}

/// Writes a partition's hand-over file into `store`'s [`HANDOFF_FOLDER`], under a temporary
/// name first, so `finalize` never reads half a file.
///
/// # Errors
/// [`HandoffError::Io`] when the folder or the file cannot be written.
pub fn write_handoff<T: Sample>(
    store: &Path,
    partition: Partition,
    plan: &PartitionPlan,
    handoff: &Handoff<T>,
) -> Result<PathBuf, HandoffError> {
    let folder = store.join(HANDOFF_FOLDER);
    let io = |path: &Path, what| {
        let path = path.to_path_buf();
        move |source| HandoffError::Io { path, what, source }
    };
    std::fs::create_dir_all(&folder).map_err(io(&folder, "cannot create the folder"))?;
    let head = HandoffHead {
        version: HANDOFF_VERSION,
        partition,
        plan: plan.clone(),
    };
    let encode = |e: postcard::Error| HandoffError::Unreadable {
        path: folder.clone(),
        reason: e.to_string(),
    };
    let mut bytes = postcard::to_stdvec(&head).map_err(encode)?;
    bytes.extend(postcard::to_stdvec(handoff).map_err(encode)?);
    let path = folder.join(partition.file_name());
    let tmp = folder.join(format!(".{}.partial", partition.file_name()));
    std::fs::write(&tmp, bytes).map_err(io(&tmp, "cannot write"))?;
    std::fs::rename(&tmp, &path).map_err(io(&path, "cannot rename into place"))?;
    Ok(path)
}

/// The hand-over files in `store`, checked: all N partitions present, one plan.
#[derive(Debug)]
pub struct Handoffs {
    /// The plan every partition followed.
    pub plan: PartitionPlan,
    /// The files, in partition order.
    pub files: Vec<PathBuf>,
}

/// The head of the hand-over file at `path`, read without the rest of the file.
fn read_head(path: &Path) -> Result<HandoffHead, HandoffError> {
    let file = std::fs::File::open(path).map_err(|source| HandoffError::Io {
        path: path.to_path_buf(),
        what: "cannot read",
        source,
    })?;
    let unreadable = |reason: String| HandoffError::Unreadable {
        path: path.to_path_buf(),
        reason,
    };
    // Room for the head's longest field (a label or the unit) while it is decoded.
    let mut scratch = vec![0; 1 << 16];
    let (head, _): (HandoffHead, _) =
        postcard::from_io((std::io::BufReader::new(file), &mut scratch))
            .map_err(|e| unreadable(e.to_string()))?;
    if head.version != HANDOFF_VERSION {
        return Err(unreadable(format!(
            "format version {}, this build reads {HANDOFF_VERSION}",
            head.version
        )));
    }
    Ok(head)
}

impl Handoffs {
    /// Finds and checks the hand-over files in `partial` (the temporary folder of the store
    /// `shown`, as messages name it).
    ///
    /// # Errors
    /// [`HandoffError`] when there are none, some are missing, one is unreadable, or they
    /// followed different plans.
    pub fn find(partial: &Path, shown: &str) -> Result<Self, HandoffError> {
        let folder = partial.join(HANDOFF_FOLDER);
        let none = || HandoffError::NoPartitions {
            store: shown.to_string(),
        };
        let entries = match std::fs::read_dir(&folder) {
            Ok(entries) => entries,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Err(none()),
            Err(source) => {
                return Err(HandoffError::Io {
                    path: folder,
                    what: "cannot list",
                    source,
                });
            }
        };
        let mut names: Vec<String> = entries
            .filter_map(Result::ok)
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .filter(|n| !n.starts_with('.') && n != PLAN_FILE)
            .collect();
        names.sort();
        let first_name = names.first().ok_or_else(none)?;
        let first = read_head(&folder.join(first_name))?;
        let count = first.partition.count;
        let mut files = Vec::new();
        let mut missing = Vec::new();
        for index in 0..count {
            let partition = Partition { index, count };
            let path = folder.join(partition.file_name());
            if !path.exists() {
                missing.push(index.to_string());
                continue;
            }
            let head = read_head(&path)?;
            if head.partition != partition || head.plan != first.plan {
                return Err(HandoffError::Disagree {
                    path,
                    partition: head.partition,
                    first: first.partition,
                });
            }
            files.push(path);
        }
        if !missing.is_empty() {
            return Err(HandoffError::Missing {
                store: shown.to_string(),
                missing: missing.join(", "),
                count,
            });
        }
        Ok(Self {
            plan: first.plan,
            files,
        })
    }

    /// Reads partition `index`'s hand-over.
    ///
    /// # Errors
    /// [`HandoffError`] when the file cannot be read or decoded.
    pub fn read<T: Sample>(&self, index: usize) -> Result<Handoff<T>, HandoffError> {
        let path = &self.files[index];
        let bytes = std::fs::read(path).map_err(|source| HandoffError::Io {
            path: path.clone(),
            what: "cannot read",
            source,
        })?;
        let unreadable = |e: postcard::Error| HandoffError::Unreadable {
            path: path.clone(),
            reason: e.to_string(),
        };
        let (_, rest): (HandoffHead, _) = postcard::take_from_bytes(&bytes).map_err(unreadable)?;
        postcard::from_bytes(rest).map_err(unreadable)
    }
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
