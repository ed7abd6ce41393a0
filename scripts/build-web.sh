#!/usr/bin/env bash
# Builds the web viewer: the viewer library compiled to WebAssembly (wgpu on WebGPU), its
# JavaScript glue (wasm-bindgen) and the page (viewer/web: the page, and the worker that reads
# VDIs off its main thread), into target/release/web/ where
# `brickserver serve` finds it (its --viewer-dir default: the folder `web` beside the binary).
#
#   scripts/build-web.sh [OUT_DIR]
#
# Installs what is missing, idempotently: the wasm32-unknown-unknown target (rustup) and
# wasm-bindgen-cli at exactly the version of the `wasm-bindgen` crate in Cargo.lock (built from
# crates.io into ~/.cargo/bin, about 6 minutes once). Writes to OUT_DIR.tmp, then renames, so a
# failed build never leaves a half-written viewer. Needs clang (scripts/setup.sh installs it):
# the viewer reads zstd-compressed VDIs with zstd's C library, compiled to WebAssembly.
set -euo pipefail
cd "$(dirname "$0")/.."
OUT="${1:-target/release/web}"

if ! rustup target list --installed 2>/dev/null | grep -qx wasm32-unknown-unknown; then
    echo "== adding the wasm32-unknown-unknown target"
    if ! rustup target add wasm32-unknown-unknown; then
        echo "cannot add the Rust target wasm32-unknown-unknown (rustup target add failed):" \
            "the web viewer needs it; check network access to static.rust-lang.org" >&2
        exit 1
    fi
fi

WB_VERSION=$(awk '/^name = "wasm-bindgen"$/ { getline; gsub(/version = |"/, ""); print; exit }' Cargo.lock)
if [ -z "$WB_VERSION" ]; then
    echo "Cargo.lock names no wasm-bindgen version" >&2
    exit 1
fi
if ! wasm-bindgen --version 2>/dev/null | grep -qx "wasm-bindgen $WB_VERSION"; then
    echo "== installing wasm-bindgen-cli $WB_VERSION (once; about 6 minutes on 2 cores)"
    # Not --locked: its lock file names a crate version this registry lacks.
    cargo install wasm-bindgen-cli --version "$WB_VERSION"
fi

if ! command -v clang >/dev/null 2>&1; then
    echo "clang not found: the web viewer compiles zstd's C to WebAssembly with it" \
        "(run scripts/setup.sh, or apt-get install clang)" >&2
    exit 1
fi

echo "== building the viewer for wasm32-unknown-unknown"
# `cargo rustc --crate-type cdylib`: the native builds keep the library an rlib only.
cargo rustc --release --target wasm32-unknown-unknown -p residency-viewer --lib --crate-type cdylib
WASM=target/wasm32-unknown-unknown/release/residency_viewer.wasm

rm -rf "$OUT.tmp"
mkdir -p "$OUT.tmp"
wasm-bindgen --target web --no-typescript --out-dir "$OUT.tmp" "$WASM"
cp viewer/web/index.html viewer/web/main.js viewer/web/vdi_worker.js viewer/web/style.css "$OUT.tmp/"
rm -rf "$OUT"
mv "$OUT.tmp" "$OUT"
echo "== web viewer in $OUT ($(du -sh "$OUT" | cut -f1))"
