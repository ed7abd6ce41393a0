//! `residency.regions(store, level, channel)`: one channel's region metadata at one level, read
//! whole from the store's `residency` arrays (the layout of `residency_schemas::RegionMetadata`):
//! the finest min/max grid (with its halo, and exact), the per-brick histograms and their bin
//! edges.

use std::sync::Arc;

use residency_schemas::{MinMaxGrid, SampleType};
use residency_store::location::{LocationError, ObjectStoreOptions, StoreLocation};
use residency_store::pyramid::{Pyramid, PyramidError};
use residency_store::region_array::{ArrayPart, read_region_array};
use zarrs::storage::ReadableListableStorageTraits;

/// Why region metadata cannot be read. Messages name the store.
#[derive(Debug, thiserror::Error)]
pub enum RegionsError {
    /// The store cannot be opened.
    #[error(transparent)]
    Open(#[from] LocationError),
    /// The pyramid reader refuses the store.
    #[error(transparent)]
    Pyramid(#[from] PyramidError),
    /// The image has no region metadata.
    #[error("{store}: no region metadata (`ingest index {store}` adds it)")]
    NoMetadata {
        /// The store.
        store: String,
    },
    /// A level the store does not have.
    #[error("{store}: no level {level} (the store has {levels})")]
    NoLevel {
        /// The store.
        store: String,
        /// The level asked for.
        level: usize,
        /// Levels of the store.
        levels: usize,
    },
    /// A channel the store does not have.
    #[error("{store}: no channel {channel} (the store has {channels})")]
    NoChannel {
        /// The store.
        store: String,
        /// The channel asked for.
        channel: usize,
        /// Channels of the store.
        channels: usize,
    },
    /// A region array cannot be read, or holds other than its metadata says.
    #[error("{store}: cannot read {path}: {reason}")]
    ReadArray {
        /// The store.
        store: String,
        /// The array's path in the store.
        path: String,
        /// What went wrong.
        reason: String,
    },
}

/// One channel's region metadata at one level.
#[derive(Clone, Debug, PartialEq)]
pub struct LevelRegions {
    /// Edge of a min/max cell in voxels of the level, `z, y, x`.
    pub cell_shape: [u64; 3],
    /// Voxels added on every side of a cell for its haloed min/max.
    pub halo: u64,
    /// Cells along `z, y, x`.
    pub grid_shape: [u64; 3],
    /// Each cell's minimum over its voxels and halo, row-major `z, y, x` (NaN: all NaN).
    pub min: Vec<f64>,
    /// Each cell's maximum over its voxels and halo.
    pub max: Vec<f64>,
    /// Each cell's exact minimum and maximum (its own voxels only), where the store has them
    /// (layout 0.2 on).
    pub exact: Option<(Vec<f64>, Vec<f64>)>,
    /// Brick shape `z, y, x`.
    pub brick_shape: [u64; 3],
    /// Bricks along `z, y, x`.
    pub brick_grid: [u64; 3],
    /// Histogram bins per brick.
    pub bins: usize,
    /// Each brick's histogram, row-major `z, y, x, bin`.
    pub histograms: Vec<u32>,
    /// The channel's bin edges (at most `bins + 1`, shared by every brick and level).
    pub edges: Vec<f64>,
}

/// Reads channel `channel`'s region metadata at level `level` of the store at `location`.
///
/// # Errors
/// A [`RegionsError`]: the store cannot be opened or read, has no region metadata, no such
/// level or channel, or a region array disagrees with its metadata.
pub fn read(
    location: &StoreLocation,
    options: &ObjectStoreOptions,
    level: usize,
    channel: usize,
) -> Result<LevelRegions, RegionsError> {
    let shown = location.to_string();
    let store = location.open_readable(options)?;
    let pyramid = Pyramid::open(store.clone(), &shown)?;
    let meta = pyramid
        .attributes
        .regions
        .as_ref()
        .ok_or_else(|| RegionsError::NoMetadata {
            store: shown.clone(),
        })?;
    let at = meta.levels.get(level).ok_or(RegionsError::NoLevel {
        store: shown.clone(),
        level,
        levels: meta.levels.len(),
    })?;
    let channels = meta.channels.len();
    let statistics = meta.channels.get(channel).ok_or(RegionsError::NoChannel {
        store: shown.clone(),
        channel,
        channels,
    })?;
    let reader = ChannelReader {
        store,
        shown: &shown,
        channel,
    };
    let grid = &at.minmax[0];
    let (min, max) = reader.grid(grid, pyramid.sample_type)?;
    let exact = match at.range.first() {
        Some(range) => Some(reader.grid(range, pyramid.sample_type)?),
        None => None,
    };
    let brick_grid: [u64; 3] = std::array::from_fn(|a| at.shape[a].div_ceil(meta.brick_shape[a]));
    let bins = meta.histogram_bins;
    let counts = reader.read(&at.histogram, SampleType::U32, cells(brick_grid) * bins)?;
    Ok(LevelRegions {
        cell_shape: grid.cell_shape,
        halo: meta.halo,
        grid_shape: grid.grid_shape,
        min,
        max,
        exact,
        brick_shape: meta.brick_shape,
        brick_grid,
        bins,
        // Counts are u32 in the store: the f64 round trip is exact.
        histograms: counts.into_iter().map(|c| c as u32).collect(),
        edges: statistics.histogram_edges.clone(),
    })
}

/// Cells of a grid of `shape`.
fn cells(shape: [u64; 3]) -> usize {
    (shape[0] * shape[1] * shape[2]) as usize
}

/// Reads one channel's part of region arrays (their first axis is the channel).
struct ChannelReader<'a> {
    store: Arc<dyn ReadableListableStorageTraits>,
    shown: &'a str,
    channel: usize,
}

impl ChannelReader<'_> {
    /// A min/max grid `[c, 2, gz, gy, gx]`: the channel's minima and maxima.
    fn grid(
        &self,
        grid: &MinMaxGrid,
        sample_type: SampleType,
    ) -> Result<(Vec<f64>, Vec<f64>), RegionsError> {
        let n = cells(grid.grid_shape);
        let mut values = self.read(&grid.path, sample_type, 2 * n)?;
        let max = values.split_off(n);
        Ok((values, max))
    }

    /// The channel's `expected` values of the array at `path` (of `sample_type`), as `f64`.
    fn read(
        &self,
        path: &str,
        sample_type: SampleType,
        expected: usize,
    ) -> Result<Vec<f64>, RegionsError> {
        let failed = |reason: String| RegionsError::ReadArray {
            store: self.shown.to_string(),
            path: path.to_string(),
            reason,
        };
        let part = ArrayPart::Channel(self.channel as u64);
        let (_, values) = read_region_array(&self.store, path, part, sample_type)
            .map_err(|e| failed(e.to_string()))?;
        if values.len() != expected {
            return Err(failed(format!(
                "{} values for channel {}, where its metadata says {expected}",
                values.len(),
                self.channel
            )));
        }
        Ok(values)
    }
}
