//! Converged GPU renders match the f64 reference.

mod render_common;

use std::sync::Arc;

use render_common::*;
use residency_viewer::gpu::synthetic::SyntheticSource;
use residency_viewer::scene::Scene;
use residency_viewer::source::SampleType;

fn blob(t: SampleType, scale: f64) -> Arc<SyntheticSource> {
    Arc::new(SyntheticSource::new(t, [32, 32, 32], [1.0; 3], [16; 3], 8, 1, move |_, [x, y, z]| {
        let d = [x as f64 - 15.5, y as f64 - 13.0, z as f64 - 17.0];
        let r2 = d[0] * d[0] + d[1] * d[1] * 1.5 + d[2] * d[2] * 0.7;
        scale * (-r2 / 60.0).exp() + scale * 0.1 * ((x as f64) * 0.7).sin().abs()
    }))
}

#[test]
fn single_channel_u8_outside() {
    let src = blob(SampleType::U8, 220.0);
    let scene = Scene {
        camera: camera([-30.0, -40.0, 45.0], [16.0, 16.0, 16.0]),
        channels: vec![ramp(0, [1.0, 0.8, 0.3], 30.0, 220.0, 0.3)],
        background: [0.05, 0.05, 0.1],
    };
    let (p, img) = render(&src, &scene, full_res(64, 64), 20);
    let reference = reference(&src, &scene, 64, 64);
    if let Some(dir) = std::env::var_os("RENDER_DUMP") {
        let dir = std::path::PathBuf::from(dir);
        img.write(&dir.join("gpu.png")).unwrap();
        reference.write(&dir.join("ref.png")).unwrap();
    }
    let (db, max) = psnr(&img, &reference);
    eprintln!("{} frames, {}, psnr {db:.2} dB, max {max:.4}, stats {:?}", p.frames.len(), p.stop_reason, p.frames.last());
    assert!(p.converged);
    assert!(db > 40.0, "psnr {db}");
}
