//! Writing a slab of a level and recording its region metadata ([`SlabSink`]): common to
//! `convert` and `index`.

use std::sync::Mutex;

use rayon::prelude::*;
use zarrs::array::{Array, ArrayError, CodecOptions};

use super::pyramid_sums::BandWork;
use crate::regions::{
    BrickStats, CellGrid, ChannelAccumulator, LevelHistograms, SliceCells, StatsScratch,
    slice_cells,
};
use crate::sample_format::Sample;
use crate::source::PlaneRegion;
use crate::store::Store;

/// A chunk of an image array that cannot be written.
#[derive(Debug, thiserror::Error)]
#[error("cannot write chunk {}/{}/{}/{}", chunk[0], chunk[1], chunk[2], chunk[3])]
pub struct ChunkWriteError {
    /// Chunk indices `c, z, y, x`.
    pub chunk: [u64; 4],
    /// What zarrs said.
    #[source]
    pub source: Box<ArrayError>,
}

/// A worker thread's brick statistics tables and outer-chunk memory (as words, so that any
/// sample type's values fit aligned), kept from slab to slab: fresh memory per chunk is
/// zeroed by the kernel on every use.
#[derive(Default)]
struct SinkScratch {
    stats: StatsScratch,
    words: Vec<u64>,
}

thread_local! {
    /// This thread's [`SinkScratch`], absent while a task uses it.
    static SCRATCH: std::cell::Cell<Option<Box<SinkScratch>>> = const { std::cell::Cell::new(None) };
}

/// Hands back the memory every worker thread (and this thread) keeps for gathering chunks (up
/// to [`GATHER_BYTES`](crate::columns::GATHER_BYTES) each), so that a process that goes on
/// after a conversion (the Python module's) does not hold it.
pub(crate) fn release_scratch() {
    rayon::broadcast(|_| drop(SCRATCH.take()));
    drop(SCRATCH.take());
}

/// Reusable per-level context for the slab processing that is common to `convert` and
/// `index`: histograms, cells, global statistics and (optionally) the image write.
pub(crate) struct SlabSink<'a> {
    pub channels: usize,
    /// The part of each plane a slab holds (chunk-aligned; the whole plane, or a column).
    pub window: PlaneRegion,
    pub brick: [u64; 3],
    pub outer: [u64; 3],
    pub array: Option<&'a Array<Store>>,
    pub histograms: &'a LevelHistograms,
    pub stats: Option<&'a [Mutex<ChannelAccumulator>]>,
    /// Neighbouring chunks of one chunk row a worker gathers at once (at most; fewer when
    /// that would leave threads without work).
    pub gather: u64,
}

/// One slab as [`SlabSink::process`]'s tasks share it.
struct Slab<'s, 'c, T: Sample> {
    /// `planes[c · nz + z]`, each `[y][x]` over the window.
    planes: &'s [&'s [T]],
    /// First plane and planes.
    z0: u64,
    nz: u64,
    /// The level's cells per plane row and column (see [`CellGrid::start_slab`]).
    grid: [u64; 2],
    cells: Mutex<&'c mut CellGrid<T>>,
    bands: Option<&'s dyn BandWork<T>>,
    /// The window's first chunk row (band 0).
    first_row: u64,
    /// How chunks are encoded.
    codec: CodecOptions,
}

/// The `count` planes of a slab held in one buffer `[c][nz][y][x]`, `plane` voxels each (an
/// empty window's planes are empty), as the slab's consumers take them (see
/// [`SlabSink::process`]).
pub(crate) fn planes_of<T>(slab: &[T], count: usize, plane: usize) -> Vec<&[T]> {
    (0..count)
        .map(|i| &slab[i * plane..(i + 1) * plane])
        .collect()
}

impl SlabSink<'_> {
    /// Writes (when an array is given) the chunks of a slab of the window starting at `z0`,
    /// given plane by plane (`planes[c · nz + z]`, each `[y][x]`), records brick histograms
    /// and statistics, and folds the slab into the min/max `cells`; and does `bands`' work
    /// on each band of the slab (a chunk row of a channel) when a worker gathers whole chunk
    /// rows. Returns (bricks written, bricks empty, whether `bands`' work was done).
    ///
    /// The slab is read once: a task gathers the chunks of (part of) a chunk row plane by
    /// plane, finds the min/max cells of that plane's rows while they are in its cache, and
    /// then does the band's work.
    pub fn process<T: Sample>(
        &self,
        planes: &[&[T]],
        z0: u64,
        nz: u64,
        cells: &mut CellGrid<T>,
        bands: Option<&dyn BandWork<T>>,
    ) -> Result<(u64, u64, bool), ChunkWriteError> {
        let w = self.window;
        let [ny, nx] = w.end();
        let [_, oy, ox] = self.outer;
        let (rows, columns) = (w.y0 / oy..ny.div_ceil(oy), w.x0 / ox..nx.div_ceil(ox));
        // Groups of neighbouring chunks of a chunk row, few enough that every thread has two.
        let chunks = self.channels as u64 * (rows.end - rows.start) * (columns.end - columns.start);
        let threads = rayon::current_num_threads() as u64;
        let group = self.gather.min(chunks.div_ceil(2 * threads)).max(1);
        let bands = bands.filter(|b| group >= columns.end - columns.start && b.band_rows() == oy);
        let tasks: Vec<(usize, u64, std::ops::Range<u64>)> = (0..self.channels)
            .flat_map(|c| {
                let columns = columns.clone();
                rows.clone().flat_map(move |cy| {
                    columns
                        .clone()
                        .step_by(group as usize)
                        .map(move |cx| (c, cy, cx..(cx + group).min(columns.end)))
                })
            })
            .collect();
        let grid = cells.start_slab(z0, nz, w);
        // A thread that waits for work it shared with rayon takes any waiting task, which
        // gathers into memory of its own. With a task for every thread, each encodes its own
        // chunks (a shard's inner chunks are not shared out), so no thread waits and no task
        // starts inside another. With fewer tasks (a chunk each), the threads left over encode
        // the inner chunks of a shard, and a thread waiting there may start one more task: a
        // shard per thread that the estimate counts for sharded stores (`Pass::estimate`).
        // Plain chunks are encoded on one thread whatever the target.
        let codec = CodecOptions::default()
            .with_concurrent_target((threads as usize).div_ceil(tasks.len().max(1)));
        let slab = Slab {
            planes,
            z0,
            nz,
            grid,
            cells: Mutex::new(cells),
            bands,
            first_row: rows.start,
            codec,
        };
        // In the pool, so that the memory a task keeps is a worker's, which
        // [`release_scratch`] hands back (a lone task would otherwise run on this thread).
        let counts = rayon::scope(|_| {
            tasks
                .into_par_iter()
                .map(|(c, cy, cxs)| self.process_group(&slab, c, cy, cxs))
                .collect::<Result<Vec<_>, _>>()
        })?;
        let (written, empty) = counts
            .into_iter()
            .fold((0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
        Ok((written, empty, bands.is_some()))
    }

    /// The rows of chunk row `cy` inside the window.
    fn rows_inside(&self, cy: u64) -> u64 {
        let oy = self.outer[1];
        (self.window.end()[0] - cy * oy).min(oy)
    }

    /// The columns of chunk column `cx` inside the window.
    fn columns_inside(&self, cx: u64) -> u64 {
        let ox = self.outer[2];
        (self.window.end()[1] - cx * ox).min(ox)
    }

    /// One task of [`process`](Self::process): gathers the chunks `cxs` of chunk row `cy` of
    /// channel `c` (in this thread's memory), folds their min/max cells and does the band's
    /// work, then records and writes each chunk. Returns (bricks written, bricks empty).
    fn process_group<T: Sample>(
        &self,
        slab: &Slab<'_, '_, T>,
        c: usize,
        cy: u64,
        cxs: std::ops::Range<u64>,
    ) -> Result<(u64, u64), ChunkWriteError> {
        let [oz, oy, ox] = self.outer;
        let chunk_len = (oz * oy * ox) as usize;
        let (nz, vy, vx) = (slab.nz, self.rows_inside(cy), |cx| self.columns_inside(cx));
        // This thread's tables and chunk memory, taken while in use.
        let mut kept = SCRATCH.take().unwrap_or_default();
        let SinkScratch {
            stats: scratch,
            words,
        } = &mut *kept;
        let count = (cxs.end - cxs.start) as usize;
        words.resize((count * chunk_len * size_of::<T>()).div_ceil(8), 0);
        let gathered = &mut bytemuck::cast_slice_mut::<u64, T>(words)[..count * chunk_len];
        // Each chunk padded with the fill value (0) past the slab.
        for (cx, chunk) in cxs.clone().zip(gathered.chunks_exact_mut(chunk_len)) {
            if (nz, vy, vx(cx)) != (oz, oy, ox) {
                chunk.fill(T::default());
            }
        }
        let found = self.gather(slab, c, cy, cxs.clone(), gathered);
        {
            let mut cells = slab.cells.lock().expect("cells");
            for (dz, cells_of_plane) in found.iter().enumerate() {
                cells.fold_slice(c, slab.z0 + dz as u64, cells_of_plane);
            }
        }
        if let Some(work) = slab.bands {
            work.band(c, (cy - slab.first_row) as usize, slab.planes);
        }
        let counts = cxs.zip(gathered.chunks_exact(chunk_len)).try_fold(
            (0, 0),
            |(written, empty), (cx, chunk)| {
                let (w, e) = self.process_chunk(
                    chunk,
                    scratch,
                    &slab.codec,
                    [c as u64, slab.z0, cy, cx],
                    [nz, vy, vx(cx)],
                )?;
                Ok((written + w, empty + e))
            },
        );
        SCRATCH.set(Some(kept));
        counts
    }

    /// Copies the rows of chunks `cxs` of chunk row `cy` of channel `c` out of the slab's
    /// planes into `gathered` (a chunk after another), plane by plane, and finds each plane's
    /// min/max cells over those rows while they are in the cache.
    fn gather<T: Sample>(
        &self,
        slab: &Slab<'_, '_, T>,
        c: usize,
        cy: u64,
        cxs: std::ops::Range<u64>,
        gathered: &mut [T],
    ) -> Vec<SliceCells<T>> {
        let w = self.window;
        let [oz, oy, ox] = self.outer;
        let chunk_len = (oz * oy * ox) as usize;
        let (y0, x0, vy) = (cy * oy, cxs.start * ox, self.rows_inside(cy));
        // The part of the window these chunks hold.
        let band = PlaneRegion {
            y0,
            x0,
            ny: vy,
            nx: (cxs.end * ox).min(w.end()[1]) - x0,
        };
        let first = ((y0 - w.y0) * w.nx + (x0 - w.x0)) as usize;
        (0..slab.nz)
            .map(|dz| {
                let plane = slab.planes[(c as u64 * slab.nz + dz) as usize];
                for dy in 0..vy {
                    let row = ((y0 - w.y0 + dy) * w.nx) as usize;
                    let dst = ((dz * oy + dy) * ox) as usize;
                    for (cx, chunk) in cxs.clone().zip(gathered.chunks_exact_mut(chunk_len)) {
                        let src = row + (cx * ox - w.x0) as usize;
                        let n = self.columns_inside(cx) as usize;
                        chunk[dst..dst + n].copy_from_slice(&plane[src..src + n]);
                    }
                }
                slice_cells(&plane[first..], w.nx as usize, band, slab.grid)
            })
            .collect()
    }

    /// Records the bricks of one gathered outer chunk (channel `c`, first plane `z0`, chunk
    /// column `cy, cx`; `nz, vy, vx` voxels of it inside the level) and writes the chunk
    /// (encoded with `codec`) unless every brick is empty. Returns (bricks written, bricks empty).
    fn process_chunk<T: Sample>(
        &self,
        chunk: &[T],
        scratch: &mut StatsScratch,
        codec: &CodecOptions,
        [c, z0, cy, cx]: [u64; 4],
        [nz, vy, vx]: [u64; 3],
    ) -> Result<(u64, u64), ChunkWriteError> {
        let [oz, oy, ox] = self.outer;
        let (y0, x0) = (cy * oy, cx * ox);
        let c = c as usize;
        let (mut written, mut empty) = (0u64, 0u64);
        let [bz, by, bx] = self.brick;
        let mut any_data = false;
        for iz in 0..nz.div_ceil(bz) {
            for iy in 0..vy.div_ceil(by) {
                for ix in 0..vx.div_ceil(bx) {
                    let (zs, ys, xs) = (iz * bz, iy * by, ix * bx);
                    let (ze, ye, xe) = ((zs + bz).min(nz), (ys + by).min(vy), (xs + bx).min(vx));
                    let rows = (zs..ze).flat_map(|z| {
                        (ys..ye).map(move |y| {
                            let row = ((z * oy + y) * ox) as usize;
                            &chunk[row + xs as usize..row + xe as usize]
                        })
                    });
                    let stats = BrickStats::of_rows(rows, scratch, self.stats.is_some());
                    if stats.all_fill {
                        empty += 1;
                    } else {
                        written += 1;
                        any_data = true;
                    }
                    let b = [(z0 + zs) / bz, (y0 + ys) / by, (x0 + xs) / bx];
                    if let Some(all) = self.stats {
                        all[c].lock().expect("stats").add(&stats);
                    }
                    let index = self.histograms.index(c, b);
                    self.histograms.fine.lock().expect("histograms")[index] = stats.fine;
                }
            }
        }
        if let Some(array) = self.array
            && any_data
        {
            let indices = [c as u64, z0 / oz, cy, cx];
            array
                .store_chunk_opt(&indices, chunk, codec)
                .map_err(|source| ChunkWriteError {
                    chunk: indices,
                    source: Box::new(source),
                })?;
        }
        Ok((written, empty))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The chunk memory each worker of `pool` keeps, in words.
    fn kept(pool: &rayon::ThreadPool) -> Vec<usize> {
        pool.broadcast(|_| {
            let scratch = SCRATCH.take();
            let words = scratch.as_ref().map_or(0, |s| s.words.capacity());
            SCRATCH.set(scratch);
            words
        })
    }

    #[test]
    fn released_scratch_leaves_no_worker_holding_chunk_memory() {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(3)
            .build()
            .expect("a pool");
        pool.broadcast(|_| {
            SCRATCH.set(Some(Box::new(SinkScratch {
                stats: StatsScratch::default(),
                words: Vec::with_capacity(1 << 20),
            })));
        });
        assert_eq!(kept(&pool), [1 << 20; 3]);
        pool.install(release_scratch);
        assert_eq!(kept(&pool), [0; 3]);
    }
}
