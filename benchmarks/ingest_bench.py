"""Ingest benchmark: converts the same synthetic u16 stack with `ingest` and with its peers,
in one run, and reports wall time, MB/s and peak RSS as ratios to `ingest`.

    .venv-bench/bin/python benchmarks/ingest_bench.py [--sizes 64,512] [--rounds 3] [--flame] [--docs]

Input: the `nuclei` channel of `ingest sample` (uint16, 1024 x 1024 pixels per plane, depth
chosen for the size), as a BigTIFF OME-TIFF. Every tool writes OME-Zarr 0.5 / Zarr v3 with
64^3 chunks, blosc-lz4 (clevel 5, byte shuffle), the same number of levels, and mean
downsampling by 2 in every axis (`ingest` runs with --voxel-size 1,1,1 so its
anisotropy-aware pyramid is the same isotropic one). Each run is a separate process timed by
GNU time after `sync`; the peers read the TIFF with tifffile. Each round runs every tool once, in
the same order, so the tools alternate; a row gives the median of the rounds, and the ratios to
`ingest` are the median (and range) of the rounds' own ratios. zarrs_ome reads a Zarr array, so
it gets the stack pre-converted to a plain Zarr v3 array (that conversion is not timed).

No output is deleted while the bench runs: every run writes a folder of its own (the flame
graphs' runs too), and they are all removed at the end. ext4 without a journal checks each inode
it hands out against the inodes deleted in the last 60 seconds, and in the last 360 seconds
when the block of the inode table holding it is dirty (`recently_deleted` in
fs/ext4/ialloc.c), as the blocks a conversion is filling with new inodes are: so a run that
follows the deletion of thousands of files within six minutes pays a scan per file it makes,
and the bench would measure its own deletes (run it six minutes after deleting many files on
the same file system, for the same reason). Leftovers of an earlier run are removed first, and
there the bench waits those six minutes out.

Beside each size, the limit probes of benchmarks/ingest_limits.py (reading the input, encoding
level 0 with the same codec on all cores, writing the store's files and syncing them to disk,
the pyramid's arithmetic alone) say how far ingest is from what the machine allows: ingest's fraction of the limit is the
slowest probe's time over ingest's wall time.

With --flame, one more `ingest` run per size is recorded by `perf record` (DWARF call graphs)
and drawn as a flame graph by inferno (`cargo install inferno`) into
docs/benchmarks/ingest-flame-<size>.svg.

Results go to docs/benchmarks/ingest.md (with --docs, docs/benchmarks.md links to them between
its `ingest-bench` markers).
"""

import argparse
import datetime
import json
import os
import pathlib
import platform
import re
import shutil
import subprocess
import sys
import time

from docs_page import point_page_at, write_result
from file_system import describe, has_journal, mount_of
from ingest_limits import limits

ROOT = pathlib.Path(__file__).resolve().parents[1]
INGEST = ROOT / "target" / "release" / "ingest"
PEERS = ROOT / "benchmarks" / "peers.py"
PY = sys.executable
ZARRS_OME = shutil.which("zarrs_ome") or "/tmp/zarrs_tools/bin/zarrs_ome"


# ext4 without a journal checks each inode it hands out against those deleted within this many
# seconds: RECENTCY_MIN, plus RECENTCY_DIRTY when the inode table's block is dirty, as it is while
# files are made in it (fs/ext4/ialloc.c).
RECENT_DELETES_S = 60 + 300


def clear(folder):
    """Removes `folder` (an earlier run's leftovers) and, where the file system is ext4 without a
    journal, waits until its inodes no longer count as recently deleted."""
    if not folder.exists():
        return
    shutil.rmtree(folder)
    subprocess.run(["sync"], check=True)
    if has_journal(mount_of(folder.parent)["source"]) is False:
        time.sleep(RECENT_DELETES_S + 1)


def timed(cmd, out):
    """Runs `cmd` under GNU time (`out` must not exist yet); returns (wall seconds, peak RSS MB,
    CPU %) or an error string."""
    assert not out.exists(), f"{out} exists: every run writes a folder of its own"
    subprocess.run(["sync"], check=True)
    p = subprocess.run(["/usr/bin/time", "-f", "%e %M %P", *map(str, cmd)], capture_output=True, text=True)
    if p.returncode != 0:
        return f"failed: {p.stderr.strip().splitlines()[-2] if len(p.stderr.strip().splitlines()) > 1 else p.stderr.strip()}"
    wall, rss_kb, cpu = p.stderr.strip().splitlines()[-1].split()
    return float(wall), int(rss_kb) / 1024, cpu


def levels_of(store):
    attrs = json.loads((store / "zarr.json").read_text())["attributes"]
    return len(attrs["ome"]["multiscales"][0]["datasets"])


def bench(size_mib, work, rounds):
    depth = max(1, size_mib // 2)
    d = work / f"{size_mib}MiB"
    d.mkdir(parents=True, exist_ok=True)
    src = d / "nuclei.ome.tif"
    if not src.exists():
        subprocess.run([INGEST, "sample", "-o", d, "--size", f"{depth},1024,1024", "--quiet"], check=True, capture_output=True)
    input_mb = depth * 1024 * 1024 * 2 / 1e6
    runs = d / "runs"
    clear(runs)
    runs.mkdir()
    ours = runs / "first.ome.zarr"
    first = timed([INGEST, "convert", src, "-o", ours, "--voxel-size", "1,1,1", "--quiet"], ours)
    if isinstance(first, str):
        return input_mb, 0, {"ingest": [first]}, None
    levels = levels_of(ours)
    probes = limits(src, ours, keep=runs)
    # Each tool's command, given the folder it writes.
    commands = {"ingest": lambda out: [INGEST, "convert", src, "-o", out, "--voxel-size", "1,1,1", "--quiet"]}
    for tool in ["tensorstore", "ngff-zarr", "ome-zarr"]:
        commands[tool] = lambda out, tool=tool: [PY, PEERS, tool, src, out, levels]
    missing = {}
    if os.path.exists(ZARRS_OME):
        plain = d / "plain.zarr"
        if not plain.exists():
            subprocess.run([PY, PEERS, "zarr-array", src, plain, str(levels)], check=True)
        commands["zarrs_ome"] = lambda out: [ZARRS_OME, "--ome-zarr-version", "0.5", "--max-levels", levels - 1, plain, out]
    else:
        missing["zarrs_ome"] = "not run: zarrs_ome not installed (cargo install zarrs_tools --features ome)"
    # Rounds: every tool once per round, in the same order.
    rows = {tool: [] for tool in commands}
    for i in range(rounds):
        for tool, command in commands.items():
            out = runs / f"{tool}-{i}.zarr"
            rows[tool].append(timed(command(out), out))
    rows.update({tool: [why] for tool, why in missing.items()})
    return input_mb, levels, rows, probes


def median(values):
    ordered = sorted(values)
    return ordered[(len(ordered) - 1) // 2]


def table(results):
    lines = []
    for size, (input_mb, levels, rows, probes) in results.items():
        ours = rows["ingest"]
        lines.append(f"\n**{size} MiB** ({input_mb:.0f} MB of uint16, {levels} levels, {len(ours)} rounds)\n")
        lines.append("| Tool | Wall s | MB/s | Peak RSS MB | CPU | Time vs ingest | RSS vs ingest |")
        lines.append("|---|---|---|---|---|---|---|")
        for tool, runs in rows.items():
            failed = next((r for r in runs if isinstance(r, str)), None)
            if failed:
                lines.append(f"| {tool} | {failed} | | | | | |")
                continue
            wall = median(r[0] for r in runs)
            rss = median(r[1] for r in runs)
            cpu = next(r[2] for r in runs if r[0] == wall)
            if any(isinstance(r, str) for r in ours):
                ratio_t = ratio_m = "n/a"
            else:
                times = [r[0] / o[0] for r, o in zip(runs, ours)]
                sizes = [r[1] / o[1] for r, o in zip(runs, ours)]
                ratio_t = f"{median(times):.2f}x ({min(times):.2f}–{max(times):.2f})"
                ratio_m = f"{median(sizes):.2f}x"
            lines.append(f"| {tool} | {wall:.2f} | {input_mb / wall:.0f} | {rss:.0f} | {cpu} | {ratio_t} | {ratio_m} |")
        lines.append("")
        if probes:
            walls = [r[0] for r in ours if not isinstance(r, str)]
            lines.append(limits_line(probes, median(walls) if walls else None))
    return "\n".join(lines)


def flame(size_mib, work, report):
    """Records one `ingest` run of `size_mib` and draws its flame graph; returns the SVG's
    name under docs/benchmarks, or why there is none."""
    collapse, draw = shutil.which("inferno-collapse-perf"), shutil.which("inferno-flamegraph")
    if not (shutil.which("perf") and collapse and draw):
        return None, "no flame graph: needs perf and inferno (cargo install inferno)"
    d = work / f"{size_mib}MiB"
    out, data = d / "runs" / "flame.ome.zarr", d / "perf.data"
    subprocess.run(["sync"], check=True)
    subprocess.run(["perf", "record", "-F", "999", "--call-graph", "dwarf,32768", "-o", data, "--",
                    INGEST, "convert", d / "nuclei.ome.tif", "-o", out, "--voxel-size", "1,1,1", "--quiet"],
                   check=True, capture_output=True)
    script = subprocess.run(["perf", "script", "-i", data], check=True, capture_output=True).stdout
    folded = subprocess.run([collapse], input=script, check=True, capture_output=True).stdout
    name = f"{report}-flame-{size_mib}.svg"
    svg = subprocess.run([draw, "--title", f"ingest convert, {size_mib} MiB u16 OME-TIFF, {os.cpu_count()} cores",
                          "--minwidth", "0.5"], input=folded, check=True, capture_output=True).stdout
    (ROOT / "docs" / "benchmarks" / name).write_bytes(svg)
    data.unlink()
    return name, None


def limits_line(probes, wall):
    """The limit probes of one size, and ingest's fraction of the limit at its median `wall`."""
    p = probes["probes"]
    unsynced = probes.get("write_unsynced")
    parts = ", ".join(f"{name} {p[name]:.3f} s" + (f" (synced; {unsynced:.3f} s before the sync)" if name == "write" and unsynced else "")
                      for name in ("read", "encode", "write", "pyramid"))
    text = (f"Limit probes on {probes['cores']} cores ([ingest_limits.py](../../benchmarks/ingest_limits.py)): {parts}; "
            f"the limit is {probes['slowest']}, {probes['limit']:.3f} s (all four one after the other: {probes['serial']:.3f} s).")
    if wall:
        text += (f" ingest runs at {probes['limit'] / wall:.0%} of the limit (the limit's time over ingest's median wall time)"
                 f" and at {probes['serial'] / wall:.0%} of the four probes one after the other.")
    return text


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", default="64,512", help="input sizes in MiB, comma-separated")
    ap.add_argument("--work", default=str(ROOT / "bench-data"), help="folder for inputs and outputs")
    ap.add_argument("--rounds", type=int, default=3, help="runs of every tool per size, alternating")
    ap.add_argument("--flame", action="store_true", help="draw a flame graph of one ingest run per size")
    ap.add_argument("--docs", action="store_true", help="point docs/benchmarks.md at this run")
    ap.add_argument("--report", default="ingest",
                    help="name of the report: docs/benchmarks/REPORT.md, its flame graphs REPORT-flame-SIZE.svg and, with "
                         "--docs, the REPORT-bench markers in docs/benchmarks.md")
    args = ap.parse_args()
    if not INGEST.exists():
        sys.exit(f"{INGEST} not built: run cargo build --release")
    work = pathlib.Path(args.work)
    results = {int(s): bench(int(s), work, args.rounds) for s in args.sizes.split(",")}
    flames = {size: flame(size, work, args.report) for size in results} if args.flame else {}
    for size in results:
        shutil.rmtree(work / f"{size}MiB" / "runs")
    cpu = re.sub(r"\s+", " ", next((l.split(":", 1)[1] for l in open("/proc/cpuinfo") if l.startswith("model name")), "?")).strip()
    header = (
        f"Measured {datetime.date.today()} on {os.cpu_count()} cores ({cpu}), "
        f"{os.sysconf('SC_PAGE_SIZE') * os.sysconf('SC_PHYS_PAGES') / 2**30:.0f} GiB RAM, {platform.system()} {platform.release()}, "
        f"inputs and outputs on {describe(work)}, "
        f"by `benchmarks/ingest_bench.py --sizes {args.sizes} --rounds {args.rounds} --work {work} --report {args.report}`. "
        f"Ratios above 1 mean the peer is slower or larger."
    )
    text = header + "\n" + table(results)
    for size, (name, why) in flames.items():
        text += f"\n\nFlame graph of one `ingest` run at {size} MiB: " + (f"[{name}]({name})." if name else why)
    print(text)
    result = write_result(f"{args.report}.md", text + "\n")
    if args.docs:
        point_page_at(f"{args.report}-bench", result, text)


if __name__ == "__main__":
    main()
