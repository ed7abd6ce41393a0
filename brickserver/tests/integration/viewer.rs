//! The web viewer's routes: `/NAME/view` (the page, its `%VIEWER_BASE%` substituted), the
//! files under `/viewer/`, the 503 without a built viewer, and that store keys are still
//! served beside them.

use std::path::Path;

use residency_brickserver::ServerOptions;

use crate::common::{
    CHUNK, WASM, get, page_with, request, server, v2_store, v3_store, viewer_dir, write,
};

/// A router for the v3 store `cells` with the test viewer folder, and the folder.
async fn with_viewer(dir: &Path) -> (axum::Router, std::path::PathBuf) {
    let store = v3_store(dir, "cells");
    let web = viewer_dir(dir);
    let options = ServerOptions {
        viewer_dir: Some(web.clone()),
        ..ServerOptions::default()
    };
    (server(&[("cells", &store)], &options).await, web)
}

#[tokio::test]
async fn the_page_of_a_dataset_finds_its_files_relative_to_itself() {
    let dir = tempfile::tempdir().unwrap();
    let (router, _) = with_viewer(dir.path()).await;
    let r = get(&router, "/cells/view", &[]).await;
    assert_eq!(r.status, 200);
    assert_eq!(r.header("content-type"), "text/html; charset=utf-8");
    assert_eq!(r.header("cache-control"), "no-cache");
    assert_eq!(r.text(), page_with("../viewer/"));
    // A query (the page's own ?width=&height=) changes nothing.
    let r = get(&router, "/cells/view?width=256&height=256", &[]).await;
    assert_eq!(
        (r.status.as_u16(), r.text()),
        (200, page_with("../viewer/"))
    );
    // HEAD: the same headers, no body.
    let r = request(&router, "HEAD", "/cells/view", &[]).await;
    assert_eq!(r.status, 200);
    assert_eq!(r.header("content-type"), "text/html; charset=utf-8");
    assert!(r.body.is_empty());
}

#[tokio::test]
async fn an_unknown_dataset_gets_the_page_with_404() {
    let dir = tempfile::tempdir().unwrap();
    let (router, _) = with_viewer(dir.path()).await;
    let r = get(&router, "/nope/view", &[]).await;
    assert_eq!(r.status, 404);
    assert_eq!(r.header("content-type"), "text/html; charset=utf-8");
    assert_eq!(r.text(), page_with("../viewer/"));
}

#[tokio::test]
async fn the_viewer_folder_page_is_relative_to_itself() {
    let dir = tempfile::tempdir().unwrap();
    let (router, _) = with_viewer(dir.path()).await;
    for path in [
        "/viewer/",
        "/viewer/index.html",
        "/viewer/?server=http://x&dataset=cells",
    ] {
        let r = get(&router, path, &[]).await;
        assert_eq!(r.status, 200, "{path}");
        assert_eq!(
            r.header("content-type"),
            "text/html; charset=utf-8",
            "{path}"
        );
        assert_eq!(r.text(), page_with("./"), "{path}");
    }
    // `/viewer` without its slash: redirected, relatively (a path prefix survives).
    let r = get(&router, "/viewer", &[]).await;
    assert_eq!(r.status, 308);
    assert_eq!(r.header("location"), "viewer/");
}

#[tokio::test]
async fn files_are_served_with_their_types_and_revalidated() {
    let dir = tempfile::tempdir().unwrap();
    let (router, web) = with_viewer(dir.path()).await;
    let r = get(&router, "/viewer/residency_viewer_bg.wasm", &[]).await;
    assert_eq!(r.status, 200);
    assert_eq!(r.header("content-type"), "application/wasm");
    assert_eq!(r.body, WASM);
    assert_eq!(r.header("cache-control"), "no-cache");
    assert_eq!(r.header("content-length"), WASM.len().to_string());
    let last_modified = r.header("last-modified").to_string();
    assert!(last_modified.ends_with(" GMT"), "{last_modified}");
    let again = get(
        &router,
        "/viewer/residency_viewer_bg.wasm",
        &[("if-modified-since", &last_modified)],
    )
    .await;
    assert_eq!(again.status, 304);
    assert!(again.body.is_empty());
    for (file, media) in [("main.js", "text/javascript"), ("style.css", "text/css")] {
        let r = get(&router, &format!("/viewer/{file}"), &[]).await;
        assert_eq!(r.status, 200, "{file}");
        assert_eq!(r.header("content-type"), media, "{file}");
        assert_eq!(r.body, std::fs::read(web.join(file)).unwrap(), "{file}");
    }
    // A nested file (wasm-bindgen's snippets/ folder).
    write(&web, "snippets/x/inline0.js", "export const x = 1;\n");
    let r = get(&router, "/viewer/snippets/x/inline0.js", &[]).await;
    assert_eq!(
        (r.status.as_u16(), r.header("content-type")),
        (200, "text/javascript")
    );
    let r = get(&router, "/viewer/main.js", &[("range", "bytes=0-5")]).await;
    assert_eq!((r.status.as_u16(), r.text().as_str()), (206, "import"));
}

#[tokio::test]
async fn missing_hidden_and_escaping_files_are_404() {
    let dir = tempfile::tempdir().unwrap();
    let (router, _) = with_viewer(dir.path()).await;
    write(dir.path(), "secret.txt", "TOP SECRET");
    for path in [
        "/viewer/missing.js",
        "/viewer/.hidden",
        "/viewer/%2ehidden",
        "/viewer/..%2fsecret.txt",
        "/viewer/%2e%2e/secret.txt",
        "/viewer/snippets",
        "/viewer/a/..%5c..%5csecret.txt",
    ] {
        let r = get(&router, path, &[]).await;
        assert_eq!(r.status, 404, "{path}");
        assert_eq!(
            r.header("content-type"),
            "text/plain; charset=utf-8",
            "{path}"
        );
        assert!(!r.text().contains("SECRET") && !r.text().contains("not for serving"));
    }
    assert_eq!(
        get(&router, "/viewer/missing.js", &[]).await.text(),
        "no viewer file '/missing.js'\n"
    );
}

#[tokio::test]
async fn without_a_built_viewer_every_viewer_route_says_how_to_build_it() {
    let dir = tempfile::tempdir().unwrap();
    let store = v3_store(dir.path(), "cells");
    // A folder that does not exist, one without index.html, and none at all.
    let empty = dir.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    write(&empty, "main.js", "// no page beside it\n");
    let missing = dir.path().join("not-built");
    let cases = [
        (
            Some(missing.clone()),
            format!(
                "the web viewer is not built: run scripts/build-web.sh, or pass --viewer-dir \
                 (looked for index.html in {})\n",
                missing.display()
            ),
        ),
        (
            Some(empty.clone()),
            format!(
                "the web viewer is not built: run scripts/build-web.sh, or pass --viewer-dir \
                 (looked for index.html in {})\n",
                empty.display()
            ),
        ),
        (
            None,
            "the web viewer is not built: run scripts/build-web.sh, or pass --viewer-dir \
             (no folder: the running executable's folder is unknown)\n"
                .to_string(),
        ),
    ];
    for (viewer_dir, message) in cases {
        let options = ServerOptions {
            viewer_dir,
            ..ServerOptions::default()
        };
        let router = server(&[("cells", &store)], &options).await;
        for path in [
            "/cells/view",
            "/nope/view",
            "/viewer/",
            "/viewer/index.html",
            "/viewer/main.js",
        ] {
            let r = get(&router, path, &[]).await;
            assert_eq!(r.status, 503, "{path}");
            assert_eq!(
                r.header("content-type"),
                "text/plain; charset=utf-8",
                "{path}"
            );
            assert_eq!(r.text(), message, "{path}");
        }
        // The store itself is still served.
        assert_eq!(get(&router, "/cells/zarr.json", &[]).await.status, 200);
    }
}

#[tokio::test]
async fn store_keys_are_still_served_beside_the_view_route() {
    let dir = tempfile::tempdir().unwrap();
    let (router, _) = with_viewer(dir.path()).await;
    let store = dir.path().join("cells.ome.zarr");
    let r = get(&router, "/cells/zarr.json", &[]).await;
    assert_eq!(r.status, 200);
    assert_eq!(r.header("content-type"), "application/json");
    assert_eq!(r.body, std::fs::read(store.join("zarr.json")).unwrap());
    let r = get(&router, "/cells/0/c/0/0/0/0", &[]).await;
    assert_eq!(r.status, 200);
    assert_eq!(r.header("content-type"), "application/octet-stream");
    assert_eq!(r.body, CHUNK);
    // A Zarr node named `view` (a folder) stays reachable; only the bare key `view` is the
    // page.
    write(
        &store,
        "view/zarr.json",
        "{\"zarr_format\": 3, \"node_type\": \"group\"}",
    );
    let r = get(&router, "/cells/view/zarr.json", &[]).await;
    assert_eq!(r.status, 200);
    assert_eq!(r.body, std::fs::read(store.join("view/zarr.json")).unwrap());
    assert_eq!(
        get(&router, "/cells/view", &[]).await.text(),
        page_with("../viewer/")
    );
    // The other API routes are untouched.
    assert_eq!(
        get(&router, "/cells/bricks?b=0,0,0,0,0&encoding=raw", &[])
            .await
            .status,
        200
    );
}

#[tokio::test]
async fn a_v2_store_is_served_beside_the_viewer_too() {
    let dir = tempfile::tempdir().unwrap();
    let store = v2_store(dir.path(), "old");
    let web = viewer_dir(dir.path());
    let options = ServerOptions {
        viewer_dir: Some(web),
        ..ServerOptions::default()
    };
    let router = server(&[("old", &store)], &options).await;
    assert_eq!(get(&router, "/old/.zattrs", &[]).await.status, 200);
    assert_eq!(get(&router, "/old/view", &[]).await.status, 200);
}
