#!/usr/bin/env bash
# The VDI benchmark on the lent GPU machine (see benchmarks/device/prepare.sh, which makes the
# binaries and loader this carries): unpacks the Vulkan loader and the binaries, runs
# `benchmarks/vdi_bench.py` at SIZE×SIZE (default 1080, the paper's HD height) into a scratch
# folder, and copies the report, each dataset's JSON results and plots to $OUT (7 files: the
# device tool brings back at most 8).
#
#   SIZE=1080 bash benchmarks/device/vdi.sh      # on the device, with .gpu-bin and .gl carried
#   OUT=/tmp/out BIN_DIR=target/release bash benchmarks/device/vdi.sh   # here, on lavapipe
set -euo pipefail
cd "$(dirname "$0")/../.."
: "${OUT:?set OUT to the folder the results go to}"
SIZE="${SIZE:-1080}"

if [ -z "${BIN_DIR:-}" ]; then
    for f in .gl/*.deb; do dpkg -x "$f" /; done
    ldconfig
    if [ -f /usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json ]; then
        export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
    fi
    BIN_DIR=/tmp/residency-bin
    mkdir -p "$BIN_DIR"
    for exe in viewer ingest; do
        gunzip -c ".gpu-bin/$exe.gz" > "$BIN_DIR/$exe"
        chmod +x "$BIN_DIR/$exe"
    done
fi
command -v nvidia-smi >/dev/null && nvidia-smi --query-gpu=name,driver_version --format=csv,noheader
export RESIDENCY_BIN="$BIN_DIR" XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-/tmp}" PYTHONUNBUFFERED=1
report=/tmp/residency-vdi-report
rm -rf "$report"
python3 benchmarks/vdi_bench.py --size "$SIZE" --out-dir "$report" --data-dir /tmp/residency-data
mkdir -p "$OUT"
cp "$report/vdi-bench.md" "$OUT/"
cp "$report"/vdi/*.json "$report"/vdi/*.png "$OUT/"
ls -la "$OUT"
