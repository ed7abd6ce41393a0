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
mod error;
mod fluorescence;
mod noise;
mod ome_tiff;
mod sparse;

use std::path::{Path, PathBuf};

pub use residency_schemas::SampleKind;

pub use self::cycif::CYCIF_VOXEL_SIZE;
pub use self::error::{MAX_SAMPLE_CHANNELS, SampleError};
pub use self::fluorescence::{SAMPLE_CHANNELS, SAMPLE_VOXEL_SIZE, SampleScene};
use self::ome_tiff::{Scene, write_scene};

/// Extent `z, y, x` of a `kind` sample when `--size` is not given.
fn default_shape(kind: SampleKind) -> [u64; 3] {
    match kind {
        SampleKind::Fluorescence => [96, 256, 256],
        SampleKind::Sparse | SampleKind::Dense | SampleKind::Mixing => [256, 256, 256],
        SampleKind::Cycif => [24, 256, 256],
    }
}

/// Channel count of a `kind` sample when `--channels` is not given.
fn default_channels(kind: SampleKind) -> usize {
    match kind {
        SampleKind::Fluorescence => 3,
        SampleKind::Sparse | SampleKind::Dense | SampleKind::Mixing => 1,
        SampleKind::Cycif => 16,
    }
}

/// Physical voxel size `z, y, x` of a `kind` sample, in micrometres.
fn voxel_size(kind: SampleKind) -> [f64; 3] {
    match kind {
        SampleKind::Fluorescence => SAMPLE_VOXEL_SIZE,
        SampleKind::Sparse | SampleKind::Dense | SampleKind::Mixing => [1.0; 3],
        SampleKind::Cycif => CYCIF_VOXEL_SIZE,
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
            shape: default_shape(kind),
            channels: default_channels(kind),
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
    debug_assert_eq!(scene.voxel_size(), voxel_size(kind));
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
    use strum::VariantArray;

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
        for &kind in SampleKind::VARIANTS {
            SampleSpec::new(kind).validate().unwrap();
        }
        let names: Vec<&str> = SampleKind::VARIANTS.iter().map(|&k| k.into()).collect();
        assert_eq!(
            names,
            ["fluorescence", "sparse", "dense", "mixing", "cycif"]
        );
        assert_eq!(SampleKind::Cycif.to_string(), "cycif");
    }
}
