//! The limit probe (`gpu::probe`): the same rays, step, transfer functions and compositing as
//! the renderer through one level-0 texture. Its image matches the f64 reference as the
//! renderer's does, with filtering by hand and, where the device filters `R32Float`, by the
//! texture unit; it counts its samples; a volume over the device's 3D texture limit is refused
//! with a message naming it.

use std::sync::Arc;

use crate::render_common::*;
use residency_viewer::gpu::probe::{LimitProbe, ProbeFilter};
use residency_viewer::gpu::synthetic::SyntheticSource;
use residency_viewer::image::RgbImage;
use residency_viewer::metrics;
use residency_viewer::scene::Scene;
use residency_viewer::source::{BrickSource, SampleType};

fn source(channels: usize) -> Arc<SyntheticSource> {
    Arc::new(SyntheticSource::new(
        SampleType::U16,
        [40, 32, 24],
        [1.0, 1.0, 1.5],
        [16; 3],
        8,
        channels,
        |c, [x, y, z]| {
            let d = [
                x as f64 - 20.0 + c as f64 * 5.0,
                y as f64 - 14.0,
                z as f64 - 11.0,
            ];
            40000.0 * (-(d[0] * d[0] + d[1] * d[1] + 2.0 * d[2] * d[2]) / 80.0).exp()
        },
    ))
}

fn image(w: u32, h: u32, pixels: &[[f32; 4]]) -> RgbImage {
    RgbImage {
        width: w as usize,
        height: h as usize,
        pixels: pixels.iter().map(|p| [p[0], p[1], p[2]]).collect(),
    }
}

#[test]
fn probe_images_match_the_reference_and_count_their_samples() {
    let src = source(2);
    let scene = Scene {
        camera: camera([-30.0, -25.0, 50.0], [20.0, 16.0, 18.0]),
        channels: vec![
            ramp(0, [1.0, 0.5, 0.2], 2000.0, 40000.0, 0.2),
            ramp(1, [0.2, 0.6, 1.0], 2000.0, 40000.0, 0.2),
        ],
        background: [0.0, 0.0, 0.1],
        filter: residency_viewer::scene::Filter::Trilinear,
        mode: residency_viewer::scene::RenderMode::Dvr,
        clip: residency_viewer::scene::Clip::default(),
    };
    let (w, h) = (48, 40);
    let reference = reference(&src, &scene, w as usize, h as usize);
    let gpu = gpu();
    let probe = LimitProbe::new(gpu, src.as_ref(), &scene, w, h, 0.5).expect("probe");
    let filters = probe.filters();
    assert_eq!(filters[0], ProbeFilter::Manual);
    let mut counts = Vec::new();
    for filter in filters {
        let frame = probe.render(gpu, &scene.camera, filter).expect("frame");
        let m = metrics::compare(&image(w, h, &frame.pixels), &reference).expect("compare");
        eprintln!(
            "probe {}: {} samples, PSNR {:.2} dB, SSIM {:.5}, GPU {:?} ms",
            filter.name(),
            frame.samples,
            m.psnr_db,
            m.ssim,
            frame.gpu_time_ms
        );
        let min_psnr = if filter == ProbeFilter::Manual {
            40.0
        } else {
            30.0
        };
        assert!(
            m.psnr_db >= min_psnr && m.ssim >= 0.99,
            "{}: {m:?}",
            filter.name()
        );
        assert_eq!(frame.gpu_time_ms.is_some(), gpu.timestamps);
        counts.push(frame.samples);
    }
    // Samples (each of both channels): at least one per pixel whose ray crosses the volume,
    // and the same rays with either filter within early termination's difference.
    assert!(counts[0] > u64::from(w * h), "{counts:?}");
    for &c in &counts[1..] {
        assert!(c.abs_diff(counts[0]) * 100 <= counts[0], "{counts:?}");
    }
}

#[test]
fn a_volume_over_the_texture_limit_is_refused() {
    let src = source(1);
    let scene = Scene {
        camera: camera([-30.0, -25.0, 50.0], [20.0, 16.0, 18.0]),
        channels: vec![ramp(0, [1.0, 1.0, 1.0], 0.0, 40000.0, 0.2)],
        background: [0.0; 3],
        filter: residency_viewer::scene::Filter::Trilinear,
        mode: residency_viewer::scene::RenderMode::Dvr,
        clip: residency_viewer::scene::Clip::default(),
    };
    let mut small = new_gpu();
    small.limits.max_texture_dimension_3d = 16;
    let e = LimitProbe::new(&small, src.as_ref(), &scene, 8, 8, 0.5)
        .err()
        .expect("refused");
    assert_eq!(
        residency_viewer::error_chain(&e),
        format!(
            "{}: the limit probe needs one 3D texture of 24×32×40 \
             voxels (level 0 of 1 channels stacked in z), over the device's limit of 16 per axis",
            src.as_ref().info().name
        )
    );
}
