"""`ingest` against code nobody here wrote: tifffile writes the inputs microscopes produce,
zarr-python reads the output, ome-zarr-models validates it, NumPy is the reference."""

import json
import os
import pathlib
import signal
import subprocess
import time

import jsonschema
import numpy as np
import pytest
import tifffile
import zarr
from ome_zarr_models import open_ome_zarr

from support.binaries import run_ingest, run_partitions
from support.paths import BIN, ROOT
from support.reference import assert_pyramid_exact, assert_region_metadata, assert_same_bits
from support.stores import files, multiscale, root_attributes

RNG = np.random.default_rng(7)


def sparse_volume(shape, dtype):
    """Mostly empty, with blobs and noise, in `dtype` (odd shapes welcome)."""
    z, y, x = np.indices(shape)
    v = np.zeros(shape, np.float64)
    for _ in range(4):
        c = [RNG.uniform(0, s) for s in shape]
        r = RNG.uniform(3, 8)
        v += np.exp(-((z - c[0]) ** 2 + (y - c[1]) ** 2 + (x - c[2]) ** 2) / r**2)
    v[v < 0.05] = 0
    if np.issubdtype(dtype, np.integer):
        info = np.iinfo(dtype)
        top = min(info.max, 60000)
        v = v / v.max() * top * 0.9 + (v > 0) * RNG.integers(0, 50, shape)
        if info.min < 0:
            v = v - (v > 0) * top * 0.45
        return np.clip(np.round(v), info.min, info.max).astype(dtype)
    return (v * 1000 - 3).astype(dtype)


def check_store(out: pathlib.Path, level0: np.ndarray, version="0.5"):
    """Level 0 is bit-identical, every level is exact, the metadata validates and is right."""
    g = zarr.open_group(str(out), mode="r")
    assert_same_bits(g["0"][...], level0)
    assert_pyramid_exact(out, level0)
    model = open_ome_zarr(g)
    assert type(model).__module__.startswith(f"ome_zarr_models.v0{version[-1]}"), type(model)
    schema = json.loads((ROOT / "schemas/json/region-metadata.schema.json").read_text())
    jsonschema.validate(root_attributes(out)["residency"], schema)
    assert_region_metadata(out)
    return g


CASES = {
    # name: (dtype, tifffile.imwrite keyword arguments)
    "u16-multipage": (np.uint16, {}),
    "u8-bigtiff": (np.uint8, {"bigtiff": True}),
    "u16-tiled": (np.uint16, {"tile": (16, 16)}),
    "u16-lzw": (np.uint16, {"compression": "lzw"}),
    "u16-deflate": (np.uint16, {"compression": "zlib"}),
    "u8-packbits": (np.uint8, {"compression": "packbits"}),
    "i16-multipage": (np.int16, {}),
    "u32-multipage": (np.uint32, {}),
    "i32-multipage": (np.int32, {}),
    "f32-multipage": (np.float32, {}),
    "f32-tiled-deflate": (np.float32, {"tile": (16, 32), "compression": "zlib"}),
}


@pytest.mark.parametrize("name", CASES)
def test_tiff_variants_round_trip_exactly(tmp_path, name):
    dtype, kwargs = CASES[name]
    vol = sparse_volume((19, 37, 45), dtype)
    src = tmp_path / f"{name}.tif"
    tifffile.imwrite(src, vol, photometric="minisblack", **kwargs)
    out = tmp_path / "out.ome.zarr"
    run_ingest("convert", src, "-o", out, "--chunk", "8", "--quiet")
    check_store(out, vol[np.newaxis])


def test_float_nan_is_excluded_from_means_and_statistics(tmp_path):
    vol = sparse_volume((10, 20, 21), np.float32)
    vol[2:4, 0:8, 0:8] = np.nan  # a window of NaN only, and partial NaN windows
    vol[5, 3, 7] = np.nan
    src = tmp_path / "nan.tif"
    tifffile.imwrite(src, vol, photometric="minisblack")
    out = tmp_path / "nan.ome.zarr"
    run_ingest("convert", src, "-o", out, "--chunk", "4", "--quiet")
    g = check_store(out, vol[np.newaxis])
    assert np.isnan(g["1"][0, 1, 0, 0])
    stats = root_attributes(out)["residency"]["channels"][0]
    assert stats["nan_voxels"] == int(np.isnan(vol).sum())
    assert stats["min"] == float(np.nanmin(vol)) and stats["max"] == float(np.nanmax(vol))
    assert stats["mean"] == pytest.approx(float(np.nanmean(vol.astype(np.float64))), rel=1e-12)


def test_imagej_hyperstack_channels_order_and_voxel_size(tmp_path):
    vol = np.stack([sparse_volume((9, 24, 30), np.uint16) for _ in range(3)], axis=1)  # Z C Y X
    src = tmp_path / "hyper.tif"
    tifffile.imwrite(
        src, vol, imagej=True, resolution=(1 / 0.25, 1 / 0.25), metadata={"axes": "ZCYX", "spacing": 1.5, "unit": "um"}
    )
    out = tmp_path / "hyper.ome.zarr"
    run_ingest("convert", src, "-o", out, "--chunk", "8", "--quiet")
    check_store(out, np.ascontiguousarray(vol.transpose(1, 0, 2, 3)))
    ms = multiscale(out)
    assert ms["datasets"][0]["coordinateTransformations"][0]["scale"] == pytest.approx([1, 1.5, 0.25, 0.25])
    assert [a.get("unit") for a in ms["axes"]] == [None, "micrometer", "micrometer", "micrometer"]


@pytest.mark.parametrize("axes", ["CZYX", "ZCYX"])
def test_ome_tiff_channel_names_order_and_physical_size(tmp_path, axes):
    czyx = np.stack([sparse_volume((7, 20, 26), np.uint16) for _ in range(2)])
    data = czyx if axes == "CZYX" else czyx.transpose(1, 0, 2, 3)
    src = tmp_path / "image.ome.tif"
    tifffile.imwrite(
        src,
        data,
        ome=True,
        photometric="minisblack",
        metadata={
            "axes": axes,
            "PhysicalSizeX": 0.3,
            "PhysicalSizeY": 0.3,
            "PhysicalSizeZ": 2.0,
            "Channel": {"Name": ["DAPI", "GFP"]},
        },
    )
    out = tmp_path / "image.ome.zarr"
    run_ingest("convert", src, "-o", out, "--chunk", "8", "--quiet")
    check_store(out, czyx)
    attrs = root_attributes(out)["ome"]
    assert [c["label"] for c in attrs["omero"]["channels"]] == ["DAPI", "GFP"]
    assert attrs["multiscales"][0]["datasets"][0]["coordinateTransformations"][0]["scale"] == pytest.approx([1, 2.0, 0.3, 0.3])


def test_rgb_pages_become_three_channels(tmp_path):
    rgb = RNG.integers(0, 255, (5, 16, 18, 3), dtype=np.uint8)
    src = tmp_path / "rgb.tif"
    tifffile.imwrite(src, rgb, photometric="rgb")
    out = tmp_path / "rgb.ome.zarr"
    run_ingest("convert", src, "-o", out, "--chunk", "8", "--quiet")
    check_store(out, np.ascontiguousarray(rgb.transpose(3, 0, 1, 2)))


def test_folder_and_glob_of_slices_in_natural_order(tmp_path):
    vol = sparse_volume((12, 17, 23), np.uint16)
    folder = tmp_path / "slices"
    folder.mkdir()
    for z in range(vol.shape[0]):
        tifffile.imwrite(folder / f"slice_z{z}.tif", vol[z])  # z10 sorts after z9 naturally
    out = tmp_path / "dir.ome.zarr"
    run_ingest("convert", folder, "-o", out, "--chunk", "8", "--quiet")
    check_store(out, vol[np.newaxis])
    out2 = tmp_path / "glob.ome.zarr"
    run_ingest("convert", str(folder / "slice_z*.tif"), "-o", out2, "--chunk", "8", "--quiet")
    assert_same_bits(zarr.open_group(str(out2), mode="r")["0"][...], vol[np.newaxis])


def test_raw_by_name_convention_and_by_flags(tmp_path):
    vol = sparse_volume((11, 13, 29), np.uint16)
    named = tmp_path / "kingsnake_29x13x11_uint16.raw"
    vol.astype("<u2").tofile(named)
    out = tmp_path / "named.ome.zarr"
    run_ingest("convert", named, "-o", out, "--chunk", "8", "--quiet")
    check_store(out, vol[np.newaxis])

    flagged = tmp_path / "scan.bin"
    header = b"HEADER!!" * 4
    flagged.write_bytes(header + vol.astype(">i4").tobytes())
    out2 = tmp_path / "flagged.ome.zarr"
    run_ingest(
        "convert", flagged, "-o", out2, "--dims", "29,13,11", "--dtype", "int32", "--endian", "big",
        "--header-bytes", len(header), "--chunk", "8", "--quiet",
    )
    check_store(out2, vol.astype(np.int32)[np.newaxis])


def test_channels_of_different_types_are_promoted_exactly(tmp_path):
    a = sparse_volume((6, 14, 15), np.uint8)
    b = sparse_volume((6, 14, 15), np.uint16)
    tifffile.imwrite(tmp_path / "a.tif", a)
    tifffile.imwrite(tmp_path / "b.tif", b)
    out = tmp_path / "mixed.ome.zarr"
    run_ingest("convert", tmp_path / "a.tif", tmp_path / "b.tif", "-o", out, "--chunk", "8", "--quiet")
    check_store(out, np.stack([a.astype(np.uint16), b]))


def test_ome_zarr_04_and_sharded_05(tmp_path):
    vol = sparse_volume((20, 33, 40), np.uint16)
    src = tmp_path / "v.tif"
    tifffile.imwrite(src, vol)
    out4 = tmp_path / "v04.ome.zarr"
    run_ingest("convert", src, "-o", out4, "--chunk", "8", "--ome-zarr-version", "0.4", "--quiet")
    assert (out4 / ".zgroup").exists() and (out4 / "0" / ".zarray").exists()
    zarray = json.loads((out4 / "0" / ".zarray").read_text())
    assert zarray["compressor"] == {"id": "blosc", "cname": "lz4", "clevel": 5, "shuffle": 1, "blocksize": 0}
    assert zarray["dimension_separator"] == "/"
    check_store(out4, vol[np.newaxis], version="0.4")

    out5 = tmp_path / "sharded.ome.zarr"
    run_ingest("convert", src, "-o", out5, "--chunk", "8", "--shard", "16", "--quiet")
    meta = json.loads((out5 / "0" / "zarr.json").read_text())
    assert meta["codecs"][0]["name"] == "sharding_indexed"
    assert meta["codecs"][0]["configuration"]["chunk_shape"] == [1, 8, 8, 8]
    check_store(out5, vol[np.newaxis])


def test_empty_bricks_are_not_written_and_are_counted(tmp_path):
    vol = np.zeros((16, 32, 32), np.uint16)
    vol[0:8, 0:8, 0:8] = 7
    src = tmp_path / "sparse.tif"
    tifffile.imwrite(src, vol)
    out = tmp_path / "sparse.ome.zarr"
    p = run_ingest("convert", src, "-o", out, "--chunk", "8", "--quiet")
    chunk_files = [f for f in (out / "0" / "c").rglob("*") if f.is_file()]
    assert len(chunk_files) == 1
    assert "level 0: shape c,z,y,x = [1, 16, 32, 32], bricks written 1, empty (not written) 31" in p.stdout
    lvl0 = root_attributes(out)["residency"]["levels"][0]
    assert (lvl0["bricks_written"], lvl0["bricks_empty"]) == (1, 31)
    check_store(out, vol[np.newaxis])


def test_anisotropic_pyramid_halves_xy_first(tmp_path):
    vol = sparse_volume((16, 64, 64), np.uint8)
    src = tmp_path / "aniso.tif"
    tifffile.imwrite(src, vol)
    out = tmp_path / "aniso.ome.zarr"
    run_ingest("convert", src, "-o", out, "--chunk", "8", "--voxel-size", "4,1,1", "--unit", "micrometer", "--quiet")
    shapes = [zarr.open_group(str(out), mode="r")[d["path"]].shape for d in multiscale(out)["datasets"]]
    assert shapes[:4] == [(1, 16, 64, 64), (1, 16, 32, 32), (1, 16, 16, 16), (1, 8, 8, 8)]
    check_store(out, vol[np.newaxis])


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.int16])
@pytest.mark.parametrize("depth", [16, 32])
@pytest.mark.parametrize("fill", ["smallest", "largest", "mixed"])
def test_sums_as_large_as_their_narrow_type_allows_are_exact(tmp_path, dtype, depth, fill):
    """Levels whose voxels cover few enough level-0 voxels sum in 32 bits. At depth 16 the
    last level's voxel covers 16 x 64 x 64 = 65,536 voxels, the most an i16 narrow sum holds
    (at -32768 each they sum to exactly the smallest 32-bit integer; at 65535 each, u16's
    sum is 65,535 short of the largest unsigned one). At depth 32 it covers twice that, so
    for u16 and i16 the level before it is narrow and it is wide."""
    info = np.iinfo(dtype)
    shape = (depth, 64, 64)
    if fill == "mixed":
        vol = RNG.choice(np.array([info.min, info.max, info.max - 1], dtype), size=shape, p=[0.45, 0.5, 0.05])
    else:
        vol = np.full(shape, info.min if fill == "smallest" else info.max, dtype)
    src = tmp_path / "extremes.tif"
    tifffile.imwrite(src, vol)
    out = tmp_path / "extremes.ome.zarr"
    run_ingest("convert", src, "-o", out, "--chunk", "16", "--levels", "7", "--voxel-size", "1,1,1", "--quiet")
    g = check_store(out, vol[np.newaxis])
    shapes = [g[d["path"]].shape for d in multiscale(out)["datasets"]]
    assert shapes[-2:] == [(1, 1, 2, 2), (1, 1, 1, 1)]
    if fill != "mixed":
        assert g["6"][...].tolist() == [[[[int(vol.flat[0])]]]]


@pytest.mark.parametrize("dtype", [np.uint16, np.int16])
def test_partitions_hand_over_wide_sums_that_narrow_levels_take(tmp_path, dtype):
    """In 2 partitions the hand-over level (level 1 of 16-plane slabs here: 8 planes a
    partition) is summed wide, written to the hand-over files, and taken back by `finalize`
    into the levels that sum narrow and the one that sums wide: the store is the one a single
    conversion writes, every level exact, with sums at the limits of the narrow types."""
    info = np.iinfo(dtype)
    vol = np.full((32, 64, 64), info.max, dtype)
    vol[::2] = info.min
    src = tmp_path / "extremes.tif"
    tifffile.imwrite(src, vol)
    flags = ["--chunk", "16", "--levels", "7", "--voxel-size", "1,1,1"]
    whole = tmp_path / "whole" / "x.ome.zarr"
    run_ingest("convert", src, "-o", whole, *flags, "--quiet")
    parted = tmp_path / "parted" / "x.ome.zarr"
    run_partitions([src], parted, 2, *flags)
    run_ingest("finalize", "-o", parted, "--quiet")
    assert files(parted) == files(whole)
    check_store(parted, vol[np.newaxis])


def test_index_adds_metadata_to_a_foreign_store(tmp_path):
    vol = sparse_volume((12, 20, 24), np.uint16)[np.newaxis]
    store = tmp_path / "foreign.ome.zarr"
    root = zarr.open_group(str(store), mode="w", zarr_format=3)
    root.create_array("0", data=vol, chunks=(1, 8, 8, 8), dimension_names=("c", "z", "y", "x"))
    root.create_array("1", data=vol[:, :, ::2, ::2].copy(), chunks=(1, 8, 8, 8), dimension_names=("c", "z", "y", "x"))
    datasets = [
        {"path": str(i), "coordinateTransformations": [{"type": "scale", "scale": [1.0, 1.0, 2.0**i, 2.0**i]}]}
        for i in range(2)
    ]
    root.attrs["ome"] = {
        "version": "0.5",
        "multiscales": [{"axes": [{"name": "c", "type": "channel"}] + [{"name": a, "type": "space"} for a in "zyx"], "datasets": datasets}],
    }
    chunk_bytes = {p: p.read_bytes() for p in (store / "0").rglob("c/**/*") if p.is_file()}
    p = run_ingest("index", store)
    assert "indexed" in p.stdout
    assert {q: q.read_bytes() for q in chunk_bytes} == chunk_bytes  # data untouched
    assert_region_metadata(store)
    open_ome_zarr(zarr.open_group(str(store), mode="r"))
    assert "region metadata: 2 levels (covers 2 of 2 image levels)" in run_ingest("inspect", store).stdout


def test_inspect_reports_levels_codecs_and_statistics(tmp_path):
    vol = sparse_volume((9, 20, 20), np.uint16)
    src = tmp_path / "i.tif"
    tifffile.imwrite(src, vol)
    out = tmp_path / "i.ome.zarr"
    run_ingest("convert", src, "-o", out, "--chunk", "8", "--voxel-size", "2,0.5,0.5", "--unit", "micrometer", "--quiet")
    text = run_ingest("inspect", out).stdout
    assert "OME-Zarr 0.5" in text
    assert "axes: c, z (micrometer), y (micrometer), x (micrometer)" in text
    assert "level 0: shape [1, 9, 20, 20] uint16" in text and "blosc(lz4" in text
    # Each level's chunking and voxel size (c, z, y, x): x and y halve first, to 1 µm.
    lines = text.splitlines()
    level = {n: next(l for l in lines if l.startswith(f"level {n}: shape")) for n in (0, 1)}
    assert level[0].startswith("level 0: shape [1, 9, 20, 20] uint16 chunks [1,8,8,8] "), level
    assert level[0].endswith(" scale [1.0,2.0,0.5,0.5]"), level
    assert level[1].startswith("level 1: shape [1, 9, 10, 10] uint16 chunks [1,8,8,8] "), level
    assert level[1].endswith(" scale [1.0,2.0,1.0,1.0]"), level
    assert f"min {int(vol.min())} max {int(vol.max())}" in text
    assert "region metadata: " in text


def test_bricks_are_64_voxels_a_side_by_default(tmp_path):
    """Without `--chunk`, every level is chunked in bricks of 64³ (one channel each), as the
    README says, and the region metadata records that brick."""
    vol = np.zeros((70, 70, 70), np.uint8)
    vol[10:60, 10:60, 10:60] = 7
    src = tmp_path / "b.tif"
    tifffile.imwrite(src, vol)
    out = tmp_path / "b.ome.zarr"
    run_ingest("convert", src, "-o", out, "--quiet")
    for level in ("0", "1"):
        meta = json.loads((out / level / "zarr.json").read_text())
        assert meta["chunk_grid"]["configuration"]["chunk_shape"] == [1, 64, 64, 64], meta
    assert root_attributes(out)["residency"]["brick_shape"] == [64, 64, 64]


# --- bad input and faults -------------------------------------------------------------


def expect_failure(args, *needles):
    p = run_ingest(*args, check=False)
    assert p.returncode != 0, p.stdout
    for n in needles:
        assert str(n) in p.stderr, p.stderr
    return p


def closed_pipe_run(*args):
    """Runs `ingest ARGS` with stdout a pipe nobody reads any more (its reading end closed
    first, as `| head` leaves it): returns the exit code and stderr."""
    read, write = os.pipe()
    os.close(read)
    try:
        p = subprocess.run([str(BIN / "ingest"), *map(str, args)], stdout=write,
                           stderr=subprocess.PIPE, text=True, timeout=120)
    finally:
        os.close(write)
    return p.returncode, p.stderr


def test_a_reader_that_stops_reading_ends_the_report_quietly(tmp_path):
    """`ingest inspect STORE | head` and the like: the report to a closed pipe ends the
    program with success and nothing on stderr (not a panic), after its work is done."""
    vol = sparse_volume((9, 20, 20), np.uint16)
    src = tmp_path / "i.tif"
    tifffile.imwrite(src, vol)
    out = tmp_path / "i.ome.zarr"
    assert closed_pipe_run("convert", src, "-o", out, "--chunk", "8") == (0, "")
    assert run_ingest("inspect", out).stdout.startswith(f"{out}: OME-Zarr 0.5")
    assert closed_pipe_run("inspect", out) == (0, "")
    assert closed_pipe_run("sample", "-o", tmp_path / "s", "--size", "8,16,16") == (0, "")
    assert sorted(p.name for p in (tmp_path / "s").iterdir()) == [
        "filaments.ome.tif", "membranes.ome.tif", "nuclei.ome.tif"]


def test_truncated_tiff_names_the_file(tmp_path):
    src = tmp_path / "cut.tif"
    tifffile.imwrite(src, sparse_volume((8, 64, 64), np.uint16))
    data = src.read_bytes()
    src.write_bytes(data[: len(data) // 2])
    out = tmp_path / "cut.ome.zarr"
    expect_failure(["convert", src, "-o", out, "--quiet"], src, "truncated or corrupt TIFF")
    assert not out.exists()
    assert not (tmp_path / ".cut.ome.zarr.partial").exists(), "a failed run cleans up after itself"


def test_raw_size_mismatch(tmp_path):
    raw = tmp_path / "vol_10x10x10_uint16.raw"
    raw.write_bytes(b"\0" * 1999)
    expect_failure(["convert", raw, "-o", tmp_path / "o.ome.zarr"], raw, "1999 bytes", "2000 bytes")


def test_channels_of_different_shapes(tmp_path):
    tifffile.imwrite(tmp_path / "a.tif", np.zeros((4, 8, 8), np.uint8), photometric="minisblack")
    tifffile.imwrite(tmp_path / "b.tif", np.zeros((4, 8, 9), np.uint8), photometric="minisblack")
    expect_failure(
        ["convert", tmp_path / "a.tif", tmp_path / "b.tif", "-o", tmp_path / "o.ome.zarr"],
        "channels of different shapes", tmp_path / "b.tif",
    )


def test_unsupported_sample_format(tmp_path):
    src = tmp_path / "f64.tif"
    tifffile.imwrite(src, np.zeros((3, 8, 8), np.float64), photometric="minisblack")
    expect_failure(["convert", src, "-o", tmp_path / "o.ome.zarr"], src, "unsupported sample format", "64-bit floating point")


def test_unwritable_output(tmp_path):
    src = tmp_path / "a.tif"
    tifffile.imwrite(src, np.ones((2, 8, 8), np.uint8))
    blocker = tmp_path / "not-a-folder"
    blocker.write_text("x")
    out = blocker / "o.ome.zarr"
    expect_failure(["convert", src, "-o", out], out, "cannot create output")


def test_existing_output_needs_overwrite(tmp_path):
    src = tmp_path / "a.tif"
    tifffile.imwrite(src, np.ones((2, 8, 8), np.uint8))
    out = tmp_path / "o.ome.zarr"
    run_ingest("convert", src, "-o", out, "--quiet")
    before = (out / "zarr.json").read_bytes()
    expect_failure(["convert", src, "-o", out], out, "already exists", "--overwrite")
    assert (out / "zarr.json").read_bytes() == before
    tifffile.imwrite(src, np.full((2, 8, 8), 3, np.uint8))
    run_ingest("convert", src, "-o", out, "--overwrite", "--quiet")
    assert zarr.open_group(str(out), mode="r")["0"][0, 0, 0, 0] == 3


def tree_bytes(root: pathlib.Path):
    return {p.relative_to(root): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def test_killed_run_leaves_no_complete_looking_store_and_rerun_is_identical(tmp_path):
    vol = RNG.integers(0, 1000, (192, 160, 160), dtype=np.uint16)  # every brick is written
    src = tmp_path / "big_160x160x192_uint16.raw"
    vol.astype("<u2").tofile(src)
    out = tmp_path / "k.ome.zarr"
    partial = tmp_path / ".k.ome.zarr.partial"
    args = [str(BIN / "ingest"), "convert", str(src), "-o", str(out), "--chunk", "16", "--threads", "1", "--quiet"]
    proc = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    deadline = time.time() + 60
    while time.time() < deadline and not (partial / "0" / "c" / "0" / "2").exists():
        time.sleep(0.002)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert proc.returncode == -signal.SIGKILL
    assert partial.exists(), "the run finished before it could be killed"
    assert not out.exists(), "a killed run must not leave a store at the output path"
    assert not (partial / "zarr.json").exists(), "the root metadata is the last write"

    run_ingest("convert", src, "-o", out, "--chunk", "16", "--quiet")
    assert not partial.exists()
    clean = tmp_path / "clean.ome.zarr"
    run_ingest("convert", src, "-o", clean, "--chunk", "16", "--quiet")
    a, b = tree_bytes(out), tree_bytes(clean)
    assert a.keys() == b.keys()
    for k in a:
        if k.name == "zarr.json" and k.parent == pathlib.Path("."):
            # The multiscale name is the store's name.
            assert a[k].replace(b'"k"', b'"clean"') == b[k]
        else:
            assert a[k] == b[k], k


def in_place_line(stdout: str) -> str:
    """The report's line about planes read in place ('' when none was)."""
    return next((l.strip() for l in stdout.splitlines() if "read in place" in l), "")


def write_inputs(kind: str, d: pathlib.Path) -> list:
    """The input files of one kind of stack (two channels of 10 × 64 × 81 where it has
    channels), as tifffile and NumPy write them."""
    a, b = (sparse_volume((10, 64, 81), np.uint16) for _ in range(2))
    if kind == "tiff-strips":
        tifffile.imwrite(d / "s.tif", a, rowsperstrip=4, photometric="minisblack")
    elif kind == "bigtiff-float":
        tifffile.imwrite(d / "s.tif", a.astype(np.float32) / 7, bigtiff=True, photometric="minisblack")
    elif kind in ("ome-czyx", "ome-zcyx"):
        czyx = np.stack([a, b])
        data = czyx if kind == "ome-czyx" else czyx.transpose(1, 0, 2, 3)
        tifffile.imwrite(d / "s.ome.tif", data, ome=True, photometric="minisblack",
                         metadata={"axes": kind[-4:].upper()})
    elif kind == "imagej-zcyx":
        tifffile.imwrite(d / "s.tif", np.stack([a, b], axis=1), imagej=True, metadata={"axes": "ZCYX"})
    elif kind == "two-files":
        tifffile.imwrite(d / "a.tif", a)
        tifffile.imwrite(d / "b.tif", b)
    elif kind == "slices":
        (d / "slices").mkdir()
        for z in range(a.shape[0]):
            tifffile.imwrite(d / "slices" / f"z{z}.tif", a[z])
        return [d / "slices"]
    elif kind == "raw":
        a.astype("<u2").tofile(d / "s_81x64x10_uint16.raw")
    elif kind == "raw-odd-header":
        (d / "s.bin").write_bytes(b"H" + a.astype("<u2").tobytes())
    elif kind == "u8-big-endian":
        tifffile.imwrite(d / "s.tif", a.astype(np.uint8), byteorder=">", photometric="minisblack")
    elif kind == "big-endian":
        tifffile.imwrite(d / "s.tif", a, byteorder=">", photometric="minisblack")
    elif kind == "white-is-zero":
        tifffile.imwrite(d / "s.tif", a, photometric="miniswhite")
    elif kind == "deflate":
        tifffile.imwrite(d / "s.tif", a, compression="zlib", photometric="minisblack")
    elif kind == "tiled":
        tifffile.imwrite(d / "s.tif", a, tile=(16, 16), photometric="minisblack")
    elif kind == "promoted":
        tifffile.imwrite(d / "a.tif", a.astype(np.uint8))
        tifffile.imwrite(d / "b.tif", b)
    elif kind == "then-deflate":
        tifffile.imwrite(d / "a.tif", a)
        tifffile.imwrite(d / "b.tif", b, compression="zlib")
    return sorted(p for p in d.iterdir() if p.is_file())


def aligned_pages(files, itemsize) -> int:
    """The pages of TIFF `files` (or folders of them) whose samples start on a multiple of
    their size in the file: those read in place; the others are copied out of the file."""
    paths = [f for p in files for f in (sorted(p.iterdir()) if p.is_dir() else [p])]
    return sum(page.dataoffsets[0] % itemsize == 0
               for f in paths for page in tifffile.TiffFile(f).pages)


# Kind of input: (whether its planes are read in place where aligned, planes in all,
# extra flags).
IN_PLACE = {
    "tiff-strips": (True, 10, []),
    "bigtiff-float": (True, 10, []),
    "ome-czyx": (True, 20, []),
    "ome-zcyx": (True, 20, []),
    "imagej-zcyx": (True, 20, []),
    "two-files": (True, 20, []),
    "slices": (True, 10, []),
    "raw": (True, 10, []),
    "raw-odd-header": (False, 10, ["--dims", "81,64,10", "--dtype", "uint16", "--header-bytes", "1"]),
    "u8-big-endian": (True, 10, []),
    "big-endian": (False, 10, []),
    "white-is-zero": (False, 10, []),
    "deflate": (False, 10, []),
    "tiled": (False, 10, []),
    "promoted": (False, 20, []),
    "then-deflate": (False, 20, []),
}


@pytest.mark.parametrize("kind", IN_PLACE)
def test_planes_read_in_place_give_the_store_copied_planes_give(tmp_path, kind):
    """Planes stored uncompressed, black-is-zero, in the store's type and this machine's byte
    order are mapped from their files (the report counts those read in place; a plane at an
    odd offset is copied out of its mapping); the store is byte for byte the one `--no-mmap`,
    which copies every plane, writes."""
    src = tmp_path / "in"
    src.mkdir()
    inputs = write_inputs(kind, src)
    mapped, planes, flags = IN_PLACE[kind]
    trees, lines = [], []
    for copy in ([], ["--no-mmap"]):
        out = tmp_path / ("copied" if copy else "mapped") / "s.ome.zarr"
        done = run_ingest("convert", *inputs, "-o", out, "--chunk", "8", *flags, *copy)
        trees.append(tree_bytes(out))
        lines.append(in_place_line(done.stdout))
    itemsize = 4 if kind == "bigtiff-float" else 1 if kind == "u8-big-endian" else 2
    in_place = (planes if kind in ("raw",) else aligned_pages(inputs, itemsize)) if mapped else 0
    assert mapped == (in_place > 0), in_place
    expected = f"{in_place} of {planes} planes read in place from the input files (memory-mapped)"
    assert lines == [expected if in_place else "", ""]
    assert trees[0].keys() == trees[1].keys()
    for k in trees[0]:
        assert trees[0][k] == trees[1][k], k


@pytest.mark.parametrize("layout", [["--chunk", "8"], ["--chunk", "8", "--shard", "16"], ["--chunk", "8", "--ome-zarr-version", "0.4"]])
def test_stores_are_byte_identical_across_runs_and_thread_counts(tmp_path, layout):
    """Every store, sharded or not, has the same bytes from run to run and whatever --threads:
    inner chunks go into a shard in C order, not in the order they finish encoding."""
    vol = (RNG.standard_normal((20, 36, 40)) * 100).astype(np.float32)
    vol[:, :10] = 0  # whole empty inner chunks too
    src = tmp_path / "v_40x36x20_float32.raw"
    vol.astype("<f4").tofile(src)
    trees = []
    for run, threads in enumerate(["1", "2", "2", "4"]):
        out = tmp_path / f"r{run}" / "v.ome.zarr"
        run_ingest("convert", src, "-o", out, *layout, "--threads", threads, "--quiet")
        trees.append(tree_bytes(out))
    for other in trees[1:]:
        assert other.keys() == trees[0].keys()
        for k in other:
            assert other[k] == trees[0][k], k
    assert_same_bits(zarr.open_group(str(tmp_path / "r0" / "v.ome.zarr"), mode="r")["0"][...], vol[np.newaxis])
