//! Helpers for the workspace-level integration tests in `tests/tests/`: they run the real
//! release binaries (built by `scripts/test.sh` before `cargo test`).

#![warn(missing_docs)]

use std::path::PathBuf;
use std::process::{Command, Output};

/// Path of a workspace binary in `target/release`, or the folder in `RESIDENCY_BIN`.
pub fn binary(name: &str) -> PathBuf {
    let dir = std::env::var_os("RESIDENCY_BIN").map_or_else(
        || PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../target/release"),
        PathBuf::from,
    );
    let path = dir.join(name);
    assert!(
        path.exists(),
        "{} is not built: run `cargo build --release --workspace --bins` first",
        path.display()
    );
    path
}

/// Runs a workspace binary and returns its output, failing the test with its stderr when
/// it exits non-zero.
pub fn run(name: &str, args: &[&str]) -> Output {
    let out = Command::new(binary(name))
        .args(args)
        .output()
        .expect("spawn binary");
    assert!(
        out.status.success(),
        "{name} {args:?} failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}
