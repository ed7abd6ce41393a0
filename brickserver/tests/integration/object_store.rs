//! Batched bricks from an object store are read by futures on the server's runtime and are
//! the folder's answers byte for byte: the same store served from its folder and from a copy
//! in `object_store`'s in-memory store (the code path of an `s3://` dataset), stored and raw,
//! with an empty brick, a missing level-1 brick and a corrupt brick among them, with the
//! memory cache and without it.

use std::sync::Arc;

use residency_brickserver::{AppState, Dataset, Datasets, ServerOptions, router};
use residency_schemas::wire::{BRICKS_MAGIC, BrickBatchHeader, BrickStatus, decode_framed};
use residency_store::location::StoreLocation;
use residency_store::location::object_store::memory::InMemory;
use residency_store::location::object_store::path::Path as ObjectPath;
use residency_store::location::object_store::{ObjectStore, ObjectStoreExt};

use crate::common::{CHUNK, get, server, v3_store, write};

/// The two batches asked of both: brick (0, 0, 1) is whole, brick (0, 0, 0) is [`CHUNK`]
/// (stored verbatim, but not a brick's 1024 bytes), (0, 1, 1) and level 1 are not stored.
const BATCHES: [&str; 2] = [
    "/cells/bricks?b=0,0,0,0,1;0,0,0,0,0;0,0,0,1,1;1,0,0,0,0",
    "/cells/bricks?b=0,0,0,0,1;0,0,0,0,0;0,0,0,1,1;1,0,0,0,0&encoding=raw",
];

/// One brick of 8³ `uint16` samples, `i * 7 + 1` (never the fill value), little-endian.
fn whole_brick() -> Vec<u8> {
    (0..512u16)
        .flat_map(|i| (i * 7 + 1).to_le_bytes())
        .collect()
}

/// The files under `root` as objects under `prefix` of an in-memory object store.
async fn in_memory(root: &std::path::Path, prefix: &str) -> Arc<dyn ObjectStore> {
    let objects = InMemory::new();
    let mut folders = vec![root.to_path_buf()];
    while let Some(folder) = folders.pop() {
        for entry in std::fs::read_dir(&folder).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                folders.push(path);
                continue;
            }
            let key = path.strip_prefix(root).unwrap().to_str().unwrap();
            let bytes = std::fs::read(&path).unwrap();
            objects
                .put(&ObjectPath::from(format!("{prefix}/{key}")), bytes.into())
                .await
                .unwrap();
        }
    }
    Arc::new(objects)
}

#[tokio::test]
async fn batches_read_from_an_object_store_are_the_folders_byte_for_byte() {
    let dir = tempfile::tempdir().unwrap();
    let store = v3_store(dir.path(), "cells");
    write(&store, "0/c/0/0/0/1", whole_brick());
    for cache_bytes in [0, 64 << 20] {
        let options = ServerOptions {
            cache_bytes,
            ..ServerOptions::default()
        };
        let folder = server(&[("cells", &store)], &options).await;
        let client = in_memory(&store, "cells.ome.zarr").await;
        let datasets = Datasets(vec![Dataset {
            name: "cells".into(),
            location: StoreLocation::S3 {
                bucket: "bucket".into(),
                prefix: "cells.ome.zarr".into(),
            },
            object_store: Some((client, ObjectPath::from("cells.ome.zarr"))),
        }]);
        let objects = router(
            Arc::new(AppState::new(datasets, &options).unwrap()),
            &options,
        );
        // Twice: read from the store, then (with a cache) from the cache.
        for _ in 0..2 {
            for path in BATCHES {
                let (a, b) = (
                    get(&folder, path, &[]).await,
                    get(&objects, path, &[]).await,
                );
                assert_eq!(
                    (a.status.as_u16(), b.status.as_u16()),
                    (200, 200),
                    "{path}: {}",
                    b.text()
                );
                assert_eq!(a.body, b.body, "{path}");
            }
        }
        let stored = get(&objects, BATCHES[0], &[]).await;
        let (header, payload) =
            decode_framed::<BrickBatchHeader>(BRICKS_MAGIC, &stored.body).unwrap();
        let statuses: Vec<_> = header.bricks.iter().map(|b| b.status).collect();
        use BrickStatus::{Empty, Error, Ok};
        assert_eq!(statuses, [Ok, Ok, Empty, Empty]);
        assert_eq!(payload, [whole_brick(), CHUNK.to_vec()].concat());
        let raw = get(&objects, BATCHES[1], &[]).await;
        let (header, payload) = decode_framed::<BrickBatchHeader>(BRICKS_MAGIC, &raw.body).unwrap();
        let statuses: Vec<_> = header.bricks.iter().map(|b| b.status).collect();
        assert_eq!(statuses, [Ok, Error, Empty, Empty]);
        assert_eq!(payload, whole_brick());
        let error = header.bricks[1].error.as_deref().unwrap();
        assert!(
            error.starts_with("level 0 channel 0 brick [0, 0, 0] (key '0/c/0/0/0/0'): "),
            "{error}"
        );
    }
}
