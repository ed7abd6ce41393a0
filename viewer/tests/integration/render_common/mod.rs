//! Shared helpers of the GPU render tests: scenes over synthetic volumes, the GPU, and image
//! error measures against the f64 reference.

#![allow(dead_code)]

use std::sync::{Arc, Once, OnceLock};

use residency_viewer::gpu::device::Gpu;
use residency_viewer::gpu::renderer::RenderOptions;
use residency_viewer::gpu::streaming::{Budget, Progressive, render_progressive};
use residency_viewer::gpu::synthetic::SyntheticSource;
use residency_viewer::image::RgbImage;
use residency_viewer::metrics::{self, Metrics};
use residency_viewer::reference::{self, ReferenceOptions};
use residency_viewer::scene::{Camera, ChannelStyle, OpacityPoint, Scene};
use residency_viewer::source::{BrickSource, SampleType};

/// The GPU (lavapipe on CI), opened once per test binary and shared by the tests.
pub fn gpu() -> &'static Gpu {
    static GPU: OnceLock<Gpu> = OnceLock::new();
    GPU.get_or_init(new_gpu)
}

/// A GPU device of its own (lavapipe on CI), for a test that owns or reconfigures it.
pub fn new_gpu() -> Gpu {
    default_runtime_dir();
    Gpu::new().expect("a GPU adapter (lavapipe)")
}

/// Sets `XDG_RUNTIME_DIR` to `/tmp` when it is unset (lavapipe wants one), once per process.
/// Every test of this binary opens its GPU through [`new_gpu`], after this.
fn default_runtime_dir() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        if std::env::var_os("XDG_RUNTIME_DIR").is_none() {
            // SAFETY: the tests run on parallel threads of one process. Rust's own environment
            // accesses (`std::env`, `Command::spawn`) take the lock `set_var` takes; the only
            // unlocked readers are the GPU driver's `getenv` calls, and no GPU is opened before
            // this `call_once` returns (it blocks every other caller until it has run).
            unsafe { std::env::set_var("XDG_RUNTIME_DIR", "/tmp") };
        }
    });
}

/// A ramp transfer function: transparent up to `lo`, opacity `a` from `hi` on.
pub fn ramp(channel: usize, color: [f64; 3], lo: f64, hi: f64, a: f64) -> ChannelStyle {
    ChannelStyle {
        channel,
        visible: true,
        color,
        opacity: vec![
            OpacityPoint {
                value: lo,
                opacity: 0.0,
            },
            OpacityPoint {
                value: hi,
                opacity: a,
            },
        ],
    }
}

/// A camera at `eye` looking at `target` with +z up (or +y when looking along z).
pub fn camera(eye: [f64; 3], target: [f64; 3]) -> Camera {
    let d = [target[0] - eye[0], target[1] - eye[1], target[2] - eye[2]];
    let up = if d[0].abs() < 1e-9 && d[1].abs() < 1e-9 {
        [0.0, 1.0, 0.0]
    } else {
        [0.0, 0.0, 1.0]
    };
    Camera {
        eye,
        target,
        up,
        fov_y_degrees: 40.0,
    }
}

/// Options rendering at level 0 only (what the reference shows).
pub fn full_res(width: u32, height: u32) -> RenderOptions {
    RenderOptions {
        width,
        height,
        level_bounds: vec![(0, 0); 8],
        ..Default::default()
    }
}

/// Options wanting level 0 wherever a brick is resident (a LOD bias far below any pixel
/// footprint), with every level allowed, so coarser levels may stand in while bricks stream.
pub fn finest_wanted(width: u32, height: u32) -> RenderOptions {
    RenderOptions {
        width,
        height,
        lod_bias: -20.0,
        ..Default::default()
    }
}

/// Renders progressively and converts the last frame to an image.
pub fn render(
    source: &Arc<SyntheticSource>,
    scene: &Scene,
    options: RenderOptions,
    frames: u32,
) -> (Progressive, RgbImage) {
    let src: Arc<dyn BrickSource> = source.clone();
    let budget = Budget {
        max_frames: frames,
        ..Default::default()
    };
    let p = render_progressive(gpu(), src, scene, options, &budget).expect("render");
    let image = RgbImage {
        width: p.width as usize,
        height: p.height as usize,
        pixels: p.pixels.iter().map(|p| [p[0], p[1], p[2]]).collect(),
    };
    (p, image)
}

/// The f64 reference of `scene`.
pub fn reference(source: &SyntheticSource, scene: &Scene, width: usize, height: usize) -> RgbImage {
    reference::render(source, scene, &ReferenceOptions::new(width, height)).expect("reference")
}

/// Compares a GPU image with the reference, printing the metrics.
pub fn check(label: &str, p: &Progressive, gpu: &RgbImage, reference: &RgbImage) -> Metrics {
    if let Some(dir) = std::env::var_os("RENDER_DUMP") {
        let dir = std::path::PathBuf::from(dir);
        gpu.write(&dir.join(format!("{label}-gpu.png"))).unwrap();
        reference
            .write(&dir.join(format!("{label}-ref.png")))
            .unwrap();
    }
    let m = metrics::compare(gpu, reference).expect("compare");
    eprintln!(
        "{label}: {} frames ({}), PSNR {:.2} dB, SSIM {:.5}, max {:.4}, last frame {:?}",
        p.frames.len(),
        p.stop_reason,
        m.psnr_db,
        m.ssim,
        m.max_abs_error,
        p.frames.last()
    );
    m
}

/// A bright front slab (x < 8: 200 to 240) before dimmer matter (at most 180), u8, 32³ in
/// bricks of 8³ (min/max cells of 4³): seen from the −x side, every ray enters through the
/// slab. Opaque under a steep ramp (nothing behind it is needed), the brightest along every
/// ray for MIP, the first surface for iso-surfaces.
pub fn bright_front() -> Arc<SyntheticSource> {
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

/// The distinct x indices of the level-0 bricks `p` requested, ascending.
pub fn level0_bricks_along_x(p: &Progressive) -> Vec<u64> {
    let mut x: Vec<u64> = p
        .request_log
        .iter()
        .filter(|k| k.level == 0)
        .map(|k| k.brick[2])
        .collect();
    x.sort_unstable();
    x.dedup();
    x
}
