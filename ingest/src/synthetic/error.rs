//! Why a sample cannot be written ([`SampleError`]), and the limit on its channels it names.

use std::io;
use std::path::PathBuf;

/// Most channels a sample may have (each is one open file while it is written).
pub const MAX_SAMPLE_CHANNELS: usize = 64;

/// Why a sample cannot be written: a [`SampleSpec`](super::SampleSpec) out of range (the
/// message names the option, `--size` or `--channels`), or a file that cannot be written (it
/// names the file).
#[derive(Debug, thiserror::Error)]
pub enum SampleError {
    /// An extent of 0.
    #[error(
        "--size {},{},{}: every extent must be at least 1 voxel",
        shape[0], shape[1], shape[2]
    )]
    EmptyExtent {
        /// Extent `z, y, x`.
        shape: [u64; 3],
    },
    /// A plane wider or higher than a TIFF page can be.
    #[error(
        "--size {},{},{}: a TIFF page holds at most {} pixels per side",
        shape[0], shape[1], shape[2], u32::MAX
    )]
    PageTooLarge {
        /// Extent `z, y, x`.
        shape: [u64; 3],
    },
    /// A channel count other than 3 for the fluorescence sample.
    #[error(
        "--channels {channels}: the fluorescence sample has exactly 3 channels (nuclei, membranes, filaments); use --kind cycif for many channels"
    )]
    FluorescenceChannels {
        /// The count asked for.
        channels: usize,
    },
    /// A channel count outside `1..=MAX_SAMPLE_CHANNELS`.
    #[error("--channels {channels}: must be between 1 and {MAX_SAMPLE_CHANNELS}")]
    ChannelCount {
        /// The count asked for.
        channels: usize,
    },
    /// Planes too large to hold a few of every channel in memory.
    #[error(
        "--size {},{},{}: planes of {}×{} pixels × {channels} channels do not fit in memory",
        shape[0], shape[1], shape[2], shape[1], shape[2]
    )]
    PlanesTooLarge {
        /// Extent `z, y, x`.
        shape: [u64; 3],
        /// Channels.
        channels: usize,
    },
    /// The output folder cannot be created.
    #[error("{}: cannot create folder", path.display())]
    CreateFolder {
        /// The folder.
        path: PathBuf,
        /// What the file system said.
        #[source]
        source: io::Error,
    },
    /// A channel file cannot be created.
    #[error("{}: cannot create", path.display())]
    CreateFile {
        /// The file (its temporary name).
        path: PathBuf,
        /// What the file system said.
        #[source]
        source: io::Error,
    },
    /// The TIFF encoder cannot start a channel file.
    #[error("{}: cannot start TIFF", path.display())]
    StartTiff {
        /// The file (its temporary name).
        path: PathBuf,
        /// What the encoder said.
        #[source]
        source: tiff::TiffError,
    },
    /// A page cannot be written.
    #[error("{}: cannot write", path.display())]
    WritePage {
        /// The file.
        path: PathBuf,
        /// What the encoder said.
        #[source]
        source: tiff::TiffError,
    },
    /// A finished channel file cannot be renamed to its final name.
    #[error("{}: cannot move into place", path.display())]
    MoveIntoPlace {
        /// The file's final name.
        path: PathBuf,
        /// What the file system said.
        #[source]
        source: io::Error,
    },
}
