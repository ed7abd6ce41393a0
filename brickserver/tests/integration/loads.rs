//! The parts of a dataset loaded on first use (its image arrays for `/NAME/bricks`, its region
//! index): a failure is answered the same for `ServerOptions::load_retry`, then the next
//! request loads again, so a store that recovers is served again without a restart; once
//! loaded, a part is kept.

use std::path::PathBuf;
use std::time::Duration;

use axum::Router;
use residency_brickserver::ServerOptions;

use crate::common::{get, server, v3_store};

/// A server of dataset `cells` that retries failed loads after `retry`, whose level-0
/// metadata is broken: the router, that document's path and its good bytes (to mend it).
async fn broken_image(dir: &std::path::Path, retry: Duration) -> (Router, PathBuf, Vec<u8>) {
    let store = v3_store(dir, "cells");
    let options = ServerOptions {
        load_retry: retry,
        ..ServerOptions::default()
    };
    let router = server(&[("cells", &store)], &options).await;
    let level = store.join("0/zarr.json");
    let good = std::fs::read(&level).unwrap();
    std::fs::write(&level, "not json").unwrap();
    (router, level, good)
}

#[tokio::test]
async fn a_failed_load_is_answered_the_same_then_tried_again_after_the_retry_time() {
    let dir = tempfile::tempdir().unwrap();
    // Seconds of retry time, so that a loaded machine's late request stays inside it.
    let (router, level, good) = broken_image(dir.path(), Duration::from_secs(3)).await;
    let path = "/cells/bricks?b=0,0,0,0,0&encoding=raw";
    let failed = get(&router, path, &[]).await;
    assert_eq!(failed.status, 500);
    let message = failed.text();
    assert!(message.contains("dataset 'cells'"), "{message}");
    // The store recovers; within the retry time the answer is the same, without a load.
    std::fs::write(&level, &good).unwrap();
    let again = get(&router, path, &[]).await;
    assert_eq!((again.status, again.text()), (failed.status, message));
    // After it, the next request loads again.
    tokio::time::sleep(Duration::from_millis(3100)).await;
    let served = get(&router, path, &[]).await;
    assert_eq!(served.status, 200, "{}", served.text());
    // Once loaded, the arrays are kept: a later fault of the file changes nothing.
    std::fs::write(&level, "not json").unwrap();
    tokio::time::sleep(Duration::from_millis(3100)).await;
    let kept = get(&router, path, &[]).await;
    assert_eq!((kept.status, kept.body), (served.status, served.body));
}

#[tokio::test]
async fn a_part_that_failed_with_the_image_is_tried_again_with_it() {
    // The image fails to open; the bricks ask for it again within the retry time (and get
    // the image's failure); the region index then reopens the image after the retry time.
    // The bricks load with it at once: their failure was the image's, timed from when the
    // image failed, not from when the bricks asked.
    let dir = tempfile::tempdir().unwrap();
    // 3 s of retry time: the bricks ask 1.5 s after the failure, the region index 3.1 s after
    // it, each with over a second to spare on a loaded machine.
    let (router, level, good) = broken_image(dir.path(), Duration::from_secs(3)).await;
    let (bricks, regions) = (
        "/cells/bricks?b=0,0,0,0,0&encoding=raw",
        "/cells/regions?level=0&channel=0&min=0,0,0&max=1,1,1",
    );
    let failed = get(&router, regions, &[]).await;
    assert_eq!(failed.status, 500, "{}", failed.text());
    tokio::time::sleep(Duration::from_millis(1500)).await;
    let same = get(&router, bricks, &[]).await;
    assert_eq!((same.status, same.text()), (failed.status, failed.text()));
    std::fs::write(&level, &good).unwrap();
    tokio::time::sleep(Duration::from_millis(1600)).await;
    let regions_again = get(&router, regions, &[]).await;
    assert_ne!(regions_again.status, 500, "{}", regions_again.text());
    let served = get(&router, bricks, &[]).await;
    assert_eq!(served.status, 200, "{}", served.text());
}
