//! Volume sources: the inputs `ingest convert` reads, one z-plane at a time.
//!
//! Every input kind (TIFF, OME-TIFF, ImageJ hyperstack, a folder of slices, raw) implements
//! [`VolumeSource`], so the converter streams planes without knowing where they come from.
//!
//! The modules below this one: [`error`](SourceError), [`volume`](VolumeSource) and
//! [`mapped`](MappedPlane), which the input kinds use, then the kinds: `tiff` (with `tiff_claims` and `tiff_metadata`),
//! `slices` and `raw`. This module only opens an input as the kind it is ([`open_input`]).

mod error;
mod mapped;
mod raw;
mod slices;
mod tiff;
mod tiff_claims;
mod tiff_metadata;
mod volume;

use std::path::Path;

pub use self::error::{PlaneClaim, SourceError, TiffDirectoryError};
pub use self::mapped::MappedPlane;
pub use self::raw::{RawOptions, RawSource, parse_raw_name};
pub use self::slices::SliceFolderSource;
pub use self::tiff::TiffSource;
pub use self::tiff_metadata::OmeXmlError;
pub use self::volume::{PlaneRegion, SourceInfo, VolumeSource};
/// Where a source writes a plane: defined with the sample types it holds, named here too
/// because every [`VolumeSource`] takes one.
pub use crate::sample_format::PlaneOut;

/// How to interpret an `INPUT` argument of `ingest convert`.
///
/// # Errors
/// When the input does not exist, is of no kind ingest reads, or cannot be opened as the kind
/// it is (see [`TiffSource::open`], [`SliceFolderSource::from_dir`],
/// [`SliceFolderSource::from_glob`] and [`RawSource::open`]).
pub fn open_input(input: &str, raw: &RawOptions) -> Result<Box<dyn VolumeSource>, SourceError> {
    let path = Path::new(input);
    if input.contains(['*', '?', '[']) && !path.exists() {
        return Ok(Box::new(SliceFolderSource::from_glob(input)?));
    }
    if !path.exists() {
        return Err(SourceError::NotFound {
            input: input.to_string(),
        });
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
        .map_err(|source| SourceError::Open {
            path: path.to_path_buf(),
            source,
        })?
        .read_exact(&mut magic)
        .map_err(|source| SourceError::TooShort {
            path: path.to_path_buf(),
            source,
        })?;
    if &magic[..2] == b"II" || &magic[..2] == b"MM" {
        return Ok(Box::new(TiffSource::open(path)?));
    }
    Err(SourceError::UnknownKind {
        input: input.to_string(),
    })
}
