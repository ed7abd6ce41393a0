//! `viewer reference` end to end: an analytic image of a constant volume, and the same image
//! whether the bricks come from a local store or from the real `brickserver`.

use std::path::Path;
use std::process::Command;

use crate::source_common::{Layout, make_store};
use residency_ingest::ConvertOptions;
use residency_viewer::image::RgbImage;
use residency_viewer::reference::{self, ReferenceOptions};
use residency_viewer::scene::{Camera, ChannelStyle, OpacityPoint, Scene};
use residency_viewer::source::{BrickSource, LocalSource};

fn viewer(args: &[&str]) -> std::process::Output {
    let out = Command::new(env!("CARGO_BIN_EXE_viewer"))
        .args(args)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "viewer {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// A 12×16×16 (z, y, x) uint8 store of the constant 100, voxel size 1.
fn constant_store(dir: &Path) -> std::path::PathBuf {
    let raw = dir.join("flat_16x16x12_uint8.raw");
    std::fs::write(&raw, vec![100u8; 16 * 16 * 12]).unwrap();
    let out = dir.join("flat.ome.zarr");
    let mut o = ConvertOptions::new(vec![raw.to_str().unwrap().into()], out.clone());
    o.brick = [8; 3];
    residency_ingest::convert(&o).unwrap();
    out
}

#[test]
fn constant_volume_gives_beer_lambert_through_the_cli() {
    let dir = tempfile::tempdir().unwrap();
    let store = constant_store(dir.path());
    let scene = dir.path().join("scene.json");
    // Looking down -z through the middle: 12 voxels of opacity 0.2 per voxel.
    std::fs::write(
        &scene,
        r#"{"camera": {"eye": [8, 8, 40], "target": [8, 8, 0], "fov_y_degrees": 10},
            "channels": [{"channel": 0, "color": [1, 0.5, 0],
                          "opacity": [{"value": 50, "opacity": 0}, {"value": 150, "opacity": 0.4}]}],
            "background": [0, 0, 1]}"#,
    )
    .unwrap();
    let out = dir.path().join("ref.exr");
    let s = |p: &Path| p.to_str().unwrap().to_string();
    // The same render, written to `out` (its format from the extension).
    let render_to = |out: &Path| {
        viewer(&[
            "reference",
            "--store",
            &s(&store),
            "--scene",
            &s(&scene),
            "--width",
            "5",
            "--height",
            "3",
            "--step",
            "0.3",
            "--out",
            &s(out),
        ]);
    };
    render_to(&out);
    let img = RgbImage::read(&out).unwrap();
    assert_eq!((img.width, img.height), (5, 3));
    let t = 0.8f64.powi(12);
    let centre = img.get(2, 1);
    let expect = [1.0 - t, 0.5 * (1.0 - t), t];
    for i in 0..3 {
        assert!(
            (centre[i] as f64 - expect[i]).abs() < 1e-6,
            "{centre:?} vs {expect:?}"
        );
    }
    // A PNG of the same render is its 8-bit sRGB encoding.
    let png = dir.path().join("ref.png");
    render_to(&png);
    let back = RgbImage::read(&png).unwrap();
    let enc = |v: f32| (residency_viewer::image::linear_to_srgb(v) * 255.0).round();
    for (a, b) in img.pixels.iter().zip(&back.pixels) {
        for i in 0..3 {
            assert_eq!(enc(a[i]), enc(b[i]));
        }
    }
}

#[test]
fn local_and_http_sources_give_the_same_reference() {
    let dir = tempfile::tempdir().unwrap();
    let store = make_store(dir.path(), "vol", Layout::V3Sharded);
    let local = LocalSource::open(&store).unwrap();
    let info = local.info();
    let scene = Scene {
        camera: Camera {
            eye: [30.0, 20.0, 80.0],
            target: [7.0, 6.0, 20.0],
            up: [0.0, 1.0, 0.0],
            fov_y_degrees: 35.0,
        },
        channels: (0..2)
            .map(|c| ChannelStyle {
                channel: c,
                visible: true,
                color: if c == 0 {
                    [1.0, 0.2, 0.0]
                } else {
                    [0.0, 0.4, 1.0]
                },
                opacity: vec![
                    OpacityPoint {
                        value: 0.0,
                        opacity: 0.0,
                    },
                    OpacityPoint {
                        value: info.display[c].range.unwrap()[1],
                        opacity: 0.3,
                    },
                ],
            })
            .collect(),
        background: [0.1, 0.1, 0.1],
        filter: residency_viewer::scene::Filter::Trilinear,
        mode: residency_viewer::scene::RenderMode::Dvr,
        clip: residency_viewer::scene::Clip::default(),
    };
    let mut options = ReferenceOptions::new(24, 16);
    options.step_fraction = 0.5;
    let a = reference::render(&local, &scene, &options).unwrap();
    // Something is drawn: not every pixel is the background.
    assert!(a.pixels.iter().any(|p| *p != [0.1f32; 3]));

    let server = crate::source_common::Server::start(&[&store]);
    let http = residency_viewer::source::HttpSource::open(&server.url, "vol").unwrap();
    let b = reference::render(&http, &scene, &options).unwrap();
    assert_eq!(a, b);
    // Through the CLI, the same scene file gives the same pixels (EXR is exact).
    let file = dir.path().join("scene.json");
    std::fs::write(&file, serde_json::to_vec(&scene).unwrap()).unwrap();
    let out = dir.path().join("cli.exr");
    viewer(&[
        "reference",
        "--server",
        &server.url,
        "--dataset",
        "vol",
        "--scene",
        file.to_str().unwrap(),
        "--width",
        "24",
        "--height",
        "16",
        "--step",
        "0.5",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(RgbImage::read(&out).unwrap(), a);
}
