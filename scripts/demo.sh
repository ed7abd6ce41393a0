#!/usr/bin/env bash
# The main job on the built-in sample: generates the synthetic stack, converts it to an
# OME-Zarr pyramid with region metadata, and prints where the result is and how to open it.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
cargo build --release --bins
out=${1:-demo}
ingest=target/release/ingest
"$ingest" sample -o "$out/sample" --size 96,256,256
"$ingest" convert "$out"/sample/nuclei.ome.tif "$out"/sample/membranes.ome.tif "$out"/sample/filaments.ome.tif \
  -o "$out/sample.ome.zarr" --overwrite
"$ingest" inspect "$out/sample.ome.zarr"
cat <<TXT

The OME-Zarr store is $PWD/$out/sample.ome.zarr
Open it with any OME-Zarr reader, for example:
  .venv/bin/python -c "import zarr; g = zarr.open_group('$out/sample.ome.zarr', mode='r'); print(g['0'].shape)"
  napari --plugin napari-ome-zarr $out/sample.ome.zarr
TXT
