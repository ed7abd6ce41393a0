"""Volumetric depth image benchmark: generates the datasets, runs `viewer bench vdi` on each,
and writes docs/benchmarks/vdi-bench.md (the tables, the paper's figures beside ours) and the
raw JSON results (`schemas/json/vdi-bench.schema.json`).

    python3 benchmarks/vdi_bench.py [--short] [--docs] [--out-dir DIR] [--data-dir DIR] [--size N]
                                    [--width W --height H] [--volume N]

For each dataset, from the scene's camera (the camera of generation), for N_S = 15, 20, 30:
the VDI's generation time and sizes (as the GPU holds it, in the paper's raw layout, and as a
.vdi file, against the volume's bytes), then at 0, 5, 10, 20, 30 and 40 degrees from that
camera the SSIM and PSNR of the VDI's image against direct volume rendering (DVR) of the same
camera, and the frame time of each (VDI with and without empty-space skipping; DVR converged).
Times are GPU times where the device has timestamp queries.

The datasets are the render bench's (`benchmarks/render_bench.py`): sparse (a CT bone window),
mixing (the Rayleigh-Taylor stand-in) and the 16-channel CyCIF-like store, all channels of a
multi-channel store mixed into one VDI (the paper's are single-channel).

Builds nothing: it needs `target/release/ingest` and `target/release/viewer`, or the folder
named by RESIDENCY_BIN. `--short` runs tiny sizes (CI's mode; it asserts nothing about speed);
the images are 640×360 by default: a 16:9 frame, as the paper's, that fits a VDI of N_S = 30
in lavapipe's 128 MiB storage-buffer binding (34 slots of 16 bytes a pixel, 125 MB). `--size N`
makes them N×N; `--width` and `--height` set each side (each defaults to `--size`, else to
640×360's); `--width 1920 --height 1080` gives the paper's HD frames on a GPU.
`--volume N` sets the edge of the sparse and mixing volumes (128 by default) and the CyCIF
store's plane (24×2N×2N).
"""

import argparse
import datetime
import json
import pathlib
import sys
import time

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from docs_page import point_page_at, write_result  # noqa: E402
from render_bench import BIN, ROOT, Data, ingest_has_kind, run  # noqa: E402


def plan(short: bool, edge: int):
    """(label, kind, size, chunk, repeat, sample channels, extra flags) per dataset."""
    if short:
        s, cy, chunk = (32, 32, 32), (8, 64, 64), 16
    else:
        s, cy, chunk = (edge, edge, edge), (24, 2 * edge, 2 * edge), 32
    bone = ["--tf", "0:800:6000:0.6"]
    window = [a for c in range(16) for a in ("--tf", f"{c}:200:3000:0.6")]
    return [
        (f"sparse {s[0]}³", "sparse", s, chunk, 1, None, bone),
        (f"mixing {s[0]}³", "mixing", s, chunk, 1, None, []),
        (f"cycif {cy[0]}×{cy[1]}×{cy[2]} (16 channels)", "cycif", cy, chunk, None, 16, window),
    ]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--short", action="store_true", help="tiny sizes, N_S 20 only, 0 and 10 degrees")
    ap.add_argument("--docs", action="store_true", help="point docs/benchmarks.md at this run")
    ap.add_argument("--out-dir", type=pathlib.Path, help="report folder [docs/benchmarks, or benchmarks/data/short-report with --short]")
    ap.add_argument("--data-dir", type=pathlib.Path, default=ROOT / "benchmarks" / "data", help="scratch folder for datasets")
    ap.add_argument("--size", type=int, help="square images of this edge in pixels [640×360; 32×32 with --short]")
    ap.add_argument("--width", type=int, help="image width in pixels [--size, else 640; 32 with --short]")
    ap.add_argument("--height", type=int, help="image height in pixels [--size, else 360; 32 with --short]")
    ap.add_argument("--volume", type=int, default=128, help="edge of the sparse and mixing volumes [128]")
    ap.add_argument("--timed-frames", type=int, help="frames timed per measurement [3; 1 with --short]")
    args = ap.parse_args()
    for exe in ("ingest", "viewer"):
        if not (BIN / exe).exists():
            raise SystemExit(f"{BIN / exe} not built: run cargo build --release")
    out = args.out_dir or (ROOT / "benchmarks" / "data" / "short-report" if args.short else ROOT / "docs" / "benchmarks")
    raw = out / "vdi"
    raw.mkdir(parents=True, exist_ok=True)
    for old in [*raw.glob("*.json"), *raw.glob("*.md"), *raw.glob("*.png")]:  # a stale file would be mistaken for this run's
        old.unlink()
    default = (32, 32) if args.short else (640, 360)
    width = args.width or args.size or default[0]
    height = args.height or args.size or default[1]
    frames = args.timed_frames or (1 if args.short else 3)
    data = Data(args.data_dir, ingest_has_kind())
    started = time.time()
    tables = []
    datasets = plan(args.short, args.volume)
    for i, (label, kind, shape, chunk, repeat, channels, extra) in enumerate(datasets):
        store = data.store(kind, shape, chunk, repeat, channels)
        slug = "-".join(label.replace("³", "").replace("×", "x").replace("(", "").replace(")", "").split())
        result, markdown, plot = (raw / f"{i:02d}-{slug}.{ext}" for ext in ("json", "md", "png"))
        cmd = [BIN / "viewer", "bench", "vdi", "--store", store, "--label", label, "--camera", "30,20,1.5",
               "--width", width, "--height", height, "--timed-frames", frames, "--out", result,
               "--markdown", markdown, "--plot", plot, *extra]
        if args.short:
            cmd += ["--supersegments", "20", "--deviations", "0,10"]
        print(f"[{i + 1}/{len(datasets)}] {label}", flush=True)
        run(cmd)
        json.loads(result.read_text())  # the results file is JSON
        link = plot.relative_to(out).as_posix()
        tables.append(markdown.read_text() + f"\n![{label}: SSIM and frame time against deviation]({link})\n")
    device = json.loads(result.read_text())["device"]
    stamp = datetime.date.today().isoformat()
    mode = " --short" if args.short else ""
    header = (f"Measured {stamp} on {device['adapter']} ({device['backend']}; CPU {device['cpu']}, "
              f"{device['cores']} cores) by `benchmarks/vdi_bench.py{mode}`, {width}×{height} images.")
    report = "\n".join([
        header,
        "",
        "# Volumetric depth images against direct volume rendering",
        "",
        "Each dataset: VDIs generated by `viewer vdi`'s pass from the camera at azimuth 30°, "
        "elevation 20°, 1.5 diagonals (`--camera 30,20,1.5`), then ray cast from cameras turned "
        "about the target by each deviation, against DVR of those cameras. Goals (issue 30): SSIM "
        "≥ 0.97 within 10° and ≥ 0.94 at 30°; VDI frames ≥ 3× faster than DVR within 10°; files at "
        "most half the paper's bytes per pixel (113.8 B/px at 1920×1080, N_S = 20).",
        "",
        *tables,
    ])
    if args.out_dir is None and not args.short:
        path = write_result("vdi-bench.md", report)
    else:
        path = out / "vdi-bench.md"
        path.write_text(report)
    print(f"\nwrote {path} in {time.time() - started:.0f} s\n")
    print(report)
    if args.docs:
        point_page_at("vdi-bench", path, report)


if __name__ == "__main__":
    main()
