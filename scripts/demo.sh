#!/usr/bin/env bash
# The main job on the built-in sample: generates the synthetic stack, converts it to an
# OME-Zarr pyramid with region metadata, serves it with brickserver, renders it with the
# GPU viewer (lavapipe when there is no GPU), builds the web viewer, and prints where
# everything is, with the link that opens the sample in a WebGPU browser.
#
#   scripts/demo.sh [--serve] [OUT_DIR]
#
# --serve keeps brickserver running at the end (on 127.0.0.1:8000, or BIND=ADDR:PORT) so the
# printed link works; stop it with Ctrl-C.
set -euo pipefail
cd "$(dirname "$0")/.."
serve=""
if [ "${1:-}" = "--serve" ]; then
  serve=1
  shift
fi
bash scripts/setup.sh
export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-/tmp}"
cargo build --release --bins
bash scripts/build-web.sh
out=${1:-demo}
bin=target/release
"$bin/ingest" sample -o "$out/sample" --size 96,256,256
"$bin/ingest" convert "$out"/sample/nuclei.ome.tif "$out"/sample/membranes.ome.tif "$out"/sample/filaments.ome.tif \
  -o "$out/sample.ome.zarr" --overwrite
"$bin/ingest" inspect "$out/sample.ome.zarr"

# Serve it on a free loopback port, render it through the server, stop the server.
log=$(mktemp)
"$bin/brickserver" serve "$out/sample.ome.zarr" --bind 127.0.0.1:0 >"$log" 2>&1 &
server=$!
trap 'kill "$server" 2>/dev/null || true; rm -f "$log"' EXIT
url=""
for _ in $(seq 300); do
  url=$(sed -n 's/^listening on //p' "$log")
  [ -n "$url" ] && break
  kill -0 "$server" 2>/dev/null || break
  sleep 0.1
done
[ -n "$url" ] || { cat "$log" >&2; echo "brickserver did not start" >&2; exit 1; }
"$bin/viewer" render --server "$url" --dataset sample --camera 30,20,1.6 \
  --width 384 --height 384 --out "$out/sample.png" --stats "$out/sample-stats.json"
kill "$server"; wait "$server" 2>/dev/null || true

abs=$(cd "$out" && pwd)
cat <<TXT

The OME-Zarr store is $abs/sample.ome.zarr
The GPU render is     $abs/sample.png (frame statistics in $abs/sample-stats.json)
Serve it to any OME-Zarr viewer (neuroglancer, vizarr, napari, zarr-python), and to the
Residency web viewer (any WebGPU browser: current Chrome or Edge):
  $bin/brickserver serve $out/sample.ome.zarr            # then open http://127.0.0.1:8000/sample/view
                                                         # (http://127.0.0.1:8000/ lists every dataset)
Read it directly:
  .venv/bin/python -c "import zarr; g = zarr.open_group('$out/sample.ome.zarr', mode='r'); print(g['0'].shape)"
TXT

if [ -n "$serve" ]; then
  bind=${BIND:-127.0.0.1:8000}
  echo
  echo "Serving on http://$bind: open http://$bind/sample/view in a WebGPU browser (Ctrl-C stops)."
  # exec skips the EXIT trap: its log is removed here (the first server has stopped).
  trap - EXIT
  rm -f "$log"
  exec "$bin/brickserver" serve "$out/sample.ome.zarr" --bind "$bind"
fi
