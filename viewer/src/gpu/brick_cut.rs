//! The rasterize method's cut of bricks (Wang et al., "octree rasterization", Sec. 4.2): each
//! frame the CPU descends the pyramid's bricks from the coarsest level, culls bricks outside
//! the view frustum or empty under the transfer functions, and refines a brick while its
//! finer level's voxels would still cover at least `2^lod_bias` pixels, judged from the
//! projected size of the brick's bounding sphere (the paper's Eq. 1). The bricks of the cut
//! are the boxes the method rasterises into ray segment lists (`segments`).
//!
//! Emptiness comes from the residency octree's per-node class words (the region metadata under
//! the transfer functions, as ours culls with them), over the nodes of the smallest size that
//! covers a brick. Bricks are widened by `occupancy::HAIR` of a leaf, so that
//! neighbours overlap by a hair and no ray slips between them.

use super::contract::{OCCUPANCY_NONEMPTY, SegmentBox, segment_payload};
use super::occupancy::HAIR;
use crate::octree::{OctreeGeometry, ResidencyOctree, node_index};
use crate::scene::Camera;

/// The camera as the cut sees it.
#[derive(Clone, Debug, PartialEq)]
pub struct CutView {
    /// The camera.
    pub camera: Camera,
    /// Image width over height.
    pub aspect: f64,
    /// Image height in pixels.
    pub height: f64,
    /// Level-of-detail bias, `log2` (the renderer's).
    pub lod_bias: f64,
    /// World size of a level-0 voxel per axis, `x, y, z`.
    pub spacing: [f64; 3],
    /// Finest and coarsest level any drawn channel may show.
    pub levels: (usize, usize),
}

/// What one cut holds.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BrickCut {
    /// The bricks, as boxes in leaf units carrying their level.
    pub boxes: Vec<SegmentBox>,
    /// Bricks culled as empty under the transfer functions.
    pub empty: u64,
    /// Bricks culled outside the view frustum.
    pub outside: u64,
}

/// A brick of the pyramid: level and index per axis (`x, y, z`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Brick {
    level: usize,
    index: [u64; 3],
}

/// The level-0 voxel box `[lo, hi)` of a brick (`x, y, z`), clipped to the volume.
fn voxel_box(g: &OctreeGeometry, b: Brick) -> ([u64; 3], [u64; 3]) {
    let s = g.level_shift[b.level];
    let lo = std::array::from_fn(|a| (b.index[a] * g.brick[a]) << s[a]);
    let hi =
        std::array::from_fn(|a| (((b.index[a] + 1) * g.brick[a]) << s[a]).min(g.volume_voxels[a]));
    (lo, hi)
}

/// Whether every drawn channel is empty over the voxel box `[lo, hi)`, by the classes of the
/// octree nodes of the deepest depth whose nodes are at least the box's size.
fn box_is_empty(octree: &ResidencyOctree, classes: &[u32], lo: [u64; 3], hi: [u64; 3]) -> bool {
    let g = octree.geometry();
    let all = (1u32 << octree.channels().len()) - 1;
    // The node edge at depth d is 2^(leaf_shift + D - d) voxels.
    let fits = |d: u32| {
        (0..3).all(|a| {
            let edge = g.leaf_shift[a] + (g.depth - d) as i32;
            edge >= 63 || (hi[a] - lo[a]) as f64 <= (edge as f64).exp2()
        })
    };
    let d = (0..=g.depth).rev().find(|&d| fits(d)).unwrap_or(0);
    let node_of = |a: usize, v: u64| {
        let edge = g.leaf_shift[a] + (g.depth - d) as i32;
        if edge <= 0 {
            v << (-edge) as u32
        } else {
            v >> edge as u32
        }
    };
    let first: [u64; 3] = std::array::from_fn(|a| node_of(a, lo[a]));
    let last: [u64; 3] = std::array::from_fn(|a| node_of(a, hi[a] - 1));
    for z in first[2]..=last[2] {
        for y in first[1]..=last[1] {
            for x in first[0]..=last[0] {
                if classes[node_index(d, [x, y, z])] & all != all {
                    return false;
                }
            }
        }
    }
    true
}

/// The camera frame and its frustum tests, world units.
struct Frustum {
    eye: [f64; 3],
    forward: [f64; 3],
    right: [f64; 3],
    up: [f64; 3],
    tan_x: f64,
    tan_y: f64,
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

impl Frustum {
    fn new(view: &CutView) -> Self {
        let (forward, right, up) = view.camera.basis();
        let tan_y = (view.camera.fov_y_degrees.to_radians() / 2.0).tan();
        Self {
            eye: view.camera.eye,
            forward,
            right,
            up,
            tan_x: tan_y * view.aspect,
            tan_y,
        }
    }

    /// Whether the sphere at `centre` of `radius` lies wholly outside the view frustum.
    fn outside(&self, centre: [f64; 3], radius: f64) -> bool {
        let rel: [f64; 3] = std::array::from_fn(|a| centre[a] - self.eye[a]);
        let z = dot(rel, self.forward);
        if z < -radius {
            return true;
        }
        let x = dot(rel, self.right);
        let y = dot(rel, self.up);
        let side = |u: f64, t: f64| (u.abs() - t * z) / (1.0 + t * t).sqrt() > radius;
        side(x, self.tan_x) || side(y, self.tan_y)
    }

    /// The projected size (image-plane `tan` units) of the sphere at `centre` of `radius`
    /// (paper Eq. 1: `tan(α + β) − tan(α − β)`, `α` the angle of the centre off the view
    /// axis, `sin β = R/|PO|`); infinite when the sphere holds the eye or reaches 90° off the
    /// axis.
    fn projected_size(&self, centre: [f64; 3], radius: f64) -> f64 {
        let rel: [f64; 3] = std::array::from_fn(|a| centre[a] - self.eye[a]);
        let dist = dot(rel, rel).sqrt();
        if dist <= radius {
            return f64::INFINITY;
        }
        let alpha = (dot(rel, self.forward) / dist).clamp(-1.0, 1.0).acos();
        let beta = (radius / dist).asin();
        if alpha + beta >= std::f64::consts::FRAC_PI_2 {
            return f64::INFINITY;
        }
        (alpha + beta).tan() - (alpha - beta).tan()
    }
}

/// The cut of `octree`'s bricks for `view`, whose node class words are `classes`
/// ([`super::residency::node_classes`]).
pub fn brick_cut(octree: &ResidencyOctree, classes: &[u32], view: &CutView) -> BrickCut {
    let g = octree.geometry();
    let frustum = Frustum::new(view);
    let (finest, coarsest) = view.levels;
    let coarsest = coarsest.min(g.level_shape.len() - 1);
    // Image-plane tan units per pixel.
    let pixel = 2.0 * frustum.tan_y / view.height;
    let target = pixel * view.lod_bias.exp2();
    let voxel_edge = |l: usize| {
        (0..3)
            .map(|a| f64::from(1u32 << g.level_shift[l][a]) * view.spacing[a])
            .fold(f64::INFINITY, f64::min)
    };
    let leaf: [f64; 3] = std::array::from_fn(|a| f64::from(g.leaf_shift[a]).exp2());
    let mut cut = BrickCut::default();
    let top = g.level_shape[coarsest];
    let roots: [u64; 3] = std::array::from_fn(|a| top[a].div_ceil(g.brick[a]));
    let mut stack = Vec::new();
    for z in 0..roots[2] {
        for y in 0..roots[1] {
            for x in 0..roots[0] {
                stack.push(Brick {
                    level: coarsest,
                    index: [x, y, z],
                });
            }
        }
    }
    while let Some(b) = stack.pop() {
        let (lo, hi) = voxel_box(g, b);
        if (0..3).any(|a| lo[a] >= hi[a]) {
            continue;
        }
        let half: [f64; 3] =
            std::array::from_fn(|a| (hi[a] - lo[a]) as f64 * view.spacing[a] / 2.0);
        let centre: [f64; 3] = std::array::from_fn(|a| lo[a] as f64 * view.spacing[a] + half[a]);
        let radius = dot(half, half).sqrt();
        if frustum.outside(centre, radius) {
            cut.outside += 1;
            continue;
        }
        if box_is_empty(octree, classes, lo, hi) {
            cut.empty += 1;
            continue;
        }
        // Refine while a voxel of the next finer level still covers `target`.
        let refine = b.level > finest && {
            let size = frustum.projected_size(centre, radius);
            size * voxel_edge(b.level - 1) / (2.0 * radius) >= target
        };
        if refine {
            let fine = b.level - 1;
            let ratio: [u64; 3] = std::array::from_fn(|a| {
                1u64 << (g.level_shift[b.level][a] - g.level_shift[fine][a])
            });
            let bricks: [u64; 3] =
                std::array::from_fn(|a| g.level_shape[fine][a].div_ceil(g.brick[a]));
            for dz in 0..ratio[2] {
                for dy in 0..ratio[1] {
                    for dx in 0..ratio[0] {
                        let index = [
                            b.index[0] * ratio[0] + dx,
                            b.index[1] * ratio[1] + dy,
                            b.index[2] * ratio[2] + dz,
                        ];
                        if (0..3).all(|a| index[a] < bricks[a]) {
                            stack.push(Brick { level: fine, index });
                        }
                    }
                }
            }
            continue;
        }
        cut.boxes.push(SegmentBox {
            lo: std::array::from_fn(|a| (lo[a] as f64 / leaf[a]) as f32 - HAIR),
            payload: segment_payload(OCCUPANCY_NONEMPTY, 0, b.level as u32),
            hi: std::array::from_fn(|a| (hi[a] as f64 / leaf[a]) as f32 + HAIR),
            pad0: 0,
        });
    }
    cut
}
