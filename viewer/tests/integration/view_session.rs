//! The non-blocking progressive loop behind `viewer view` ([`Session`]) on lavapipe: it
//! converges to the same image as the blocking loop, a camera change reuses the resident
//! bricks, a style change rebuilds the renderer and fetches only the channels drawn, a size
//! change resizes the image, and hiding every channel shows the background.

use std::sync::Arc;
use std::time::Duration;

use crate::render_common::new_gpu as gpu;
use residency_viewer::gpu::renderer::RenderOptions;
use residency_viewer::gpu::streaming::{Budget, render_progressive};
use residency_viewer::gpu::synthetic::SyntheticSource;
use residency_viewer::interactive::camera_control::orbit;
use residency_viewer::interactive::controls::next_variant;
use residency_viewer::interactive::session::{Session, Step};
use residency_viewer::scene::{Camera, ChannelStyle, Filter, OpacityPoint, Scene};
use residency_viewer::source::SampleType;

fn source() -> Arc<SyntheticSource> {
    Arc::new(SyntheticSource::new(
        SampleType::U8,
        [32, 32, 32],
        [1.0; 3],
        [8; 3],
        4,
        2,
        |c, [x, y, z]| {
            let d = [
                x as f64 - 16.0 - 4.0 * c as f64,
                y as f64 - 16.0,
                z as f64 - 16.0,
            ];
            200.0 * (-(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) / 60.0).exp()
        },
    ))
}

fn style(channel: usize, color: [f64; 3]) -> ChannelStyle {
    ChannelStyle {
        channel,
        visible: true,
        color,
        opacity: vec![
            OpacityPoint {
                value: 20.0,
                opacity: 0.0,
            },
            OpacityPoint {
                value: 200.0,
                opacity: 0.3,
            },
        ],
    }
}

fn scene() -> Scene {
    Scene {
        camera: Camera {
            eye: [16.0, 16.0, -50.0],
            target: [16.0, 16.0, 16.0],
            up: [0.0, -1.0, 0.0],
            fov_y_degrees: 40.0,
        },
        channels: vec![style(0, [0.0, 1.0, 1.0]), style(1, [1.0, 0.0, 1.0])],
        background: [0.0, 0.0, 0.1],
        filter: Filter::Trilinear,
        mode: residency_viewer::scene::RenderMode::Dvr,
        clip: residency_viewer::scene::Clip::default(),
    }
}

fn options() -> RenderOptions {
    RenderOptions {
        width: 40,
        height: 32,
        level_bounds: vec![(0, 0); 2],
        ..Default::default()
    }
}

/// Steps until idle; returns the number of frames rendered.
fn settle(s: &mut Session) -> u32 {
    let mut frames = 0;
    for _ in 0..500 {
        match s.step(Duration::from_millis(20)).unwrap() {
            Step::Rendered => frames += 1,
            Step::Waiting => {}
            Step::Idle => return frames,
        }
    }
    panic!("no convergence after 500 steps: {}", s.status());
}

#[test]
fn session_converges_and_keeps_its_bricks_through_camera_and_style_changes() {
    let src = source();
    let mut s = Session::new(gpu(), src.clone(), scene(), options(), 2, 4);
    let frames = settle(&mut s);
    assert_eq!(s.status(), "converged");
    assert!(frames >= 2, "{frames}");
    let fetched = src.fetch_log().len() as u64;
    assert_eq!(s.totals().bricks_fetched, fetched);
    assert_eq!(s.totals().rebuilds, 1);
    assert!(fetched > 0 && s.last_frame().unwrap().shader.samples > 0);

    // The same image as the blocking loop.
    let (w, h, pixels) = s.image();
    assert_eq!((w, h), (40, 32));
    let blocking =
        render_progressive(s.gpu(), source(), &scene(), options(), &Budget::default()).unwrap();
    assert!(blocking.converged);
    let diff = pixels
        .iter()
        .zip(&blocking.pixels)
        .flat_map(|(a, b)| (0..3).map(move |i| (a[i] - b[i]).abs()))
        .fold(0.0f32, f32::max);
    assert!(diff < 1e-5, "max difference {diff}");
    let first: Vec<[f32; 4]> = pixels.to_vec();

    // Idle stays idle.
    assert_eq!(s.step(Duration::from_millis(50)).unwrap(), Step::Idle);

    // Orbit: the renderer and its bricks stay; a new image.
    let cam = orbit(&s.scene().camera, 40.0, 10.0, 0.01);
    s.set_camera(cam);
    assert!(settle(&mut s) >= 1);
    assert_eq!(s.totals().rebuilds, 1);
    assert_ne!(s.image().2, &first[..]);
    let after_orbit = src.fetch_log().len();
    let orbited = s.image().2.to_vec();

    // Hide channel 1: restyled in place, no rebuild and nothing fetched.
    let shown = s.scene().clone();
    let mut hidden = shown.clone();
    hidden.channels[1].visible = false;
    s.set_scene(hidden);
    settle(&mut s);
    assert_eq!(s.totals().rebuilds, 1);
    assert_eq!(src.fetch_log().len(), after_orbit);
    // No magenta left: every pixel is at most as red as it is green, plus the background.
    assert!(
        s.image().2.iter().all(|p| p[0] <= p[1] + 1e-6),
        "red remains"
    );
    // Shown again: the same image as before, from the bricks still resident.
    s.set_scene(shown);
    settle(&mut s);
    assert_eq!(s.totals().rebuilds, 1);
    assert_eq!(src.fetch_log().len(), after_orbit);
    assert_eq!(s.image().2, &orbited[..]);

    // A new size.
    s.set_size(24, 20);
    settle(&mut s);
    assert_eq!(s.totals().rebuilds, 2);
    // Every renderer on the device (the session's two, the blocking loop's) shares one
    // compiled pipeline: the format and method did not change.
    assert_eq!(s.gpu().pipelines.len(), 1);

    // The tricubic filter (the `f` key): a new renderer and pipeline, a smoother image; and
    // back to trilinear, the first pipeline again.
    let trilinear = s.image().2.to_vec();
    let press_f = |s: &mut Session| {
        let mut scene = s.scene().clone();
        scene.filter = next_variant(scene.filter);
        s.set_scene(scene);
        settle(s);
        s.scene().filter
    };
    assert_eq!(press_f(&mut s), Filter::Tricubic);
    assert_eq!(s.totals().rebuilds, 3);
    assert_eq!(s.gpu().pipelines.len(), 2);
    assert_ne!(s.image().2, &trilinear[..]);
    assert_eq!(press_f(&mut s), Filter::Trilinear);
    assert_eq!(s.totals().rebuilds, 4);
    assert_eq!(s.gpu().pipelines.len(), 2);
    assert_eq!(s.image().2, &trilinear[..]);
    let (w, h, pixels) = s.image();
    assert_eq!((w, h, pixels.len()), (24, 20, 480));

    // Nothing visible: the background.
    let mut none = s.scene().clone();
    for c in &mut none.channels {
        c.visible = false;
    }
    s.set_scene(none);
    assert_eq!(s.step(Duration::ZERO).unwrap(), Step::Rendered);
    assert_eq!(s.step(Duration::from_millis(50)).unwrap(), Step::Idle);
    assert_eq!(s.status(), "no channel visible");
    let (_, _, pixels) = s.image();
    assert!(pixels.iter().all(|p| p[..3] == [0.0, 0.0, 0.1]));
}
