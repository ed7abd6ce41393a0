//! The OpenAPI document names the viewer routes and the listing's two forms, with the status
//! codes and media types the server really answers.

use residency_brickserver::ServerOptions;
use serde_json::Value;

use crate::common::{Answer, BROWSER_ACCEPT, get, server, v3_store, viewer_dir};

/// Asserts that the document gives `path` a `status` answer of `answer`'s media type.
fn documented(doc: &Value, path: &str, answer: &Answer) {
    let status = answer.status.as_u16().to_string();
    let spec = &doc["paths"][path]["get"]["responses"][&status];
    assert!(spec.is_object(), "{path}: {status} is not documented");
    let media = answer
        .header("content-type")
        .split(';')
        .next()
        .unwrap()
        .trim();
    if !media.is_empty() && spec.get("content").is_some() {
        assert!(
            spec["content"][media].is_object(),
            "{path}: {status} as {media} is not documented: {spec}"
        );
    }
}

#[tokio::test]
async fn the_viewer_routes_and_listing_are_documented_as_answered() {
    let dir = tempfile::tempdir().unwrap();
    let store = v3_store(dir.path(), "cells");
    let doc = residency_brickserver::openapi_document();
    for path in [
        "/",
        "/datasets",
        "/{name}/view",
        "/viewer/",
        "/viewer/{file}",
    ] {
        assert!(doc["paths"][path]["get"].is_object(), "{path}");
    }
    let options = ServerOptions {
        viewer_dir: Some(viewer_dir(dir.path())),
        ..ServerOptions::default()
    };
    let router = server(&[("cells", &store)], &options).await;
    let cases = [
        ("/", "/", vec![]),
        ("/", "/", vec![("accept", BROWSER_ACCEPT)]),
        ("/datasets", "/datasets", vec![("accept", BROWSER_ACCEPT)]),
        ("/{name}/view", "/cells/view", vec![]),
        ("/{name}/view", "/nope/view", vec![]),
        ("/viewer/", "/viewer/", vec![]),
        ("/viewer/{file}", "/viewer/residency_viewer_bg.wasm", vec![]),
        ("/viewer/{file}", "/viewer/main.js", vec![]),
        ("/viewer/{file}", "/viewer/style.css", vec![]),
        ("/viewer/{file}", "/viewer/index.html", vec![]),
        ("/viewer/{file}", "/viewer/missing.js", vec![]),
    ];
    for (documented_path, path, headers) in &cases {
        let answer = get(&router, path, headers).await;
        documented(&doc, documented_path, &answer);
    }
    let router = server(&[("cells", &store)], &ServerOptions::default()).await;
    for (documented_path, path) in [
        ("/{name}/view", "/cells/view"),
        ("/viewer/", "/viewer/"),
        ("/viewer/{file}", "/viewer/main.js"),
    ] {
        let answer = get(&router, path, &[]).await;
        assert_eq!(answer.status, 503);
        documented(&doc, documented_path, &answer);
    }
    // The listing's JSON schema names the new `view` link.
    let item = &doc["components"]["schemas"]["DatasetList"]["properties"]["datasets"]["items"];
    assert!(item["properties"]["view"].is_object());
    assert!(
        item["required"]
            .as_array()
            .unwrap()
            .contains(&Value::from("view"))
    );
}
