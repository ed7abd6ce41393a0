//! How the ray caster finds data and skips empty space: [`Method`], ours or a baseline, and
//! its names on the command line, in statistics and in results files, written once (`strum`
//! and serde derive them from the variants alike).

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use residency_schemas::names::{Named, UnknownName};

/// How the ray caster finds data and skips empty space: the residency octree, or one of the
/// paper's two baselines (Table 1), built on the same ray caster, data path and transfer
/// functions so that their ratios are fair.
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
    strum::Display,
    strum::EnumCount,
    strum::EnumString,
    strum::IntoStaticStr,
    strum::VariantArray,
    strum::VariantNames,
)]
#[serde(rename_all = "kebab-case")]
#[strum(
    serialize_all = "kebab-case",
    parse_err_ty = UnknownMethod,
    parse_err_fn = UnknownMethod::new
)]
pub enum Method {
    /// The residency octree: per-channel residency masks and min/max per node, nodes finer
    /// than a brick, substitution of missing bricks from other resident levels.
    #[default]
    Residency,
    /// Multi-resolution multi-channel page table (MRMCPT): data is read straight through the
    /// page table; only whole bricks empty in every channel are skipped; a missing brick is a
    /// hole until it arrives.
    PageTable,
    /// Octree of one node per brick (GigaVoxels style): each channel descends from the
    /// coarsest level to the level it wants, needs every ancestor brick resident, and renders
    /// from the finest resident ancestor while a brick is missing.
    Octree,
    /// SparseLeap (Hadwiger et al. 2018): occupancy geometry (nested octree boxes where the
    /// occupancy class changes: empty under the transfer functions, non-empty, unknown) is
    /// rasterised each frame into per-pixel ray segment lists, and the ray caster leaps over
    /// the empty segments without traversing a hierarchy, sampling the others through the page
    /// table as ours does.
    #[serde(rename = "sparseleap")]
    #[strum(serialize = "sparseleap")]
    SparseLeap,
    /// Octree rasterisation (Wang et al.): the CPU picks a cut of bricks by the projected
    /// size of each brick's bounding sphere and culls empty ones, the bricks are rasterised
    /// into per-pixel ray segment lists, and each ray samples every brick on its list at that
    /// brick's level, skipping empty macrocells (the octree nodes of 8³ voxels of the level)
    /// inside it.
    Rasterize,
}

// `Method::ALL` lists ours first: the order of the variants.
residency_schemas::strum_names!(Method, all);

impl Method {
    /// Whether the method rasterises boxes into ray segment lists before ray casting.
    pub fn uses_segment_lists(self) -> bool {
        matches!(self, Self::SparseLeap | Self::Rasterize)
    }

    /// Whether the method culls with the residency octree's per-node classes (and never
    /// fetches bricks that are clear under the transfer functions), rather than with the
    /// baselines' per-brick classes.
    pub fn uses_node_classes(self) -> bool {
        !matches!(self, Self::PageTable | Self::Octree)
    }
}

impl Named for Method {
    const NOUN: &'static str = "method";
}

/// A method name that is not one of [`Method::ALL`]'s.
pub type UnknownMethod = UnknownName<Method>;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_method_has_one_name_for_strum_and_serde() {
        let names: Vec<&str> = Method::ALL.into_iter().map(Method::name).collect();
        assert_eq!(
            names,
            [
                "residency",
                "page-table",
                "octree",
                "sparseleap",
                "rasterize"
            ]
        );
        for m in Method::ALL {
            assert_eq!(serde_json::to_value(m).unwrap(), m.name());
            assert_eq!(m.to_string(), m.name());
            assert_eq!(m.name().parse::<Method>(), Ok(m));
        }
    }

    #[test]
    fn an_unknown_method_is_named_with_the_known_ones() {
        assert_eq!(
            "sparse-leap".parse::<Method>().unwrap_err().to_string(),
            "unknown method 'sparse-leap' (residency, page-table, octree, sparseleap or rasterize)"
        );
    }
}
