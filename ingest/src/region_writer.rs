//! Writing region metadata into a store as the pass goes: the min/max grid hierarchy and the
//! brick histograms of every level as Zarr arrays under `residency/`, and the
//! [`RegionMetadata`] document at the end.
//!
//! Rows of cells are written as soon as they are final (no later plane can reach them, halo
//! included), eight rows (one chunk) at a time, and folded into the coarser grids, which are
//! written the same way; so a pass holds a few rows per level, never a whole grid. Brick
//! histograms are binned by each channel's range, which is known only at the end: their
//! final rows go to a scratch file in the store's temporary folder, and are binned and written
//! row by row when the pass ends.

use rayon::prelude::*;
use std::path::{Path, PathBuf};

use residency_schemas::{
    ChannelStatistics, HISTOGRAM_BINS, MinMaxGrid, REGIONS_VERSION, RegionLevel, RegionMetadata,
};
use zarrs::array::{Array, ArrayError, ArraySubset};

use crate::ome::ChannelDisplay;
pub use crate::region_scratch::{ScratchCause, ScratchError};

use crate::region_scratch::{CellRecords, HistogramRecords, LevelRecords};
use crate::regions::{
    Binning, CELL, CHUNK_ROWS, CellGrid, ChannelAccumulator, HALO, HistogramBlock, LevelHistograms,
};
use crate::sample_format::{Sample, SampleType};
use crate::store::{ArrayLayout, Store, StoreError, StoreWriter};

/// Region metadata that cannot be written into a store.
#[derive(Debug, thiserror::Error)]
pub enum RegionWriteError {
    /// A group or an array cannot be created.
    #[error(transparent)]
    Store(#[from] StoreError),
    /// A scratch file of region metadata cannot be written or read back.
    #[error(transparent)]
    Scratch(#[from] ScratchError),
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
pub(crate) const PERCENTS: [f64; 5] = [0.1, 1.0, 50.0, 99.0, 99.9];

/// Scratch folder (in the store's temporary folder) of the brick histograms, and of the
/// columns' cells until their rows are final.
pub(crate) const SCRATCH_FOLDER: &str = ".region-scratch";

/// The channels' statistics, display windows and histogram binnings, from what the pass
/// gathered.
pub(crate) fn channel_summaries<T: Sample>(
    stats: &[ChannelAccumulator],
    labels: &[String],
) -> (Vec<ChannelStatistics>, Vec<ChannelDisplay>, Vec<Binning>) {
    let mut channel_stats = Vec::new();
    let mut displays = Vec::new();
    let mut binnings = Vec::new();
    for (c, s) in stats.iter().enumerate() {
        let binning = s.binning();
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
    (channel_stats, displays, binnings)
}

/// The region metadata document of finished levels.
pub(crate) fn region_document(
    levels: Vec<RegionLevel>,
    channels: Vec<ChannelStatistics>,
    brick: [u64; 3],
) -> RegionMetadata {
    RegionMetadata {
        version: REGIONS_VERSION.into(),
        path: "residency".into(),
        cell_shape: [CELL; 3],
        halo: HALO,
        brick_shape: brick,
        histogram_bins: HISTOGRAM_BINS,
        levels,
        channels,
    }
}

/// One grid of a level's min/max hierarchy (cells `CELL << k` voxels wide) being written:
/// its two arrays and the rows not yet written.
struct GridRows<T: Sample> {
    /// Cells `z, y, x`.
    grid: [u64; 3],
    /// Haloed ranges.
    minmax: Array<Store>,
    /// Exact ranges.
    range: Array<Store>,
    minmax_path: String,
    range_path: String,
    /// Final rows not yet written (a window starting on a multiple of [`CHUNK_ROWS`]).
    pending: CellGrid<T>,
}

/// Writes one level's region metadata as the pass makes it final: rows of min/max cells
/// (and the coarser grids from them) and rows of brick histograms.
pub(crate) struct LevelRegionWriter<T: Sample> {
    output: PathBuf,
    image: String,
    shape: [u64; 3],
    factor: [u64; 3],
    channels: usize,
    /// The min/max hierarchy's arrays (none in a partition, which writes no arrays).
    grids: Vec<GridRows<T>>,
    /// The histogram array and its path (none in a partition).
    histogram: Option<(Array<Store>, String)>,
    /// Brick histograms waiting for the channels' binnings.
    histograms: HistogramRecords,
    /// Cells waiting for other columns or partitions to pass their rows (a level made in
    /// columns, a partition's levels, and `finalize`'s levels below the hand-over level).
    cells: Option<CellRecords>,
}

impl<T: Sample> LevelRegionWriter<T> {
    /// Creates the level's region groups and arrays (level `index` of the image, its image
    /// array at `image`) and its scratch files (`cell_records`: rows of cells come from
    /// several columns or partitions, see [`LevelRegionWriter::assemble_cells`]).
    ///
    /// # Errors
    /// When a group, an array or the scratch file cannot be created.
    #[allow(clippy::too_many_arguments)]
    pub fn create(
        writer: &StoreWriter,
        index: usize,
        image: &str,
        shape: [u64; 3],
        factor: [u64; 3],
        channels: usize,
        brick: [u64; 3],
        cell_records: bool,
    ) -> Result<Self, RegionWriteError> {
        if index == 0 {
            writer.write_group("residency")?;
        }
        writer.write_group(&format!("residency/{index}"))?;
        writer.write_group(&format!("residency/{index}/minmax"))?;
        writer.write_group(&format!("residency/{index}/range"))?;
        // The grids' shapes, finest first, down to one cell.
        let mut shapes = vec![shape.map(|s| s.div_ceil(CELL))];
        while let Some(&g) = shapes.last().filter(|&&g| g != [1, 1, 1]) {
            shapes.push(g.map(|s| s.div_ceil(2)));
        }
        // Their arrays are made on every core: each is a few folders and a file.
        let grids = shapes
            .into_par_iter()
            .enumerate()
            .map(|(k, g)| -> Result<GridRows<T>, RegionWriteError> {
                let layout = ArrayLayout {
                    shape: vec![channels as u64, 2, g[0], g[1], g[2]],
                    chunk: vec![1, 2, g[0].min(CHUNK_ROWS), g[1].min(64), g[2].min(64)],
                    inner_chunk: None,
                    format: T::FORMAT,
                    dimension_names: None,
                };
                let minmax_path = format!("residency/{index}/minmax/{k}");
                let range_path = format!("residency/{index}/range/{k}");
                Ok(GridRows {
                    grid: g,
                    minmax: writer.create_array(&format!("/{minmax_path}"), &layout)?,
                    range: writer.create_array(&format!("/{range_path}"), &layout)?,
                    minmax_path,
                    range_path,
                    pending: CellGrid::window(channels, [g[1], g[2]], 0..0, g[0]),
                })
            })
            .collect::<Result<Vec<_>, _>>()?;
        let bricks: [u64; 3] = std::array::from_fn(|a| shape[a].div_ceil(brick[a]));
        let histogram_path = format!("residency/{index}/histogram");
        let histogram = writer.create_array(
            &format!("/{histogram_path}"),
            &ArrayLayout {
                shape: vec![
                    channels as u64,
                    bricks[0],
                    bricks[1],
                    bricks[2],
                    HISTOGRAM_BINS as u64,
                ],
                chunk: vec![
                    1,
                    1,
                    bricks[1].min(16),
                    bricks[2].min(16),
                    HISTOGRAM_BINS as u64,
                ],
                inner_chunk: None,
                format: SampleType::U32,
                dimension_names: None,
            },
        )?;
        let folder = writer.partial.join(SCRATCH_FOLDER);
        let cells = if cell_records {
            Some(CellRecords::create(folder.join(format!("{index}.cells")))?)
        } else {
            None
        };
        Ok(Self {
            output: writer.output.clone(),
            image: image.to_string(),
            shape,
            factor,
            channels,
            grids,
            histogram: Some((histogram, histogram_path)),
            histograms: HistogramRecords::create(folder.join(format!("{index}.histograms")))?,
            cells,
        })
    }

    /// A partition's writer for a level of `shape`: it writes no arrays, only records of its
    /// rows of cells and brick histograms, in `folder` as `STEM.cells` and `STEM.histograms`,
    /// for `finalize` (see [`LevelRegionWriter::into_records`] and
    /// [`LevelRegionWriter::adopt`]).
    ///
    /// # Errors
    /// When a file cannot be created.
    pub fn for_partition(
        folder: &Path,
        stem: &str,
        shape: [u64; 3],
        channels: usize,
    ) -> Result<Self, RegionWriteError> {
        Ok(Self {
            output: folder.to_path_buf(),
            image: String::new(),
            shape,
            factor: [1; 3],
            channels,
            grids: Vec::new(),
            histogram: None,
            histograms: HistogramRecords::create(folder.join(format!("{stem}.histograms")))?,
            cells: Some(CellRecords::create(folder.join(format!("{stem}.cells")))?),
        })
    }

    /// A partition's records, with its files complete.
    ///
    /// # Errors
    /// When a file cannot be written.
    pub fn into_records(self) -> Result<LevelRecords, RegionWriteError> {
        Ok(LevelRecords {
            cells: match self.cells {
                Some(cells) => cells.into_records()?,
                None => Vec::new(),
            },
            histograms: self.histograms.into_records()?,
        })
    }

    /// Takes in a partition's records of this level, in its files `STEM.cells` and
    /// `STEM.histograms` in `folder`, which stay open and are read where they lie: its cells
    /// when their chunk of rows is assembled, its histograms when they are binned.
    ///
    /// # Errors
    /// When a file cannot be read or written.
    ///
    /// # Panics
    /// When the level was not created with cell records.
    pub fn adopt(
        &mut self,
        folder: &Path,
        stem: &str,
        records: &LevelRecords,
    ) -> Result<(), RegionWriteError> {
        self.histograms.adopt(
            &folder.join(format!("{stem}.histograms")),
            &records.histograms,
        )?;
        self.cells
            .as_mut()
            .expect("cell records")
            .adopt(&folder.join(format!("{stem}.cells")), &records.cells)?;
        Ok(())
    }

    /// Takes the rows of `cells` and `histograms` (the pass's windows over the level, or a
    /// column's blocks) that no plane from `delivered` on can reach, every plane before it
    /// being made: min/max cell rows whose halo ends before it, and whole brick rows. A
    /// column's cells go to the scratch file until every column has passed them (see
    /// [`LevelRegionWriter::assemble_cells`]).
    ///
    /// # Errors
    /// When an array or the scratch file cannot be written.
    pub fn release(
        &mut self,
        cells: &mut CellGrid<T>,
        histograms: &mut LevelHistograms,
        delivered: u64,
        brick_depth: u64,
    ) -> Result<(), RegionWriteError> {
        let (cell_rows, brick_rows) = if delivered >= self.shape[0] {
            (u64::MAX, u64::MAX)
        } else {
            (
                delivered.saturating_sub(HALO) / CELL,
                delivered / brick_depth,
            )
        };
        let rows = cells.split_before(cell_rows);
        if rows.rows().is_empty() {
        } else if let Some(records) = &mut self.cells {
            // A column's or a partition's rows: final for it, but others fold into them too.
            records.spill(&rows)?;
        } else {
            self.push_cells(&rows)?;
        }
        let block = histograms.split_before(brick_rows);
        if !block.fine.is_empty() {
            self.push_histograms(&block)?;
        }
        Ok(())
    }

    /// Assembles the columns' cells of every whole chunk of rows before `end` (and of the
    /// rows left, past the level's last row) and writes them as [`push_cells`] does.
    ///
    /// # Errors
    /// When the scratch file cannot be read or an array cannot be written.
    ///
    /// [`push_cells`]: LevelRegionWriter::push_cells
    pub fn assemble_cells(&mut self, end: u64) -> Result<(), RegionWriteError> {
        let Some(grid) = self.grids.first() else {
            // A partition's: `finalize` assembles its rows.
            return Ok(());
        };
        let [depth, gy, gx] = grid.grid;
        let end = end.min(depth);
        loop {
            let records = self.cells.as_mut().expect("cell records");
            let start = records.next;
            let stop = (start / CHUNK_ROWS + 1) * CHUNK_ROWS;
            if start >= depth || (stop > end && end < depth) {
                return Ok(());
            }
            let stop = stop.min(depth);
            let mut rows = CellGrid::window(self.channels, [gy, gx], start..stop, depth);
            records.take_chunk(start / CHUNK_ROWS, &mut rows)?;
            records.next = stop;
            self.push_cells(&rows)?;
        }
    }

    /// Takes final rows of min/max cells (the next rows of the level, in order): writes every
    /// whole chunk of rows, and folds whole pairs of rows into the next coarser grid.
    ///
    /// # Errors
    /// When an array cannot be written.
    pub fn push_cells(&mut self, rows: &CellGrid<T>) -> Result<(), RegionWriteError> {
        self.push_grid(0, rows)
    }

    /// Adds rows of cells to grid `k` and writes its whole chunks of rows, and the rows they
    /// coarsen into in the coarser grids; the arrays' writes go to every core.
    fn push_grid(&mut self, k: usize, rows: &CellGrid<T>) -> Result<(), RegionWriteError> {
        // (grid, exact, rows written, their ranges)
        let mut writes: Vec<(usize, bool, ArraySubset, Vec<T>)> = Vec::new();
        let mut next = Some((k, std::borrow::Cow::Borrowed(rows)));
        while let Some((k, rows)) = next.take() {
            let grid = &mut self.grids[k];
            debug_assert_eq!(rows.z0, grid.pending.rows().end);
            grid.pending.extend_to(rows.rows().end);
            grid.pending.merge(&rows);
            let held = grid.pending.rows();
            // Whole chunks, or everything at the level's end.
            let end = if held.end == grid.grid[0] {
                held.end
            } else {
                held.end / CHUNK_ROWS * CHUNK_ROWS
            };
            if end <= held.start {
                break;
            }
            let done = grid.pending.split_before(end);
            let subset = ArraySubset::new_with_ranges(&[
                0..self.channels as u64,
                0..2,
                done.rows(),
                0..grid.grid[1],
                0..grid.grid[2],
            ]);
            for exact in [false, true] {
                writes.push((k, exact, subset.clone(), done.to_min_max_array(exact)));
            }
            if k + 1 < self.grids.len() {
                // Chunks hold an even number of rows, so the written rows coarsen whole.
                next = Some((k + 1, std::borrow::Cow::Owned(done.coarsen())));
            }
        }
        writes
            .into_par_iter()
            .try_for_each(|(k, exact, subset, values)| {
                let grid = &self.grids[k];
                let (array, path) = if exact {
                    (&grid.range, &grid.range_path)
                } else {
                    (&grid.minmax, &grid.minmax_path)
                };
                array
                    .store_array_subset(&subset, values.as_slice())
                    .map_err(|source| RegionWriteError::WriteArray {
                        path: self.output.clone(),
                        array: path.clone(),
                        source: Box::new(source),
                    })
            })
    }

    /// Takes final brick histograms (a block of bricks no later plane reaches) into the
    /// scratch file, until the channels' binnings are known.
    ///
    /// # Errors
    /// When the scratch file cannot be written.
    pub fn push_histograms(&mut self, block: &HistogramBlock) -> Result<(), RegionWriteError> {
        Ok(self.histograms.push(block)?)
    }

    /// Bins the histograms of the scratch file by the channels' `binnings` and writes them
    /// row by row, removes the scratch file, and returns the level's entry in the document.
    ///
    /// # Errors
    /// When the scratch file cannot be read back or an array cannot be written.
    pub fn finish(
        mut self,
        binnings: &[Binning],
        written: u64,
        empty: u64,
    ) -> Result<RegionLevel, RegionWriteError> {
        if self.cells.is_some() {
            self.assemble_cells(u64::MAX)?;
        }
        debug_assert!(self.grids.iter().all(|g| g.pending.rows().end == g.grid[0]));
        let (histogram, histogram_path) = self.histogram.take().expect("a store's level");
        let channels = self.channels as u64;
        let output = self.output.clone();
        let mut binned = Vec::new();
        self.histograms.for_each(|block| {
            let [z0, y0, x0] = block.origin;
            let [nz, ny, nx] = block.bricks;
            let per_channel = (nz * ny * nx) as usize;
            binned.clear();
            binned.resize(block.fine.len() * HISTOGRAM_BINS, 0u32);
            for (i, f) in block.fine.iter().enumerate() {
                binnings[i / per_channel]
                    .bin_into(f, &mut binned[i * HISTOGRAM_BINS..(i + 1) * HISTOGRAM_BINS]);
            }
            let subset = ArraySubset::new_with_ranges(&[
                0..channels,
                z0..z0 + nz,
                y0..y0 + ny,
                x0..x0 + nx,
                0..HISTOGRAM_BINS as u64,
            ]);
            histogram
                .store_array_subset(&subset, binned.as_slice())
                .map_err(|source| RegionWriteError::WriteArray {
                    path: output.clone(),
                    array: histogram_path.clone(),
                    source: Box::new(source),
                })
        })?;
        self.histograms.remove()?;
        if let Some(cells) = self.cells {
            cells.remove()?;
        }
        let grids = |exact: bool| {
            self.grids
                .iter()
                .enumerate()
                .map(|(k, g)| MinMaxGrid {
                    path: if exact { &g.range_path } else { &g.minmax_path }.clone(),
                    cell_shape: [CELL << k; 3],
                    grid_shape: g.grid,
                })
                .collect()
        };
        Ok(RegionLevel {
            image: self.image,
            shape: self.shape,
            factor: self.factor,
            minmax: grids(false),
            range: grids(true),
            histogram: histogram_path,
            bricks_written: written,
            bricks_empty: empty,
        })
    }
}
