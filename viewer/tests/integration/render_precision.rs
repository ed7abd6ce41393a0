//! Precision far from the origin: a volume 2²⁵ voxels wide (procedural, never held in
//! memory), viewed from inside near its far end. In f32 world coordinates positions there
//! are only good to ±2 voxels; the renderer's node-local coordinates (integer leaf cell plus
//! an f32 offset) must still match the f64 reference.

use std::sync::Arc;

use crate::render_common::*;
use residency_viewer::gpu::renderer::RenderOptions;
use residency_viewer::gpu::streaming::{Budget, render_progressive};
use residency_viewer::image::RgbImage;
use residency_viewer::metrics;
use residency_viewer::reference::{self, ReferenceOptions};
use residency_viewer::scene::{Camera, Scene};
use residency_viewer::source::{
    BrickKey, BrickSource, BrickVoxels, ChannelDisplay, LevelInfo, SampleType, SourceError,
    VolumeInfo,
};

const WIDTH: u64 = 1 << 25;
const BRICK: [u64; 3] = [4, 4, 64];

/// `z, y, x` = 4 × 4 × 2²⁵ u8 voxels; value depends on x (period ≈ 7 voxels) and y.
struct Wide {
    info: VolumeInfo,
}

fn level0(x: u64, y: u64) -> f64 {
    (100.0 + 80.0 * (x as f64 * 0.9).sin() + 10.0 * y as f64).round()
}

impl Wide {
    fn new() -> Self {
        Self {
            info: VolumeInfo {
                name: "wide".into(),
                sample_type: SampleType::U8,
                channels: vec!["c0".into()],
                display: vec![ChannelDisplay::default()],
                voxel_size: [1.0; 3],
                unit: None,
                brick_shape: BRICK,
                levels: vec![
                    LevelInfo {
                        shape: [4, 4, WIDTH],
                        factor: [1, 1, 1],
                    },
                    LevelInfo {
                        shape: [4, 4, WIDTH / 2],
                        factor: [1, 1, 2],
                    },
                ],
                minmax: None,
            },
        }
    }

    fn value(level: u32, x: u64, y: u64) -> f64 {
        match level {
            0 => level0(x, y),
            _ => f64::midpoint(level0(2 * x, y), level0(2 * x + 1, y)).round(),
        }
    }
}

impl BrickSource for Wide {
    fn info(&self) -> &VolumeInfo {
        &self.info
    }

    fn fetch(&self, keys: &[BrickKey]) -> Vec<Result<BrickVoxels, SourceError>> {
        keys.iter()
            .map(|k| {
                self.info.check_key(k)?;
                let mut v = Vec::with_capacity(1024);
                for _z in 0..BRICK[0] {
                    for y in 0..BRICK[1] {
                        for x in 0..BRICK[2] {
                            v.push(Self::value(k.level, k.brick[2] * BRICK[2] + x, y) as u8);
                        }
                    }
                }
                Ok(BrickVoxels::U8(v))
            })
            .collect()
    }
}

#[test]
fn far_from_the_origin_matches_the_reference() {
    let src = Arc::new(Wide::new());
    let far = WIDTH as f64;
    let scene = Scene {
        camera: Camera {
            eye: [far - 40.3, 2.1, 1.7],
            target: [far - 70.0, 1.2, 2.6],
            up: [0.0, 0.0, 1.0],
            fov_y_degrees: 12.0,
        },
        channels: vec![ramp(0, [1.0, 0.7, 0.2], 40.0, 190.0, 0.6)],
        background: [0.0, 0.0, 0.2],
        filter: residency_viewer::scene::Filter::Trilinear,
        mode: residency_viewer::scene::RenderMode::Dvr,
        clip: residency_viewer::scene::Clip::default(),
    };
    let options = RenderOptions {
        width: 32,
        height: 32,
        ..full_res(32, 32)
    };
    let budget = Budget {
        max_frames: 10,
        ..Default::default()
    };
    let p = render_progressive(gpu(), src.clone(), &scene, options, &budget).unwrap();
    assert!(p.converged, "{}", p.stop_reason);
    let img = RgbImage {
        width: 32,
        height: 32,
        pixels: p.pixels.iter().map(|q| [q[0], q[1], q[2]]).collect(),
    };
    // Both stop rays at transmittance 1/255.
    let reference = reference::render(
        src.as_ref(),
        &scene,
        &ReferenceOptions {
            min_transmittance: 1.0 / 255.0,
            ..ReferenceOptions::new(32, 32)
        },
    )
    .unwrap();
    // Not a blank picture: most rays hit data.
    assert!(img.pixels.iter().filter(|q| q[0] > 0.3).count() > 500);
    let m = metrics::compare(&img, &reference).unwrap();
    eprintln!(
        "wide: PSNR {:.2} dB, SSIM {:.5}, max {:.4}",
        m.psnr_db, m.ssim, m.max_abs_error
    );
    assert!(m.psnr_db >= 35.0, "PSNR {}", m.psnr_db);
    assert!(m.ssim >= 0.98, "SSIM {}", m.ssim);
}
