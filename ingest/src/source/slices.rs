//! A z-stack stored as one single-page TIFF file per slice, in natural sort order.

use std::fs::File;
use std::io::BufReader;
use std::path::{Path, PathBuf};

use tiff::decoder::Decoder;

use super::error::SourceError;
use super::mapped::MappedPlane;
use super::tiff::{
    DecodeUnit, DecodedRegion, TiffFile, check_page, map_page, open_decoder, page_format,
};
use super::volume::{PlaneRegion, SourceInfo, VolumeSource};
use crate::sample_format::{PlaneOut, SampleType};

/// A folder or glob of single-slice TIFF files.
pub struct SliceFolderSource {
    info: SourceInfo,
    files: Vec<PathBuf>,
    samples_per_pixel: usize,
    /// The slice and region decoded last.
    decoded: DecodedRegion,
    /// What decoding the first slice holds (the slices are taken to be alike).
    unit: DecodeUnit,
}

fn is_tiff(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| matches!(e.to_ascii_lowercase().as_str(), "tif" | "tiff"))
}

impl SliceFolderSource {
    /// Every `.tif`/`.tiff` file in `dir`, in natural order (`z2` before `z10`).
    ///
    /// # Errors
    /// When the folder cannot be listed or holds no TIFF file, or the first slice cannot be
    /// opened or claims more than its file or the machine can hold.
    pub fn from_dir(dir: &Path) -> Result<Self, SourceError> {
        let files = std::fs::read_dir(dir)
            .map_err(|source| SourceError::ListFolder {
                path: dir.to_path_buf(),
                source,
            })?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.is_file() && is_tiff(p))
            .collect();
        Self::from_files(dir, files)
    }

    /// Every file matching a glob pattern, in natural order.
    ///
    /// # Errors
    /// When the pattern is invalid or matches no file, or the first slice cannot be opened or
    /// claims more than its file or the machine can hold.
    pub fn from_glob(pattern: &str) -> Result<Self, SourceError> {
        let files = glob::glob(pattern)
            .map_err(|source| SourceError::BadGlob {
                pattern: pattern.to_string(),
                source,
            })?
            .filter_map(Result::ok)
            .filter(|p| p.is_file())
            .collect();
        Self::from_files(Path::new(pattern), files)
    }

    fn from_files(origin: &Path, mut files: Vec<PathBuf>) -> Result<Self, SourceError> {
        files.sort_by(|a, b| natord::compare(&a.to_string_lossy(), &b.to_string_lossy()));
        let first = files.first().ok_or_else(|| SourceError::NoSlices {
            path: origin.to_path_buf(),
        })?;
        let (mut decoder, tiff) = open_decoder(first)?;
        let (w, h) = decoder
            .dimensions()
            .map_err(|source| SourceError::ImageSize {
                path: first.clone(),
                source,
            })?;
        let (format, samples_per_pixel) = page_format(&mut decoder, first)?;
        // The shape comes from the first slice: check it can hold the plane it claims.
        let unit = check_page(&mut decoder, first, 0, tiff, format, samples_per_pixel)?;
        Ok(Self {
            info: SourceInfo {
                path: origin.to_path_buf(),
                shape: [files.len() as u64, h as u64, w as u64],
                channels: samples_per_pixel,
                format,
                voxel_size: None,
                unit: None,
                channel_names: Vec::new(),
            },
            files,
            samples_per_pixel,
            decoded: DecodedRegion::default(),
            unit,
        })
    }
}

impl SliceFolderSource {
    /// Opens slice `z`, once it is found to be of the first slice's size and sample format;
    /// returns its decoder, what its claims are checked against, and that format.
    fn open_slice(
        &self,
        z: u64,
    ) -> Result<(Decoder<BufReader<File>>, TiffFile, SampleType), SourceError> {
        let file = &self.files[z as usize];
        let (mut decoder, tiff) = open_decoder(file)?;
        let (w, h) = decoder.dimensions().map_err(SourceError::Tiff)?;
        let [_, ey, ex] = self.info.shape;
        if (h as u64, w as u64) != (ey, ex) {
            return Err(SourceError::SliceSize {
                path: file.clone(),
                width: w,
                height: h,
                first: self.files[0].clone(),
                expected: [ey, ex],
            });
        }
        let (format, spp) = page_format(&mut decoder, file)?;
        if (format, spp) != (self.info.format, self.samples_per_pixel) {
            return Err(SourceError::SliceFormat {
                path: file.clone(),
                samples: spp,
                format,
                first: self.files[0].clone(),
                expected_samples: self.samples_per_pixel,
                expected_format: self.info.format,
            });
        }
        Ok((decoder, tiff, format))
    }
}

impl VolumeSource for SliceFolderSource {
    fn info(&self) -> &SourceInfo {
        &self.info
    }

    fn decoder_bytes(&self, _region: PlaneRegion) -> u64 {
        self.unit.bytes()
    }

    fn map_plane(
        &mut self,
        _channel: usize,
        z: u64,
        format: SampleType,
    ) -> Result<Option<MappedPlane>, SourceError> {
        if self.samples_per_pixel != 1 || format != self.info.format {
            return Ok(None);
        }
        let (mut decoder, tiff, _) = self.open_slice(z)?;
        let [_, ny, nx] = self.info.shape;
        let path = &self.files[z as usize];
        Ok(map_page(&mut decoder, path, tiff, [ny, nx], format))
    }

    fn read_region(
        &mut self,
        channel: usize,
        z: u64,
        region: PlaneRegion,
        mut out: PlaneOut<'_>,
    ) -> Result<(), SourceError> {
        let file = &self.files[z as usize];
        if !self.decoded.holds(z, region) {
            let (mut decoder, tiff, format) = self.open_slice(z)?;
            let [_, ey, ex] = self.info.shape;
            let spp = self.samples_per_pixel;
            self.decoded.decode(
                z,
                &mut decoder,
                file,
                0,
                tiff,
                (format, spp),
                [ey, ex],
                region,
                None,
            )?;
        }
        self.decoded
            .fill(&mut out, self.info.format, self.samples_per_pixel, channel);
        Ok(())
    }
}
