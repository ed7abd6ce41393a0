//! `ingest sample`: deterministic synthetic volumes, generated plane by plane, written as one
//! BigTIFF OME-TIFF per channel so they exercise the TIFF path of `ingest convert`.
//!
//! Five kinds of specimen, each in the spirit of a data set that volume renderers are judged on:
//!
//! - [`SampleKind::Fluorescence`] (the default): a cleared-tissue light-sheet acquisition. An
//!   ellipsoidal piece of tissue floats in mostly empty space; a 16-bit nuclear stain shows
//!   round nuclei, two 8-bit channels show the cell membranes around them and thin filaments.
//!   Camera noise only inside the tissue, z steps 4× the pixel size (2 µm and 0.5 µm).
//! - [`SampleKind::Sparse`]: a micro-CT scan of a small skeleton, like the Kingsnake and
//!   Beechnut scans: a coiled, hollow spine with thin branching ribs and a few small dense
//!   blobs, in air that is exactly 0. Only a few percent of the voxels hold anything, so most
//!   bricks are empty. 16-bit, isotropic 1 µm voxels.
//! - [`SampleKind::Dense`]: a fluid simulation, like the Rayleigh–Taylor instability: a heavy
//!   fluid sinking into a light one through a turbulent mixing layer. Every voxel holds a
//!   positive density and every region varies, so nothing can be skipped. 32-bit float,
//!   isotropic voxels.
//! - [`SampleKind::Mixing`]: the same fluids, closer to the Rayleigh–Taylor data set the
//!   residency-octree paper measures: outside the mixing layer the fluids are pure, so their
//!   regions are exactly constant.
//! - [`SampleKind::Cycif`]: a thin tissue section stained in many cycles of multiplexed
//!   immunofluorescence (CyCIF): cells packed in the xy plane, one channel per antibody, each
//!   bright in the nuclei, membranes or cytoplasm of its own subset of cells, near-zero noisy
//!   background between them. 16-bit, 1 µm z steps and 0.325 µm pixels.
//!
//! Extra channels of the sparse and dense samples are the same volume through different
//! transfer functions (like the residency-octree paper's "simulated channels"); extra cycif
//! channels are further markers. Every voxel is a pure function of the seed and its position,
//! so planes are rendered in parallel and the files are the same, byte for byte, on every run;
//! only a few planes are in memory at a time.

mod cycif;
mod dense;
mod fluorescence;
mod noise;
mod ome_tiff;
mod sparse;

use std::fmt;
use std::io;
use std::path::{Path, PathBuf};

pub use self::cycif::CYCIF_VOXEL_SIZE;
pub use self::fluorescence::{SAMPLE_CHANNELS, SAMPLE_VOXEL_SIZE, SampleScene};
use self::ome_tiff::{Scene, write_scene};

/// Most channels a sample may have (each is one open file while it is written).
pub const MAX_SAMPLE_CHANNELS: usize = 64;

/// Why a sample cannot be written: a [`SampleSpec`] out of range (the message names the
/// option, `--size` or `--channels`), or a file that cannot be written (it names the file).
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

/// Which synthetic specimen `ingest sample` writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SampleKind {
    /// Cleared-tissue light-sheet stack: nuclei (uint16), membranes and filaments (uint8).
    Fluorescence,
    /// Micro-CT of a coiled skeleton in empty space (uint16), mostly exactly 0.
    Sparse,
    /// Rayleigh–Taylor-like mixing fluids (float32) filling the whole volume, no region
    /// constant.
    Dense,
    /// Rayleigh–Taylor-like mixing fluids (float32), pure (constant) outside the mixing layer.
    Mixing,
    /// Multiplexed immunofluorescence of a thin tissue section (uint16), many markers.
    Cycif,
}

impl SampleKind {
    /// Every kind, in the order `--kind` lists them.
    pub const ALL: [SampleKind; 5] = [
        Self::Fluorescence,
        Self::Sparse,
        Self::Dense,
        Self::Mixing,
        Self::Cycif,
    ];

    /// The name `--kind` takes.
    pub fn name(self) -> &'static str {
        match self {
            Self::Fluorescence => "fluorescence",
            Self::Sparse => "sparse",
            Self::Dense => "dense",
            Self::Mixing => "mixing",
            Self::Cycif => "cycif",
        }
    }

    /// Extent `z, y, x` when `--size` is not given.
    pub fn default_shape(self) -> [u64; 3] {
        match self {
            Self::Fluorescence => [96, 256, 256],
            Self::Sparse | Self::Dense | Self::Mixing => [256, 256, 256],
            Self::Cycif => [24, 256, 256],
        }
    }

    /// Channel count when `--channels` is not given.
    pub fn default_channels(self) -> usize {
        match self {
            Self::Fluorescence => 3,
            Self::Sparse | Self::Dense | Self::Mixing => 1,
            Self::Cycif => 16,
        }
    }

    /// Physical voxel size `z, y, x` in micrometres.
    pub fn voxel_size(self) -> [f64; 3] {
        match self {
            Self::Fluorescence => SAMPLE_VOXEL_SIZE,
            Self::Sparse | Self::Dense | Self::Mixing => [1.0; 3],
            Self::Cycif => CYCIF_VOXEL_SIZE,
        }
    }
}

impl fmt::Display for SampleKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// What `ingest sample` generates: kind, extent, channel count and seed.
#[derive(Clone, Debug, PartialEq)]
pub struct SampleSpec {
    /// The specimen.
    pub kind: SampleKind,
    /// Extent `z, y, x` in voxels.
    pub shape: [u64; 3],
    /// Number of channels (one file each).
    pub channels: usize,
    /// Seed of every random choice.
    pub seed: u64,
}

impl SampleSpec {
    /// The kind's default extent and channel count, seed 1.
    pub fn new(kind: SampleKind) -> Self {
        Self {
            kind,
            shape: kind.default_shape(),
            channels: kind.default_channels(),
            seed: 1,
        }
    }

    /// Checks the extent and channel count, with an error saying what is allowed.
    ///
    /// # Errors
    /// When an extent is 0, a plane is wider or higher than a TIFF page can be, the channel
    /// count does not suit the kind, or planes of every channel would not fit in memory.
    pub fn validate(&self) -> Result<(), SampleError> {
        let shape = self.shape;
        let [_, y, x] = shape;
        if shape.contains(&0) {
            return Err(SampleError::EmptyExtent { shape });
        }
        if y > u64::from(u32::MAX) || x > u64::from(u32::MAX) {
            return Err(SampleError::PageTooLarge { shape });
        }
        let n = self.channels;
        if self.kind == SampleKind::Fluorescence && n != 3 {
            return Err(SampleError::FluorescenceChannels { channels: n });
        }
        if !(1..=MAX_SAMPLE_CHANNELS).contains(&n) {
            return Err(SampleError::ChannelCount { channels: n });
        }
        // A few planes of every channel are held at once (4 bytes per sample at most).
        let plane_bytes = y
            .checked_mul(x)
            .and_then(|p| p.checked_mul(4 * n as u64))
            .filter(|&b| b <= isize::MAX as u64 / 16);
        if plane_bytes.is_none() {
            return Err(SampleError::PlanesTooLarge { shape, channels: n });
        }
        Ok(())
    }
}

/// Writes the sample described by `spec` into `dir`, one OME-TIFF per channel, and returns the
/// file paths in channel order.
///
/// # Errors
/// When `spec` is out of range ([`SampleSpec::validate`]), or a file cannot be written.
pub fn write_samples(
    dir: &Path,
    spec: &SampleSpec,
    progress: bool,
) -> Result<Vec<PathBuf>, SampleError> {
    spec.validate()?;
    let SampleSpec {
        kind,
        shape,
        channels,
        seed,
    } = *spec;
    let scene: Box<dyn Scene> = match kind {
        SampleKind::Fluorescence => Box::new(SampleScene::new(shape, seed)),
        SampleKind::Sparse => Box::new(sparse::SparseScene::new(shape, channels, seed)),
        SampleKind::Dense | SampleKind::Mixing => {
            let fluids = if kind == SampleKind::Mixing {
                dense::Fluids::Pure
            } else {
                dense::Fluids::Stratified
            };
            Box::new(dense::DenseScene::new(shape, channels, seed, fluids))
        }
        SampleKind::Cycif => Box::new(cycif::CycifScene::new(shape, channels, seed)),
    };
    debug_assert_eq!(scene.voxel_size(), kind.voxel_size());
    write_scene(dir, scene.as_ref(), progress)
}

/// Writes the fluorescence sample stack of `shape` into `dir`, one OME-TIFF per channel, and
/// returns the file paths in channel order.
///
/// # Errors
/// As [`write_samples`].
pub fn write_sample(
    dir: &Path,
    shape: [u64; 3],
    seed: u64,
    progress: bool,
) -> Result<Vec<PathBuf>, SampleError> {
    let spec = SampleSpec {
        shape,
        seed,
        ..SampleSpec::new(SampleKind::Fluorescence)
    };
    write_samples(dir, &spec, progress)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn specs_are_checked_with_clear_errors() {
        let spec = |kind, shape, channels| SampleSpec {
            kind,
            shape,
            channels,
            seed: 1,
        };
        let error = |s: SampleSpec| s.validate().unwrap_err().to_string();
        assert_eq!(
            error(spec(SampleKind::Fluorescence, [8, 16, 16], 4)),
            "--channels 4: the fluorescence sample has exactly 3 channels (nuclei, membranes, \
             filaments); use --kind cycif for many channels"
        );
        assert_eq!(
            error(spec(SampleKind::Cycif, [8, 16, 16], 0)),
            "--channels 0: must be between 1 and 64"
        );
        assert_eq!(
            error(spec(SampleKind::Sparse, [8, 16, 16], 65)),
            "--channels 65: must be between 1 and 64"
        );
        assert_eq!(
            error(spec(SampleKind::Dense, [8, 0, 16], 1)),
            "--size 8,0,16: every extent must be at least 1 voxel"
        );
        assert_eq!(
            error(spec(SampleKind::Dense, [1, 1 << 32, 1], 1)),
            "--size 1,4294967296,1: a TIFF page holds at most 4294967295 pixels per side"
        );
        assert_eq!(
            error(spec(SampleKind::Cycif, [1, 1 << 31, 1 << 31], 16)),
            "--size 1,2147483648,2147483648: planes of 2147483648×2147483648 pixels × 16 \
             channels do not fit in memory"
        );
        for kind in SampleKind::ALL {
            SampleSpec::new(kind).validate().unwrap();
        }
    }
}
