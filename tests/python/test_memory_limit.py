"""`ingest convert --memory-limit` is a promise: the peak resident set of the process (its
`ru_maxrss`, from `wait4`) stays within the limit for every input kind ingest reads (strips,
one strip per page, tiles, zlib strips, zlib with a predictor, one zlib strip per page, a tiled
zlib BigTIFF, raw, a slice folder), for a sharded store, for each process of a partitioned conversion and for a store written to S3, at
a limit whole planes do not fit, so the conversion must cut them into columns; and the store it
writes is byte for byte the one written in whole planes (which peaks above the limit)."""

import os
import re
import subprocess
import sys

import numpy as np
import pytest
import tifffile

from support.paths import BIN
from support.s3 import env as s3_env, start_s3
from support.stores import files

pytestmark = pytest.mark.slow

# 16 planes of 1024 × 1536 uint16 voxels (3 MiB a plane, 48 MiB in all), in slabs 8 planes
# deep: whole planes do not fit the limit, columns do.
SHAPE = (16, 1024, 1536)
FLAGS = ["--chunk", "8,64,64", "--threads", "2"]
LIMIT = "84M"
LIMIT_BYTES = 84 << 20


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    """The same volume in every kind of input: strips of 16 rows, one strip per page, 256²
    tiles, zlib strips (tifffile's default of about 256 KB each), zlib strips with the
    horizontal predictor, one zlib strip per page, a zlib BigTIFF in 256² tiles, a raw file, and a folder of one TIFF
    per plane."""
    d = tmp_path_factory.mktemp("memory")
    z, y, x = SHAPE
    yy, xx = np.mgrid[0:y, 0:x]
    base = np.sin(xx / 37.0) * np.cos(yy / 53.0) * 800 + 2000
    rng = np.random.default_rng(5)
    vol = np.empty(SHAPE, np.uint16)
    for i in range(z):
        vol[i] = base + i * 10 + rng.integers(0, 64, size=(y, x))
    gray = {"photometric": "minisblack"}
    tifffile.imwrite(d / "strips.tif", vol, rowsperstrip=16, **gray)
    tifffile.imwrite(d / "one-strip.tif", vol, rowsperstrip=y, **gray)
    tifffile.imwrite(d / "tiled.tif", vol, tile=(256, 256), **gray)
    tifffile.imwrite(d / "zlib.tif", vol, compression="zlib", compressionargs={"level": 1},
                     **gray)
    tifffile.imwrite(d / "predictor.tif", vol, compression="zlib", predictor=True,
                     compressionargs={"level": 1}, **gray)
    # A page in one compressed strip decodes whole, however narrow the column.
    tifffile.imwrite(d / "zlib-one-strip.tif", vol, rowsperstrip=y, compression="zlib",
                     compressionargs={"level": 1}, **gray)
    tifffile.imwrite(d / "bigtiff.tif", vol, bigtiff=True, tile=(256, 256), compression="zlib",
                     compressionargs={"level": 1}, **gray)
    vol.tofile(d / f"vol_{x}x{y}x{z}_uint16.raw")
    (d / "slices").mkdir()
    for i in range(z):
        tifffile.imwrite(d / "slices" / f"z{i:02}.tif", vol[i], rowsperstrip=64, **gray)
    return {
        "strips": d / "strips.tif",
        "one-strip": d / "one-strip.tif",
        "tiled": d / "tiled.tif",
        "zlib": d / "zlib.tif",
        "predictor": d / "predictor.tif",
        "zlib-one-strip": d / "zlib-one-strip.tif",
        "bigtiff": d / "bigtiff.tif",
        "raw": d / f"vol_{x}x{y}x{z}_uint16.raw",
        "slices": d / "slices",
    }


# Runs a command and writes its peak RSS (KiB) to the file named first. A process's
# `ru_maxrss` starts at the resident set of the process that forked it (and an exec keeps the
# larger of the two), so the command is forked from this small interpreter, not from pytest's
# process, which holds the test volume (the interpreter's own 10 MiB or so is then the least
# it can measure).
MEASURE = """
import os, sys
pid = os.fork()
if pid == 0:
    os.execv(sys.argv[2], sys.argv[2:])
_, status, usage = os.wait4(pid, 0)
with open(sys.argv[1], "w") as f:
    f.write(str(usage.ru_maxrss))
sys.exit(os.waitstatus_to_exitcode(status))
"""


def run_measured(tmp_path, *args, env=None):
    """Runs `ingest ARGS` to its end; returns (exit code, stdout, stderr, peak RSS in bytes)
    from `wait4`'s `ru_maxrss` (KiB on Linux) of that process alone."""
    assert (BIN / "ingest").exists(), f"{BIN / 'ingest'} not built: run cargo build --release"
    out, err, peak = (tmp_path / f"{name}.txt" for name in ("stdout", "stderr", "peak"))
    with open(out, "w") as o, open(err, "w") as e:
        code = subprocess.run([sys.executable, "-c", MEASURE, peak, BIN / "ingest", *args],
                              stdout=o, stderr=e, env=env, timeout=300).returncode
    return code, out.read_text(), err.read_text(), int(peak.read_text()) * 1024


def assert_within_limit(tmp_path, *args, env=None):
    """Runs `ingest convert ARGS --memory-limit LIMIT`: it succeeds, says it cut the planes
    into columns, and peaks within the limit. Returns its stdout."""
    code, out, err, peak = run_measured(tmp_path, "convert", *args, "--memory-limit", LIMIT,
                                        env=env)
    assert code == 0, err
    line = re.search(r"in (\d+) columns of \d+×\d+ voxels \(levels 0 to \d+ column by column\) "
                     r"to stay within the memory limit \(estimated peak ([0-9.]+) MiB\)", out)
    assert line, f"not cut into columns:\n{out}"
    assert int(line.group(1)) > 1
    assert float(line.group(2)) <= LIMIT_BYTES / 2**20
    print(f"peak RSS {peak / 2**20:.1f} MiB, {peak / LIMIT_BYTES:.3f}× the limit")
    assert peak <= LIMIT_BYTES, (
        f"peak RSS {peak / 2**20:.1f} MiB is {peak / LIMIT_BYTES:.3f}× --memory-limit {LIMIT}")
    return out


@pytest.mark.parametrize("kind", ["strips", "one-strip", "tiled", "zlib", "predictor", "zlib-one-strip",
                                  "bigtiff", "raw", "slices"])
def test_every_input_kind_peaks_within_the_limit(inputs, tmp_path, kind):
    assert_within_limit(tmp_path, inputs[kind], "-o", tmp_path / "x.ome.zarr", *FLAGS,
                        "--quiet")


def test_columns_within_the_limit_write_the_store_whole_planes_write(inputs, tmp_path):
    kind = "bigtiff"
    whole = tmp_path / "whole" / "x.ome.zarr"
    code, out, err, peak = run_measured(tmp_path, "convert", inputs[kind], "-o", whole, *FLAGS,
                                        "--quiet")
    assert code == 0, err
    assert " columns of " not in out
    # Whole planes do not fit the limit: the limit is what makes the conversion cut.
    assert peak > LIMIT_BYTES, f"whole planes peaked at {peak / 2**20:.1f} MiB"
    cut = tmp_path / "cut" / "x.ome.zarr"
    assert_within_limit(tmp_path, inputs[kind], "-o", cut, *FLAGS, "--quiet")
    assert files(cut) == files(whole)


# Shards of 8 × 128 × 128 voxels (256 KiB): a worker gathers a shard row of its column at once,
# and each shard's 4 inner chunks are encoded on the worker that gathered it.
SHARDED = ["--ome-zarr-version", "0.5", "--shard", "8,128,128"]


def test_a_sharded_store_in_columns_peaks_within_the_limit_and_matches_whole_planes(
        inputs, tmp_path):
    whole = tmp_path / "whole" / "x.ome.zarr"
    code, out, err, peak = run_measured(tmp_path, "convert", inputs["raw"], "-o", whole, *FLAGS,
                                        *SHARDED, "--quiet")
    assert code == 0, err
    assert " columns of " not in out
    assert peak > LIMIT_BYTES, f"whole planes peaked at {peak / 2**20:.1f} MiB"
    cut = tmp_path / "cut" / "x.ome.zarr"
    assert_within_limit(tmp_path, inputs["raw"], "-o", cut, *FLAGS, *SHARDED, "--quiet")
    assert files(cut) == files(whole)
    # Level 0 is 8 × 12 shards of a plane, 2 slabs deep: every shard holds data.
    assert len(list((cut / "0" / "c" / "0").rglob("*"))) == 2 + 2 * 8 + 2 * 8 * 12


def test_each_partition_peaks_within_the_limit(inputs, tmp_path):
    out = tmp_path / "x.ome.zarr"
    for i in range(2):
        done = assert_within_limit(tmp_path, inputs["bigtiff"], "-o", out, *FLAGS, "--quiet",
                                   "--partition", f"{i}/2")
        assert done.startswith("wrote partition "), done
    code, _, err, _ = run_measured(tmp_path, "finalize", "-o", out, "--quiet")
    assert code == 0, err
    whole = tmp_path / "whole" / "x.ome.zarr"
    code, _, err, _ = run_measured(tmp_path, "convert", inputs["bigtiff"], "-o", whole, *FLAGS,
                                   "--quiet")
    assert code == 0, err
    assert files(out) == files(whole)


@pytest.mark.s3
def test_a_store_written_to_s3_peaks_within_the_limit(inputs, tmp_path):
    root = tmp_path / "root"
    (root / "bucket").mkdir(parents=True)
    server, endpoint = start_s3(root)
    try:
        assert_within_limit(tmp_path, inputs["raw"], "-o", "s3://bucket/x.ome.zarr",
                            "--s3-endpoint", endpoint, *FLAGS, "--quiet", env=s3_env())
        local = tmp_path / "local" / "x.ome.zarr"
        code, _, err, _ = run_measured(tmp_path, "convert", inputs["raw"], "-o", local, *FLAGS,
                                       "--quiet")
        assert code == 0, err
        assert files(root / "bucket" / "x.ome.zarr") == files(local)
    finally:
        server.terminate()
        server.wait(timeout=10)
