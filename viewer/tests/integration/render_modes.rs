//! Render modes and clipping. Maximum intensity projection (`Scene::mode`, `mip`): converged
//! GPU renders of every method and both filters match the f64 reference's MIP; skipping is
//! exact, and a node whose largest value cannot raise the ray's maximum is skipped, so the
//! bricks behind a bright front that emission–absorption fetches are never fetched. Clipping
//! (`Scene::clip`: a box, planes, `near`): every method in both modes matches the reference,
//! and no brick outside what is kept is fetched.

use std::sync::Arc;

use crate::render_common::*;
use residency_viewer::gpu::renderer::{Method, RenderOptions};
use residency_viewer::gpu::synthetic::SyntheticSource;
use residency_viewer::metrics;
use residency_viewer::scene::{
    Camera, ChannelStyle, Clip, ClipBox, ClipPlane, Filter, RenderMode, Scene,
};
use residency_viewer::source::SampleType;

fn scene(camera: Camera, channels: Vec<ChannelStyle>, filter: Filter, mode: RenderMode) -> Scene {
    Scene {
        camera,
        channels,
        background: [0.05, 0.05, 0.1],
        filter,
        mode,
        clip: Clip::default(),
    }
}

/// Per channel a ball (30000 at its centre, falling off) over ripples up to 3000, shifted by
/// channel, and a rod of 20000 two voxels thick (a thinner one peaks between the samples of
/// any ray: its maximum is a sampling error of up to a step's slope, which the reference's
/// finer steps do not make): 32³ voxels of u16, bricks 16³.
fn balls(channels: usize) -> Arc<SyntheticSource> {
    Arc::new(SyntheticSource::new(
        SampleType::U16,
        [32, 32, 32],
        [1.0; 3],
        [16; 3],
        8,
        channels,
        move |c, [x, y, z]| {
            let d = [
                x as f64 - 14.5 - 3.0 * c as f64,
                y as f64 - 16.0,
                z as f64 - 17.5 + 2.0 * c as f64,
            ];
            let r2 = d[0] * d[0] + d[1] * d[1] * 1.4 + d[2] * d[2] * 0.8;
            let ripple = 3000.0 * ((x as f64 * 0.6).sin() * (y as f64 * 0.45).cos()).abs();
            let on_rod = (6 + c as u64..8 + c as u64).contains(&x) && (24..26).contains(&z);
            let rod = if on_rod { 20000.0 } else { 0.0 };
            (30000.0 * (-r2 / 40.0).exp()).max(ripple).max(rod)
        },
    ))
}

fn styles(channels: usize) -> Vec<ChannelStyle> {
    let colours = [[1.0, 0.6, 0.2], [0.2, 0.8, 1.0]];
    (0..channels)
        .map(|c| ramp(c, colours[c], 2000.0, 28000.0, 0.3))
        .collect()
}

#[test]
fn mip_matches_its_reference_for_every_method_and_filter() {
    for (channels, eye) in [(1, [-30.0, -40.0, 45.0]), (2, [40.0, 45.0, 30.0])] {
        let src = balls(channels);
        for filter in [Filter::Trilinear, Filter::Tricubic] {
            let mip = scene(
                camera(eye, [16.0, 16.0, 16.0]),
                styles(channels),
                filter,
                RenderMode::Mip,
            );
            let (w, h) = (48, 40);
            let want = reference(&src, &mip, w, h);
            // MIP and DVR differ on this data.
            let dvr = reference(
                &src,
                &Scene {
                    mode: RenderMode::Dvr,
                    ..mip.clone()
                },
                w,
                h,
            );
            let apart = metrics::compare(&want, &dvr).unwrap().psnr_db;
            assert!(apart < 35.0, "MIP and DVR references {apart} dB apart");
            for method in Method::ALL {
                let label = format!("mip-{channels}ch-{}-{}", filter.name(), method.name());
                let options = RenderOptions {
                    method,
                    ..full_res(w as u32, h as u32)
                };
                let (p, img) = render(&src, &mip, options, 40);
                assert!(p.converged, "{label}: {}", p.stop_reason);
                let m = check(&label, &p, &img, &want);
                assert!(m.psnr_db >= 45.0, "{label}: PSNR {}", m.psnr_db);
                assert!(m.ssim >= 0.995, "{label}: SSIM {}", m.ssim);
            }
        }
    }
}

/// A bright front slab (x < 8: 200 to 240) before dimmer matter (at most 180), u8, 32³ in
/// bricks of 8³; a camera on the −x side, every ray entering through the slab.
fn bright_front() -> Arc<SyntheticSource> {
    Arc::new(SyntheticSource::new(
        SampleType::U8,
        [32, 32, 32],
        [1.0; 3],
        [8; 3],
        4,
        1,
        |_, [x, y, z]| {
            if x < 8 {
                220.0 + 20.0 * ((y + z) as f64 * 0.4).sin()
            } else {
                120.0 + 60.0 * (x as f64 * 0.5).sin() * (y as f64 * 0.3 + z as f64 * 0.2).cos()
            }
        },
    ))
}

fn front_scene(mode: RenderMode, opacity: f64) -> Scene {
    scene(
        camera([-40.0, 16.0, 16.0], [16.0, 16.0, 16.0]),
        vec![ramp(0, [0.9, 0.7, 0.3], 100.0, 255.0, opacity)],
        Filter::Trilinear,
        mode,
    )
}

/// Behind the slab every node's largest value (180; 240 only in the node next to the slab,
/// whose halo reaches into it) is below what each ray has already met in the slab, so MIP
/// samples the first two nodes along x only: it fetches the level-0 bricks of x < 16 and, for
/// the footprints of that node's last samples, of 16 ≤ x < 24, never those of x ≥ 24, where
/// emission–absorption of the same faint transfer function fetches all four. Both match their
/// references.
#[test]
fn mip_never_fetches_bricks_that_cannot_raise_the_rays_maximum() {
    let src = bright_front();
    let fetched_x = |mode: RenderMode| {
        let scene = front_scene(mode, 0.02);
        let (p, img) = render(&src, &scene, finest_wanted(32, 32), 30);
        assert!(p.converged, "{mode:?}: {}", p.stop_reason);
        let label = format!("front-{}", mode.name());
        let m = check(&label, &p, &img, &reference(&src, &scene, 32, 32));
        assert!(m.psnr_db >= 45.0, "{label}: PSNR {}", m.psnr_db);
        let mut x: Vec<u64> = p
            .request_log
            .iter()
            .filter(|k| k.level == 0)
            .map(|k| k.brick[2])
            .collect();
        x.sort_unstable();
        x.dedup();
        x
    };
    assert_eq!(fetched_x(RenderMode::Dvr), [0, 1, 2, 3]);
    assert_eq!(fetched_x(RenderMode::Mip), [0, 1, 2]);
}

/// Skipping changes no pixel beyond the step's placement (the same image within 50 dB) and
/// takes fewer samples: behind the slab every node is skipped by the ray's maximum, although
/// the transfer function shows every value there (100 to 255 ramps up from 0).
#[test]
fn mip_skipping_is_exact_and_skips_by_the_rays_maximum() {
    let src = bright_front();
    let scene = front_scene(RenderMode::Mip, 0.5);
    let want = reference(&src, &scene, 32, 32);
    let run = |skipping: bool| {
        let options = RenderOptions {
            empty_space_skipping: skipping,
            ..full_res(32, 32)
        };
        let (p, img) = render(&src, &scene, options, 30);
        assert!(p.converged, "{skipping}: {}", p.stop_reason);
        let m = check(&format!("mip-skip-{skipping}"), &p, &img, &want);
        assert!(m.psnr_db >= 45.0, "{skipping}: PSNR {}", m.psnr_db);
        (p.frames.last().unwrap().shader.clone(), img)
    };
    let (with, skipped) = run(true);
    let (without, marched) = run(false);
    let same = metrics::compare(&skipped, &marched).unwrap().psnr_db;
    assert!(same >= 50.0, "{same} dB");
    assert!(with.empty_nodes_skipped > 0);
    // Half the bricks are read (the two nodes along x that the ray's maximum leaves), and
    // about two thirds of the samples taken (measured 29,100 against 45,040).
    assert_eq!((with.bricks_used, without.bricks_used), (32, 64));
    assert!(
        with.samples * 3 < without.samples * 2,
        "{} samples with skipping, {} without",
        with.samples,
        without.samples
    );
}

/// A box, a slanted plane and `near`: every method in both modes matches the reference of the
/// same clipping (which cuts each ray's span in f64 by the same rule).
#[test]
fn clipping_matches_the_reference_in_every_mode_and_method() {
    let src = balls(2);
    let clip = Clip {
        region: Some(ClipBox {
            min: [2.0, 4.0, 0.0],
            max: [30.0, 30.0, 21.0],
        }),
        planes: vec![ClipPlane {
            point: [16.0, 16.0, 16.0],
            normal: [1.0, -0.5, 0.3],
        }],
        near: Some(34.0),
    };
    let (w, h) = (48, 40);
    for mode in RenderMode::ALL {
        let clipped = Scene {
            clip: clip.clone(),
            ..scene(
                camera([40.0, 45.0, 30.0], [16.0, 16.0, 16.0]),
                styles(2),
                Filter::Trilinear,
                mode,
            )
        };
        let want = reference(&src, &clipped, w, h);
        let whole = reference(
            &src,
            &Scene {
                clip: Clip::default(),
                ..clipped.clone()
            },
            w,
            h,
        );
        let apart = metrics::compare(&want, &whole).unwrap().psnr_db;
        assert!(apart < 30.0, "{mode:?}: clipped and whole {apart} dB apart");
        for method in Method::ALL {
            let label = format!("clip-{}-{}", mode.name(), method.name());
            let options = RenderOptions {
                method,
                ..full_res(w as u32, h as u32)
            };
            let (p, img) = render(&src, &clipped, options, 40);
            assert!(p.converged, "{label}: {}", p.stop_reason);
            let m = check(&label, &p, &img, &want);
            assert!(m.psnr_db >= 45.0, "{label}: PSNR {}", m.psnr_db);
        }
    }
}

/// Clipped to x ≤ 12 and y ≤ 14 (world = voxels), no sample's footprint reaches a level-0
/// voxel at x or y 16 or beyond: of the 64 level-0 bricks only those of x and y index 0 and 1
/// are fetched, in both modes, and the images match the reference.
#[test]
fn bricks_outside_the_clipping_are_never_fetched() {
    let src = bright_front();
    for mode in RenderMode::ALL {
        let scene = Scene {
            clip: Clip {
                region: Some(ClipBox {
                    min: [0.0, 0.0, 0.0],
                    max: [12.0, 32.0, 32.0],
                }),
                planes: vec![ClipPlane {
                    point: [0.0, 14.0, 0.0],
                    normal: [0.0, -1.0, 0.0],
                }],
                near: None,
            },
            ..front_scene(mode, 0.02)
        };
        let (p, img) = render(&src, &scene, finest_wanted(32, 32), 30);
        assert!(p.converged, "{mode:?}: {}", p.stop_reason);
        let label = format!("clip-front-{}", mode.name());
        let m = check(&label, &p, &img, &reference(&src, &scene, 32, 32));
        assert!(m.psnr_db >= 45.0, "{label}: PSNR {}", m.psnr_db);
        let level0: Vec<_> = p.request_log.iter().filter(|k| k.level == 0).collect();
        assert!(!level0.is_empty(), "{mode:?}");
        assert!(
            level0.iter().all(|k| k.brick[2] <= 1 && k.brick[1] <= 1),
            "{mode:?}: {level0:?}"
        );
    }
}
