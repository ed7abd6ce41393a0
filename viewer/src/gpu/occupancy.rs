//! SparseLeap's occupancy geometry (Hadwiger et al. 2018, Secs. 5 and 6), built on the CPU
//! from the residency octree: the boxes the `sparseleap` method rasterises into ray segment
//! lists (`segments`).
//!
//! - **Occupancy classes** of the *occupancy leaves*, the octree nodes at depth
//!   `min(D, MAX_GEOMETRY_DEPTH)`: *empty* where every drawn channel is transparent under its
//!   transfer function by the node's class word (the one ours culls with,
//!   `residency::node_class`), *unknown* where some channel that is not empty has no
//!   level resident anywhere in the node (or the store has no region metadata), *non-empty*
//!   otherwise.
//! - **Occupancy histograms**: every coarser node counts its occupancy leaves per class, and
//!   takes the majority class (ties: non-empty, then unknown, then empty).
//! - **Geometry**: breadth first from the root, a node emits its box when its class differs
//!   from its parent's (the root always does). Along any ray the class of the deepest box
//!   holding a point is then the class of the occupancy leaf there, so the lists are exact, and
//!   boxes are only emitted where the class changes.
//!
//! Boxes that are not empty (and the root) are widened, and empty ones narrowed, by `HAIR`
//! of a leaf, so that a ray running exactly along a shared face is never taken as empty by
//! rounding. Unknown
//! and non-empty segments are both sampled (where a brick is missing the ray caster requests
//! it); the distinction is kept for the statistics, as the paper keeps it for its occupancy
//! misses.

use super::contract::{
    OCCUPANCY_EMPTY, OCCUPANCY_NONEMPTY, OCCUPANCY_UNKNOWN, SegmentBox, segment_payload,
};
use crate::octree::{ResidencyOctree, node_index};

/// Deepest octree depth whose nodes are occupancy leaves (8⁶ of them at most).
pub(crate) const MAX_GEOMETRY_DEPTH: u32 = 6;

/// How far boxes are widened (non-empty, unknown) or narrowed (empty), in leaf units.
pub(crate) const HAIR: f32 = 1e-3;

/// The occupancy geometry of one octree under one set of styles.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct OccupancyGeometry {
    /// The boxes, coarsest first.
    pub boxes: Vec<SegmentBox>,
    /// Occupancy leaves per class: empty, non-empty, unknown.
    pub leaves: [u64; 3],
}

/// The occupancy class of node `node` of `octree`, whose class words are `classes`
/// ([`super::residency::node_classes`]).
pub fn leaf_class(octree: &ResidencyOctree, classes: &[u32], node: usize) -> u32 {
    let channels = octree.channels().len();
    let all = (1u32 << channels) - 1;
    let empty = classes[node] & all;
    if empty == all {
        return OCCUPANCY_EMPTY;
    }
    if octree.unknown_ranges() {
        return OCCUPANCY_UNKNOWN;
    }
    let unmapped = (0..channels).any(|c| empty & (1 << c) == 0 && octree.mask(node, c) == 0);
    if unmapped {
        OCCUPANCY_UNKNOWN
    } else {
        OCCUPANCY_NONEMPTY
    }
}

/// The majority class of occupancy-leaf counts `[empty, non-empty, unknown]`.
fn majority(counts: [u64; 3]) -> u32 {
    let [e, n, u] = counts;
    if n >= u && n >= e {
        OCCUPANCY_NONEMPTY
    } else if u >= e {
        OCCUPANCY_UNKNOWN
    } else {
        OCCUPANCY_EMPTY
    }
}

/// Builds the occupancy geometry of `octree`, whose class words are `classes`.
pub fn occupancy_geometry(octree: &ResidencyOctree, classes: &[u32]) -> OccupancyGeometry {
    let leaf_depth = octree.geometry().depth;
    let g = leaf_depth.min(MAX_GEOMETRY_DEPTH);
    let nodes = node_index(g + 1, [0, 0, 0]);
    let mut counts = vec![[0u64; 3]; nodes];
    let mut leaves = [0u64; 3];
    let n = 1u64 << g;
    for z in 0..n {
        for y in 0..n {
            for x in 0..n {
                let i = node_index(g, [x, y, z]);
                let class = leaf_class(octree, classes, i) as usize;
                counts[i][class] = 1;
                leaves[class] += 1;
            }
        }
    }
    for d in (0..g).rev() {
        let n = 1u64 << d;
        for z in 0..n {
            for y in 0..n {
                for x in 0..n {
                    let mut sum = [0u64; 3];
                    for k in 0..8u64 {
                        let c = [2 * x + (k & 1), 2 * y + ((k >> 1) & 1), 2 * z + (k >> 2)];
                        let child = counts[node_index(d + 1, c)];
                        for (s, v) in sum.iter_mut().zip(child) {
                            *s += v;
                        }
                    }
                    counts[node_index(d, [x, y, z])] = sum;
                }
            }
        }
    }
    // Breadth first: depth by depth, each node against its parent's class.
    let mut class = vec![0u32; nodes];
    let mut boxes = Vec::new();
    for d in 0..=g {
        let n = 1u64 << d;
        let edge = (1u64 << (leaf_depth - d)) as f32;
        for z in 0..n {
            for y in 0..n {
                for x in 0..n {
                    let i = node_index(d, [x, y, z]);
                    let c = majority(counts[i]);
                    class[i] = c;
                    let parent = (d > 0).then(|| class[node_index(d - 1, [x / 2, y / 2, z / 2])]);
                    if parent != Some(c) {
                        // The root holds every ray's whole span, whatever its class.
                        let hair = if c == OCCUPANCY_EMPTY && d > 0 {
                            -HAIR
                        } else {
                            HAIR
                        };
                        let lo = [x, y, z].map(|v| v as f32 * edge - hair);
                        let hi = [x, y, z].map(|v| (v + 1) as f32 * edge + hair);
                        boxes.push(SegmentBox {
                            lo,
                            payload: segment_payload(c, d, 0),
                            hi,
                            pad0: 0,
                        });
                    }
                }
            }
        }
    }
    OccupancyGeometry { boxes, leaves }
}
