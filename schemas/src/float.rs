//! Serde for `f64` statistics that may be infinite or NaN. JSON has no such numbers (serde_json
//! writes them as `null`, which would read back as "no value"), so a finite value is a JSON
//! number and the others are the strings `"Infinity"`, `"-Infinity"` and `"NaN"`, as Zarr v3
//! writes non-finite fill values. `null` is kept for "no value" ([`option`]).
//!
//! Use with `#[serde(with = "residency_schemas::float")]` on an `f64`, or
//! `#[serde(with = "residency_schemas::float::option")]` on an `Option<f64>`.

use serde::de::{self, Deserializer, Visitor};
use serde::{Deserialize, Serializer};

/// The string a non-finite value is written as, or `None` for a finite one.
pub fn non_finite_name(v: f64) -> Option<&'static str> {
    if v.is_nan() {
        Some("NaN")
    } else if v == f64::INFINITY {
        Some("Infinity")
    } else if v == f64::NEG_INFINITY {
        Some("-Infinity")
    } else {
        None
    }
}

/// Writes `v` as a JSON number, or as `"Infinity"`, `"-Infinity"` or `"NaN"`.
///
/// # Errors
/// Whatever the serializer reports.
pub fn serialize<S: Serializer>(v: &f64, s: S) -> Result<S::Ok, S::Error> {
    match non_finite_name(*v) {
        Some(name) => s.serialize_str(name),
        None => s.serialize_f64(*v),
    }
}

/// Reads a JSON number, or one of the strings `"Infinity"`, `"-Infinity"`, `"NaN"`.
///
/// # Errors
/// When the value is neither a number nor one of those strings.
pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    d.deserialize_any(FloatVisitor)
}

/// The JSON Schema of what [`serialize`] writes, for `#[schemars(schema_with = ...)]`: a
/// number, or one of the strings `"Infinity"`, `"-Infinity"`, `"NaN"`.
pub fn json_schema(_: &mut schemars::SchemaGenerator) -> schemars::Schema {
    schemars::json_schema!({
        "oneOf": [
            {"type": "number"},
            {"type": "string", "enum": ["Infinity", "-Infinity", "NaN"]}
        ]
    })
}

struct FloatVisitor;

impl Visitor<'_> for FloatVisitor {
    type Value = f64;

    fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.write_str("a number, or \"Infinity\", \"-Infinity\" or \"NaN\"")
    }

    fn visit_f64<E: de::Error>(self, v: f64) -> Result<f64, E> {
        Ok(v)
    }

    fn visit_i64<E: de::Error>(self, v: i64) -> Result<f64, E> {
        Ok(v as f64)
    }

    fn visit_u64<E: de::Error>(self, v: u64) -> Result<f64, E> {
        Ok(v as f64)
    }

    fn visit_str<E: de::Error>(self, v: &str) -> Result<f64, E> {
        match v {
            "Infinity" => Ok(f64::INFINITY),
            "-Infinity" => Ok(f64::NEG_INFINITY),
            "NaN" => Ok(f64::NAN),
            other => Err(E::invalid_value(de::Unexpected::Str(other), &self)),
        }
    }
}

/// The same for `Option<f64>`, `None` being `null`.
pub mod option {
    use super::{Deserialize, Deserializer, Serializer};

    /// Writes `None` as `null`, a value as [`super::serialize`] does.
    ///
    /// # Errors
    /// Whatever the serializer reports.
    pub fn serialize<S: Serializer>(v: &Option<f64>, s: S) -> Result<S::Ok, S::Error> {
        match v {
            Some(v) => super::serialize(v, s),
            None => s.serialize_none(),
        }
    }

    /// The JSON Schema of what [`serialize`] writes: that of [`super::json_schema`], or
    /// `null`.
    pub fn json_schema(_: &mut schemars::SchemaGenerator) -> schemars::Schema {
        schemars::json_schema!({
            "oneOf": [
                {"type": "number"},
                {"type": "string", "enum": ["Infinity", "-Infinity", "NaN"]},
                {"type": "null"}
            ]
        })
    }

    /// Reads `null` as `None`, anything else as [`super::deserialize`] does.
    ///
    /// # Errors
    /// When the value is neither `null`, a number nor one of the strings.
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Option<f64>, D::Error> {
        #[derive(Deserialize)]
        struct Wrapped(#[serde(with = "super")] f64);
        Ok(Option::<Wrapped>::deserialize(d)?.map(|w| w.0))
    }
}

#[cfg(test)]
mod tests {
    use serde::{Deserialize, Serialize};

    #[derive(Debug, PartialEq, Serialize, Deserialize)]
    struct Doc {
        #[serde(with = "crate::float")]
        v: f64,
        #[serde(with = "crate::float::option")]
        o: Option<f64>,
    }

    #[test]
    fn non_finite_values_round_trip_as_strings_and_null_stays_no_value() {
        for (v, o, text) in [
            (1.5, Some(-2.0), r#"{"v":1.5,"o":-2.0}"#),
            (
                f64::INFINITY,
                Some(f64::NEG_INFINITY),
                r#"{"v":"Infinity","o":"-Infinity"}"#,
            ),
            (f64::NEG_INFINITY, None, r#"{"v":"-Infinity","o":null}"#),
        ] {
            let doc = Doc { v, o };
            assert_eq!(serde_json::to_string(&doc).unwrap(), text);
            assert_eq!(serde_json::from_str::<Doc>(text).unwrap(), doc);
        }
        let nan: Doc = serde_json::from_str(r#"{"v":"NaN","o":"NaN"}"#).unwrap();
        assert!(nan.v.is_nan() && nan.o.unwrap().is_nan());
        assert_eq!(
            serde_json::to_string(&nan).unwrap(),
            r#"{"v":"NaN","o":"NaN"}"#
        );
        let int: Doc = serde_json::from_str(r#"{"v":3,"o":-4}"#).unwrap();
        assert_eq!(
            int,
            Doc {
                v: 3.0,
                o: Some(-4.0)
            }
        );
        let e = serde_json::from_str::<Doc>(r#"{"v":"inf","o":null}"#).unwrap_err();
        assert!(
            e.to_string().contains("invalid value: string \"inf\""),
            "{e}"
        );
    }
}
