//! Volume sources: the inputs `ingest convert` reads, one z-plane at a time.
//!
//! Every input kind (TIFF, OME-TIFF, ImageJ hyperstack, a folder of slices, raw) implements
//! [`VolumeSource`], so the converter streams planes without knowing where they come from.

mod raw;
mod slices;
mod tiff;
mod tiff_metadata;

use std::any::Any;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};

pub use self::raw::{RawOptions, RawSource, parse_raw_name};
pub use self::slices::SliceFolderSource;
pub use self::tiff::TiffSource;

use crate::sample_format::{Sample, SampleFormat};

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
    pub format: SampleFormat,
    /// Physical voxel size `z, y, x`, when the file's metadata gives it.
    pub voxel_size: Option<[f64; 3]>,
    /// Physical unit of `voxel_size` (an OME-Zarr / UDUNITS name such as `micrometer`).
    pub unit: Option<String>,
    /// Channel names from the metadata, when present (one per channel).
    pub channel_names: Vec<String>,
}

/// One decoded z-plane of one channel, `y, x` in C order.
#[derive(Clone, Debug, PartialEq)]
pub enum Plane {
    /// 8-bit unsigned samples.
    U8(Vec<u8>),
    /// 16-bit unsigned samples.
    U16(Vec<u16>),
    /// 16-bit signed samples.
    I16(Vec<i16>),
    /// 32-bit unsigned samples.
    U32(Vec<u32>),
    /// 32-bit signed samples.
    I32(Vec<i32>),
    /// 32-bit float samples.
    F32(Vec<f32>),
}

impl Plane {
    /// Number of samples.
    pub fn len(&self) -> usize {
        match self {
            Plane::U8(v) => v.len(),
            Plane::U16(v) => v.len(),
            Plane::I16(v) => v.len(),
            Plane::U32(v) => v.len(),
            Plane::I32(v) => v.len(),
            Plane::F32(v) => v.len(),
        }
    }

    /// Whether the plane has no samples.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Copies the plane into `out`, converting exactly to `T` when the formats differ
    /// (the converter only asks for promotions that [`SampleFormat::promote`] allows).
    pub fn copy_into<T: Sample>(&self, out: &mut [T]) {
        assert_eq!(out.len(), self.len(), "plane size");
        #[allow(clippy::ptr_arg)]
        fn copy<S: Copy + Into<f64> + 'static, T: Sample>(src: &Vec<S>, out: &mut [T]) {
            if let Some(same) = (src as &dyn Any).downcast_ref::<Vec<T>>() {
                out.copy_from_slice(same);
                return;
            }
            for (o, s) in out.iter_mut().zip(src) {
                *o = T::from_f64((*s).into());
            }
        }
        match self {
            Plane::U8(v) => copy(v, out),
            Plane::U16(v) => copy(v, out),
            Plane::I16(v) => copy(v, out),
            Plane::U32(v) => copy(v, out),
            Plane::I32(v) => copy(v, out),
            Plane::F32(v) => copy(v, out),
        }
    }
}

/// A volume that can be read plane by plane.
pub trait VolumeSource: Send {
    /// Shape, format and metadata of the source.
    fn info(&self) -> &SourceInfo;
    /// Reads the plane at depth `z` of channel `channel`.
    fn read_plane(&mut self, channel: usize, z: u64) -> Result<Plane>;
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
    let lower = input.to_ascii_lowercase();
    if lower.ends_with(".tif") || lower.ends_with(".tiff") || lower.ends_with(".btf") {
        return Ok(Box::new(TiffSource::open(path)?));
    }
    if raw.is_given() || lower.ends_with(".raw") || parse_raw_name(path).is_some() {
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
