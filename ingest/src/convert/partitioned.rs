//! The entry points of a partitioned conversion: `ingest convert --partition I/N`
//! ([`convert_partition`]) and `ingest finalize` ([`finalize`]), which run the pass of
//! [`crate::convert`](mod@crate::convert) over a partition's planes, or from the partitions'
//! hand-over files ([`crate::partition`] says where partitions cut and what they hand over).

use std::path::{Path, PathBuf};
use std::time::Instant;

use super::error::ConvertError;
use super::inputs::{Inputs, open_inputs};
use super::options::ConvertOptions;
use super::pass::{
    HandedOver, Level, RegionOutput, finish_store, flush_if_full, into_stats, new_stats,
    open_levels, run_pass,
};
use super::plan::{plan_pass, plan_store};
use super::pyramid_sums::Accumulator;
use super::summary::{ConvertSummary, columns_report, in_place_report};
use crate::columns::ColumnPlan;
use crate::partition::handoff::{
    HANDOFF_FOLDER, Handoff, HandoffError, Handoffs, LevelPart, LevelSums, RECORDS_FOLDER,
    claim_plan, records_stem, write_handoff,
};
use crate::partition::plan::Partition;
use crate::regions::ChannelAccumulator;
use crate::sample_format::Sample;
use crate::source::PlaneRegion;
use crate::store::StoreWriter;
use crate::with_sample_type;

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
    /// Its level-0 planes, of all channels.
    pub input_planes: u64,
    /// Of those, the planes read in place from the input files (see
    /// [`ConvertOptions::map_inputs`](super::ConvertOptions::map_inputs)).
    pub planes_in_place: u64,
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
        ) + &in_place_report(self.planes_in_place, self.input_planes)
            + &columns_report(self.columns.as_ref(), self.plane)
    }
}

/// `ingest convert --partition I/N`: converts the partition's level-0 planes, writes the
/// bricks of the levels it covers whole into the store's temporary folder (shared with the
/// other partitions, never cleared), and leaves what `finalize` needs in a hand-over file.
/// Running a partition again replaces what it wrote before.
///
/// # Errors
/// As [`convert`](crate::convert()), and [`ConvertError::Handoff`] when the hand-over file
/// cannot be written.
pub fn convert_partition(
    options: &ConvertOptions,
    partition: Partition,
) -> Result<PartitionSummary, ConvertError> {
    let inputs = open_inputs(options)?;
    let result =
        with_sample_type!(inputs.format, T => partition_typed::<T>(options, inputs, partition));
    super::sink::release_scratch();
    result
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
    let columns = plan_pass::<T>(options, &plan, &inputs.sources, written, &planes)?;
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
            // Wide: the hand-over file holds wide sums.
            Accumulator::new(false, channels, z0, z1 - z0, PlaneRegion::whole([y, x])),
        )
    });
    let stats = new_stats(channels);
    let planes_in_place = run_pass(
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
            sum: acc.sum.into_wide(),
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
        input_planes: (planes.end - planes.start) * channels as u64,
        planes_in_place,
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
/// errors of [`convert`](crate::convert()) for writing the store.
pub fn finalize(
    output: &Path,
    shown: &str,
    overwrite: bool,
    progress: bool,
) -> Result<ConvertSummary, ConvertError> {
    let partial = crate::store::partial_path(output);
    let handoffs = Handoffs::find(&partial, shown)?;
    let format = handoffs.plan.format;
    let result =
        with_sample_type!(format, T => finalize_typed::<T>(output, overwrite, progress, &handoffs));
    super::sink::release_scratch();
    result
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
            acc.sum.set_from_wide(dst, &sums.sum[src..src + plane]);
            if T::HAS_NAN {
                acc.count[dst..dst + plane].copy_from_slice(&sums.count[src..src + plane]);
            }
        }
        flush_if_full(levels, &mut None, h, ((z + 1) * step).min(below_depth))?;
    }
    Ok(())
}
