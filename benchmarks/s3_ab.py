"""What the A/B benches over S3 share (`s3_batches.py`, `s3_viewer.py`): the builds named on
the command line, rounds that alternate their order, and one dense store in s3s-fs."""

import argparse
import contextlib
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "python"))
from support.paths import BIN  # noqa: E402
from support.s3 import start_s3  # noqa: E402


def parser(doc: str, program: str) -> argparse.ArgumentParser:
    """The bench's flags: `--bin NAME=PATH` builds of `program` (repeatable) and `--rounds`."""
    ap = argparse.ArgumentParser(description=doc.splitlines()[0])
    ap.add_argument("--bin", action="append", default=[], help=f"NAME=PATH of a {program}")
    ap.add_argument("--rounds", type=int, default=3)
    return ap


def rounds(args, program: str):
    """(round, name, path) for every round and build: the builds of `--bin`, else the release
    build's `program` alone, each round in the other order, so that neither goes first always."""
    bins = [b.split("=", 1) for b in args.bin] or [["release", str(BIN / program)]]
    for rnd in range(args.rounds):
        for name, exe in (bins if rnd % 2 == 0 else bins[::-1]):
            yield rnd, name, exe


@contextlib.contextmanager
def dense_store_in_s3():
    """s3s-fs on loopback, its bucket `bucket` holding `dense.ome.zarr` (`ingest sample --kind
    dense`: 256³ float32, 64 bricks of 64³ at level 0); yields (work folder, endpoint)."""
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        subprocess.run([BIN / "ingest", "sample", "--kind", "dense", "-o", tmp / "in", "--quiet"],
                       check=True)
        (tmp / "root" / "bucket").mkdir(parents=True)
        subprocess.run([BIN / "ingest", "convert", tmp / "in" / "dense.ome.tif", "-o",
                        tmp / "root" / "bucket" / "dense.ome.zarr", "--quiet"], check=True)
        s3, endpoint = start_s3(tmp / "root")
        try:
            yield tmp, endpoint
        finally:
            s3.terminate()
            s3.wait()
