//! Planning a conversion before anything is written: the store (brick and shard shapes,
//! levels, cuts), checked against the options, and the columns of a pass within the memory
//! limit.

use super::error::ConvertError;
use super::inputs::Inputs;
use super::options::ConvertOptions;
use super::pyramid_sums::sum_bytes;
use crate::columns::{ColumnPlan, Pass};
use crate::partition::plan::{Cuts, PartitionPlan};
use crate::pyramid::plan_levels;
use crate::sample_format::Sample;
use crate::source::{PlaneRegion, VolumeSource};
use crate::store::OmeZarrVersion;

/// Checks the options against the inputs and plans the store: brick and shard shapes, levels,
/// and where `count` partitions cut.
pub(crate) fn plan_store<T: Sample>(
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

/// Chooses the columns of a pass over `planes` that writes levels `0..written`, within the
/// memory limit.
pub(crate) fn plan_pass<T: Sample>(
    options: &ConvertOptions,
    plan: &PartitionPlan,
    sources: &[Box<dyn VolumeSource>],
    written: usize,
    planes: &std::ops::Range<u64>,
) -> Result<ColumnPlan, ConvertError> {
    // The sources are read at once, each with its own decoder.
    let decoders = |column: PlaneRegion| sources.iter().map(|s| s.decoder_bytes(column)).sum();
    let pass = Pass {
        plan,
        sum_bytes: size_of::<T::Sum>() as u64,
        level_sum_bytes: &sum_bytes::<T>,
        count_bytes: if T::HAS_NAN { 4 } else { 0 },
        decoders: &decoders,
        written,
        planes: planes.end - planes.start,
        threads: rayon::current_num_threads() as u64,
    };
    let limit = options.memory_limit_or_default();
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
