"""Batched bricks read from S3: `brickserver` binaries side by side on one store in s3s-fs on
loopback (the object-store tests' S3 server), for an A/B of two builds.

    .venv/bin/python benchmarks/s3_batches.py [--bin NAME=PATH ...] [--rounds 3]

Builds `ingest sample --kind dense` (256³ float32, 64 bricks of 64³ at level 0) into a bucket,
then per round and per binary: starts `brickserver serve s3://bucket/dense.ome.zarr
--cache-bytes 0` (every brick from the store), and asks 24 batches of 16 random level-0
bricks, stored and raw, from 1 and from 4 clients at once. Prints per binary the median batch
latency and the bricks per second of each round, and the server's thread count after the
load. Without `--bin`, the release build's brickserver alone. s3s-fs comes from
scripts/test.sh.
"""

import concurrent.futures
import random
import statistics
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "python"))
sys.path.insert(0, str(ROOT / "benchmarks"))
import s3_ab  # noqa: E402
from support.s3 import env, free_port  # noqa: E402

BRICKS = [f"0,0,{z},{y},{x}" for z in range(4) for y in range(4) for x in range(4)]


def serve(exe, endpoint):
    """Starts brickserver `exe` on the bucket's store; returns (process, base URL)."""
    port = free_port()
    p = subprocess.Popen([exe, "serve", "s3://bucket/dense.ome.zarr", "--s3-endpoint", endpoint,
                          "--cache-bytes", "0", "--bind", f"127.0.0.1:{port}"],
                         env=env(), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    base = f"http://127.0.0.1:{port}"
    for _ in range(300):
        try:
            urllib.request.urlopen(base + "/healthz", timeout=1).read()
            return p, base
        except OSError:
            time.sleep(0.1)
    raise SystemExit(f"{exe} did not answer /healthz within 30 s")


def batch(base, encoding, rng):
    """Seconds for one batch of 16 random bricks."""
    pick = rng.sample(BRICKS, 16)
    t = time.perf_counter()
    urllib.request.urlopen(f"{base}/dense/bricks?b={';'.join(pick)}&encoding={encoding}",
                           timeout=120).read()
    return time.perf_counter() - t


def threads(pid):
    """The process's thread count."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("Threads:"):
            return int(line.split()[1])
    return 0


def main():
    args = s3_ab.parser(__doc__, "brickserver").parse_args()
    results = {}
    with s3_ab.dense_store_in_s3() as (_, endpoint):
        for rnd, name, exe in s3_ab.rounds(args, "brickserver"):
            p, base = serve(exe, endpoint)
            try:
                rng = random.Random(rnd)
                batch(base, "stored", rng)  # loads the image arrays
                for encoding in ["stored", "raw"]:
                    for clients in [1, 4]:
                        t0 = time.perf_counter()
                        with concurrent.futures.ThreadPoolExecutor(clients) as pool:
                            lat = list(pool.map(lambda _: batch(base, encoding, rng), range(24)))
                        rate = 24 * 16 / (time.perf_counter() - t0)
                        results.setdefault((name, encoding, clients), []).append(
                            (statistics.median(lat), rate))
                results.setdefault((name, "threads"), []).append(threads(p.pid))
            finally:
                p.terminate()
                p.wait()
    for key, values in results.items():
        if key[1] == "threads":
            print(f"{key[0]}: threads after the load {values}")
        else:
            name, encoding, clients = key
            print(f"{name}: {encoding}, {clients} client(s): median batch "
                  f"{[round(a * 1e3, 1) for a, _ in values]} ms, bricks/s {[round(b) for _, b in values]}")


if __name__ == "__main__":
    main()
