#!/usr/bin/env bash
# The server benchmark on the lent machine's cores (see benchmarks/device/prepare.sh, which
# makes the binaries and the client and peer packages this carries): unpacks wrk and nginx
# with their libraries into a folder of their own (never into /), unpacks `brickserver` and
# `ingest`, runs `benchmarks/server_bench.py` with wrk for DURATION seconds a run (default 4)
# and REPEAT rounds (default 3), and copies its report and JSON to $OUT. With 16 CPUs its rows
# "pinned apart" put the servers on the upper 8 and wrk on the lower 8: the client on cores of
# its own, which the 2-core development machine cannot give it (issue 33).
# The bench stops after LIMIT_S seconds (default 420), so that the command ends inside the
# device tool's limit.
#
#   bash benchmarks/device/server.sh      # on the device, with .gpu-bin and .srv carried
#   OUT=/tmp/out BIN_DIR=target/release PYTHON=.venv/bin/python DURATION=1 REPEAT=1 \
#       bash benchmarks/device/server.sh  # here, with the system's wrk and nginx
# (PYTHON: a python3 with numpy, default python3, which on the GPU machine has it.)
set -euo pipefail
cd "$(dirname "$0")/../.."
# shellcheck source=benchmarks/device/common.sh
. benchmarks/device/common.sh
: "${OUT:?set OUT to the folder the results go to}"
DURATION="${DURATION:-4}" REPEAT="${REPEAT:-3}" LIMIT_S="${LIMIT_S:-420}" PYTHON="${PYTHON:-python3}"

if [ -z "${BIN_DIR:-}" ]; then
    root=/tmp/residency-srv
    mkdir -p "$root/bin"
    for f in .srv/*.deb; do dpkg -x "$f" "$root"; done
    # Each tool through a wrapper that finds the carried libraries, so that nothing else
    # (python3 among them) loads them.
    for tool in usr/bin/wrk usr/sbin/nginx; do
        printf '#!/bin/sh\nLD_LIBRARY_PATH=%s exec %s "$@"\n' \
            "$root/usr/lib/x86_64-linux-gnu" "$root/$tool" > "$root/bin/${tool##*/}"
        chmod +x "$root/bin/${tool##*/}"
    done
    export PATH="$root/bin:$PATH"
    BIN_DIR=/tmp/residency-bin
    unpack_bins "$BIN_DIR" brickserver ingest
fi
echo "$(nproc) CPUs; $(wrk --version 2>&1 | head -1); $(nginx -v 2>&1)"
export RESIDENCY_BIN="$BIN_DIR" PYTHONUNBUFFERED=1
status=0
timeout "$LIMIT_S" "$PYTHON" benchmarks/server_bench.py --client wrk --duration "$DURATION" \
    --repeat "$REPEAT" --work /tmp/residency-sbw || status=$?
mkdir -p "$OUT"
cp docs/benchmarks/server.md docs/benchmarks/server.json "$OUT/" 2>/dev/null || true
ls -la "$OUT"
exit "$status"
