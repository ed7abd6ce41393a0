//! [`VdiFilter`]: how the ray caster reads a volumetric depth image between its lists.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use residency_schemas::names::{Named, UnknownName};

/// How a ray reads a VDI between the centres of its lists (`V_O`'s pixels).
#[derive(
    Clone,
    Copy,
    Debug,
    Default,
    PartialEq,
    Eq,
    Serialize,
    Deserialize,
    JsonSchema,
    strum::EnumCount,
    strum::EnumString,
    strum::IntoStaticStr,
    strum::VariantArray,
    strum::VariantNames,
)]
#[serde(rename_all = "kebab-case")]
#[strum(
    serialize_all = "kebab-case",
    parse_err_ty = UnknownName<VdiFilter>,
    parse_err_fn = UnknownName::new
)]
pub enum VdiFilter {
    /// The list whose cell holds the point (the paper's): the fastest. A surface `V_O` sees
    /// edge-on is as wide as whole lists, and shows as stripes from the side.
    #[default]
    Nearest,
    /// The bilinear mix of the four lists whose centres surround the point, each
    /// supersegment a homogeneous medium (its extinction and colour per opacity), composited
    /// exactly between the four lists' supersegment ends: closer to DVR away from `V_O`
    /// (`viewer bench vdi` measures both), at several times the nearest filter's cost.
    Linear,
}

residency_schemas::strum_names!(VdiFilter, all);

impl Named for VdiFilter {
    const NOUN: &'static str = "VDI filter";
}
