"""Limit probes for an `ingest convert` run: how fast this machine does each part of the same
conversion on its own, on all cores, so that ingest's time can be read as a fraction of what
the hardware allows.

    .venv/bin/python benchmarks/ingest_limits.py INPUT.ome.tif STORE.ome.zarr [--ingest-seconds S]

STORE is ingest's output of INPUT (its chunk files give the sizes and count to write). The
probes, each timed alone, the input already in the page cache:
- read: the input file read into memory (large reads);
- encode: level 0 cut into the store's chunks and compressed with the store's codec
  (blosc-lz4, clevel 5, byte shuffle), one chunk per task on every core;
- write: the store's chunk files (every level, their stored bytes) written to a new folder on
  every core, then the file system synced (`syncfs`), as ingest syncs its store before it
  renames it into place: the time for the bytes to reach the disk, not only the page cache
  (the result also gives the time before the sync, `write_unsynced`);
- pyramid: the mean-of-2×2×2 levels computed from level 0 (numpy, z-slabs on every core).
A perfectly overlapped pipeline takes as long as its slowest part: that is the limit, and
ingest's fraction of it is limit / ingest's wall time. `ingest_bench.py` runs these beside each
conversion.
"""

import argparse
import concurrent.futures
import ctypes
import json
import os
import pathlib
import shutil
import tempfile
import time

import numcodecs
import numpy as np
import tifffile

CORES = os.cpu_count() or 1


def best_of(fn, rounds=3):
    """The shortest of `rounds` timed calls of `fn`, in seconds."""
    times = []
    for _ in range(rounds):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


def probe_read(path: pathlib.Path) -> float:
    """Seconds to read `path` into memory, from the page cache."""
    size = path.stat().st_size
    buf = bytearray(size)
    view = memoryview(buf)

    def read():
        with open(path, "rb", buffering=0) as f:
            done = 0
            while done < size:
                n = f.readinto(view[done : done + (64 << 20)])
                if not n:
                    break
                done += n

    read()  # into the page cache
    return best_of(read)


def chunks_of(volume: np.ndarray, edge: int):
    """The `edge`³ chunks of `volume` (z, y, x), as contiguous arrays."""
    z, y, x = volume.shape
    return [
        np.ascontiguousarray(volume[k : k + edge, j : j + edge, i : i + edge])
        for k in range(0, z, edge)
        for j in range(0, y, edge)
        for i in range(0, x, edge)
    ]


def probe_encode(volume: np.ndarray, edge: int) -> float:
    """Seconds to compress level 0's chunks with blosc-lz4 (clevel 5, shuffle) on every core."""
    numcodecs.blosc.use_threads = False
    codec = numcodecs.Blosc(cname="lz4", clevel=5, shuffle=numcodecs.Blosc.SHUFFLE)
    chunks = chunks_of(volume, edge)
    with concurrent.futures.ThreadPoolExecutor(CORES) as pool:
        return best_of(lambda: list(pool.map(codec.encode, chunks)))


def sync_file_system(path: pathlib.Path) -> None:
    """Flushes the file system holding `path` to disk (Linux `syncfs`; `sync` elsewhere)."""
    syncfs = getattr(ctypes.CDLL(None, use_errno=True), "syncfs", None)
    if syncfs is None:
        os.sync()
        return
    fd = os.open(path, os.O_RDONLY)
    try:
        if syncfs(fd) != 0:
            raise OSError(ctypes.get_errno(), f"syncfs of {path} failed")
    finally:
        os.close(fd)


def probe_write(store: pathlib.Path, keep: pathlib.Path | None = None) -> tuple[float, float]:
    """Seconds to write the store's chunk files (their stored bytes) anew on every core, then
    sync the file system; and the seconds before the sync. The copies are left in the folder
    `keep` when one is given (see `ingest_bench.py`: deleting files just before making others
    slows ext4 without a journal), else removed."""
    files = [p for p in store.rglob("*") if p.is_file() and not p.name.endswith(".json")]
    blobs = [(p.relative_to(store), p.read_bytes()) for p in files]
    folders = sorted({rel.parent for rel, _ in blobs})

    def write_all(out):
        for d in folders:
            (out / d).mkdir(parents=True, exist_ok=True)

        def write(item):
            rel, data = item
            with open(out / rel, "wb") as f:
                f.write(data)

        with concurrent.futures.ThreadPoolExecutor(CORES) as pool:
            list(pool.map(write, blobs))

    times = []
    for _ in range(3):
        out = pathlib.Path(tempfile.mkdtemp(prefix="write-probe-", dir=keep or store.parent))
        os.sync()
        t = time.perf_counter()
        write_all(out)
        written = time.perf_counter() - t
        sync_file_system(out)
        times.append((time.perf_counter() - t, written))
        if keep is None:
            shutil.rmtree(out)
    return min(times)


def half(level: np.ndarray) -> np.ndarray:
    """The mean of each 2×2×2 block (an odd edge keeps its last plane, row or column)."""
    z, y, x = (s - s % 2 for s in level.shape)
    v = level[:z, :y, :x].astype(np.uint32)
    s = v[0::2] + v[1::2]
    s = s[:, 0::2] + s[:, 1::2]
    s = s[:, :, 0::2] + s[:, :, 1::2]
    return ((s + 4) // 8).astype(level.dtype)


def probe_pyramid(volume: np.ndarray, levels: int) -> float:
    """Seconds to compute levels 1.. from level 0 (z-slabs of 16 planes on every core)."""

    def pyramid():
        level = volume
        with concurrent.futures.ThreadPoolExecutor(CORES) as pool:
            for _ in range(1, levels):
                slabs = [level[k : k + 16] for k in range(0, level.shape[0] - level.shape[0] % 2, 16)]
                parts = list(pool.map(half, slabs))
                level = np.concatenate(parts) if parts else level[:0]
                if min(level.shape) < 2:
                    break

    return best_of(pyramid)


def limits(src: pathlib.Path, store: pathlib.Path, keep: pathlib.Path | None = None) -> dict:
    """Every probe's seconds for the conversion of `src` into `store`, and the limit (the
    write probe's copies left in `keep`, when given)."""
    meta = json.loads((store / "zarr.json").read_text())
    levels = len(meta["attributes"]["ome"]["multiscales"][0]["datasets"])
    array = json.loads((store / "0" / "zarr.json").read_text())
    chunk = array["chunk_grid"]["configuration"]["chunk_shape"]
    edge = chunk[-1]
    volume = tifffile.imread(src)
    volume = volume.reshape(volume.shape[-3:]) if volume.ndim > 3 else volume
    probes = {"read": probe_read(src), "encode": probe_encode(volume, edge)}
    probes["write"], write_unsynced = probe_write(store, keep)
    probes["pyramid"] = probe_pyramid(volume, levels)
    slowest = max(probes, key=probes.get)
    return {"cores": CORES, "probes": probes, "limit": probes[slowest], "slowest": slowest,
            "serial": sum(probes.values()), "write_unsynced": write_unsynced}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("input", type=pathlib.Path)
    ap.add_argument("store", type=pathlib.Path)
    ap.add_argument("--ingest-seconds", type=float, help="ingest's wall time, for its fraction of the limit")
    a = ap.parse_args()
    result = limits(a.input, a.store)
    if a.ingest_seconds:
        result["fraction_of_limit"] = result["limit"] / a.ingest_seconds
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
