//! The papers' published numbers our datasets stand beside: Table 1 of the residency-octree
//! paper ([`PAPER`]), SparseLeap's Table 1 ([`SPARSELEAP_PAPER`]) and octree rasterisation's
//! speed-ups ([`RASTERIZE_PAPER`]), each keyed by the [`SampleKind`] that stands in for the
//! paper's data set.

use residency_schemas::SampleKind;

/// Table 1 of the residency-octree paper: ms per frame and GPU memory (GB) per method.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct PaperRow {
    /// Data set.
    pub dataset: &'static str,
    /// Channels rendered.
    pub channels: usize,
    /// MRMCPT, Octree, Ours: ms per frame.
    pub ms: [f64; 3],
    /// MRMCPT, Octree, Ours: GB per frame.
    pub gb: [f64; 3],
}

impl PaperRow {
    /// A row: data set, channels, then ms and GB per frame of MRMCPT, Octree and Ours.
    const fn new(dataset: &'static str, channels: usize, ms: [f64; 3], gb: [f64; 3]) -> Self {
        Self {
            dataset,
            channels,
            ms,
            gb,
        }
    }
}

/// The rows of the paper's Table 1 that our synthetic kinds stand in for.
pub(crate) const PAPER: [PaperRow; 5] = [
    PaperRow::new("Kingsnake", 1, [15.0, 11.6, 5.1], [0.66, 0.23, 0.13]),
    PaperRow::new("Kingsnake", 4, [42.5, 60.7, 19.8], [1.88, 0.89, 0.48]),
    PaperRow::new("Rayleigh–Taylor", 1, [11.2, 13.8, 6.4], [0.13, 0.06, 0.04]),
    PaperRow::new("Rayleigh–Taylor", 4, [24.3, 54.9, 20.0], [0.31, 0.19, 0.14]),
    PaperRow::new("CyCIF Small", 16, [34.0, 122.8, 25.7], [0.95, 0.46, 0.29]),
];

/// The paper row our dataset `kind` with `channels` visible channels stands in for: sparse →
/// Kingsnake, mixing (and dense, its worst case with no constant region) → Rayleigh–Taylor (1
/// or 4 channels), cycif → CyCIF Small (16).
pub(crate) fn paper_row(kind: SampleKind, channels: usize) -> Option<&'static PaperRow> {
    let (name, ch) = match kind {
        SampleKind::Sparse => ("Kingsnake", if channels > 1 { 4 } else { 1 }),
        SampleKind::Dense | SampleKind::Mixing => {
            ("Rayleigh–Taylor", if channels > 1 { 4 } else { 1 })
        }
        SampleKind::Cycif => ("CyCIF Small", 16),
        SampleKind::Fluorescence => return None,
    };
    PAPER.iter().find(|r| r.dataset == name && r.channels == ch)
}

/// A row of SparseLeap's Table 1 (Hadwiger et al., TVCG 2018): frames per second of octree
/// empty space skipping and of SparseLeap with rasterisation (no early ray termination,
/// 1200² pixels, GeForce Titan X), for one occupancy setting of one data set.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct LeapRow {
    /// Data set and occupancy of the enabled segments.
    pub dataset: &'static str,
    /// Octree frames per second.
    pub octree_fps: f64,
    /// SparseLeap (with rasterisation) frames per second.
    pub sparseleap_fps: f64,
}

impl LeapRow {
    /// SparseLeap's speed-up over the octree: octree time over SparseLeap time.
    pub(crate) fn speedup(&self) -> f64 {
        self.sparseleap_fps / self.octree_fps
    }
}

/// The SparseLeap rows our kinds stand in for: sparse → King Snake with 0.92% of its voxels
/// enabled, dense and mixing → King Snake at 59.57%, cycif → KESM Mouse Brain (59,162 small
/// segmented objects, microscopy) at 23.4%. Over all 16 rows of that table the speed-up runs
/// from 0.77× (Dreh Sensor, dense) to 2.43× (SEM Mouse Cortex, dense).
pub(crate) const SPARSELEAP_PAPER: [(&[SampleKind], LeapRow); 3] = [
    (
        &[SampleKind::Sparse],
        LeapRow {
            dataset: "King Snake 0.92%",
            octree_fps: 8.5,
            sparseleap_fps: 15.0,
        },
    ),
    (
        &[SampleKind::Dense, SampleKind::Mixing],
        LeapRow {
            dataset: "King Snake 59.57%",
            octree_fps: 3.0,
            sparseleap_fps: 5.5,
        },
    ),
    (
        &[SampleKind::Cycif],
        LeapRow {
            dataset: "KESM Mouse Brain 23.4%",
            octree_fps: 18.0,
            sparseleap_fps: 24.0,
        },
    ),
];

/// Speed-ups of octree rasterisation over per-ray octree traversal in its paper's Table 1
/// (Wang et al.: nine CT data sets, 512² pixels, tricubic filtering): smallest, median,
/// largest. None of them is microscopy, so every kind is shown beside the whole range.
pub(crate) const RASTERIZE_PAPER: [f64; 3] = [2.18, 2.63, 4.23];

/// The SparseLeap row our dataset `kind` stands in for.
pub(crate) fn sparseleap_row(kind: SampleKind) -> Option<&'static LeapRow> {
    SPARSELEAP_PAPER
        .iter()
        .find(|(kinds, _)| kinds.contains(&kind))
        .map(|(_, r)| r)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The paper row of the kind named `kind`, if it names one.
    fn paper_row(kind: &str, channels: usize) -> Option<&'static PaperRow> {
        super::paper_row(kind.parse().ok()?, channels)
    }

    #[test]
    fn kinds_map_to_the_papers_rows() {
        assert_eq!(paper_row("sparse", 1).unwrap().ms, [15.0, 11.6, 5.1]);
        assert_eq!(paper_row("sparse", 4).unwrap().gb, [1.88, 0.89, 0.48]);
        assert_eq!(paper_row("dense", 4).unwrap().ms[2], 20.0);
        assert_eq!(paper_row("mixing", 1).unwrap().ms, [11.2, 13.8, 6.4]);
        assert_eq!(paper_row("cycif", 8).unwrap().channels, 16);
        assert!(paper_row("fluorescence", 3).is_none());
    }
}
