//! Whether a store's region metadata can drive the viewer's culling, and the warnings when it
//! cannot. The volume's description itself is `residency_schemas::volume`'s
//! ([`VolumeInfo::from_ome`](super::VolumeInfo::from_ome)).

use residency_schemas::RegionMetadata;

/// Whether a store's region metadata can drive culling, warning when it cannot: it must be
/// present, and its min/max cells haloed by at least one voxel, since the renderer relies on
/// a cell's range holding every voxel a trilinear sample inside the cell reads.
pub fn usable_region_metadata(regions: Option<&RegionMetadata>, source: &str) -> bool {
    match regions {
        None => {
            warn_no_region_metadata(source);
            false
        }
        Some(r) if r.halo == 0 => {
            tracing::warn!(
                "{source}: the region metadata's min/max cells have no halo, so they do not bound \
                 trilinear samples; culling falls back to computing min/max from bricks (run \
                 `ingest index` on the store to rewrite it)"
            );
            false
        }
        Some(_) => true,
    }
}

/// The warning a source logs for a store without region metadata.
pub fn warn_no_region_metadata(source: &str) {
    tracing::warn!(
        "{source}: no region metadata; culling falls back to computing min/max from bricks \
         (run `ingest index` on the store to add it)"
    );
}
