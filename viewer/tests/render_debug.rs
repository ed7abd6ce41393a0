mod render_common;
use std::sync::Arc;
use render_common::*;
use residency_viewer::gpu::synthetic::SyntheticSource;
use residency_viewer::scene::Scene;
use residency_viewer::source::SampleType;

fn run(name: &str, f: impl Fn(usize, [u64; 3]) -> f64 + 'static, lo: f64, hi: f64) {
    let src = Arc::new(SyntheticSource::new(SampleType::U8, [32, 32, 32], [1.0; 3], [16; 3], 8, 1, f));
    let scene = Scene {
        camera: camera([16.0, -40.0, 16.0], [16.0, 16.0, 16.0]),
        channels: vec![ramp(0, [1.0, 0.8, 0.3], lo, hi, 0.05)],
        background: [0.0, 0.0, 0.0],
    };
    let (p, img) = render(&src, &scene, full_res(16, 16), 20);
    let r = reference(&src, &scene, 16, 16);
    let (db, _) = psnr(&img, &r);
    eprintln!("{name}: psnr {db:.1} frames {} {:?}", p.frames.len(), p.frames.last().map(|f| &f.shader));
    for y in [4usize, 8, 12] {
        let g: Vec<String> = (0..16).step_by(2).map(|x| format!("{:?}", p.pixels[y * 16 + x])).collect();
        let q: Vec<String> = (0..16).step_by(2).map(|x| format!("{:.3}", r.get(x, y)[0])).collect();
        eprintln!("  gpu {}\n  ref {}", g.join(" "), q.join(" "));
    }
}

#[test]
fn debug() {
    run("const", |_, _| 100.0, 0.0, 200.0);
    run("ramp x", |_, [x, _, _]| x as f64 * 6.0, 0.0, 200.0);
    run("ramp z", |_, [_, _, z]| z as f64 * 6.0, 0.0, 200.0);
}
