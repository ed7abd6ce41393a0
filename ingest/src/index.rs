//! `ingest index`: adds region metadata to an OME-Zarr image written by another tool,
//! reading each level once and never rewriting its data.
//!
//! Bricks are the store's own chunks (inner chunks when sharded). The metadata arrays are
//! written first; the image group's attributes are replaced last, through a temporary file
//! and a rename, so an interrupted run leaves the store as it was.

use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use residency_schemas::REGIONS_KEY;
use residency_store::location::{LocationError, ObjectStoreOptions, ROOT_METADATA, StoreLocation};
use residency_store::pyramid::{Pyramid, PyramidError};
use zarrs::array::{ArrayError, ArraySubset};
use zarrs::storage::{ReadableStorageTraits, StoreKey};

use crate::convert::sink::{ChunkWriteError, SlabSink, planes_of};
use crate::region_writer::{
    LevelRegionWriter, RegionWriteError, channel_summaries, region_document,
};
use crate::regions::{CELL, CellGrid, ChannelAccumulator, LevelHistograms};
use crate::sample_format::Sample;
use crate::source::PlaneRegion;
use crate::store::{StoreError, StoreWriter};
use crate::with_sample_type;

/// Why a store cannot be indexed. Messages name the store (and the level or axis) at fault;
/// errors of the pyramid reader and of writing the store are theirs, unchanged.
#[derive(Debug, thiserror::Error)]
pub enum IndexError {
    /// The path is not a folder.
    #[error("{}: not an OME-Zarr image (no zarr.json or .zattrs)", path.display())]
    NotAnImage {
        /// The path.
        path: PathBuf,
    },
    /// The pyramid reader refuses the store.
    #[error(transparent)]
    Pyramid(#[from] PyramidError),
    /// A leading axis other than `c` with several entries.
    #[error(
        "{}: axis '{axis}' has {entries} entries; only c, z, y, x can be indexed",
        path.display()
    )]
    ExtraAxis {
        /// The store.
        path: PathBuf,
        /// The axis.
        axis: String,
        /// Its entries.
        entries: u64,
    },
    /// A slab of a level cannot be read.
    #[error("{}: cannot read level {level} at z {z}", path.display())]
    ReadLevel {
        /// The store.
        path: PathBuf,
        /// The level's path in the store.
        level: String,
        /// First z of the slab.
        z: u64,
        /// What zarrs said.
        #[source]
        source: Box<ArrayError>,
    },
    /// A chunk cannot be written (indexing writes no image chunk, so never in practice).
    #[error(transparent)]
    Chunk(#[from] ChunkWriteError),
    /// The store cannot be opened, synced or its attributes replaced.
    #[error(transparent)]
    Store(#[from] StoreError),
    /// The region metadata cannot be written.
    #[error(transparent)]
    Regions(#[from] RegionWriteError),
    /// A value that cannot be serialised as JSON.
    #[error(transparent)]
    Json(#[from] serde_json::Error),
    /// The object store cannot be opened or written.
    #[error(transparent)]
    Location(#[from] LocationError),
    /// The local staging folder of an object-store index cannot be created.
    #[error("cannot create a local staging folder")]
    Staging {
        /// What the file system said.
        #[source]
        source: std::io::Error,
    },
}

/// Indexes the image at `location` and returns a short report. A folder is indexed in place;
/// in an object store the region metadata is written to a local staging folder with a copy
/// of the root metadata, then uploaded, the root metadata last (the image's keys are kept).
///
/// # Errors
/// When the store is not an OME-Zarr image the pyramid reader accepts, has a leading axis
/// other than `c` with several entries, or cannot be read or written.
pub fn index(location: &StoreLocation, options: &ObjectStoreOptions) -> Result<String, IndexError> {
    let path = match location {
        StoreLocation::Folder(path) => path,
        StoreLocation::S3 { .. } => return index_object_store(location, options),
    };
    if !path.is_dir() {
        return Err(IndexError::NotAnImage { path: path.clone() });
    }
    let store = Arc::new(crate::store::StagingStore::new(path)?);
    let pyramid = Pyramid::open(store, &path.display().to_string())?;
    index_pyramid(&pyramid, path, path)
}

/// Indexes an image in an object store through a local staging folder.
fn index_object_store(
    location: &StoreLocation,
    options: &ObjectStoreOptions,
) -> Result<String, IndexError> {
    let shown = PathBuf::from(location.to_string());
    let store = location.open_readable(options)?;
    let pyramid = Pyramid::open(store.clone(), &location.to_string())?;
    let staging = tempfile::Builder::new()
        .prefix("ingest-index-")
        .tempdir()
        .map_err(|source| IndexError::Staging { source })?;
    // The root metadata, updated in the staging folder and uploaded last.
    for name in ROOT_METADATA {
        let key = StoreKey::new(name).expect("a valid key");
        let bytes = store.get(&key).map_err(|e| PyramidError::Storage {
            what: format!("{location}/{name}"),
            source: e.into(),
        })?;
        if let Some(bytes) = bytes {
            let file = staging.path().join(name);
            std::fs::write(&file, &bytes).map_err(|source| StoreError::Write {
                path: file.clone(),
                source,
            })?;
        }
    }
    let report = index_pyramid(&pyramid, staging.path(), &shown)?;
    location.upload_folder(staging.path(), options, false, None, &|_| {})?;
    Ok(report)
}

/// Checks the axes, then indexes `pyramid`, writing the region metadata into the folder
/// `write_to` (errors and the report name the store `shown`).
fn index_pyramid<S: ReadableStorageTraits + ?Sized + 'static>(
    pyramid: &Pyramid<S>,
    write_to: &Path,
    shown: &Path,
) -> Result<String, IndexError> {
    let n = pyramid.layout.axis_names.len();
    for level in &pyramid.levels {
        for (i, axis) in pyramid.layout.axis_names[..n - 3].iter().enumerate() {
            let entries = level.description.shape[i];
            if Some(i) != pyramid.layout.channel_axis && entries != 1 {
                return Err(IndexError::ExtraAxis {
                    path: shown.to_path_buf(),
                    axis: axis.clone(),
                    entries,
                });
            }
        }
    }
    let omero = pyramid.attributes.omero.as_ref();
    let labels: Vec<String> = (0..pyramid.channels as usize)
        .map(|c| {
            omero
                .and_then(|o| o.channels.get(c))
                .and_then(|ch| ch.label.clone())
                .unwrap_or_else(|| format!("Channel {c}"))
        })
        .collect();
    with_sample_type!(pyramid.sample_type, T => index_typed::<T, S>(write_to, shown, pyramid, &labels))
}

fn index_typed<T: Sample, S: ReadableStorageTraits + ?Sized + 'static>(
    path: &Path,
    shown_path: &Path,
    pyramid: &Pyramid<S>,
    labels: &[String],
) -> Result<String, IndexError> {
    let shown = shown_path.display().to_string();
    let channels = pyramid.channels as usize;
    let brick = pyramid.brick_shape;
    let levels = &pyramid.levels;
    let stats: Vec<Mutex<ChannelAccumulator>> = (0..channels)
        .map(|_| Mutex::new(ChannelAccumulator::default()))
        .collect();
    let writer = StoreWriter::in_place(path, pyramid.attributes.version)?;
    let mut gathered = Vec::new();
    for (i, level) in levels.iter().enumerate() {
        let shape = level.description.zyx_shape();
        let [depth, ny, nx] = shape;
        let factor =
            std::array::from_fn(|a| levels[0].description.zyx_shape()[a].div_ceil(shape[a].max(1)));
        let mut regions = LevelRegionWriter::<T>::create(
            &writer,
            i,
            &level.path,
            shape,
            factor,
            channels,
            brick,
            false,
        )?;
        let cell_grid = shape.map(|s| s.div_ceil(CELL));
        let mut cells =
            CellGrid::<T>::window(channels, [cell_grid[1], cell_grid[2]], 0..0, cell_grid[0]);
        let mut histograms = LevelHistograms::for_rows(channels, level.grid, 0..0);
        let (mut written, mut empty) = (0, 0);
        let dims = level.array.shape().len();
        let mut z0 = 0;
        while z0 < depth {
            let nz = brick[0].min(depth - z0);
            let mut ranges: Vec<std::ops::Range<u64>> = level.array.shape()[..dims - 3]
                .iter()
                .map(|&s| 0..s)
                .collect();
            ranges.extend([z0..z0 + nz, 0..ny, 0..nx]);
            let slab: Vec<T> = level
                .array
                .retrieve_array_subset(&ArraySubset::new_with_ranges(&ranges))
                .map_err(|source| IndexError::ReadLevel {
                    path: shown_path.to_path_buf(),
                    level: level.path.clone(),
                    z: z0,
                    source: Box::new(source),
                })?;
            histograms.extend_to((z0 + nz).div_ceil(brick[0]), level.grid[0]);
            let sink = SlabSink {
                channels,
                window: PlaneRegion::whole([ny, nx]),
                brick,
                outer: brick,
                array: None,
                histograms: &histograms,
                stats: (i == 0).then_some(stats.as_slice()),
                gather: 1,
            };
            let planes = planes_of(&slab, channels * nz as usize, (ny * nx) as usize);
            let (w, e, _) = sink.process(&planes, z0, nz, &mut cells, None)?;
            written += w;
            empty += e;
            z0 += nz;
            regions.release(&mut cells, &mut histograms, z0, brick[0])?;
        }
        regions.release(&mut cells, &mut histograms, u64::MAX, brick[0])?;
        gathered.push((regions, written, empty));
    }
    let stats: Vec<ChannelAccumulator> = stats
        .into_iter()
        .map(|m| m.into_inner().expect("stats"))
        .collect();
    let (channel_stats, _, binnings) = channel_summaries::<T>(&stats, labels);
    let region_levels = gathered
        .into_iter()
        .map(|(regions, written, empty)| regions.finish(&binnings, written, empty))
        .collect::<Result<Vec<_>, _>>()?;
    let regions = region_document(region_levels, channel_stats, brick);
    // The metadata arrays reach the disk before the attributes that point to them.
    crate::store::sync_file_system(path)?;
    writer.set_root_attribute(REGIONS_KEY, serde_json::to_value(&regions)?)?;
    Ok(format!(
        "indexed {shown}: {} levels, {} channels, bricks {:?}\n",
        levels.len(),
        channels,
        brick
    ))
}
