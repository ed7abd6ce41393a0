//! Region metadata of one dataset, loaded once from the store's `residency` arrays, and the
//! answers built from it: region queries (`/NAME/regions`) and the binary min/max hierarchy
//! (`/NAME/minmax`). Nothing here decodes an image brick.
//!
//! **Query contract.** A box of voxels of one level is answered by walking two pyramids from
//! their root cell down: the exact min/max cells (8³ voxels at the finest grid, doubling per
//! grid) and the brick histograms (one cell per brick, summed 2×2×2 per coarser grid). A cell
//! inside the box is taken whole; a cell crossing the box's edge is split into its children,
//! and at the finest grid taken whole. So the answer covers the smallest union of finest cells
//! (bricks for the histogram) containing the box: never narrower than the truth, exact for a
//! box aligned to cells (bricks) or ending at the level's edge, and found in time that grows
//! with the box's surface, not its volume.

use std::collections::{HashMap, HashSet};
use std::sync::Arc;

use axum::body::Bytes;
use residency_schemas::SampleType;
use residency_schemas::server::{RegionAnswer, RegionHistogram, VoxelBox};
use residency_schemas::wire::{
    MINMAX_MAGIC, MinMaxGridBlock, MinMaxHierarchyHeader, MinMaxLevelBlock, encode_framed,
};
use residency_schemas::{MinMaxGrid, RegionMetadata};
use residency_store::at_once;
use residency_store::region_array::{ArrayPart, RegionArrayError, read_region_array};
use zarrs::storage::ReadableListableStorageTraits;

use crate::bricks::ImagePyramid;

/// A pyramid of grids: grid `k` has cells of `cell · 2^k` voxels; each cell of grid `k + 1`
/// aggregates the (up to) 2×2×2 cells below it in grid `k`.
#[derive(Clone, Debug)]
struct GridPyramid {
    cell: [u64; 3],
    shapes: Vec<[u64; 3]>,
}

impl GridPyramid {
    /// Visits cells covering `[lo, hi)` (voxels `z, y, x` of a level of `shape`) as
    /// `(grid, linear index)`: every finest cell the box touches is covered exactly once, by
    /// itself or by a coarser cell made only of such cells. Returns the voxel box covered: the
    /// box widened to whole finest cells, clipped to the level.
    fn cover(
        &self,
        shape: [u64; 3],
        lo: [u64; 3],
        hi: [u64; 3],
        mut visit: impl FnMut(usize, usize),
    ) -> ([u64; 3], [u64; 3]) {
        let clo: [u64; 3] = std::array::from_fn(|a| lo[a] / self.cell[a]);
        let chi: [u64; 3] = std::array::from_fn(|a| hi[a].div_ceil(self.cell[a]));
        self.fold_box(0, clo, chi, &mut visit);
        (
            std::array::from_fn(|a| clo[a] * self.cell[a]),
            std::array::from_fn(|a| (chi[a] * self.cell[a]).min(shape[a])),
        )
    }

    /// Visits the cells `[lo, hi)` of grid `k`: the part aligned to pairs is handed to grid
    /// `k + 1`, and only the ragged border is visited here, so the cost grows with the box's
    /// surface.
    fn fold_box(&self, k: usize, lo: [u64; 3], hi: [u64; 3], visit: &mut impl FnMut(usize, usize)) {
        if (0..3).any(|a| lo[a] >= hi[a]) {
            return;
        }
        // Cells of grid k + 1 whose children all lie in the box; at the grid's far edge a
        // coarse cell may have a single child.
        let n = self.shapes[k];
        let ilo: [u64; 3] = std::array::from_fn(|a| lo[a].div_ceil(2));
        let ihi: [u64; 3] = std::array::from_fn(|a| {
            if hi[a] == n[a] {
                hi[a].div_ceil(2)
            } else {
                hi[a] / 2
            }
        });
        if k + 1 == self.shapes.len() || (0..3).any(|a| ilo[a] >= ihi[a]) {
            self.each(k, lo, hi, visit);
            return;
        }
        self.fold_box(k + 1, ilo, ihi, visit);
        let alo: [u64; 3] = ilo.map(|v| 2 * v);
        let ahi: [u64; 3] = std::array::from_fn(|a| (2 * ihi[a]).min(hi[a]));
        // The border: z slabs, then y slabs inside them, then x slabs inside both.
        self.each(k, lo, [alo[0], hi[1], hi[2]], visit);
        self.each(k, [ahi[0], lo[1], lo[2]], hi, visit);
        self.each(k, [alo[0], lo[1], lo[2]], [ahi[0], alo[1], hi[2]], visit);
        self.each(k, [alo[0], ahi[1], lo[2]], [ahi[0], hi[1], hi[2]], visit);
        self.each(k, [alo[0], alo[1], lo[2]], [ahi[0], ahi[1], alo[2]], visit);
        self.each(k, [alo[0], alo[1], ahi[2]], [ahi[0], ahi[1], hi[2]], visit);
    }

    /// Visits every cell `[lo, hi)` of grid `k`.
    fn each(&self, k: usize, lo: [u64; 3], hi: [u64; 3], visit: &mut impl FnMut(usize, usize)) {
        let [_, gy, gx] = self.shapes[k];
        for z in lo[0]..hi[0] {
            for y in lo[1]..hi[1] {
                let row = ((z * gy + y) * gx) as usize;
                for x in lo[2]..hi[2] {
                    visit(k, row + x as usize);
                }
            }
        }
    }
}

/// Region data of one level: per channel, the min/max pyramid (values per grid, `[min, max]`
/// pairs) and the histogram pyramid (`bins` counts per cell).
struct LevelIndex {
    shape: [u64; 3],
    ranges: GridPyramid,
    range_values: Vec<Vec<Vec<[f64; 2]>>>,
    exact_ranges: bool,
    bricks: GridPyramid,
    histograms: Vec<Vec<Vec<u64>>>,
}

/// Everything the server answers region questions from, for one dataset.
pub(crate) struct RegionIndex {
    /// The store's region metadata document.
    pub(crate) meta: RegionMetadata,
    levels: Vec<LevelIndex>,
    minmax_docs: Vec<Bytes>,
}

/// A bad region or min/max query (answered 400).
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub(crate) enum QueryError {
    /// A coordinate parameter (`min`, `max`) is not `x,y,z`.
    #[error("{parameter} '{text}' is not three integers x,y,z")]
    NotXyz {
        /// The parameter's name.
        parameter: &'static str,
        /// Its value as given.
        text: String,
    },
    /// No such pyramid level.
    #[error("level {level} does not exist (the dataset has {levels})")]
    NoLevel {
        /// The level asked for.
        level: usize,
        /// Levels of the dataset.
        levels: usize,
    },
    /// No such channel.
    #[error("channel {channel} does not exist (the dataset has {channels})")]
    NoChannel {
        /// The channel asked for.
        channel: usize,
        /// Channels of the dataset.
        channels: usize,
    },
    /// The box holds no voxel.
    #[error("empty box: min {min:?} must be below max {max:?} on every axis")]
    EmptyBox {
        /// First voxel asked for, `x, y, z`.
        min: [u64; 3],
        /// One past the last voxel asked for, `x, y, z`.
        max: [u64; 3],
    },
    /// The box reaches past the level.
    #[error("box max {max:?} lies outside level {level} (x, y, z size {size:?})")]
    OutsideLevel {
        /// One past the last voxel asked for, `x, y, z`.
        max: [u64; 3],
        /// The level.
        level: usize,
        /// The level's size, `x, y, z`.
        size: [u64; 3],
    },
}

/// Why a dataset's region metadata could not be loaded.
#[derive(Debug, thiserror::Error)]
pub(crate) enum RegionsError {
    /// The region metadata lists no level.
    #[error("region metadata lists no level")]
    NoLevel,
    /// A region array could not be opened or read.
    #[error("cannot read region array '{path}': {source}")]
    ReadArray {
        /// The array's path in the store.
        path: String,
        /// What zarrs said.
        #[source]
        source: Box<RegionArrayError>,
    },
    /// A region array holds another number of values than its description implies.
    #[error("{kind} array '{path}' holds {found} {unit}, expected {expected}")]
    ValueCount {
        /// `region` or `histogram`.
        kind: &'static str,
        /// The array's path in the store.
        path: String,
        /// `values` or `counts`.
        unit: &'static str,
        /// Values found.
        found: usize,
        /// Values expected.
        expected: usize,
    },
}

/// Reads a whole region array as little-endian bytes and as `f64` values, naming it in the
/// error.
fn read_array(
    store: &Arc<dyn ReadableListableStorageTraits>,
    path: &str,
    data_type: SampleType,
) -> Result<(Vec<u8>, Vec<f64>), RegionsError> {
    read_region_array(store, path, ArrayPart::Whole, data_type).map_err(|source| {
        RegionsError::ReadArray {
            path: path.to_string(),
            source: Box::new(source),
        }
    })
}

/// Splits a grid array `[c, 2, gz, gy, gx]` into per-channel `[min, max]` pairs.
fn pairs(values: &[f64], channels: usize, cells: usize) -> Vec<Vec<[f64; 2]>> {
    (0..channels)
        .map(|c| {
            let base = c * 2 * cells;
            (0..cells)
                .map(|i| [values[base + i], values[base + cells + i]])
                .collect()
        })
        .collect()
}

fn cells_of(shape: [u64; 3]) -> usize {
    (shape[0] * shape[1] * shape[2]) as usize
}

/// Sums a brick histogram grid `[bz, by, bx, bins]` into its 2×2×2 coarser grid.
fn coarser_histograms(fine: &[u64], shape: [u64; 3], bins: usize) -> ([u64; 3], Vec<u64>) {
    let coarse = shape.map(|s| s.div_ceil(2));
    let mut out = vec![0u64; cells_of(coarse) * bins];
    for z in 0..shape[0] {
        for y in 0..shape[1] {
            for x in 0..shape[2] {
                let i = ((z * shape[1] + y) * shape[2] + x) as usize;
                let o = (((z / 2) * coarse[1] + y / 2) * coarse[2] + x / 2) as usize;
                for b in 0..bins {
                    out[o * bins + b] += fine[i * bins + b];
                }
            }
        }
    }
    (coarse, out)
}

impl RegionIndex {
    /// Loads the region index of a dataset's store from its opened `pyramid` (whose image
    /// attributes list the region arrays, read from the pyramid's store), or `None` for a
    /// store without region metadata.
    ///
    /// # Errors
    /// [`RegionsError`] when a region array cannot be read, or the arrays disagree with the
    /// metadata.
    pub(crate) fn load(pyramid: &ImagePyramid) -> Result<Option<Self>, RegionsError> {
        let store = &pyramid.store;
        let Some(meta) = &pyramid.attributes.regions else {
            return Ok(None);
        };
        if meta.levels.is_empty() {
            return Err(RegionsError::NoLevel);
        }
        let data_type = pyramid.sample_type;
        let channels = meta.channels.len();
        let bins = meta.histogram_bins;
        // Every region array the index needs, read side by side (over an object store each
        // read waits on the network) in the order the loop below takes them, up to the first
        // that fails; the loop meets that failure where a loop reading them in turn would.
        let mut seen = HashSet::new();
        let wanted: Vec<(&str, SampleType)> = meta
            .levels
            .iter()
            .flat_map(|level| {
                let grids = level.minmax.iter().chain(&level.range);
                grids
                    .map(|g| (g.path.as_str(), data_type))
                    .chain([(level.histogram.as_str(), SampleType::U32)])
            })
            .filter(|wanted| seen.insert(*wanted))
            .collect();
        let read = at_once::try_read_all(&wanted, |&(path, t)| read_array(store, path, t));
        let mut read_ahead: HashMap<(String, SampleType), _> = wanted
            .iter()
            .map(|&(path, t)| (path.to_string(), t))
            .zip(read)
            .collect();
        // What was not read ahead (an array taken a second time, or past a failure) is read now.
        let mut take_array = |path: &str, t| {
            read_ahead
                .remove(&(path.to_string(), t))
                .unwrap_or_else(|| read_array(store, path, t))
        };
        let mut levels = Vec::new();
        let mut blocks: Vec<Vec<MinMaxLevelBlock>> = vec![Vec::new(); channels];
        let mut payloads: Vec<Vec<u8>> = vec![Vec::new(); channels];
        for (l, level) in meta.levels.iter().enumerate() {
            // The binary hierarchy: haloed grids, per channel.
            let mut level_blocks: Vec<Vec<MinMaxGridBlock>> = vec![Vec::new(); channels];
            let mut haloed = Vec::new();
            for grid in &level.minmax {
                let (raw, values) = take_array(&grid.path, data_type)?;
                let cells = cells_of(grid.grid_shape);
                let per_channel = raw.len() / channels.max(1);
                if values.len() != channels * 2 * cells {
                    return Err(RegionsError::ValueCount {
                        kind: "region",
                        path: grid.path.clone(),
                        unit: "values",
                        found: values.len(),
                        expected: channels * 2 * cells,
                    });
                }
                for c in 0..channels {
                    let payload = &mut payloads[c];
                    level_blocks[c].push(MinMaxGridBlock {
                        cell_shape: grid.cell_shape,
                        grid_shape: grid.grid_shape,
                        offset: payload.len() as u64,
                        length: per_channel as u64,
                    });
                    payload.extend_from_slice(&raw[c * per_channel..(c + 1) * per_channel]);
                }
                // The haloed ranges answer queries only for stores without exact ones.
                if level.range.is_empty() {
                    haloed.push(pairs(&values, channels, cells));
                }
            }
            for (c, grids) in level_blocks.into_iter().enumerate() {
                blocks[c].push(MinMaxLevelBlock {
                    level: l,
                    shape: level.shape,
                    grids,
                });
            }
            // Query pyramids: exact ranges where the store has them.
            let (grids, exact_ranges): (&[MinMaxGrid], bool) = if level.range.is_empty() {
                (&level.minmax, false)
            } else {
                (&level.range, true)
            };
            let range_grids: Vec<Vec<Vec<[f64; 2]>>> = if exact_ranges {
                grids
                    .iter()
                    .map(|g| {
                        let (_, values) = take_array(&g.path, data_type)?;
                        Ok(pairs(&values, channels, cells_of(g.grid_shape)))
                    })
                    .collect::<Result<_, RegionsError>>()?
            } else {
                haloed
            };
            let range_values = (0..channels)
                .map(|c| range_grids.iter().map(|g| g[c].clone()).collect())
                .collect();
            let (_, counts) = take_array(&level.histogram, SampleType::U32)?;
            let brick_grid: [u64; 3] =
                std::array::from_fn(|a| level.shape[a].div_ceil(meta.brick_shape[a]));
            let per_channel = cells_of(brick_grid) * bins;
            if counts.len() != channels * per_channel {
                return Err(RegionsError::ValueCount {
                    kind: "histogram",
                    path: level.histogram.clone(),
                    unit: "counts",
                    found: counts.len(),
                    expected: channels * per_channel,
                });
            }
            let mut brick_shapes = vec![brick_grid];
            let mut histograms: Vec<Vec<Vec<u64>>> = (0..channels)
                .map(|c| {
                    vec![
                        counts[c * per_channel..(c + 1) * per_channel]
                            .iter()
                            .map(|&n| n as u64)
                            .collect(),
                    ]
                })
                .collect();
            while *brick_shapes.last().expect("one grid") != [1, 1, 1] {
                let shape = *brick_shapes.last().expect("one grid");
                for per_channel in &mut histograms {
                    let (_, coarse) =
                        coarser_histograms(per_channel.last().expect("one grid"), shape, bins);
                    per_channel.push(coarse);
                }
                brick_shapes.push(shape.map(|s| s.div_ceil(2)));
            }
            levels.push(LevelIndex {
                shape: level.shape,
                ranges: GridPyramid {
                    cell: grids[0].cell_shape,
                    shapes: grids.iter().map(|g| g.grid_shape).collect(),
                },
                range_values,
                exact_ranges,
                bricks: GridPyramid {
                    cell: meta.brick_shape,
                    shapes: brick_shapes,
                },
                histograms,
            });
        }
        let minmax_docs = blocks
            .into_iter()
            .zip(payloads)
            .enumerate()
            .map(|(channel, (levels, payload))| {
                let header = MinMaxHierarchyHeader {
                    channel,
                    data_type,
                    halo: meta.halo,
                    levels,
                };
                Bytes::from(encode_framed(MINMAX_MAGIC, &header, &payload))
            })
            .collect();
        Ok(Some(Self {
            meta: meta.clone(),
            levels,
            minmax_docs,
        }))
    }

    /// The framed min/max hierarchy document of `channel`.
    ///
    /// # Errors
    /// [`QueryError::NoChannel`] for a channel the dataset does not have.
    pub(crate) fn minmax_document(&self, channel: usize) -> Result<Bytes, QueryError> {
        self.minmax_docs
            .get(channel)
            .cloned()
            .ok_or(QueryError::NoChannel {
                channel,
                channels: self.minmax_docs.len(),
            })
    }

    /// Answers a region query; `min`/`max` are `x, y, z` voxel coordinates of the level,
    /// `max` exclusive.
    ///
    /// # Errors
    /// [`QueryError`] for a level or channel the dataset does not have, an empty box, or a
    /// box reaching past the level.
    pub(crate) fn query(
        &self,
        dataset: &str,
        level: usize,
        channel: usize,
        min: [u64; 3],
        max: [u64; 3],
    ) -> Result<RegionAnswer, QueryError> {
        let l = self.levels.get(level).ok_or(QueryError::NoLevel {
            level,
            levels: self.levels.len(),
        })?;
        if channel >= self.meta.channels.len() {
            return Err(QueryError::NoChannel {
                channel,
                channels: self.meta.channels.len(),
            });
        }
        let [nz, ny, nx] = l.shape;
        let (lo, hi) = ([min[2], min[1], min[0]], [max[2], max[1], max[0]]);
        if (0..3).any(|a| lo[a] >= hi[a]) {
            return Err(QueryError::EmptyBox { min, max });
        }
        if (0..3).any(|a| hi[a] > l.shape[a]) {
            return Err(QueryError::OutsideLevel {
                max,
                level,
                size: [nx, ny, nz],
            });
        }
        let to_xyz = |zyx: [u64; 3]| [zyx[2], zyx[1], zyx[0]];
        let query = VoxelBox { min, max };

        let (mut vmin, mut vmax) = (f64::INFINITY, f64::NEG_INFINITY);
        let ranges = &l.range_values[channel];
        let (mlo, mhi) = l.ranges.cover(l.shape, lo, hi, |k, i| {
            let [a, b] = ranges[k][i];
            // NaN (a cell without values) compares false and is skipped.
            if a < vmin {
                vmin = a;
            }
            if b > vmax {
                vmax = b;
            }
        });
        let seen = vmin <= vmax;
        let minmax_box = VoxelBox {
            min: to_xyz(mlo),
            max: to_xyz(mhi),
        };

        let bins = self.meta.histogram_bins;
        let mut counts = vec![0u64; bins];
        let histograms = &l.histograms[channel];
        let (hlo, hhi) = l.bricks.cover(l.shape, lo, hi, |k, i| {
            let cell = &histograms[k][i * bins..(i + 1) * bins];
            for (acc, n) in counts.iter_mut().zip(cell) {
                *acc += n;
            }
        });
        let edges = self.meta.channels[channel].histogram_edges.clone();
        counts.truncate(edges.len().saturating_sub(1).max(1));
        let hist_box = VoxelBox {
            min: to_xyz(hlo),
            max: to_xyz(hhi),
        };
        Ok(RegionAnswer {
            dataset: dataset.to_string(),
            level,
            channel,
            query,
            min: seen.then_some(vmin),
            max: seen.then_some(vmax),
            minmax_box,
            minmax_exact: l.exact_ranges && minmax_box == query,
            histogram: RegionHistogram {
                edges,
                voxels: counts.iter().sum(),
                counts,
                covered: hist_box,
                exact: hist_box == query,
            },
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The cells `cover` visits, sorted, and the box it reports.
    fn visited(
        p: &GridPyramid,
        shape: [u64; 3],
        lo: [u64; 3],
        hi: [u64; 3],
    ) -> (Vec<(usize, usize)>, [u64; 3], [u64; 3]) {
        let mut cells = Vec::new();
        let (a, b) = p.cover(shape, lo, hi, |k, i| cells.push((k, i)));
        cells.sort_unstable();
        (cells, a, b)
    }

    #[test]
    fn cover_takes_whole_cells_inside_and_splits_at_the_edges() {
        // A 20 × 20 × 20 level with 8³ cells: grids 3³, 2³, 1.
        let p = GridPyramid {
            cell: [8; 3],
            shapes: vec![[3; 3], [2; 3], [1; 3]],
        };
        let whole = visited(&p, [20; 3], [0; 3], [20; 3]);
        assert_eq!(whole, (vec![(2, 0)], [0; 3], [20; 3]));
        // Aligned to cells: exactly the cells inside.
        let aligned = visited(&p, [20; 3], [8, 0, 0], [16, 8, 8]);
        assert_eq!(aligned, (vec![(0, 9)], [8, 0, 0], [16, 8, 8]));
        // Unaligned: widened to the finest cells it touches.
        let loose = visited(&p, [20; 3], [3, 3, 3], [9, 4, 4]);
        assert_eq!(loose, (vec![(0, 0), (0, 9)], [0, 0, 0], [16, 8, 8]));
        // Ending at the volume's edge counts as aligned; the coarse cell (1, 1, 1) of grid 1,
        // clipped to the level, is the same voxels as the finest cell (2, 2, 2).
        let edge = visited(&p, [20; 3], [16, 16, 16], [20, 20, 20]);
        assert_eq!(edge, (vec![(1, 7)], [16; 3], [20; 3]));
    }

    #[test]
    fn cover_spans_every_touched_voxel_exactly_once() {
        // A 37 × 21 × 50 level of 4³ cells; for many random boxes, the voxels of the visited
        // cells are exactly the box widened to whole cells, each counted once.
        let shape = [37u64, 21, 50];
        let cell = [4u64; 3];
        let mut shapes = vec![shape.map(|s| s.div_ceil(4))];
        while *shapes.last().unwrap() != [1, 1, 1] {
            let s = *shapes.last().unwrap();
            shapes.push(s.map(|v| v.div_ceil(2)));
        }
        let p = GridPyramid { cell, shapes };
        let mut seed = 7u64;
        let mut next = |n: u64| {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 33) % n
        };
        let at = |z: u64, y: u64, x: u64| ((z * shape[1] + y) * shape[2] + x) as usize;
        for _ in 0..300 {
            let lo: [u64; 3] = std::array::from_fn(|a| next(shape[a]));
            let hi: [u64; 3] = std::array::from_fn(|a| lo[a] + 1 + next(shape[a] - lo[a]));
            let mut count = vec![0u32; (shape[0] * shape[1] * shape[2]) as usize];
            let (a, b) = p.cover(shape, lo, hi, |k, i| {
                let [_, gy, gx] = p.shapes[k];
                let c = [i as u64 / (gy * gx), (i as u64 / gx) % gy, i as u64 % gx];
                let size = cell.map(|v| v << k);
                let span = |ax: usize| c[ax] * size[ax]..((c[ax] + 1) * size[ax]).min(shape[ax]);
                for z in span(0) {
                    for y in span(1) {
                        for x in span(2) {
                            count[at(z, y, x)] += 1;
                        }
                    }
                }
            });
            for ax in 0..3 {
                assert!(a[ax] <= lo[ax] && hi[ax] <= b[ax]);
                assert!(a[ax] % 4 == 0 && lo[ax] - a[ax] < 4);
                assert!((b[ax] % 4 == 0 || b[ax] == shape[ax]) && b[ax] - hi[ax] < 4);
            }
            for z in 0..shape[0] {
                for y in 0..shape[1] {
                    for x in 0..shape[2] {
                        let p = [z, y, x];
                        let inside = (0..3).all(|ax| a[ax] <= p[ax] && p[ax] < b[ax]);
                        assert_eq!(count[at(z, y, x)], inside as u32, "{lo:?}..{hi:?} at {p:?}");
                    }
                }
            }
        }
    }

    #[test]
    fn query_errors_keep_their_messages() {
        let cases = [
            (
                QueryError::NotXyz {
                    parameter: "min",
                    text: "0,0".into(),
                },
                "min '0,0' is not three integers x,y,z",
            ),
            (
                QueryError::NoLevel {
                    level: 9,
                    levels: 3,
                },
                "level 9 does not exist (the dataset has 3)",
            ),
            (
                QueryError::NoChannel {
                    channel: 2,
                    channels: 2,
                },
                "channel 2 does not exist (the dataset has 2)",
            ),
            (
                QueryError::EmptyBox {
                    min: [5, 0, 0],
                    max: [5, 1, 1],
                },
                "empty box: min [5, 0, 0] must be below max [5, 1, 1] on every axis",
            ),
            (
                QueryError::OutsideLevel {
                    max: [31, 1, 1],
                    level: 0,
                    size: [30, 37, 21],
                },
                "box max [31, 1, 1] lies outside level 0 (x, y, z size [30, 37, 21])",
            ),
        ];
        for (error, message) in cases {
            assert_eq!(error.to_string(), message);
        }
    }

    #[test]
    fn coarser_histograms_sum_their_children() {
        // 3 × 1 × 1 bricks of 2 bins.
        let (shape, out) = coarser_histograms(&[1, 0, 2, 1, 5, 5], [3, 1, 1], 2);
        assert_eq!(shape, [2, 1, 1]);
        assert_eq!(out, vec![3, 1, 5, 5]);
    }
}
