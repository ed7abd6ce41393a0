//! [`LocalSource`]: a local OME-Zarr store (0.5 on Zarr v3, sharded or not, or 0.4 on Zarr
//! v2), read with zarrs.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use anyhow::{Context, Result, bail};
use rayon::prelude::*;
use zarrs::array::{
    Array, ArrayShardedReadableExt, ArrayShardedReadableExtCache, CodecOptions, ElementOwned,
};
use zarrs::filesystem::FilesystemStore;

use super::ome::{self, AxisLayout, OmeGroup, ZarrFormat};
use super::{BrickKey, BrickSource, BrickVoxels, MinMaxGrid, SampleType, VolumeInfo};

/// One level's array, with the cache of shard indices zarrs keeps for brick reads.
struct LevelArray {
    array: Array<FilesystemStore>,
    cache: ArrayShardedReadableExtCache,
    fill_value: f64,
}

/// A local OME-Zarr store written by `ingest` (or indexed by `ingest index`).
pub struct LocalSource {
    path: PathBuf,
    info: VolumeInfo,
    axes: AxisLayout,
    levels: Vec<LevelArray>,
}

impl std::fmt::Debug for LocalSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LocalSource")
            .field("path", &self.path)
            .field("info", &self.info)
            .finish_non_exhaustive()
    }
}

/// The dataset name of a store path: its folder name without `.ome.zarr` / `.zarr`.
pub fn dataset_name(path: &Path) -> String {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| path.display().to_string());
    name.strip_suffix(".ome.zarr")
        .or_else(|| name.strip_suffix(".zarr"))
        .unwrap_or(&name)
        .to_string()
}

fn read_file(path: &Path) -> Result<Vec<u8>> {
    std::fs::read(path).with_context(|| format!("{}: cannot read", path.display()))
}

impl LocalSource {
    /// Opens the OME-Zarr image at `path`: its multiscales, region metadata and min/max grids.
    /// A store without region metadata opens with `minmax: None`, and a warning.
    pub fn open(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let shown = path.display().to_string();
        let format = if path.join("zarr.json").is_file() {
            ZarrFormat::V3
        } else if path.join(".zattrs").is_file() {
            ZarrFormat::V2
        } else if path.exists() {
            bail!("{shown}: not an OME-Zarr image (no zarr.json or .zattrs)");
        } else {
            bail!("{shown}: no such store");
        };
        let group_file = path.join(format.group_key());
        let group = ome::parse_group(
            format,
            &read_file(&group_file)?,
            &group_file.display().to_string(),
        )?;
        let store =
            Arc::new(FilesystemStore::new(path).with_context(|| format!("{shown}: cannot open"))?);
        let mut descriptions = Vec::new();
        let mut levels = Vec::new();
        for p in &group.level_paths {
            let file = path.join(p).join(format.array_key());
            let shown_file = file.display().to_string();
            descriptions.push(ome::parse_array(format, &read_file(&file)?, &shown_file)?);
            let array = Array::open(store.clone(), &format!("/{p}"))
                .with_context(|| format!("{shown_file}: cannot open the array"))?;
            levels.push(LevelArray {
                cache: ArrayShardedReadableExtCache::new(&array),
                fill_value: descriptions.last().expect("pushed").fill_value,
                array,
            });
        }
        let mut info = ome::volume_info(&dataset_name(path), &group, &descriptions, &shown)?;
        info.minmax = if ome::usable_region_metadata(group.regions.as_ref(), &shown) {
            Some(read_minmax(&store, &group, &info, &shown)?)
        } else {
            None
        };
        Ok(Self {
            path: path.to_path_buf(),
            info,
            axes: group.axes,
            levels,
        })
    }

    /// The store's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    fn fetch_one(&self, key: &BrickKey) -> Result<BrickVoxels> {
        self.info.check_key(key)?;
        let level = &self.levels[key.level as usize];
        let indices = self.axes.chunk_indices(key.channel as u64, key.brick);
        let context = || {
            format!(
                "{}: cannot read brick {:?} of channel {} at level {}",
                self.path.display(),
                key.brick,
                key.channel,
                key.level
            )
        };
        fn decode<T: ElementOwned + Copy + Into<f64>>(
            level: &LevelArray,
            indices: &[u64],
            wrap: fn(Vec<T>) -> BrickVoxels,
        ) -> Result<BrickVoxels> {
            let v: Vec<T> = level.array.retrieve_subchunk_opt(
                &level.cache,
                indices,
                &CodecOptions::default(),
            )?;
            let fill = level.fill_value;
            let is_fill = |x: &T| {
                let x: f64 = (*x).into();
                x == fill || (x.is_nan() && fill.is_nan())
            };
            Ok(if v.iter().all(is_fill) {
                BrickVoxels::Empty
            } else {
                wrap(v)
            })
        }
        match self.info.sample_type {
            SampleType::U8 => decode::<u8>(level, &indices, BrickVoxels::U8),
            SampleType::U16 => decode::<u16>(level, &indices, BrickVoxels::U16),
            SampleType::I16 => decode::<i16>(level, &indices, BrickVoxels::I16),
            SampleType::U32 => decode::<u32>(level, &indices, BrickVoxels::U32),
            SampleType::I32 => decode::<i32>(level, &indices, BrickVoxels::I32),
            SampleType::F32 => decode::<f32>(level, &indices, BrickVoxels::F32),
        }
        .with_context(context)
    }
}

/// Reads every min/max grid of the region metadata into `minmax[channel][level][k]`.
fn read_minmax(
    store: &Arc<FilesystemStore>,
    group: &OmeGroup,
    info: &VolumeInfo,
    shown: &str,
) -> Result<Vec<Vec<Vec<MinMaxGrid>>>> {
    let regions = group.regions.as_ref().expect("called with region metadata");
    let channels = info.channels.len();
    let mut out = vec![Vec::with_capacity(regions.levels.len()); channels];
    for level in &regions.levels {
        let mut per_channel = vec![Vec::with_capacity(level.minmax.len()); channels];
        for grid in &level.minmax {
            let source = format!("{shown}/{}", grid.path);
            let array = Array::open(store.clone(), &format!("/{}", grid.path))
                .with_context(|| format!("{source}: cannot open the min/max array"))?;
            let [gz, gy, gx] = grid.grid_shape;
            let expected = [channels as u64, 2, gz, gy, gx];
            if array.shape() != expected {
                bail!(
                    "{source}: min/max array has shape {:?}, expected {expected:?}",
                    array.shape()
                );
            }
            let values = read_all_f64(&array, info.sample_type)
                .with_context(|| format!("{source}: cannot read the min/max array"))?;
            let per = 2 * (gz * gy * gx) as usize;
            for (c, chunk) in values.chunks_exact(per).enumerate() {
                per_channel[c].push(ome::minmax_grid(
                    grid.cell_shape,
                    grid.grid_shape,
                    chunk,
                    &source,
                )?);
            }
        }
        for (c, grids) in per_channel.into_iter().enumerate() {
            out[c].push(grids);
        }
    }
    Ok(out)
}

/// The whole array as `f64`.
fn read_all_f64(array: &Array<FilesystemStore>, sample_type: SampleType) -> Result<Vec<f64>> {
    fn all<T: ElementOwned + Copy + Into<f64>>(array: &Array<FilesystemStore>) -> Result<Vec<f64>> {
        let v: Vec<T> =
            array.retrieve_array_subset_opt(&array.subset_all(), &CodecOptions::default())?;
        Ok(v.into_iter().map(Into::into).collect())
    }
    match sample_type {
        SampleType::U8 => all::<u8>(array),
        SampleType::U16 => all::<u16>(array),
        SampleType::I16 => all::<i16>(array),
        SampleType::U32 => all::<u32>(array),
        SampleType::I32 => all::<i32>(array),
        SampleType::F32 => all::<f32>(array),
    }
}

impl BrickSource for LocalSource {
    fn info(&self) -> &VolumeInfo {
        &self.info
    }

    fn fetch(&self, keys: &[BrickKey]) -> Vec<Result<BrickVoxels>> {
        keys.par_iter().map(|k| self.fetch_one(k)).collect()
    }
}
