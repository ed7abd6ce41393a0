//! The hand-written JSON Schemas in `schemas/json/` of the server's and the store's documents
//! (also the component schemas of the server's OpenAPI document, which embeds them) cannot
//! drift from the Rust types that write the documents: each schema is compared with the one
//! `schemars` derives from its type, as the type serializes (`residency_schemas::drift` says
//! what is compared). The viewer's documents are checked the same way in its own tests.

use residency_schemas::RegionMetadata;
use residency_schemas::drift::{Node, derived, drift, drift_of_files, hand_written};
use residency_schemas::server::{ApiError, DatasetList, RegionAnswer};
use residency_schemas::wire::{BrickBatchHeader, MinMaxHierarchyHeader};
use serde_json::{Value, json};

/// Every hand-written schema of a Rust type, with the schema derived from that type.
fn pairs() -> Vec<(&'static str, Value)> {
    vec![
        ("datasets.schema.json", derived::<DatasetList>()),
        ("region-answer.schema.json", derived::<RegionAnswer>()),
        ("api-error.schema.json", derived::<ApiError>()),
        (
            "minmax-hierarchy.schema.json",
            derived::<MinMaxHierarchyHeader>(),
        ),
        ("brick-batch.schema.json", derived::<BrickBatchHeader>()),
        ("region-metadata.schema.json", derived::<RegionMetadata>()),
    ]
}

#[test]
fn hand_written_schemas_match_the_rust_types() {
    let failures = drift_of_files(&pairs());
    assert!(
        failures.is_empty(),
        "the JSON Schemas drifted from the Rust types (fix the file or the type):\n{}",
        failures.join("\n")
    );
}

/// The check is not vacuous: every kind of drift in a hand-written schema is reported.
#[test]
fn drift_is_reported() {
    let rust = derived::<BrickBatchHeader>();
    let file = hand_written("brick-batch.schema.json");
    assert_eq!(drift(&file, &rust), Vec::<String>::new());

    let mut renamed = file.clone();
    let entry = renamed["properties"]["bricks"]["items"]
        .as_object_mut()
        .unwrap();
    let props = entry["properties"].as_object_mut().unwrap();
    let offset = props.remove("offset").unwrap();
    props.insert("start".into(), offset);
    entry["required"] = json!(["level", "channel", "brick", "status", "start", "length"]);
    assert_eq!(
        drift(&renamed, &rust),
        [
            "#/bricks/[]: property 'start' is in the file, not in the Rust type",
            "#/bricks/[]: property 'offset' is in the Rust type, not in the file",
            "#/bricks/[]: the file requires {\"brick\", \"channel\", \"length\", \"level\", \
             \"start\", \"status\"}, Rust always writes {\"brick\", \"channel\", \"length\", \
             \"level\", \"offset\", \"status\"}",
        ]
    );

    let mut optional = file.clone();
    optional["required"] = json!(["encoding", "data_type", "bricks"]);
    assert_eq!(
        drift(&optional, &rust),
        [
            "#: the file requires {\"bricks\", \"data_type\", \"encoding\"}, Rust always writes \
             {\"brick_shape\", \"bricks\", \"data_type\", \"encoding\"}"
        ]
    );

    let mut retyped = file.clone();
    retyped["properties"]["bricks"]["items"]["properties"]["level"] = json!({"type": "string"});
    retyped["properties"]["brick_shape"]["maxItems"] = json!(4);
    retyped["properties"]["brick_shape"]["minItems"] = json!(4);
    assert_eq!(
        drift(&retyped, &rust),
        [
            "#/brick_shape: the file's array length is Some(4), Rust's Some(3)",
            "#/bricks/[]/level: the file admits types {\"string\"}, Rust writes {\"integer\"}",
        ]
    );

    let mut fewer = file.clone();
    fewer["properties"]["data_type"]["enum"] = json!(["uint8", "uint16"]);
    fewer["properties"]["encoding"]["enum"] = json!(["stored", "raw", "zstd"]);
    let found = drift(&fewer, &rust);
    assert_eq!(found.len(), 2, "{found:#?}");
    assert!(found[0].starts_with(
        "#/data_type: the file lists {\"uint16\", \"uint8\"}, the Rust enum writes {"
    ));
    assert!(found[1].starts_with("#/encoding: the file lists {\"raw\", \"stored\", \"zstd\"}"));
}

/// What the custom serde of the statistics really writes: numbers or the strings of
/// non-finite values, `null` for "no value", and `null` for infinite histogram edges.
#[test]
fn custom_serde_fields_are_described_as_written() {
    let rust = derived::<RegionAnswer>();
    let root = Node::document(&rust);
    let (props, required) = root.object().unwrap();
    assert!(required.contains("min") && required.contains("max"));
    assert_eq!(
        props["min"].types(),
        ["null", "number", "string"].map(String::from).into()
    );
    assert_eq!(
        props["min"].strings(),
        Some(["-Infinity", "Infinity", "NaN"].map(String::from).into())
    );
    let (histogram, _) = props["histogram"].object().unwrap();
    let (edges, _) = histogram["edges"].array().unwrap();
    assert_eq!(
        edges.unwrap().types(),
        ["null", "number"].map(String::from).into()
    );
}
