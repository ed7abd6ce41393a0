#!/usr/bin/env bash
# Runs every test: installs what is missing, checks formatting and lints, builds the binaries,
# runs the Rust tests, a short run of every fuzz target, then the external-client tests
# (tifffile inputs, zarr-python and ome-zarr-models readers, the HTTP API, the web viewer and
# neuroglancer and Viv in headless Chromium).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-/tmp}"
cargo fmt --all --check
# The fuzz targets are a cargo project of their own (outside the workspace).
cargo fmt --manifest-path tests/fuzz/Cargo.toml --check
cargo clippy --workspace --all-targets -- -D warnings
cargo build --release --workspace --bins
# The web viewer (WebAssembly + WebGPU) into target/release/web, where brickserver finds it.
bash scripts/build-web.sh
cargo test --release --workspace
# A short run (10 s) of every fuzz target: the corpora and seeds must still run clean.
bash scripts/fuzz.sh 10
RESIDENCY_BIN="$PWD/target/release" .venv/bin/python -m pytest -q tests/python
