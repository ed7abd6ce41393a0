#!/usr/bin/env bash
# Runs every test: installs what is missing, builds the binaries, runs the Rust tests, then
# the external-client tests (tifffile inputs, zarr-python and ome-zarr-models readers).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-/tmp}"
cargo build --release --workspace --bins
cargo test --release --workspace
RESIDENCY_BIN="$PWD/target/release" .venv/bin/python -m pytest -q tests/python
