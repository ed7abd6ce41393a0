//! Region metadata computed during the pass: conservative min/max cell grids, per-brick
//! histograms and whole-channel statistics.
//!
//! **Min/max cells.** Cell `(k, j, i)` of a level covers voxels `[8k, 8k+8) × [8j, 8j+8) ×
//! [8i, 8i+8)`. Two ranges are kept per cell, gathered in the same pass:
//! - the *haloed* range, over those voxels plus a one-voxel halo on every side (clipped to the
//!   volume). A trilinear sample at any position inside the cell, whichever voxel-centre
//!   convention the renderer uses, interpolates only voxels within the halo, so the
//!   interpolated value lies within `[min, max]`: this is what culling needs;
//! - the *exact* range, over the cell's own voxels only: region queries answer from it, so a
//!   box aligned to the cells gets exactly the range of its voxels.
//!
//! **Histograms.** Each sample has a fine key (see
//! [`Sample::key`](crate::sample_format::Sample::key)). Bricks count keys while streaming; at
//! the end of the pass, the keys spanned by the channel's global range are grouped into at
//! most [`HISTOGRAM_BINS`](residency_schemas::HISTOGRAM_BINS) equal runs, whose lower edges
//! become the bin edges. Counts are exact: every voxel falls in exactly one bin.
//!
//! The modules: [`cells`](CellGrid), [`histograms`](LevelHistograms) and
//! [`statistics`](ChannelAccumulator).

pub(crate) mod cells;
pub(crate) mod histograms;
pub(crate) mod statistics;

pub use self::cells::{CELL, CHUNK_ROWS, CellGrid, HALO, SliceCells, cells_reached, slice_cells};
pub use self::histograms::{Binning, BrickStats, HistogramBlock, LevelHistograms, StatsScratch};
pub use self::statistics::ChannelAccumulator;
