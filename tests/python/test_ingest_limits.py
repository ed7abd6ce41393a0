"""The ingest limit probes (benchmarks/ingest_limits.py) on a small conversion: every probe runs
and is timed, the limit is the slowest probe, the encode probe's codec is the store's (its bytes
decode to level 0's chunk), and the write probe leaves nothing behind. Nothing here is about
speed."""

import json
import subprocess
import sys

import numcodecs
import numpy as np

from support.binaries import run_ingest
from support.paths import ROOT

sys.path.insert(0, str(ROOT / "benchmarks"))
import ingest_limits  # noqa: E402


def test_the_probes_time_each_part_and_the_limit_is_the_slowest(tmp_path):
    run_ingest("sample", "-o", tmp_path / "in", "--size", "16,128,128", "--quiet")
    src = tmp_path / "in" / "nuclei.ome.tif"
    store = tmp_path / "out.ome.zarr"
    run_ingest("convert", src, "-o", store, "--chunk", "32", "--quiet")
    before = sorted(p.name for p in tmp_path.iterdir())
    r = ingest_limits.limits(src, store)
    assert sorted(r["probes"]) == ["encode", "pyramid", "read", "write"]
    assert all(t > 0 for t in r["probes"].values()), r
    assert r["limit"] == max(r["probes"].values())
    assert r["probes"][r["slowest"]] == r["limit"]
    assert abs(r["serial"] - sum(r["probes"].values())) < 1e-12
    # The write probe's time includes the sync that follows the writes.
    assert 0 < r["write_unsynced"] <= r["probes"]["write"]
    assert sorted(p.name for p in tmp_path.iterdir()) == before
    # The command line gives the same document, with ingest's fraction of the limit.
    p = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "ingest_limits.py"), src, store,
                        "--ingest-seconds", "2"], capture_output=True, text=True, check=True)
    out = json.loads(p.stdout)
    assert out["fraction_of_limit"] == out["limit"] / 2


def test_the_encode_probe_compresses_level_0_chunks_as_the_store_does(tmp_path):
    volume = np.arange(40 * 40 * 40, dtype=np.uint16).reshape(40, 40, 40)
    chunks = ingest_limits.chunks_of(volume, 32)
    assert [c.shape for c in chunks] == [(32, 32, 32), (32, 32, 8), (32, 8, 32), (32, 8, 8),
                                         (8, 32, 32), (8, 32, 8), (8, 8, 32), (8, 8, 8)]
    assert np.array_equal(chunks[7], volume[32:, 32:, 32:])
    codec = numcodecs.Blosc(cname="lz4", clevel=5, shuffle=numcodecs.Blosc.SHUFFLE)
    back = np.frombuffer(codec.decode(codec.encode(chunks[0])), dtype=np.uint16)
    assert np.array_equal(back.reshape(32, 32, 32), volume[:32, :32, :32])
    # The pyramid's step is the rounded mean of each 2×2×2 block.
    block = np.array([[[1, 2], [3, 4]], [[5, 6], [7, 9]]], dtype=np.uint16)
    assert ingest_limits.half(block).tolist() == [[[5]]]  # (37 + 4) // 8
