//! What `viewer bench run` measures and how ([`Plan`]): the experiments, the orbit, the
//! Table-1 configurations ([`MethodConfig`]) and the values a sweep visits ([`SweepValues`],
//! from the [`SweepGroup`]s turned on).

use super::experiment::Experiment;
use crate::gpu::renderer::{Method, UnknownMethod};
use residency_schemas::names::{Named, UnknownName};

/// A Table-1 configuration: a method with or without empty-space skipping, named as the
/// method (with skipping) or `no-skipping` (ours without it).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MethodConfig {
    /// The traversal method.
    pub method: Method,
    /// Whether empty space is skipped.
    pub skipping: bool,
}

impl MethodConfig {
    /// The name of ours without empty-space skipping.
    pub const NO_SKIPPING: &'static str = "no-skipping";

    /// Every configuration's name: each method's (with skipping), then [`Self::NO_SKIPPING`].
    pub fn names() -> impl Iterator<Item = &'static str> {
        <Method as strum::VariantNames>::VARIANTS
            .iter()
            .copied()
            .chain([Self::NO_SKIPPING])
    }

    /// The label of the configuration in results files: the method's name, followed by
    /// ` (no skipping)` without skipping.
    pub fn label(self) -> String {
        if self.skipping {
            self.method.name().to_string()
        } else {
            format!("{} (no skipping)", self.method.name())
        }
    }
}

impl std::str::FromStr for MethodConfig {
    type Err = UnknownMethod;

    /// A method's name (with skipping), or `no-skipping` for ours without it.
    fn from_str(s: &str) -> Result<Self, UnknownMethod> {
        if s == Self::NO_SKIPPING {
            return Ok(Self {
                method: Method::Residency,
                skipping: false,
            });
        }
        s.parse().map(|method| Self {
            method,
            skipping: true,
        })
    }
}

/// A group of sweep runs, named on the command line as `step`, `lod-bias`, `cache`, `leaf`
/// or `methods` (every other Table-1 method over the same steps and LOD biases).
#[derive(
    Clone,
    Copy,
    Debug,
    PartialEq,
    Eq,
    strum::Display,
    strum::EnumString,
    strum::IntoStaticStr,
    strum::VariantNames,
)]
#[strum(
    serialize_all = "kebab-case",
    parse_err_ty = UnknownSweepGroup,
    parse_err_fn = UnknownSweepGroup::new
)]
pub enum SweepGroup {
    /// The step factors.
    Step,
    /// The LOD biases.
    LodBias,
    /// The cache budgets.
    Cache,
    /// The octree leaf targets.
    Leaf,
    /// The other methods, each over the steps and LOD biases.
    Methods,
}

impl Named for SweepGroup {
    const NOUN: &'static str = "parameter";
}

/// A sweep group name that is not one of [`SweepGroup`]'s.
pub type UnknownSweepGroup = UnknownName<SweepGroup>;

/// The values a sweep visits.
#[derive(Clone, Debug, PartialEq)]
pub struct SweepValues {
    /// Step factors.
    pub steps: Vec<f32>,
    /// LOD biases.
    pub lod_biases: Vec<f32>,
    /// Cache budgets as fractions of the default run's working set (largest `bricks_used`).
    pub cache_fractions: Vec<f64>,
    /// Leaf targets in level-0 voxels.
    pub leaf_voxels: Vec<u64>,
    /// Other methods swept too, each at its defaults and over `steps` and `lod_biases`, so
    /// that the time–error front holds every renderer, not only ours.
    pub methods: Vec<Method>,
}

/// What to measure and how.
#[derive(Clone, Debug)]
pub struct Plan {
    /// Experiments, in order.
    pub experiments: Vec<Experiment>,
    /// Dataset label.
    pub label: Option<String>,
    /// Dataset kind.
    pub kind: String,
    /// Views of the orbit.
    pub views: usize,
    /// Frames timed per view.
    pub timed_frames: usize,
    /// Most frames to converge a view.
    pub max_frames: u32,
    /// Orbit elevation, degrees.
    pub elevation: f64,
    /// Orbit distance, volume diagonals.
    pub distance: f64,
    /// First azimuth, degrees.
    pub first_azimuth: f64,
    /// Reference step fraction.
    pub reference_step: f64,
    /// Fetch workers.
    pub workers: usize,
    /// Table-1 configurations.
    pub methods: Vec<MethodConfig>,
    /// Sweep values.
    pub sweep: SweepValues,
    /// Show a progress bar.
    pub progress: bool,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn method_configs_are_named_as_their_methods_or_no_skipping() {
        for method in Method::ALL {
            let c: MethodConfig = method.name().parse().unwrap();
            assert_eq!(
                c,
                MethodConfig {
                    method,
                    skipping: true
                }
            );
            assert_eq!(c.label(), method.name());
        }
        let c: MethodConfig = "no-skipping".parse().unwrap();
        assert_eq!(
            c,
            MethodConfig {
                method: Method::Residency,
                skipping: false
            }
        );
        assert_eq!(c.label(), "residency (no skipping)");
        assert!("no_skipping".parse::<MethodConfig>().is_err());
        assert_eq!(
            MethodConfig::names().collect::<Vec<_>>().join(", "),
            "residency, page-table, octree, sparseleap, rasterize, no-skipping"
        );
    }

    #[test]
    fn sweep_groups_are_their_command_line_names() {
        use strum::VariantNames as _;
        assert_eq!(
            SweepGroup::VARIANTS,
            ["step", "lod-bias", "cache", "leaf", "methods"]
        );
        assert_eq!("lod-bias".parse::<SweepGroup>(), Ok(SweepGroup::LodBias));
        assert_eq!(
            "lod_bias".parse::<SweepGroup>().unwrap_err().to_string(),
            "unknown parameter 'lod_bias' (step, lod-bias, cache, leaf or methods)"
        );
    }
}
