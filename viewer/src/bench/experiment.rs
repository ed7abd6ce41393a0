//! The experiments of `viewer bench run` ([`Experiment`]), named once, by `strum` and serde
//! alike, as they appear on the command line and in results files.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use residency_schemas::names::{Named, UnknownName};

/// An experiment of `viewer bench run`, named `table1`, `sweep`, `skipped` or `scaling` on the
/// command line and in results files.
#[derive(
    Clone,
    Copy,
    Debug,
    PartialEq,
    Eq,
    Hash,
    Serialize,
    Deserialize,
    JsonSchema,
    strum::Display,
    strum::EnumCount,
    strum::EnumString,
    strum::IntoStaticStr,
    strum::VariantArray,
    strum::VariantNames,
)]
#[serde(rename_all = "lowercase")]
#[strum(
    serialize_all = "lowercase",
    parse_err_ty = UnknownExperiment,
    parse_err_fn = UnknownExperiment::new
)]
pub enum Experiment {
    /// Table 1 of the paper: every method, GPU and wall ms per converged frame, resident bytes.
    Table1,
    /// Time against error: step, LOD bias, cache budget and leaf size, one at a time.
    Sweep,
    /// Skipped work against a naive frustum loader.
    Skipped,
    /// One residency run (frame time, resident and fetched bytes) for the scaling plots.
    Scaling,
}

// `Experiment::ALL` is the order `viewer bench run` lists them in: that of the variants.
residency_schemas::strum_names!(Experiment, all);

impl Named for Experiment {
    const NOUN: &'static str = "experiment";
}

/// An experiment name that is not one of [`Experiment::ALL`]'s.
pub type UnknownExperiment = UnknownName<Experiment>;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn experiments_are_listed_in_the_order_of_the_variants() {
        assert_eq!(
            Experiment::ALL,
            [
                Experiment::Table1,
                Experiment::Sweep,
                Experiment::Skipped,
                Experiment::Scaling
            ]
        );
        assert_eq!(
            Experiment::ALL.map(Experiment::name),
            ["table1", "sweep", "skipped", "scaling"]
        );
    }

    #[test]
    fn an_unknown_experiment_is_named_with_the_known_ones() {
        assert_eq!(
            "Table1".parse::<Experiment>().unwrap_err().to_string(),
            "unknown experiment 'Table1' (table1, sweep, skipped or scaling)"
        );
    }
}
