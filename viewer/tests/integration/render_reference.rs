//! Converged GPU renders match the f64 reference (`reference::render`, level 0, step ¼
//! voxel): PSNR ≥ 40 dB and SSIM ≥ 0.99 for 1, 3 and 16 channels, u8/u16/i16/u32/f32, with the
//! camera outside, inside and on a brick boundary, and with rays parallel to an axis. Renders
//! are forced to level 0 (the reference's resolution) and must converge (no request left).

use std::sync::Arc;

use crate::render_common::*;
use residency_viewer::defaults::DEFAULT_COLOURS;
use residency_viewer::gpu::synthetic::SyntheticSource;
use residency_viewer::scene::{Camera, ChannelStyle, Scene};
use residency_viewer::source::SampleType;

const MIN_PSNR: f64 = 40.0;
const MIN_SSIM: f64 = 0.99;

/// A blob plus ripples over 32³ voxels (bricks 16³): value in `[0, scale]`, per channel
/// shifted so channels differ.
fn blob(t: SampleType, scale: f64, offset: f64, channels: usize) -> Arc<SyntheticSource> {
    Arc::new(SyntheticSource::new(
        t,
        [32, 32, 32],
        [1.0; 3],
        [16; 3],
        8,
        channels,
        move |c, [x, y, z]| {
            let cc = c as f64 * 4.0;
            let d = [
                x as f64 - 15.5 + cc,
                y as f64 - 13.0,
                z as f64 - 17.0 + cc * 0.5,
            ];
            let r2 = d[0] * d[0] + d[1] * d[1] * 1.5 + d[2] * d[2] * 0.7;
            offset + scale * (-r2 / 60.0).exp() + scale * 0.1 * ((x as f64) * 0.7).sin().abs()
        },
    ))
}

fn scene(camera: Camera, channels: Vec<ChannelStyle>) -> Scene {
    Scene {
        camera,
        channels,
        background: [0.05, 0.05, 0.1],
        filter: residency_viewer::scene::Filter::Trilinear,
        mode: residency_viewer::scene::RenderMode::Dvr,
        clip: residency_viewer::scene::Clip::default(),
    }
}

fn assert_matches(label: &str, src: &Arc<SyntheticSource>, scene: &Scene, w: u32, h: u32) {
    let (p, img) = render(src, scene, full_res(w, h), 30);
    let reference = reference(src, scene, w as usize, h as usize);
    let m = check(label, &p, &img, &reference);
    assert!(p.converged, "{label}: {}", p.stop_reason);
    assert!(p.failed.is_empty());
    assert!(m.psnr_db >= MIN_PSNR, "{label}: PSNR {}", m.psnr_db);
    assert!(m.ssim >= MIN_SSIM, "{label}: SSIM {}", m.ssim);
}

#[test]
fn u8_one_channel_camera_outside() {
    let src = blob(SampleType::U8, 220.0, 0.0, 1);
    let s = scene(
        camera([-30.0, -40.0, 45.0], [16.0, 16.0, 16.0]),
        vec![ramp(0, [1.0, 0.8, 0.3], 30.0, 220.0, 0.3)],
    );
    assert_matches("u8-outside", &src, &s, 64, 64);
}

#[test]
fn u16_one_channel_camera_inside() {
    let src = blob(SampleType::U16, 60000.0, 1000.0, 1);
    let s = scene(
        camera([20.5, 9.3, 14.2], [0.0, 30.0, 20.0]),
        vec![ramp(0, [0.3, 0.9, 1.0], 9000.0, 61000.0, 0.2)],
    );
    assert_matches("u16-inside", &src, &s, 64, 48);
}

#[test]
fn f32_one_channel_negative_values() {
    let src = blob(SampleType::F32, 3.75, -1.25, 1);
    let s = scene(
        camera([50.0, 20.0, -20.0], [16.0, 16.0, 16.0]),
        vec![ramp(0, [1.0, 0.4, 0.9], -0.5, 2.5, 0.25)],
    );
    assert_matches("f32-outside", &src, &s, 48, 64);
}

#[test]
fn u16_three_channels() {
    let src = blob(SampleType::U16, 40000.0, 0.0, 3);
    let s = scene(
        camera([-25.0, 50.0, 40.0], [16.0, 16.0, 16.0]),
        vec![
            ramp(0, [1.0, 0.1, 0.1], 8000.0, 40000.0, 0.15),
            ramp(1, [0.1, 1.0, 0.1], 15000.0, 30000.0, 0.25),
            ramp(2, [0.1, 0.2, 1.0], 5000.0, 45000.0, 0.1),
        ],
    );
    assert_matches("u16-3ch", &src, &s, 64, 64);
}

#[test]
fn f32_three_channels_camera_on_brick_boundary() {
    // The eye sits exactly on the x = 16 and z = 16 brick faces, inside the volume.
    let src = blob(SampleType::F32, 1.0, 0.0, 3);
    let s = scene(
        camera([16.0, 3.5, 16.0], [10.0, 30.0, 18.0]),
        vec![
            ramp(0, [1.0, 0.3, 0.1], 0.2, 1.0, 0.2),
            ramp(1, [0.1, 1.0, 0.3], 0.3, 0.9, 0.3),
            ramp(2, [0.2, 0.3, 1.0], 0.1, 1.1, 0.1),
        ],
    );
    assert_matches("f32-3ch-boundary", &src, &s, 64, 64);
}

#[test]
fn u8_axis_parallel_rays_along_brick_faces() {
    // Odd image: the centre pixel's ray is exactly +x, running along the y = 16 and z = 16
    // brick faces; the whole centre row and column are parallel to a coordinate plane.
    let src = blob(SampleType::U8, 220.0, 0.0, 1);
    let mut cam = camera([-20.0, 16.0, 16.0], [40.0, 16.0, 16.0]);
    cam.fov_y_degrees = 30.0;
    let s = scene(cam, vec![ramp(0, [1.0, 0.8, 0.3], 30.0, 220.0, 0.3)]);
    assert_matches("u8-axis-x", &src, &s, 63, 63);
    // Looking straight down −z from above.
    let s = scene(
        camera([16.0, 16.0, 60.0], [16.0, 16.0, 0.0]),
        vec![ramp(0, [1.0, 0.8, 0.3], 30.0, 220.0, 0.3)],
    );
    assert_matches("u8-axis-z", &src, &s, 63, 63);
}

#[test]
fn homogeneous_nodes_integrate_analytically() {
    // A constant volume: every node has min == max and is integrated in closed form.
    let src = Arc::new(SyntheticSource::new(
        SampleType::U16,
        [32, 32, 32],
        [1.0; 3],
        [16; 3],
        8,
        1,
        |_, _| 1000.0,
    ));
    let s = scene(
        camera([-20.0, 50.0, 40.0], [16.0, 16.0, 16.0]),
        vec![ramp(0, [0.5, 1.0, 0.5], 0.0, 2000.0, 0.05)],
    );
    let (p, img) = render(&src, &s, full_res(32, 32), 10);
    let m = check("homogeneous", &p, &img, &reference(&src, &s, 32, 32));
    let last = p.frames.last().unwrap();
    assert!(last.shader.homogeneous_nodes > 0);
    assert_eq!(last.shader.samples, last.shader.homogeneous_nodes);
    // Nothing to fetch: a homogeneous node needs no brick.
    assert!(src.fetch_log().iter().all(|k| k.level == 0));
    assert!(m.psnr_db >= 60.0, "{}", m.psnr_db);
}

/// Sixteen u16 channels over 32³ voxels (bricks 16³): channels below `constant_from` are the
/// blob of channel `c`, the others constant (1000 × (c + 1)).
fn sixteen(constant_from: usize) -> Arc<SyntheticSource> {
    Arc::new(SyntheticSource::new(
        SampleType::U16,
        [32, 32, 32],
        [1.0; 3],
        [16; 3],
        8,
        16,
        move |c, [x, y, z]| {
            if c >= constant_from {
                return 1000.0 * (c + 1) as f64;
            }
            let cc = c as f64 * 1.5;
            let d = [x as f64 - 10.0 - cc, y as f64 - 13.0, z as f64 - 17.0];
            let r2 = d[0] * d[0] + d[1] * d[1] * 1.5 + d[2] * d[2] * 0.7;
            40000.0 * (-r2 / 60.0).exp()
        },
    ))
}

/// Channel `c`'s colour: the viewer's default for a store that gives none.
fn hue(c: usize) -> [f64; 3] {
    DEFAULT_COLOURS[c % DEFAULT_COLOURS.len()]
}

#[test]
fn sixteen_channels_varying_constant_and_empty() {
    // Channels 8-15 keep their levels in the upper words of the shader's packed levels and
    // their class bits in the upper half of the node's class word: varying ones (8-11),
    // constant ones (12-14) and one empty under its TF (15) all match the reference.
    let src = sixteen(12);
    let mut styles: Vec<ChannelStyle> = (0..16)
        .map(|c| ramp(c, hue(c), 4000.0, 40000.0, 0.08))
        .collect();
    styles[15] = ramp(15, hue(15), 30000.0, 40000.0, 0.5);
    let s = scene(camera([-25.0, 50.0, 40.0], [16.0, 16.0, 16.0]), styles);
    assert_matches("u16-16ch", &src, &s, 48, 48);

    // Channels 0-7 empty under their TFs (windows above the blobs' peak) and 8-15 constant:
    // every node is homogeneous, so every step integrates one in closed form.
    let src = sixteen(8);
    let styles = (0..16)
        .map(|c| {
            let (lo, hi) = if c < 8 {
                (50000.0, 60000.0)
            } else {
                (0.0, 20000.0)
            };
            ramp(c, hue(c), lo, hi, 0.02)
        })
        .collect();
    let s = scene(camera([-20.0, 50.0, 40.0], [16.0, 16.0, 16.0]), styles);
    let (p, img) = render(&src, &s, full_res(32, 32), 10);
    let m = check("16ch-homogeneous", &p, &img, &reference(&src, &s, 32, 32));
    let last = p.frames.last().unwrap();
    assert!(last.shader.homogeneous_nodes > 0);
    assert_eq!(last.shader.samples, last.shader.homogeneous_nodes);
    // 58.7 dB measured (one constant channel reaches 60 dB; eight add up their opacity).
    assert!(m.psnr_db >= 55.0, "{}", m.psnr_db);
}

#[test]
fn anisotropic_spacing_and_shape() {
    // z spacing 2, x/y 0.5, 16 × 48 × 40 voxels: the octree root is not a cube in voxels.
    let src = Arc::new(SyntheticSource::new(
        SampleType::U16,
        [16, 48, 40],
        [2.0, 0.5, 0.5],
        [8, 16, 16],
        8,
        1,
        |_, [x, y, z]| {
            1000.0 + 800.0 * (x as f64 * 0.3).sin() * (y as f64 * 0.2).cos() + 60.0 * z as f64
        },
    ));
    let s = scene(
        camera([-15.0, -10.0, 45.0], [10.0, 12.0, 16.0]),
        vec![ramp(0, [0.9, 0.6, 1.0], 900.0, 2500.0, 0.1)],
    );
    assert_matches("anisotropic", &src, &s, 64, 48);
}

#[test]
fn coarse_level_addressing_matches_a_reference_of_that_level() {
    // Render level 1 of a 64³ volume and compare with the reference of a volume whose level
    // 0 is that level 1 (voxels twice as large, same world box). The reference step Δ₀ of
    // that volume is 2 instead of 1, so its plateau opacity is 1 − (1 − a)².
    let fine = Arc::new(SyntheticSource::new(
        SampleType::U8,
        [64, 64, 64],
        [1.0; 3],
        [16; 3],
        8,
        1,
        |_, [x, y, z]| {
            let d = [x as f64 - 30.0, y as f64 - 34.0, z as f64 - 31.0];
            180.0 * (-(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) / 300.0).exp()
                + 40.0 * (x as f64 * 0.2).sin().abs()
        },
    ));
    let f2 = fine.clone();
    let coarse = Arc::new(SyntheticSource::new(
        SampleType::U8,
        [32, 32, 32],
        [2.0; 3],
        [16; 3],
        8,
        1,
        move |_, xyz| f2.value(0, 1, xyz),
    ));
    let plateau = |a: f64| {
        vec![
            residency_viewer::scene::OpacityPoint {
                value: 99.0,
                opacity: 0.0,
            },
            residency_viewer::scene::OpacityPoint {
                value: 100.0,
                opacity: a,
            },
        ]
    };
    let cam = camera([-40.0, 90.0, 70.0], [32.0, 32.0, 32.0]);
    let mut style = ramp(0, [1.0, 0.5, 0.2], 0.0, 1.0, 0.0);
    style.opacity = plateau(0.1);
    let s = scene(cam.clone(), vec![style.clone()]);
    let options = residency_viewer::gpu::renderer::RenderOptions {
        level_bounds: vec![(1, 1)],
        ..full_res(64, 64)
    };
    let (p, img) = render(&fine, &s, options, 20);
    assert!(p.converged);
    assert!(fine.fetch_log().iter().all(|k| k.level == 1));
    style.opacity = plateau(1.0 - 0.9f64.powi(2));
    let s2 = scene(cam, vec![style]);
    let m = check("coarse-level", &p, &img, &reference(&coarse, &s2, 64, 64));
    assert!(m.psnr_db >= 35.0, "{}", m.psnr_db);
    assert!(m.ssim >= 0.98, "{}", m.ssim);
}

#[test]
fn signed_and_u32_formats() {
    // i16 (the `texture_3d<i32>` atlas) with negative values, and u32.
    let src = blob(SampleType::I16, 20000.0, -8000.0, 1);
    let s = scene(
        camera([45.0, -20.0, 30.0], [16.0, 16.0, 16.0]),
        vec![ramp(0, [0.4, 1.0, 0.6], -2000.0, 12000.0, 0.2)],
    );
    assert_matches("i16", &src, &s, 48, 48);
    let src = blob(SampleType::U32, 3.0e6, 1.0e5, 1);
    let s = scene(
        camera([45.0, -20.0, 30.0], [16.0, 16.0, 16.0]),
        vec![ramp(0, [0.4, 1.0, 0.6], 5.0e5, 3.0e6, 0.2)],
    );
    assert_matches("u32", &src, &s, 48, 48);
}
