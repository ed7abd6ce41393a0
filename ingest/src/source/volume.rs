//! What every input kind implements: [`VolumeSource`], read plane by plane or a rectangle
//! ([`PlaneRegion`]) of a plane at a time, and described by its [`SourceInfo`].

use std::path::PathBuf;

use super::error::SourceError;
use super::mapped::MappedPlane;
use crate::sample_format::{PlaneOut, SampleType};

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

/// A rectangle of a plane: rows `y0..y0 + ny` and columns `x0..x0 + nx`, in voxels.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct PlaneRegion {
    /// First row.
    pub y0: u64,
    /// First column.
    pub x0: u64,
    /// Rows.
    pub ny: u64,
    /// Columns.
    pub nx: u64,
}

impl PlaneRegion {
    /// The whole of a plane of `ny × nx` voxels.
    pub fn whole([ny, nx]: [u64; 2]) -> Self {
        Self {
            y0: 0,
            x0: 0,
            ny,
            nx,
        }
    }

    /// Voxels in the rectangle.
    pub fn area(&self) -> u64 {
        self.ny * self.nx
    }

    /// Whether the rectangle is the whole of a plane of `ny × nx` voxels.
    pub fn is_whole(&self, plane: [u64; 2]) -> bool {
        *self == Self::whole(plane)
    }

    /// The end row and end column (exclusive).
    pub fn end(&self) -> [u64; 2] {
        [self.y0 + self.ny, self.x0 + self.nx]
    }
}

/// A volume that can be read plane by plane, or a rectangle of a plane at a time.
pub trait VolumeSource: Send {
    /// Shape, format and metadata of the source.
    fn info(&self) -> &SourceInfo;
    /// Reads `region` of the plane at depth `z` of channel `channel` into `out` (`ny × nx`
    /// values, row-major). Only what covers the region is read and decoded: the strips or
    /// tiles of a TIFF page it meets, the rows of a raw file it spans.
    ///
    /// # Errors
    /// When the plane cannot be read or decoded, or (TIFF) its page differs from the first
    /// in size or sample format.
    fn read_region(
        &mut self,
        channel: usize,
        z: u64,
        region: PlaneRegion,
        out: PlaneOut<'_>,
    ) -> Result<(), SourceError>;

    /// Bytes this source's decoder holds, besides the destination, while it reads `region` of
    /// a plane: the strips or tiles of a compressed TIFF page, as stored and decoded (a page in
    /// one compressed strip decodes whole, however narrow the region). For the memory limit.
    fn decoder_bytes(&self, region: PlaneRegion) -> u64 {
        let _ = region;
        0
    }

    /// The whole plane at depth `z` of channel `channel` mapped from the source's file, when
    /// the file stores it as it would be read: its samples uncompressed, next to each other,
    /// in `format` and the machine's byte order (see [`MappedPlane`] for samples that do
    /// not start on a multiple of their size). None when it is stored otherwise
    /// (compressed, tiled, with several samples per pixel, in another format or byte order),
    /// or the source has no such file; the plane is then read with
    /// [`VolumeSource::read_region`].
    ///
    /// # Errors
    /// As [`VolumeSource::read_region`], and when the system refuses the mapping.
    fn map_plane(
        &mut self,
        channel: usize,
        z: u64,
        format: SampleType,
    ) -> Result<Option<MappedPlane>, SourceError> {
        let _ = (channel, z, format);
        Ok(None)
    }

    /// Reads the whole plane at depth `z` of channel `channel` into `out`.
    ///
    /// # Errors
    /// As [`VolumeSource::read_region`].
    fn read_plane(&mut self, channel: usize, z: u64, out: PlaneOut<'_>) -> Result<(), SourceError> {
        let [_, ny, nx] = self.info().shape;
        self.read_region(channel, z, PlaneRegion::whole([ny, nx]), out)
    }
}
