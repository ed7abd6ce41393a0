//! [`LocalSource`]: an OME-Zarr store read directly (0.5 on Zarr v3, sharded or not, or 0.4
//! on Zarr v2) with zarrs, from a local folder or an S3-compatible object store.

use std::path::Path;
use std::sync::Arc;

use rayon::prelude::*;
use residency_store::at_once;
use residency_store::location::{AsyncReadable, BlockOn, ObjectStoreOptions, StoreLocation};
use residency_store::pyramid::{AsyncBricks, BrickIndex, Pyramid, PyramidError, REMOTE_READS};
use zarrs::array::{Array, ArrayError, CodecOptions, ElementOwned};
use zarrs::storage::ReadableListableStorageTraits;

use super::regions;
use super::{BrickKey, BrickSource, BrickVoxels, MinMaxGrid, SampleType, SourceError, VolumeInfo};

pub use residency_schemas::dataset::dataset_name;

/// The storage a store is read from (a folder or an object store).
type Storage = dyn ReadableListableStorageTraits;

/// An OME-Zarr store written by `ingest` (or indexed by `ingest index`), read through the
/// pyramid reader of `residency_schemas` without a server.
pub struct LocalSource {
    location: StoreLocation,
    info: VolumeInfo,
    /// The location as messages name it.
    shown: Arc<str>,
    pyramid: Arc<Pyramid<Storage>>,
    /// An object store's bricks read by futures; `None` for a folder.
    remote: Option<RemoteBricks>,
}

/// An object store's level arrays over its async storage, and the runtime their requests run on.
struct RemoteBricks {
    bricks: Arc<AsyncBricks>,
    runtime: BlockOn,
}

impl std::fmt::Debug for LocalSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LocalSource")
            .field("location", &self.location)
            .field("info", &self.info)
            .finish_non_exhaustive()
    }
}

impl LocalSource {
    /// Opens the OME-Zarr image in the folder `path`: its multiscales, region metadata and
    /// min/max grids. A store without region metadata opens with `minmax: None`, and a
    /// warning.
    ///
    /// # Errors
    /// When the path is missing, is not an OME-Zarr image, or its levels or region metadata
    /// are unusable; the [`SourceError`] names the store.
    pub fn open(path: impl AsRef<Path>) -> Result<Self, SourceError> {
        let location = StoreLocation::Folder(path.as_ref().to_path_buf());
        Self::open_location(&location, &ObjectStoreOptions::default())
    }

    /// Opens the OME-Zarr image at `location` (a folder, or a prefix of an object store
    /// reached with `options`), as [`LocalSource::open`].
    ///
    /// # Errors
    /// As [`LocalSource::open`], and when the object store cannot be reached.
    pub fn open_location(
        location: &StoreLocation,
        options: &ObjectStoreOptions,
    ) -> Result<Self, SourceError> {
        let shown = location.to_string();
        if let Some(path) = location.folder()
            && !path.exists()
        {
            return Err(SourceError::NoSuchStore { store: shown });
        }
        let (store, remote) = location
            .open_readable_and_async(options)
            .map_err(|source| SourceError::CannotOpen {
                store: shown.clone(),
                source: Box::new(source),
            })?;
        let pyramid = Pyramid::open(store, &shown)?;
        let remote = remote.map(|AsyncReadable { storage, runtime }| RemoteBricks {
            bricks: Arc::new(pyramid.async_bricks(storage)),
            runtime,
        });
        let descriptions: Vec<_> = pyramid
            .levels
            .iter()
            .map(|l| l.description.clone())
            .collect();
        let mut info = VolumeInfo::from_ome(
            &dataset_name(Path::new(&location.file_name())),
            &pyramid.attributes,
            &pyramid.layout,
            &descriptions,
            &shown,
        )?;
        info.minmax =
            if regions::usable_region_metadata(pyramid.attributes.regions.as_ref(), &shown) {
                Some(read_minmax(&pyramid, &info, &shown)?)
            } else {
                None
            };
        Ok(Self {
            location: location.clone(),
            info,
            shown: shown.into(),
            pyramid: Arc::new(pyramid),
            remote,
        })
    }

    /// Where the store is.
    pub fn location(&self) -> &StoreLocation {
        &self.location
    }

    /// The brick a key names, after checking it, and its level's fill value.
    fn brick_at(&self, key: &BrickKey) -> Result<(BrickIndex, f64), SourceError> {
        self.info.check_key(key)?;
        let at = BrickIndex {
            level: key.level,
            channel: key.channel,
            brick: key.brick,
        };
        let fill = self.pyramid.levels[key.level as usize]
            .description
            .fill_value;
        Ok((at, fill))
    }

    /// Reads one brick synchronously (from a folder).
    fn fetch_one(&self, key: &BrickKey) -> Result<BrickVoxels, SourceError> {
        let (at, fill) = self.brick_at(key)?;
        let p = &self.pyramid;
        match self.info.sample_type {
            SampleType::U8 => p.read_brick(&at).map(BrickVoxels::U8),
            SampleType::U16 => p.read_brick(&at).map(BrickVoxels::U16),
            SampleType::I16 => p.read_brick(&at).map(BrickVoxels::I16),
            SampleType::U32 => p.read_brick(&at).map(BrickVoxels::U32),
            SampleType::I32 => p.read_brick(&at).map(BrickVoxels::I32),
            SampleType::F32 => p.read_brick(&at).map(BrickVoxels::F32),
        }
        .map(|voxels| voxels.empty_if_all(fill))
        .map_err(|source| read_error(&self.shown, *key, source))
    }

    /// Reads `keys` from an object store by futures: one runtime task per brick, at most
    /// [`REMOTE_READS`] in flight, each decoding what it read.
    fn fetch_remote(
        &self,
        remote: &RemoteBricks,
        keys: &[BrickKey],
    ) -> Vec<Result<BrickVoxels, SourceError>> {
        let tasks = keys.iter().map(|&key| {
            let brick = self.brick_at(&key);
            let (pyramid, bricks) = (self.pyramid.clone(), remote.bricks.clone());
            let (sample_type, shown) = (self.info.sample_type, self.shown.clone());
            async move {
                let (at, fill) = brick?;
                let p = &*pyramid;
                let b = &*bricks;
                match sample_type {
                    SampleType::U8 => p.read_brick_async(b, &at).await.map(BrickVoxels::U8),
                    SampleType::U16 => p.read_brick_async(b, &at).await.map(BrickVoxels::U16),
                    SampleType::I16 => p.read_brick_async(b, &at).await.map(BrickVoxels::I16),
                    SampleType::U32 => p.read_brick_async(b, &at).await.map(BrickVoxels::U32),
                    SampleType::I32 => p.read_brick_async(b, &at).await.map(BrickVoxels::I32),
                    SampleType::F32 => p.read_brick_async(b, &at).await.map(BrickVoxels::F32),
                }
                .map(|voxels| voxels.empty_if_all(fill))
                .map_err(|source| read_error(&shown, key, source))
            }
        });
        remote.runtime.run_all(tasks, REMOTE_READS)
    }
}

/// The error of a brick that could not be read from the store shown as `store`.
fn read_error(store: &str, key: BrickKey, source: PyramidError) -> SourceError {
    SourceError::ReadBrick {
        store: store.to_string(),
        key,
        source: Box::new(source),
    }
}

/// Reads every min/max grid of the region metadata into `minmax[channel][level][k]`, side by
/// side (over an object store each read waits on the network; [`at_once::try_read_all`]).
fn read_minmax(
    pyramid: &Pyramid<Storage>,
    info: &VolumeInfo,
    shown: &str,
) -> Result<Vec<Vec<Vec<MinMaxGrid>>>, SourceError> {
    let regions = pyramid
        .attributes
        .regions
        .as_ref()
        .expect("called with region metadata");
    let channels = info.channels.len();
    let grids: Vec<_> = regions.levels.iter().flat_map(|l| &l.minmax).collect();
    let mut read =
        at_once::try_read_all(&grids, |grid| read_minmax_grid(pyramid, grid, info, shown))
            .into_iter()
            .collect::<Result<Vec<_>, _>>()?
            .into_iter();
    let mut out = vec![Vec::with_capacity(regions.levels.len()); channels];
    for level in &regions.levels {
        let mut per_channel = vec![Vec::with_capacity(level.minmax.len()); channels];
        for grid_per_channel in read.by_ref().take(level.minmax.len()) {
            for (c, grid) in grid_per_channel.into_iter().enumerate() {
                per_channel[c].push(grid);
            }
        }
        for (c, grids) in per_channel.into_iter().enumerate() {
            out[c].push(grids);
        }
    }
    Ok(out)
}

/// One min/max grid of the region metadata, one per channel.
fn read_minmax_grid(
    pyramid: &Pyramid<Storage>,
    grid: &residency_schemas::MinMaxGrid,
    info: &VolumeInfo,
    shown: &str,
) -> Result<Vec<MinMaxGrid>, SourceError> {
    let channels = info.channels.len();
    let source = format!("{shown}/{}", grid.path);
    let array = match Array::open(pyramid.store.clone(), &format!("/{}", grid.path)) {
        Ok(array) => array,
        Err(e) => {
            return Err(SourceError::OpenMinMax {
                array: source,
                source: Box::new(e),
            });
        }
    };
    let [gz, gy, gx] = grid.grid_shape;
    let expected = [channels as u64, 2, gz, gy, gx];
    if array.shape() != expected {
        return Err(SourceError::MinMaxShape {
            array: source,
            shape: array.shape().to_vec(),
            expected,
        });
    }
    let values = match read_all_f64(&array, info.sample_type) {
        Ok(values) => values,
        Err(e) => {
            return Err(SourceError::ReadMinMax {
                array: source,
                source: Box::new(e),
            });
        }
    };
    let per = 2 * (gz * gy * gx) as usize;
    values
        .chunks_exact(per)
        .map(|chunk| {
            MinMaxGrid::from_values(grid.cell_shape, grid.grid_shape, chunk, &source)
                .map_err(SourceError::from)
        })
        .collect()
}

/// The whole array as `f64`.
fn read_all_f64(array: &Array<Storage>, sample_type: SampleType) -> Result<Vec<f64>, ArrayError> {
    fn all<T: ElementOwned + Copy + Into<f64>>(
        array: &Array<Storage>,
    ) -> Result<Vec<f64>, ArrayError> {
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

    /// From a folder, one brick per core; from an object store, many at once by futures
    /// ([`REMOTE_READS`]), since those reads wait on the network.
    fn fetch(&self, keys: &[BrickKey]) -> Vec<Result<BrickVoxels, SourceError>> {
        match &self.remote {
            Some(remote) => self.fetch_remote(remote, keys),
            None => keys.par_iter().map(|k| self.fetch_one(k)).collect(),
        }
    }
}
