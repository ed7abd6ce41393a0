//! `viewer vdi` and `viewer render --vdi` end to end on a store written by `ingest`: the VDI
//! file composites back to `viewer render`'s image of the same view, ray casting it from its
//! own camera gives that image again, and bad input fails with a message naming the problem.

use std::path::Path;

use crate::render_cli::{VIEW, fails, s, store, viewer_ok};
use residency_schemas::vdi::VolumetricDepthImage;
use residency_viewer::image::RgbImage;
use residency_viewer::metrics;

#[test]
fn a_vdi_file_gives_back_the_image_of_its_view() {
    let dir = tempfile::tempdir().unwrap();
    let store = s(&store(dir.path()));
    let (vdi, dvr, cast) = (
        s(&dir.path().join("blob.vdi")),
        s(&dir.path().join("dvr.exr")),
        s(&dir.path().join("cast.exr")),
    );
    let size = ["--width", "40", "--height", "32", "--max-level", "0"];
    let mut args = vec![
        "vdi",
        "--store",
        &store,
        "--supersegments",
        "12",
        "--out",
        &vdi,
    ];
    args.extend(VIEW);
    args.extend(size);
    viewer_ok(&args);
    let mut args = vec!["render", "--store", &store, "--out", &dvr];
    args.extend(VIEW);
    args.extend(size);
    viewer_ok(&args);
    viewer_ok(&[
        "render", "--vdi", &vdi, "--width", "40", "--height", "32", "--out", &cast,
    ]);
    let linear = s(&dir.path().join("linear.exr"));
    viewer_ok(&[
        "render",
        "--vdi",
        &vdi,
        "--vdi-filter",
        "linear",
        "--width",
        "40",
        "--height",
        "32",
        "--out",
        &linear,
    ]);

    let image = VolumetricDepthImage::decode(&std::fs::read(&vdi).unwrap(), &vdi).unwrap();
    let h = &image.header;
    assert_eq!(
        (h.width, h.height, h.supersegments, h.channels),
        (40, 32, 12, 2)
    );
    assert_eq!(h.dataset.as_deref(), Some("blob"));
    assert_eq!(h.camera.eye, [-30.0, -40.0, 70.0]);
    assert!(image.counts.iter().any(|&c| c > 1));
    // No partial file is left beside it.
    let names: Vec<String> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.contains("vdi"))
        .collect();
    assert_eq!(names, ["blob.vdi"]);

    let dvr = RgbImage::read(Path::new(&dvr)).unwrap();
    let composited = RgbImage {
        width: 40,
        height: 32,
        pixels: (0..32)
            .flat_map(|y| (0..40).map(move |x| (x, y)))
            .map(|(x, y)| {
                let [r, g, b, _] = image.composite(x, y);
                [r, g, b]
            })
            .collect(),
    };
    let m = metrics::compare(&composited, &dvr).unwrap();
    assert!(m.max_abs_error <= 5e-3, "composited VDI vs DVR: {m:?}");
    let m = metrics::compare(&RgbImage::read(Path::new(&cast)).unwrap(), &dvr).unwrap();
    assert!(
        m.max_abs_error <= 5e-3,
        "VDI ray cast from its camera vs DVR: {m:?}"
    );
    // The linear filter too: from V_O each ray reads its own list alone.
    let m = metrics::compare(&RgbImage::read(Path::new(&linear)).unwrap(), &dvr).unwrap();
    assert!(
        m.max_abs_error <= 5e-3,
        "VDI ray cast with the linear filter from its camera vs DVR: {m:?}"
    );
}

/// The image size of [`small_vdi`] and [`render_moved`].
const SMALL: [&str; 4] = ["--width", "40", "--height", "32"];

/// The store under `dir` and a VDI of it from [`VIEW`]'s camera at [`SMALL`]'s size: their
/// paths.
fn small_vdi(dir: &Path) -> (String, String) {
    let store = s(&store(dir));
    let vdi = s(&dir.join("blob.vdi"));
    let mut args = vec!["vdi", "--store", &store, "--max-level", "0", "--out", &vdi];
    args.extend(VIEW);
    args.extend(SMALL);
    viewer_ok(&args);
    (store, vdi)
}

/// `viewer render --vdi VDI` with `extra` flags from [`VIEW`]'s camera turned about 15° about
/// its target, at [`SMALL`]'s size, written to `dir/NAME.exr` and read back.
fn render_moved(dir: &Path, vdi: &str, extra: &[&str], name: &str) -> RgbImage {
    let out = s(&dir.join(format!("{name}.exr")));
    let moved = "-13.8,-51.0,70:20,16,24";
    let mut args = vec!["render", "--vdi", vdi, "--camera", moved, "--out", &out];
    args.extend(SMALL);
    args.extend(extra);
    viewer_ok(&args);
    RgbImage::read(Path::new(&out)).unwrap()
}

/// A single image from away from the VDI's camera is a frame at rest: `auto`, the default,
/// draws it with the linear filter, pixel for pixel, and the nearest list draws it otherwise.
#[test]
fn render_reads_a_vdi_with_the_linear_filter_by_default() {
    let dir = tempfile::tempdir().unwrap();
    let (_, vdi) = small_vdi(dir.path());
    let cast = |filter: &str| {
        let flags = ["--vdi-filter", filter];
        let extra: &[&str] = if filter == "default" { &[] } else { &flags };
        render_moved(dir.path(), &vdi, extra, filter)
    };
    let (default, auto) = (cast("default"), cast("auto"));
    let (linear, nearest) = (cast("linear"), cast("nearest"));
    assert_eq!(default.pixels, linear.pixels);
    assert_eq!(auto.pixels, linear.pixels);
    let m = metrics::compare(&nearest, &linear).unwrap();
    assert!(m.max_abs_error > 1e-3, "the filters agree: {m:?}");
}

/// `--vdi-ray-sampling` samples along the nearest filter's rays: close to its image, the same
/// at 1, and refused with another filter, out of range, or without a VDI.
#[test]
fn render_samples_along_the_rays_of_the_nearest_filter_only() {
    let dir = tempfile::tempdir().unwrap();
    let (store, vdi) = small_vdi(dir.path());
    let cast = |d_r: Option<&str>, name: &str| {
        let mut flags = vec!["--vdi-filter", "nearest"];
        flags.extend(d_r.map(|d| ["--vdi-ray-sampling", d]).into_iter().flatten());
        render_moved(dir.path(), &vdi, &flags, name)
    };
    let (every_list, every) = (cast(None, "nearest"), cast(Some("1"), "every"));
    let half = cast(Some("0.5"), "half");
    assert_eq!(every.pixels, every_list.pixels);
    let m = metrics::compare(&half, &every_list).unwrap();
    assert!(m.max_abs_error > 0.0 && m.ssim > 0.9, "{m:?}");
    let png = s(&dir.path().join("x.png"));
    let err = fails(&[
        "render",
        "--vdi",
        &vdi,
        "--vdi-ray-sampling",
        "0.5",
        "--out",
        &png,
    ]);
    assert!(
        err.contains(
            "error: --vdi-ray-sampling samples the nearest filter's lists: add --vdi-filter \
             nearest (this image would be drawn with the linear filter)"
        ),
        "{err}"
    );
    for bad in ["0", "1.5", "half"] {
        let err = fails(&[
            "render",
            "--vdi",
            &vdi,
            "--vdi-ray-sampling",
            bad,
            "--out",
            &png,
        ]);
        assert!(
            err.contains(&format!(
                "invalid value '{bad}' for '--vdi-ray-sampling <D_R>': '{bad}' is not a sampling \
                 along the ray: a number from 0.01 to 1 (the share of the lists a ray crosses \
                 that it reads)"
            )),
            "{err}"
        );
    }
    let err = fails(&[
        "render",
        "--store",
        &store,
        "--vdi-ray-sampling",
        "0.5",
        "--out",
        &png,
    ]);
    assert!(
        err.contains("error: --vdi-ray-sampling applies to a VDI only (with --vdi)"),
        "{err}"
    );
    assert!(!Path::new(&png).exists());
}

#[test]
fn bad_vdi_input_fails_with_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let store = s(&store(dir.path()));
    let png = s(&dir.path().join("x.png"));
    let err = fails(&["vdi", "--store", &store, "--out", &png]);
    assert!(
        err.contains(&format!("error: {png}: a VDI is written as a .vdi file")),
        "{err}"
    );
    let vdi = s(&dir.path().join("x.vdi"));
    let err = fails(&[
        "vdi",
        "--store",
        &store,
        "--supersegments",
        "0",
        "--out",
        &vdi,
    ]);
    assert!(
        err.contains("error: --supersegments 0: a VDI has 1 to 64 supersegments per pixel"),
        "{err}"
    );
    assert!(!Path::new(&vdi).exists());
    std::fs::write(&vdi, b"not a vdi at all").unwrap();
    let err = fails(&["render", "--vdi", &vdi, "--out", &png]);
    assert!(
        err.contains(&format!("error: {vdi}: not a VDI (bad magic)")),
        "{err}"
    );
    let err = fails(&["render", "--vdi", &vdi, "--tf", "0:1:2:0.5", "--out", &png]);
    assert!(
        err.contains(
            "error: --tf does not apply to a VDI: its colours, transfer functions, background, \
             filter, mode and clipping were fixed when it was generated (`viewer vdi`)"
        ),
        "{err}"
    );
    let err = fails(&["render", "--vdi", &vdi, "--store", &store, "--out", &png]);
    assert!(err.contains("cannot be used with"), "{err}");
    let err = fails(&[
        "render",
        "--store",
        &store,
        "--vdi-no-skipping",
        "--out",
        &png,
    ]);
    assert!(
        err.contains("error: --vdi-no-skipping applies to a VDI only (with --vdi)"),
        "{err}"
    );
    let err = fails(&[
        "render",
        "--store",
        &store,
        "--vdi-filter",
        "linear",
        "--out",
        &png,
    ]);
    assert!(
        err.contains("error: --vdi-filter applies to a VDI only (with --vdi)"),
        "{err}"
    );
    let err = fails(&[
        "render",
        "--vdi",
        "x.vdi",
        "--vdi-filter",
        "cubic",
        "--out",
        &png,
    ]);
    assert!(
        err.contains("invalid value 'cubic' for '--vdi-filter <FILTER>'")
            && err.contains("[possible values: auto, nearest, linear]"),
        "{err}"
    );
    let err = fails(&[
        "vdi",
        "--store",
        &store,
        "--compression",
        "brotli",
        "--out",
        &vdi,
    ]);
    assert!(
        err.contains("invalid value 'brotli' for '--compression <COMPRESSION>'")
            && err.contains("[possible values: lz4, none, shuffled_lz4, shuffled_zstd]"),
        "{err}"
    );
}

/// `viewer vdi --server URL --dataset NAME` generates, from the bricks brickserver serves, the
/// VDI that `--store` generates from the files, byte for byte; with no `--supersegments` a
/// pixel holds up to 20 of them.
#[test]
fn a_vdi_over_the_server_is_the_vdi_of_the_store() {
    let dir = tempfile::tempdir().unwrap();
    let store_path = store(dir.path());
    let server = crate::source_common::Server::start(&[&store_path]);
    let store = s(&store_path);
    let (local, served) = (
        s(&dir.path().join("local.vdi")),
        s(&dir.path().join("served.vdi")),
    );
    let write = |source: &[&str], out: &str| {
        let mut args = vec!["vdi", "--out", out];
        args.extend(source);
        args.extend(VIEW);
        args.extend(["--width", "40", "--height", "32", "--max-level", "0"]);
        viewer_ok(&args);
    };
    write(&["--store", &store], &local);
    write(&["--server", &server.url, "--dataset", "blob"], &served);
    let bytes = std::fs::read(&local).unwrap();
    assert!(bytes == std::fs::read(&served).unwrap(), "the VDIs differ");
    let image = VolumetricDepthImage::decode(&bytes, &local).unwrap();
    assert_eq!(image.header.supersegments, 20);
    assert_eq!(image.header.dataset.as_deref(), Some("blob"));
    assert!(image.counts.iter().any(|&c| c > 1));
}
