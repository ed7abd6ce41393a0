//! The synthetic specimens `ingest sample --kind` writes ([`SampleKind`]): the one list of
//! their names, which `ingest` generates from and the render benchmark keys the papers' rows
//! by.

use serde::{Deserialize, Serialize};

/// A kind of synthetic specimen, named as `ingest sample --kind` and `viewer bench run --kind`
/// name it: `fluorescence`, `sparse`, `dense`, `mixing`, `cycif` (its `Display`, `FromStr`,
/// `&'static str` and serde name, case-sensitive). [`strum::VariantArray::VARIANTS`] lists
/// every kind in that order. A results file keeps a dataset's kind as given, so a dataset of
/// another kind (any other name) has no `SampleKind`.
#[derive(
    Clone,
    Copy,
    Debug,
    PartialEq,
    Eq,
    Hash,
    Serialize,
    Deserialize,
    strum::Display,
    strum::EnumString,
    strum::IntoStaticStr,
    strum::VariantArray,
    strum::VariantNames,
)]
#[serde(rename_all = "lowercase")]
#[strum(serialize_all = "lowercase")]
pub enum SampleKind {
    /// Cleared-tissue light-sheet stack: nuclei (uint16), membranes and filaments (uint8).
    Fluorescence,
    /// Micro-CT of a coiled skeleton in empty space (uint16), mostly exactly 0, like the
    /// Kingsnake.
    Sparse,
    /// Rayleigh–Taylor-like mixing fluids (float32) filling the whole volume, no region
    /// constant.
    Dense,
    /// Rayleigh–Taylor-like mixing fluids (float32), pure (constant) outside the mixing layer.
    Mixing,
    /// Multiplexed immunofluorescence of a thin tissue section (uint16), many markers.
    Cycif,
}

#[cfg(test)]
mod tests {
    use strum::{VariantArray, VariantNames};

    use super::*;

    #[test]
    fn kinds_are_their_ingest_names() {
        for (name, kind) in [
            ("fluorescence", SampleKind::Fluorescence),
            ("sparse", SampleKind::Sparse),
            ("dense", SampleKind::Dense),
            ("mixing", SampleKind::Mixing),
            ("cycif", SampleKind::Cycif),
        ] {
            assert_eq!(name.parse::<SampleKind>(), Ok(kind));
            assert_eq!(kind.to_string(), name);
            assert_eq!(<&str>::from(kind), name);
            assert_eq!(serde_json::to_string(&kind).unwrap(), format!("\"{name}\""));
            assert_eq!(
                serde_json::from_str::<SampleKind>(&format!("\"{name}\"")).unwrap(),
                kind
            );
        }
        assert!("Sparse".parse::<SampleKind>().is_err());
        assert!("ct".parse::<SampleKind>().is_err());
        let names: Vec<&str> = <SampleKind as VariantArray>::VARIANTS
            .iter()
            .map(|&k| k.into())
            .collect();
        assert_eq!(
            names,
            ["fluorescence", "sparse", "dense", "mixing", "cycif"]
        );
        assert_eq!(names, <SampleKind as VariantNames>::VARIANTS);
    }
}
