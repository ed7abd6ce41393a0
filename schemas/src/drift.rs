//! Drift checks between a hand-written JSON Schema and the schema `schemars` derives from the
//! Rust type that writes the document (feature `drift`, for tests: this crate's own and the
//! viewer's).
//!
//! Compared, recursively through `$ref`s, `oneOf`/`anyOf`, object properties and array
//! items:
//! - the property names of every object (a field added, removed or renamed in Rust fails);
//! - the `required` list of every object (`Option` fields are required when serde always
//!   writes them, `null` included; fields skipped when empty are not);
//! - the JSON types every value may take (`integer`, `number`, `string`, `null`, ...);
//! - fixed array lengths (`[u64; 3]`);
//! - the strings a Rust enum writes, exactly, and that every string a schema lists is one
//!   Rust can write (a schema may list fewer, as for a minimum that is never `"NaN"`).
//!
//! The hand-written schemas say more (descriptions, `minimum`, `pattern`, `minItems`,
//! `additionalProperties: false`); that is left to them.

use std::collections::{BTreeMap, BTreeSet};

use schemars::JsonSchema;
use schemars::generate::SchemaSettings;
use serde_json::{Value, json};

/// The schema `schemars` derives for `T` as it serializes (draft 2020-12): for documents
/// Rust writes.
#[must_use]
pub fn derived<T: JsonSchema>() -> Value {
    root_schema::<T>(SchemaSettings::draft2020_12().for_serialize())
}

/// The schema `schemars` derives for `T` as it deserializes (fields with a serde default are
/// not required): for documents Rust reads, such as scene files.
#[must_use]
pub fn derived_for_reading<T: JsonSchema>() -> Value {
    root_schema::<T>(SchemaSettings::draft2020_12().for_deserialize())
}

fn root_schema<T: JsonSchema>(settings: SchemaSettings) -> Value {
    settings
        .into_generator()
        .into_root_schema_for::<T>()
        .to_value()
}

/// The hand-written schema `schemas/json/NAME`.
///
/// # Panics
///
/// When the file cannot be read or is not JSON.
#[must_use]
pub fn hand_written(name: &str) -> Value {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("json")
        .join(name);
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Every drift between each named schema file and the schema derived from its Rust type, each
/// line prefixed with the file's name.
#[must_use]
pub fn drift_of_files(pairs: &[(&str, Value)]) -> Vec<String> {
    pairs
        .iter()
        .flat_map(|(file, rust)| {
            drift(&hand_written(file), rust)
                .into_iter()
                .map(move |d| format!("{file} {d}"))
        })
        .collect()
}

/// A schema node inside the document `root` it belongs to (for its `$ref`s).
#[derive(Clone, Copy)]
pub struct Node<'a> {
    /// The node.
    pub value: &'a Value,
    /// The document it belongs to.
    pub root: &'a Value,
}

impl<'a> Node<'a> {
    /// The root node of a schema document.
    #[must_use]
    pub fn document(root: &'a Value) -> Self {
        Self { value: root, root }
    }

    /// The node with its local `$ref`s followed.
    ///
    /// # Panics
    ///
    /// On a non-local, dangling or cyclic `$ref` (a broken schema).
    pub fn resolved(self) -> Self {
        let mut value = self.value;
        for _ in 0..32 {
            match value.get("$ref").and_then(Value::as_str) {
                Some(r) => {
                    let pointer = r
                        .strip_prefix('#')
                        .unwrap_or_else(|| panic!("only local references: {r}"));
                    value = self
                        .root
                        .pointer(pointer)
                        .unwrap_or_else(|| panic!("dangling reference {r}"));
                }
                None => return Self { value, ..self },
            }
        }
        panic!("reference cycle")
    }

    fn child(self, value: &'a Value) -> Self {
        Self { value, ..self }
    }

    /// The alternatives of a `oneOf` / `anyOf` node, each resolved, flattened; the node
    /// itself otherwise.
    pub fn alternatives(self) -> Vec<Self> {
        let node = self.resolved();
        let members = ["oneOf", "anyOf"]
            .iter()
            .find_map(|k| node.value.get(*k).and_then(Value::as_array));
        match members {
            Some(members) => members
                .iter()
                .flat_map(|m| node.child(m).alternatives())
                .collect(),
            None => vec![node],
        }
    }

    /// The JSON types the node admits.
    pub fn types(self) -> BTreeSet<String> {
        let mut out = BTreeSet::new();
        for alt in self.alternatives() {
            let v = alt.value;
            match v.get("type") {
                Some(Value::String(t)) => {
                    out.insert(t.clone());
                }
                Some(Value::Array(ts)) => {
                    out.extend(ts.iter().filter_map(Value::as_str).map(str::to_string));
                }
                _ => {
                    let listed = v
                        .get("enum")
                        .and_then(Value::as_array)
                        .cloned()
                        .or_else(|| v.get("const").map(|c| vec![c.clone()]));
                    match listed {
                        Some(values) => out.extend(values.iter().map(json_type)),
                        None => {
                            out.insert("any".into());
                        }
                    }
                }
            }
        }
        out
    }

    /// The strings the node admits when it lists them all (`enum` or `const` for every
    /// alternative admitting strings); `None` when it admits any string.
    pub fn strings(self) -> Option<BTreeSet<String>> {
        let mut out = BTreeSet::new();
        for alt in self.alternatives() {
            let v = alt.value;
            let listed = v
                .get("enum")
                .and_then(Value::as_array)
                .cloned()
                .or_else(|| v.get("const").map(|c| vec![c.clone()]));
            match listed {
                Some(values) => {
                    out.extend(values.iter().filter_map(Value::as_str).map(String::from));
                }
                None if alt.types().contains("string") || alt.types().contains("any") => {
                    return None;
                }
                None => {}
            }
        }
        Some(out)
    }

    /// Whether the node is a plain enumeration (a Rust enum of unit variants).
    pub fn is_pure_enum(self) -> bool {
        self.alternatives()
            .iter()
            .all(|a| a.value.get("enum").is_some() || a.value.get("const").is_some())
    }

    /// The object alternative's properties and required names, if it has one.
    ///
    /// # Panics
    ///
    /// When `properties` is not an object (a broken schema).
    pub fn object(self) -> Option<(BTreeMap<String, Self>, BTreeSet<String>)> {
        let alt = self
            .alternatives()
            .into_iter()
            .find(|a| a.value.get("properties").is_some())?;
        let properties = alt.value["properties"]
            .as_object()
            .expect("properties is an object")
            .iter()
            .map(|(k, v)| (k.clone(), alt.child(v)))
            .collect();
        let required = alt
            .value
            .get("required")
            .and_then(Value::as_array)
            .map(|r| {
                r.iter()
                    .filter_map(Value::as_str)
                    .map(String::from)
                    .collect()
            })
            .unwrap_or_default();
        Some((properties, required))
    }

    /// The array alternative's items and, for a fixed-length array, its length.
    pub fn array(self) -> Option<(Option<Self>, Option<u64>)> {
        let alt = self.alternatives().into_iter().find(|a| {
            a.value.get("items").is_some() || a.value.get("type") == Some(&json!("array"))
        })?;
        let items = alt.value.get("items").map(|i| alt.child(i));
        let (min, max) = (alt.value.get("minItems"), alt.value.get("maxItems"));
        let fixed = match (min.and_then(Value::as_u64), max.and_then(Value::as_u64)) {
            (Some(a), Some(b)) if a == b => Some(a),
            _ => None,
        };
        Some((items, fixed))
    }
}

fn json_type(v: &Value) -> String {
    match v {
        Value::Null => "null",
        Value::Bool(_) => "boolean",
        Value::Number(n) if n.is_f64() => "number",
        Value::Number(_) => "integer",
        Value::String(_) => "string",
        Value::Array(_) => "array",
        Value::Object(_) => "object",
    }
    .into()
}

/// Which side of a comparison has what the other lacks.
fn side(in_file: bool) -> &'static str {
    if in_file { "the file" } else { "the Rust type" }
}

/// Every way the hand-written node `file` (at `path`) differs from the derived node `rust`.
fn differences(path: &str, file: Node, rust: Node, out: &mut Vec<String>) {
    let (ft, rt) = (file.types(), rust.types());
    if ft != rt {
        out.push(format!(
            "{path}: the file admits types {ft:?}, Rust writes {rt:?}"
        ));
    }
    match (file.strings(), rust.strings()) {
        (Some(fs), Some(rs)) if rust.is_pure_enum() && fs != rs => {
            out.push(format!(
                "{path}: the file lists {fs:?}, the Rust enum writes {rs:?}"
            ));
        }
        (Some(fs), Some(rs)) if !rust.is_pure_enum() && !fs.is_subset(&rs) => {
            out.push(format!(
                "{path}: the file lists {fs:?}, Rust writes only {rs:?}"
            ));
        }
        (None, Some(rs)) if !rs.is_empty() => {
            out.push(format!(
                "{path}: the file admits any string, Rust writes only {rs:?}"
            ));
        }
        // The file may list fewer strings than a Rust `String` admits (a version, say).
        _ => {}
    }
    match (file.object(), rust.object()) {
        (Some((fp, fr)), Some((rp, rr))) => {
            let (fnames, rnames): (BTreeSet<_>, BTreeSet<_>) =
                (fp.keys().collect(), rp.keys().collect());
            for name in fnames.difference(&rnames) {
                out.push(format!(
                    "{path}: property '{name}' is in the file, not in the Rust type"
                ));
            }
            for name in rnames.difference(&fnames) {
                out.push(format!(
                    "{path}: property '{name}' is in the Rust type, not in the file"
                ));
            }
            if fr != rr {
                out.push(format!(
                    "{path}: the file requires {fr:?}, Rust always writes {rr:?}"
                ));
            }
            for (name, f) in &fp {
                if let Some(r) = rp.get(name) {
                    differences(&format!("{path}/{name}"), *f, *r, out);
                }
            }
        }
        (None, None) => {}
        (f, _) => out.push(format!(
            "{path}: {} has properties, the other does not",
            side(f.is_some())
        )),
    }
    match (file.array(), rust.array()) {
        (Some((fi, fl)), Some((ri, rl))) => {
            if rl.is_some() && fl != rl {
                out.push(format!(
                    "{path}: the file's array length is {fl:?}, Rust's {rl:?}"
                ));
            }
            match (fi, ri) {
                (Some(f), Some(r)) => differences(&format!("{path}/[]"), f, r, out),
                (None, None) => {}
                _ => out.push(format!("{path}: only one side says what the items are")),
            }
        }
        (None, None) => {}
        (f, _) => out.push(format!(
            "{path}: {} is an array, the other is not",
            side(f.is_some())
        )),
    }
}

/// The differences between a hand-written schema document and a derived one.
pub fn drift(file: &Value, rust: &Value) -> Vec<String> {
    let mut out = Vec::new();
    differences("#", Node::document(file), Node::document(rust), &mut out);
    out
}
