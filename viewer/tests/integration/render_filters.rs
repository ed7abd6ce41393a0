//! The tricubic filter (`Scene::filter`): converged GPU renders of every method match the f64
//! tricubic reference (PSNR ≥ 40 dB, SSIM ≥ 0.99) and are measurably closer to it than to the
//! trilinear reference; the culling ranges are widened by the filter's reach, so a region next
//! to bright voxels that trilinear culls is kept for tricubic, for nodes and for clear bricks.

use std::sync::Arc;

use crate::render_common::*;
use residency_viewer::gpu::renderer::{Method, RenderOptions, is_clear};
use residency_viewer::gpu::synthetic::SyntheticSource;
use residency_viewer::metrics;
use residency_viewer::octree::{ResidencyOctree, node_index};
use residency_viewer::scene::{Camera, ChannelStyle, Filter, RenderMode, Scene};
use residency_viewer::source::{BrickKey, BrickSource, SampleType};

/// A ball of radius 6 and a rod one voxel thin along z, both 30000 in 0 (one per channel,
/// shifted): 32³ voxels, bricks 16³. Trilinear samples on the rod's axis read 30000; the
/// B-spline spreads it over its neighbours (at most (4/6)² of it), so the rod vanishes under a
/// threshold of 12000 to 18000 and the ball's edge moves.
fn ball_and_rod(channels: usize) -> Arc<SyntheticSource> {
    Arc::new(SyntheticSource::new(
        SampleType::U16,
        [32, 32, 32],
        [1.0; 3],
        [16; 3],
        8,
        channels,
        move |c, [x, y, z]| {
            let d = [
                x as f64 - 15.5,
                y as f64 - 14.0 + c as f64 * 3.0,
                z as f64 - 16.5,
            ];
            let ball = d[0] * d[0] + d[1] * d[1] + d[2] * d[2] < 36.0;
            let rod = x == 7 + c as u64 && y == 22;
            if ball || rod { 30000.0 } else { 0.0 }
        },
    ))
}

fn scene(camera: Camera, channels: Vec<ChannelStyle>, filter: Filter) -> Scene {
    Scene {
        camera,
        channels,
        background: [0.05, 0.05, 0.1],
        filter,
        mode: RenderMode::Dvr,
        clip: residency_viewer::scene::Clip::default(),
    }
}

fn styles(channels: usize) -> Vec<ChannelStyle> {
    let colours = [[1.0, 0.6, 0.2], [0.2, 0.8, 1.0]];
    (0..channels)
        .map(|c| ramp(c, colours[c], 12000.0, 18000.0, 0.6))
        .collect()
}

#[test]
fn tricubic_matches_its_reference_for_every_method() {
    for (channels, eye) in [(1, [-30.0, -40.0, 45.0]), (2, [40.0, 45.0, 30.0])] {
        let src = ball_and_rod(channels);
        let cubic = scene(
            camera(eye, [16.0, 18.0, 16.0]),
            styles(channels),
            Filter::Tricubic,
        );
        let linear = Scene {
            filter: Filter::Trilinear,
            ..cubic.clone()
        };
        let (w, h) = (48, 40);
        let cubic_ref = reference(&src, &cubic, w, h);
        let linear_ref = reference(&src, &linear, w, h);
        // The filters differ on this data: the rod is gone, the ball smaller.
        let apart = metrics::compare(&cubic_ref, &linear_ref).unwrap().psnr_db;
        assert!(apart < 35.0, "references only {apart} dB apart");
        for method in Method::ALL {
            let label = format!("tricubic-{}ch-{}", channels, method.name());
            let options = RenderOptions {
                method,
                ..full_res(w as u32, h as u32)
            };
            let (p, img) = render(&src, &cubic, options, 40);
            assert!(p.converged, "{label}: {}", p.stop_reason);
            let m = check(&label, &p, &img, &cubic_ref);
            assert!(m.psnr_db >= 40.0, "{label}: PSNR {}", m.psnr_db);
            assert!(m.ssim >= 0.99, "{label}: SSIM {}", m.ssim);
            let off = metrics::compare(&img, &linear_ref).unwrap().psnr_db;
            assert!(
                m.psnr_db > off + 6.0,
                "{label}: {} dB to the tricubic reference, {off} dB to the trilinear one",
                m.psnr_db
            );
        }
    }
}

/// One bright plane at x = 9, zeros elsewhere: 32³ voxels, min/max cells of 8³ (halo 1),
/// bricks of 8³, so cell and brick x ∈ [0, 8) ends one voxel before the halo reaches x = 9.
fn plane() -> SyntheticSource {
    SyntheticSource::new(
        SampleType::U16,
        [32, 32, 32],
        [1.0; 3],
        [8; 3],
        8,
        1,
        |_, [x, _, _]| if x == 9 { 1000.0 } else { 0.0 },
    )
}

#[test]
fn culling_ranges_widen_by_the_filters_reach() {
    let src = plane();
    let info = src.info();
    // Leaves of 8³ voxels (depth 2 over 32³): leaf x = 0 holds voxels 0..8.
    for (filter, expected) in [(Filter::Trilinear, 0.0), (Filter::Tricubic, 1000.0)] {
        let tree = ResidencyOctree::for_filter(info, &[0], 2, filter.reach()).unwrap();
        let leaf = node_index(2, [0, 1, 1]);
        assert_eq!(tree.range(leaf, 0), (0.0, expected), "{filter:?}");
        // Leaf x = 3 (voxels 24..32) is 15 voxels from the plane: empty for both.
        assert_eq!(tree.range(node_index(2, [3, 1, 1]), 0), (0.0, 0.0));
    }
    // Brick x = 0: trilinear footprints reaching it read voxels -1..9, tricubic ones -3..11.
    let style = ramp(0, [1.0; 3], 100.0, 1000.0, 0.5);
    let key = BrickKey {
        level: 0,
        channel: 0,
        brick: [1, 1, 0],
    };
    assert!(is_clear(
        info,
        &style,
        RenderMode::Dvr,
        &key,
        Filter::Trilinear
    ));
    assert!(!is_clear(
        info,
        &style,
        RenderMode::Dvr,
        &key,
        Filter::Tricubic
    ));
    // Brick x = 3 (voxels 24..32): far away, clear for both.
    let far = BrickKey {
        brick: [1, 1, 3],
        ..key
    };
    assert!(is_clear(
        info,
        &style,
        RenderMode::Dvr,
        &far,
        Filter::Tricubic
    ));
}
