//! A z-stack stored as one single-page TIFF file per slice, in natural sort order.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};

use super::tiff::{NATIVE_BIG_ENDIAN, check_page, decode_page, open_decoder, page_format};
use super::{PlaneOut, SourceInfo, VolumeSource};

/// A folder or glob of single-slice TIFF files.
pub struct SliceFolderSource {
    info: SourceInfo,
    files: Vec<PathBuf>,
    samples_per_pixel: usize,
    /// Slice decoded in `page`.
    cached: Option<u64>,
    page: Vec<u8>,
}

fn is_tiff(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| matches!(e.to_ascii_lowercase().as_str(), "tif" | "tiff"))
}

impl SliceFolderSource {
    /// Every `.tif`/`.tiff` file in `dir`, in natural order (`z2` before `z10`).
    pub fn from_dir(dir: &Path) -> Result<Self> {
        let files = std::fs::read_dir(dir)
            .with_context(|| format!("{}: cannot list folder", dir.display()))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.is_file() && is_tiff(p))
            .collect();
        Self::from_files(dir, files)
    }

    /// Every file matching a glob pattern, in natural order.
    pub fn from_glob(pattern: &str) -> Result<Self> {
        let files = glob::glob(pattern)
            .with_context(|| format!("{pattern}: invalid glob pattern"))?
            .filter_map(Result::ok)
            .filter(|p| p.is_file())
            .collect();
        Self::from_files(Path::new(pattern), files)
    }

    fn from_files(origin: &Path, mut files: Vec<PathBuf>) -> Result<Self> {
        files.sort_by(|a, b| natord::compare(&a.to_string_lossy(), &b.to_string_lossy()));
        let first = files
            .first()
            .with_context(|| format!("{}: no TIFF slices found", origin.display()))?;
        let (mut decoder, tiff) = open_decoder(first)?;
        let (w, h) = decoder
            .dimensions()
            .with_context(|| format!("{}: cannot read the image size", first.display()))?;
        let (format, samples_per_pixel) = page_format(&mut decoder, first)?;
        // The shape comes from the first slice: check it can hold the plane it claims.
        check_page(&mut decoder, first, 0, tiff, format, samples_per_pixel)?;
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
            cached: None,
            page: Vec::new(),
        })
    }
}

impl VolumeSource for SliceFolderSource {
    fn info(&self) -> &SourceInfo {
        &self.info
    }

    fn read_plane(&mut self, channel: usize, z: u64, mut out: PlaneOut<'_>) -> Result<()> {
        let file = &self.files[z as usize];
        if self.cached != Some(z) {
            self.cached = None;
            let (mut decoder, tiff) = open_decoder(file)?;
            let (w, h) = decoder.dimensions()?;
            let [_, ey, ex] = self.info.shape;
            if (h as u64, w as u64) != (ey, ex) {
                bail!(
                    "{}: slice is {w}x{h} pixels but {} is {ex}x{ey}",
                    file.display(),
                    self.files[0].display()
                );
            }
            let (format, spp) = page_format(&mut decoder, file)?;
            if (format, spp) != (self.info.format, self.samples_per_pixel) {
                bail!(
                    "{}: slice holds {spp} x {format} samples but {} holds {} x {}",
                    file.display(),
                    self.files[0].display(),
                    self.samples_per_pixel,
                    self.info.format
                );
            }
            decode_page(&mut decoder, file, 0, tiff, format, spp, &mut self.page)?;
            self.cached = Some(z);
        }
        out.fill_from_bytes(
            &self.page,
            self.info.format,
            NATIVE_BIG_ENDIAN,
            self.samples_per_pixel,
            channel,
        );
        Ok(())
    }
}
