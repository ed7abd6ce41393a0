#!/usr/bin/env bash
# The VDI benchmark on the lent GPU machine (see benchmarks/device/prepare.sh, which makes the
# binaries and loader this carries): unpacks the Vulkan loader and the binaries, runs
# `benchmarks/vdi_bench.py` at WIDTH×HEIGHT (default 1920×1080, the paper's HD frames) on
# volumes of edge VOLUME (default 256) into a scratch folder, and copies the report, each
# dataset's JSON results and plots to $OUT (7 files: the device tool brings back at most 8).
# The bench stops after LIMIT_S seconds (default 420) so that what finished still comes back:
# then each finished dataset's table comes back instead of the report.
#
#   bash benchmarks/device/vdi.sh      # on the device, with .gpu-bin and .gl carried
#   OUT=/tmp/out BIN_DIR=target/release WIDTH=64 HEIGHT=48 VOLUME=32 bash benchmarks/device/vdi.sh
#                                      # here, on lavapipe
set -euo pipefail
cd "$(dirname "$0")/../.."
# shellcheck source=benchmarks/device/common.sh
. benchmarks/device/common.sh
: "${OUT:?set OUT to the folder the results go to}"
WIDTH="${WIDTH:-1920}" HEIGHT="${HEIGHT:-1080}" VOLUME="${VOLUME:-256}" LIMIT_S="${LIMIT_S:-420}"

if [ -z "${BIN_DIR:-}" ]; then
    for f in .gl/*.deb; do dpkg -x "$f" /; done
    ldconfig
    if [ -f /usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json ]; then
        export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
    fi
    BIN_DIR=/tmp/residency-bin
    unpack_bins "$BIN_DIR" viewer ingest
fi
command -v nvidia-smi >/dev/null && nvidia-smi --query-gpu=name,driver_version --format=csv,noheader
export RESIDENCY_BIN="$BIN_DIR" XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-/tmp}" PYTHONUNBUFFERED=1
report=/tmp/residency-vdi-report
rm -rf "$report"
status=0
timeout "$LIMIT_S" python3 benchmarks/vdi_bench.py --width "$WIDTH" --height "$HEIGHT" --volume "$VOLUME" \
    --out-dir "$report" --data-dir /tmp/residency-data || status=$?
mkdir -p "$OUT"
if [ -f "$report/vdi-bench.md" ]; then
    cp "$report/vdi-bench.md" "$OUT/"
else
    echo "the bench stopped (exit $status) before its report: copying the finished datasets' tables"
    cp "$report"/vdi/*.md "$OUT/" 2>/dev/null || true
fi
cp "$report"/vdi/*.json "$report"/vdi/*.png "$OUT/" 2>/dev/null || true
ls -la "$OUT"
exit "$status"
