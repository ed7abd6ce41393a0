//! What a partition hands to `finalize`: the hand-over files ([`Handoff`]) under
//! [`HANDOFF_FOLDER`], the plan the first partition recorded there, and the records of region
//! metadata beside them.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::plan::{Partition, PartitionPlan};
use crate::region_scratch::LevelRecords;
use crate::regions::ChannelAccumulator;
use crate::sample_format::Sample;

/// The folder, under a store's root, where partitions leave their hand-over files.
pub const HANDOFF_FOLDER: &str = ".partitions";

/// Bumped whenever [`Handoff`] changes: `finalize` refuses files of another version.
const HANDOFF_VERSION: u32 = 2;

/// The file under [`HANDOFF_FOLDER`] holding the plan the first partition to start followed.
const PLAN_FILE: &str = "plan";

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
    /// Counts of non-NaN voxels (empty for sample types without NaN, whose counts follow
    /// from the geometry).
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
    #[error("{}: not a partition hand-over file of this ingest version", path.display())]
    Unreadable {
        /// The file.
        path: PathBuf,
        /// What is wrong with it.
        #[source]
        source: UnreadableHandoff,
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

/// Why a file is not a hand-over file (or plan) this build reads or writes.
#[derive(Debug, thiserror::Error)]
pub enum UnreadableHandoff {
    /// It does not decode (or a value does not encode).
    #[error(transparent)]
    Postcard(#[from] postcard::Error),
    /// It was written by a build with another format version.
    #[error("format version {found}, this build reads {HANDOFF_VERSION}")]
    Version {
        /// The version it was written with.
        found: u32,
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
        source: e.into(),
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
        source: e.into(),
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
    let unreadable = |source: UnreadableHandoff| HandoffError::Unreadable {
        path: path.to_path_buf(),
        source,
    };
    // Room for the head's longest field (a label or the unit) while it is decoded.
    let mut scratch = vec![0; 1 << 16];
    let (head, _): (HandoffHead, _) =
        postcard::from_io((std::io::BufReader::new(file), &mut scratch))
            .map_err(|e| unreadable(e.into()))?;
    if head.version != HANDOFF_VERSION {
        return Err(unreadable(UnreadableHandoff::Version {
            found: head.version,
        }));
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
            source: e.into(),
        };
        let (_, rest): (HandoffHead, _) = postcard::take_from_bytes(&bytes).map_err(unreadable)?;
        postcard::from_bytes(rest).map_err(unreadable)
    }
}
