//! Helpers shared by the `brickserver` integration tests: small stores written by hand (an
//! OME-Zarr 0.5 / Zarr v3 store with two `uint16` channels and an OME-Zarr 0.4 / Zarr v2 store
//! with one `uint8` channel), a built web viewer folder, and requests to the router.

#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::sync::Arc;

use axum::Router;
use axum::body::Body;
use axum::http::{HeaderMap, Request, StatusCode};
use residency_brickserver::{AppState, Datasets, ServerOptions, router};
use residency_store::location::ObjectStoreOptions;
use tower::ServiceExt as _;

/// The viewer page of the test folder: it names its files through `%VIEWER_BASE%`.
pub const INDEX_HTML: &str = "<!doctype html>\n<link rel=\"stylesheet\" \
     href=\"%VIEWER_BASE%style.css\">\n<p id=\"message\"></p>\n\
     <script type=\"module\" src=\"%VIEWER_BASE%main.js\"></script>\n";

/// The test page as served with `base` for `%VIEWER_BASE%`.
pub fn page_with(base: &str) -> String {
    INDEX_HTML.replace("%VIEWER_BASE%", base)
}

/// The bytes of the test folder's dummy `.wasm` file.
pub const WASM: &[u8] = b"\0asm\x01\0\0\0dummy module";

/// The first chunk of the v3 store (channel 0, brick 0, 0, 0), as stored.
pub const CHUNK: &[u8] = b"not really a chunk, but served verbatim";

/// Writes `text` to `root/key`, creating folders.
pub fn write(root: &Path, key: &str, text: impl AsRef<[u8]>) {
    let path = root.join(key);
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    std::fs::write(path, text).unwrap();
}

/// An OME-Zarr 0.5 (Zarr v3) store at `dir/NAME.ome.zarr`: channels `c`, `z`, `y`, `x` in
/// micrometres, 2 × 16 × 32 × 64 `uint16` voxels of 2 × 0.5 × 0.25 µm at level 0, two
/// levels; `omero`: DAPI (blue, window 100–3000 of 0–65535, active) and GFP (green, 250–40000,
/// inactive); one chunk.
pub fn v3_store(dir: &Path, name: &str) -> PathBuf {
    let root = dir.join(format!("{name}.ome.zarr"));
    write(
        &root,
        "zarr.json",
        r#"{"zarr_format": 3, "node_type": "group", "attributes": {"ome": {"version": "0.5",
        "multiscales": [{"name": "cells", "axes": [
            {"name": "c", "type": "channel"},
            {"name": "z", "type": "space", "unit": "micrometer"},
            {"name": "y", "type": "space", "unit": "micrometer"},
            {"name": "x", "type": "space", "unit": "micrometer"}],
          "datasets": [
            {"path": "0", "coordinateTransformations": [{"type": "scale", "scale": [1.0, 2.0, 0.5, 0.25]}]},
            {"path": "1", "coordinateTransformations": [{"type": "scale", "scale": [1.0, 4.0, 1.0, 0.5]}]}]}],
        "omero": {"channels": [
            {"label": "DAPI", "color": "0000FF", "active": true,
             "window": {"min": 0, "max": 65535, "start": 100, "end": 3000}},
            {"label": "GFP", "color": "00FF00", "active": false,
             "window": {"min": 0, "max": 65535, "start": 250, "end": 40000}}]}}}}"#,
    );
    for (level, shape) in [("0", "[2, 16, 32, 64]"), ("1", "[2, 8, 16, 32]")] {
        write(
            &root,
            &format!("{level}/zarr.json"),
            format!(
                r#"{{"zarr_format": 3, "node_type": "array", "shape": {shape},
                "data_type": "uint16",
                "chunk_grid": {{"name": "regular", "configuration": {{"chunk_shape": [1, 8, 8, 8]}}}},
                "chunk_key_encoding": {{"name": "default", "configuration": {{"separator": "/"}}}},
                "fill_value": 0, "codecs": [{{"name": "bytes", "configuration": {{"endian": "little"}}}}],
                "dimension_names": ["c", "z", "y", "x"]}}"#
            ),
        );
    }
    write(&root, "0/c/0/0/0/0", CHUNK);
    root
}

/// An OME-Zarr 0.4 (Zarr v2) store at `dir/NAME.ome.zarr`: axes `c`, `z`, `y`, `x` without
/// units, 1 × 4 × 6 × 8 `uint8` voxels of 1 × 1 × 1 at level 0; `omero`: one white channel,
/// window 10–200 of 0–255.
pub fn v2_store(dir: &Path, name: &str) -> PathBuf {
    let root = dir.join(format!("{name}.ome.zarr"));
    write(&root, ".zgroup", r#"{"zarr_format": 2}"#);
    write(
        &root,
        ".zattrs",
        r#"{"multiscales": [{"version": "0.4", "axes": [
            {"name": "c", "type": "channel"}, {"name": "z", "type": "space"},
            {"name": "y", "type": "space"}, {"name": "x", "type": "space"}],
          "datasets": [{"path": "0", "coordinateTransformations": [{"type": "scale", "scale": [1, 1, 1, 1]}]}]}],
        "omero": {"channels": [{"label": "gray", "color": "FFFFFF",
            "window": {"min": 0, "max": 255, "start": 10, "end": 200}}]}}"#,
    );
    write(
        &root,
        "0/.zarray",
        r#"{"zarr_format": 2, "shape": [1, 4, 6, 8], "chunks": [1, 4, 6, 8], "dtype": "|u1",
        "compressor": null, "fill_value": 0, "order": "C", "filters": null,
        "dimension_separator": "/"}"#,
    );
    root
}

/// A built web viewer folder at `dir/web`: [`INDEX_HTML`], `main.js`, `style.css`, the
/// dummy `residency_viewer_bg.wasm` ([`WASM`]) and a hidden file.
pub fn viewer_dir(dir: &Path) -> PathBuf {
    let web = dir.join("web");
    write(&web, "index.html", INDEX_HTML);
    write(
        &web,
        "main.js",
        "import init from './residency_viewer.js';\n",
    );
    write(&web, "style.css", "body { margin: 0; }\n");
    write(&web, "residency_viewer_bg.wasm", WASM);
    write(&web, ".hidden", "not for serving");
    web
}

/// The router serving `stores` (NAME, path) under `options`.
pub async fn server(stores: &[(&str, &Path)], options: &ServerOptions) -> Router {
    let named: Vec<String> = stores
        .iter()
        .map(|(n, p)| format!("{n}={}", p.display()))
        .collect();
    let datasets = Datasets::from_args(&[], &named, &ObjectStoreOptions::default())
        .await
        .expect("test datasets");
    let state = Arc::new(AppState::new(datasets, options).expect("state"));
    router(state, options)
}

/// An answer: status, headers and body.
#[derive(Debug)]
pub struct Answer {
    /// The status.
    pub status: StatusCode,
    /// The headers.
    pub headers: HeaderMap,
    /// The body.
    pub body: Vec<u8>,
}

impl Answer {
    /// Header `name` as text (`""` when absent).
    pub fn header(&self, name: &str) -> &str {
        self.headers
            .get(name)
            .map_or("", |v| v.to_str().expect("text header"))
    }

    /// The body as text.
    pub fn text(&self) -> String {
        String::from_utf8(self.body.clone()).expect("utf-8 body")
    }

    /// The body as JSON.
    pub fn json<T: serde::de::DeserializeOwned>(&self) -> T {
        serde_json::from_slice(&self.body)
            .unwrap_or_else(|e| panic!("{e}: {}", String::from_utf8_lossy(&self.body)))
    }
}

/// Sends `method path` with `headers` to `router`.
pub async fn request(
    router: &Router,
    method: &str,
    path: &str,
    headers: &[(&str, &str)],
) -> Answer {
    let mut builder = Request::builder().method(method).uri(path);
    for (name, value) in headers {
        builder = builder.header(*name, *value);
    }
    let response = router
        .clone()
        .oneshot(builder.body(Body::empty()).unwrap())
        .await
        .expect("the router answers");
    let (parts, body) = response.into_parts();
    let body = axum::body::to_bytes(body, usize::MAX)
        .await
        .expect("a body");
    Answer {
        status: parts.status,
        headers: parts.headers,
        body: body.to_vec(),
    }
}

/// `GET path` with `headers`.
pub async fn get(router: &Router, path: &str, headers: &[(&str, &str)]) -> Answer {
    request(router, "GET", path, headers).await
}

/// The `Accept` header a browser sends for a page.
pub const BROWSER_ACCEPT: &str =
    "text/html,application/xhtml+xml,application/xml;q=0.9,image/avif,image/webp,*/*;q=0.8";
