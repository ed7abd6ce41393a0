//! The streaming pass: each level's state ([`Level`]), level-0 slabs read from the inputs
//! and sent up the pyramid, in whole planes or column by column, and the store finished once
//! every level is written.

use std::path::PathBuf;
use std::sync::Mutex;
use std::sync::mpsc::sync_channel;
use std::time::Instant;

use rayon::prelude::*;
use residency_schemas::dataset::dataset_name;
use zarrs::array::Array;

use super::error::ConvertError;
use super::options::ConvertOptions;
use super::pyramid_sums::{
    Accumulator, BandSums, BandWork, SlabRows, Sums, Target, Values, accumulate, covered,
    narrow_sums, with_sums,
};
use super::sink::{SlabSink, planes_of};
use super::summary::{ConvertSummary, LevelSummary};
use crate::columns::{ColumnPlan, at_level};
use crate::ome::{image_attributes, multiscale, omero};
use crate::partition::handoff::{HANDOFF_FOLDER, RECORDS_FOLDER, records_stem};
use crate::partition::plan::{Partition, PartitionPlan};
use crate::pyramid::LevelPlan;
use crate::region_writer::{
    LevelRegionWriter, RegionWriteError, channel_summaries, region_document,
};
use crate::regions::{CELL, CellGrid, ChannelAccumulator, HALO, LevelHistograms, cells_reached};
use crate::sample_format::{Sample, SumOf};
use crate::source::{MappedPlane, PlaneRegion, SourceError, VolumeSource};
use crate::store::{ArrayLayout, Store, StoreWriter, directory_bytes};

/// Per-level state during the pass.
pub(crate) struct Level<T: Sample> {
    pub(crate) plan: LevelPlan,
    pub(crate) array: Array<Store>,
    /// Zarr chunk (shard) shape `z, y, x`.
    pub(crate) outer: [u64; 3],
    /// The slab being filled (levels ≥ 1; empty for level 0): `min(outer z, level depth)`
    /// planes.
    pub(crate) acc: Accumulator<T>,
    /// Brick shape `z, y, x`.
    pub(crate) brick: [u64; 3],
    /// The part of the level's planes this pass makes now: the whole plane, or a column.
    pub(crate) window: PlaneRegion,
    /// The rounded means of the slab being flushed (reused between flushes).
    pub(crate) values: Vec<T>,
    /// The rows of min/max cells not yet final (all a partition's rows: it writes none).
    pub(crate) cells: CellGrid<T>,
    /// The rows of brick histograms not yet final (all a partition's rows).
    pub(crate) histograms: LevelHistograms,
    /// Where final rows go (none in a partition, which hands its rows to `finalize`).
    pub(crate) regions: Option<LevelRegionWriter<T>>,
    /// The output, for messages.
    pub(crate) output: PathBuf,
    pub(crate) written: u64,
    pub(crate) empty: u64,
    /// Chunks of one chunk row a worker gathers at once ([`ColumnPlan::gather`]).
    pub(crate) gather: u64,
}

impl<T: Sample> Level<T> {
    /// Writes one slab of this level's values (`planes[c · nz + z]`) and records its region
    /// metadata, doing `bands`' work on each band of it where the workers gather whole chunk
    /// rows; returns whether they did.
    pub(crate) fn write_slab(
        &mut self,
        planes: &[&[T]],
        z0: u64,
        nz: u64,
        stats: Option<&[Mutex<ChannelAccumulator>]>,
        bands: Option<&dyn BandWork<T>>,
    ) -> Result<bool, ConvertError> {
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
            gather: self.gather,
        };
        let (written, empty, banded) = sink
            .process(planes, z0, nz, &mut self.cells, bands)
            .map_err(|source| ConvertError::WriteLevel0 {
                path: self.output.clone(),
                source,
            })?;
        self.written += written;
        self.empty += empty;
        self.release(z0 + nz)?;
        Ok(banded)
    }

    /// Starts a column's blocks of region metadata, for the level's planes `planes` over its
    /// window: the cells they reach (halos included) and their bricks. A partition keeps
    /// whole rows.
    pub(crate) fn open_column(&mut self, planes: std::ops::Range<u64>) {
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
    pub(crate) fn assemble(&mut self, delivered: u64) -> Result<(), RegionWriteError> {
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
    pub(crate) fn release(&mut self, delivered: u64) -> Result<(), RegionWriteError> {
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

/// Where a pass's region metadata goes.
#[derive(Clone, Copy, Debug)]
pub(crate) enum RegionOutput {
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
pub(crate) fn open_levels<T: Sample>(
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
            Accumulator::new(
                narrow_sums::<T>(level),
                channels,
                z0,
                outer[0].min(z),
                window,
            )
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
            gather: 1,
        });
    }
    Ok(levels)
}

/// A level-0 slab as the reader hands it over: decoded into memory, or lent plane by plane by
/// the inputs' files (see [`VolumeSource::map_plane`]).
enum Level0Slab<T> {
    /// `[c][nz][y][x]` in one buffer.
    Decoded(Vec<T>),
    /// Plane `c · nz + z` of the slab at index `c · nz + z`.
    Mapped(Vec<MappedPlane>),
}

impl<T: Sample> Level0Slab<T> {
    /// The slab's `count` planes of `plane` voxels, as its consumers take them.
    fn planes(&self, count: usize, plane: usize) -> Vec<&[T]> {
        match self {
            Self::Decoded(values) => planes_of(values, count, plane),
            Self::Mapped(mapped) => {
                let planes: Vec<&[T]> = mapped.iter().map(MappedPlane::samples).collect();
                debug_assert!(planes.len() == count && planes.iter().all(|p| p.len() == plane));
                planes
            }
        }
    }
}

/// The planes `z0..z0 + nz` of every channel of `sources`, in the slab's order, mapped from
/// their files while `mapping`; None once a plane must be read instead, which ends `mapping`
/// for the pass: a slab is mapped whole or read whole.
fn map_slab<T: Sample>(
    sources: &mut [Box<dyn VolumeSource>],
    mapping: &mut bool,
    z0: u64,
    nz: u64,
) -> Result<Option<Vec<MappedPlane>>, SourceError> {
    if !*mapping {
        return Ok(None);
    }
    let mut planes = Vec::new();
    for source in sources.iter_mut() {
        for c in 0..source.info().channels {
            for z in z0..z0 + nz {
                let Some(plane) = source.map_plane(c, z, T::FORMAT)? else {
                    *mapping = false;
                    return Ok(None);
                };
                planes.push(plane);
            }
        }
    }
    Ok(Some(planes))
}

/// Decodes `region` of the planes `z0..z0 + nz` of every channel of `sources` into one slab
/// `[c][nz][y][x]` of `channels` channels, in a buffer from `spare` when it holds one; each
/// source on its own thread.
fn decode_slab<T: Sample>(
    sources: &mut [Box<dyn VolumeSource>],
    spare: &mut Vec<Vec<T>>,
    z0: u64,
    nz: u64,
    region: PlaneRegion,
    channels: usize,
) -> Result<Vec<T>, SourceError> {
    let plane = region.area() as usize;
    let mut slab = spare.pop().unwrap_or_default();
    crate::memory::sized(&mut slab, channels * nz as usize * plane);
    let mut rest: &mut [T] = &mut slab;
    let mut parts = Vec::new();
    for s in sources.iter_mut() {
        let len = s.info().channels * nz as usize * plane;
        let (part, tail) = rest.split_at_mut(len);
        parts.push((s, part));
        rest = tail;
    }
    parts.into_par_iter().try_for_each(|(s, part)| {
        for c in 0..s.info().channels {
            for dz in 0..nz {
                let start = (c * nz as usize + dz as usize) * plane;
                let out = T::plane_out(&mut part[start..start + plane]);
                s.read_region(c, z0 + dz, region, out)?;
            }
        }
        Ok(())
    })?;
    Ok(slab)
}

/// Reads `region` of level-0 planes `planes` of the inputs slab by slab (a reader thread
/// decodes or maps slab k+1 while slab k is written) and sends each up the pyramid. Whole
/// planes stored as they are read are mapped from their files when `map_inputs` allows;
/// the others are decoded into two slabs that come from `spare` and go back to it, so the
/// columns of a pass reuse the same memory. Returns the input planes read in place.
#[allow(clippy::too_many_arguments)]
fn read_level0<T: Sample>(
    sources: &mut [Box<dyn VolumeSource>],
    plan: &PartitionPlan,
    planes: std::ops::Range<u64>,
    region: PlaneRegion,
    map_inputs: bool,
    levels: &mut [Level<T>],
    handed_over: &mut HandedOver<T>,
    stats: &[Mutex<ChannelAccumulator>],
    bar: &crate::progress::Progress,
    spare: &mut Vec<Vec<T>>,
) -> Result<u64, ConvertError> {
    let channels = plan.labels.len();
    let plane = region.area() as usize;
    let oz = plan.outer[0];
    let [_, ny, nx] = plan.shape;
    let mut mapping = map_inputs && region.is_whole([ny, nx]);
    std::thread::scope(|scope| {
        // Reader thread: decodes or maps slab k+1 while slab k is processed.
        type Message<T> = Result<(u64, u64, Level0Slab<T>), SourceError>;
        let (tx, rx) = sync_channel::<Message<T>>(0);
        // Processed slabs go back to the reader, so their memory is reused, not re-faulted.
        let (recycle_tx, recycle_rx) = std::sync::mpsc::channel::<Level0Slab<T>>();
        let mut own = std::mem::take(spare);
        let reader = scope.spawn(move || {
            let mut z0 = planes.start;
            let mut allocated = 0;
            while z0 < planes.end {
                let nz = oz.min(planes.end - z0);
                // At most two slabs exist: the one being processed and the one being read.
                // A decoded slab that comes back is kept for the next decoded one; a mapped
                // one is unmapped.
                if allocated < 2 {
                    allocated += 1;
                } else {
                    match recycle_rx.recv() {
                        Ok(Level0Slab::Decoded(slab)) => own.push(slab),
                        Ok(Level0Slab::Mapped(_)) => {}
                        Err(_) => return (own, recycle_rx),
                    }
                }
                let slab = match map_slab::<T>(sources, &mut mapping, z0, nz) {
                    Ok(Some(mapped)) => Ok(Level0Slab::Mapped(mapped)),
                    Ok(None) => decode_slab(sources, &mut own, z0, nz, region, channels)
                        .map(Level0Slab::Decoded),
                    Err(e) => Err(e),
                };
                let failed = slab.is_err();
                if tx.send(slab.map(|slab| (z0, nz, slab))).is_err() || failed {
                    return (own, recycle_rx);
                }
                z0 += nz;
            }
            (own, recycle_rx)
        });

        let result = (|| -> Result<u64, ConvertError> {
            let mut mapped = 0;
            for message in &rx {
                let (z0, nz, slab) = message?;
                let planes = slab.planes(channels * nz as usize, plane);
                process_level0(levels, handed_over, stats, &planes, z0, nz)?;
                bar.inc((channels * nz as usize * plane * T::FORMAT.bytes()) as u64);
                if let Level0Slab::Mapped(planes) = &slab {
                    mapped += planes.iter().filter(|p| p.in_place()).count() as u64;
                }
                drop(planes);
                let _ = recycle_tx.send(slab);
            }
            Ok(mapped)
        })();
        // Unblock the reader whether it waits to send a slab or to get one back.
        drop(rx);
        drop(recycle_tx);
        let (own, recycled) = reader.join().map_err(|_| ConvertError::ReaderPanicked)?;
        let decoded = recycled.try_iter().filter_map(|slab| match slab {
            Level0Slab::Decoded(values) => Some(values),
            Level0Slab::Mapped(_) => None,
        });
        spare.extend(own.into_iter().chain(decoded));
        result
    })
}

/// Runs level-0 planes `planes` of the inputs through the levels of `levels` (and into the
/// hand-over accumulator after them, in a partition), in the columns of `columns`: whole
/// planes in one pass, or each group of planes column by column (see [`crate::columns`]).
/// Returns the input planes read in place from their files (mapped, not copied).
#[allow(clippy::too_many_arguments)]
pub(crate) fn run_pass<T: Sample>(
    options: &ConvertOptions,
    sources: &mut [Box<dyn VolumeSource>],
    plan: &PartitionPlan,
    columns: &ColumnPlan,
    planes: std::ops::Range<u64>,
    levels: &mut [Level<T>],
    handed_over: &mut HandedOver<T>,
    stats: &[Mutex<ChannelAccumulator>],
) -> Result<u64, ConvertError> {
    let channels = plan.labels.len();
    let [_, ny, nx] = plan.shape;
    let input_bytes =
        (planes.end - planes.start) * ny * nx * channels as u64 * T::FORMAT.bytes() as u64;
    let bar = crate::progress::Progress::new(
        input_bytes,
        "",
        options.progress,
        options.on_progress.clone(),
    );
    let local = columns.local_levels;
    let split = !columns.is_whole([ny, nx]);
    for level in levels.iter_mut() {
        level.gather = columns.gather;
    }
    // Every local level is complete at the end of a group: one slab of the first level made
    // from whole planes (all planes when every level is local).
    let group_depth = levels.get(local).map_or(planes.end - planes.start, |l| {
        plan.outer[0] * l.plan.factor[0]
    });
    // The level-0 slabs, kept from column to column.
    let mut spare = Vec::new();
    let mut mapped = 0;
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
                    level.acc.restart(channels, z0, depth, level.window);
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
            mapped += read_level0(
                sources,
                plan,
                group.clone(),
                region,
                options.map_inputs,
                &mut levels[..local],
                into,
                stats,
                &bar,
                &mut spare,
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
    Ok(mapped)
}

pub(crate) fn new_stats(channels: usize) -> Vec<Mutex<ChannelAccumulator>> {
    (0..channels)
        .map(|_| Mutex::new(ChannelAccumulator::default()))
        .collect()
}

pub(crate) fn into_stats(stats: Vec<Mutex<ChannelAccumulator>>) -> Vec<ChannelAccumulator> {
    stats
        .into_iter()
        .map(|m| m.into_inner().expect("stats"))
        .collect()
}

/// Writes the region metadata and the root metadata (the last write) of a store whose levels
/// are all written, and moves it into place.
pub(crate) fn finish_store<T: Sample>(
    writer: StoreWriter,
    plan: &PartitionPlan,
    levels: &mut [Level<T>],
    stats: &[ChannelAccumulator],
    started: Instant,
) -> Result<ConvertSummary, ConvertError> {
    let channels = plan.labels.len();
    let (channel_stats, displays, binnings) = channel_summaries::<T>(stats, &plan.labels);
    // The levels' last rows and binned histograms, every level at once.
    let region_levels = levels
        .par_iter_mut()
        .map(|level| -> Result<_, ConvertError> {
            level.release(u64::MAX)?;
            let regions = level
                .regions
                .take()
                .expect("a store's levels write their regions");
            Ok(regions.finish(&binnings, level.written, level.empty)?)
        })
        .collect::<Result<Vec<_>, _>>()?;
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
        planes_in_place: 0,
    })
}

/// The rounded means of the first `nz` planes of a level's accumulator, `[c][nz][y][x]`, into
/// `values`. Sample types without NaN count the level-0 voxels under each voxel from the
/// level's factor and the level-0 extent `full` (see [`covered`]); the others kept counts.
fn mean_slab<T: Sample>(
    acc: &Accumulator<T>,
    level: &LevelPlan,
    full: [u64; 3],
    nz: u64,
    values: &mut [T],
) {
    let w = acc.window;
    let row = w.nx as usize;
    let f = level.factor;
    // Every voxel of a row covers `f[2]` columns but the level's last one.
    let inner = if w.x0 + w.nx >= level.shape[2] {
        row - 1
    } else {
        row
    };
    with_sums!(&acc.sum, sums => values.par_chunks_mut(row).enumerate().for_each(|(i, out)| {
        let (y, z) = (i as u64 % w.ny, i as u64 / w.ny % nz);
        let c = i as u64 / w.ny / nz;
        let start = ((c * acc.depth + z) * w.ny + y) as usize * row;
        let sum = &sums[start..start + row];
        if T::HAS_NAN {
            for ((o, s), &n) in out.iter_mut().zip(sum).zip(&acc.count[start..]) {
                *o = T::from_mean(s.widened(), n);
            }
            return;
        }
        let zy = covered(acc.z0 + z, f[0], full[0]) * covered(w.y0 + y, f[1], full[1]);
        T::means(&mut out[..inner], &sum[..inner], zy * f[2] as u32);
        for x in inner..row {
            let n = zy * covered(w.x0 + x as u64, f[2], full[2]);
            T::means(&mut out[x..=x], &sum[x..=x], n);
        }
    }));
}

/// The accumulator of the level a partition hands over to `finalize` (the first level it does
/// not write), with that level's plan.
pub(crate) type HandedOver<T> = Option<(LevelPlan, Accumulator<T>)>;

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

/// Writes a level-0 slab (`planes[c · nz + z]`) and propagates it up the pyramid.
fn process_level0<T: Sample>(
    levels: &mut [Level<T>],
    handed_over: &mut HandedOver<T>,
    stats: &[Mutex<ChannelAccumulator>],
    planes: &[&[T]],
    z0: u64,
    nz: u64,
) -> Result<(), ConvertError> {
    // Level 1's sums are added band by band by the workers that write level 0 (the slab's
    // rows in their cache), where they gather whole chunk rows; else after, as for the
    // other levels.
    let summed = match levels {
        [first, next, ..] => {
            let channels = first.cells.channels;
            let target = Target::new(&next.plan, &next.acc, channels, first.window, z0, nz);
            let acc = &mut next.acc;
            with_sums!(&mut acc.sum, sum => {
                let bands = BandSums::new(target, (sum, &mut acc.count), first.outer[1]);
                first.write_slab(planes, z0, nz, Some(stats), Some(&bands))?
            })
        }
        [first] => first.write_slab(planes, z0, nz, Some(stats), None)?,
        [] => false,
    };
    if summed {
        flush_if_full(levels, handed_over, 1, z0 + nz)
    } else {
        propagate(levels, handed_over, 0, z0, nz, &Values(planes))
    }
}

/// Flushes level `l`'s accumulator when the level below has delivered everything it covers
/// (`below_end` is the end, in level `l-1` z, of what has been delivered).
pub(crate) fn flush_if_full<T: Sample>(
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
    crate::memory::sized(&mut values, channels * slab_len);
    mean_slab(
        &levels[l].acc,
        &levels[l].plan,
        levels[0].plan.shape,
        nz,
        &mut values,
    );
    let planes = planes_of(&values, channels * nz as usize, plane);
    levels[l].write_slab(&planes, z0, nz, None, None)?;
    levels[l].values = values;
    let mut acc = std::mem::replace(&mut levels[l].acc, Accumulator::empty());
    let done = with_sums!(&acc.sum, sum => {
        let sums = Sums {
            sum,
            count: &acc.count,
            nz: nz as usize,
            oz: acc.depth as usize,
            plane,
        };
        propagate(levels, handed_over, l, z0, nz, &sums)
    });
    acc.sum.zero();
    acc.count.fill(0);
    acc.z0 += nz;
    levels[l].acc = acc;
    done
}
