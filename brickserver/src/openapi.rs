//! The OpenAPI 3.1 document served at `/openapi.json`. Its component schemas are the JSON
//! Schemas in `schemas/json/`, embedded at build time, so the two cannot drift apart; those
//! are checked against the schemas `schemars` derives from the Rust types
//! (`schemas/tests/json_schemas.rs`), and the query parameters of its paths against what the
//! handlers read (the tests of [`crate::routes`]).

use serde_json::{Value, json};

/// An embedded JSON Schema as the component `name`: its local references (`#/$defs/...`)
/// re-rooted under `#/components/schemas/NAME/`, and its `$id` dropped, so OpenAPI tools that
/// resolve every reference against the document root find them.
fn schema(name: &str, text: &str) -> Value {
    fn reroot(v: &mut Value, prefix: &str) {
        match v {
            Value::Object(map) => {
                map.remove("$id");
                for (k, child) in map.iter_mut() {
                    match child {
                        Value::String(r) if k == "$ref" && r.starts_with("#/") => {
                            *r = format!("{prefix}{}", &r[1..]);
                        }
                        _ => reroot(child, prefix),
                    }
                }
            }
            Value::Array(items) => items.iter_mut().for_each(|i| reroot(i, prefix)),
            _ => {}
        }
    }
    let mut value: Value =
        serde_json::from_str(text).expect("the embedded JSON Schemas are valid JSON");
    reroot(&mut value, &format!("#/components/schemas/{name}"));
    value
}

fn error_responses(codes: &[(&str, &str)]) -> Value {
    let mut out = serde_json::Map::new();
    for (code, why) in codes {
        out.insert(
            (*code).into(),
            json!({
                "description": why,
                "content": {"application/json": {"schema": {"$ref": "#/components/schemas/ApiError"}}}
            }),
        );
    }
    Value::Object(out)
}

fn with(mut base: Value, extra: Value) -> Value {
    if let (Some(b), Value::Object(e)) = (base.as_object_mut(), extra) {
        b.extend(e);
    }
    base
}

/// The OpenAPI document.
pub fn document() -> Value {
    let name = json!({"name": "name", "in": "path", "required": true, "schema": {"type": "string"}, "description": "Dataset name."});
    let datasets = json!({
        "get": {
            "summary": "List the served datasets, with links that open each in the Residency web viewer, neuroglancer and vizarr",
            "description": "Links are built on --public-url when given, else on the request's X-Forwarded-Proto and X-Forwarded-Host (first values), else http:// and its Host. The neuroglancer link names the store's Zarr version (zarr:// for v2, zarr3:// for v3) and carries each channel's omero window and colour.",
            "responses": {"200": {"description": "The datasets", "content": {"application/json": {"schema": {"$ref": "#/components/schemas/DatasetList"}}}}}
        }
    });
    let text = |description: &str| json!({"description": description, "content": {"text/plain": {"schema": {"type": "string"}}}});
    let page = |description: &str| json!({"description": description, "content": {"text/html": {"schema": {"type": "string"}}}});
    let not_built = text(
        "The web viewer is not built: the message names the folder looked at and says how to build it (scripts/build-web.sh, or --viewer-dir)",
    );
    json!({
        "openapi": "3.1.0",
        "info": {
            "title": "Residency brickserver",
            "version": env!("CARGO_PKG_VERSION"),
            "description": "Serves OME-Zarr stores verbatim at their Zarr keys (for any viewer), plus region metadata queries, the binary min/max hierarchy and batched bricks (for renderers), and the Residency web viewer. Read-only: GET, HEAD and OPTIONS only. With --token-file, every path but /healthz needs `Authorization: Bearer <token>`."
        },
        "paths": {
            "/": {
                "get": {
                    "summary": "The datasets: for a browser (an Accept that prefers text/html) an HTML page with each dataset's size, levels, channels and links (the Residency viewer's relative, NAME/view); otherwise the JSON of /datasets",
                    "responses": {"200": {"description": "The datasets (the answer varies with Accept)", "content": {
                        "application/json": {"schema": {"$ref": "#/components/schemas/DatasetList"}},
                        "text/html": {"schema": {"type": "string"}}
                    }}}
                }
            },
            "/{name}/view": {"get": {
                "summary": "The Residency web viewer (WebAssembly + WebGPU) on dataset NAME",
                "description": "The viewer's index.html, its %VIEWER_BASE% placeholders replaced with ../viewer/ (relative, so it works behind a path prefix). Wins over the Zarr key route: a store's root key 'view' is not served.",
                "parameters": [name.clone()],
                "responses": {
                    "200": page("The viewer page"),
                    "404": page("No such dataset: the same page, which says so"),
                    "503": not_built.clone()
                }
            }},
            "/viewer": {"get": {
                "summary": "Redirects to viewer/ (relative, so a path prefix survives)",
                "responses": {"308": {"description": "Location: viewer/"}}
            }},
            "/viewer/": {"get": {
                "summary": "The Residency web viewer page, its %VIEWER_BASE% placeholders replaced with ./ (the page takes ?server=URL&dataset=NAME)",
                "responses": {
                    "200": page("The viewer page"),
                    "503": not_built.clone()
                }
            }},
            "/viewer/{file}": {"get": {
                "summary": "A file of the web viewer: .wasm as application/wasm, .js as text/javascript, .html, .css; Last-Modified with If-Modified-Since, Range",
                "parameters": [{"name": "file", "in": "path", "required": true, "schema": {"type": "string"}, "description": "Path of the file in the viewer's folder ('/'-separated); index.html is the page as at /viewer/."}],
                "responses": {
                    "200": {"description": "The file", "content": {
                        "application/wasm": {"schema": {"type": "string", "contentMediaType": "application/wasm"}},
                        "text/javascript": {"schema": {"type": "string"}},
                        "text/html": {"schema": {"type": "string"}},
                        "text/css": {"schema": {"type": "string"}}
                    }},
                    "206": {"description": "A byte range of the file"},
                    "304": {"description": "Not modified (If-Modified-Since)"},
                    "404": text("No such file (hidden files and paths leaving the folder included)"),
                    "503": not_built
                }
            }},
            "/datasets": datasets,
            "/healthz": {"get": {"summary": "Liveness", "security": [], "responses": {"200": {"description": "ok", "content": {"text/plain": {"schema": {"type": "string"}}}}}}},
            "/metrics": {"get": {"summary": "Prometheus metrics: requests by status class, bytes, latency histogram, cache hits/misses/bytes, connections", "responses": {"200": {"description": "OpenMetrics text", "content": {"application/openmetrics-text": {"schema": {"type": "string"}}}}}}},
            "/openapi.json": {"get": {"summary": "This document", "responses": {"200": {"description": "OpenAPI 3.1", "content": {"application/json": {"schema": {"type": "object"}}}}}}},
            "/{name}/regions": {"get": {
                "summary": "Value range and histogram of a box of voxels, from the stored region metadata",
                "description": "Never narrower than the truth; exact for a box aligned to the stored cells (min/max, 8 voxels at the finest grid) and bricks (histogram), or ending at the level's edge. The answer states the boxes it covers.",
                "parameters": [
                    name.clone(),
                    {"name": "level", "in": "query", "required": true, "schema": {"type": "integer", "minimum": 0}},
                    {"name": "channel", "in": "query", "required": true, "schema": {"type": "integer", "minimum": 0}},
                    {"name": "min", "in": "query", "required": true, "schema": {"type": "string", "pattern": "^[0-9]+,[0-9]+,[0-9]+$"}, "description": "First voxel x,y,z of the level."},
                    {"name": "max", "in": "query", "required": true, "schema": {"type": "string", "pattern": "^[0-9]+,[0-9]+,[0-9]+$"}, "description": "One past the last voxel x,y,z (exclusive)."}
                ],
                "responses": with(
                    json!({"200": {"description": "The answer", "content": {"application/json": {"schema": {"$ref": "#/components/schemas/RegionAnswer"}}}}}),
                    error_responses(&[("400", "Malformed query, level or channel out of range, or box outside the level"), ("404", "No such dataset, or no region metadata"), ("500", "Region metadata unreadable")])
                )
            }},
            "/{name}/minmax": {"get": {
                "summary": "The whole conservative min/max hierarchy of one channel, every level and grid, in one framed binary document",
                "description": "Framing: 8 bytes 'RSMINMAX', little-endian u32 header length, JSON header (schema MinMaxHierarchyHeader), payload.",
                "parameters": [name.clone(), {"name": "channel", "in": "query", "required": true, "schema": {"type": "integer", "minimum": 0}}],
                "responses": with(
                    json!({"200": {"description": "The document", "content": {"application/x-residency-minmax": {"schema": {"type": "string", "contentMediaType": "application/x-residency-minmax"}}}}}),
                    error_responses(&[("400", "Malformed query or channel out of range"), ("404", "No such dataset, or no region metadata"), ("500", "Region metadata unreadable")])
                )
            }},
            "/{name}/bricks": {"get": {
                "summary": "Many bricks in one framed binary document",
                "description": "Framing: 8 bytes 'RSBRICKS', little-endian u32 header length, JSON header (schema BrickBatchHeader), payload. An unreadable or corrupt brick is an `error` entry naming its key; the other bricks are still answered.",
                "parameters": [
                    name.clone(),
                    {"name": "b", "in": "query", "required": true, "schema": {"type": "string"}, "description": "Bricks as L,C,z,y,x separated by ';' (level, channel, brick coordinates)."},
                    {"name": "encoding", "in": "query", "required": false, "schema": {"enum": ["stored", "raw"], "default": "stored"}}
                ],
                "responses": with(
                    json!({"200": {"description": "The batch", "content": {"application/x-residency-bricks": {"schema": {"type": "string", "contentMediaType": "application/x-residency-bricks"}}}}}),
                    error_responses(&[("400", "Malformed request"), ("404", "No such dataset"), ("413", "Too many bricks, or too many decoded bytes, in one batch"), ("500", "Image arrays unreadable")])
                )
            }},
            "/{name}/{key}": {"get": {
                "summary": "A Zarr key of the store, verbatim",
                "description": "zarr.json, .zattrs, .zarray, chunk and shard keys, residency/ arrays. ETag with If-None-Match (304), single Range (206/416), Cache-Control immutable for chunks and no-cache for metadata, CORS. A missing chunk is a 404 (the fill value to Zarr readers).",
                "parameters": [name, {"name": "key", "in": "path", "required": true, "schema": {"type": "string"}, "description": "The Zarr key, '/'-separated."}],
                "responses": {
                    "200": {"description": "The stored bytes", "content": {"application/json": {"schema": {"type": "object"}}, "application/octet-stream": {"schema": {"type": "string", "contentMediaType": "application/octet-stream"}}}},
                    "206": {"description": "A byte range of the stored bytes"},
                    "304": {"description": "Not modified (If-None-Match matched the ETag)"},
                    "400": {"description": "Refused key: '..', backslash, absolute path, NUL byte, empty segment, or a symlink leading out of the dataset"},
                    "404": {"description": "No such key (a missing chunk reads as the fill value)"},
                    "416": {"description": "Range outside the file"},
                    "500": {"description": "The key exists but cannot be read; the message names it"}
                }
            }}
        },
        "components": {
            "schemas": {
                "DatasetList": schema("DatasetList", include_str!("../../schemas/json/datasets.schema.json")),
                "RegionAnswer": schema("RegionAnswer", include_str!("../../schemas/json/region-answer.schema.json")),
                "ApiError": schema("ApiError", include_str!("../../schemas/json/api-error.schema.json")),
                "MinMaxHierarchyHeader": schema("MinMaxHierarchyHeader", include_str!("../../schemas/json/minmax-hierarchy.schema.json")),
                "BrickBatchHeader": schema("BrickBatchHeader", include_str!("../../schemas/json/brick-batch.schema.json")),
                "RegionMetadata": schema("RegionMetadata", include_str!("../../schemas/json/region-metadata.schema.json"))
            },
            "securitySchemes": {"bearer": {"type": "http", "scheme": "bearer", "description": "Only when the server runs with --token-file."}}
        }
    })
}
