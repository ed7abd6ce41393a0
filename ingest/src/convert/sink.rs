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
        let [oz, oy, ox] = self.outer;
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
        let chunk_len = (oz * oy * ox) as usize;
        let grid = cells.start_slab(z0, nz, w);
        let cells = Mutex::new(cells);
        // A thread that waits for work it shared with rayon takes any waiting task, which
        // gathers into memory of its own. With a task for every thread, each encodes its own
        // chunks (a shard's inner chunks are not shared out), so no thread waits and no task
        // starts inside another. With fewer tasks (a chunk each), the threads left over encode
        // the inner chunks of a shard, and a thread waiting there may start one more task: a
        // shard per thread that the estimate counts for sharded stores (`Pass::estimate`).
        // Plain chunks are encoded on one thread whatever the target.
        let codec = CodecOptions::default()
            .with_concurrent_target((threads as usize).div_ceil(tasks.len().max(1)));
        // In the pool, so that the memory a task keeps is a worker's, which
        // [`release_scratch`] hands back (a lone task would otherwise run on this thread).
        let counts = rayon::scope(|_| {
            tasks
                .into_par_iter()
                .map(|(c, cy, cxs)| -> Result<(u64, u64), ChunkWriteError> {
                    // This thread's tables and chunk memory, taken while in use.
                    let mut kept = SCRATCH.take().unwrap_or_default();
                    let SinkScratch {
                        stats: scratch,
                        words,
                    } = &mut *kept;
                    let count = (cxs.end - cxs.start) as usize;
                    words.resize((count * chunk_len * size_of::<T>()).div_ceil(8), 0);
                    let gathered =
                        &mut bytemuck::cast_slice_mut::<u64, T>(words)[..count * chunk_len];
                    let y0 = cy * oy;
                    let vy = (ny - y0).min(oy);
                    // The voxels of each chunk inside the level along x.
                    let vx = |cx: u64| (nx - cx * ox).min(ox);
                    // Gather the outer chunks, each padded with the fill value (0) past the slab.
                    for (cx, chunk) in cxs.clone().zip(gathered.chunks_exact_mut(chunk_len)) {
                        if (nz, vy, vx(cx)) != (oz, oy, ox) {
                            chunk.fill(T::default());
                        }
                    }
                    // The part of the window these chunks hold, and its min/max cells plane by plane.
                    let x0 = cxs.start * ox;
                    let band = PlaneRegion {
                        y0,
                        x0,
                        ny: vy,
                        nx: (cxs.end * ox).min(nx) - x0,
                    };
                    let first = ((y0 - w.y0) * w.nx + (x0 - w.x0)) as usize;
                    let mut band_cells: Vec<SliceCells<T>> = Vec::with_capacity(nz as usize);
                    for dz in 0..nz {
                        let plane = planes[(c as u64 * nz + dz) as usize];
                        for dy in 0..vy {
                            let row = ((y0 - w.y0 + dy) * w.nx) as usize;
                            let dst = ((dz * oy + dy) * ox) as usize;
                            for (cx, chunk) in cxs.clone().zip(gathered.chunks_exact_mut(chunk_len))
                            {
                                let (src, n) = (row + (cx * ox - w.x0) as usize, vx(cx) as usize);
                                chunk[dst..dst + n].copy_from_slice(&plane[src..src + n]);
                            }
                        }
                        band_cells.push(slice_cells(&plane[first..], w.nx as usize, band, grid));
                    }
                    {
                        let mut cells = cells.lock().expect("cells");
                        for (dz, found) in band_cells.iter().enumerate() {
                            cells.fold_slice(c, z0 + dz as u64, found);
                        }
                    }
                    if let Some(work) = bands {
                        work.band(c, (cy - rows.start) as usize, planes);
                    }
                    let counts = cxs.zip(gathered.chunks_exact(chunk_len)).try_fold(
                        (0, 0),
                        |(written, empty), (cx, chunk)| {
                            let (w, e) = self.process_chunk(
                                chunk,
                                scratch,
                                &codec,
                                [c as u64, z0, cy, cx],
                                [nz, vy, vx(cx)],
                            )?;
                            Ok((written + w, empty + e))
                        },
                    );
                    SCRATCH.set(Some(kept));
                    counts
                })
                .collect::<Result<Vec<_>, _>>()
        })?;
        let (written, empty) = counts
            .into_iter()
            .fold((0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
        Ok((written, empty, bands.is_some()))
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
