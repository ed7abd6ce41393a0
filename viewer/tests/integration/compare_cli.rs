//! `viewer compare` end to end: metrics as text and JSON, the EXR error map, and errors.

use std::process::Command;

use residency_viewer::image::RgbImage;

fn viewer(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_viewer"))
        .args(args)
        .output()
        .unwrap()
}

fn json(out: &std::process::Output) -> serde_json::Value {
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

#[test]
fn metrics_and_error_map_of_hand_made_images() {
    let dir = tempfile::tempdir().unwrap();
    let p = |n: &str| dir.path().join(n).to_str().unwrap().to_string();
    let a = RgbImage::filled(16, 12, [0.25, 0.5, 0.75]);
    let mut b = a.clone();
    // One pixel off by 0.5 in green: MSE = 0.25 / (3·192).
    b.pixels[5 * 16 + 7] = [0.25, 1.0, 0.75];
    a.write(dir.path().join("a.exr").as_path()).unwrap();
    b.write(dir.path().join("b.exr").as_path()).unwrap();

    let same = json(&viewer(&["compare", &p("a.exr"), &p("a.exr"), "--json"]));
    assert_eq!(
        same["psnr_db"],
        serde_json::Value::Null,
        "infinite PSNR is null"
    );
    assert_eq!(same["ssim"], 1.0);
    assert_eq!(same["max_abs_error"], 0.0);

    let m = json(&viewer(&[
        "compare",
        &p("a.exr"),
        &p("b.exr"),
        "--json",
        "--error-map",
        &p("err.exr"),
    ]));
    let mse: f64 = 0.25 / 576.0;
    assert_eq!(m["mse"], mse);
    assert!((m["psnr_db"].as_f64().unwrap() - 10.0 * (1.0 / mse).log10()).abs() < 1e-12);
    assert_eq!(m["max_abs_error"], 0.5);
    // SSIM in closed form: x is flat (mean μ, no variance), y differs by δ at one pixel of
    // window weight w, so μy = μ + wδ, σy² = wδ²(1 − w), cov = 0; every 11×11 window position
    // (6 × 2 of them) contains the pixel (7, 5).
    let g: Vec<f64> = (0..11)
        .map(|i| (-((i as f64 - 5.0).powi(2)) / 4.5).exp())
        .collect();
    let norm: f64 = g.iter().sum();
    let mu = 0.2126 * 0.25 + 0.7152 * 0.5 + 0.0722 * 0.75;
    let delta = 0.7152 * 0.5;
    let (c1, c2) = (1e-4, 9e-4);
    let mut expected = 0.0;
    for oy in 0..2 {
        for ox in 0..6 {
            let w = g[7 - ox] * g[5 - oy] / (norm * norm);
            let my = mu + w * delta;
            let vy = w * delta * delta * (1.0 - w);
            expected += (2.0 * mu * my + c1) * c2 / ((mu * mu + my * my + c1) * (vy + c2));
        }
    }
    expected /= 12.0;
    let ssim = m["ssim"].as_f64().unwrap();
    assert!((ssim - expected).abs() < 1e-9, "{ssim} vs {expected}");
    let err = RgbImage::read(dir.path().join("err.exr").as_path()).unwrap();
    assert_eq!((err.width, err.height), (16, 12));
    for (i, px) in err.pixels.iter().enumerate() {
        let want = if i == 5 * 16 + 7 {
            [0.0, 0.5, 0.0]
        } else {
            [0.0; 3]
        };
        assert_eq!(*px, want, "pixel {i}");
    }

    // Text output, and a PNG against itself.
    a.write(dir.path().join("a.png").as_path()).unwrap();
    let out = viewer(&["compare", &p("a.png"), &p("a.png")]);
    assert!(out.status.success());
    assert_eq!(
        String::from_utf8(out.stdout).unwrap(),
        "PSNR inf dB\nSSIM 1.000000\nmax abs error 0.000000\n"
    );
}

#[test]
fn mismatched_or_missing_images_fail_with_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let p = |n: &str| dir.path().join(n).to_str().unwrap().to_string();
    RgbImage::filled(16, 12, [0.0; 3])
        .write(dir.path().join("a.exr").as_path())
        .unwrap();
    RgbImage::filled(12, 16, [0.0; 3])
        .write(dir.path().join("b.exr").as_path())
        .unwrap();
    let out = viewer(&["compare", &p("a.exr"), &p("b.exr")]);
    assert!(!out.status.success());
    assert_eq!(
        String::from_utf8(out.stderr).unwrap().trim(),
        format!(
            "error: {} vs {}: images differ in size: 16×12 and 12×16",
            p("a.exr"),
            p("b.exr")
        )
    );
    let out = viewer(&["compare", &p("a.exr"), &p("missing.png")]);
    assert!(!out.status.success());
    let err = String::from_utf8(out.stderr).unwrap();
    assert!(
        err.starts_with(&format!("error: {}: cannot read PNG", p("missing.png"))),
        "{err}"
    );
}
