#!/usr/bin/env bash
# Runs every test: installs what is missing, checks formatting and lints, builds the binaries,
# runs the Rust tests, a short run of every fuzz target, then the external-client tests
# (tifffile inputs, zarr-python and ome-zarr-models readers, the HTTP API, the web viewer and
# neuroglancer and Viv in headless Chromium).
set -euo pipefail
cd "$(dirname "$0")/.."
# Each long step's wall time, and the run's so far: a run that nears CI's limit says which step
# grew (CI keeps the output of a run that fails).
timed() {
  local label=$1 start=$SECONDS
  shift
  "$@"
  echo "== $label: $((SECONDS - start)) s (run so far: $SECONDS s)"
}
timed setup bash scripts/setup.sh
# The disk this run has, and what the build folders take, printed at the start and before the
# external-client tests: a full disk fails every test after it, and this says how close it was.
disk() {
  echo "== disk ($1): $(df -h --output=avail . | tail -1 | tr -d ' ') free; target $(du -sh target 2>/dev/null | cut -f1), tests/fuzz/target $(du -sh tests/fuzz/target 2>/dev/null | cut -f1)"
}
disk start
# A real S3 server for the object-storage tests (tests/python/test_object_store.py): s3s-fs, the
# s3s project's S3 protocol server over a local folder, built once into ~/.cargo/bin (about
# 2 minutes on 2 cores). Garage would take an estimated 20-40 minutes to build here; see
# docs/storage.md.
S3S_FS_VERSION=0.14.1
if ! s3s-fs --version 2>/dev/null | grep -q " $S3S_FS_VERSION$"; then
  echo "== installing s3s-fs $S3S_FS_VERSION (once)"
  cargo install s3s-fs --version "$S3S_FS_VERSION" --features binary --locked
fi

export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-/tmp}"
# The tree's shape (docs/architecture.md): no import loop between modules, no Rust or WGSL file
# above 1,000 lines; the checker first proves on small trees that it finds both.
python3 scripts/check_structure.py --self-test
python3 scripts/check_structure.py
cargo fmt --all --check
# The fuzz targets are a cargo project of their own (outside the workspace).
cargo fmt --manifest-path tests/fuzz/Cargo.toml --check
timed clippy cargo clippy --workspace --all-targets -- -D warnings
timed doc env RUSTDOCFLAGS="-D warnings" cargo doc --workspace --no-deps
timed "release build" cargo build --release --workspace --bins
# The web viewer (WebAssembly + WebGPU) into target/release/web, where brickserver finds it.
timed "web build" bash scripts/build-web.sh
timed wheel bash scripts/build-wheel.sh
timed "cargo test" cargo test --release --workspace
# A short run (10 s) of every fuzz target: the corpora and seeds must still run clean.
timed fuzz bash scripts/fuzz.sh 10
disk "before the external-client tests"
# The slowest tests are listed at the end, for whoever trims the suite's time.
timed pytest env RESIDENCY_BIN="$PWD/target/release" .venv/bin/python -m pytest -q --durations=25 tests/python
