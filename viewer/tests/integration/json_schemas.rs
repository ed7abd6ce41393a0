//! The viewer's JSON Schemas in `schemas/json/` are generated from the Rust types that write
//! (or, for VDI requests, read) the documents (`residency_schemas::generate`): the committed
//! files must equal the generated text byte for byte. After a type change, regenerate them with
//! `RESIDENCY_UPDATE_SCHEMAS=1 cargo test -p residency-viewer --test integration json_schemas`.

use residency_schemas::generate::{SchemaFile, required, snapshot};
use residency_viewer::bench::BenchResults;
use residency_viewer::bench::vdi::VdiBenchResults;
use residency_viewer::gpu::streaming::RenderStats;
use residency_viewer::metrics::Metrics;
use residency_viewer::service::{ServiceInfo, VdiRequest};
use serde_json::{Value, json};

/// The command regenerating the viewer's schema files.
const REGENERATE: &str =
    "RESIDENCY_UPDATE_SCHEMAS=1 cargo test -p residency-viewer --test integration json_schemas";

/// Every viewer document's schema file (scene files are `residency-schemas`'). `viewer
/// serve`'s VDI requests are documents the viewer reads; the others it writes (`viewer serve`'s
/// `GET /info` answers the service info).
fn documents() -> Vec<SchemaFile> {
    vec![
        SchemaFile::read::<VdiRequest>("vdi-request.schema.json"),
        SchemaFile::written::<ServiceInfo>("vdi-service-info.schema.json"),
        SchemaFile::written::<RenderStats>("render-stats.schema.json"),
        SchemaFile::written::<Metrics>("compare.schema.json"),
        SchemaFile::written::<BenchResults>("render-bench.schema.json"),
        SchemaFile::written::<VdiBenchResults>("vdi-bench.schema.json"),
    ]
}

#[test]
fn viewer_schema_files_are_generated_from_the_rust_types() {
    snapshot(&documents(), REGENERATE);
}

/// A VDI request needs only its size: the view defaults to the service's scene.
#[test]
fn vdi_request_schema_requires_only_the_size() {
    let read: Value =
        serde_json::from_str(&SchemaFile::read::<VdiRequest>("vdi-request.schema.json").text)
            .unwrap();
    assert_eq!(required(&read), ["height", "width"]);
    assert_eq!(read["additionalProperties"], json!(false));
}
