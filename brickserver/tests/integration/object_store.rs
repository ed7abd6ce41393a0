//! Batched bricks from an object store are read by futures on the server's runtime and are
//! the folder's answers byte for byte: the same store served from its folder and from a copy
//! in `object_store`'s in-memory store (the code path of an `s3://` dataset), stored and raw,
//! with an empty brick, a missing level-1 brick and a corrupt brick among them, with the
//! memory cache and without it; and a sharded store's bricks, among them a brick of fill that
//! its shard does not store (zarrs 0.23 would ask the store for it from offset `u64::MAX`: a
//! panic from a folder, a refused range from an object store).

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

/// The router serving the store at folder `root` as dataset `cells` from a copy of it in an
/// in-memory object store (under the folder's name), as an `s3://` dataset is served.
async fn object_store_server(root: &std::path::Path, options: &ServerOptions) -> axum::Router {
    let prefix = root.file_name().unwrap().to_str().unwrap();
    let datasets = Datasets(vec![Dataset {
        name: "cells".into(),
        location: StoreLocation::S3 {
            bucket: "bucket".into(),
            prefix: prefix.into(),
        },
        object_store: Some((in_memory(root, prefix).await, ObjectPath::from(prefix))),
    }]);
    router(Arc::new(AppState::new(datasets, options).unwrap()), options)
}

/// Asserts that `folder` and `objects` answer `GET path` 200 with the same bytes.
async fn same_answers(folder: &axum::Router, objects: &axum::Router, path: &str) {
    let (a, b) = (get(folder, path, &[]).await, get(objects, path, &[]).await);
    assert_eq!(
        (a.status.as_u16(), b.status.as_u16()),
        (200, 200),
        "{path}: {}",
        b.text()
    );
    assert_eq!(a.body, b.body, "{path}");
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
        let objects = object_store_server(&store, &options).await;
        // Twice: read from the store, then (with a cache) from the cache.
        for _ in 0..2 {
            for path in BATCHES {
                same_answers(&folder, &objects, path).await;
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

/// The values written to channel 0 of level 0 of [`sharded_store`]: `z < 8, y < 16, x < 24`
/// hold `1 + (z·7 + y·3 + x) mod 1000`, the rest the fill value (so the shard of `x` 16–31
/// holds one brick of data and one of fill).
fn sharded_value(z: u64, y: u64, x: u64) -> u16 {
    if z < 8 && y < 16 && x < 24 {
        1 + ((z * 7 + y * 3 + x) % 1000) as u16
    } else {
        0
    }
}

/// [`v3_store`]'s image with its levels rewritten by zarrs as sharded arrays: shards of
/// `1 × 8 × 16 × 16` voxels holding bricks of `8³`, channel 0 of level 0 partly written.
fn sharded_store(dir: &std::path::Path) -> std::path::PathBuf {
    use zarrs::array::{ArrayBuilder, ArraySubset, DataType};
    use zarrs::filesystem::FilesystemStore;
    use zarrs::metadata::v3::{FillValueMetadataV3, MetadataV3};
    let root = v3_store(dir, "shards");
    std::fs::remove_dir_all(root.join("0")).unwrap();
    std::fs::remove_dir_all(root.join("1")).unwrap();
    let store = Arc::new(FilesystemStore::new(&root).unwrap());
    for (level, shape) in [("0", [2u64, 16, 32, 64]), ("1", [2, 8, 16, 32])] {
        let data_type = DataType::from_metadata(&MetadataV3::new("uint16")).unwrap();
        let array = ArrayBuilder::new(
            shape.to_vec(),
            [1, 8, 16, 16],
            data_type,
            FillValueMetadataV3::from(0),
        )
        .subchunk_shape(vec![1, 8, 8, 8])
        .dimension_names(Some(["c", "z", "y", "x"]))
        .build(store.clone(), &format!("/{level}"))
        .unwrap();
        array.store_metadata().unwrap();
        if level == "0" {
            let values: Vec<u16> = (0..8 * 16 * 32)
                .map(|i| sharded_value(i / 512, i / 32 % 16, i % 32))
                .collect();
            let part = ArraySubset::new_with_ranges(&[0..1, 0..8, 0..16, 0..32]);
            array.store_array_subset(&part, values.as_slice()).unwrap();
        }
    }
    root
}

/// The decoded bytes of brick `z, y, x` of channel 0 of level 0 of [`sharded_store`].
fn sharded_brick(z: u64, y: u64, x: u64) -> Vec<u8> {
    (0..512u64)
        .flat_map(|i| sharded_value(z * 8 + i / 64, y * 8 + i / 8 % 8, x * 8 + i % 8).to_le_bytes())
        .collect()
}

#[tokio::test]
async fn sharded_batches_read_from_an_object_store_are_the_folders_byte_for_byte() {
    let dir = tempfile::tempdir().unwrap();
    let store = sharded_store(dir.path());
    let options = ServerOptions {
        cache_bytes: 0,
        ..ServerOptions::default()
    };
    let folder = server(&[("cells", &store)], &options).await;
    let objects = object_store_server(&store, &options).await;
    // Two bricks of one shard, one of another, one of fill in that shard, one in a shard
    // never written, a level-1 brick, and a brick of channel 1.
    let bricks = "b=0,0,0,0,0;0,0,0,0,1;0,0,0,1,2;0,0,0,1,3;0,0,1,3,7;1,0,0,1,1;0,1,0,0,0";
    for encoding in ["stored", "raw"] {
        same_answers(
            &folder,
            &objects,
            &format!("/cells/bricks?{bricks}&encoding={encoding}"),
        )
        .await;
    }
    let raw = get(
        &objects,
        &format!("/cells/bricks?{bricks}&encoding=raw"),
        &[],
    )
    .await;
    let (header, payload) = decode_framed::<BrickBatchHeader>(BRICKS_MAGIC, &raw.body).unwrap();
    let statuses: Vec<_> = header.bricks.iter().map(|b| b.status).collect();
    use BrickStatus::{Empty, Ok};
    assert_eq!(statuses, [Ok, Ok, Ok, Empty, Empty, Empty, Empty]);
    let expected = [
        sharded_brick(0, 0, 0),
        sharded_brick(0, 0, 1),
        sharded_brick(0, 1, 2),
    ];
    assert_eq!(payload, expected.concat());
}
