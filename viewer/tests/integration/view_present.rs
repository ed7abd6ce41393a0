//! `viewer view` presents on the GPU (a wgpu surface of the window; lavapipe presents to
//! Xvfb) and by the CPU blit, and both put the same pixels on the X screen: for a volume
//! (`view --store`, converged) and for a volumetric depth image (`view --vdi`, at rest at full
//! resolution), compared on real screenshots below the statistics panel. Also: `view --vdi`
//! refuses what does not apply to a VDI with a message naming it.

use std::process::Command;
use std::time::Duration;

use crate::render_cli::{VIEW, fails, s, viewer_ok};
use crate::view_xvfb::{SCREEN, X, spawn_with_lines, store, xvfb};

const WINDOW: (u32, u32) = (320, 240);

/// Rows of the window at the top that the statistics panel may cover (its numbers differ
/// from run to run).
const PANEL_ROWS: usize = 100;

/// Runs `viewer view ARGS --present PATH` on `display` until its view settles and the window
/// holds still, takes a screenshot, quits it with `q`, and returns its stderr (logged at info),
/// its summary line and the window's pixels below the panel.
fn shown(display: &str, args: &[&str], present: &str) -> (String, String, Vec<[u8; 3]>) {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_viewer"));
    if std::env::var_os("XDG_RUNTIME_DIR").is_none() {
        cmd.env("XDG_RUNTIME_DIR", "/tmp");
    }
    cmd.env("DISPLAY", display)
        .env("RUST_LOG", "info")
        .arg("view")
        .args(args)
        .args(["--width", &WINDOW.0.to_string()])
        .args(["--height", &WINDOW.1.to_string()])
        .args(["--present", present])
        .args(["--exit-after-frames", "1000", "--exit-delay-ms", "12000"]);
    let (mut child, rx, err_thread) = spawn_with_lines(&mut cmd);
    let line = rx
        .recv_timeout(Duration::from_mins(4))
        .unwrap_or_else(|e| panic!("{present}: no summary line: {e}"));
    assert!(line.starts_with("view: "), "{line:?}");
    let x = X::open(display);
    let pixels = x.still_screenshot();
    x.point(160, 200);
    x.type_char('q');
    let status = child.0.wait().unwrap();
    let stderr = err_thread.join().unwrap();
    assert!(
        status.success(),
        "{present}: viewer failed: {status}\n{stderr}"
    );
    let (w, h) = (WINDOW.0 as usize, WINDOW.1 as usize);
    let below: Vec<[u8; 3]> = (PANEL_ROWS..h)
        .flat_map(|y| pixels[y * SCREEN.0 as usize..][..w].to_vec())
        .collect();
    (stderr, line, below)
}

/// Asserts both ways of presenting show the same, lit pixels, and returns the summary line of
/// the GPU path.
fn same_on_both_paths(display: &str, args: &[&str]) -> String {
    let (gpu_log, line, gpu) = shown(display, args, "gpu");
    assert!(
        gpu_log.contains("presenting on the GPU ("),
        "no GPU surface under Xvfb: {gpu_log}"
    );
    let (cpu_log, _, cpu) = shown(display, args, "cpu");
    assert!(
        cpu_log.contains("presenting by a CPU blit (--present cpu)"),
        "{cpu_log}"
    );
    let lit = gpu.iter().filter(|p| p.iter().any(|&c| c > 40)).count();
    assert!(lit >= gpu.len() / 20, "{args:?}: blank window ({lit} lit)");
    let differ = gpu.iter().zip(&cpu).filter(|(a, b)| a != b).count();
    assert_eq!(differ, 0, "{args:?}: GPU and CPU presentation differ");
    line
}

#[test]
fn view_presents_the_same_pixels_on_the_gpu_as_by_the_cpu_blit_under_xvfb() {
    let dir = tempfile::tempdir().unwrap();
    let (_xvfb, display) = xvfb();
    // A volume, converged.
    let volume = s(&store(dir.path()));
    same_on_both_paths(
        &display,
        &[
            "--store",
            &volume,
            "--camera",
            "30,-25,1.6",
            "--render-scale",
            "0.5",
        ],
    );
    // A VDI of another store, at rest.
    let vdi_store = s(&crate::render_cli::store(dir.path()));
    let vdi = s(&dir.path().join("view.vdi"));
    let mut args = vec!["vdi", "--store", &vdi_store, "--out", &vdi];
    args.extend(VIEW);
    args.extend(["--width", "64", "--height", "48", "--max-level", "0"]);
    viewer_ok(&args);
    let line = same_on_both_paths(&display, &["--vdi", &vdi, "--render-scale", "0.5"]);
    // `--target-fps` is 60 by default: 16.7 ms a frame.
    assert!(
        line.ends_with(" (160x120 rays, linear filter), target 16.7 ms"),
        "{line}"
    );
    // From a camera turned away from the VDI's, at rest: the linear filter by default.
    let line = same_on_both_paths(
        &display,
        &[
            "--vdi",
            &vdi,
            "--render-scale",
            "0.5",
            "--camera",
            "-13.8,-51.0,70:20,16,24",
            "--target-fps",
            "30",
        ],
    );
    assert!(
        line.ends_with(" (160x120 rays, linear filter), target 33.3 ms"),
        "{line}"
    );
}

#[test]
fn view_vdi_refuses_what_does_not_apply_to_a_vdi() {
    let dir = tempfile::tempdir().unwrap();
    let vdi = s(&dir.path().join("x.vdi"));
    let err = fails(&["view", "--vdi", &vdi]);
    assert!(err.contains(&format!("error: {vdi}: cannot read")), "{err}");
    std::fs::write(&vdi, b"not a vdi at all").unwrap();
    let err = fails(&["view", "--vdi", &vdi]);
    assert!(
        err.contains(&format!("error: {vdi}: not a VDI (bad magic)")),
        "{err}"
    );
    let err = fails(&["view", "--vdi", &vdi, "--tf", "0:1:2:0.5"]);
    assert!(
        err.contains(
            "error: --tf does not apply to a VDI: its colours, transfer functions, background, \
             filter, mode and clipping were fixed when it was generated (`viewer vdi`)"
        ),
        "{err}"
    );
    let err = fails(&["view", "--vdi", &vdi, "--target-fps", "0"]);
    assert!(
        err.contains("error: --target-fps 0 must be positive"),
        "{err}"
    );
    let err = fails(&["view", "--vdi", &vdi, "--store", "x.ome.zarr"]);
    assert!(err.contains("cannot be used with"), "{err}");
    let err = fails(&["view", "--store", "x.ome.zarr", "--target-fps", "30"]);
    assert!(
        err.contains("error: --target-fps applies to a VDI only (with --vdi)"),
        "{err}"
    );
    let err = fails(&["view", "--store", "x.ome.zarr", "--vdi-no-skipping"]);
    assert!(
        err.contains("error: --vdi-no-skipping applies to a VDI only (with --vdi)"),
        "{err}"
    );
    let err = fails(&["view", "--store", "x.ome.zarr", "--vdi-filter", "linear"]);
    assert!(
        err.contains("error: --vdi-filter applies to a VDI only (with --vdi)"),
        "{err}"
    );
    let err = fails(&["view", "--vdi", &vdi, "--present", "screen"]);
    assert!(
        err.contains("invalid value 'screen' for '--present <PATH>'"),
        "{err}"
    );
}
