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
//! **What a partition hands over** (`handoff::Handoff`): for each level below H, its bricks'
//! written and empty counts, and where its records of min/max cell rows and brick histograms are
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
//!
//! The modules: `plan` (which partition, where they cut, what they agree on) and `handoff`
//! (what a partition leaves for `finalize`). The entry points, which run the conversion's
//! pass, are beside it: [`crate::convert::convert_partition`] and [`crate::convert::finalize`].

pub(crate) mod handoff;
pub(crate) mod plan;

pub use self::handoff::{HANDOFF_FOLDER, HandoffError, UnreadableHandoff};
pub use self::plan::{Partition, PartitionParseError};
