"""Numerical stress suite, data and pipeline: hostile volumes (f32 with NaN, ±Inf, denormals
and a dynamic range beyond 1e30; constant and all-zero volumes; 1×1×1, 1×N×M, N×1×1 and prime
shapes with chunks larger than the volume or not dividing it; extreme anisotropy; full-range
u16 and i16) go through the real binaries: `ingest convert` → `brickserver serve` → HTTP
(zarr-python, region queries, raw brick batches) → `viewer reference`. Each step must give the
right answer (checked against NumPy brute force) or a clear error, never a panic, a hang or a
silently wrong answer."""

import json
import math
import signal
import struct
import subprocess

import jsonschema
import numpy as np
import pytest
import requests
import tifffile
import zarr
from ome_zarr_models import open_ome_zarr

from support.binaries import run_ingest, start_server
from support.paths import BIN, schema
from support.reference import assert_region_metadata, histogram_bins_of, histogram_edges, window_sums
from support.stores import level_factors, root_attributes
from support.wire import unframe, widen

TIMEOUT = 60


def num(v):
    """A statistic as written in the region metadata or a region answer: a JSON number, one of
    the strings "Infinity", "-Infinity", "NaN", or null (no value)."""
    if v is None:
        return None
    if isinstance(v, str):
        assert v in ("Infinity", "-Infinity", "NaN"), v
    return float(v)


def stop(proc):
    """Stops a server started by `start_server`; it must exit cleanly, without a panic."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
        proc.wait(timeout=10)
    err = proc.stderr.read()
    proc.stdout.close()
    proc.stderr.close()
    assert proc.returncode == 0 and "panicked" not in err, err


# ---------------------------------------------------------------------------------------------
# The volumes. Each is (z, y, x) NumPy data plus the extra `ingest convert` options.


def hostile_f32():
    """NaN, ±Inf, denormals, ±3e38 next to 1e-38, and windows mixing +Inf with -Inf."""
    rng = np.random.default_rng(7)
    v = rng.normal(0, 1, (11, 13, 17)).astype(np.float32)
    v[0, 0, 0] = np.inf
    v[0, 0, 1] = -np.inf  # same 2×2×2 window: the coarser voxel is NaN
    v[3, 5, 7] = np.inf  # alone among finite values: the coarser voxel is +Inf
    v[9, 12, 16] = -np.inf
    v[4, 4, :] = np.float32(3e38)
    v[4, 5, :] = np.float32(-3e38)
    v[5, 4, :] = np.float32(1e-38)
    v[6, 6, 2:9] = np.float32(1e-45)  # smallest denormal
    v[6, 7, 2:9] = -np.float32(3e-42)
    v[2, :, 3] = np.nan
    v[7:9, 0:2, 0:2] = np.nan  # a whole 2×2×2 window of NaN stays NaN
    v[10, 10, 10] = -0.0
    return v


def nan_payloads():
    """Quiet and signalling NaNs with payloads, of both signs, and -0.0: kept bit for bit."""
    bits = np.full((4, 5, 6), np.float32(1.5).view(np.uint32), np.uint32)
    bits[0, 0, :4] = [0x7FC00001, 0xFFC00000, 0x7F800001, 0xFF800123]
    bits[1, :2, :2] = 0xFFFFFFFF  # a whole window of NaN
    bits[2, 3, 4] = 0x80000000  # -0.0
    bits[3, 4, 5] = 0x00000001  # smallest denormal
    return bits.view(np.float32)


def volumes():
    f = hostile_f32()
    u16 = np.random.default_rng(1).integers(0, 65536, (9, 10, 11), dtype=np.uint16)
    u16[0, 0, 0], u16[-1, -1, -1] = 0, 65535
    i16 = np.random.default_rng(2).integers(-32768, 32768, (9, 10, 11), dtype=np.int16)
    i16[0, 0, 0], i16[-1, -1, -1] = -32768, 32767
    i16[4, 4, 4] = -1
    u32 = np.random.default_rng(10).integers(0, 2**32, (5, 6, 7), dtype=np.uint32)
    u32[0, 0, 0], u32[-1, -1, -1] = 0, 2**32 - 1
    i32 = np.random.default_rng(11).integers(-(2**31), 2**31, (5, 6, 7), dtype=np.int32)
    i32[0, 0, 0], i32[-1, -1, -1] = -(2**31), 2**31 - 1
    return {
        "hostile_f32": (f, ["--chunk", "8"]),
        "hostile_f32_chunk5": (f, ["--chunk", "5,3,7"]),
        "hostile_f32_sharded": (f, ["--chunk", "4", "--shard", "8"]),
        "hostile_f32_v04": (f, ["--chunk", "6", "--ome-zarr-version", "0.4"]),
        "nan_payloads": (nan_payloads(), ["--chunk", "2,4,4"]),
        # Three channels (an OME-TIFF): hostile, constant, all zero; each has its own range.
        "channels_mixed": (np.stack([f, np.full(f.shape, 5.0, np.float32), np.zeros(f.shape, np.float32)]), ["--chunk", "8"]),
        "only_pos_inf": (np.where(np.arange(5 * 6 * 7).reshape(5, 6, 7) % 9 == 0, np.inf, 2.5).astype(np.float32), ["--chunk", "4"]),
        "constant_u16": (np.full((7, 13, 31), 1234, np.uint16), ["--chunk", "8"]),
        "constant_f32": (np.full((6, 9, 10), -7.25, np.float32), ["--chunk", "64"]),
        "zero_u8": (np.zeros((12, 10, 9), np.uint8), ["--chunk", "4"]),
        "zero_f32": (np.zeros((5, 5, 5), np.float32), ["--chunk", "2"]),
        "one_voxel_u16": (np.full((1, 1, 1), 65535, np.uint16), []),
        "one_voxel_f32_nan": (np.full((1, 1, 1), np.nan, np.float32), []),
        "plane_1xNxM": (np.random.default_rng(3).integers(0, 255, (1, 19, 23), dtype=np.uint8), ["--chunk", "8"]),
        "line_Nx1x1": (np.arange(37, dtype=np.uint16).reshape(37, 1, 1) * 1000, ["--chunk", "5"]),
        "prime_7x13x31": (np.random.default_rng(4).integers(0, 4000, (7, 13, 31), dtype=np.uint16), ["--chunk", "3,5,11"]),
        "prime_chunk_larger": (np.random.default_rng(5).integers(0, 4000, (7, 13, 31), dtype=np.uint16), ["--chunk", "40"]),
        # Far larger than the volume: clamped to it (it used to overflow or abort on allocation).
        "prime_chunk_huge": (np.random.default_rng(5).integers(0, 4000, (7, 13, 31), dtype=np.uint16), ["--chunk", "4294967296"]),
        "prime_chunk_huge_sharded": (np.random.default_rng(8).integers(0, 4000, (7, 13, 31), dtype=np.uint16), ["--chunk", "65536,3,7", "--shard", "131072,6,14"]),
        "anisotropic_20": (np.random.default_rng(6).integers(0, 4000, (6, 40, 36), dtype=np.uint16), ["--chunk", "4", "--voxel-size", "20,1,1"]),
        "full_u16": (u16, ["--chunk", "4"]),
        "full_i16": (i16, ["--chunk", "4"]),
        "full_u32": (u32, ["--chunk", "4"]),
        "full_i32": (i32, ["--chunk", "4"]),
    }


VOLUMES = volumes()
DTYPES = {np.dtype(t): np.dtype(t).name for t in (np.uint8, np.uint16, np.int16, np.uint32, np.int32, np.float32)}


def convert(tmp_path, name):
    """Writes volume `name` as a raw file and converts it; returns (store, level-0 data as
    (c, z, y, x))."""
    vol, extra = VOLUMES[name]
    store = tmp_path / f"{name}.ome.zarr"
    if vol.ndim == 4:
        src = tmp_path / f"{name}.ome.tif"
        tifffile.imwrite(src, vol, ome=True, photometric="minisblack", metadata={"axes": "CZYX"})
        args = [src]
    else:
        nz, ny, nx = vol.shape
        src = tmp_path / f"{name}.raw"
        vol.astype(vol.dtype.newbyteorder("<")).tofile(src)
        args = [src, "--dims", f"{nx},{ny},{nz}", "--dtype", DTYPES[vol.dtype]]
    p = run_ingest("convert", *args, "-o", store, "--quiet", *extra, timeout=TIMEOUT, check=False)
    assert p.returncode == 0 and "panicked" not in p.stderr, p.stderr
    return store, vol if vol.ndim == 4 else vol[None]


# ---------------------------------------------------------------------------------------------
# Brute-force references.


def exact_window_mean(level0, factor):
    """The exact mean of every window's non-NaN level-0 voxels (c, z, y, x), with the rule
    for infinities: +Inf with -Inf is NaN, otherwise an infinity wins; no value is NaN. Also
    returns, per window, the bound of f64 summation error ((n − 1) · 2^-53 · Σ|v| / n) that
    ingest's documented accuracy allows for floats."""
    with np.errstate(invalid="ignore"):  # signalling NaNs
        d = level0.astype(np.float64)
    valid = ~np.isnan(d)
    finite = np.where(np.isfinite(d), d, 0.0)
    pos = (d == np.inf).astype(np.int64)
    neg = (d == -np.inf).astype(np.int64)
    absum = np.abs(finite)
    count = valid.astype(np.int64)
    # Exact sums of each window's finite values, as Fractions.
    sums = finite.astype(object)
    for axis, f in zip((1, 2, 3), factor):
        sums = _fsum_windows(sums, f, axis)
        pos = window_sums(pos, f, axis)
        neg = window_sums(neg, f, axis)
        absum = window_sums(absum, f, axis)
        count = window_sums(count, f, axis)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.array([float(s) for s in sums.ravel()]).reshape(count.shape) / np.maximum(count, 1)
    mean = np.where((pos > 0) & (neg > 0), np.nan, np.where(pos > 0, np.inf, np.where(neg > 0, -np.inf, mean)))
    mean = np.where(count == 0, np.nan, mean)
    bound = absum * np.maximum(count - 1, 0) * 2.0**-53 / np.maximum(count, 1)
    return mean, bound


def _fsum_windows(a, f, axis):
    """Exact window sums of an object array of Python floats / Fractions along `axis`."""
    from fractions import Fraction

    idx = np.arange(0, a.shape[axis], f)
    parts = []
    for i in idx:
        sl = [slice(None)] * a.ndim
        sl[axis] = slice(i, i + f)
        block = a[tuple(sl)]
        s = np.frompyfunc(lambda x: Fraction(x) if not isinstance(x, Fraction) else x, 1, 1)(block).sum(axis=axis)
        parts.append(np.expand_dims(s, axis))
    return np.concatenate(parts, axis=axis)


def assert_pyramid(store, level0):
    """Integers: every level is the exact window mean rounded half away from zero. Floats:
    bit-identical to the exact mean rounded to f32, except where cancellation in the f64 sum
    allows the documented bound; NaN and infinities follow the rule in docs/ingest.md."""
    g = zarr.open_group(str(store), mode="r")
    for i, f in enumerate(level_factors(store)):
        got = g[str(i)][...]
        mean, bound = exact_window_mean(level0, f)
        assert got.shape == mean.shape, (i, got.shape, mean.shape)
        if np.issubdtype(got.dtype, np.integer):
            want = np.sign(mean) * np.floor(np.abs(mean) + 0.5)
            np.testing.assert_array_equal(got, want.astype(got.dtype), err_msg=f"level {i}")
            continue
        with np.errstate(invalid="ignore", over="ignore"):
            want = mean.astype(np.float32)
            diff = np.abs(got.astype(np.float64) - mean)
        same = (got.view(np.uint32) == want.view(np.uint32)) | (np.isnan(got) & np.isnan(want)) | (got == want)
        close = diff <= bound + np.abs(mean) * 2.0**-24 + 2.0**-149
        ok = same | (np.isfinite(mean) & close)
        assert ok.all(), (i, np.argwhere(~ok)[:5], got[~ok][:5], mean[~ok][:5])


def f32_key(v):
    """ingest's fine histogram key of f32 values (12 bits of the IEEE order)."""
    b = np.asarray(v, np.float32).view(np.uint32).astype(np.uint64)
    k = np.where(b & 0x80000000, ~b & 0xFFFFFFFF, b | 0x80000000)
    return (k >> 20).astype(np.int64)


def f32_lower_edge(key):
    """The smallest value of fine key `key` (ingest's `key_lower_edge`): ±inf past the finite
    keys."""
    if key >= 4096:
        return math.inf
    k = np.uint32(int(key) << 20)
    bits = k & np.uint32(0x7FFFFFFF) if k & np.uint32(0x80000000) else ~k
    v = float(np.array(bits, np.uint32).view(np.float32))
    if math.isnan(v):
        return -math.inf if key < 2048 else math.inf
    return v


def assert_channel_statistics(meta, level0):
    for c, s in enumerate(meta["channels"]):
        with np.errstate(invalid="ignore"):
            d = level0[c].astype(np.float64).ravel()
        valid = d[~np.isnan(d)]
        assert s["voxels"] == d.size and s["nan_voxels"] == d.size - valid.size
        if valid.size == 0:
            assert s["min"] is None and s["max"] is None and s["mean"] is None and s["percentiles"] == []
            continue
        assert num(s["min"]) == valid.min() and num(s["max"]) == valid.max(), (s["min"], s["max"])
        mean, bound = exact_window_mean(level0[c : c + 1], level0.shape[1:])
        mean, bound = mean.item(), bound.item()
        got = num(s["mean"])
        if math.isnan(mean) or math.isinf(mean):
            assert got == mean or (math.isnan(got) and math.isnan(mean)), (got, mean)
        else:
            assert abs(got - mean) <= bound + abs(mean) * 2.0**-52, (got, mean)
        ordered = np.sort(valid)
        for p in s["percentiles"]:
            value = num(p["value"])
            assert valid.min() <= value <= valid.max(), p
            target = p["percent"] / 100 * valid.size
            true = ordered[max(math.ceil(target), 1) - 1]
            if level0.dtype.itemsize <= 2 and level0.dtype.kind in "iu":
                assert value == true, (p, true)
            elif level0.dtype == np.float32:
                # Interpolated inside the fine key holding the true percentile (its closed
                # interval: the value may reach the next key's lower edge).
                k = f32_key(true)
                assert f32_lower_edge(k) <= value <= f32_lower_edge(k + 1), (p, true)
        edges = [num(e) if e is not None else None for e in s["histogram_edges"]]
        lo = -math.inf if edges[0] is None else edges[0]
        hi = math.inf if edges[-1] is None else edges[-1]
        assert lo <= valid.min() and (valid.max() < hi or valid.max() == hi == math.inf), (edges[:2], edges[-2:])


# ---------------------------------------------------------------------------------------------
# HTTP: region queries and raw bricks against brute force.


def boxes(shape_zyx, rng, count):
    nz, ny, nx = shape_zyx
    out = [([0, 0, 0], [nx, ny, nz]), ([nx - 1, ny - 1, nz - 1], [nx, ny, nz])]
    while len(out) < count:
        lo = [int(rng.integers(0, n)) for n in (nx, ny, nz)]
        hi = [int(rng.integers(l + 1, n + 1)) for l, n in zip(lo, (nx, ny, nz))]
        out.append((lo, hi))
    return out


def assert_regions(s, base, name, store):
    meta = root_attributes(store)["residency"]
    g = zarr.open_group(str(store), mode="r")
    validator = jsonschema.Draft202012Validator(schema("region-answer.schema.json"))
    rng = np.random.default_rng(9)
    cell = meta["cell_shape"][::-1]
    brick = meta["brick_shape"][::-1]
    for level, lvl in enumerate(meta["levels"]):
        with np.errstate(invalid="ignore"):  # signalling NaNs
            data = g[lvl["image"]][...].astype(np.float64)
        nz, ny, nx = lvl["shape"]
        for c in range(data.shape[0]):
            for lo, hi in boxes(lvl["shape"], rng, 6):
                r = s.get(f"{base}/{name}/regions", params={"level": level, "channel": c, "min": ",".join(map(str, lo)), "max": ",".join(map(str, hi))}, timeout=TIMEOUT)
                assert r.status_code == 200, r.text
                a = r.json()
                validator.validate(a)
                mlo, mhi = widen(lo, hi, cell, (nx, ny, nz))
                assert a["minmax_box"] == {"min": mlo, "max": mhi}
                region = data[c, mlo[2] : mhi[2], mlo[1] : mhi[1], mlo[0] : mhi[0]]
                if np.isnan(region).all():
                    assert a["min"] is None and a["max"] is None
                else:
                    assert (num(a["min"]), num(a["max"])) == (np.nanmin(region), np.nanmax(region)), (level, lo, hi, a["min"], a["max"])
                hlo, hhi = widen(lo, hi, brick, (nx, ny, nz))
                h = a["histogram"]
                assert h["box"] == {"min": hlo, "max": hhi}
                edges = histogram_edges(h["edges"])
                assert edges.tolist() == histogram_edges(meta["channels"][c]["histogram_edges"]).tolist()
                vox = data[c, hlo[2] : hhi[2], hlo[1] : hhi[1], hlo[0] : hhi[0]].ravel()
                vox = vox[~np.isnan(vox)]
                want = np.zeros(len(edges) - 1, np.int64)
                np.add.at(want, histogram_bins_of(edges, vox), 1)
                assert h["counts"] == want.tolist(), (level, lo, hi)
                assert h["voxels"] == vox.size


def assert_raw_bricks(s, base, name, store):
    meta = root_attributes(store)["residency"]
    g = zarr.open_group(str(store), mode="r")
    bz, by, bx = meta["brick_shape"]
    everything = []
    for level, lvl in enumerate(meta["levels"]):
        grid = [-(-n // b) for n, b in zip(lvl["shape"], meta["brick_shape"])]
        for c in range(len(meta["channels"])):
            everything += [(level, c, z, y, x) for z in range(grid[0]) for y in range(grid[1]) for x in range(grid[2])]
    for start in range(0, len(everything), 200):
        part = everything[start : start + 200]
        q = ";".join(",".join(map(str, b)) for b in part)
        r = s.get(f"{base}/{name}/bricks?b={q}&encoding=raw", timeout=TIMEOUT)
        assert r.status_code == 200, r.text
        header, payload = unframe(r.content, b"RSBRICKS")
        jsonschema.validate(header, schema("brick-batch.schema.json"))
        for (level, c, z, y, x), e in zip(part, header["bricks"]):
            arr = g[meta["levels"][level]["image"]]
            want = np.zeros((bz, by, bx), arr.dtype)
            piece = arr[c, z * bz : (z + 1) * bz, y * by : (y + 1) * by, x * bx : (x + 1) * bx]
            want[: piece.shape[0], : piece.shape[1], : piece.shape[2]] = piece
            if e["status"] == "empty":
                assert not want.view(np.uint8).any(), (level, z, y, x)
            else:
                assert e["status"] == "ok", e
                got = payload[e["offset"] : e["offset"] + e["length"]]
                assert got == want.astype(want.dtype.newbyteorder("<")).tobytes(), (level, z, y, x)


# ---------------------------------------------------------------------------------------------
# `viewer reference` and its OpenEXR output.


def read_exr(path):
    """Reads the OpenEXR files `viewer` writes (the exr crate's defaults: RGB f32, tiled or
    scan lines, uncompressed or RLE) as an (h, w, 3) float32 array."""
    data = path.read_bytes()
    assert data[:4] == b"\x76\x2f\x31\x01", "not an OpenEXR file"
    pos = 8
    attrs = {}
    while data[pos] != 0:
        end = data.index(b"\0", pos)
        name = data[pos:end].decode()
        tend = data.index(b"\0", end + 1)
        size = struct.unpack("<i", data[tend + 1 : tend + 5])[0]
        attrs[name] = data[tend + 5 : tend + 5 + size]
        pos = tend + 5 + size
    pos += 1
    channels = []
    ch = attrs["channels"]
    i = 0
    while ch[i] != 0:
        end = ch.index(b"\0", i)
        channels.append((ch[i:end].decode(), struct.unpack("<i", ch[end + 1 : end + 5])[0]))
        i = end + 17
    assert all(t == 2 for _, t in channels), f"only f32 channels supported: {channels}"
    xmin, ymin, xmax, ymax = struct.unpack("<4i", attrs["dataWindow"])
    w, h = xmax - xmin + 1, ymax - ymin + 1
    compression = attrs["compression"][0]
    assert compression in (0, 1), f"compression {compression} not supported"
    tiled = "tiles" in attrs
    if tiled:
        tw, th = struct.unpack("<2I", attrs["tiles"][:8])
        blocks = math.ceil(w / tw) * math.ceil(h / th)
    else:
        tw, th = w, 1
        blocks = h
    offsets = struct.unpack(f"<{blocks}Q", data[pos : pos + 8 * blocks])
    out = {name: np.zeros((h, w), np.float32) for name, _ in channels}
    for off in offsets:
        if tiled:
            tx, ty, _, _, size = struct.unpack("<5i", data[off : off + 20])
            raw = data[off + 20 : off + 20 + size]
            x0, y0 = tx * tw, ty * th
            bw, bh = min(tw, w - x0), min(th, h - y0)
        else:
            y, size = struct.unpack("<2i", data[off : off + 8])
            raw = data[off + 8 : off + 8 + size]
            x0, y0, bw, bh = 0, y - ymin, w, 1
        expected = bw * bh * 4 * len(channels)
        if compression == 1 and len(raw) < expected:
            raw = rle_decode(raw, expected)
        assert len(raw) == expected
        floats = np.frombuffer(raw, "<f4").reshape(bh, len(channels), bw)
        for k, (name, _) in enumerate(channels):
            out[name][y0 : y0 + bh, x0 : x0 + bw] = floats[:, k, :]
    return np.stack([out["R"], out["G"], out["B"]], axis=-1)


def rle_decode(raw, expected):
    t = bytearray()
    i = 0
    while i < len(raw):
        n = struct.unpack("b", raw[i : i + 1])[0]
        if n < 0:
            t += raw[i + 1 : i + 1 - n]
            i += 1 - n
        else:
            t += raw[i + 1 : i + 2] * (n + 1)
            i += 2
    assert len(t) == expected
    for k in range(1, len(t)):
        t[k] = (t[k - 1] + t[k] - 128) & 0xFF
    half = (len(t) + 1) // 2
    out = bytearray(len(t))
    out[0::2] = t[:half]
    out[1::2] = t[half:]
    return bytes(out)


def render(base, name, tmp_path, *extra):
    out = tmp_path / f"{name}.exr"
    p = subprocess.run(
        [str(BIN / "viewer"), "reference", "--server", base, "--dataset", name, "--width", "32", "--height", "32", "--out", str(out), *map(str, extra)],
        capture_output=True,
        text=True,
        timeout=TIMEOUT,
    )
    assert p.returncode == 0 and "panicked" not in p.stderr, p.stderr
    return read_exr(out)


def ray_lengths(eye, target, up, fov, extent, w, h):
    """Length of each pixel's ray inside the box [0, extent] (the projection of
    schemas/src/scene.rs)."""
    eye, target, up = map(np.asarray, (eye, target, up))
    f = (target - eye) / np.linalg.norm(target - eye)
    r = np.cross(f, up)
    r /= np.linalg.norm(r)
    u = np.cross(r, f)
    tan = math.tan(math.radians(fov) / 2)
    out = np.zeros((h, w))
    for py in range(h):
        for px in range(w):
            nx = (2 * (px + 0.5) / w - 1) * tan * w / h
            ny = (1 - 2 * (py + 0.5) / h) * tan
            d = f + nx * r + ny * u
            d /= np.linalg.norm(d)
            t0, t1 = 0.0, math.inf
            for a in range(3):
                if d[a] == 0:
                    continue
                ta, tb = (0 - eye[a]) / d[a], (extent[a] - eye[a]) / d[a]
                t0, t1 = max(t0, min(ta, tb)), min(t1, max(ta, tb))
            out[py, px] = max(t1 - t0, 0.0)
    return out


# ---------------------------------------------------------------------------------------------
# The pipeline, per volume.


@pytest.mark.parametrize("name", list(VOLUMES))
def test_pipeline(tmp_path, name):
    store, level0 = convert(tmp_path, name)
    g = zarr.open_group(str(store), mode="r")
    # Level 0 bit-identical, -0.0 and NaN payloads included.
    got0 = g["0"][...]
    assert got0.dtype == level0.dtype and got0.tobytes() == level0.tobytes()
    assert_pyramid(store, level0)
    assert_region_metadata(store)
    meta = root_attributes(store)["residency"]
    jsonschema.validate(meta, schema("region-metadata.schema.json"))
    assert_channel_statistics(meta, level0)
    open_ome_zarr(g)
    # Bricks equal to the fill value everywhere are not written, and counted.
    bz, by, bx = meta["brick_shape"]
    for lvl in meta["levels"]:
        data = g[lvl["image"]][...]
        grid = [-(-n // b) for n, b in zip(lvl["shape"], meta["brick_shape"])]
        empty = sum(
            not data[c, z * bz : (z + 1) * bz, y * by : (y + 1) * by, x * bx : (x + 1) * bx].view(np.uint8).any()
            for c in range(data.shape[0])
            for z in range(grid[0])
            for y in range(grid[1])
            for x in range(grid[2])
        )
        assert lvl["bricks_empty"] == empty and lvl["bricks_written"] == data.shape[0] * grid[0] * grid[1] * grid[2] - empty, lvl

    for c, st in enumerate(meta["channels"]):
        if st["min"] is not None and st["min"] == st["max"]:
            # A constant channel: its histogram collapses to a single bin holding every voxel.
            assert len(st["histogram_edges"]) == 2, st["histogram_edges"]
            for lvl in meta["levels"]:
                hist = g[lvl["histogram"]][c]
                assert hist[..., 1:].sum() == 0
    if not level0.view(np.uint8).any():
        # All fill value: no brick of any level is written, and the store holds no chunk.
        assert all(lvl["bricks_written"] == 0 for lvl in meta["levels"])
        assert not any(p.is_file() for p in (store / "0").rglob("*") if p.name not in ("zarr.json", ".zarray", ".zattrs"))
    proc, base = start_server(store)
    try:
        remote = zarr.open_group(f"{base}/{name}/", mode="r")
        for i in range(len(meta["levels"])):
            assert remote[str(i)][...].tobytes() == g[str(i)][...].tobytes()
        with requests.Session() as s:
            assert_regions(s, base, name, store)
            assert_raw_bricks(s, base, name, store)
        img = render(base, name, tmp_path)
        assert np.isfinite(img).all(), f"NaN or Inf pixels: {np.argwhere(~np.isfinite(img))[:5]}"
        assert img.min() >= 0 and img.max() <= 1 + 1e-6, (img.min(), img.max())
    finally:
        stop(proc)


# ---------------------------------------------------------------------------------------------
# Targeted checks.


def test_chunks_larger_than_the_volume_are_clamped_to_it(tmp_path):
    """`--chunk` far beyond the volume (once a u64 overflow or a petabyte allocation) is
    clamped to the volume's extent, and a shard to the bricks covering the volume."""
    store, _ = convert(tmp_path, "prime_chunk_huge")
    meta = root_attributes(store)["residency"]
    assert meta["brick_shape"] == [7, 13, 31] and len(meta["levels"]) == 1
    store, _ = convert(tmp_path, "prime_chunk_huge_sharded")
    meta = root_attributes(store)["residency"]
    assert meta["brick_shape"] == [7, 3, 7]
    shard = json.loads((store / "0" / "zarr.json").read_text())["chunk_grid"]["configuration"]["chunk_shape"]
    assert shard == [1, 7, 6, 14]


def test_a_brick_beyond_blosc_limit_is_a_clear_error(tmp_path):
    """A brick that no Blosc chunk can hold (> 2 GiB) is refused before anything is read or
    written, naming the option; the input is a sparse 8 GiB raw file."""
    raw = tmp_path / "big.raw"
    with open(raw, "wb") as f:
        f.truncate(2048 * 2048 * 512 * 4)
    out = tmp_path / "big.ome.zarr"
    p = run_ingest("convert", raw, "-o", out, "--dims", "2048,2048,512", "--dtype", "float32", "--chunk", "512,1024,1024", "--quiet", check=False, timeout=TIMEOUT)
    assert p.returncode != 0 and "panicked" not in p.stderr
    assert "--chunk [512, 1024, 1024]" in p.stderr and "2 GiB" in p.stderr, p.stderr
    assert not out.exists()


@pytest.mark.parametrize(
    "dims, dtype, header",
    [
        ("4294967296,4294967296,1", "uint8", "0"),  # wrapped to 0 bytes: matched an empty file
        ("4294967296,4294967296,4294967296", "float32", "0"),
        ("5,5,1", "float32", "18446744073709551615"),
    ],
)
def test_raw_layouts_beyond_2_64_bytes_are_clear_errors(tmp_path, dims, dtype, header):
    """The expected raw size is computed without wrapping (it used to wrap, so an empty file
    matched 2^64 bytes of dims and the run aborted allocating them)."""
    raw = tmp_path / "tiny.raw"
    raw.write_bytes(b"")
    out = tmp_path / "o.ome.zarr"
    p = run_ingest("convert", raw, "-o", out, "--dims", dims, "--dtype", dtype, "--header-bytes", header, "--quiet", check=False, timeout=TIMEOUT)
    assert p.returncode == 1 and "panicked" not in p.stderr and "memory allocation" not in p.stderr, p.stderr
    assert f"tiny.raw: --dims {dims} of {dtype} with a {header}-byte header is more than 2^64 bytes" in p.stderr, p.stderr
    assert not out.exists()


def planned_factors(shape, voxel, brick):
    """The pyramid rule of docs/ingest.md: halve an axis (longer than 1) while its spacing is within √2
    of the finest spacing among such axes; stop when a level fits in one brick."""
    shape, voxel, factors = list(shape), list(voxel), [(1, 1, 1)]
    while any(s > b for s, b in zip(shape, brick)):
        finest = min(v for v, s in zip(voxel, shape) if s > 1)
        step = [2 if s > 1 and v <= finest * math.sqrt(2) * (1 + 1e-9) else 1 for s, v in zip(shape, voxel)]
        shape = [-(-s // k) for s, k in zip(shape, step)]
        voxel = [v * k for v, k in zip(voxel, step)]
        factors.append(tuple(f * k for f, k in zip(factors[-1], step)))
    return factors


def test_extreme_anisotropy_halves_only_y_and_x_until_they_catch_up(tmp_path):
    store, level0 = convert(tmp_path, "anisotropic_20")
    factors = level_factors(store)
    assert factors == planned_factors(level0.shape[1:], (20, 1, 1), (4, 4, 4))
    assert factors[:5] == [(1, 1, 1), (1, 2, 2), (1, 4, 4), (1, 8, 8), (1, 16, 16)]
    meta = root_attributes(store)["residency"]
    assert [tuple(l["factor"]) for l in meta["levels"]] == factors
    ms = json.loads((store / "zarr.json").read_text())["attributes"]["ome"]["multiscales"][0]
    assert ms["datasets"][1]["coordinateTransformations"][0]["scale"] == [1.0, 20.0, 2.0, 2.0]


def ray_image(extent, camera, w, h):
    """Ray lengths of a LookAt camera `(eye, target)` with the CLI's default up (−y) and fov."""
    eye, target = camera
    return ray_lengths(eye, target, (0.0, -1.0, 0.0), 30.0, extent, w, h)


@pytest.mark.parametrize(
    "name, opacity",
    [
        # Constant 1234 under a ramp 0 → 0.5 over [0, 2000]: opacity 0.5 · 1234 / 2000.
        ("constant_u16", 0.5 * 1234 / 2000),
        ("one_voxel_u16", 0.5),
        # Below the ramp, and all-zero volumes (every brick empty): only the background.
        ("constant_f32", 0.0),
        ("zero_u8", 0.0),
        ("zero_f32", 0.0),
    ],
)
def test_constant_and_empty_volumes_render_the_exact_compositing_rule(tmp_path, name, opacity):
    """The rule of schemas/src/scene.rs for a homogeneous medium: with opacity `a` per
    reference step Δ₀ (one voxel here), a ray crossing length L gets T = (1 − a)^(L/Δ₀)
    whatever the step, and the pixel is colour·(1 − T) + T·background."""
    store, level0 = convert(tmp_path, name)
    nz, ny, nx = level0.shape[1:]
    extent = (nx, ny, nz)
    eye = (nx * 0.3 - 2.0 * max(extent), ny * 0.4 - 1.5 * max(extent), -2.5 * max(extent))
    target = (nx / 2, ny / 2, nz / 2)
    colour, background = np.array([1.0, 0.5, 0.25]), np.array([0.1, 0.2, 0.3])
    proc, base = start_server(store)
    try:
        img = render(
            base, name, tmp_path,
            "--camera", f"{','.join(map(str, eye))}:{','.join(map(str, target))}",
            "--tf", "0:0:2000:0.5" if level0.dtype != np.float32 else "0:0:1:0.5",
            "--color", "0:1,0.5,0.25",
            "--background", "0.1,0.2,0.3",
        )
    finally:
        stop(proc)
    lengths = ray_image(extent, (eye, target), 32, 32)
    assert (lengths > 0).sum() > 20, "the camera must see the volume"
    t = (1 - opacity) ** lengths
    want = colour * (1 - t)[..., None] + t[..., None] * background
    np.testing.assert_allclose(img, want, rtol=0, atol=2e-6)


def test_infinities_under_an_opaque_transfer_function_render_finite(tmp_path):
    """Samples of +Inf (opaque), -Inf (transparent), +Inf next to -Inf (NaN, transparent) and
    NaN: the image stays finite and within [0, 1], and differs from the empty background."""
    store, _ = convert(tmp_path, "hostile_f32")
    proc, base = start_server(store)
    try:
        for extra in (["--tf", "0:0:1:0.5"], ["--tf", "0:-1=0,1e38=1"], ["--camera", "0,0,1"], []):
            img = render(base, "hostile_f32", tmp_path, *extra)
            assert np.isfinite(img).all() and img.min() >= 0 and img.max() <= 1 + 1e-6, extra
        assert img.max() > 0
    finally:
        stop(proc)


def test_renders_are_invariant_to_the_scale_of_the_voxels(tmp_path):
    """The same volume with voxels of 1, 1e300 and 1e-300 (isotropic) gives the same image: the
    default camera orbits at volume diagonals and opacity is per voxel. (At 1e±300 the diagonal
    once overflowed or underflowed, and `viewer reference` then looped forever.)"""
    vol = np.random.default_rng(12).integers(0, 4000, (6, 9, 10), dtype=np.uint16)
    images = []
    for size in ("1,1,1", "1e300,1e300,1e300", "1e-300,1e-300,1e-300"):
        VOLUMES["scaled"] = (vol, ["--voxel-size", size])
        try:
            store, _ = convert(tmp_path, "scaled")
        finally:
            del VOLUMES["scaled"]
        proc, base = start_server(store)
        try:
            images.append(render(base, "scaled", tmp_path))
        finally:
            stop(proc)
        (tmp_path / "scaled.raw").unlink()
        import shutil

        shutil.rmtree(store)
    assert images[0].max() > 0.01
    for img in images[1:]:
        assert np.isfinite(img).all()
        np.testing.assert_allclose(img, images[0], rtol=0, atol=1e-5)


def test_renders_that_cannot_finish_or_have_no_view_are_clear_errors(tmp_path):
    """z voxels 10⁶ times the x spacing, stepped at a quarter of x: a ray along z would need
    24 million steps, refused upfront naming --step (it used to run for hours); a camera whose
    eye is its target has no view."""
    vol = np.ones((6, 9, 10), np.uint16)
    VOLUMES["needle"] = (vol, ["--voxel-size", "1e6,1,1"])
    try:
        store, _ = convert(tmp_path, "needle")
    finally:
        del VOLUMES["needle"]
    proc, base = start_server(store)
    try:
        for extra, message in [
            (["--camera", "5,4.5,-10:5,4.5,3000000", "--fov", "1e-5"], "use a larger --step"),
            (["--step", "1e6", "--camera", "5,5,5:5,5,5"], "do not define a view"),
        ]:
            out = tmp_path / "x.exr"
            p = subprocess.run(
                [str(BIN / "viewer"), "reference", "--server", base, "--dataset", "needle", "--width", "8", "--height", "8", "--out", str(out), *extra],
                capture_output=True,
                text=True,
                timeout=TIMEOUT,
            )
            assert p.returncode != 0 and "panicked" not in p.stderr and message in p.stderr, p.stderr
            assert not out.exists()
        # A step of 10⁵ x spacings (a tenth of a z voxel) renders.
        img = render(base, "needle", tmp_path, "--step", "1e5", "--camera", "5,4.5,-10:5,4.5,3000000", "--fov", "1e-5")
        assert img.max() > 0.01, "the rays cross the needle"
        assert np.isfinite(img).all()
    finally:
        stop(proc)


def test_index_recomputes_the_same_metadata_for_hostile_floats(tmp_path):
    """`ingest index` on the store stripped of its region metadata writes the same document and
    the same arrays as `convert` (infinities, NaN and denormals included)."""
    import shutil

    store, _ = convert(tmp_path, "hostile_f32")
    copy = tmp_path / "copy.ome.zarr"
    shutil.copytree(store, copy)
    shutil.rmtree(copy / "residency")
    doc = json.loads((copy / "zarr.json").read_text())
    del doc["attributes"]["residency"]
    (copy / "zarr.json").write_text(json.dumps(doc))
    p = run_ingest("index", copy, check=False, timeout=TIMEOUT)
    assert p.returncode == 0 and "panicked" not in p.stderr, p.stderr
    assert root_attributes(copy)["residency"] == root_attributes(store)["residency"]
    for f in (store / "residency").rglob("*"):
        if f.is_file() and f.name != "zarr.json":
            assert (copy / f.relative_to(store)).read_bytes() == f.read_bytes(), f
    p = run_ingest("inspect", copy, timeout=TIMEOUT)
    assert "min -inf max inf mean NaN" in p.stdout, p.stdout


def test_viewer_errors_name_the_dataset(tmp_path):
    store, _ = convert(tmp_path, "one_voxel_f32_nan")
    proc, base = start_server(store)
    try:
        out = tmp_path / "x.exr"
        p = subprocess.run([str(BIN / "viewer"), "reference", "--server", base, "--dataset", "nosuch", "--out", str(out)], capture_output=True, text=True, timeout=TIMEOUT)
        assert p.returncode != 0 and "panicked" not in p.stderr and "nosuch" in p.stderr, p.stderr
        # An all-NaN volume renders as background only.
        img = render(base, "one_voxel_f32_nan", tmp_path, "--tf", "0:0:1:1", "--background", "0.5,0.5,0.5")
        assert (img == np.float32(0.5)).all()
    finally:
        stop(proc)


def test_big_endian_and_promoted_inputs_keep_every_value(tmp_path):
    """Full-range i16 read big-endian, and full-range u16 beside hostile f32 (promoted to f32,
    where every u16 is exact): level 0 bit for bit, statistics exact per channel."""
    i16 = VOLUMES["full_i16"][0]
    raw = tmp_path / "be.raw"
    i16.astype(">i2").tofile(raw)
    store = tmp_path / "be.ome.zarr"
    nz, ny, nx = i16.shape
    run_ingest("convert", raw, "-o", store, "--dims", f"{nx},{ny},{nz}", "--dtype", "int16", "--endian", "big", "--quiet", timeout=TIMEOUT)
    assert zarr.open_group(str(store), mode="r")["0"][0].tobytes() == i16.astype("<i2").tobytes()
    assert_channel_statistics(root_attributes(store)["residency"], i16[None])

    u16 = np.zeros((11, 13, 17), np.uint16)
    u16[...] = np.random.default_rng(13).integers(0, 65536, u16.shape)
    u16[0, 0, 0], u16[1, 1, 1] = 0, 65535
    f = hostile_f32()
    a, b = tmp_path / "u16.tif", tmp_path / "f32.tif"
    tifffile.imwrite(a, u16, photometric="minisblack")
    tifffile.imwrite(b, f, photometric="minisblack")
    store = tmp_path / "mixed.ome.zarr"
    run_ingest("convert", a, b, "-o", store, "--chunk", "8", "--quiet", timeout=TIMEOUT)
    level0 = np.stack([u16.astype(np.float32), f])
    got = zarr.open_group(str(store), mode="r")["0"][...]
    assert got.dtype == np.float32 and got.tobytes() == level0.tobytes()
    assert_pyramid(store, level0)
    assert_region_metadata(store)
    meta = root_attributes(store)["residency"]
    assert_channel_statistics(meta, level0)
    assert (num(meta["channels"][0]["min"]), num(meta["channels"][0]["max"])) == (0.0, 65535.0)
