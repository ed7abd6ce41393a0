//! The viewer's hand-written JSON Schemas cannot drift from the Rust types that write (or, for
//! scenes, read) the documents: each is compared with the schema `schemars` derives from its
//! type (`residency_schemas::drift` says what is compared).

use residency_schemas::drift::{
    Node, derived, derived_for_reading, drift, drift_of_files, hand_written,
};
use residency_viewer::bench::BenchResults;
use residency_viewer::gpu::streaming::RenderStats;
use residency_viewer::metrics::Metrics;
use residency_viewer::scene::Scene;
use serde_json::{Value, json};

/// Every viewer document's schema file, with the schema derived from its type.
fn pairs() -> Vec<(&'static str, Value)> {
    vec![
        ("scene.schema.json", derived_for_reading::<Scene>()),
        ("render-stats.schema.json", derived::<RenderStats>()),
        ("compare.schema.json", derived::<Metrics>()),
        ("render-bench.schema.json", derived::<BenchResults>()),
    ]
}

#[test]
fn viewer_schemas_match_the_rust_types() {
    let failures = drift_of_files(&pairs());
    assert!(
        failures.is_empty(),
        "the viewer's JSON Schemas drifted from its Rust types (fix the file or the type):\n{}",
        failures.join("\n")
    );
}

/// Scenes are documents the viewer reads: what the derived schema requires is exactly what
/// serde cannot default, and a field the file lacks is reported.
#[test]
fn scene_schema_is_checked_as_read() {
    let rust = derived_for_reading::<Scene>();
    let (props, required) = Node::document(&rust).object().unwrap();
    assert_eq!(required, ["camera", "channels"].map(String::from).into());
    let (_, camera_required) = props["camera"].object().unwrap();
    assert_eq!(camera_required, ["eye", "target"].map(String::from).into());

    let mut file = hand_written("scene.schema.json");
    file["properties"]
        .as_object_mut()
        .unwrap()
        .remove("background");
    file["properties"]["camera"]["required"] = json!(["eye", "target", "up"]);
    assert_eq!(
        drift(&file, &rust),
        [
            "#: property 'background' is in the Rust type, not in the file",
            "#/camera: the file requires {\"eye\", \"target\", \"up\"}, Rust always writes \
             {\"eye\", \"target\"}",
        ]
    );
}
