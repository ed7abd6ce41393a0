"""Ingest benchmark: converts the same synthetic u16 stack with `ingest` and with its peers,
in one run, and reports wall time, MB/s and peak RSS as ratios to `ingest`.

    .venv-bench/bin/python benchmarks/ingest_bench.py [--sizes 64,512] [--docs]

Input: the `nuclei` channel of `ingest sample` (uint16, 1024 x 1024 pixels per plane, depth
chosen for the size), as a BigTIFF OME-TIFF. Every tool writes OME-Zarr 0.5 / Zarr v3 with
64^3 chunks, blosc-lz4 (clevel 5, byte shuffle), the same number of levels, and mean
downsampling by 2 in every axis (`ingest` runs with --voxel-size 1,1,1 so its
anisotropy-aware pyramid is the same isotropic one). Each run is a separate process timed by
GNU time after `sync`; the peers read the TIFF with tifffile. zarrs_ome reads a Zarr array, so
it gets the stack pre-converted to a plain Zarr v3 array (that conversion is not timed).

Beside each size, the limit probes of benchmarks/ingest_limits.py (reading the input, encoding
level 0 with the same codec on all cores, writing the store's files, the pyramid's arithmetic
alone) say how far ingest is from what the machine allows: ingest's fraction of the limit is the
slowest probe's time over ingest's wall time.

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

from docs_page import point_page_at, write_result
from ingest_limits import limits

ROOT = pathlib.Path(__file__).resolve().parents[1]
INGEST = ROOT / "target" / "release" / "ingest"
PEERS = ROOT / "benchmarks" / "peers.py"
PY = sys.executable
ZARRS_OME = shutil.which("zarrs_ome") or "/tmp/zarrs_tools/bin/zarrs_ome"


def timed(cmd, out):
    """Runs `cmd` under GNU time; returns (wall seconds, peak RSS MB, CPU %) or an error string."""
    if out.exists():
        shutil.rmtree(out)
    subprocess.run(["sync"], check=True)
    p = subprocess.run(["/usr/bin/time", "-f", "%e %M %P", *map(str, cmd)], capture_output=True, text=True)
    if p.returncode != 0:
        return f"failed: {p.stderr.strip().splitlines()[-2] if len(p.stderr.strip().splitlines()) > 1 else p.stderr.strip()}"
    wall, rss_kb, cpu = p.stderr.strip().splitlines()[-1].split()
    return float(wall), int(rss_kb) / 1024, cpu


def levels_of(store):
    attrs = json.loads((store / "zarr.json").read_text())["attributes"]
    return len(attrs["ome"]["multiscales"][0]["datasets"])


def bench(size_mib, work):
    depth = max(1, size_mib // 2)
    d = work / f"{size_mib}MiB"
    d.mkdir(parents=True, exist_ok=True)
    src = d / "nuclei.ome.tif"
    if not src.exists():
        subprocess.run([INGEST, "sample", "-o", d, "--size", f"{depth},1024,1024", "--quiet"], check=True, capture_output=True)
    input_mb = depth * 1024 * 1024 * 2 / 1e6
    rows = {}
    ours = d / "ingest.ome.zarr"
    rows["ingest"] = timed([INGEST, "convert", src, "-o", ours, "--voxel-size", "1,1,1", "--quiet"], ours)
    levels = levels_of(ours)
    probes = limits(src, ours)
    for tool in ["tensorstore", "ngff-zarr", "ome-zarr"]:
        rows[tool] = timed([PY, PEERS, tool, src, d / f"{tool}.zarr", levels], d / f"{tool}.zarr")
    if os.path.exists(ZARRS_OME):
        plain = d / "plain.zarr"
        if not plain.exists():
            subprocess.run([PY, PEERS, "zarr-array", src, plain, str(levels)], check=True)
        out = d / "zarrs_ome.zarr"
        rows["zarrs_ome"] = timed(
            [ZARRS_OME, "--ome-zarr-version", "0.5", "--max-levels", levels - 1, plain, out], out
        )
    else:
        rows["zarrs_ome"] = "not run: zarrs_ome not installed (cargo install zarrs_tools --features ome)"
    return input_mb, levels, rows, probes


def table(results):
    lines = []
    for size, (input_mb, levels, rows, probes) in results.items():
        base = rows["ingest"]
        lines.append(f"\n**{size} MiB** ({input_mb:.0f} MB of uint16, {levels} levels)\n")
        lines.append("| Tool | Wall s | MB/s | Peak RSS MB | CPU | Time vs ingest | RSS vs ingest |")
        lines.append("|---|---|---|---|---|---|---|")
        for tool, r in rows.items():
            if isinstance(r, str):
                lines.append(f"| {tool} | {r} | | | | | |")
                continue
            wall, rss, cpu = r
            ratio_t = wall / base[0] if not isinstance(base, str) else float("nan")
            ratio_m = rss / base[1] if not isinstance(base, str) else float("nan")
            lines.append(f"| {tool} | {wall:.2f} | {input_mb / wall:.0f} | {rss:.0f} | {cpu} | {ratio_t:.2f}x | {ratio_m:.2f}x |")
        lines.append("")
        lines.append(limits_line(probes, base))
    return "\n".join(lines)


def limits_line(probes, ingest):
    """The limit probes of one size, and ingest's fraction of the limit."""
    p = probes["probes"]
    parts = ", ".join(f"{name} {p[name]:.3f} s" for name in ("read", "encode", "write", "pyramid"))
    text = (f"Limit probes on {probes['cores']} cores ([ingest_limits.py](../../benchmarks/ingest_limits.py)): {parts}; "
            f"the limit is {probes['slowest']}, {probes['limit']:.3f} s (all four one after the other: {probes['serial']:.3f} s).")
    if not isinstance(ingest, str):
        text += f" ingest runs at {probes['limit'] / ingest[0]:.0%} of the limit (the limit's time over ingest's wall time)."
    return text


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", default="64,512", help="input sizes in MiB, comma-separated")
    ap.add_argument("--work", default=str(ROOT / "bench-data"), help="folder for inputs and outputs")
    ap.add_argument("--docs", action="store_true", help="point docs/benchmarks.md at this run")
    args = ap.parse_args()
    if not INGEST.exists():
        sys.exit(f"{INGEST} not built: run cargo build --release")
    work = pathlib.Path(args.work)
    results = {int(s): bench(int(s), work) for s in args.sizes.split(",")}
    cpu = re.sub(r"\s+", " ", next((l.split(":", 1)[1] for l in open("/proc/cpuinfo") if l.startswith("model name")), "?")).strip()
    header = (
        f"Measured {datetime.date.today()} on {os.cpu_count()} cores ({cpu}), "
        f"{os.sysconf('SC_PAGE_SIZE') * os.sysconf('SC_PHYS_PAGES') / 2**30:.0f} GiB RAM, {platform.system()} {platform.release()}, "
        f"by `benchmarks/ingest_bench.py --sizes {args.sizes}`. Ratios above 1 mean the peer is slower or larger."
    )
    text = header + "\n" + table(results)
    print(text)
    result = write_result("ingest.md", text + "\n")
    if args.docs:
        point_page_at("ingest-bench", result, text)


if __name__ == "__main__":
    main()
