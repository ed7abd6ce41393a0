//! Scene files (`schemas/src/scene.rs`: `Scene::from_json`, which the viewer's `read_scene`,
//! the page and the Python module call) on any bytes, then what the renderer asks of a scene:
//! the camera frame and some rays, every channel's opacity at a few values and over a few
//! ranges (and what each mode hides there, MIP's scale and saturation), and the clipped span
//! of those rays. A scene must serialise and
//! parse back to itself.
#![no_main]

use libfuzzer_sys::fuzz_target;
use residency_schemas::scene::{RenderMode, Scene, box_diagonal, corrected_opacity};

fuzz_target!(|data: &[u8]| {
    let Ok(scene) = Scene::from_json(data, "scene.json") else {
        return;
    };
    let cam = &scene.camera;
    let _ = cam.basis();
    let planes = scene.clip.planes_for(cam);
    for (px, py, w, h) in [(0, 0, 1, 1), (3, 1, 4, 2), (0, 9, 1, 10)] {
        let dir = cam.ray_direction(px, py, w, h);
        if let Some((t0, t1)) = scene.clip.clip_span(&planes, cam.eye, dir, (0.0, 1e6)) {
            assert!(t0 < t1 && t0 >= 0.0 && t1 <= 1e6, "{t0} {t1}");
        }
    }
    let probes = [
        f64::NEG_INFINITY,
        -1.0,
        0.0,
        0.5,
        1.0,
        255.0,
        65535.0,
        f64::INFINITY,
        f64::NAN,
    ];
    for ch in &scene.channels {
        for &v in &probes {
            let _ = ch.opacity_at(v);
            let _ = corrected_opacity(ch.opacity_at(v), 0.5, 1.0);
        }
        for w in probes.windows(2) {
            let _ = ch.transparent_over(w[0], w[1]);
            for mode in RenderMode::ALL {
                let _ = ch.hides(mode, w[0], w[1]);
            }
        }
        let _ = (ch.opacity_top(), ch.saturation_value());
    }
    let _ = box_diagonal(cam.eye);
    let json = serde_json::to_vec(&scene).expect("a scene serialises");
    let back: Scene = serde_json::from_slice(&json).expect("a serialised scene parses");
    assert_eq!(back, scene, "{}", String::from_utf8_lossy(&json));
});
