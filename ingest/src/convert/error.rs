//! Why a conversion failed ([`ConvertError`]).

use std::path::PathBuf;

use super::sink::ChunkWriteError;
use crate::columns::MemoryEstimate;
use crate::partition::handoff::HandoffError;
use crate::region_writer::RegionWriteError;
use crate::sample_format::SampleType;
use crate::source::SourceError;
use crate::store::StoreError;

/// Why a conversion failed: options that do not fit the inputs, inputs that cannot be read or
/// do not go together, or a store that cannot be written. Messages name the option, input or
/// output at fault; errors of the inputs and the store are theirs, unchanged.
#[derive(Debug, thiserror::Error)]
pub enum ConvertError {
    /// No input.
    #[error("no input given")]
    NoInput,
    /// An input cannot be opened or read.
    #[error(transparent)]
    Source(#[from] SourceError),
    /// Two inputs of different shapes.
    #[error(
        "channels of different shapes: {} is {first_shape:?} (z,y,x) but {} is {shape:?}",
        first.display(), path.display()
    )]
    ShapeMismatch {
        /// The first input.
        first: PathBuf,
        /// Its shape `z, y, x`.
        first_shape: [u64; 3],
        /// The input that differs.
        path: PathBuf,
        /// Its shape `z, y, x`.
        shape: [u64; 3],
    },
    /// An input whose samples no sample type holds exactly together with the others'.
    #[error(
        "{}: {format} samples cannot be stored exactly beside {others} samples of {}",
        path.display(), first.display()
    )]
    IncompatibleSamples {
        /// The input.
        path: PathBuf,
        /// Its sample type.
        format: SampleType,
        /// The sample type of the inputs before it.
        others: SampleType,
        /// The first input.
        first: PathBuf,
    },
    /// A volume without voxels.
    #[error("{}: volume is empty ({shape:?})", path.display())]
    EmptyVolume {
        /// The first input.
        path: PathBuf,
        /// Its shape `z, y, x`.
        shape: [u64; 3],
    },
    /// A `--chunk` edge of 0.
    #[error("--chunk must be positive")]
    ChunkNotPositive,
    /// A `--shard` that is not a whole number of chunks.
    #[error("--shard {shard:?} must be a positive multiple of --chunk {chunk:?}")]
    ShardNotMultiple {
        /// `--shard`, `z, y, x`.
        shard: [u64; 3],
        /// `--chunk`, `z, y, x`.
        chunk: [u64; 3],
    },
    /// `--shard` with OME-Zarr 0.4.
    #[error("--shard needs Zarr v3: use --ome-zarr-version 0.5")]
    ShardNeedsV3,
    /// A brick larger than Blosc compresses.
    #[error(
        "--chunk {requested:?}: a brick of {brick:?} {format} voxels is {bytes} bytes, more than the 2 GiB a Blosc chunk can hold"
    )]
    BrickTooLarge {
        /// `--chunk`, `z, y, x`.
        requested: [u64; 3],
        /// The brick, clamped to the volume.
        brick: [u64; 3],
        /// The sample type.
        format: SampleType,
        /// Bytes of one brick.
        bytes: u64,
    },
    /// A voxel size that is zero, negative or not finite.
    #[error("voxel size {voxel_size:?} must be positive and finite")]
    BadVoxelSize {
        /// The voxel size `z, y, x`.
        voxel_size: [f64; 3],
    },
    /// A conversion that does not fit `--memory-limit` however its planes are cut.
    #[error(
        "{output}: converting needs about {needed} bytes of memory even in the smallest columns ({} for level-0 slabs of {channels} channel(s) × {depth} planes, {} for the coarser levels' sums, {} for the region metadata), more than --memory-limit {limit} bytes; allow more memory, or a smaller z edge of --chunk (and --shard) needs less",
        estimate.slabs, estimate.pyramid, estimate.regions
    )]
    MemoryLimit {
        /// The output, as given.
        output: String,
        /// The estimate of the smallest columns.
        estimate: MemoryEstimate,
        /// Its total.
        needed: u64,
        /// Channels.
        channels: usize,
        /// Planes per slab.
        depth: u64,
        /// The limit in bytes.
        limit: u64,
    },
    /// The output store cannot be created or written.
    #[error(transparent)]
    Store(#[from] StoreError),
    /// The region metadata cannot be written.
    #[error(transparent)]
    Regions(#[from] RegionWriteError),
    /// A chunk of level 0 cannot be written.
    #[error("{}: writing level 0", path.display())]
    WriteLevel0 {
        /// The output.
        path: PathBuf,
        /// The chunk and why.
        #[source]
        source: ChunkWriteError,
    },
    /// The thread reading the inputs panicked.
    #[error("reader thread panicked")]
    ReaderPanicked,
    /// A value that cannot be serialised as JSON.
    #[error(transparent)]
    Json(#[from] serde_json::Error),
    /// A partition's hand-over file cannot be written, or `finalize` cannot use them.
    #[error(transparent)]
    Handoff(#[from] HandoffError),
}
