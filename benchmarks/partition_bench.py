"""Partitioned conversion benchmark: `ingest convert` in one process against N partitions run at
once and `ingest finalize`, to a local folder and to an S3 server on loopback (s3s-fs, as the
tests use), on the same input in the same run.

    python3 benchmarks/partition_bench.py [--size 256,512,512] [--partitions 1,2,4] [--docs]

With `--large Z,Y,X` it instead converts one sample larger than this machine's memory (written
by `ingest sample`, deleted afterwards) in one process and in N partitions at once, and reports
each process's peak RSS against the input's size; the two stores are compared file by file by
SHA-256, one on disk at a time (the input and a store need about 1.5× the input's size of free
disk). Results go to docs/benchmarks/partitions-large.md (docs/benchmarks.md markers
`partition-large`).

Every run's store is checked byte for byte against the single-process store. Reported (the
median of `--repeat` runs): wall time of the partitions (all at once on this machine, so they
share its cores), of finalize, and in all; the peak RSS of the largest process (GNU time). Results go to
docs/benchmarks/partitions.md; with `--docs`, docs/benchmarks.md links to them between its
`partition-bench` markers.
"""

import argparse
import datetime
import os
import pathlib
import platform
import re
import shutil
import subprocess
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
BIN = ROOT / "target" / "release"
from docs_page import point_page_at, write_result
from server_bench import S3_KEY as KEY, S3_SECRET as SECRET, cpu_name, start_s3s_fs as start_s3


def timed(cmd, env=None):
    """Starts `cmd` under GNU time; returns the process (stderr carries time's report)."""
    return subprocess.Popen(["/usr/bin/time", "-f", "RSS_KB %M", *map(str, cmd)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)


def outputs(procs):
    """Waits for `procs`; returns each one's (stdout, peak RSS in MB)."""
    done = []
    for p in procs:
        out, err = p.communicate()
        if p.returncode != 0:
            raise RuntimeError(err)
        done.append((out, int(re.search(r"RSS_KB (\d+)", err).group(1)) / 1024))
    return done


def finish(procs):
    """Waits for `procs`; returns the largest peak RSS in MB."""
    return max(rss for _, rss in outputs(procs))


def machine() -> str:
    """This machine, for a report: cores, CPU and memory."""
    mem_gb = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 1e9
    return f"{os.cpu_count()} cores ({cpu_name()}) with {mem_gb:.0f} GB of memory"


def files(folder: pathlib.Path) -> dict:
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


def publish(report: str, name: str, marker: str, docs: bool):
    """Writes `report` to docs/benchmarks/NAME.md, prints it, and with `docs` links
    docs/benchmarks.md to it between the `marker` comments."""
    result = write_result(f"{name}.md", report)
    print(report)
    if docs:
        point_page_at(marker, result, report)


def digests(folder: pathlib.Path) -> dict:
    """SHA-256 of every file under `folder`, read in blocks (stores larger than memory)."""
    import hashlib

    out = {}
    for p in folder.rglob("*"):
        if p.is_file():
            h = hashlib.sha256()
            with p.open("rb") as f:
                for block in iter(lambda: f.read(1 << 20), b""):
                    h.update(block)
            out[str(p.relative_to(folder))] = h.hexdigest()
    return out


def large(a):
    """One sample larger than memory: one process against N partitions at once."""
    n = max(int(c) for c in a.partitions.split(","))
    work = pathlib.Path(tempfile.mkdtemp(prefix="partition-large-", dir=a.work))
    try:
        t = time.time()
        subprocess.run([BIN / "ingest", "sample", "-o", work / "in", "--kind", "sparse", "--size", a.large, "--quiet"], check=True)
        sample_s = time.time() - t
        inputs = sorted((work / "in").glob("*.tif"))
        input_gb = sum(p.stat().st_size for p in inputs) / 1e9
        t = time.time()
        one = work / "one" / "x.ome.zarr"
        one_rss = finish([timed([BIN / "ingest", "convert", *inputs, "-o", one, "--quiet"])])
        one_s = time.time() - t
        # One store on disk at a time: the input and two stores may not fit.
        one_digests = digests(one)
        shutil.rmtree(one.parent)
        t = time.time()
        out = work / "parted" / "x.ome.zarr"
        part_rss = finish([timed([BIN / "ingest", "convert", *inputs, "-o", out, "--quiet", "--partition", f"{i}/{n}"]) for i in range(n)])
        parts_s = time.time() - t
        t = time.time()
        fin_rss = finish([timed([BIN / "ingest", "finalize", "-o", out, "--quiet"])])
        fin_s = time.time() - t
        same = one_digests == digests(out)
        stored_gb = sum(p.stat().st_size for p in out.rglob("*") if p.is_file()) / 1e9
    finally:
        shutil.rmtree(work, ignore_errors=True)
    report = (
        f"Measured {datetime.date.today()} on {machine()}, by "
        f"`benchmarks/partition_bench.py --large {a.large} --partitions {n}`: the sparse sample of {a.large} (z,y,x) uint16 voxels, "
        f"{input_gb:.1f} GB of TIFF (written by `ingest sample` in {sample_s:.0f} s, deleted after), more than this machine's memory; "
        f"stored {stored_gb:.2f} GB. One process: {one_s:.0f} s, peak RSS {one_rss:,.0f} MB. {n} partitions at once: "
        f"{parts_s:.0f} s, peak RSS of the largest {part_rss:,.0f} MB; finalize {fin_s:.1f} s, peak RSS {fin_rss:,.0f} MB. "
        f"The two stores are {'identical file by file (SHA-256)' if same else 'DIFFERENT'}.\n"
    )
    publish(report, "partitions-large", "partition-large", a.docs)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--size", default="256,512,512", help="z,y,x of the sparse sample")
    ap.add_argument("--partitions", default="1,2,4")
    ap.add_argument("--repeat", type=int, default=3, help="runs of each; the median is reported")
    ap.add_argument("--large", help="Z,Y,X of one sample larger than memory: one process against N partitions")
    ap.add_argument("--work", default=None, help="folder for the large run's files (default: the system's temp dir)")
    ap.add_argument("--docs", action="store_true", help="point docs/benchmarks.md at this run")
    a = ap.parse_args()
    if a.large:
        large(a)
        return
    counts = [int(n) for n in a.partitions.split(",")]
    work = pathlib.Path(tempfile.mkdtemp(prefix="partition-bench-"))
    env = {k: v for k, v in os.environ.items() if not k.startswith("AWS_")}
    env.update(AWS_ACCESS_KEY_ID=KEY, AWS_SECRET_ACCESS_KEY=SECRET)
    s3root = work / "s3"
    (s3root / "bucket").mkdir(parents=True)
    s3, endpoint = start_s3(s3root)
    rows = []
    try:
        subprocess.run([BIN / "ingest", "sample", "-o", work / "in", "--kind", "sparse", "--size", a.size, "--quiet"], check=True)
        inputs = sorted((work / "in").glob("*.tif"))
        input_mb = sum(p.stat().st_size for p in inputs) / 1e6
        ref = work / "ref" / "x.ome.zarr"
        # Warm the page cache for every run alike, and make the reference store.
        finish([timed([BIN / "ingest", "convert", *inputs, "-o", ref, "--quiet"])])
        reference = files(ref)

        def once(target, n, r):
            """Run `r` of `target` in `n` partitions (0: one process), into a folder of its own:
            nothing is deleted while the bench runs, so that no run pays for the deletes of the
            one before (`benchmarks/ingest_bench.py` says why)."""
            if n == 0:
                out = work / f"one-{r}" / "x.ome.zarr"
                t0 = time.time()
                rss = finish([timed([BIN / "ingest", "convert", *inputs, "-o", out, "--quiet"])])
                return time.time() - t0, None, rss, files(out)
            if target == "folder":
                out, extra, where = work / f"f{n}-{r}" / "x.ome.zarr", [], work / f"f{n}-{r}"
            else:
                out, extra = f"s3://bucket/p{n}-{r}/x.ome.zarr", ["--s3-endpoint", endpoint]
                where = s3root / "bucket" / f"p{n}-{r}"
            t0 = time.time()
            rss = finish([timed([BIN / "ingest", "convert", *inputs, "-o", out, "--quiet", *extra, "--partition", f"{i}/{n}"], env)
                          for i in range(n)])
            t1 = time.time()
            rss = max(rss, finish([timed([BIN / "ingest", "finalize", "-o", out, "--quiet", *extra], env)]))
            t2 = time.time()
            return t1 - t0, t2 - t1, rss, files(where / "x.ome.zarr")

        plan = [("folder", 0)] + [(t, n) for t in ["folder", "S3"] for n in counts]
        for target, n in plan:
            runs = []
            for r in range(a.repeat):
                tp, tf, rss, got = once(target, n, r)
                if got != reference:
                    raise RuntimeError(f"{target} N={n}: not the single-process store")
                runs.append((tp + (tf or 0), tp, tf, rss))
            total, tp, tf, rss = sorted(runs)[len(runs) // 2]
            rows.append((target, "one process" if n == 0 else f"{n} partitions", tp, tf, max(r[3] for r in runs)))
    finally:
        s3.terminate()
        s3.wait(timeout=10)
        shutil.rmtree(work, ignore_errors=True)
    lines = [
        f"Measured {datetime.date.today()} on {os.cpu_count()} cores ({cpu_name()}), Linux {platform.release()}, by "
        f"`benchmarks/partition_bench.py --size {a.size} --partitions {a.partitions} --repeat {a.repeat}`: the sparse sample ({a.size} z,y,x, uint16, "
        f"{input_mb:.0f} MB of TIFF), default 64³ bricks; the N partitions run at once on this machine (so they share its "
        "cores: the speed-up a cluster gets from N machines is not measured here), to a local folder and to s3s-fs on "
        "loopback, after one conversion that warms the page cache; the median of the runs is shown. "
        "Every store was checked byte for byte against the single-process store.",
        "",
        "| Output | Run | partitions s | finalize s | total s | MB/s | peak RSS per process MB |",
        "|---|---|---|---|---|---|---|",
    ]
    for target, run, tp, tf, rss in rows:
        total = tp + (tf or 0)
        lines.append(f"| {target} | {run} | {tp:.2f} | {'' if tf is None else f'{tf:.2f}'} | {total:.2f} | "
                     f"{input_mb / total:.0f} | {rss:.0f} |")
    publish("\n".join(lines) + "\n", "partitions", "partition-bench", a.docs)


if __name__ == "__main__":
    main()
