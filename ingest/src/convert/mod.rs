//! `ingest convert`: one streaming pass from the inputs to a finished OME-Zarr pyramid with
//! region metadata.
//!
//! Level 0 is read in slabs one chunk (or shard) deep. Each slab is written, folded into the
//! min/max cells and brick histograms, and summed into the next level's accumulator, which
//! holds exact sums and counts of level-0 voxels. When an accumulator has a full slab, its
//! means are rounded once and the same happens one level up. Memory is a few slabs per level
//! and never depends on the depth of the stack.
//!
//! The modules, in the order a conversion uses them: [`options`](ConvertOptions) and
//! [`error`](ConvertError); `inputs` (opened and checked together) and `plan` (the store and
//! the columns of the pass); `pass`, the streaming pass, with `pyramid_sums` (the exact-sum
//! downsampling) and `sink` (a slab written and its region metadata recorded); and
//! [`summary`](ConvertSummary). Partitioned conversions run the same pass from `partitioned`
//! ([`convert_partition`], [`finalize`]; [`crate::partition`] plans their cuts and hand-over).

pub(crate) mod error;
pub(crate) mod inputs;
pub(crate) mod options;
mod partitioned;
pub(crate) mod pass;
pub(crate) mod plan;
pub(crate) mod pyramid_sums;
pub(crate) mod sink;
pub(crate) mod summary;

use std::time::Instant;

pub use self::error::ConvertError;
pub use self::options::{ConvertOptions, default_memory_limit};
pub use self::partitioned::{PartitionSummary, convert_partition, finalize};
pub use self::sink::ChunkWriteError;
pub use self::summary::{ConvertSummary, LevelSummary};

use self::inputs::{Inputs, open_inputs};
use self::pass::{RegionOutput, finish_store, into_stats, new_stats, open_levels, run_pass};
use self::plan::{plan_pass, plan_store};
use crate::sample_format::Sample;
use crate::store::StoreWriter;
use crate::with_sample_type;

/// Converts the inputs to an OME-Zarr store, as `ingest convert` does.
///
/// # Errors
/// When the options do not fit the inputs (chunk, shard, voxel size, memory), an input cannot
/// be opened or read or does not go with the others, or the store cannot be written. A failed
/// run leaves no output behind.
pub fn convert(options: &ConvertOptions) -> Result<ConvertSummary, ConvertError> {
    let inputs = open_inputs(options)?;
    let result = with_sample_type!(inputs.format, T => convert_typed::<T>(options, inputs));
    sink::release_scratch();
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

fn convert_typed<T: Sample>(
    options: &ConvertOptions,
    mut inputs: Inputs,
) -> Result<ConvertSummary, ConvertError> {
    let started = Instant::now();
    let plan = plan_store::<T>(options, &inputs, 1)?;
    let depth = plan.shape[0];
    let columns = plan_pass::<T>(
        options,
        &plan,
        &inputs.sources,
        plan.levels.len(),
        &(0..depth),
    )?;
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
    let in_place = run_pass(
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
    summary.planes_in_place = in_place;
    summary.columns = (!columns.is_whole([plan.shape[1], plan.shape[2]])).then_some(columns);
    Ok(summary)
}
