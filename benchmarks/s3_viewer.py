"""`viewer render` straight from S3 over a slow link: `viewer` binaries side by side on one
store in s3s-fs on loopback, behind a proxy that holds every request a fixed time (the
latency of a distant object store), for an A/B of two builds.

    .venv/bin/python benchmarks/s3_viewer.py [--bin NAME=PATH ...] [--latency-ms 20] [--rounds 3]

Builds `ingest sample --kind dense` (256³ float32, 64 bricks of 64³ at level 0) into a bucket,
then per round and per binary renders it at 256 × 256 from `s3://bucket/dense.ome.zarr`
through the proxy (support/fault_proxy.py with every request stalled `--latency-ms`), with the
default fetch workers, the builds' order alternating round by round, and each build also from
the store's folder (the floor). Prints per binary the wall time of each round, the requests
the proxy saw, and the most it held at once, and says when two builds' images differ, or a
build's image from S3 and from the folder. Without `--bin`, the release build's viewer alone. s3s-fs
comes from scripts/test.sh.
"""

import filecmp
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "python"))
from support.fault_proxy import FaultProxy  # noqa: E402
sys.path.insert(0, str(ROOT / "benchmarks"))
import s3_ab  # noqa: E402
from support.s3 import env  # noqa: E402


def render(exe, store, out):
    """Seconds for one converged render of `store` (the flags that name it)."""
    t = time.perf_counter()
    done = subprocess.run([exe, "render", "--store", *store, "--width", "256", "--height", "256",
                           "--out", out], env=env(XDG_RUNTIME_DIR="/tmp"), capture_output=True,
                          text=True)
    if done.returncode:
        raise SystemExit(f"{exe} render failed:\n{done.stderr}")
    return time.perf_counter() - t


def main():
    ap = s3_ab.parser(__doc__, "viewer")
    ap.add_argument("--latency-ms", type=float, default=20.0)
    args = ap.parse_args()
    results = {}
    with s3_ab.dense_store_in_s3() as (tmp, endpoint):
        first = None
        for rnd, name, exe in s3_ab.rounds(args, "viewer"):
            with FaultProxy(endpoint, stall_rate=1.0, stall_s=args.latency_ms / 1e3) as proxy:
                seconds = render(exe, ["s3://bucket/dense.ome.zarr", "--s3-endpoint", proxy.url],
                                 tmp / f"{name}.png")
                stats = proxy.stats()
            results.setdefault(name, []).append(
                (seconds, stats["requests"], stats["max_in_flight"]))
            # The floor: the same render from the store's folder, the same image.
            seconds = render(exe, [tmp / "root" / "bucket" / "dense.ome.zarr"], tmp / "folder.png")
            results.setdefault(f"{name} from the folder", []).append((seconds, 0, 0))
            if not filecmp.cmp(tmp / "folder.png", tmp / f"{name}.png", shallow=False):
                print(f"round {rnd}: {name}'s image from S3 differs from the folder's")
            # Each round's images are compared with the round's first build's.
            if first is None or first[0] != rnd:
                first = (rnd, name)
            elif not filecmp.cmp(tmp / f"{first[1]}.png", tmp / f"{name}.png", shallow=False):
                print(f"round {rnd}: {name}'s image differs from {first[1]}'s")
    print(f"latency {args.latency_ms:g} ms per request, {args.rounds} rounds")
    for name, runs in results.items():
        print(f"{name}: median {statistics.median(r[0] for r in runs):.2f} s, rounds "
              f"{[round(r[0], 2) for r in runs]} s" + ("" if name.endswith(" folder") else
              f", requests {[r[1] for r in runs]}, most in flight {[r[2] for r in runs]}"))


if __name__ == "__main__":
    main()
