"""Renderer benchmark: generates the datasets, runs `viewer bench run` on each, and writes the
report (markdown, PNG plots, raw JSON) with `viewer bench report`.

    python3 benchmarks/render_bench.py [--short] [--docs] [--out-dir DIR] [--data-dir DIR]

Builds nothing: it needs `target/release/ingest` and `target/release/viewer`
(`cargo build --release`), or the folder named by RESIDENCY_BIN. Datasets come from
`ingest sample --kind sparse|mixing|dense|cycif` (an `ingest` without `--kind` makes every
dataset from the fluorescence sample, and the report says so through the kind). Multi-channel
sparse, mixing and dense stores repeat channel 0 (the paper's simulated channels), rendered
with shifted transfer functions (`--vary-tf`). The 16-channel CyCIF-like store renders all 16,
as the paper's CyCIF Small does.

Experiments (see `viewer bench run --help` and docs/benchmarks/render-bench.md):
- table1: every method over the same orbit (sparse 1 and 4 channels, mixing 1 and 4, dense 1
  and 4, cycif):
  ours, the page-table and octree baselines, no skipping, SparseLeap and octree rasterisation;
- sweep: step, LOD bias, cache budget and leaf size on sparse 1 channel, and step and LOD bias
  for every other method on sparse, dense and cycif (the time–error front of every renderer);
  leaf size again on stores of smaller and larger bricks;
- skipped: bytes fetched against a naive frustum loader (sparse, mixing, dense, cycif, and
  sparse at half the brick size);
- scaling: sparse at three sizes, and 1, 2, 4, 8, 16 channels;
- modes: table1 and skipped again in maximum intensity projection and iso-surfaces (sparse,
  dense, cycif), iso without the segment-list renderers (they decline the mode).

`--short` runs tiny sizes, one view, one timed frame, 32x32 images (CI's mode, a few minutes
on two cores; it asserts nothing about speed). Outputs go to docs/benchmarks/ (full) or
benchmarks/data/short-report/ (short) unless --out-dir says otherwise; `--docs` also
points docs/benchmarks.md at the report, between its render-bench markers. `--modes` runs only
the render modes' comparison (Table 1 and skipped work in DVR, MIP and iso on the sparse, dense
and CyCIF stores) into docs/benchmarks/modes/.
"""

import argparse
import datetime
import json
import os
import pathlib
import shutil
import subprocess
import sys
import time

from docs_page import point_page_at

ROOT = pathlib.Path(__file__).resolve().parents[1]
BIN = pathlib.Path(os.environ.get("RESIDENCY_BIN", ROOT / "target" / "release"))


def run(cmd, quiet=False):
    """Runs `cmd`; on failure raises with the command and its stderr."""
    t = time.time()
    env = dict(os.environ)
    env.setdefault("XDG_RUNTIME_DIR", "/tmp")
    p = subprocess.run([str(c) for c in cmd], capture_output=True, text=True, env=env)
    if p.returncode != 0:
        raise SystemExit(f"failed ({p.returncode}): {' '.join(map(str, cmd))}\n{p.stderr[-4000:]}")
    if not quiet:
        print(f"  {time.time() - t:6.1f} s  {' '.join(map(str, cmd[:3]))} ... {cmd[-1]}", flush=True)
    return p.stdout


def ingest_has_kind():
    return "--kind" in run([BIN / "ingest", "sample", "--help"], quiet=True)


class Data:
    """Generates and converts the datasets on demand, once each."""

    def __init__(self, folder: pathlib.Path, has_kind: bool):
        self.folder = folder
        self.has_kind = has_kind
        folder.mkdir(parents=True, exist_ok=True)

    def kind(self, kind):
        return kind if self.has_kind else "fluorescence"

    def sample(self, kind, size, channels=None):
        z, y, x = size
        name = f"{self.kind(kind)}-{z}x{y}x{x}" + (f"-{channels}c" if channels else "")
        out = self.folder / "tiff" / name
        if not (out / "done").exists():
            shutil.rmtree(out, ignore_errors=True)
            cmd = [BIN / "ingest", "sample", "-o", out, "--size", f"{z},{y},{x}", "--quiet"]
            if self.has_kind:
                cmd += ["--kind", kind]
                if channels:
                    cmd += ["--channels", str(channels)]
            run(cmd)
            (out / "done").write_text("")
        tiffs = sorted(out.glob("*.tif"))
        if not tiffs:
            raise SystemExit(f"{out}: ingest sample wrote no TIFF")
        return name, tiffs

    def store(self, kind, size, chunk, repeat=1, channels=None):
        """A store of the `kind` sample: channel 0 repeated `repeat` times, or all channels of
        a `channels`-channel sample when `repeat` is None."""
        name, tiffs = self.sample(kind, size, channels)
        if repeat is None:
            inputs, tag = tiffs, "all"
        else:
            inputs, tag = [tiffs[0]] * repeat, f"x{repeat}"
        store = self.folder / f"{name}-{tag}-b{chunk}.ome.zarr"
        if not (store / "zarr.json").exists():
            cmd = [BIN / "ingest", "convert", *inputs, "-o", store, "--chunk", str(chunk), "--overwrite", "--quiet"]
            if repeat is not None and repeat > 1:
                cmd += ["--channel-names", ",".join(f"c{i}" for i in range(repeat))]
            run(cmd)
        return store


def plan(short: bool, modes: bool = False):
    """Datasets and experiments: (label, kind, size, chunk, repeat, sample channels, visible
    channels or None for all, experiments, extra flags). With `modes`, only the render modes'
    comparison: Table 1 and skipped work in DVR, MIP and iso on the sparse, dense and CyCIF
    stores."""
    if short:
        s, big, cy, chunk = (32, 32, 32), (48, 48, 48), (8, 64, 64), 16
    else:
        # The paper's Table 1 bricks: 32³.
        s, big, cy, chunk = (128, 128, 128), (192, 192, 192), (24, 256, 256), 32
    small = tuple(v // 2 for v in s)
    sweep_leaf = ["--sweep-params", "leaf"]
    # Every method over step and LOD bias, on the kinds the full sweep does not cover.
    sweep_methods = ["--sweep-params", "step,lod-bias,methods"]

    def bone(n):
        # A CT bone window on each of n channels: the soft tissue (values 100-400) is
        # transparent though its bricks hold data, as in the paper's Kingsnake renders.
        return [a for c in range(n) for a in ("--tf", f"{c}:800:6000:0.6")]

    def window(n):
        return [a for c in range(n) for a in ("--tf", f"{c}:200:3000:0.6")]

    iso = ["--mode", "iso", "--methods", "page-table,octree,residency,no-skipping"]

    p = [
        (f"sparse {s[0]}³", "sparse", s, chunk, 1, None, None, "table1,skipped,sweep,scaling", bone(1)),
        (f"sparse {s[0]}³ ×4", "sparse", s, chunk, 4, None, None, "table1,scaling", ["--vary-tf"] + bone(4)),
        # The Rayleigh–Taylor stand-in: pure (constant) fluids outside the mixing layer.
        (f"mixing {s[0]}³", "mixing", s, chunk, 1, None, None, "table1,skipped", []),
        (f"mixing {s[0]}³ ×4", "mixing", s, chunk, 4, None, None, "table1", ["--vary-tf"]),
        # Its worst case: no region empty or constant.
        (f"dense {s[0]}³", "dense", s, chunk, 1, None, None, "table1,skipped,sweep,scaling", sweep_methods),
        (f"dense {s[0]}³ ×4", "dense", s, chunk, 4, None, None, "table1", ["--vary-tf"]),
        # Skipping behind opaque matter: the heavy fluid made nearly opaque.
        (f"dense {s[0]}³ opaque", "dense", s, chunk, 1, None, None, "skipped", ["--tf", "0:0.3:0.8:0.9"]),
        # A contrast window above the camera background (offset 60, noise and autofluorescence
        # reach 163), as a microscopist sets it: the default ramp starts at the median (108),
        # so the background noise would be faint fog and no brick would be transparent.
        (f"cycif {cy[0]}×{cy[1]}×{cy[2]}", "cycif", cy, chunk, None, 16, None, "table1,skipped,sweep", sweep_methods + window(16)),
        # Maximum intensity projection beside DVR on the same stores and windows: what its
        # skipping (by the ray's running maximum, and regions transparent up to their largest
        # value) saves against the baselines, and bytes against the naive loader.
        (f"sparse {s[0]}³ MIP", "sparse", s, chunk, 1, None, None, "table1,skipped", bone(1) + ["--mode", "mip"]),
        (f"dense {s[0]}³ MIP", "dense", s, chunk, 1, None, None, "table1,skipped", ["--mode", "mip"]),
        (f"cycif {cy[0]}×{cy[1]}×{cy[2]} MIP", "cycif", cy, chunk, None, 16, None, "table1,skipped", window(16) + ["--mode", "mip"]),
        # Iso-surfaces (each channel's surface at its ramp's middle) on the same stores: what
        # skipping by the sides of the iso values saves, for the methods that draw the mode (the
        # segment-list renderers decline it).
        (f"sparse {s[0]}³ iso", "sparse", s, chunk, 1, None, None, "table1,skipped", bone(1) + iso),
        (f"dense {s[0]}³ iso", "dense", s, chunk, 1, None, None, "table1,skipped", iso),
        (f"cycif {cy[0]}×{cy[1]}×{cy[2]} iso", "cycif", cy, chunk, None, 16, None, "table1,skipped", window(16) + iso),
        (f"sparse {small[0]}³", "sparse", small, chunk, 1, None, None, "scaling", bone(1)),
        (f"sparse {big[0]}³", "sparse", big, chunk, 1, None, None, "scaling", bone(1)),
        (f"sparse {s[0]}³ ×8 (2 shown)", "sparse", s, chunk, 8, None, [0, 1], "scaling", ["--vary-tf"] + bone(8)),
        (f"sparse {s[0]}³ ×8", "sparse", s, chunk, 8, None, None, "scaling", ["--vary-tf"] + bone(8)),
        (f"sparse {s[0]}³ ×16", "sparse", s, chunk, 16, None, None, "scaling", ["--vary-tf"] + bone(16)),
        # Bytes against the naive loader at finer bricks too: the ceiling grows as bricks shrink.
        (f"sparse {s[0]}³ bricks {chunk // 2}", "sparse", s, chunk // 2, 1, None, None, "sweep,skipped", sweep_leaf + bone(1)),
        (f"sparse {s[0]}³ bricks {chunk * 2}", "sparse", s, chunk * 2, 1, None, None, "sweep", sweep_leaf + bone(1)),
    ]
    if modes:
        dvr = (f"sparse {s[0]}³", f"dense {s[0]}³", f"cycif {cy[0]}×{cy[1]}×{cy[2]}")
        p = [(label, kind, size, chunk, repeat, channels, visible, "table1,skipped", extra)
             for (label, kind, size, chunk, repeat, channels, visible, _, extra) in p
             if label in dvr or label.endswith((" MIP", " iso"))]
    if short:
        # Keep CI's run small: one leaf-vs-brick store is enough to exercise the code.
        p = [x for x in p if not x[0].endswith(f"bricks {chunk * 2}")]
    return p


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--short", action="store_true", help="tiny sizes, 1 view, 1 timed frame, 32x32 images")
    ap.add_argument("--docs", action="store_true", help="point docs/benchmarks.md at this run")
    ap.add_argument("--modes", action="store_true",
                    help="only the render modes' comparison: Table 1 and skipped work in DVR, MIP and iso on the sparse, dense and CyCIF stores [report in docs/benchmarks/modes]")
    ap.add_argument("--out-dir", type=pathlib.Path, help="report folder [docs/benchmarks, or benchmarks/data/short-report with --short]")
    ap.add_argument("--data-dir", type=pathlib.Path, default=ROOT / "benchmarks" / "data", help="scratch folder for datasets")
    ap.add_argument("--views", type=int, help="views of the orbit [4; 1 with --short]")
    ap.add_argument("--size", type=int, help="image edge in pixels [96; 32 with --short]")
    ap.add_argument("--timed-frames", type=int, help="frames timed per view [3; 1 with --short]")
    args = ap.parse_args()
    for exe in ("ingest", "viewer"):
        if not (BIN / exe).exists():
            raise SystemExit(f"{BIN / exe} not built: run cargo build --release")
    if args.modes and args.docs:
        raise SystemExit("--docs points docs/benchmarks.md at the full run, not at --modes")
    default_out = ROOT / "docs" / "benchmarks" / ("modes" if args.modes else "")
    out = args.out_dir or (ROOT / "benchmarks" / "data" / "short-report" if args.short else default_out)
    raw = out / "raw"
    raw.mkdir(parents=True, exist_ok=True)
    for old in [*raw.glob("*.json"), *out.glob("*.png")]:  # a stale file would be mistaken for this run's
        old.unlink()
    views = args.views or (1 if args.short else 3)
    size = args.size or (32 if args.short else 96)
    frames = args.timed_frames or (1 if args.short else 3)
    has_kind = ingest_has_kind()
    if not has_kind:
        print("note: this ingest has no `sample --kind`; every dataset is the fluorescence sample", file=sys.stderr)
    data = Data(args.data_dir, has_kind)
    started = time.time()
    results = []
    rows = plan(args.short, args.modes)
    for i, (label, kind, shape, chunk, repeat, channels, visible, experiments, extra) in enumerate(rows):
        store = data.store(kind, shape, chunk, repeat, channels)
        k = data.kind(kind)
        if k != kind:
            label = label.replace(kind, k, 1)
        result = raw / f"{i:02d}-{'-'.join(label.replace('³', '').replace('×', 'x').replace('(', '').replace(')', '').split())}.json"
        cmd = [BIN / "viewer", "bench", "run", "--store", store, "--experiment", experiments, "--label", label,
               "--kind", k, "--width", size, "--height", size, "--views", views, "--timed-frames", frames,
               "--out", result, "--quiet", *extra]
        if visible is not None:
            cmd += ["--channels", ",".join(map(str, visible))]
        print(f"[{i + 1}/{len(rows)}] {label}: {experiments}", flush=True)
        run(cmd)
        results.append(result)
    flags = " ".join(f for f, on in (("--short", args.short), ("--modes", args.modes)) if on)
    command = f"benchmarks/render_bench.py {flags}".strip()
    run([BIN / "viewer", "bench", "report", *results, "--out-dir", out, "--command", command])
    summary = (out / "summary.md").read_text()
    stamp = datetime.date.today().isoformat()
    summary = summary.replace("Measured on", f"Measured {stamp} on", 1)
    # The report links the full tables from the repository's root; summary.md sits beside them.
    (out / "summary.md").write_text(summary.replace("](docs/benchmarks/render-bench.md)", "](render-bench.md)"))
    print(f"\nwrote {out / 'render-bench.md'} in {time.time() - started:.0f} s\n")
    print(summary)
    if args.docs:
        point_page_at("render-bench", out / "render-bench.md", summary)
    # The raw results files, in run order, for whoever reads the folder.
    (raw / "index.json").write_text(json.dumps([r.name for r in results], indent=1) + "\n")


if __name__ == "__main__":
    main()
