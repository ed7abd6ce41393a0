"""Memory-limit benchmark: `ingest convert --memory-limit` on planes of 1024², 4096² and 16384²
voxels, against whole-plane conversion of the same input in the same run.

    python3 benchmarks/columns_bench.py [--planes 1024,4096,16384] [--docs]
        [--baseline-bin PATH]

The 1024² and 4096² inputs are the sparse sample (`ingest sample --kind sparse`, uint16,
OME-TIFF in uncompressed strips of about 1 MB, as the `tiff` crate writes them); the 16384²
one is a synthetic mosaic (rings of bright voxels in black, uint16) that tifffile writes as a
BigTIFF with one uncompressed strip per page, as ImageJ and tifffile write stacks (the sample
generator is too slow for such planes). Each is written into `--work` and deleted after its
plane size is done. For every run it reports wall time, MB/s of input, the peak RSS
(GNU time) against the limit, and the columns `ingest` chose. Stores of the same input are
compared file by file (SHA-256) with the first run's. `--baseline-bin` adds runs of another
`ingest` binary (for example the build before columns existed) on the 1024² input.

Results go to docs/benchmarks/columns.md (docs/benchmarks.md markers `columns-bench`, with
`--docs`).
"""

import argparse
import datetime
import itertools
import os
import pathlib
import re
import shutil
import statistics
import subprocess
import tempfile
import time

from partition_bench import ROOT, digests, machine, outputs, publish, timed

# The binaries under test (a copy lets the tree be rebuilt while the benchmark runs).
BIN = pathlib.Path(os.environ.get("RESIDENCY_BIN", ROOT / "target" / "release"))

# Plane edge → (depth, input kind, [(label, memory limit or None for the default, repeats)])
RUNS = {
    1024: (256, "sample", [("whole planes (default limit)", None, 3),
                           ("--memory-limit 512M", "512M", 3),
                           ("--memory-limit 300M", "300M", 3)]),
    4096: (64, "sample", [("whole planes (default limit)", None, 1),
                          ("--memory-limit 2G", "2G", 1)]),
    16384: (64, "mosaic", [("--memory-limit 4G", "4G", 1), ("default limit", None, 1)]),
}


def write_mosaic(path: pathlib.Path, depth: int, edge: int):
    """A uint16 BigTIFF of `depth` planes of `edge`² voxels, one uncompressed strip per page:
    rings of bright voxels (a different radius on every plane) in black, written plane by
    plane."""
    import numpy as np
    import tifffile

    y, x = np.ogrid[:edge, :edge]
    r = np.hypot(y - edge / 2, x - edge / 3).astype(np.float32)

    def planes():
        for z in range(depth):
            ring = np.abs(r - (edge / 8 + z * edge / (4 * depth))) < edge / 64
            value = 1000 + (r.astype(np.int64) * 7 + z) % 3000
            yield np.where(ring, value, 0).astype(np.uint16)

    tifffile.imwrite(path, planes(), shape=(depth, edge, edge), dtype=np.uint16, bigtiff=True,
                     photometric="minisblack", metadata=None)


def run(cmd):
    """Runs `cmd` under GNU time; returns (seconds, peak RSS in MB, stdout)."""
    t = time.time()
    [(stdout, rss)] = outputs([timed(cmd)])
    return time.time() - t, rss, stdout


def limit_bytes(limit):
    if limit is None:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") // 2
    return int(limit[:-1]) << {"K": 10, "M": 20, "G": 30}[limit[-1]]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--planes", default="1024,4096,16384")
    ap.add_argument("--work", default=tempfile.gettempdir())
    ap.add_argument("--baseline-bin", type=pathlib.Path)
    ap.add_argument("--docs", action="store_true", help="point docs/benchmarks.md at this run")
    a = ap.parse_args()
    rows = []
    # Every run writes a store of its own, and the stores are removed at the end: no run pays
    # for the deletes of the one before (`benchmarks/ingest_bench.py` says why). Each size's
    # inputs (a few large files) go as soon as it is done.
    works = []
    try:
        for edge in map(int, a.planes.split(",")):
            depth, kind, runs = RUNS[edge]
            work = pathlib.Path(tempfile.mkdtemp(prefix=f"columns-{edge}-", dir=a.work))
            works.append(work)
            run_number = itertools.count()
            size = f"{depth},{edge},{edge}"
            if kind == "sample":
                subprocess.run([BIN / "ingest", "sample", "-o", work / "in", "--kind", "sparse",
                                "--size", size, "--quiet"], check=True)
            else:
                (work / "in").mkdir()
                write_mosaic(work / "in" / "mosaic.tif", depth, edge)
            inputs = sorted((work / "in").glob("*.tif"))
            input_mb = sum(p.stat().st_size for p in inputs) / 1e6
            first = None
            binaries = [(BIN / "ingest", runs)]
            if a.baseline_bin and edge == 1024:
                binaries.append((a.baseline_bin, [("baseline binary, whole planes", None, 3)]))
            for exe, these in binaries:
                for label, limit, repeats in these:
                    times, rss, line = [], [], ""
                    for _ in range(repeats):
                        out = work / f"out-{next(run_number)}" / "x.ome.zarr"
                        cmd = [exe, "convert", *inputs, "-o", out, "--quiet"]
                        if limit:
                            cmd += ["--memory-limit", limit]
                        s, r, stdout = run(cmd)
                        times.append(s)
                        rss.append(r)
                        line = next((l.strip() for l in stdout.splitlines()
                                     if " columns of " in l), "whole planes")
                    d = digests(out)
                    first = first or d
                    if exe == BIN / "ingest":
                        same = "identical" if d == first else "DIFFERENT"
                    else:
                        # An older build chunks the region arrays otherwise: compare the rest.
                        images = lambda ds: {k: v for k, v in ds.items()
                                             if not k.startswith("residency/")}
                        same = ("identical but for the region arrays' chunking"
                                if images(d) == images(first) else "DIFFERENT")
                    s = statistics.median(times)
                    peak = max(rss)
                    cap = limit_bytes(limit) / 2**20
                    ours = exe == BIN / "ingest"
                    rows.append((f"{depth}×{edge}²", f"{input_mb:,.0f}", label, f"{s:.1f}",
                                 f"{input_mb / s:.0f}", f"{peak:,.0f}",
                                 f"{cap:,.0f}" if ours else "none",
                                 ("yes" if peak <= cap else "NO") if ours else "",
                                 re.sub(r" to stay within.*", "", line), same))
                    print(rows[-1], flush=True)
            shutil.rmtree(work / "in")
    finally:
        for work in works:
            shutil.rmtree(work, ignore_errors=True)
    report = (
        f"Measured {datetime.date.today()} on {machine()}, by "
        f"`benchmarks/columns_bench.py --planes {a.planes}"
        f"{' --baseline-bin …' if a.baseline_bin else ''}`: the sparse sample (uint16, OME-TIFF "
        "in uncompressed strips of about 1 MB) for 1024² and 4096² planes, a synthetic mosaic "
        "(uint16 BigTIFF, one uncompressed strip per page) for 16384²; default 64³ bricks; wall time "
        "(the median of the repeats on 1024² planes), peak RSS by GNU time, and the store "
        "compared file by file (SHA-256) with the first run of the same input.\n\n"
        "| Volume z×plane | input MB | Run | s | MB/s | peak RSS MiB | limit MiB | under | "
        "columns | store |\n|---|---|---|---|---|---|---|---|---|---|\n"
        + "".join("| " + " | ".join(r) + " |\n" for r in rows))
    publish(report, "columns", "columns-bench", a.docs)


if __name__ == "__main__":
    main()
