"""`ingest convert --memory-limit`: planes too large for the limit are converted in columns,
reading only the strips, tiles or rows each column spans. The store must be byte for byte the
one a whole-plane conversion writes, for strip and tiled TIFFs (compressed, float, RGB), slice
folders, raw files, shards, anisotropic pyramids and partitions; a limit nothing fits is
refused before anything is written, and without the flag the limit is half the machine's
memory."""

import os
import re

import numpy as np
import pytest
import tifffile

from support.binaries import run_ingest, run_partitions
from support.stores import files

SHAPE = (19, 640, 960)


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    """One volume stored the ways microscopes and scanners write it: 16-bit strips of 7 rows,
    one big-endian strip per page (as ImageJ writes), zlib strips with a horizontal predictor,
    zlib-compressed float tiles of 64×48, 8-bit RGB strips, a folder of tiled 16-bit slices,
    and raw 8-bit; and a wide 16-bit mosaic in 64×64 tiles. A band of rows is empty, so some
    bricks are not written."""
    d = tmp_path_factory.mktemp("columns")
    z, y, x = SHAPE
    zz, yy, xx = np.mgrid[0:z, 0:y, 0:x]
    rng = np.random.default_rng(3)
    vol = (np.sin(xx / 17.0) * np.cos(yy / 23.0) * 1000 + zz * 30 + 2000).astype(np.float32)
    vol += rng.normal(0, 50, size=SHAPE).astype(np.float32)
    vol[:, 100:140, :] = 0
    u16 = np.clip(vol, 0, 65535).astype(np.uint16)
    tifffile.imwrite(d / "strips.tif", u16, rowsperstrip=7, photometric="minisblack")
    tifffile.imwrite(d / "tiled.tif", vol, tile=(64, 48), compression="zlib",
                     photometric="minisblack")
    tifffile.imwrite(d / "big-endian.tif", u16, byteorder=">", photometric="minisblack")
    tifffile.imwrite(d / "predictor.tif", u16, compression="zlib", predictor=True,
                     photometric="minisblack")
    rgb = np.stack([u16 >> 8, (u16 >> 4) & 255, u16 & 255], axis=-1).astype(np.uint8)
    tifffile.imwrite(d / "rgb.tif", rgb, photometric="rgb", rowsperstrip=5)
    (d / "slices").mkdir()
    for i in range(z):
        tifffile.imwrite(d / "slices" / f"z{i}.tif", u16[i], tile=(32, 80),
                         photometric="minisblack")
    u16.astype(np.uint8).tofile(d / f"vol_{x}x{y}x{z}_uint8.raw")
    # A wide mosaic strip: cut in x as well.
    wide = np.tile(u16[:10, :160, :], (1, 1, 4))[:, :, :3700]
    tifffile.imwrite(d / "wide.tif", wide, tile=(64, 64), photometric="minisblack")
    return {
        "wide": d / "wide.tif",
        "strips": d / "strips.tif",
        "big-endian": d / "big-endian.tif",
        "predictor": d / "predictor.tif",
        "tiled": d / "tiled.tif",
        "rgb": d / "rgb.tif",
        "slices": d / "slices",
        "raw": d / f"vol_{x}x{y}x{z}_uint8.raw",
    }


def columns_line(stdout: str) -> str:
    """The report's line about columns ('' for whole planes)."""
    return next((l.strip() for l in stdout.splitlines() if " columns of " in l), "")


# (input, flags, --memory-limit, the report's columns line without its estimate)
CASES = {
    "strips-bands": ("strips", [], "90M", "in 5 columns of 128×960 voxels (levels 0 to 2"),
    "strips-thin-bands": ("strips", [], "80M", "in 10 columns of 64×960 voxels (levels 0 to 1"),
    "big-endian-one-strip-bands": ("big-endian", [], "140M",
                                   "in 2 columns of 512×960 voxels (levels 0 to 4"),
    "predictor-bands": ("predictor", [], "120M", "in 3 columns of 256×960 voxels (levels 0 to 3"),
    "tiled-float-squares": ("tiled", [], "80M", "in 12 columns of 256×256 voxels (levels 0 to 3"),
    "rgb-squares": ("rgb", [], "80M", "in 40 columns of 128×128 voxels (levels 0 to 2"),
    "slices-bands": ("slices", [], "85M", "in 5 columns of 128×960 voxels (levels 0 to 2"),
    "raw-bands": ("raw", [], "100M", "in 3 columns of 256×960 voxels (levels 0 to 3"),
    "wide-cut-in-x": ("wide", [], "90M", "in 4 columns of 160×1024 voxels (levels 0 to 5"),
    "wide-thin-bands": ("wide", [], "100M", "in 3 columns of 64×3700 voxels (levels 0 to 1"),
    "strips-anisotropic-0.4": (
        "strips", ["--chunk", "4,16,16", "--voxel-size", "3,1,1", "--ome-zarr-version", "0.4"],
        "91M", "in 3 columns of 256×960 voxels (levels 0 to 3"),
    "strips-sharded-squares": ("strips", ["--chunk", "4,16,16", "--shard", "8,32,32"], "76M",
                               "in 12 columns of 256×256 voxels (levels 0 to 2"),
}


@pytest.mark.slow
@pytest.mark.parametrize("case", sorted(CASES))
def test_columns_write_the_store_whole_planes_write(inputs, tmp_path, case):
    name, flags, limit, line = CASES[case]
    flags = flags if "--chunk" in flags else ["--chunk", "8,16,16", *flags]
    whole = tmp_path / "whole" / "x.ome.zarr"
    done = run_ingest("convert", inputs[name], "-o", whole, *flags, "--quiet", "--threads", "2")
    assert columns_line(done.stdout) == ""
    cut = tmp_path / "cut" / "x.ome.zarr"
    done = run_ingest("convert", inputs[name], "-o", cut, *flags, "--quiet", "--threads", "2",
                      "--memory-limit", limit)
    got = columns_line(done.stdout)
    assert got.startswith(line + " column by column) to stay within the memory limit "
                          "(estimated peak "), got
    estimate = float(re.search(r"estimated peak ([0-9.]+) MiB", got).group(1))
    assert estimate <= int(limit[:-1]) + 0.05
    assert files(cut) == files(whole)
    # The scratch files of region metadata are gone (Zarr v2's own files start with a dot).
    assert sorted(p.name for p in cut.iterdir() if p.name.startswith(".")) in (
        [], [".zattrs", ".zgroup"])
    assert sorted(p.name for p in cut.parent.iterdir()) == ["x.ome.zarr"]


def test_partitions_cut_into_columns_write_the_same_store(inputs, tmp_path):
    whole = tmp_path / "whole" / "x.ome.zarr"
    run_ingest("convert", inputs["strips"], "-o", whole, "--chunk", "8,16,16", "--quiet")
    parted = tmp_path / "parted" / "x.ome.zarr"
    flags = ["--chunk", "8,16,16", "--memory-limit", "90M", "--threads", "2"]
    run_partitions([inputs["strips"]], parted, 3, *flags)
    one = run_ingest("convert", inputs["strips"], "-o", tmp_path / "again" / "x.ome.zarr",
                     *flags, "--partition", "0/3")
    assert columns_line(one.stdout).startswith("in 5 columns of 128×960 voxels (levels 0 to 0 ")
    run_ingest("finalize", "-o", parted, "--quiet")
    assert files(parted) == files(whole)


def test_a_limit_nothing_fits_is_refused_before_anything_is_written(inputs, tmp_path):
    out = tmp_path / "x.ome.zarr"
    p = run_ingest("convert", inputs["strips"], "-o", out, "--chunk", "8,16,16", "--quiet",
                   "--threads", "2", "--memory-limit", "1M", check=False)
    assert p.returncode == 1
    assert p.stderr == (
        f"error: {out}: converting needs about 70578823 bytes of memory even in the smallest "
        "columns (581632 for level-0 slabs of 1 channel(s) × 8 planes, 434028 for the coarser "
        "levels' sums, 2454299 for the region metadata), more than --memory-limit 1048576 "
        "bytes; allow more memory, or a smaller z edge of --chunk (and --shard) needs less\n")
    assert not out.exists()
    assert list(tmp_path.iterdir()) == []


def test_without_a_memory_limit_the_limit_is_half_the_machines_memory(tmp_path):
    """The README's default of `--memory-limit`: half the machine's physical memory, read here
    from the kernel (`SC_PHYS_PAGES`) and named in the refusal of a conversion that needs more
    (a sparse raw file of 2⁴² voxels, 4 TiB that take no disk, whose region metadata alone
    needs about 92 GB)."""
    half = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE") // 2
    if half >= 80 << 30:
        pytest.skip(f"this machine's default limit ({half} bytes) may let the conversion start")
    raw = tmp_path / "huge.raw"
    with open(raw, "wb") as f:
        f.truncate(1 << 42)
    out = tmp_path / "x.ome.zarr"
    p = run_ingest("convert", raw, "--dims", f"{1 << 19},{1 << 19},16", "--dtype", "uint8",
                   "-o", out, "--quiet", check=False)
    assert p.returncode == 1, p.stderr
    assert p.stderr.startswith(f"error: {out}: converting needs about "), p.stderr
    assert p.stderr.endswith(
        f"for the region metadata), more than --memory-limit {half} bytes; allow more memory, "
        "or a smaller z edge of --chunk (and --shard) needs less\n"), p.stderr
    assert sorted(q.name for q in tmp_path.iterdir()) == ["huge.raw"]


@pytest.mark.parametrize("value", ["0", "lots", "4X", "-1G"])
def test_a_memory_limit_that_is_not_a_byte_count_is_refused(inputs, tmp_path, value):
    p = run_ingest("convert", inputs["strips"], "-o", tmp_path / "x.ome.zarr",
                   f"--memory-limit={value}", check=False)
    assert p.returncode == 2
    assert (f"invalid value '{value}' for '--memory-limit <BYTES>': expected a positive byte "
            f"count such as 4G or 500M, not \"{value}\"") in p.stderr
    assert list(tmp_path.iterdir()) == []
