//! The brick server's query strings, through the real router (`brickserver/src/routes/`)
//! over a small store that `ingest` writes once per process (40×24×20 uint16, 8³ bricks,
//! several levels, with region metadata):
//!
//! - `/d/regions?...`: the region query (`level`, `channel`, `min=x,y,z`, `max=x,y,z`, parsed
//!   by `parse_xyz` and checked and answered by `RegionIndex::query` in `regions.rs`);
//! - `/d/minmax?...`: the min/max hierarchy's `channel`;
//! - `/d/bricks?...`: the batch query (`parse_batch`, `bricks.rs`), then the batch read;
//! - `/d/KEY` with an optional `Range` header: store key resolution and range parsing (and,
//!   for `KEY` = `view`, the web viewer's page).
//!
//! Any URI that `http` accepts is sent. The server must never answer 5xx for a store it reads
//! well, and what it answers 200 must be well-formed: a region answer covers the box asked
//! for, a framed document decodes.
#![no_main]

use std::sync::OnceLock;

use arbitrary::Arbitrary;
use axum::Router;
use axum::body::Body;
use axum::http::{Request, StatusCode, Uri, header};
use libfuzzer_sys::fuzz_target;
use residency_brickserver::{AppState, Datasets, ServerOptions, router};
use residency_fuzz::scratch;
use residency_ingest::{ConvertOptions, convert};
use residency_schemas::server::RegionAnswer;
use residency_schemas::wire::{
    BRICKS_MAGIC, BrickBatchHeader, MINMAX_MAGIC, MinMaxHierarchyHeader, decode_framed,
};
use residency_store::location::{ObjectStoreOptions, StoreLocation};
use tower::ServiceExt;

struct Server {
    runtime: tokio::runtime::Runtime,
    router: Router,
}

fn server() -> &'static Server {
    static SERVER: OnceLock<Server> = OnceLock::new();
    SERVER.get_or_init(|| {
        let dir = scratch::empty_dir("server");
        let (x, y, z) = (40usize, 24usize, 20usize);
        let mut raw = Vec::with_capacity(x * y * z * 2);
        for i in 0..x * y * z {
            let v = ((i * 2654435761) >> 7) as u16 % 5000;
            raw.extend_from_slice(&v.to_le_bytes());
        }
        let input = dir.join(format!("vol_{x}x{y}x{z}_uint16.raw"));
        std::fs::write(&input, raw).unwrap();
        let store = dir.join("d.ome.zarr");
        let mut options =
            ConvertOptions::new(vec![input.to_string_lossy().into_owned()], store.clone());
        options.brick = [8, 8, 8];
        convert(&options).expect("ingest converts the fuzz store");
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .unwrap();
        let datasets = runtime
            .block_on(Datasets::from_args(
                &[StoreLocation::Folder(store)],
                &[],
                &ObjectStoreOptions::default(),
            ))
            .expect("the store is a dataset");
        // A built web viewer, as `scripts/build-web.sh` leaves one: `/d/view` and `/viewer/...`
        // then answer as they do for users (without one they answer 503 by design, saying how
        // to build it; brickserver's own tests check that).
        let viewer = dir.join("web");
        std::fs::create_dir_all(&viewer).unwrap();
        std::fs::write(
            viewer.join("index.html"),
            "<!doctype html><link rel=\"stylesheet\" href=\"%VIEWER_BASE%style.css\">",
        )
        .unwrap();
        let server_options = ServerOptions {
            viewer_dir: Some(viewer),
            ..ServerOptions::default()
        };
        let state = AppState::new(datasets, &server_options).expect("the server state");
        let router = router(std::sync::Arc::new(state), &server_options);
        Server { runtime, router }
    })
}

#[derive(Arbitrary, Debug)]
enum Endpoint {
    Regions,
    MinMax,
    Bricks,
    Key { range: Option<String> },
}

#[derive(Arbitrary, Debug)]
struct Input {
    endpoint: Endpoint,
    query: String,
}

fuzz_target!(|input: Input| {
    let server = server();
    let q = &input.query;
    let uri = match &input.endpoint {
        Endpoint::Regions => format!("/d/regions?{q}"),
        Endpoint::MinMax => format!("/d/minmax?{q}"),
        Endpoint::Bricks => format!("/d/bricks?{q}"),
        Endpoint::Key { .. } => format!("/d/{q}"),
    };
    let Ok(uri) = Uri::try_from(uri) else {
        return;
    };
    let mut request = Request::get(uri.clone());
    if let Endpoint::Key { range: Some(r) } = &input.endpoint {
        let Ok(value) = header::HeaderValue::from_str(r) else {
            return;
        };
        request = request.header(header::RANGE, value);
    }
    let request = request.body(Body::empty()).unwrap();
    let (status, headers, body) = server.runtime.block_on(async {
        let response = server.router.clone().oneshot(request).await.unwrap();
        let (parts, body) = response.into_parts();
        let body = axum::body::to_bytes(body, usize::MAX).await.unwrap();
        (parts.status, parts.headers, body)
    });
    assert!(
        !status.is_server_error(),
        "{uri} answered {status}: {}",
        String::from_utf8_lossy(&body)
    );
    if status != StatusCode::OK && status != StatusCode::PARTIAL_CONTENT {
        return;
    }
    match &input.endpoint {
        Endpoint::Regions => {
            let a: RegionAnswer = serde_json::from_slice(&body).expect("a region answer");
            for ax in 0..3 {
                for covered in [&a.minmax_box, &a.histogram.covered] {
                    assert!(
                        covered.min[ax] <= a.query.min[ax] && a.query.max[ax] <= covered.max[ax],
                        "{uri}: {covered:?} does not cover {:?}",
                        a.query
                    );
                }
            }
            assert_eq!(a.histogram.counts.iter().sum::<u64>(), a.histogram.voxels);
        }
        Endpoint::MinMax => {
            decode_framed::<MinMaxHierarchyHeader>(MINMAX_MAGIC, &body)
                .expect("a min/max document");
        }
        Endpoint::Bricks => {
            let (h, payload) =
                decode_framed::<BrickBatchHeader>(BRICKS_MAGIC, &body).expect("a brick batch");
            assert!(!h.bricks.is_empty());
            for b in &h.bricks {
                assert!(
                    b.offset
                        .checked_add(b.length)
                        .is_some_and(|e| e <= payload.len() as u64)
                );
            }
        }
        Endpoint::Key { .. } => {
            if status == StatusCode::PARTIAL_CONTENT {
                let range = headers[header::CONTENT_RANGE].to_str().unwrap().to_string();
                let (span, total) = range
                    .strip_prefix("bytes ")
                    .and_then(|r| r.split_once('/'))
                    .expect("Content-Range: bytes a-b/n");
                let (a, b) = span.split_once('-').unwrap();
                let (a, b, total): (u64, u64, u64) = (
                    a.parse().unwrap(),
                    b.parse().unwrap(),
                    total.parse().unwrap(),
                );
                assert!(a <= b && b < total, "{range}");
                assert_eq!(body.len() as u64, b - a + 1, "{range}");
            }
        }
    }
});
