//! Raw volumes: headerless (or fixed-header) binary stacks, `x` fastest, then `y`, then `z`.

use std::fs::File;
use std::path::Path;

use super::error::SourceError;
use super::mapped::MappedPlane;
use super::volume::{PlaneRegion, SourceInfo, VolumeSource};
use crate::sample_format::{PlaneOut, SampleType};

/// Layout options for raw inputs (`--dims`, `--dtype`, `--endian`, `--header-bytes`).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RawOptions {
    /// Extent `x, y, z` in voxels.
    pub dims: Option<[u64; 3]>,
    /// Sample format.
    pub format: Option<SampleType>,
    /// Whether samples are big-endian (default little-endian).
    pub big_endian: bool,
    /// Bytes to skip at the start of the file.
    pub header_bytes: u64,
}

impl RawOptions {
    /// Whether any raw layout option was given on the command line.
    pub fn is_given(&self) -> bool {
        self.dims.is_some() || self.format.is_some()
    }
}

/// Recognises the common `name_XxYxZ_dtype.raw` naming convention
/// (e.g. `kingsnake_1024x1024x795_uint8.raw`) and returns `([x, y, z], format)`.
pub fn parse_raw_name(path: &Path) -> Option<([u64; 3], SampleType)> {
    let stem = path.file_stem()?.to_str()?;
    let mut parts = stem.rsplit('_');
    let format = parts.next()?.parse::<SampleType>().ok()?;
    let dims: Vec<u64> = parts
        .next()?
        .split('x')
        .map(|d| d.parse().ok())
        .collect::<Option<_>>()?;
    match dims[..] {
        [x, y, z] if x > 0 && y > 0 && z > 0 => Some(([x, y, z], format)),
        _ => None,
    }
}

/// A raw volume file with one channel.
pub struct RawSource {
    info: SourceInfo,
    file: File,
    big_endian: bool,
    header_bytes: u64,
    buffer: Vec<u8>,
}

impl RawSource {
    /// Opens a raw file, taking its layout from `options` or, failing that, its name,
    /// and checks that the file size matches the layout exactly.
    ///
    /// # Errors
    /// When the layout is neither given nor in the name, has an empty axis, or does not match
    /// the file's size, or the file cannot be opened.
    pub fn open(path: &Path, options: &RawOptions) -> Result<Self, SourceError> {
        let from_name = parse_raw_name(path);
        let dims =
            options
                .dims
                .or(from_name.map(|n| n.0))
                .ok_or_else(|| SourceError::RawNeedsDims {
                    path: path.to_path_buf(),
                })?;
        let format =
            options
                .format
                .or(from_name.map(|n| n.1))
                .ok_or_else(|| SourceError::RawNeedsType {
                    path: path.to_path_buf(),
                })?;
        let file = File::open(path).map_err(|source| SourceError::Open {
            path: path.to_path_buf(),
            source,
        })?;
        let actual = file
            .metadata()
            .map_err(|source| SourceError::Stat {
                path: path.to_path_buf(),
                source,
            })?
            .len();
        let [x, y, z] = dims;
        if dims.contains(&0) {
            return Err(SourceError::RawEmptyAxis {
                path: path.to_path_buf(),
                dims,
            });
        }
        let header_bytes = options.header_bytes;
        let Some(expected) = [x, y, z]
            .iter()
            .try_fold(format.bytes() as u64, |acc, &d| acc.checked_mul(d))
            .and_then(|data| data.checked_add(header_bytes))
        else {
            return Err(SourceError::RawTooLarge {
                path: path.to_path_buf(),
                dims,
                format,
                header_bytes,
            });
        };
        if actual != expected {
            return Err(SourceError::RawSize {
                path: path.to_path_buf(),
                actual,
                dims,
                format,
                header_bytes,
                expected,
            });
        }
        Ok(Self {
            info: SourceInfo {
                path: path.to_path_buf(),
                shape: [z, y, x],
                channels: 1,
                format,
                voxel_size: None,
                unit: None,
                channel_names: Vec::new(),
            },
            file,
            big_endian: options.big_endian,
            header_bytes: options.header_bytes,
            buffer: Vec::new(),
        })
    }
}

impl VolumeSource for RawSource {
    fn info(&self) -> &SourceInfo {
        &self.info
    }

    fn read_region(
        &mut self,
        _channel: usize,
        z: u64,
        region: PlaneRegion,
        mut out: PlaneOut<'_>,
    ) -> Result<(), SourceError> {
        use std::os::unix::fs::FileExt;
        let [_, _, x] = self.info.shape;
        let sample = self.info.format.bytes() as u64;
        let plane_start = self.header_bytes + z * self.info.shape[1] * x * sample;
        let row_bytes = (region.nx * sample) as usize;
        self.buffer.resize(region.ny as usize * row_bytes, 0);
        let cannot_read = |source| SourceError::ReadPlane {
            path: self.info.path.clone(),
            z,
            source,
        };
        if region.nx == x {
            // Whole rows lie next to each other in the file: one read.
            self.file
                .read_exact_at(&mut self.buffer, plane_start + region.y0 * x * sample)
                .map_err(cannot_read)?;
        } else {
            for (dy, row) in self.buffer.chunks_exact_mut(row_bytes).enumerate() {
                let at = plane_start + ((region.y0 + dy as u64) * x + region.x0) * sample;
                self.file.read_exact_at(row, at).map_err(cannot_read)?;
            }
        }
        out.fill_from_bytes(&self.buffer, self.info.format, self.big_endian, 1, 0);
        Ok(())
    }

    fn map_plane(
        &mut self,
        _channel: usize,
        z: u64,
        format: SampleType,
    ) -> Result<Option<MappedPlane>, SourceError> {
        let swapped = self.big_endian != cfg!(target_endian = "big") && format.bytes() > 1;
        if format != self.info.format || swapped {
            return Ok(None);
        }
        let [depth, y, x] = self.info.shape;
        let bytes = y * x * format.bytes() as u64;
        let end = self.header_bytes + depth * bytes;
        Ok(MappedPlane::map(
            &self.file,
            &self.info.path,
            (self.header_bytes + z * bytes, bytes),
            end,
            format.bytes(),
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sample_format::Sample;

    #[test]
    fn recognises_the_naming_convention() {
        assert_eq!(
            parse_raw_name(Path::new("/d/kingsnake_1024x1024x795_uint8.raw")),
            Some(([1024, 1024, 795], SampleType::U8))
        );
        assert_eq!(
            parse_raw_name(Path::new("rayleigh_taylor_256x256x256_float32.raw")),
            Some(([256, 256, 256], SampleType::F32))
        );
        assert_eq!(parse_raw_name(Path::new("scan.raw")), None);
        assert_eq!(parse_raw_name(Path::new("a_10x10_uint8.raw")), None);
    }

    /// Found by fuzzing (tests/fuzz, target raw_name): an empty file matched `--dims` with a
    /// zero axis (0 bytes), so the source was opened with 1.8e19 planes to read.
    #[test]
    fn planes_in_the_machines_byte_order_are_mapped_where_aligned() {
        let dir = tempfile::tempdir().unwrap();
        let values: Vec<u16> = (0..2 * 3 * 4).map(|v| v * 100).collect();
        let bytes = |big: bool| -> Vec<u8> {
            values
                .iter()
                .flat_map(|v| {
                    if big {
                        v.to_be_bytes()
                    } else {
                        v.to_le_bytes()
                    }
                })
                .collect()
        };
        let open = |name: &str, header: usize, big: bool| {
            let path = dir.path().join(name);
            let mut file = vec![7u8; header];
            file.extend(bytes(big));
            std::fs::write(&path, file).unwrap();
            let options = RawOptions {
                dims: Some([4, 3, 2]),
                format: Some(SampleType::U16),
                big_endian: big,
                header_bytes: header as u64,
            };
            RawSource::open(&path, &options).unwrap()
        };
        let little = cfg!(target_endian = "little");
        let mut native = open("native.raw", 6, !little);
        let plane = native.map_plane(0, 1, SampleType::U16).unwrap().unwrap();
        assert_eq!(
            plane.samples::<u16>(),
            [
                1200, 1300, 1400, 1500, 1600, 1700, 1800, 1900, 2000, 2100, 2200, 2300
            ]
        );
        assert!(native.map_plane(0, 0, SampleType::I32).unwrap().is_none());
        assert!(plane.in_place());
        // Swapped bytes are read instead; samples at odd offsets are copied out of the file.
        let mut swapped = open("swapped.raw", 6, little);
        assert!(swapped.map_plane(0, 1, SampleType::U16).unwrap().is_none());
        let mut odd = open("odd.raw", 5, !little);
        let copied = odd.map_plane(0, 1, SampleType::U16).unwrap().unwrap();
        assert!(!copied.in_place());
        let mut plane = vec![0u16; 12];
        odd.read_plane(0, 1, u16::plane_out(&mut plane)).unwrap();
        assert_eq!((copied.samples::<u16>(), plane[11]), (&plane[..], 2300));
    }

    #[test]
    fn an_empty_axis_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("empty.raw");
        std::fs::write(&path, b"").unwrap();
        let options = RawOptions {
            dims: Some([128017563084139, 0, 18446742974197923840]),
            format: Some(SampleType::U8),
            ..RawOptions::default()
        };
        let error = RawSource::open(&path, &options).err().unwrap().to_string();
        assert_eq!(
            error,
            format!(
                "{}: --dims 128017563084139,0,18446742974197923840 has an empty axis; each needs \
                 at least one voxel",
                path.display()
            )
        );
    }
}
