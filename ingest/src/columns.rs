//! Columns: how a conversion keeps within `--memory-limit` whatever the plane size.
//!
//! A pass holds slabs of whole planes: two level-0 slabs one chunk deep, and each coarser
//! level's exact sums one chunk deep. That grows with the plane area, so a stitched mosaic of
//! 16384² planes would need tens of gigabytes. When the estimate of a whole-plane pass does not
//! fit the limit, the planes are cut into columns (bands of whole rows first, squares where
//! bands are still too large):
//! - levels `0..local_levels` are made column by column: each column's level-0 voxels are read
//!   (only the strips, tiles or rows they span), written and summed up the pyramid inside the
//!   column, since column edges fall on chunk edges of every such level;
//! - the first level that is not local gathers the columns' exact sums into whole planes, and
//!   the coarser levels follow from it as in a whole-plane pass.
//!
//! Columns take turns within groups of level-0 planes one slab of that first whole-plane level
//! deep, so it is complete when the last column of a group is done. Sums are exact and every
//! mean is rounded once, so a store made in columns is byte-identical to a whole-plane one.

use crate::partition::plan::PartitionPlan;
use crate::pyramid::LevelPlan;
use crate::regions::{CELL, CHUNK_ROWS};
use crate::sample_format::FINE_KEYS;
use crate::source::PlaneRegion;

/// Bytes a pass holds whatever its shape: the program and its libraries (about 13 MiB
/// resident), thread stacks, the reader thread, zarrs' and the decoders' buffers (a strip or
/// tile) and what the allocator has not yet handed back (`ingest` makes mimalloc purge freed
/// memory a second after it was last used). Measured by `tests/python/test_memory_limit.py`,
/// whose passes peak at about 0.6× their limit.
pub const FIXED_BYTES: u64 = 64 << 20;

/// How a pass cuts its level-0 planes into columns.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ColumnPlan {
    /// Column edge `y, x` in level-0 voxels (at least the plane's extent on an axis that is not
    /// cut); the last column of a row or band may be narrower.
    pub edge: [u64; 2],
    /// Levels made column by column (`0..local_levels`); the levels the pass writes beyond
    /// them are made from whole planes.
    pub local_levels: usize,
    /// Estimated peak memory of the pass in bytes.
    pub estimate: u64,
    /// How many neighbouring chunks of one chunk row a worker gathers at once (at least one;
    /// see [`gather_chunks`]), with the memory they take in `estimate`.
    pub gather: u64,
}

/// The most bytes of chunks a worker gathers at once.
pub const GATHER_BYTES: u64 = 8 << 20;

/// How many neighbouring chunks of one chunk row (`row_chunks` of them) a worker gathers at
/// once, chunks of `chunk_bytes` each: as many as [`GATHER_BYTES`] holds, and at least one.
/// Gathering a chunk row's chunks together reads each input row once, whole, instead of in
/// pieces as far apart as the row is long: on the 2-core development machine, gathering the
/// 64³ chunks of a 1024³ uint16 volume took half the time in groups of 16 (a whole chunk row)
/// as one by one.
pub fn gather_chunks(chunk_bytes: u64, row_chunks: u64) -> u64 {
    (GATHER_BYTES / chunk_bytes.max(1)).clamp(1, row_chunks.max(1))
}

impl ColumnPlan {
    /// Whether the pass reads whole planes (one column).
    pub fn is_whole(&self, [ny, nx]: [u64; 2]) -> bool {
        self.edge[0] >= ny && self.edge[1] >= nx
    }

    /// The columns of a plane of `ny × nx` voxels, band by band.
    pub fn columns(&self, [ny, nx]: [u64; 2]) -> Vec<PlaneRegion> {
        let [ey, ex] = self.edge;
        (0..ny.div_ceil(ey))
            .flat_map(|j| {
                (0..nx.div_ceil(ex)).map(move |i| {
                    let (y0, x0) = (j * ey, i * ex);
                    PlaneRegion {
                        y0,
                        x0,
                        ny: ey.min(ny - y0),
                        nx: ex.min(nx - x0),
                    }
                })
            })
            .collect()
    }
}

/// A level-0 region of a plane in the voxels of a level `factor` times coarser and `shape`
/// large: every voxel of that level that sums a voxel of the region.
pub(crate) fn at_level(region: PlaneRegion, factor: [u64; 3], shape: [u64; 3]) -> PlaneRegion {
    let [y1, x1] = region.end();
    let (y0, x0) = (region.y0 / factor[1], region.x0 / factor[2]);
    PlaneRegion {
        y0,
        x0,
        ny: y1.div_ceil(factor[1]).min(shape[1]) - y0,
        nx: x1.div_ceil(factor[2]).min(shape[2]) - x0,
    }
}

/// What a pass is: the store's plan, the levels it writes (`0..written`: all of them in one
/// process, those below the hand-over level in a partition) and its level-0 planes.
#[derive(Clone, Copy)]
pub(crate) struct Pass<'a> {
    /// The store's plan.
    pub plan: &'a PartitionPlan,
    /// Bytes of one wide exact sum (`T::Sum`), which a partition hands over.
    pub sum_bytes: u64,
    /// Bytes of one exact sum of a level (narrower for levels whose voxels cover few level-0
    /// voxels, see `convert::pyramid_sums`).
    pub level_sum_bytes: &'a dyn Fn(&LevelPlan) -> u64,
    /// Bytes of one voxel count (4 for sample types with NaN, 0 for the others, which count
    /// from the geometry).
    pub count_bytes: u64,
    /// Bytes the inputs' decoders hold while reading a column (see
    /// [`VolumeSource::decoder_bytes`](crate::source::VolumeSource::decoder_bytes)).
    pub decoders: &'a dyn Fn(PlaneRegion) -> u64,
    /// Levels the pass writes.
    pub written: usize,
    /// Level-0 planes of the pass.
    pub planes: u64,
    /// Worker threads, each gathering one chunk, or one group of neighbouring chunks, at a
    /// time.
    pub threads: u64,
}

/// Where a pass's memory goes, in bytes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MemoryEstimate {
    /// Level-0 slabs (the one processed and the one read ahead), decoded planes, and chunks
    /// being gathered.
    pub slabs: u64,
    /// The coarser levels' exact sums and rounded means, and a partition's hand-over sums.
    pub pyramid: u64,
    /// The rows of min/max cells and brick histograms not yet final.
    pub regions: u64,
}

impl MemoryEstimate {
    /// All of it, with [`FIXED_BYTES`].
    pub fn total(&self) -> u64 {
        self.slabs + self.pyramid + self.regions + FIXED_BYTES
    }
}

impl Pass<'_> {
    /// Bytes of one outer chunk (a shard, when sharded) of level 0.
    fn chunk_bytes(&self) -> u64 {
        self.plan.outer.iter().product::<u64>() * self.plan.format.bytes() as u64
    }

    /// The estimate for columns of `edge` level-0 voxels with `local` levels made in columns.
    pub fn estimate(&self, edge: [u64; 2], local: usize) -> MemoryEstimate {
        let plan = self.plan;
        let channels = plan.labels.len() as u64;
        let sample = plan.format.bytes() as u64;
        let [depth, ny, nx] = plan.shape;
        let column = PlaneRegion {
            y0: 0,
            x0: 0,
            ny: edge[0].min(ny),
            nx: edge[1].min(nx),
        };
        let split = column.ny < ny || column.nx < nx;
        let oz = plan.outer[0];
        let slab = channels * oz.min(depth) * column.area() * sample;
        let chunk = self.chunk_bytes();
        // Two slabs, the decoders' planes and strips, the cell scratch of a slab (a
        // sixteenth: what a whole slab's cells take; workers fold theirs band by band, which
        // takes less), a chunk per thread; and for shards, another per thread, which a thread
        // waiting inside a shard's encode may gather for a task it takes meanwhile (see
        // `SlabSink::process`).
        let in_flight = if plan.sharded { 2 } else { 1 };
        let slabs = 2 * slab
            + channels * column.area() * sample
            + (self.decoders)(column)
            + slab / 16
            + in_flight * self.threads * chunk;
        let mut pyramid = 0;
        let mut regions = 0;
        for (l, level) in plan.levels.iter().enumerate().take(self.written) {
            let [lz, ly, lx] = level.shape;
            let area = if l < local {
                at_level(column, level.factor, level.shape).area()
            } else {
                ly * lx
            };
            if l > 0 {
                let sum = (self.level_sum_bytes)(level);
                pyramid += channels * oz.min(lz) * area * (sum + self.count_bytes + sample);
            }
            let cells = level.shape.map(|s| s.div_ceil(CELL));
            let bricks: [u64; 3] = std::array::from_fn(|a| level.shape[a].div_ceil(plan.brick[a]));
            // A brick's fine histogram: at most one count per key, or per voxel.
            let histogram = 24 + 4 * (FINE_KEYS as u64).min(plan.brick.iter().product());
            // Haloed and exact minima and maxima of a cell.
            let cell = 4 * channels * sample;
            // The rows one slab of the level reaches (halos included), over the column's
            // cells (and a ring of halo cells) or the whole plane; rows are written (or, in a
            // column, put in a scratch file) as the slab is done.
            let (held_y, held_x, held_by, held_bx) = if l < local {
                let w = at_level(column, level.factor, level.shape);
                let b = plan.brick;
                (
                    w.ny.div_ceil(CELL) + 2,
                    w.nx.div_ceil(CELL) + 2,
                    w.ny.div_ceil(b[1]),
                    w.nx.div_ceil(b[2]),
                )
            } else {
                (cells[1], cells[2], bricks[1], bricks[2])
            };
            let slab = oz.min(lz);
            let rows = (slab.div_ceil(CELL) + 2).min(cells[0]);
            regions += rows * held_y.min(cells[1]) * held_x.min(cells[2]) * cell;
            // A chunk of rows of the whole plane waiting to be written (and, in columns, one
            // being assembled), with the coarser grids' (a seventh more).
            let waiting = if split && l < local { 2 } else { 1 };
            regions += waiting * CHUNK_ROWS.min(cells[0]) * cells[1] * cells[2] * cell * 8 / 7;
            let rows = (slab.div_ceil(plan.brick[0]) + 1).min(bricks[0]);
            regions +=
                channels * rows * held_by.min(bricks[1]) * held_bx.min(bricks[2]) * histogram;
        }
        if let Some(level) = plan.levels.get(self.written) {
            // A partition's hand-over level: wide sums over all its planes.
            let [_, ly, lx] = level.shape;
            pyramid += channels
                * self.planes.div_ceil(level.factor[0])
                * ly
                * lx
                * (self.sum_bytes + self.count_bytes);
        }
        MemoryEstimate {
            slabs,
            pyramid,
            regions,
        }
    }

    /// The columns of the fewest (and then the smallest estimate) that fit `limit` bytes:
    /// whole planes when they fit.
    ///
    /// # Errors
    /// When not even the smallest columns fit; the error holds their estimate.
    pub fn plan_columns(&self, limit: u64) -> Result<ColumnPlan, MemoryEstimate> {
        let plan = self.plan;
        let [_, ny, nx] = plan.shape;
        let whole = ColumnPlan {
            edge: [ny, nx],
            local_levels: self.written,
            estimate: self.estimate([ny, nx], self.written).total(),
            gather: 1,
        };
        if whole.estimate <= limit {
            return Ok(self.with_gather(whole, limit));
        }
        let mut best: Option<(u64, ColumnPlan)> = None;
        let mut smallest = self.estimate([ny, nx], self.written);
        for local in 1..=self.written {
            // Column edges fall on chunk edges of every local level, and of the first level
            // after them, which sums whole voxels of the last local level.
            let factor = plan
                .levels
                .get(local)
                .unwrap_or(&plan.levels[local - 1])
                .factor;
            let unit = [plan.outer[1] * factor[1], plan.outer[2] * factor[2]];
            let mut m = 1;
            while unit[0] * m < ny || unit[1] * m < nx {
                for edge in [[unit[0] * m, nx], [unit[0] * m, unit[1] * m]] {
                    let estimate = self.estimate(edge, local);
                    if estimate.total() < smallest.total() {
                        smallest = estimate;
                    }
                    let candidate = ColumnPlan {
                        edge,
                        local_levels: local,
                        estimate: estimate.total(),
                        gather: 1,
                    };
                    let count = candidate.columns([ny, nx]).len() as u64;
                    let better =
                        best.is_none_or(|(n, b)| (count, candidate.estimate) < (n, b.estimate));
                    if candidate.estimate <= limit && better {
                        best = Some((count, candidate));
                    }
                }
                m *= 2;
            }
        }
        best.map(|(_, plan)| self.with_gather(plan, limit))
            .ok_or(smallest)
    }

    /// `plan` (chosen with one chunk gathered at a time) with as many chunks gathered at once
    /// as [`gather_chunks`] allows and the room left under `limit` holds, for every thread;
    /// their memory is added to its estimate. The columns chosen do not change.
    fn with_gather(&self, mut plan: ColumnPlan, limit: u64) -> ColumnPlan {
        let chunk = self.chunk_bytes();
        let row = plan.edge[1]
            .min(self.plan.shape[2])
            .div_ceil(self.plan.outer[2]);
        let threads = self.threads.max(1);
        let room = limit.saturating_sub(plan.estimate) / (threads * chunk).max(1);
        plan.gather = gather_chunks(chunk, row).min(1 + room);
        plan.estimate += threads * (plan.gather - 1) * chunk;
        plan
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::partition::plan::Cuts;
    use crate::pyramid::plan_levels;
    use crate::sample_format::SampleType;
    use crate::store::OmeZarrVersion;

    fn plan(shape: [u64; 3]) -> PartitionPlan {
        let levels = plan_levels(shape, [1.0; 3], [64; 3], None);
        let cuts = Cuts::plan(&levels, 64, 1);
        PartitionPlan {
            format: SampleType::U16,
            shape,
            labels: vec!["a".into()],
            voxel_size: [1.0; 3],
            unit: None,
            brick: [64; 3],
            outer: [64; 3],
            sharded: false,
            version: OmeZarrVersion::V05,
            levels,
            cuts,
        }
    }

    fn pass(plan: &PartitionPlan) -> Pass<'_> {
        Pass {
            plan,
            sum_bytes: 8,
            level_sum_bytes: &|_| 8,
            count_bytes: 0,
            decoders: &|_| 0,
            written: plan.levels.len(),
            planes: plan.shape[0],
            threads: 2,
        }
    }

    #[test]
    fn the_decoders_and_counts_add_to_the_estimate() {
        let plan = plan([64, 1024, 1024]);
        let base = pass(&plan);
        let strips = |c: PlaneRegion| 1000 + c.nx;
        let with = Pass {
            decoders: &strips,
            count_bytes: 4,
            ..base
        };
        let (a, b) = (base.estimate([256, 256], 1), with.estimate([256, 256], 1));
        assert_eq!(b.slabs - a.slabs, 1256);
        // Levels 1 to 4 are made from whole planes: 32 × 512², 16 × 256², 8 × 128², 4 × 64²
        // counts of 4 bytes.
        assert_eq!(plan.levels.len(), 5);
        let counts = 4 * (32 * 512 * 512 + 16 * 256 * 256 + 8 * 128 * 128 + 4 * 64 * 64);
        assert_eq!(b.pyramid - a.pyramid, counts);
    }

    #[test]
    fn workers_gather_a_chunk_row_at_once_where_the_limit_leaves_room() {
        let plan = plan([64, 1024, 1024]);
        let pass = pass(&plan);
        // uint16 chunks of 64³: 512 KiB, 16 to a chunk row of the plane, all 16 in 8 MiB.
        let chunk = 64 * 64 * 64 * 2;
        assert_eq!(gather_chunks(chunk, 16), 16);
        assert_eq!(gather_chunks(chunk, 5), 5);
        assert_eq!(gather_chunks(GATHER_BYTES * 2, 16), 1);
        let alone = pass.estimate([1024, 1024], plan.levels.len()).total();
        let roomy = pass.plan_columns(u64::MAX).unwrap();
        assert_eq!((roomy.edge, roomy.gather), ([1024, 1024], 16));
        assert_eq!(roomy.estimate, alone + 2 * 15 * chunk);
        // Room for three more chunks a thread: four at once.
        let tight = pass.plan_columns(alone + 2 * 3 * chunk + 1).unwrap();
        assert_eq!((tight.edge, tight.gather), ([1024, 1024], 4));
        assert_eq!(tight.estimate, alone + 2 * 3 * chunk);
        // No room: one at a time, and the columns as before.
        let full = pass.plan_columns(alone).unwrap();
        assert_eq!((full.gather, full.estimate), (1, alone));
        let cut = pass.plan_columns(alone / 2).unwrap();
        assert!(!cut.is_whole([1024, 1024]));
        assert!(cut.estimate <= alone / 2);
        let row = cut.edge[1].min(1024) / 64;
        assert!((1..=row).contains(&cut.gather), "{cut:?}");
    }

    #[test]
    fn a_sharded_store_counts_a_second_shard_per_thread() {
        // Shards of 64³ (the plan's outer chunk): a thread waiting inside one shard's encode
        // may gather another.
        let plain = plan([64, 1024, 1024]);
        let sharded = PartitionPlan {
            sharded: true,
            ..plain.clone()
        };
        let shard = 64 * 64 * 64 * 2;
        let estimate = |p: &PartitionPlan| pass(p).estimate([1024, 1024], p.levels.len());
        let (a, b) = (estimate(&plain), estimate(&sharded));
        assert_eq!(b.slabs, a.slabs + 2 * shard);
        assert_eq!((b.pyramid, b.regions), (a.pyramid, a.regions));
    }

    #[test]
    fn narrow_sums_count_for_the_levels_that_keep_them() {
        let plan = plan([64, 1024, 1024]);
        let wide = pass(&plan);
        // Levels 1 (8 level-0 voxels a voxel) and 2 (64) sum narrow; 3 (512) and 4 do not.
        let narrow = Pass {
            level_sum_bytes: &|level: &LevelPlan| {
                if level.factor.iter().product::<u64>() <= 64 {
                    4
                } else {
                    8
                }
            },
            ..wide
        };
        let (a, b) = (wide.estimate([256, 256], 1), narrow.estimate([256, 256], 1));
        assert_eq!(a.pyramid - b.pyramid, 4 * (32 * 512 * 512 + 16 * 256 * 256));
        assert_eq!((a.slabs, a.regions), (b.slabs, b.regions));
    }

    #[test]
    fn columns_cover_the_plane_once_band_by_band() {
        let columns = ColumnPlan {
            edge: [128, 256],
            local_levels: 2,
            estimate: 0,
            gather: 1,
        };
        let c = columns.columns([300, 500]);
        assert_eq!(c.len(), 6);
        assert_eq!(
            c[..3],
            [
                PlaneRegion {
                    y0: 0,
                    x0: 0,
                    ny: 128,
                    nx: 256
                },
                PlaneRegion {
                    y0: 0,
                    x0: 256,
                    ny: 128,
                    nx: 244
                },
                PlaneRegion {
                    y0: 128,
                    x0: 0,
                    ny: 128,
                    nx: 256
                },
            ]
        );
        assert_eq!(
            c[5],
            PlaneRegion {
                y0: 256,
                x0: 256,
                ny: 44,
                nx: 244
            }
        );
        assert_eq!(c.iter().map(PlaneRegion::area).sum::<u64>(), 300 * 500);
        assert!(!columns.is_whole([300, 500]));
        assert!(columns.is_whole([128, 200]));
    }

    #[test]
    fn a_region_at_a_coarser_level_covers_every_voxel_it_sums_into() {
        let r = PlaneRegion {
            y0: 128,
            x0: 0,
            ny: 128,
            nx: 61,
        };
        assert_eq!(
            at_level(r, [1, 2, 2], [10, 200, 31]),
            PlaneRegion {
                y0: 64,
                x0: 0,
                ny: 64,
                nx: 31
            }
        );
        assert_eq!(
            at_level(r, [2, 4, 4], [5, 100, 16]),
            PlaneRegion {
                y0: 32,
                x0: 0,
                ny: 32,
                nx: 16
            }
        );
    }

    /// A stitched mosaic of 16384² planes, 64 deep, needs about 40 GiB in whole planes; in
    /// columns it fits 4 GiB.
    #[test]
    fn mosaic_planes_fit_a_few_gigabytes_in_columns() {
        let plan = plan([64, 16384, 16384]);
        let pass = pass(&plan);
        let whole = pass.estimate([16384, 16384], plan.levels.len());
        assert!(whole.total() > 40 << 30, "{whole:?}");
        for limit in [4u64 << 30, 8 << 30] {
            let chosen = pass.plan_columns(limit).unwrap();
            println!(
                "{limit}: {chosen:?} {:?}",
                pass.estimate(chosen.edge, chosen.local_levels)
            );
            assert!(chosen.estimate <= limit);
            assert!(!chosen.is_whole([16384, 16384]));
        }
    }

    #[test]
    fn whole_planes_when_they_fit_columns_when_they_do_not() {
        let plan = plan([64, 4096, 4096]);
        let pass = pass(&plan);
        let whole = pass.estimate([4096, 4096], plan.levels.len());
        // Two slabs of 64 planes of 4096² uint16 voxels, and their decoded planes.
        assert!(whole.slabs > 2 * 64 * 4096 * 4096 * 2);
        let chosen = pass.plan_columns(whole.total()).unwrap();
        assert_eq!(chosen.edge, [4096, 4096]);
        assert_eq!(chosen.local_levels, plan.levels.len());

        let limit = 2 << 30;
        let chosen = pass.plan_columns(limit).unwrap();
        assert!(chosen.estimate <= limit, "{chosen:?}");
        assert!(!chosen.is_whole([4096, 4096]));
        // Edges on chunk edges of every local level and of the level after them.
        let f = plan.levels[chosen.local_levels].factor;
        assert!(chosen.edge[0].is_multiple_of(64 * f[1]), "{chosen:?}");
        assert!(chosen.edge[1] == 4096 || chosen.edge[1].is_multiple_of(64 * f[2]));

        let too_small = pass.plan_columns(1 << 20).unwrap_err();
        assert!(too_small.total() > 1 << 20);
    }
}
