//! The JSON Schemas in `schemas/json/` of the server's and the store's documents (also the
//! component schemas of the server's OpenAPI document, which embeds them) and of scene files
//! are generated from the Rust types that write (or, for scenes, read) the documents
//! (`residency_schemas::generate`): the committed files must equal the generated text byte
//! for byte. After a type change, regenerate them
//! with `RESIDENCY_UPDATE_SCHEMAS=1 cargo test -p residency-schemas --test json_schemas`. The
//! viewer's documents are checked the same way in its own tests.

use residency_schemas::generate::{
    REGENERATE, SchemaFile, SnapshotError, documents, required, snapshot, stale, write,
};
use residency_schemas::scene::Scene;
use residency_schemas::server::RegionAnswer;
use residency_schemas::wire::BrickBatchHeader;
use serde_json::{Value, json};

#[test]
fn schema_files_are_generated_from_the_rust_types() {
    snapshot(&documents(), REGENERATE);
}

/// The check is not vacuous: a file whose text differs from the generated one in any way,
/// or that is missing, is reported by name with the command that regenerates it.
#[test]
fn a_stale_schema_file_is_reported() {
    let dir = tempfile::tempdir().unwrap();
    let files = documents();
    write(dir.path(), &files).unwrap();
    assert!(stale(dir.path(), &files, REGENERATE).is_empty());

    let path = dir.path().join("brick-batch.schema.json");
    let text = std::fs::read_to_string(&path).unwrap();
    let renamed = text.replace("\"offset\"", "\"start\"");
    assert_ne!(renamed, text);
    std::fs::write(&path, renamed).unwrap();
    let found = stale(dir.path(), &files, REGENERATE);
    assert_eq!(found.len(), 1, "{found:#?}");
    assert!(matches!(&found[0], SnapshotError::Stale { path: p, .. } if *p == path));
    assert_eq!(
        found[0].to_string(),
        format!(
            "{} is stale: it differs from the schema generated from its Rust type; regenerate \
             it with `RESIDENCY_UPDATE_SCHEMAS=1 cargo test -p residency-schemas --test \
             json_schemas`",
            path.display()
        )
    );

    // A change of layout alone (the trailing newline) is a change too.
    std::fs::write(&path, text.trim_end()).unwrap();
    assert_eq!(stale(dir.path(), &files, REGENERATE).len(), 1);

    std::fs::remove_file(&path).unwrap();
    let found = stale(dir.path(), &files, REGENERATE);
    assert_eq!(found.len(), 1, "{found:#?}");
    let message = found[0].to_string();
    assert!(
        message.starts_with(&format!(
            "{} cannot be read; generate it with `",
            path.display()
        )),
        "{message}"
    );
    assert!(std::error::Error::source(&found[0]).is_some());

    write(dir.path(), &files).unwrap();
    assert!(stale(dir.path(), &files, REGENERATE).is_empty());
}

fn generated<T: schemars::JsonSchema>(name: &'static str) -> Value {
    serde_json::from_str(&SchemaFile::written::<T>(name).text).unwrap()
}

/// The generated text is stable: keys sorted, two-space indents, one trailing newline, and
/// the `$id` and the draft named.
#[test]
fn schema_text_is_canonical() {
    for file in documents() {
        let value: Value = serde_json::from_str(&file.text).unwrap();
        let mut again = serde_json::to_string_pretty(&value).unwrap();
        again.push('\n');
        assert_eq!(again, file.text, "{}", file.name);
        assert_eq!(
            value["$id"],
            json!(format!("https://residency.invalid/schemas/{}", file.name))
        );
        assert_eq!(
            value["$schema"],
            json!("https://json-schema.org/draft/2020-12/schema")
        );
        assert!(value["title"].is_string(), "{} has a title", file.name);
        assert_eq!(value["additionalProperties"], json!(false), "{}", file.name);
    }
}

/// The strings an enumeration admits, one `const` per variant.
fn listed(schema: &Value) -> Vec<&str> {
    schema["oneOf"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v["const"].as_str().unwrap())
        .collect()
}

/// Fields are required exactly when serde always writes them (an `Option` skipped when
/// `None` is not), fixed arrays have their length, and enums list what Rust writes.
#[test]
fn schemas_describe_what_is_written() {
    let batch = generated::<BrickBatchHeader>("brick-batch.schema.json");
    assert_eq!(
        required(&batch),
        ["brick_shape", "bricks", "data_type", "encoding"]
    );
    let entry = &batch["properties"]["bricks"]["items"];
    assert_eq!(
        required(entry),
        ["brick", "channel", "length", "level", "offset", "status"]
    );
    assert_eq!(entry["properties"]["error"]["type"], json!("string"));
    let shape = &batch["properties"]["brick_shape"];
    assert_eq!(
        (&shape["minItems"], &shape["maxItems"]),
        (&json!(3), &json!(3))
    );
    assert_eq!(shape["items"]["minimum"], json!(1));
    assert_eq!(listed(&batch["properties"]["encoding"]), ["stored", "raw"]);
    assert_eq!(
        listed(&entry["properties"]["status"]),
        ["ok", "empty", "error"]
    );
    assert_eq!(
        listed(&batch["properties"]["data_type"]),
        ["uint8", "uint16", "int16", "uint32", "int32", "float32"]
    );
}

/// What the custom serde of the statistics really writes: numbers or the strings of
/// non-finite values, `null` for "no value", and `null` for infinite histogram edges.
#[test]
fn custom_serde_fields_are_described_as_written() {
    let answer = generated::<RegionAnswer>("region-answer.schema.json");
    let names = required(&answer);
    assert!(
        names.contains(&"min") && names.contains(&"max"),
        "{names:?}"
    );
    assert_eq!(
        answer["properties"]["min"]["oneOf"],
        json!([
            {"type": "number"},
            {"type": "string", "enum": ["Infinity", "-Infinity", "NaN"]},
            {"type": "null"}
        ])
    );
    let edges = &answer["properties"]["histogram"]["properties"]["edges"];
    assert_eq!(edges["items"]["type"], json!(["number", "null"]));
}

/// Scenes are described as the viewer reads them: what the schema requires is exactly what
/// serde cannot default, where the schema of the scene as written would require every field.
#[test]
fn scene_schema_is_generated_as_read() {
    let read: Value =
        serde_json::from_str(&SchemaFile::read::<Scene>("scene.schema.json").text).unwrap();
    assert_eq!(required(&read), ["camera", "channels"]);
    assert_eq!(required(&read["properties"]["camera"]), ["eye", "target"]);
    assert_eq!(
        required(&read["properties"]["channels"]["items"]),
        ["channel", "color", "opacity"]
    );
    assert_eq!(read["additionalProperties"], json!(false));

    let written: Value =
        serde_json::from_str(&SchemaFile::written::<Scene>("scene.schema.json").text).unwrap();
    assert_eq!(
        required(&written["properties"]["camera"]),
        ["eye", "fov_y_degrees", "target", "up"]
    );
}
