//! Writing region metadata into a store: the min/max grid hierarchy and the brick histograms
//! of every level as Zarr arrays under `residency/`, and the [`RegionMetadata`] document.

use std::path::PathBuf;

use residency_schemas::{
    ChannelStatistics, HISTOGRAM_BINS, MinMaxGrid, REGIONS_VERSION, RegionLevel, RegionMetadata,
};
use zarrs::array::{ArrayError, ArraySubset};

use crate::ome::ChannelDisplay;
use crate::regions::{CELL, CellGrid, ChannelAccumulator, HALO, LevelHistograms};
use crate::sample_format::{Sample, SampleType};
use crate::store::{ArrayLayout, StoreError, StoreWriter};

/// Region metadata that cannot be written into a store.
#[derive(Debug, thiserror::Error)]
pub enum RegionWriteError {
    /// A group or an array cannot be created.
    #[error(transparent)]
    Store(#[from] StoreError),
    /// An array's values cannot be written.
    #[error("{}: cannot write {array}", path.display())]
    WriteArray {
        /// The store.
        path: PathBuf,
        /// The array's path in the store (`residency/0/minmax/0`).
        array: String,
        /// What zarrs said.
        #[source]
        source: Box<ArrayError>,
    },
}

/// Percentiles recorded for every channel.
pub const PERCENTS: [f64; 5] = [0.1, 1.0, 50.0, 99.0, 99.9];

/// What the pass gathered for one level.
pub struct LevelRegions<'a, T: Sample> {
    /// Path of the level's image array in the group.
    pub image: String,
    /// Level shape `z, y, x`.
    pub shape: [u64; 3],
    /// Downsampling factor relative to level 0.
    pub factor: [u64; 3],
    /// Finest min/max grid.
    pub cells: &'a CellGrid<T>,
    /// Brick histograms.
    pub histograms: &'a LevelHistograms,
    /// Bricks written.
    pub written: u64,
    /// Bricks skipped as empty.
    pub empty: u64,
}

/// Writes the region arrays and returns the metadata document and the channels' display
/// windows (for `omero`).
///
/// # Errors
/// When a group or an array cannot be created or written.
pub fn write_region_metadata<T: Sample>(
    writer: &StoreWriter,
    levels: &[LevelRegions<'_, T>],
    stats: &[ChannelAccumulator],
    labels: &[String],
    brick: [u64; 3],
) -> Result<(RegionMetadata, Vec<ChannelDisplay>), RegionWriteError> {
    let cannot_write = |array: &str| {
        let array = array.to_string();
        move |source: ArrayError| RegionWriteError::WriteArray {
            path: writer.output.clone(),
            array,
            source: Box::new(source),
        }
    };
    let channels = stats.len();
    let mut channel_stats = Vec::new();
    let mut displays = Vec::new();
    let mut binnings = Vec::new();
    for (c, s) in stats.iter().enumerate() {
        let binning = s.binning::<T>();
        let percentiles = s.percentiles::<T>(&PERCENTS);
        let valid = s.count > 0;
        let at = |p: f64| percentiles.iter().find(|x| x.percent == p).map(|x| x.value);
        // The `omero` window holds JSON numbers only: infinities become the largest finite
        // values of the type, and a NaN (never expected) 0.
        let finite = |v: f64| {
            if v.is_nan() {
                0.0
            } else {
                v.clamp(-(f32::MAX as f64), f32::MAX as f64)
            }
        };
        displays.push(ChannelDisplay {
            label: labels[c].clone(),
            min: if valid { finite(s.min) } else { 0.0 },
            max: if valid { finite(s.max) } else { 0.0 },
            start: finite(at(0.1).unwrap_or(0.0)),
            end: finite(at(99.9).unwrap_or(0.0)),
        });
        channel_stats.push(ChannelStatistics {
            label: labels[c].clone(),
            min: valid.then_some(s.min),
            max: valid.then_some(s.max),
            mean: valid.then(|| s.sum / s.count as f64),
            voxels: s.count + s.nan,
            nan_voxels: s.nan,
            percentiles,
            histogram_edges: binning.edges::<T>(),
        });
        binnings.push(binning);
    }

    writer.write_group("residency")?;
    let mut region_levels = Vec::new();
    for (i, level) in levels.iter().enumerate() {
        writer.write_group(&format!("residency/{i}"))?;
        writer.write_group(&format!("residency/{i}/minmax"))?;
        writer.write_group(&format!("residency/{i}/range"))?;
        let (mut minmax, mut range) = (Vec::new(), Vec::new());
        let mut grid = level.cells.clone();
        let mut k = 0;
        loop {
            let g = grid.grid;
            for (kind, exact, out) in [("minmax", false, &mut minmax), ("range", true, &mut range)]
            {
                let path = format!("residency/{i}/{kind}/{k}");
                let array = writer.create_array(
                    &format!("/{path}"),
                    &ArrayLayout {
                        shape: vec![channels as u64, 2, g[0], g[1], g[2]],
                        chunk: vec![1, 2, g[0].min(64), g[1].min(64), g[2].min(64)],
                        inner_chunk: None,
                        format: T::FORMAT,
                        dimension_names: None,
                    },
                )?;
                array
                    .store_array_subset(
                        &ArraySubset::new_with_shape(array.shape().to_vec()),
                        grid.to_min_max_array(exact).as_slice(),
                    )
                    .map_err(cannot_write(&path))?;
                out.push(MinMaxGrid {
                    path,
                    cell_shape: [CELL << k; 3],
                    grid_shape: g,
                });
            }
            if g == [1, 1, 1] {
                break;
            }
            grid = grid.coarsen();
            k += 1;
        }
        let hb = level.histograms.bricks;
        let hist_path = format!("residency/{i}/histogram");
        let hist = writer.create_array(
            &format!("/{hist_path}"),
            &ArrayLayout {
                shape: vec![channels as u64, hb[0], hb[1], hb[2], HISTOGRAM_BINS as u64],
                chunk: vec![
                    1,
                    hb[0].min(16),
                    hb[1].min(16),
                    hb[2].min(16),
                    HISTOGRAM_BINS as u64,
                ],
                inner_chunk: None,
                format: SampleType::U32,
                dimension_names: None,
            },
        )?;
        hist.store_array_subset(
            &ArraySubset::new_with_shape(hist.shape().to_vec()),
            level.histograms.binned(&binnings).as_slice(),
        )
        .map_err(cannot_write(&hist_path))?;
        region_levels.push(RegionLevel {
            image: level.image.clone(),
            shape: level.shape,
            factor: level.factor,
            minmax,
            range,
            histogram: hist_path,
            bricks_written: level.written,
            bricks_empty: level.empty,
        });
    }
    let regions = RegionMetadata {
        version: REGIONS_VERSION.into(),
        path: "residency".into(),
        cell_shape: [CELL; 3],
        halo: HALO,
        brick_shape: brick,
        histogram_bins: HISTOGRAM_BINS,
        levels: region_levels,
        channels: channel_stats,
    };
    Ok((regions, displays))
}
