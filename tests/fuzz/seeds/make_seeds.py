"""Writes the seed corpora of the fuzz targets (tests/fuzz/seeds/TARGET/), small valid
inputs the fuzzer starts from. Run with the project's venv (tifffile, numpy):

    .venv/bin/python tests/fuzz/seeds/make_seeds.py

The files are committed; rerunning rewrites them identically.
"""

import json
import os
import pathlib
import struct
import subprocess
import tempfile

import numpy as np
import tifffile

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parents[2]


def out(target, name, data):
    d = HERE / target
    d.mkdir(parents=True, exist_ok=True)
    (d / name).write_bytes(data)


def tiffs():
    d = HERE / "tiff_file"
    d.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(7)
    vol = rng.integers(0, 4000, size=(3, 5, 7), dtype=np.uint16)

    def w(name, data, **kw):
        tifffile.imwrite(d / name, data, **kw)

    w("plain_u16.tif", vol, photometric="minisblack")
    w("lzw_u16.tif", vol, photometric="minisblack", compression="lzw")
    w("deflate_pred_u16.tif", vol, photometric="minisblack", compression="zlib", predictor=True)
    w("packbits_u8.tif", (vol % 256).astype(np.uint8), photometric="minisblack",
      compression="packbits")
    w("tiled_f32.tif", rng.random((2, 20, 18), dtype=np.float32), photometric="minisblack",
      tile=(16, 16))
    w("big_i16.tif", (vol.astype(np.int32) - 2000).astype(np.int16), photometric="minisblack",
      bigtiff=True)
    w("be_u32.tif", vol.astype(np.uint32), photometric="minisblack", byteorder=">")
    w("rgb_u8.tif", rng.integers(0, 255, size=(2, 4, 5, 3), dtype=np.uint8),
      photometric="rgb")
    w("imagej_czyx.tif", rng.integers(0, 4000, size=(2, 3, 4, 5), dtype=np.uint16),
      imagej=True, metadata={"axes": "ZCYX", "spacing": 2.5, "unit": "um"},
      resolution=(2.0, 2.0))
    # OME-XML given in full (tifffile's own would carry a fresh UUID on every run).
    ome_xml = (
        '<?xml version="1.0" encoding="UTF-8"?>'
        '<OME xmlns="http://www.openmicroscopy.org/Schemas/OME/2016-06" '
        'UUID="urn:uuid:00000000-0000-0000-0000-000000000000">'
        '<Image ID="Image:0"><Pixels ID="Pixels:0" DimensionOrder="XYCZT" Type="uint16" '
        'SizeX="5" SizeY="4" SizeC="2" SizeZ="3" SizeT="1" PhysicalSizeX="0.5" '
        'PhysicalSizeY="0.5" PhysicalSizeZ="2.0" PhysicalSizeXUnit="um">'
        '<Channel ID="Channel:0:0" Name="DAPI" SamplesPerPixel="1"/>'
        '<Channel ID="Channel:0:1" Name="GFP" SamplesPerPixel="1"/>'
        '<TiffData IFD="0" PlaneCount="6"/></Pixels></Image></OME>')
    w("ome_zcyx.tif", rng.integers(0, 4000, size=(6, 4, 5), dtype=np.uint16),
      photometric="minisblack", description=ome_xml, metadata=None)


def scenes():
    schema = json.loads((ROOT / "schemas/json/scene.schema.json").read_text())
    out("scene_json", "example.json", json.dumps(schema["examples"][0], indent=1).encode())
    out("scene_json", "minimal.json", json.dumps({
        "camera": {"eye": [0, 0, 5], "target": [0, 0, 0]},
        "channels": [{"channel": 0, "color": [1, 1, 1], "opacity": []}]}).encode())


def framed(magic, header, payload):
    h = json.dumps(header, separators=(",", ":")).encode()
    return magic + struct.pack("<I", len(h)) + h + payload


def wire():
    grid = lambda off, cells: {"cell_shape": [8, 8, 8], "grid_shape": cells,
                               "offset": off, "length": 2 * 2 * cells[0] * cells[1] * cells[2]}
    header = {"channel": 0, "data_type": "uint16", "halo": 1, "levels": [
        {"level": 0, "shape": [20, 24, 40], "grids": [grid(0, [3, 3, 5]), grid(180, [2, 2, 3]),
                                                       grid(228, [1, 1, 1])]}]}
    out("wire_decode", "minmax.bin", framed(b"RSMINMAX", header, bytes(range(232))))
    header = {"encoding": "raw", "data_type": "float32", "brick_shape": [2, 2, 2], "bricks": [
        {"level": 0, "channel": 0, "brick": [0, 0, 1], "status": "ok", "offset": 0,
         "length": 32},
        {"level": 1, "channel": 0, "brick": [0, 0, 0], "status": "empty", "offset": 0,
         "length": 0},
        {"level": 0, "channel": 2, "brick": [9, 9, 9], "status": "error", "offset": 0,
         "length": 0, "error": "brick out of range"}]}
    out("wire_decode", "bricks.bin", framed(b"RSBRICKS", header, struct.pack("<8f", *range(8))))


def queries():
    out("batch_query", "two.txt", b"\x00\x01b=0,0,0,0,0;1,0,0,1,2&encoding=raw")
    out("http_range", "range.txt", b"\x00\x10\x00\x00\x00\x00\x00\x00bytes=10-99")
    out("store_key", "chunk.txt", b"0/c/0/0/0")
    out("raw_name", "name.bin", b"/data/kingsnake_16x8x4_uint8.raw")
    out("slice_order", "names.bin", b"z1.tif\x00z10.tif\x00z2.tif")


def ome():
    """Stores written by `ingest` (RESIDENCY_BIN, default target/release): the group document
    and the level array documents, NUL-separated, behind a format byte (0: v2, 1: v3)."""
    ingest = pathlib.Path(os.environ.get("RESIDENCY_BIN", ROOT / "target/release")) / "ingest"
    if not ingest.exists():
        print(f"{ingest} not built: ome_metadata seeds left as they are")
        return
    with tempfile.TemporaryDirectory() as tmp:
        tmp = pathlib.Path(tmp)
        raw = tmp / "vol_20x12x10_uint16.raw"
        raw.write_bytes(np.arange(20 * 12 * 10, dtype="<u2").tobytes())
        for version, fmt, group_key, array_key in [("0.5", 1, "zarr.json", "zarr.json"),
                                                   ("0.4", 0, ".zattrs", ".zarray")]:
            store = tmp / f"v{version}.ome.zarr"
            subprocess.run([str(ingest), "convert", str(raw), "-o", str(store), "--chunk", "8",
                            "--ome-zarr-version", version], check=True,
                           stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            group = (store / group_key).read_bytes()
            attrs = json.loads(group)
            ms = (attrs["attributes"]["ome"] if fmt else attrs)["multiscales"][0]
            docs = [group] + [(store / d["path"] / array_key).read_bytes()
                              for d in ms["datasets"]]
            out("ome_metadata", f"ingest_{version}.bin", bytes([fmt]) + b"\0".join(docs))


if __name__ == "__main__":
    ome()
    tiffs()
    scenes()
    wire()
    queries()
