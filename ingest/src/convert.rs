//! `ingest convert`: one streaming pass from the inputs to a finished OME-Zarr pyramid with
//! region metadata.
//!
//! Level 0 is read in slabs one chunk (or shard) deep. Each slab is written, folded into the
//! min/max cells and brick histograms, and summed into the next level's accumulator, which
//! holds exact sums and counts of level-0 voxels. When an accumulator has a full slab, its
//! means are rounded once and the same happens one level up. Memory is a few slabs per level
//! and never depends on the depth of the stack.

use std::fmt::Write;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::mpsc::sync_channel;
use std::time::Instant;

use rayon::prelude::*;
use residency_schemas::dataset::dataset_name;
use zarrs::array::{Array, ArrayError};

use crate::columns::{ColumnPlan, MemoryEstimate, Pass, at_level};
use crate::ome::{image_attributes, multiscale, omero};
use crate::partition::{
    Cuts, HANDOFF_FOLDER, Handoff, HandoffError, Handoffs, LevelPart, LevelSums, Partition,
    PartitionPlan, RECORDS_FOLDER, claim_plan, records_stem, write_handoff,
};
use crate::pyramid::{LevelPlan, plan_levels};
use crate::region_writer::{
    LevelRegionWriter, RegionWriteError, channel_summaries, region_document,
};
use crate::regions::{
    BrickStats, CELL, CellGrid, ChannelAccumulator, HALO, LevelHistograms, StatsScratch,
    cells_reached,
};
use crate::sample_format::{Sample, SampleType};
use crate::source::{PlaneRegion, RawOptions, SourceError, SourceInfo, VolumeSource, open_input};
use crate::store::{ArrayLayout, OmeZarrVersion, Store, StoreError, StoreWriter, directory_bytes};
use crate::with_sample_type;

/// Why a conversion failed: options that do not fit the inputs, inputs that cannot be read or
/// do not go together, or a store that cannot be written. Messages name the option, input or
/// output at fault; errors of the inputs and the store are theirs, unchanged.
#[derive(Debug, thiserror::Error)]
pub enum ConvertError {
    /// No input.
    #[error("no input given")]
    NoInput,
    /// An input cannot be opened or read.
    #[error(transparent)]
    Source(#[from] SourceError),
    /// Two inputs of different shapes.
    #[error(
        "channels of different shapes: {} is {first_shape:?} (z,y,x) but {} is {shape:?}",
        first.display(), path.display()
    )]
    ShapeMismatch {
        /// The first input.
        first: PathBuf,
        /// Its shape `z, y, x`.
        first_shape: [u64; 3],
        /// The input that differs.
        path: PathBuf,
        /// Its shape `z, y, x`.
        shape: [u64; 3],
    },
    /// An input whose samples no sample type holds exactly together with the others'.
    #[error(
        "{}: {format} samples cannot be stored exactly beside {others} samples of {}",
        path.display(), first.display()
    )]
    IncompatibleSamples {
        /// The input.
        path: PathBuf,
        /// Its sample type.
        format: SampleType,
        /// The sample type of the inputs before it.
        others: SampleType,
        /// The first input.
        first: PathBuf,
    },
    /// A volume without voxels.
    #[error("{}: volume is empty ({shape:?})", path.display())]
    EmptyVolume {
        /// The first input.
        path: PathBuf,
        /// Its shape `z, y, x`.
        shape: [u64; 3],
    },
    /// A `--chunk` edge of 0.
    #[error("--chunk must be positive")]
    ChunkNotPositive,
    /// A `--shard` that is not a whole number of chunks.
    #[error("--shard {shard:?} must be a positive multiple of --chunk {chunk:?}")]
    ShardNotMultiple {
        /// `--shard`, `z, y, x`.
        shard: [u64; 3],
        /// `--chunk`, `z, y, x`.
        chunk: [u64; 3],
    },
    /// `--shard` with OME-Zarr 0.4.
    #[error("--shard needs Zarr v3: use --ome-zarr-version 0.5")]
    ShardNeedsV3,
    /// A brick larger than Blosc compresses.
    #[error(
        "--chunk {requested:?}: a brick of {brick:?} {format} voxels is {bytes} bytes, more than the 2 GiB a Blosc chunk can hold"
    )]
    BrickTooLarge {
        /// `--chunk`, `z, y, x`.
        requested: [u64; 3],
        /// The brick, clamped to the volume.
        brick: [u64; 3],
        /// The sample type.
        format: SampleType,
        /// Bytes of one brick.
        bytes: u64,
    },
    /// A voxel size that is zero, negative or not finite.
    #[error("voxel size {voxel_size:?} must be positive and finite")]
    BadVoxelSize {
        /// The voxel size `z, y, x`.
        voxel_size: [f64; 3],
    },
    /// A conversion that does not fit `--memory-limit` however its planes are cut.
    #[error(
        "{output}: converting needs about {needed} bytes of memory even in the smallest columns ({} for level-0 slabs of {channels} channel(s) × {depth} planes, {} for the coarser levels' sums, {} for the region metadata), more than --memory-limit {limit} bytes; allow more memory, or a smaller z edge of --chunk (and --shard) needs less",
        estimate.slabs, estimate.pyramid, estimate.regions
    )]
    MemoryLimit {
        /// The output, as given.
        output: String,
        /// The estimate of the smallest columns.
        estimate: MemoryEstimate,
        /// Its total.
        needed: u64,
        /// Channels.
        channels: usize,
        /// Planes per slab.
        depth: u64,
        /// The limit in bytes.
        limit: u64,
    },
    /// The output store cannot be created or written.
    #[error(transparent)]
    Store(#[from] StoreError),
    /// The region metadata cannot be written.
    #[error(transparent)]
    Regions(#[from] RegionWriteError),
    /// A chunk of level 0 cannot be written.
    #[error("{}: writing level 0", path.display())]
    WriteLevel0 {
        /// The output.
        path: PathBuf,
        /// The chunk and why.
        #[source]
        source: ChunkWriteError,
    },
    /// The thread reading the inputs panicked.
    #[error("reader thread panicked")]
    ReaderPanicked,
    /// A value that cannot be serialised as JSON.
    #[error(transparent)]
    Json(#[from] serde_json::Error),
    /// A partition's hand-over file cannot be written, or `finalize` cannot use them.
    #[error(transparent)]
    Handoff(#[from] HandoffError),
}

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

/// Everything `ingest convert` needs to know.
#[derive(Clone, Debug)]
pub struct ConvertOptions {
    /// Input files, folders or globs; their channels are concatenated in order.
    pub inputs: Vec<String>,
    /// Output store path.
    pub output: PathBuf,
    /// Layout of raw inputs.
    pub raw: RawOptions,
    /// Voxel size `z, y, x` overriding the inputs' metadata.
    pub voxel_size: Option<[f64; 3]>,
    /// Physical unit overriding the inputs' metadata.
    pub unit: Option<String>,
    /// Brick (chunk, or inner chunk when sharded) shape `z, y, x`.
    pub brick: [u64; 3],
    /// Shard shape `z, y, x` (Zarr v3 sharding), a multiple of the brick.
    pub shard: Option<[u64; 3]>,
    /// OME-Zarr version.
    pub version: OmeZarrVersion,
    /// Number of levels (default: until a level fits in one brick).
    pub levels: Option<usize>,
    /// Replace an existing output.
    pub overwrite: bool,
    /// Show a progress bar on stderr.
    pub progress: bool,
    /// Channel labels overriding the inputs' metadata.
    pub channel_names: Vec<String>,
    /// Peak memory to stay within, in bytes (default: [`default_memory_limit`]).
    pub memory_limit: Option<u64>,
}

/// The memory a conversion keeps within unless told otherwise: half of this machine's
/// physical memory (no limit where the system does not say).
pub fn default_memory_limit() -> u64 {
    crate::memory::physical_memory().map_or(u64::MAX, |m| m / 2)
}

impl ConvertOptions {
    /// Options with defaults for everything but inputs and output.
    pub fn new(inputs: Vec<String>, output: PathBuf) -> Self {
        Self {
            inputs,
            output,
            raw: RawOptions::default(),
            voxel_size: None,
            unit: None,
            brick: [64; 3],
            shard: None,
            version: OmeZarrVersion::V05,
            levels: None,
            overwrite: false,
            progress: false,
            channel_names: Vec::new(),
            memory_limit: None,
        }
    }
}

/// What one level of a finished conversion holds.
#[derive(Clone, Debug, PartialEq)]
pub struct LevelSummary {
    /// Shape `c, z, y, x`.
    pub shape: [u64; 4],
    /// Bricks written (all channels).
    pub bricks_written: u64,
    /// Bricks equal to the fill value everywhere, not written.
    pub bricks_empty: u64,
}

/// The end-of-run report of a conversion.
#[derive(Clone, Debug, PartialEq)]
pub struct ConvertSummary {
    /// Path of the finished store.
    pub output: PathBuf,
    /// Sample format of the store.
    pub format: SampleType,
    /// Per-level results, finest first.
    pub levels: Vec<LevelSummary>,
    /// Bytes of level-0 voxels (uncompressed).
    pub input_bytes: u64,
    /// Bytes of the whole store on disk.
    pub stored_bytes: u64,
    /// Bytes of the level-0 image array on disk.
    pub level0_stored_bytes: u64,
    /// Bytes of the region metadata (arrays and attributes) on disk.
    pub metadata_bytes: u64,
    /// Wall time in seconds.
    pub seconds: f64,
    /// The columns the planes were cut into, when they were (see [`crate::columns`]).
    pub columns: Option<ColumnPlan>,
}

/// The report line of a pass made in columns, or nothing for whole planes.
fn columns_report(columns: Option<&ColumnPlan>, plane: [u64; 2]) -> String {
    columns.map_or_else(String::new, |c| {
        format!(
            "  in {} columns of {}×{} voxels (levels 0 to {} column by column) to stay within the memory limit (estimated peak {:.1} MiB)\n",
            c.columns(plane).len(),
            c.edge[0].min(plane[0]),
            c.edge[1].min(plane[1]),
            c.local_levels - 1,
            c.estimate as f64 / f64::from(1 << 20)
        )
    })
}

impl ConvertSummary {
    /// Human-readable report printed by the command line.
    pub fn report(&self) -> String {
        let mut s = format!("wrote {} ({})\n", self.output.display(), self.format);
        for (i, l) in self.levels.iter().enumerate() {
            let _ = writeln!(
                s,
                "  level {i}: shape c,z,y,x = {:?}, bricks written {}, empty (not written) {}",
                l.shape, l.bricks_written, l.bricks_empty
            );
        }
        let mb = self.input_bytes as f64 / 1e6;
        let _ = writeln!(
            s,
            "  input {:.1} MB, stored {:.1} MB, level-0 compression ratio {:.2}, region metadata {:.3} MB ({:.2}% of the store)",
            mb,
            self.stored_bytes as f64 / 1e6,
            self.input_bytes as f64 / self.level0_stored_bytes.max(1) as f64,
            self.metadata_bytes as f64 / 1e6,
            100.0 * self.metadata_bytes as f64 / self.stored_bytes.max(1) as f64
        );
        let _ = writeln!(
            s,
            "  {:.2} s, {:.1} MB/s",
            self.seconds,
            mb / self.seconds.max(1e-9)
        );
        let plane = [self.levels[0].shape[2], self.levels[0].shape[3]];
        s + &columns_report(self.columns.as_ref(), plane)
    }
}

/// The inputs, opened and checked against each other.
struct Inputs {
    sources: Vec<Box<dyn VolumeSource>>,
    shape: [u64; 3],
    format: SampleType,
    voxel_size: Option<[f64; 3]>,
    unit: Option<String>,
    labels: Vec<String>,
}

fn open_inputs(options: &ConvertOptions) -> Result<Inputs, ConvertError> {
    if options.inputs.is_empty() {
        return Err(ConvertError::NoInput);
    }
    let sources: Vec<Box<dyn VolumeSource>> = options
        .inputs
        .iter()
        .map(|i| open_input(i, &options.raw))
        .collect::<Result<_, _>>()?;
    let first: &SourceInfo = sources[0].info();
    let mut format = first.format;
    for s in &sources[1..] {
        let info = s.info();
        if info.shape != first.shape {
            return Err(ConvertError::ShapeMismatch {
                first: first.path.clone(),
                first_shape: first.shape,
                path: info.path.clone(),
                shape: info.shape,
            });
        }
        format = SampleType::promote(format, info.format).ok_or_else(|| {
            ConvertError::IncompatibleSamples {
                path: info.path.clone(),
                format: info.format,
                others: format,
                first: first.path.clone(),
            }
        })?;
    }
    if first.shape.contains(&0) {
        return Err(ConvertError::EmptyVolume {
            path: first.path.clone(),
            shape: first.shape,
        });
    }
    let channels: usize = sources.iter().map(|s| s.info().channels).sum();
    let mut labels: Vec<String> = Vec::new();
    for s in &sources {
        let info = s.info();
        let stem = info
            .path
            .file_name()
            .map(|n| {
                n.to_string_lossy()
                    .split('.')
                    .next()
                    .unwrap_or("")
                    .to_string()
            })
            .unwrap_or_default();
        for c in 0..info.channels {
            labels.push(info.channel_names.get(c).cloned().unwrap_or_else(|| {
                if info.channels == 1 {
                    stem.clone()
                } else {
                    format!("{stem} {c}")
                }
            }));
        }
    }
    for (i, l) in options.channel_names.iter().enumerate().take(channels) {
        labels[i].clone_from(l);
    }
    let voxel_size = options
        .voxel_size
        .or_else(|| sources.iter().find_map(|s| s.info().voxel_size));
    let unit = options
        .unit
        .clone()
        .or_else(|| sources.iter().find_map(|s| s.info().unit.clone()));
    Ok(Inputs {
        shape: first.shape,
        format,
        voxel_size,
        unit,
        labels,
        sources,
    })
}

/// Converts the inputs to an OME-Zarr store, as `ingest convert` does.
///
/// # Errors
/// When the options do not fit the inputs (chunk, shard, voxel size, memory), an input cannot
/// be opened or read or does not go with the others, or the store cannot be written. A failed
/// run leaves no output behind.
pub fn convert(options: &ConvertOptions) -> Result<ConvertSummary, ConvertError> {
    let inputs = open_inputs(options)?;
    let result = with_sample_type!(inputs.format, T => convert_typed::<T>(options, inputs));
    if result.is_err() {
        // A failed run leaves nothing behind (a killed one leaves only the hidden partial
        // folder, which has no root metadata and which the next run removes).
        let partial = crate::store::partial_path(&options.output);
        if partial.exists() {
            let _ = std::fs::remove_dir_all(&partial);
        }
    }
    result
}

/// A level's accumulator: exact sums of level-0 voxels and their non-NaN counts,
/// `[c][depth][y][x]`, for the level's planes `z0..z0 + depth` over `window` of each.
struct Accumulator<T: Sample> {
    /// First plane held.
    z0: u64,
    /// Planes per channel.
    depth: u64,
    /// The part of each plane held (the whole plane, or a column).
    window: PlaneRegion,
    /// Exact sums.
    sum: Vec<T::Sum>,
    /// Non-NaN level-0 voxel counts matching `sum`.
    count: Vec<u32>,
}

impl<T: Sample> Accumulator<T> {
    /// An accumulator that holds nothing (level 0's, or one taken out for a while).
    fn empty() -> Self {
        Self::new(0, 0, 0, PlaneRegion::whole([0, 0]))
    }

    /// Zeroed sums for `depth` planes from `z0` of `channels` channels over `window`.
    fn new(channels: usize, z0: u64, depth: u64, window: PlaneRegion) -> Self {
        let len = channels * (depth * window.area()) as usize;
        Self {
            z0,
            depth,
            window,
            sum: vec![T::Sum::default(); len],
            count: vec![0; len],
        }
    }
}

/// Per-level state during the pass.
struct Level<T: Sample> {
    plan: LevelPlan,
    array: Array<Store>,
    /// Zarr chunk (shard) shape `z, y, x`.
    outer: [u64; 3],
    /// The slab being filled (levels ≥ 1; empty for level 0): `min(outer z, level depth)`
    /// planes.
    acc: Accumulator<T>,
    /// Brick shape `z, y, x`.
    brick: [u64; 3],
    /// The part of the level's planes this pass makes now: the whole plane, or a column.
    window: PlaneRegion,
    /// The rounded means of the slab being flushed (reused between flushes).
    values: Vec<T>,
    /// The rows of min/max cells not yet final (all a partition's rows: it writes none).
    cells: CellGrid<T>,
    /// The rows of brick histograms not yet final (all a partition's rows).
    histograms: LevelHistograms,
    /// Where final rows go (none in a partition, which hands its rows to `finalize`).
    regions: Option<LevelRegionWriter<T>>,
    /// The output, for messages.
    output: PathBuf,
    written: u64,
    empty: u64,
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
}

impl SlabSink<'_> {
    /// Writes (when an array is given) the chunks of a slab `[c][nz][y][x]` of the window
    /// starting at `z0`,
    /// records brick histograms and statistics, and folds the slab into the min/max `cells`.
    /// Returns (bricks written, bricks empty).
    pub fn process<T: Sample>(
        &self,
        slab: &[T],
        z0: u64,
        nz: u64,
        cells: &mut CellGrid<T>,
    ) -> Result<(u64, u64), ChunkWriteError> {
        let w = self.window;
        let [ny, nx] = w.end();
        let [oz, oy, ox] = self.outer;
        let tasks: Vec<(usize, u64, u64)> = (0..self.channels)
            .flat_map(|c| {
                (w.y0 / oy..ny.div_ceil(oy))
                    .flat_map(move |cy| (w.x0 / ox..nx.div_ceil(ox)).map(move |cx| (c, cy, cx)))
            })
            .collect();
        let chunk_len = (oz * oy * ox) as usize;
        let counts = tasks
            .into_par_iter()
            .map_init(
                || (StatsScratch::default(), Vec::<T>::new()),
                |(scratch, chunk), (c, cy, cx)| -> Result<(u64, u64), ChunkWriteError> {
                    // Gather the outer chunk, padded with the fill value (0).
                    chunk.clear();
                    chunk.resize(chunk_len, T::default());
                    let (y0, x0) = (cy * oy, cx * ox);
                    let (vy, vx) = ((ny - y0).min(oy), (nx - x0).min(ox));
                    let plane = w.area() as usize;
                    for dz in 0..nz {
                        for dy in 0..vy {
                            let src = (c as u64 * nz + dz) as usize * plane
                                + ((y0 - w.y0 + dy) * w.nx + x0 - w.x0) as usize;
                            let dst = ((dz * oy + dy) * ox) as usize;
                            chunk[dst..dst + vx as usize]
                                .copy_from_slice(&slab[src..src + vx as usize]);
                        }
                    }
                    let (mut written, mut empty) = (0u64, 0u64);
                    let [bz, by, bx] = self.brick;
                    let mut any_data = false;
                    for iz in 0..nz.div_ceil(bz) {
                        for iy in 0..vy.div_ceil(by) {
                            for ix in 0..vx.div_ceil(bx) {
                                let (zs, ys, xs) = (iz * bz, iy * by, ix * bx);
                                let (ze, ye, xe) =
                                    ((zs + bz).min(nz), (ys + by).min(vy), (xs + bx).min(vx));
                                let chunk: &[T] = chunk;
                                let rows = (zs..ze).flat_map(|z| {
                                    (ys..ye).map(move |y| {
                                        let row = ((z * oy + y) * ox) as usize;
                                        &chunk[row + xs as usize..row + xe as usize]
                                    })
                                });
                                let stats =
                                    BrickStats::of_rows(rows, scratch, self.stats.is_some());
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
                                self.histograms.fine.lock().expect("histograms")[index] =
                                    stats.fine;
                            }
                        }
                    }
                    if let Some(array) = self.array
                        && any_data
                    {
                        let indices = [c as u64, z0 / oz, cy, cx];
                        array
                            .store_chunk(&indices, chunk.as_slice())
                            .map_err(|source| ChunkWriteError {
                                chunk: indices,
                                source: Box::new(source),
                            })?;
                    }
                    Ok((written, empty))
                },
            )
            .collect::<Result<Vec<_>, _>>()?;
        cells.add_slab(slab, z0, nz, w);
        Ok(counts
            .into_iter()
            .fold((0, 0), |a, b| (a.0 + b.0, a.1 + b.1)))
    }
}

impl<T: Sample> Level<T> {
    /// Writes one slab of this level's values and records its region metadata.
    fn write_slab(
        &mut self,
        values: &[T],
        z0: u64,
        nz: u64,
        stats: Option<&[Mutex<ChannelAccumulator>]>,
    ) -> Result<(), ConvertError> {
        let bricks_z = self.plan.shape[0].div_ceil(self.brick[0]);
        self.histograms
            .extend_to((z0 + nz).div_ceil(self.brick[0]), bricks_z);
        let sink = SlabSink {
            channels: self.cells.channels,
            window: self.window,
            brick: self.brick,
            outer: self.outer,
            array: Some(&self.array),
            histograms: &self.histograms,
            stats,
        };
        let (written, empty) = sink
            .process(values, z0, nz, &mut self.cells)
            .map_err(|source| ConvertError::WriteLevel0 {
                path: self.output.clone(),
                source,
            })?;
        self.written += written;
        self.empty += empty;
        self.release(z0 + nz)?;
        Ok(())
    }

    /// Starts a column's blocks of region metadata, for the level's planes `planes` over its
    /// window: the cells they reach (halos included) and their bricks. A partition keeps
    /// whole rows.
    fn open_column(&mut self, planes: std::ops::Range<u64>) {
        if self.regions.is_none() || planes.is_empty() {
            return;
        }
        let channels = self.cells.channels;
        let w = self.window;
        let [y1, x1] = w.end();
        let cells = self.plan.shape.map(|s| s.div_ceil(CELL));
        self.cells = CellGrid::block(
            channels,
            cells_reached(planes.clone(), cells[0]),
            cells_reached(w.y0..y1, cells[1]),
            cells_reached(w.x0..x1, cells[2]),
            cells[0],
        );
        let b = self.brick;
        self.histograms = LevelHistograms::block(
            channels,
            planes.start / b[0]..planes.end.div_ceil(b[0]),
            w.y0 / b[1]..y1.div_ceil(b[1]),
            w.x0 / b[2]..x1.div_ceil(b[2]),
        );
    }

    /// Writes the rows of cells the columns found that no plane from `delivered` on can
    /// reach (every column of the planes before it being made).
    fn assemble(&mut self, delivered: u64) -> Result<(), RegionWriteError> {
        let Some(regions) = &mut self.regions else {
            return Ok(());
        };
        let rows = if delivered >= self.plan.shape[0] {
            u64::MAX
        } else {
            delivered.saturating_sub(HALO) / CELL
        };
        regions.assemble_cells(rows)
    }

    /// Writes the rows of region metadata that no plane from `delivered` on can reach (see
    /// [`LevelRegionWriter::release`]). A partition keeps its rows.
    fn release(&mut self, delivered: u64) -> Result<(), RegionWriteError> {
        match &mut self.regions {
            Some(regions) => regions.release(
                &mut self.cells,
                &mut self.histograms,
                delivered,
                self.brick[0],
            ),
            None => Ok(()),
        }
    }
}

/// A slab of one level, as the next level's accumulator reads it: rows of `x` values.
trait SlabRows<T: Sample>: Sync {
    /// Adds the source row starting at `base` (length `sx`) into `sum`/`count`, summing
    /// `step_x` (1 or 2) neighbours per destination voxel.
    fn add_row(&self, base: usize, sx: usize, step_x: u64, sum: &mut [T::Sum], count: &mut [u32]);
}

/// Level-0 voxel values, `[c][nz][y][x]`.
struct Values<'a, T>(&'a [T]);

impl<T: Sample> SlabRows<T> for Values<'_, T> {
    fn add_row(&self, base: usize, sx: usize, step_x: u64, sum: &mut [T::Sum], count: &mut [u32]) {
        let row = &self.0[base..base + sx];
        if step_x == 1 {
            for ((s, n), &v) in sum.iter_mut().zip(count.iter_mut()).zip(row) {
                *s += v.to_sum();
                *n += v.counts() as u32;
            }
        } else {
            let pairs = row.chunks_exact(2);
            let tail = pairs.remainder();
            for ((s, n), p) in sum.iter_mut().zip(count.iter_mut()).zip(pairs) {
                *s += p[0].to_sum();
                *s += p[1].to_sum();
                *n += p[0].counts() as u32 + p[1].counts() as u32;
            }
            if let [v] = tail {
                let last = sx / 2;
                sum[last] += v.to_sum();
                count[last] += v.counts() as u32;
            }
        }
    }
}

/// Exact sums and counts of a level ≥ 1 accumulator, laid out `[c][oz][y][x]` while the
/// slab holds `nz ≤ oz` planes.
struct Sums<'a, T: Sample> {
    sum: &'a [T::Sum],
    count: &'a [u32],
    nz_plane: usize,
    oz_plane: usize,
}

impl<T: Sample> SlabRows<T> for Sums<'_, T> {
    fn add_row(&self, base: usize, sx: usize, step_x: u64, sum: &mut [T::Sum], count: &mut [u32]) {
        let j = base / self.nz_plane * self.oz_plane + base % self.nz_plane;
        let (src_sum, src_count) = (&self.sum[j..j + sx], &self.count[j..j + sx]);
        if step_x == 1 {
            for (d, &v) in sum.iter_mut().zip(src_sum) {
                *d += v;
            }
            for (d, &v) in count.iter_mut().zip(src_count) {
                *d += v;
            }
        } else {
            for (x, (&v, &n)) in src_sum.iter().zip(src_count).enumerate() {
                sum[x / 2] += v;
                count[x / 2] += n;
            }
        }
    }
}

/// Adds a slab of one level into the accumulator of the next level.
/// `src_z0..src_z0 + nz` is the slab's z range in the source level's coordinates, and
/// `window` the part of each plane it holds (its edges on voxel edges of the next level).
fn accumulate<T: Sample>(
    plan: &LevelPlan,
    next: &mut Accumulator<T>,
    channels: usize,
    window: PlaneRegion,
    src_z0: u64,
    nz: u64,
    src: &impl SlabRows<T>,
) {
    let step = plan.step;
    let dst = next.window;
    let oz = next.depth;
    let a0 = next.z0;
    let src_plane = window.area() as usize;
    let [src_y1, _] = window.end();
    // The first column of the destination this window sums into.
    let offset = (window.x0 / step[2] - dst.x0) as usize;
    next.sum
        .par_chunks_mut(dst.nx as usize)
        .zip(next.count.par_chunks_mut(dst.nx as usize))
        .enumerate()
        .for_each(|(row, (sum, count))| {
            let row = row as u64;
            let y = dst.y0 + row % dst.ny;
            let zi = (row / dst.ny) % oz;
            let c = (row / dst.ny / oz) as usize;
            if c >= channels {
                return;
            }
            let z = a0 + zi;
            for dz in 0..step[0] {
                let szz = z * step[0] + dz;
                if szz < src_z0 || szz >= src_z0 + nz {
                    continue;
                }
                for dy in 0..step[1] {
                    let syy = y * step[1] + dy;
                    if syy < window.y0 || syy >= src_y1 {
                        continue;
                    }
                    let base = (c as u64 * nz + (szz - src_z0)) as usize * src_plane
                        + ((syy - window.y0) * window.nx) as usize;
                    src.add_row(
                        base,
                        window.nx as usize,
                        step[2],
                        &mut sum[offset..],
                        &mut count[offset..],
                    );
                }
            }
        });
}

/// Checks the options against the inputs and plans the store: brick and shard shapes, levels,
/// and where `count` partitions cut.
fn plan_store<T: Sample>(
    options: &ConvertOptions,
    inputs: &Inputs,
    count: usize,
) -> Result<PartitionPlan, ConvertError> {
    let requested = options.brick;
    if requested.contains(&0) {
        return Err(ConvertError::ChunkNotPositive);
    }
    if let Some(s) = options.shard {
        if (0..3).any(|i| s[i] == 0 || s[i] % requested[i] != 0) {
            return Err(ConvertError::ShardNotMultiple {
                shard: s,
                chunk: requested,
            });
        }
        if options.version == OmeZarrVersion::V04 {
            return Err(ConvertError::ShardNeedsV3);
        }
    }
    // A brick edge longer than the volume would hold only fill value past it: clamp it to the
    // volume (and a shard to the bricks that cover the volume), so a huge --chunk costs nothing.
    let shape = inputs.shape;
    let brick: [u64; 3] = std::array::from_fn(|i| requested[i].min(shape[i]));
    let outer: [u64; 3] = match options.shard {
        Some(s) => std::array::from_fn(|i| s[i].min(shape[i].div_ceil(brick[i]) * brick[i])),
        None => brick,
    };
    let brick_bytes = brick
        .iter()
        .try_fold(T::FORMAT.bytes() as u64, |acc, &e| acc.checked_mul(e))
        .unwrap_or(u64::MAX);
    // Blosc compresses at most 2 GiB (less its 16-byte header) in one chunk.
    if brick_bytes > i32::MAX as u64 - 16 {
        return Err(ConvertError::BrickTooLarge {
            requested,
            brick,
            format: T::FORMAT,
            bytes: brick_bytes,
        });
    }
    let voxel_size = inputs.voxel_size.unwrap_or([1.0; 3]);
    if voxel_size.iter().any(|v| !(v.is_finite() && *v > 0.0)) {
        return Err(ConvertError::BadVoxelSize { voxel_size });
    }
    let levels = plan_levels(shape, voxel_size, brick, options.levels);
    let cuts = Cuts::plan(&levels, outer[0], count);
    Ok(PartitionPlan {
        format: T::FORMAT,
        shape,
        labels: inputs.labels.clone(),
        voxel_size,
        unit: inputs.unit.clone(),
        brick,
        outer,
        sharded: options.shard.is_some(),
        version: options.version,
        levels,
        cuts,
    })
}

/// Where a pass's region metadata goes.
#[derive(Clone, Copy, Debug)]
enum RegionOutput {
    /// Into the store's arrays; levels `0..gathered_levels` gather their cells from several
    /// columns or partitions.
    Store { gathered_levels: usize },
    /// Into a partition's records, for `finalize`.
    Partition(Partition),
}

/// Creates the arrays of levels `0..written` and their state for a pass over level-0 planes
/// `planes`: each level's accumulator starts at the first of its planes that the pass makes.
/// Each level writes its region metadata (or a partition's records of it) as rows become
/// final, holding a few rows at a time.
fn open_levels<T: Sample>(
    writer: &StoreWriter,
    plan: &PartitionPlan,
    written: usize,
    planes: std::ops::Range<u64>,
    output: RegionOutput,
) -> Result<Vec<Level<T>>, ConvertError> {
    let channels = plan.labels.len();
    let (brick, outer) = (plan.brick, plan.outer);
    let mut levels = Vec::new();
    for (i, level) in plan.levels.iter().take(written).enumerate() {
        let [z, y, x] = level.shape;
        let layout = ArrayLayout {
            shape: vec![channels as u64, z, y, x],
            chunk: vec![1, outer[0], outer[1], outer[2]],
            inner_chunk: plan.sharded.then(|| vec![1, brick[0], brick[1], brick[2]]),
            format: T::FORMAT,
            dimension_names: Some(vec!["c", "z", "y", "x"]),
        };
        let array = writer.create_array(&format!("/{i}"), &layout)?;
        // This level's planes.
        let f = level.factor[0];
        let (z0, z1) = (planes.start / f, planes.end.div_ceil(f));
        // One slab of the level: a chunk deep, or the whole level when that is shallower.
        let window = PlaneRegion::whole([y, x]);
        let acc = if i == 0 {
            Accumulator::empty()
        } else {
            Accumulator::new(channels, z0, outer[0].min(z), window)
        };
        let bricks: [u64; 3] = std::array::from_fn(|a| level.shape[a].div_ceil(brick[a]));
        let regions = match output {
            RegionOutput::Store { gathered_levels } => LevelRegionWriter::create(
                writer,
                i,
                &i.to_string(),
                level.shape,
                level.factor,
                channels,
                brick,
                i < gathered_levels,
            )?,
            RegionOutput::Partition(partition) => LevelRegionWriter::for_partition(
                &writer.partial.join(HANDOFF_FOLDER).join(RECORDS_FOLDER),
                &records_stem(partition, i),
                level.shape,
                channels,
            )?,
        };
        // Empty windows at the first rows the planes reach.
        let cells = level.shape.map(|s| s.div_ceil(CELL));
        let first = if z0 < z1 {
            cells_reached(z0..z1, cells[0]).start
        } else {
            0
        };
        let cells = CellGrid::window(channels, [cells[1], cells[2]], first..first, cells[0]);
        let first = z0 / brick[0];
        let histograms = LevelHistograms::for_rows(channels, bricks, first..first);
        levels.push(Level {
            plan: level.clone(),
            array,
            outer,
            acc,
            brick,
            window,
            values: Vec::new(),
            cells,
            histograms,
            regions: Some(regions),
            output: writer.output.clone(),
            written: 0,
            empty: 0,
        });
    }
    Ok(levels)
}

/// Reads `region` of level-0 planes `planes` of the inputs slab by slab (a reader thread
/// decodes slab k+1 while slab k is written) and sends each up the pyramid.
#[allow(clippy::too_many_arguments)]
fn read_level0<T: Sample>(
    sources: &mut [Box<dyn VolumeSource>],
    plan: &PartitionPlan,
    planes: std::ops::Range<u64>,
    region: PlaneRegion,
    levels: &mut [Level<T>],
    handed_over: &mut HandedOver<T>,
    stats: &[Mutex<ChannelAccumulator>],
    bar: &indicatif::ProgressBar,
) -> Result<(), ConvertError> {
    let channels = plan.labels.len();
    let plane = region.area() as usize;
    let oz = plan.outer[0];
    std::thread::scope(|scope| {
        // Reader thread: decodes slab k+1 while slab k is processed.
        let (tx, rx) = sync_channel::<Result<(u64, u64, Vec<T>), SourceError>>(0);
        // Processed slabs go back to the reader, so their memory is reused, not re-faulted.
        let (recycle_tx, recycle_rx) = std::sync::mpsc::channel::<Vec<T>>();
        let reader = scope.spawn(move || {
            let mut z0 = planes.start;
            let mut allocated = 0;
            while z0 < planes.end {
                let nz = oz.min(planes.end - z0);
                // At most two slabs exist: the one being processed and the one being read.
                let mut slab = if allocated < 2 {
                    allocated += 1;
                    Vec::new()
                } else {
                    match recycle_rx.recv() {
                        Ok(slab) => slab,
                        Err(_) => return,
                    }
                };
                slab.resize(channels * nz as usize * plane, T::default());
                let mut rest: &mut [T] = &mut slab;
                let mut parts = Vec::new();
                for s in sources.iter_mut() {
                    let len = s.info().channels * nz as usize * plane;
                    let (part, tail) = rest.split_at_mut(len);
                    parts.push((s, part));
                    rest = tail;
                }
                let result: Result<(), SourceError> =
                    parts.into_par_iter().try_for_each(|(s, part)| {
                        for c in 0..s.info().channels {
                            for dz in 0..nz {
                                let start = (c * nz as usize + dz as usize) * plane;
                                s.read_region(
                                    c,
                                    z0 + dz,
                                    region,
                                    T::plane_out(&mut part[start..start + plane]),
                                )?;
                            }
                        }
                        Ok(())
                    });
                let failed = result.is_err();
                if tx.send(result.map(|()| (z0, nz, slab))).is_err() || failed {
                    return;
                }
                z0 += nz;
            }
        });

        let result = (|| -> Result<(), ConvertError> {
            for message in &rx {
                let (z0, nz, slab) = message?;
                process_level0(levels, handed_over, stats, &slab, z0, nz)?;
                bar.inc(slab.len() as u64 * T::FORMAT.bytes() as u64);
                let _ = recycle_tx.send(slab);
            }
            Ok(())
        })();
        // Unblock the reader whether it waits to send a slab or to get one back.
        drop(rx);
        drop(recycle_tx);
        reader.join().map_err(|_| ConvertError::ReaderPanicked)?;
        result
    })
}

/// Runs level-0 planes `planes` of the inputs through the levels of `levels` (and into the
/// hand-over accumulator after them, in a partition), in the columns of `columns`: whole
/// planes in one pass, or each group of planes column by column (see [`crate::columns`]).
#[allow(clippy::too_many_arguments)]
fn run_pass<T: Sample>(
    options: &ConvertOptions,
    sources: &mut [Box<dyn VolumeSource>],
    plan: &PartitionPlan,
    columns: &ColumnPlan,
    planes: std::ops::Range<u64>,
    levels: &mut [Level<T>],
    handed_over: &mut HandedOver<T>,
    stats: &[Mutex<ChannelAccumulator>],
) -> Result<(), ConvertError> {
    let channels = plan.labels.len();
    let [_, ny, nx] = plan.shape;
    let input_bytes =
        (planes.end - planes.start) * ny * nx * channels as u64 * T::FORMAT.bytes() as u64;
    let bar = crate::progress::bytes_bar(input_bytes, "", options.progress);
    let local = columns.local_levels;
    let split = !columns.is_whole([ny, nx]);
    // Every local level is complete at the end of a group: one slab of the first level made
    // from whole planes (all planes when every level is local).
    let group_depth = levels.get(local).map_or(planes.end - planes.start, |l| {
        plan.outer[0] * l.plan.factor[0]
    });
    let mut start = planes.start;
    while start < planes.end {
        let group = start..(start + group_depth.max(1)).min(planes.end);
        // The first whole-plane level's slab gathers the columns' sums; it is flushed (and
        // the coarser levels made) once every column has added its share.
        let mut gathered: HandedOver<T> = levels.get_mut(local).map(|l| {
            let acc = std::mem::replace(&mut l.acc, Accumulator::empty());
            (l.plan.clone(), acc)
        });
        for region in columns.columns([ny, nx]) {
            for (l, level) in levels.iter_mut().enumerate().take(local) {
                let f = level.plan.factor;
                level.window = at_level(region, f, level.plan.shape);
                // A column's own sums (whole planes keep those `open_levels` made).
                let z0 = group.start / f[0];
                if l > 0 && (level.acc.window, level.acc.z0) != (level.window, z0) {
                    let depth = plan.outer[0].min(level.plan.shape[0]);
                    level.acc = Accumulator::new(channels, z0, depth, level.window);
                }
            }
            if split {
                for level in levels.iter_mut().take(local) {
                    let f = level.plan.factor[0];
                    level.open_column(group.start / f..group.end.div_ceil(f));
                }
            }
            let into = if gathered.is_some() {
                &mut gathered
            } else {
                &mut *handed_over
            };
            read_level0(
                sources,
                plan,
                group.clone(),
                region,
                &mut levels[..local],
                into,
                stats,
                &bar,
            )?;
            if split {
                // The rest of the column's blocks of region metadata.
                for level in levels.iter_mut().take(local) {
                    level.release(u64::MAX)?;
                }
            }
        }
        if split {
            // Every column of the group is made: the local levels' rows before its end are
            // final (the whole-plane levels write theirs slab by slab).
            for level in levels.iter_mut().take(local) {
                level.assemble(group.end.div_ceil(level.plan.factor[0]))?;
            }
        }
        if let Some((_, acc)) = gathered {
            levels[local].acc = acc;
            let below_depth = levels[local - 1].plan.shape[0];
            flush_if_full(levels, handed_over, local, below_depth)?;
        }
        start = group.end;
    }
    bar.finish_and_clear();
    Ok(())
}

/// Chooses the columns of a pass over `planes` that writes levels `0..written`, within the
/// memory limit.
fn plan_pass<T: Sample>(
    options: &ConvertOptions,
    plan: &PartitionPlan,
    written: usize,
    planes: &std::ops::Range<u64>,
) -> Result<ColumnPlan, ConvertError> {
    let pass = Pass {
        plan,
        sum_bytes: size_of::<T::Sum>() as u64,
        written,
        planes: planes.end - planes.start,
        threads: rayon::current_num_threads() as u64,
    };
    let limit = options.memory_limit.unwrap_or_else(default_memory_limit);
    pass.plan_columns(limit)
        .map_err(|estimate| ConvertError::MemoryLimit {
            output: options.output.display().to_string(),
            needed: estimate.total(),
            estimate,
            channels: plan.labels.len(),
            depth: plan.outer[0].min(plan.shape[0]),
            limit,
        })
}

fn new_stats(channels: usize) -> Vec<Mutex<ChannelAccumulator>> {
    (0..channels)
        .map(|_| Mutex::new(ChannelAccumulator::default()))
        .collect()
}

fn into_stats(stats: Vec<Mutex<ChannelAccumulator>>) -> Vec<ChannelAccumulator> {
    stats
        .into_iter()
        .map(|m| m.into_inner().expect("stats"))
        .collect()
}

fn convert_typed<T: Sample>(
    options: &ConvertOptions,
    mut inputs: Inputs,
) -> Result<ConvertSummary, ConvertError> {
    let started = Instant::now();
    let plan = plan_store::<T>(options, &inputs, 1)?;
    let depth = plan.shape[0];
    let columns = plan_pass::<T>(options, &plan, plan.levels.len(), &(0..depth))?;
    let writer = StoreWriter::create(&options.output, options.version, options.overwrite)?;
    let column_levels = if columns.is_whole([plan.shape[1], plan.shape[2]]) {
        0
    } else {
        columns.local_levels
    };
    let output = RegionOutput::Store {
        gathered_levels: column_levels,
    };
    let mut levels = open_levels::<T>(&writer, &plan, plan.levels.len(), 0..depth, output)?;
    let stats = new_stats(plan.labels.len());
    run_pass(
        options,
        &mut inputs.sources,
        &plan,
        &columns,
        0..depth,
        &mut levels,
        &mut None,
        &stats,
    )?;
    let mut summary = finish_store(writer, &plan, &mut levels, &into_stats(stats), started)?;
    summary.columns = (!columns.is_whole([plan.shape[1], plan.shape[2]])).then_some(columns);
    Ok(summary)
}

/// Writes the region metadata and the root metadata (the last write) of a store whose levels
/// are all written, and moves it into place.
fn finish_store<T: Sample>(
    writer: StoreWriter,
    plan: &PartitionPlan,
    levels: &mut [Level<T>],
    stats: &[ChannelAccumulator],
    started: Instant,
) -> Result<ConvertSummary, ConvertError> {
    let channels = plan.labels.len();
    let (channel_stats, displays, binnings) = channel_summaries::<T>(stats, &plan.labels);
    let mut region_levels = Vec::new();
    for level in levels.iter_mut() {
        level.release(u64::MAX)?;
        let regions = level
            .regions
            .take()
            .expect("a store's levels write their regions");
        region_levels.push(regions.finish(&binnings, level.written, level.empty)?);
    }
    let regions = region_document(region_levels, channel_stats, plan.brick);
    let name = dataset_name(&writer.output);
    let metadata_bytes = serde_json::to_vec_pretty(&regions)?.len() as u64;
    let depth = plan.shape[0];
    let attributes = image_attributes(
        plan.version,
        multiscale(plan.version, &name, &plan.levels, plan.unit.as_deref()),
        omero(&displays, depth),
        regions,
    );
    // The root group metadata is the last write of the store.
    writer.write_image_group(&attributes)?;
    let partial = writer.partial.clone();
    let stored_bytes = directory_bytes(&partial);
    let level0_stored_bytes = directory_bytes(&partial.join("0"));
    let metadata_bytes = directory_bytes(&partial.join("residency")) + metadata_bytes;
    let output = writer.commit()?;
    let [_, ny, nx] = plan.shape;
    Ok(ConvertSummary {
        output,
        format: T::FORMAT,
        levels: levels
            .iter()
            .map(|l| LevelSummary {
                shape: [
                    channels as u64,
                    l.plan.shape[0],
                    l.plan.shape[1],
                    l.plan.shape[2],
                ],
                bricks_written: l.written,
                bricks_empty: l.empty,
            })
            .collect(),
        input_bytes: depth * ny * nx * channels as u64 * T::FORMAT.bytes() as u64,
        stored_bytes,
        level0_stored_bytes,
        metadata_bytes,
        seconds: started.elapsed().as_secs_f64(),
        columns: None,
    })
}

/// What one partition of a conversion did.
#[derive(Clone, Debug, PartialEq)]
pub struct PartitionSummary {
    /// The partition.
    pub partition: Partition,
    /// The store's temporary folder, which holds its bricks and its hand-over file.
    pub folder: PathBuf,
    /// Its level-0 planes.
    pub planes: std::ops::Range<u64>,
    /// The levels it wrote (`0..written_levels`).
    pub written_levels: usize,
    /// Bricks written, all levels.
    pub bricks_written: u64,
    /// Bricks found empty, all levels.
    pub bricks_empty: u64,
    /// Bytes of its level-0 voxels (uncompressed).
    pub input_bytes: u64,
    /// Wall time in seconds.
    pub seconds: f64,
    /// The columns the planes were cut into, when they were.
    pub columns: Option<ColumnPlan>,
    /// Plane extent `y, x`.
    pub plane: [u64; 2],
}

impl PartitionSummary {
    /// Human-readable report printed by the command line.
    pub fn report(&self) -> String {
        let mb = self.input_bytes as f64 / 1e6;
        format!(
            "wrote partition {} into {}: level-0 planes {}..{}, levels 0 to {}, bricks written {}, empty (not written) {}\n  input {mb:.1} MB, {:.2} s, {:.1} MB/s\n",
            self.partition,
            self.folder.display(),
            self.planes.start,
            self.planes.end,
            self.written_levels.saturating_sub(1),
            self.bricks_written,
            self.bricks_empty,
            self.seconds,
            mb / self.seconds.max(1e-9)
        ) + &columns_report(self.columns.as_ref(), self.plane)
    }
}

/// `ingest convert --partition I/N`: converts the partition's level-0 planes, writes the
/// bricks of the levels it covers whole into the store's temporary folder (shared with the
/// other partitions, never cleared), and leaves what `finalize` needs in a hand-over file.
/// Running a partition again replaces what it wrote before.
///
/// # Errors
/// As [`convert`], and [`ConvertError::Handoff`] when the hand-over file cannot be written.
pub fn convert_partition(
    options: &ConvertOptions,
    partition: Partition,
) -> Result<PartitionSummary, ConvertError> {
    let inputs = open_inputs(options)?;
    with_sample_type!(inputs.format, T => partition_typed::<T>(options, inputs, partition))
}

fn partition_typed<T: Sample>(
    options: &ConvertOptions,
    mut inputs: Inputs,
    partition: Partition,
) -> Result<PartitionSummary, ConvertError> {
    let started = Instant::now();
    let plan = plan_store::<T>(options, &inputs, partition.count)?;
    let planes = plan.cuts.planes(partition.index, plan.shape[0]);
    let written = plan.cuts.handoff_level;
    let columns = plan_pass::<T>(options, &plan, written, &planes)?;
    let writer = StoreWriter::shared(&options.output, options.version, options.overwrite)?;
    claim_plan(
        &writer.partial,
        &options.output.display().to_string(),
        &plan,
    )?;
    let output = RegionOutput::Partition(partition);
    let mut levels = open_levels::<T>(&writer, &plan, written, planes.clone(), output)?;
    let channels = plan.labels.len();
    let mut handed_over: HandedOver<T> = plan.levels.get(written).map(|level| {
        let f = level.factor[0];
        let z0 = planes.start / f;
        let z1 = planes.end.div_ceil(f).max(z0);
        let [_, y, x] = level.shape;
        (
            level.clone(),
            Accumulator::new(channels, z0, z1 - z0, PlaneRegion::whole([y, x])),
        )
    });
    let stats = new_stats(channels);
    run_pass(
        options,
        &mut inputs.sources,
        &plan,
        &columns,
        planes.clone(),
        &mut levels,
        &mut handed_over,
        &stats,
    )?;
    let (bricks_written, bricks_empty) = levels
        .iter()
        .fold((0, 0), |(w, e), l| (w + l.written, e + l.empty));
    let mut parts = Vec::new();
    for mut level in levels {
        // The rows at the partition's ends: finalize merges them with the neighbours'.
        level.release(u64::MAX)?;
        let regions = level.regions.take().expect("a partition's records");
        parts.push(LevelPart {
            written: level.written,
            empty: level.empty,
            records: regions.into_records()?,
        });
    }
    let handoff: Handoff<T> = Handoff {
        levels: parts,
        stats: into_stats(stats),
        sums: handed_over.map(|(_, acc)| LevelSums {
            z0: acc.z0,
            depth: acc.depth,
            sum: acc.sum,
            count: acc.count,
        }),
    };
    write_handoff(&writer.partial, partition, &plan, &handoff)?;
    let [_, ny, nx] = plan.shape;
    Ok(PartitionSummary {
        partition,
        folder: writer.partial.clone(),
        planes: planes.clone(),
        written_levels: written,
        bricks_written,
        bricks_empty,
        input_bytes: (planes.end - planes.start)
            * ny
            * nx
            * channels as u64
            * T::FORMAT.bytes() as u64,
        seconds: started.elapsed().as_secs_f64(),
        columns: (!columns.is_whole([ny, nx])).then_some(columns),
        plane: [ny, nx],
    })
}

/// `ingest finalize`: finishes the store at `output` (named `shown` in messages) whose N
/// partitions have all run. Merges their region
/// metadata and statistics, writes the levels they did not (from the exact sums they handed
/// over), removes the hand-over files, writes the root metadata last and moves the store into
/// place: byte for byte the store one `ingest convert` writes.
///
/// # Errors
/// [`ConvertError::Handoff`] when partitions are missing, unreadable or disagree, and the
/// errors of [`convert`] for writing the store.
pub fn finalize(
    output: &Path,
    shown: &str,
    overwrite: bool,
    progress: bool,
) -> Result<ConvertSummary, ConvertError> {
    let partial = crate::store::partial_path(output);
    let handoffs = Handoffs::find(&partial, shown)?;
    let format = handoffs.plan.format;
    with_sample_type!(format, T => finalize_typed::<T>(output, overwrite, progress, &handoffs))
}

fn finalize_typed<T: Sample>(
    output: &Path,
    overwrite: bool,
    progress: bool,
    handoffs: &Handoffs,
) -> Result<ConvertSummary, ConvertError> {
    let started = Instant::now();
    let plan = &handoffs.plan;
    let writer = StoreWriter::shared(output, plan.version, overwrite)?;
    // The levels below the hand-over level gather their cells from the partitions' records.
    let output = RegionOutput::Store {
        gathered_levels: plan.cuts.handoff_level,
    };
    let mut levels = open_levels::<T>(&writer, plan, plan.levels.len(), 0..plan.shape[0], output)?;
    let channels = plan.labels.len();
    let h = plan.cuts.handoff_level;
    let mut stats = vec![ChannelAccumulator::default(); channels];
    let bar = crate::progress::bytes_bar(handoffs.files.len() as u64, "merging", progress);
    let count = handoffs.files.len();
    for index in 0..count {
        let part = handoffs.read::<T>(index)?;
        // Partitions come in z order: rows the next one cannot reach are final.
        let next = if index + 1 < count {
            plan.cuts.planes(index + 1, plan.shape[0]).start
        } else {
            u64::MAX
        };
        let records = writer.partial.join(HANDOFF_FOLDER).join(RECORDS_FOLDER);
        let partition = Partition { index, count };
        for (l, (level, from)) in levels.iter_mut().zip(part.levels).enumerate() {
            level.written += from.written;
            level.empty += from.empty;
            let regions = level.regions.as_mut().expect("a store's levels");
            regions.adopt(&records, &records_stem(partition, l), &from.records)?;
            level.assemble(next / level.plan.factor[0])?;
        }
        for (all, from) in stats.iter_mut().zip(&part.stats) {
            all.merge(from);
        }
        if let Some(sums) = part.sums {
            feed_sums(&mut levels, h, &sums)?;
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    // The store must not hold the hand-over files when its root metadata is written; the
    // partitions' record files the levels adopted stay open and readable until they finish.
    let folder = writer.partial.join(HANDOFF_FOLDER);
    std::fs::remove_dir_all(&folder).map_err(|source| HandoffError::Io {
        path: folder,
        what: "cannot remove",
        source,
    })?;
    finish_store(writer, plan, &mut levels, &stats, started)
}

/// Feeds a partition's level-`h` sums into level `h`'s accumulator plane by plane, flushing
/// each slab as it fills, as the level below would have.
fn feed_sums<T: Sample>(
    levels: &mut [Level<T>],
    h: usize,
    sums: &LevelSums<T>,
) -> Result<(), ConvertError> {
    let channels = levels[h].cells.channels;
    let plane = levels[h].window.area() as usize;
    let below_depth = levels[h - 1].plan.shape[0];
    let step = levels[h].plan.step[0];
    for p in 0..sums.depth {
        let z = sums.z0 + p;
        let acc = &mut levels[h].acc;
        let zi = (z - acc.z0) as usize;
        for c in 0..channels {
            let dst = (c * acc.depth as usize + zi) * plane;
            let src = (c * sums.depth as usize + p as usize) * plane;
            acc.sum[dst..dst + plane].copy_from_slice(&sums.sum[src..src + plane]);
            acc.count[dst..dst + plane].copy_from_slice(&sums.count[src..src + plane]);
        }
        flush_if_full(levels, &mut None, h, ((z + 1) * step).min(below_depth))?;
    }
    Ok(())
}

/// The accumulator of the level a partition hands over to `finalize` (the first level it does
/// not write), with that level's plan.
type HandedOver<T> = Option<(LevelPlan, Accumulator<T>)>;

/// Adds a slab of level `l` (`z0..z0 + nz`, in its own z) into the level above: the next
/// written level's accumulator, whose slab is then flushed if full, or the hand-over
/// accumulator.
fn propagate<T: Sample>(
    levels: &mut [Level<T>],
    handed_over: &mut HandedOver<T>,
    l: usize,
    z0: u64,
    nz: u64,
    src: &impl SlabRows<T>,
) -> Result<(), ConvertError> {
    let channels = levels[l].cells.channels;
    let window = levels[l].window;
    if l + 1 < levels.len() {
        let next = &mut levels[l + 1];
        accumulate(&next.plan, &mut next.acc, channels, window, z0, nz, src);
        flush_if_full(levels, handed_over, l + 1, z0 + nz)?;
    } else if let Some((plan, acc)) = handed_over {
        accumulate(plan, acc, channels, window, z0, nz, src);
    }
    Ok(())
}

/// Writes a level-0 slab and propagates it up the pyramid.
fn process_level0<T: Sample>(
    levels: &mut [Level<T>],
    handed_over: &mut HandedOver<T>,
    stats: &[Mutex<ChannelAccumulator>],
    slab: &[T],
    z0: u64,
    nz: u64,
) -> Result<(), ConvertError> {
    levels[0].write_slab(slab, z0, nz, Some(stats))?;
    propagate(levels, handed_over, 0, z0, nz, &Values(slab))
}

/// Flushes level `l`'s accumulator when the level below has delivered everything it covers
/// (`below_end` is the end, in level `l-1` z, of what has been delivered).
fn flush_if_full<T: Sample>(
    levels: &mut [Level<T>],
    handed_over: &mut HandedOver<T>,
    l: usize,
    below_end: u64,
) -> Result<(), ConvertError> {
    let below_depth = levels[l - 1].plan.shape[0];
    let level = &levels[l];
    let channels = level.cells.channels;
    let depth = level.plan.shape[0];
    let oz = level.outer[0];
    let nz = oz.min(depth - level.acc.z0);
    let needed = ((level.acc.z0 + nz) * level.plan.step[0]).min(below_depth);
    if below_end < needed {
        return Ok(());
    }
    let z0 = level.acc.z0;
    let plane = level.window.area() as usize;
    // Means of the slab: rounded once, from exact sums.
    let slab_len = nz as usize * plane;
    let mut values = std::mem::take(&mut levels[l].values);
    values.resize(channels * slab_len, T::default());
    {
        let acc = &levels[l].acc;
        values
            .par_chunks_mut(slab_len)
            .enumerate()
            .for_each(|(c, out)| {
                let start = c * acc.depth as usize * plane;
                let sum = &acc.sum[start..start + slab_len];
                let count = &acc.count[start..start + slab_len];
                for ((o, &s), &n) in out.iter_mut().zip(sum).zip(count) {
                    *o = T::from_mean(s, n);
                }
            });
    }
    levels[l].write_slab(&values, z0, nz, None)?;
    levels[l].values = values;
    let acc = std::mem::replace(&mut levels[l].acc, Accumulator::empty());
    let sums = Sums::<T> {
        sum: &acc.sum,
        count: &acc.count,
        nz_plane: nz as usize * plane,
        oz_plane: acc.depth as usize * plane,
    };
    let done = propagate(levels, handed_over, l, z0, nz, &sums);
    let mut acc = acc;
    acc.sum.fill(T::Sum::default());
    acc.count.fill(0);
    acc.z0 += nz;
    levels[l].acc = acc;
    done
}
