//! Raw volumes: headerless (or fixed-header) binary stacks, `x` fastest, then `y`, then `z`.

use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::path::Path;

use anyhow::{Context, Result, bail};

use super::{PlaneOut, SourceInfo, VolumeSource};
use crate::sample_format::SampleType;

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
    pub fn open(path: &Path, options: &RawOptions) -> Result<Self> {
        let shown = path.display();
        let from_name = parse_raw_name(path);
        let dims = options.dims.or(from_name.map(|n| n.0)).with_context(|| {
            format!("{shown}: raw input needs --dims X,Y,Z (or a name like name_XxYxZ_uint8.raw)")
        })?;
        let format = options.format.or(from_name.map(|n| n.1)).with_context(|| {
            format!("{shown}: raw input needs --dtype (or a name like name_XxYxZ_uint8.raw)")
        })?;
        let file = File::open(path).with_context(|| format!("{shown}: cannot open"))?;
        let actual = file
            .metadata()
            .with_context(|| format!("{shown}: cannot stat"))?
            .len();
        let [x, y, z] = dims;
        if dims.contains(&0) {
            bail!("{shown}: --dims {x},{y},{z} has an empty axis; each needs at least one voxel");
        }
        let Some(expected) = [x, y, z]
            .iter()
            .try_fold(format.bytes() as u64, |acc, &d| acc.checked_mul(d))
            .and_then(|data| data.checked_add(options.header_bytes))
        else {
            bail!(
                "{shown}: --dims {x},{y},{z} of {format} with a {}-byte header is more than 2^64 bytes",
                options.header_bytes
            );
        };
        if actual != expected {
            bail!(
                "{shown}: raw file is {actual} bytes, but --dims {x},{y},{z} of {format} with a {}-byte header need {expected} bytes",
                options.header_bytes
            );
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

    fn read_plane(&mut self, _channel: usize, z: u64, mut out: PlaneOut<'_>) -> Result<()> {
        let [_, y, x] = self.info.shape;
        let plane_bytes = y * x * self.info.format.bytes() as u64;
        self.buffer.resize(plane_bytes as usize, 0);
        let shown = self.info.path.display();
        self.file
            .seek(SeekFrom::Start(self.header_bytes + z * plane_bytes))
            .and_then(|_| self.file.read_exact(&mut self.buffer))
            .with_context(|| format!("{shown}: cannot read plane z={z}"))?;
        out.fill_from_bytes(&self.buffer, self.info.format, self.big_endian, 1, 0);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
