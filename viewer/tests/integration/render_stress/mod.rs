//! Numerical stress tests of the GPU ray caster against the f64 reference
//! (`reference::render`): tiny steps where transmittance underflows, thousands of samples per
//! ray, far and near cameras, grazing rays along brick and node faces, a region of interest
//! 10⁷ voxels from the origin, and LOD transitions.
//!
//! Every render here is converged (no brick left to request) and checked for finite pixels and
//! alpha in `[0, 1]` before it is compared. Images are small (16²–48²): lavapipe takes about
//! 2 M samples/s.
//!
//! One module per concern: [`precision`] (tiny steps, thousands of samples per ray),
//! [`cameras`] (far and near cameras, grazing rays along faces), [`far_region`] (a region of
//! interest 10⁷ voxels from the origin) and [`lod`] (a transition between levels). This module
//! holds what they share: rendering and checking, and the shell volume.

mod cameras;
mod far_region;
mod lod;
mod precision;

use std::sync::Arc;

use crate::render_common::*;
use residency_viewer::gpu::renderer::{Method, RenderOptions, Renderer};
use residency_viewer::gpu::streaming::{Budget, Fetcher, Progressive, converge};
use residency_viewer::gpu::synthetic::SyntheticSource;
use residency_viewer::image::RgbImage;
use residency_viewer::metrics::{self, Metrics};
use residency_viewer::reference::{self, ReferenceOptions};
use residency_viewer::scene::{Camera, ChannelStyle, OpacityPoint, Scene};
use residency_viewer::source::{
    BrickKey, BrickSource, BrickVoxels, ChannelDisplay, LevelInfo, MinMaxGrid, SampleType,
    VolumeInfo,
};

const METHODS: [Method; 5] = Method::ALL;

// ---------------------------------------------------------------------------------------------
// Rendering and checking
// ---------------------------------------------------------------------------------------------

/// A converged GPU render: the progressive result (RGBA pixels, alpha = 1 − T) and its colour
/// image.
struct Gpu {
    p: Progressive,
    img: RgbImage,
}

impl Gpu {
    fn samples_per_pixel(&self) -> f64 {
        let last = self.p.frames.last().expect("a frame");
        last.shader.samples as f64 / self.p.pixels.len() as f64
    }
}

/// Renders `scene` progressively from `source` and checks the result is sane: converged, no
/// failed brick, every component finite, alpha in `[0, 1]`, colour in `[0, Σ_c colour_c]` (or
/// up to the background, where that is brighter).
fn gpu_render(
    label: &str,
    source: Arc<dyn BrickSource>,
    scene: &Scene,
    options: RenderOptions,
    preload: bool,
) -> Gpu {
    let gpu = gpu();
    let mut renderer = Renderer::new(gpu, source.info(), scene, options.clone()).expect("renderer");
    if preload {
        // Make every level-0 brick of the drawn channels resident first, so that the one
        // frame rendered is complete: tiny steps make a frame with missing bricks (which the
        // baselines march through step by step) as expensive as a complete one.
        let info = source.info().clone();
        let mut keys = Vec::new();
        for (i, style) in scene.channels.iter().filter(|c| c.visible).enumerate() {
            let level = options.level_bounds.get(i).map_or(0, |b| b.0);
            let g = info.brick_grid(level as usize);
            for z in 0..g[0] {
                for y in 0..g[1] {
                    for x in 0..g[2] {
                        keys.push(BrickKey {
                            level,
                            channel: style.channel as u32,
                            brick: [z, y, x],
                        });
                    }
                }
            }
        }
        for (key, voxels) in keys.iter().zip(source.fetch(&keys)) {
            renderer
                .insert(gpu, *key, &voxels.expect("brick"))
                .expect("insert");
        }
    }
    let fetcher = Fetcher::new(source, 2, 16);
    let budget = Budget {
        max_frames: 20,
        ..Default::default()
    };
    let p = converge(gpu, &mut renderer, &fetcher, &budget).expect("render");
    assert!(p.converged, "{label}: {}", p.stop_reason);
    assert!(p.failed.is_empty(), "{label}: {:?}", p.failed);
    if preload {
        assert_eq!(
            p.frames.len(),
            1,
            "{label}: a preloaded render needs one frame"
        );
    }
    // Channels add before blending (a sample's colour is Σ α_c·colour_c, its opacity
    // min(1, Σ α_c)), so a component is bounded by the sum over channels, or the background.
    let bound: [f32; 3] = std::array::from_fn(|i| {
        let sum: f64 = scene
            .channels
            .iter()
            .filter(|c| c.visible)
            .map(|c| c.color[i])
            .sum();
        sum.max(scene.background[i]) as f32
    });
    for (i, q) in p.pixels.iter().enumerate() {
        let (x, y) = (i % p.width as usize, i / p.width as usize);
        assert!(
            q.iter().all(|v| v.is_finite()),
            "{label}: pixel ({x}, {y}) = {q:?} is not finite"
        );
        assert!(
            (0.0..=1.0).contains(&q[3]),
            "{label}: pixel ({x}, {y}) alpha {} outside [0, 1]",
            q[3]
        );
        assert!(
            (0..3).all(|i| (-1e-6..=bound[i] + 1e-5).contains(&q[i])),
            "{label}: pixel ({x}, {y}) colour {q:?} outside [0, {bound:?}]"
        );
    }
    let img = RgbImage {
        width: p.width as usize,
        height: p.height as usize,
        pixels: p.pixels.iter().map(|q| [q[0], q[1], q[2]]).collect(),
    };
    Gpu { p, img }
}

/// The reference image and its per-pixel transmittance (from a second render over a
/// background one brighter: `T = (C + T·(b + 1)) − (C + T·b)`).
fn reference_t(
    source: &dyn BrickSource,
    scene: &Scene,
    options: &ReferenceOptions,
) -> (RgbImage, Vec<f64>) {
    let img = reference::render(source, scene, options).expect("reference");
    let mut brighter = scene.clone();
    brighter.background = scene.background.map(|b| b + 1.0);
    let b = reference::render(source, &brighter, options).expect("reference");
    let t = img
        .pixels
        .iter()
        .zip(&b.pixels)
        .map(|(p, q)| (0..3).map(|i| (q[i] - p[i]) as f64).sum::<f64>() / 3.0)
        .collect();
    (img, t)
}

fn compare(label: &str, gpu: &Gpu, reference: &RgbImage) -> Metrics {
    if let Some(dir) = std::env::var_os("RENDER_DUMP") {
        let dir = std::path::PathBuf::from(dir);
        gpu.img
            .write(&dir.join(format!("{label}-gpu.png")))
            .unwrap();
        reference
            .write(&dir.join(format!("{label}-ref.png")))
            .unwrap();
    }
    let m = metrics::compare(&gpu.img, reference).expect("compare");
    let last = gpu.p.frames.last().unwrap();
    eprintln!(
        "{label}: {} frames, PSNR {:.2} dB, SSIM {:.5}, max {:.5}, samples/pixel {:.1}, \
         homogeneous {}, skipped {}",
        gpu.p.frames.len(),
        m.psnr_db,
        m.ssim,
        m.max_abs_error,
        gpu.samples_per_pixel(),
        last.shader.homogeneous_nodes,
        last.shader.empty_nodes_skipped,
    );
    m
}

fn assert_metrics(label: &str, m: &Metrics, psnr: f64, ssim: f64, max_abs: f64) {
    assert!(m.psnr_db >= psnr, "{label}: PSNR {} < {psnr}", m.psnr_db);
    assert!(m.ssim >= ssim, "{label}: SSIM {} < {ssim}", m.ssim);
    assert!(
        m.max_abs_error <= max_abs,
        "{label}: max abs error {} > {max_abs}",
        m.max_abs_error
    );
}

fn style(channel: usize, color: [f64; 3], points: &[(f64, f64)]) -> ChannelStyle {
    ChannelStyle {
        channel,
        visible: true,
        color,
        opacity: points
            .iter()
            .map(|&(value, opacity)| OpacityPoint { value, opacity })
            .collect(),
    }
}

fn options(width: u32, height: u32, method: Method) -> RenderOptions {
    RenderOptions {
        method,
        ..full_res(width, height)
    }
}

// ---------------------------------------------------------------------------------------------
// Volumes
// ---------------------------------------------------------------------------------------------

/// A smooth u16 volume of 32³ voxels, bricks 8³: a thin spherical shell (radius 11, about 2
/// voxels thick) around a soft core, with ripples along x.
fn shell_n(n: u64) -> Arc<SyntheticSource> {
    Arc::new(SyntheticSource::new(
        SampleType::U16,
        [n, n, n],
        [1.0; 3],
        [8; 3],
        4,
        1,
        |_, [x, y, z]| {
            let d = [x as f64 - 15.7, y as f64 - 16.2, z as f64 - 15.4];
            let r = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            1000.0
                + 40000.0 * (-(r - 11.0) * (r - 11.0) / 2.0).exp()
                + 15000.0 * (-r * r / 20.0).exp()
                + 3000.0 * (x as f64 * 0.8).sin().abs()
        },
    ))
}

fn shell() -> Arc<SyntheticSource> {
    shell_n(32)
}

fn shell_style() -> Vec<ChannelStyle> {
    vec![style(
        0,
        [1.0, 0.8, 0.4],
        &[(3000.0, 0.0), (20000.0, 0.25), (42000.0, 0.6)],
    )]
}

fn scene(camera: Camera, channels: Vec<ChannelStyle>, background: [f64; 3]) -> Scene {
    Scene {
        camera,
        channels,
        background,
        filter: residency_viewer::scene::Filter::Trilinear,
        mode: residency_viewer::scene::RenderMode::Dvr,
        clip: residency_viewer::scene::Clip::default(),
    }
}
