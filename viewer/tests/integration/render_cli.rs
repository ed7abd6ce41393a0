//! `viewer render` end to end on a store written by `ingest`: the image matches `viewer
//! reference`, the statistics JSON reports every frame, and bad input fails cleanly.

use std::path::{Path, PathBuf};
use std::process::Command;

use residency_ingest::ConvertOptions;
use residency_viewer::image::RgbImage;
use residency_viewer::metrics;

pub(crate) fn viewer(args: &[&str]) -> std::process::Output {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_viewer"));
    if std::env::var_os("XDG_RUNTIME_DIR").is_none() {
        cmd.env("XDG_RUNTIME_DIR", "/tmp");
    }
    cmd.args(args).output().unwrap()
}

/// The camera and transfer functions both renders of [`store`] draw.
pub(crate) const VIEW: [&str; 6] = [
    "--camera",
    "-30,-40,70:20,16,24",
    "--tf",
    "0:300:3000:0.2",
    "--tf",
    "1:500:2500:0.1",
];

/// Runs `viewer` and fails the test with its stderr unless it succeeds.
pub(crate) fn viewer_ok(args: &[&str]) {
    let out = viewer(args);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// The stderr of a `viewer` run that must fail (and must not panic).
pub(crate) fn fails(args: &[&str]) -> String {
    let out = viewer(args);
    assert!(!out.status.success(), "{args:?} succeeded");
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(!err.contains("panicked"), "{err}");
    err
}

/// `p` as an argument.
pub(crate) fn s(p: &Path) -> String {
    p.to_str().unwrap().to_string()
}

/// Asserts the images at `a` and `b` agree as a converged render and its reference do
/// (PSNR ≥ 40 dB, SSIM ≥ 0.99).
fn assert_matches(label: &str, a: &Path, b: &Path) {
    let m = metrics::compare(&RgbImage::read(a).unwrap(), &RgbImage::read(b).unwrap()).unwrap();
    eprintln!("{label}: PSNR {:.2} dB, SSIM {:.5}", m.psnr_db, m.ssim);
    assert!(m.psnr_db >= 40.0 && m.ssim >= 0.99, "{label}: {m:?}");
}

/// 24 × 32 × 40 (z, y, x) u16, two channels, bricks 8³, voxel size 2 × 1 × 1.
pub(crate) fn store(dir: &Path) -> PathBuf {
    let (nz, ny, nx) = (24u64, 32u64, 40u64);
    let mut inputs = Vec::new();
    for c in 0..2u64 {
        let mut bytes = Vec::new();
        for z in 0..nz {
            for y in 0..ny {
                for x in 0..nx {
                    let d = [
                        x as f64 - 20.0 - 4.0 * c as f64,
                        y as f64 - 15.0,
                        (z as f64 - 12.0) * 2.0,
                    ];
                    let r2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
                    let v = (3000.0 * (-r2 / 120.0).exp()) as u16;
                    bytes.extend_from_slice(&v.to_le_bytes());
                }
            }
        }
        let path = dir.join(format!("c{c}_{nx}x{ny}x{nz}_uint16.raw"));
        std::fs::write(&path, bytes).unwrap();
        inputs.push(path.to_str().unwrap().to_string());
    }
    let out = dir.join("blob.ome.zarr");
    let mut o = ConvertOptions::new(inputs, out.clone());
    o.brick = [8; 3];
    o.voxel_size = Some([2.0, 1.0, 1.0]);
    residency_ingest::convert(&o).unwrap();
    out
}

#[test]
fn render_matches_reference_and_writes_stats() {
    let dir = tempfile::tempdir().unwrap();
    let store = store(dir.path());
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let (gpu, reference, stats) = (
        dir.path().join("gpu.exr"),
        dir.path().join("ref.exr"),
        dir.path().join("stats.json"),
    );
    let mut scene = VIEW.to_vec();
    scene.extend([
        "--color",
        "0:1,0.3,0.1",
        "--color",
        "1:0.1,0.5,1",
        "--width",
        "48",
        "--height",
        "40",
    ]);
    let store = s(&store);
    let mut args = vec!["render", "--store", &store];
    args.extend(&scene);
    let (g, st) = (s(&gpu), s(&stats));
    args.extend(["--out", &g, "--stats", &st, "--max-level", "0"]);
    viewer_ok(&args);
    let mut args = vec!["reference", "--store", &store];
    args.extend(&scene);
    let r = s(&reference);
    args.extend(["--out", &r]);
    viewer_ok(&args);

    assert_matches("cli", &gpu, &reference);

    let json: serde_json::Value = serde_json::from_slice(&std::fs::read(&stats).unwrap()).unwrap();
    assert_eq!(json["converged"], true);
    assert_eq!(json["width"], 48);
    let frames = json["frames"].as_array().unwrap();
    assert!(frames.len() >= 2);
    assert!(frames[0]["bricks_requested"].as_u64().unwrap() > 0);
    assert_eq!(frames.last().unwrap()["bricks_requested"], 0);
    let fetched: u64 = frames
        .iter()
        .map(|f| f["bricks_fetched"].as_u64().unwrap())
        .sum();
    assert_eq!(json["bricks_fetched"].as_u64().unwrap(), fetched);
    // Non-empty u16 bricks of 8³ are 1024 bytes decoded.
    assert!(json["bytes_fetched"].as_u64().unwrap() > 0);
    assert_eq!(json["bytes_fetched"].as_u64().unwrap() % 1024, 0);
    for f in frames {
        for k in [
            "samples",
            "empty_nodes_skipped",
            "bricks_substituted",
            "bytes_fetched",
        ] {
            assert!(f[k].is_u64(), "{k}");
        }
        assert!(f["gpu_time_ms"].is_f64() || f["gpu_time_ms"].is_null());
    }
}

/// `--method sparseleap` and `--method rasterize`, each with `--filter tricubic`, match
/// `viewer reference --filter tricubic` on a store written by `ingest`, and say in their
/// statistics how many boxes they rasterised.
#[test]
fn seed_methods_and_tricubic_match_the_reference() {
    let dir = tempfile::tempdir().unwrap();
    let store = store(dir.path());
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let store = s(&store);
    let mut scene = VIEW.to_vec();
    scene.extend(["--width", "40", "--height", "32", "--filter", "tricubic"]);
    let reference = dir.path().join("ref.exr");
    let r = s(&reference);
    let mut args = vec!["reference", "--store", &store, "--out", &r];
    args.extend(&scene);
    viewer_ok(&args);
    for method in ["sparseleap", "rasterize"] {
        let (gpu, stats) = (
            dir.path().join(format!("{method}.exr")),
            dir.path().join(format!("{method}.json")),
        );
        let (g, st) = (s(&gpu), s(&stats));
        let mut args = vec!["render", "--store", &store, "--method", method];
        args.extend(&scene);
        args.extend(["--out", &g, "--stats", &st, "--max-level", "0"]);
        viewer_ok(&args);
        assert_matches(method, &gpu, &reference);
        let json: serde_json::Value =
            serde_json::from_slice(&std::fs::read(&stats).unwrap()).unwrap();
        assert_eq!(json["converged"], true, "{method}");
        let last = json["frames"].as_array().unwrap().last().unwrap().clone();
        assert!(
            last["segment_boxes"].as_u64().unwrap() > 0,
            "{method}: {last}"
        );
        assert_eq!(last["rays_overflowed"], 0, "{method}");
    }
}

#[test]
fn bad_input_fails_with_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("nothing.ome.zarr");
    let out_png = dir.path().join("x.png");
    let out = viewer(&[
        "render",
        "--store",
        missing.to_str().unwrap(),
        "--out",
        out_png.to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("no such store"), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    let store = store(dir.path());
    let out = viewer(&[
        "render",
        "--store",
        store.to_str().unwrap(),
        "--out",
        dir.path().join("x.tif").to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("unknown image format"));
}

/// `--max-frames` and `--time-budget-s` stop the progressive render before it converges: the
/// image is written, the run succeeds, and the statistics say which budget ended it.
#[test]
fn a_frame_or_time_budget_stops_the_render_and_says_so() {
    let dir = tempfile::tempdir().unwrap();
    let store = s(&store(dir.path()));
    let stats_of = |budget: &[&str], name: &str| {
        let (out, stats) = (
            dir.path().join(format!("{name}.png")),
            dir.path().join(format!("{name}.json")),
        );
        let (o, st) = (s(&out), s(&stats));
        let mut args = vec![
            "render", "--store", &store, "--width", "32", "--height", "24",
        ];
        args.extend(VIEW);
        args.extend(["--out", &o, "--stats", &st]);
        args.extend(budget);
        viewer_ok(&args);
        assert!(RgbImage::read(&out).is_ok(), "{name}: no image written");
        serde_json::from_slice::<serde_json::Value>(&std::fs::read(&stats).unwrap()).unwrap()
    };
    // Unbudgeted, this view takes more than one frame: its first frame asks for bricks.
    let free = stats_of(&[], "free");
    assert_eq!(free["converged"], true);
    assert_eq!(free["stop_reason"], "converged: no brick requested");
    assert!(free["frames"].as_array().unwrap().len() >= 2, "{free}");

    let frames = stats_of(&["--max-frames", "1"], "frames");
    assert_eq!(frames["converged"], false);
    assert_eq!(frames["stop_reason"], "frame budget of 1 frames spent");
    assert_eq!(frames["frames"].as_array().unwrap().len(), 1);

    // A microsecond is spent before the first frame's bricks are asked for.
    let time = stats_of(&["--time-budget-s", "0.000001"], "time");
    assert_eq!(time["converged"], false);
    assert_eq!(time["stop_reason"], "time budget spent");
    assert_eq!(time["frames"].as_array().unwrap().len(), 1);

    let err = fails(&[
        "render",
        "--store",
        &store,
        "--out",
        &s(&dir.path().join("never.png")),
        "--time-budget-s",
        "0",
    ]);
    assert!(err.contains("--time-budget-s 0 must be positive"), "{err}");
}
