//! The methods that rasterise ray segment lists: SparseLeap's occupancy geometry is exact (the
//! class of the deepest box over every occupancy leaf is the leaf's own) and nests boxes only
//! where the class changes; the rasterize method's cut refines by projected size, culls
//! empty bricks and bricks outside the view; both skip what ours skips; and a pixel whose list
//! does not fit the pool is marched whole, still matching the reference.

use std::sync::Arc;

use crate::render_common::*;
use residency_viewer::gpu::brick_cut::{CutView, brick_cut};
use residency_viewer::gpu::contract::{OCCUPANCY_EMPTY, OCCUPANCY_NONEMPTY, OCCUPANCY_UNKNOWN};
use residency_viewer::gpu::occupancy::{leaf_class, occupancy_geometry};
use residency_viewer::gpu::renderer::{Method, RenderOptions};
use residency_viewer::gpu::residency::node_classes;
use residency_viewer::gpu::synthetic::SyntheticSource;
use residency_viewer::octree::{ResidencyOctree, node_index};
use residency_viewer::scene::{ChannelStyle, Filter, RenderMode, Scene};
use residency_viewer::source::{BrickKey, BrickSource, SampleType};

/// 32³ voxels, bricks 16³, min/max cells of 4: data (1000) in the octant x ≥ 16, y < 16,
/// z < 16 except its 8³ corner at x ≥ 24, y ≥ 8, z ≥ 8, which is 0 like everything else; the
/// data keeps one voxel from the faces of those boxes, so that the cells' one-voxel halos
/// leave every 8³ leaf outside it empty.
fn octant() -> SyntheticSource {
    SyntheticSource::new(
        SampleType::U16,
        [32, 32, 32],
        [1.0; 3],
        [16; 3],
        4,
        1,
        |_, [x, y, z]| {
            let inside = (17..31).contains(&x) && (1..15).contains(&y) && (1..15).contains(&z);
            let hole = x >= 23 && y >= 7 && z >= 7;
            if inside && !hole { 1000.0 } else { 0.0 }
        },
    )
}

fn style() -> ChannelStyle {
    ramp(0, [1.0, 0.8, 0.4], 100.0, 1000.0, 0.3)
}

/// The class of the deepest box holding point `p` (leaf units), ties to the class that is not
/// empty, as the ray caster reads a list.
fn class_at(boxes: &[residency_viewer::gpu::contract::SegmentBox], p: [f32; 3]) -> u32 {
    let mut best: Option<(u32, u32)> = None;
    for b in boxes {
        if (0..3).all(|a| b.lo[a] <= p[a] && p[a] < b.hi[a]) {
            let (class, depth) = (b.payload & 3, (b.payload >> 4) & 15);
            if best.is_none_or(|(c, d)| {
                depth > d || (depth == d && class != OCCUPANCY_EMPTY && c == OCCUPANCY_EMPTY)
            }) {
                best = Some((class, depth));
            }
        }
    }
    best.expect("the root holds every point").0
}

#[test]
fn occupancy_geometry_is_exact_and_nests_where_the_class_changes() {
    let src = octant();
    let info = src.info();
    let styles = vec![Some(style())];
    // Leaves of 8³ (depth 2): the octant is one depth-1 node of 8 leaves, 7 with data.
    let mut tree = ResidencyOctree::new(info, &[0], 2).unwrap();
    // The classes depend on the ranges and styles only, not on what is resident.
    let classes = node_classes(&tree, &styles, RenderMode::Dvr);
    let geometry = occupancy_geometry(&tree, &classes);
    // Nothing resident: the leaves with data are unknown.
    assert_eq!(geometry.leaves, [57, 0, 7]);
    // Root (empty, 57 of 64), the octant (unknown, 7 of 8), its empty corner leaf.
    let summary: Vec<(u32, u32)> = geometry
        .boxes
        .iter()
        .map(|b| (b.payload & 3, (b.payload >> 4) & 15))
        .collect();
    assert_eq!(
        summary,
        [
            (OCCUPANCY_EMPTY, 0),
            (OCCUPANCY_UNKNOWN, 1),
            (OCCUPANCY_EMPTY, 2)
        ]
    );
    assert_eq!(geometry.boxes[1].lo, [2.0 - 1e-3, -1e-3, -1e-3]);
    assert_eq!(geometry.boxes[2].hi, [4.0 - 1e-3, 2.0 - 1e-3, 2.0 - 1e-3]);
    // Level-0 brick (x 1, y 0, z 0) resident: the octant's leaves are non-empty.
    tree.insert(BrickKey {
        level: 0,
        channel: 0,
        brick: [0, 0, 1],
    })
    .unwrap();
    let geometry = occupancy_geometry(&tree, &classes);
    assert_eq!(geometry.leaves, [57, 7, 0]);
    assert_eq!(geometry.boxes.len(), 3);
    assert_eq!(geometry.boxes[1].payload & 3, OCCUPANCY_NONEMPTY);
    // Every leaf's class is the deepest box's over its centre.
    for z in 0..4u64 {
        for y in 0..4u64 {
            for x in 0..4u64 {
                let centre = [x, y, z].map(|v| v as f32 + 0.5);
                let own = leaf_class(&tree, &classes, node_index(2, [x, y, z]));
                assert_eq!(class_at(&geometry.boxes, centre), own, "leaf {x} {y} {z}");
            }
        }
    }
}

/// 64³ voxels, bricks 8³ (4 levels: 64, 32, 16, 8 voxels a side), data everywhere but the
/// octant x, y, z < 32.
fn big_octant() -> SyntheticSource {
    SyntheticSource::new(
        SampleType::U8,
        [64, 64, 64],
        [1.0; 3],
        [8; 3],
        8,
        1,
        |_, [x, y, z]| {
            if x < 32 && y < 32 && z < 32 {
                0.0
            } else {
                200.0
            }
        },
    )
}

fn cut_view(eye: [f64; 3], target: [f64; 3], fov: f64) -> CutView {
    let mut cam = camera(eye, target);
    cam.fov_y_degrees = fov;
    CutView {
        camera: cam,
        aspect: 1.0,
        height: 64.0,
        lod_bias: -1.0,
        spacing: [1.0; 3],
        levels: (0, 3),
    }
}

#[test]
fn brick_cut_refines_by_projected_size_and_culls_empty_and_hidden_bricks() {
    let src = big_octant();
    let tree = ResidencyOctree::new(src.info(), &[0], 3).unwrap();
    let classes = node_classes(
        &tree,
        &[Some(ramp(0, [1.0; 3], 50.0, 200.0, 0.3))],
        RenderMode::Dvr,
    );
    let levels = |cut: &residency_viewer::gpu::brick_cut::BrickCut| {
        let mut n = [0usize; 4];
        for b in &cut.boxes {
            n[((b.payload >> 8) & 15) as usize] += 1;
        }
        n
    };
    // Far away (the volume 3 pixels across): the coarsest brick, which holds data.
    let far = brick_cut(
        &tree,
        &classes,
        &cut_view([3000.0, 2000.0, 2500.0], [32.0; 3], 20.0),
    );
    assert_eq!(levels(&far), [0, 0, 0, 1]);
    // 500 voxels away, 20° over 64 pixels: a level-0 voxel covers under half a pixel even at
    // the nearest bricks, a level-1 voxel more, so the cut is level 1 throughout. The empty
    // octant's level-1 brick at the origin is culled; its other seven reach data within their
    // halo (the octant's faces touch data at 32).
    let mid = brick_cut(
        &tree,
        &classes,
        &cut_view([320.7, 320.7, 320.7], [32.0; 3], 20.0),
    );
    assert_eq!(levels(&mid), [0, 63, 0, 0]);
    assert_eq!((mid.empty, mid.outside), (1, 0));
    for b in &mid.boxes {
        // Leaf units of 8 voxels: the culled brick is leaves 0..2 on every axis.
        assert!(
            !(0..3).all(|a| b.hi[a] <= 2.0 + 1e-2),
            "{b:?} lies in the empty brick"
        );
    }
    // Close to a corner: level-0 bricks at the eye, coarser ones further away.
    let near = brick_cut(
        &tree,
        &classes,
        &cut_view([70.0, 70.0, 70.0], [32.0; 3], 60.0),
    );
    // (At 60° the bricks off the view axis project larger on the image plane, Eq. 1's
    // tan(α + β): every brick in view is refined to level 0 here.)
    assert_eq!(levels(&near), [476, 0, 0, 0]);
    // At 25° from 320 voxels, a level-0 voxel covers half a pixel up to 289 voxels away: level 0
    // on the near side, level 1 on the far side.
    let n = levels(&brick_cut(
        &tree,
        &classes,
        &cut_view([217.0, 217.0, 217.0], [32.0; 3], 25.0),
    ));
    assert!(n[0] > 0 && n[1] > 0, "{n:?}");
    // Looking away from the volume: nothing drawn, the coarsest brick culled as hidden.
    let away = brick_cut(
        &tree,
        &classes,
        &cut_view([70.0, 70.0, 70.0], [200.0; 3], 40.0),
    );
    assert!(away.boxes.is_empty());
    assert_eq!((away.outside, away.empty), (1, 0));
}

fn scene_of(style: ChannelStyle) -> Scene {
    Scene {
        camera: camera([-30.0, -45.0, 40.0], [16.0, 16.0, 16.0]),
        channels: vec![style],
        background: [0.02, 0.02, 0.05],
        filter: Filter::Trilinear,
        mode: RenderMode::Dvr,
        clip: residency_viewer::scene::Clip::default(),
    }
}

#[test]
fn segment_methods_skip_what_ours_skips() {
    let src = Arc::new(octant());
    let s = scene_of(style());
    let reference = reference(&src, &s, 48, 48);
    let samples = |method: Method, skipping: bool| {
        let options = RenderOptions {
            method,
            empty_space_skipping: skipping,
            ..full_res(48, 48)
        };
        let (p, img) = render(&src, &s, options, 30);
        let m = check(
            &format!("{}-{skipping}", method.name()),
            &p,
            &img,
            &reference,
        );
        assert!(
            p.converged && m.psnr_db >= 40.0,
            "{}: {}",
            method.name(),
            m.psnr_db
        );
        p.frames.last().unwrap().shader.clone()
    };
    let ours = samples(Method::Residency, true).samples;
    let all = samples(Method::Residency, false).samples;
    for method in [Method::SparseLeap, Method::Rasterize] {
        let c = samples(method, true);
        assert!(c.segment_boxes > 0 && c.empty_nodes_skipped > 0, "{c:?}");
        assert_eq!(c.rays_overflowed, 0);
        assert!(
            (c.samples as f64) <= 1.05 * ours as f64,
            "{}: {} samples, ours {ours}",
            method.name(),
            c.samples
        );
        assert!(
            c.samples * 3 < all,
            "{}: {} of {all}",
            method.name(),
            c.samples
        );
    }
}

/// A checkerboard of 4³ blocks over 128³ voxels (data in the inner 2³ of every other block,
/// so the empty blocks' halos stay empty): SparseLeap's empty boxes alternate with data along
/// every ray, more than the pool's 16 records per pixel. The rays that do not fit are
/// marched whole, and the image still matches the reference.
#[test]
fn overflowing_lists_fall_back_to_whole_rays() {
    let src = Arc::new(SyntheticSource::new(
        SampleType::U8,
        [128, 128, 128],
        [1.0; 3],
        [32; 3],
        4,
        1,
        |_, [x, y, z]| {
            let inner = [x, y, z].iter().all(|v| (1..3).contains(&(v % 4)));
            if inner && (x / 4 + y / 4 + z / 4) % 2 == 0 {
                90.0
            } else {
                0.0
            }
        },
    ));
    let s = Scene {
        camera: camera([-60.0, -90.0, 200.0], [64.0; 3]),
        ..scene_of(ramp(0, [0.9, 0.9, 0.5], 20.0, 90.0, 0.02))
    };
    let reference = reference(&src, &s, 32, 32);
    let options = RenderOptions {
        method: Method::SparseLeap,
        octree_depth: Some(5),
        ..full_res(32, 32)
    };
    let (p, img) = render(&src, &s, options, 30);
    let m = check("overflow", &p, &img, &reference);
    let last = &p.frames.last().unwrap().shader;
    assert!(last.rays_overflowed > 100, "{last:?}");
    assert!(p.converged && m.psnr_db >= 40.0 && m.ssim >= 0.99, "{m:?}");
}
