//! Volume sources: the inputs `ingest convert` reads, one z-plane at a time.
//!
//! Every input kind (TIFF, OME-TIFF, ImageJ hyperstack, a folder of slices, raw) implements
//! [`VolumeSource`], so the converter streams planes without knowing where they come from.

mod raw;
mod slices;
mod tiff;
mod tiff_claims;
mod tiff_metadata;

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};

pub use self::raw::{RawOptions, RawSource, parse_raw_name};
pub use self::slices::SliceFolderSource;
pub use self::tiff::TiffSource;

use crate::sample_format::{Sample, SampleType};
use crate::with_sample_type;

/// What a source holds, known before any plane is read.
#[derive(Clone, Debug, PartialEq)]
pub struct SourceInfo {
    /// The file or folder the source reads, for messages.
    pub path: PathBuf,
    /// Extent `z, y, x` in voxels.
    pub shape: [u64; 3],
    /// Number of channels in this source.
    pub channels: usize,
    /// Sample format of every channel.
    pub format: SampleType,
    /// Physical voxel size `z, y, x`, when the file's metadata gives it.
    pub voxel_size: Option<[f64; 3]>,
    /// Physical unit of `voxel_size` (an OME-Zarr / UDUNITS name such as `micrometer`).
    pub unit: Option<String>,
    /// Channel names from the metadata, when present (one per channel).
    pub channel_names: Vec<String>,
}

/// Where a source writes one z-plane of one channel (`y, x` in C order): a slice of the
/// converter's sample type, which the source fills converting exactly from its own format.
pub enum PlaneOut<'a> {
    /// 8-bit unsigned destination.
    U8(&'a mut [u8]),
    /// 16-bit unsigned destination.
    U16(&'a mut [u16]),
    /// 16-bit signed destination.
    I16(&'a mut [i16]),
    /// 32-bit unsigned destination.
    U32(&'a mut [u32]),
    /// 32-bit signed destination.
    I32(&'a mut [i32]),
    /// 32-bit float destination.
    F32(&'a mut [f32]),
}

impl PlaneOut<'_> {
    /// Number of samples to write.
    pub fn len(&self) -> usize {
        match self {
            PlaneOut::U8(v) => v.len(),
            PlaneOut::U16(v) => v.len(),
            PlaneOut::I16(v) => v.len(),
            PlaneOut::U32(v) => v.len(),
            PlaneOut::I32(v) => v.len(),
            PlaneOut::F32(v) => v.len(),
        }
    }

    /// Whether there is nothing to write.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Fills the destination from packed samples of `format` in `bytes`: sample `sample` of
    /// every pixel of `samples` interleaved samples. Values are converted exactly (the
    /// converter only asks for promotions that [`SampleType::promote`] allows).
    pub fn fill_from_bytes(
        &mut self,
        bytes: &[u8],
        format: SampleType,
        big_endian: bool,
        samples: usize,
        sample: usize,
    ) {
        fn fill<S: Sample, T: Sample>(
            bytes: &[u8],
            big_endian: bool,
            samples: usize,
            sample: usize,
            out: &mut [T],
        ) {
            let w = S::FORMAT.bytes();
            let stride = w * samples;
            assert_eq!(bytes.len(), out.len() * stride, "decoded plane size");
            let pixels = bytes.chunks_exact(stride);
            if S::FORMAT == T::FORMAT {
                // Same format: decode the bytes as the destination type, bit for bit.
                for (o, px) in out.iter_mut().zip(pixels) {
                    *o = T::from_bytes(&px[sample * w..(sample + 1) * w], big_endian);
                }
            } else {
                for (o, px) in out.iter_mut().zip(pixels) {
                    let s = S::from_bytes(&px[sample * w..(sample + 1) * w], big_endian);
                    *o = T::from_f64(s.to_f64());
                }
            }
        }
        macro_rules! dispatch {
            ($out:expr) => {
                with_sample_type!(format, S => fill::<S, _>(bytes, big_endian, samples, sample, $out))
            };
        }
        match self {
            PlaneOut::U8(v) => dispatch!(v),
            PlaneOut::U16(v) => dispatch!(v),
            PlaneOut::I16(v) => dispatch!(v),
            PlaneOut::U32(v) => dispatch!(v),
            PlaneOut::I32(v) => dispatch!(v),
            PlaneOut::F32(v) => dispatch!(v),
        }
    }
}

/// A volume that can be read plane by plane.
pub trait VolumeSource: Send {
    /// Shape, format and metadata of the source.
    fn info(&self) -> &SourceInfo;
    /// Reads the plane at depth `z` of channel `channel` into `out`.
    fn read_plane(&mut self, channel: usize, z: u64, out: PlaneOut<'_>) -> Result<()>;
}

/// How to interpret an `INPUT` argument of `ingest convert`.
pub fn open_input(input: &str, raw: &RawOptions) -> Result<Box<dyn VolumeSource>> {
    let path = Path::new(input);
    if input.contains(['*', '?', '[']) && !path.exists() {
        return Ok(Box::new(SliceFolderSource::from_glob(input)?));
    }
    if !path.exists() {
        bail!("{input}: no such file or directory");
    }
    if path.is_dir() {
        return Ok(Box::new(SliceFolderSource::from_dir(path)?));
    }
    let extension = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase());
    if matches!(extension.as_deref(), Some("tif" | "tiff" | "btf")) {
        return Ok(Box::new(TiffSource::open(path)?));
    }
    if raw.is_given() || extension.as_deref() == Some("raw") || parse_raw_name(path).is_some() {
        return Ok(Box::new(RawSource::open(path, raw)?));
    }
    // Fall back on content: TIFF files start with II* / MM*.
    let mut magic = [0u8; 4];
    use std::io::Read;
    std::fs::File::open(path)
        .with_context(|| format!("{input}: cannot open"))?
        .read_exact(&mut magic)
        .with_context(|| format!("{input}: file too short to identify"))?;
    if &magic[..2] == b"II" || &magic[..2] == b"MM" {
        return Ok(Box::new(TiffSource::open(path)?));
    }
    bail!(
        "{input}: unknown input kind: expected a TIFF file, a folder or glob of TIFF slices, or a raw file (name_XxYxZ_dtype.raw, or --dims/--dtype)"
    )
}
