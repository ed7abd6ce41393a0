//! Writing Zarr stores: array and group metadata for Zarr v2 (OME-Zarr 0.4) and v3
//! (OME-Zarr 0.5), the blosc-lz4 codec, optional sharding, and the atomic
//! write-to-temporary-then-rename that keeps a half-written store from looking complete.
//!
//! The modules: `error` ([`StoreError`]), `metadata` (array layouts and codecs), `staging`
//! (the store being written) and `writer` (the temporary folder and the commit).

mod error;
mod metadata;
mod staging;
mod writer;

use std::path::Path;

pub use residency_schemas::ome::OmeZarrVersion;

pub use self::error::StoreError;
pub(crate) use self::metadata::ArrayLayout;
pub(crate) use self::staging::{StagingStore, Store, sync_file_system};
pub(crate) use self::writer::StoreWriter;
pub use self::writer::partial_path;

/// Total size in bytes of the files under `dir`.
pub fn directory_bytes(dir: &Path) -> u64 {
    fn walk(dir: &Path) -> u64 {
        std::fs::read_dir(dir).map_or(0, |entries| {
            entries
                .filter_map(Result::ok)
                .map(|e| match e.file_type() {
                    Ok(t) if t.is_dir() => walk(&e.path()),
                    Ok(_) => e.metadata().map_or(0, |m| m.len()),
                    Err(_) => 0,
                })
                .sum()
        })
    }
    walk(dir)
}
