"""`brickserver`'s own API with real clients: region queries against a brute-force NumPy
computation over the data zarr-python decodes, the binary min/max hierarchy against the stored
grids, batched bricks against individually fetched ones, the OpenAPI document and JSON Schemas
against real responses, and the limits and faults (timeouts, connection limit, batch caps,
bounded cache, unreadable and corrupt chunks)."""

import shutil
import socket
import subprocess
import time

import jsonschema
import numpy as np
import pytest
import requests
import tifffile
import zarr
from openapi_spec_validator import validate as validate_openapi

from support.binaries import run_ingest, start_server, stop_server
from support.paths import BIN, schema
from support.stores import root_attributes
from support.wire import metric, unframe, widen


@pytest.fixture(scope="module")
def stores(tmp_path_factory):
    """Two stores made by `ingest`: `u16` (2 channels, 8³ bricks, empty bricks, odd sizes,
    anisotropic pyramid) and `f32` (float with NaN, sharded, 0.5); served together."""
    d = tmp_path_factory.mktemp("api")
    rng = np.random.default_rng(11)
    vol = np.zeros((2, 21, 37, 30), np.uint16)
    vol[:, 3:17, 5:33, 2:27] = rng.integers(1, 60000, (2, 14, 28, 25))
    src = d / "u16.ome.tif"
    tifffile.imwrite(src, vol, ome=True, photometric="minisblack", metadata={"axes": "CZYX", "PhysicalSizeZ": 3.0, "PhysicalSizeY": 1.0, "PhysicalSizeX": 1.0})
    u16 = d / "u16.ome.zarr"
    run_ingest("convert", src, "-o", u16, "--chunk", "8", "--quiet")
    f = rng.normal(0, 1e3, (19, 26, 33)).astype(np.float32)
    f[rng.random(f.shape) < 0.05] = np.nan
    f[:, :, :5] = np.nan
    fsrc = d / "f32.tif"
    tifffile.imwrite(fsrc, f, photometric="minisblack")
    f32 = d / "f32.ome.zarr"
    run_ingest("convert", fsrc, "-o", f32, "--chunk", "8", "--shard", "16", "--quiet")
    proc, base = start_server(u16, f32)
    yield base, {"u16": u16, "f32": f32}
    stop_server(proc)


def boxes(shape_zyx, rng, count):
    nz, ny, nx = shape_zyx
    out = [([0, 0, 0], [nx, ny, nz]), ([0, 0, 0], [min(8, nx), min(8, ny), min(8, nz)])]
    while len(out) < count:
        lo = [int(rng.integers(0, n)) for n in (nx, ny, nz)]
        hi = [int(rng.integers(l + 1, n + 1)) for l, n in zip(lo, (nx, ny, nz))]
        out.append((lo, hi))
    return out


@pytest.mark.parametrize("name", ["u16", "f32"])
def test_region_answers_equal_brute_force(stores, name):
    base, paths = stores
    store = paths[name]
    meta = root_attributes(store)["residency"]
    g = zarr.open_group(str(store), mode="r")
    validator = jsonschema.Draft202012Validator(schema("region-answer.schema.json"))
    rng = np.random.default_rng(5)
    cell = meta["cell_shape"][::-1]
    brick = meta["brick_shape"][::-1]
    with requests.Session() as s:
        for level, lvl in enumerate(meta["levels"]):
            data = g[lvl["image"]][...].astype(np.float64)
            nz, ny, nx = lvl["shape"]
            for c in range(data.shape[0]):
                edges = np.array([np.inf if e is None else e for e in meta["channels"][c]["histogram_edges"]])
                edges[0] = -np.inf if meta["channels"][c]["histogram_edges"][0] is None else edges[0]
                for lo, hi in boxes(lvl["shape"], rng, 12):
                    r = s.get(f"{base}/{name}/regions", params={"level": level, "channel": c, "min": ",".join(map(str, lo)), "max": ",".join(map(str, hi))})
                    assert r.status_code == 200, r.text
                    a = r.json()
                    validator.validate(a)
                    assert a["box"] == {"min": lo, "max": hi}
                    # min/max: over the box widened to whole cells.
                    mlo, mhi = widen(lo, hi, cell, (nx, ny, nz))
                    assert a["minmax_box"] == {"min": mlo, "max": mhi}, (lo, hi)
                    region = data[c, mlo[2] : mhi[2], mlo[1] : mhi[1], mlo[0] : mhi[0]]
                    if np.isnan(region).all():
                        assert a["min"] is None and a["max"] is None
                    else:
                        assert (a["min"], a["max"]) == (np.nanmin(region), np.nanmax(region))
                    truth = data[c, lo[2] : hi[2], lo[1] : hi[1], lo[0] : hi[0]]
                    if not np.isnan(truth).all():
                        assert a["min"] <= np.nanmin(truth) and a["max"] >= np.nanmax(truth)
                    assert a["minmax_exact"] == ([mlo, mhi] == [lo, hi])
                    # Histogram: over the box widened to whole bricks.
                    hlo, hhi = widen(lo, hi, brick, (nx, ny, nz))
                    h = a["histogram"]
                    assert h["box"] == {"min": hlo, "max": hhi}
                    vox = data[c, hlo[2] : hhi[2], hlo[1] : hhi[1], hlo[0] : hhi[0]].ravel()
                    vox = vox[~np.isnan(vox)]
                    want = np.zeros(len(edges) - 1, np.int64)
                    np.add.at(want, np.searchsorted(edges, vox, side="right") - 1, 1)
                    assert h["counts"] == want.tolist()
                    assert h["voxels"] == vox.size
                    assert h["exact"] == ([hlo, hhi] == [lo, hi])


def test_region_answers_need_no_brick(stores, tmp_path):
    """The server answers region queries from the region metadata alone: a copy of the store
    without any image chunk (every level's bricks deleted) gives every answer the whole
    store gives, byte for byte."""
    base, paths = stores
    bare = tmp_path / "u16.ome.zarr"
    shutil.copytree(paths["u16"], bare)
    meta = root_attributes(bare)["residency"]
    for level in meta["levels"]:
        chunks = bare / level["image"] / "c"
        assert chunks.is_dir(), chunks
        shutil.rmtree(chunks)
    proc, bare_base = start_server(bare)
    try:
        rng = np.random.default_rng(11)
        asked = 0
        with requests.Session() as s:
            for level, lvl in enumerate(meta["levels"]):
                for c in range(len(meta["channels"])):
                    for lo, hi in boxes(lvl["shape"], rng, 4):
                        params = {"level": level, "channel": c, "min": ",".join(map(str, lo)),
                                  "max": ",".join(map(str, hi))}
                        whole = s.get(f"{base}/u16/regions", params=params, timeout=30)
                        without = s.get(f"{bare_base}/u16/regions", params=params, timeout=30)
                        assert whole.status_code == without.status_code == 200, without.text
                        assert without.content == whole.content, params
                        asked += 1
        assert asked >= 8
        # The bricks are gone indeed: a brick of level 0 the whole store serves.
        key = next(f for f in sorted((paths["u16"] / "0" / "c").rglob("*")) if f.is_file())
        key = key.relative_to(paths["u16"]).as_posix()
        assert requests.get(f"{base}/u16/{key}", timeout=30).status_code == 200, key
        assert requests.get(f"{bare_base}/u16/{key}", timeout=30).status_code == 404, key
    finally:
        stop_server(proc)


def test_aligned_boxes_are_exact(stores):
    base, paths = stores
    data = zarr.open_group(str(paths["u16"]), mode="r")["0"][...]
    r = requests.get(f"{base}/u16/regions", params={"level": 0, "channel": 1, "min": "8,8,0", "max": "24,16,8"}).json()
    box = data[1, 0:8, 8:16, 8:24]
    assert r["minmax_exact"] and r["histogram"]["exact"]
    assert (r["min"], r["max"]) == (box.min(), box.max())
    assert r["histogram"]["voxels"] == box.size


@pytest.mark.parametrize(
    "params, message",
    [
        ({"level": 9, "channel": 0, "min": "0,0,0", "max": "1,1,1"}, "level 9 does not exist (the dataset has"),
        ({"level": 0, "channel": 2, "min": "0,0,0", "max": "1,1,1"}, "channel 2 does not exist (the dataset has 2)"),
        ({"level": 0, "channel": 0, "min": "0,0,0", "max": "31,1,1"}, "box max [31, 1, 1] lies outside level 0 (x, y, z size [30, 37, 21])"),
        ({"level": 0, "channel": 0, "min": "5,0,0", "max": "5,1,1"}, "empty box"),
        ({"level": 0, "channel": 0, "min": "0,0", "max": "1,1,1"}, "min '0,0' is not three integers x,y,z"),
        ({"level": "x", "channel": 0, "min": "0,0,0", "max": "1,1,1"}, "expected level=L&channel=C&min=x,y,z&max=x,y,z"),
    ],
)
def test_bad_region_queries_are_clear_400s(stores, params, message):
    base, _ = stores
    r = requests.get(f"{base}/u16/regions", params=params)
    assert r.status_code == 400
    jsonschema.validate(r.json(), schema("api-error.schema.json"))
    assert message in r.json()["error"]


def test_region_api_without_metadata_or_dataset_is_404(tmp_path):
    plain = tmp_path / "plain.zarr"
    z = zarr.create_array(str(plain), shape=(4, 4), dtype="uint8", chunks=(2, 2))
    z[...] = 1
    proc, base = start_server(plain)
    try:
        r = requests.get(f"{base}/plain/regions", params={"level": 0, "channel": 0, "min": "0,0,0", "max": "1,1,1"})
        assert r.status_code == 404 and "has no region metadata" in r.json()["error"]
        assert requests.get(f"{base}/plain/minmax?channel=0").status_code == 404
        r = requests.get(f"{base}/nope/regions", params={"level": 0, "channel": 0, "min": "0,0,0", "max": "1,1,1"})
        assert r.status_code == 404 and r.json() == {"error": "no dataset 'nope'"}
    finally:
        stop_server(proc)


@pytest.mark.parametrize("name", ["u16", "f32"])
def test_minmax_hierarchy_equals_the_stored_grids(stores, name):
    base, paths = stores
    store = paths[name]
    meta = root_attributes(store)["residency"]
    g = zarr.open_group(str(store), mode="r")
    for c in range(len(meta["channels"])):
        r = requests.get(f"{base}/{name}/minmax", params={"channel": c})
        assert r.headers["Content-Type"] == "application/x-residency-minmax"
        header, payload = unframe(r.content, b"RSMINMAX")
        jsonschema.validate(header, schema("minmax-hierarchy.schema.json"))
        assert header["channel"] == c and header["halo"] == meta["halo"]
        dtype = np.dtype(header["data_type"]).newbyteorder("<")
        assert [lv["shape"] for lv in header["levels"]] == [lv["shape"] for lv in meta["levels"]]
        for lv, stored in zip(header["levels"], meta["levels"]):
            assert len(lv["grids"]) == len(stored["minmax"])
            for block, grid in zip(lv["grids"], stored["minmax"]):
                assert block["grid_shape"] == grid["grid_shape"] and block["cell_shape"] == grid["cell_shape"]
                values = np.frombuffer(payload[block["offset"] : block["offset"] + block["length"]], dtype)
                want = g[grid["path"]][c]
                np.testing.assert_array_equal(values.reshape(want.shape), want)
    assert requests.get(f"{base}/{name}/minmax", params={"channel": 7}).status_code == 400


def all_bricks(meta, channels):
    out = []
    for level, lvl in enumerate(meta["levels"]):
        grid = [-(-n // b) for n, b in zip(lvl["shape"], meta["brick_shape"])]
        for c in range(channels):
            out += [(level, c, z, y, x) for z in range(grid[0]) for y in range(grid[1]) for x in range(grid[2])]
    return out


def fetch_batch(base, name, bricks, encoding):
    q = ";".join(",".join(map(str, b)) for b in bricks)
    r = requests.get(f"{base}/{name}/bricks?b={q}&encoding={encoding}")
    assert r.status_code == 200, r.text
    assert r.headers["Content-Type"] == "application/x-residency-bricks"
    header, payload = unframe(r.content, b"RSBRICKS")
    jsonschema.validate(header, schema("brick-batch.schema.json"))
    assert [(e["level"], e["channel"], *e["brick"]) for e in header["bricks"]] == [tuple(b) for b in bricks]
    return header, payload


@pytest.mark.parametrize("name", ["u16", "f32"])
def test_batched_bricks_equal_individually_fetched_ones(stores, name):
    base, paths = stores
    store = paths[name]
    meta = root_attributes(store)["residency"]
    g = zarr.open_group(str(store), mode="r")
    channels = len(meta["channels"])
    everything = all_bricks(meta, channels)
    bz, by, bx = meta["brick_shape"]
    sharded = name == "f32"
    for start in range(0, len(everything), 200):
        part = everything[start : start + 200]
        raw_header, raw = fetch_batch(base, name, part, "raw")
        stored_header, stored = fetch_batch(base, name, part, "stored")
        for (level, c, z, y, x), e, s in zip(part, raw_header["bricks"], stored_header["bricks"]):
            arr = g[meta["levels"][level]["image"]]
            want = np.zeros((bz, by, bx), arr.dtype)
            piece = arr[c, z * bz : (z + 1) * bz, y * by : (y + 1) * by, x * bx : (x + 1) * bx]
            want[: piece.shape[0], : piece.shape[1], : piece.shape[2]] = piece
            if e["status"] == "empty":
                assert not want.view(np.uint8).any()
            else:
                assert e["status"] == "ok", e
                got = np.frombuffer(raw[e["offset"] : e["offset"] + e["length"]], want.dtype.newbyteorder("<"))
                assert got.tobytes() == want.tobytes()
            if not sharded:
                key = f"{meta['levels'][level]['image']}/c/{c}/{z}/{y}/{x}"
                single = requests.get(f"{base}/{name}/{key}")
                if s["status"] == "empty":
                    assert single.status_code == 404
                else:
                    assert s["status"] == "ok" and single.status_code == 200, s
                    assert stored[s["offset"] : s["offset"] + s["length"]] == single.content
            else:
                assert s["status"] in ("ok", "empty")
                assert (s["status"] == "empty") <= (e["status"] == "empty")


def test_batch_caps_and_bad_batches(tmp_path, stores):
    _, paths = stores
    proc, base = start_server(paths["u16"], "--max-batch-bricks", "3", "--max-batch-bytes", "2048")
    try:
        r = requests.get(f"{base}/u16/bricks?b=0,0,0,0,0;0,0,0,0,1;0,0,0,0,2;0,0,0,0,3")
        assert r.status_code == 413 and r.json()["error"] == "more than 3 bricks in one batch"
        r = requests.get(f"{base}/u16/bricks?b=0,0,0,0,0;0,0,0,0,1;0,0,0,0,2")
        assert r.status_code == 413
        assert r.json()["error"] == "3 bricks of 1024 bytes exceed the batch limit of 2048 bytes"
        assert requests.get(f"{base}/u16/bricks?b=0,0,0,0,0;0,0,0,0,1").status_code == 200
        r = requests.get(f"{base}/u16/bricks?b=0,0,x")
        assert r.status_code == 400 and "is not five integers L,C,z,y,x" in r.json()["error"]
        assert requests.get(f"{base}/u16/bricks").status_code == 400
        header, _ = fetch_batch(base, "u16", [(0, 0, 99, 0, 0), (0, 5, 0, 0, 0)], "raw")
        assert [e["status"] for e in header["bricks"]] == ["error", "error"]
        assert "brick [99, 0, 0] lies outside level 0" in header["bricks"][0]["error"]
        assert header["bricks"][1]["error"] == "channel 5 does not exist (the dataset has 2)"
    finally:
        stop_server(proc)


def test_corrupt_and_unreadable_chunks_are_named_and_the_rest_still_served(tmp_path, stores):
    _, paths = stores
    store = tmp_path / "broken.ome.zarr"
    shutil.copytree(paths["u16"], store)
    chunks = sorted(p for p in (store / "0" / "c").rglob("*") if p.is_file())
    corrupt, gone, fine = chunks[0], chunks[1], chunks[2]
    corrupt.write_bytes(b"this is not a blosc frame")
    gone.unlink()
    gone.symlink_to(gone.name)  # a symlink loop: exists, cannot be read
    proc, base = start_server(store)
    try:
        ckey, gkey, fkey = (p.relative_to(store).as_posix() for p in (corrupt, gone, fine))
        r = requests.get(f"{base}/broken/{gkey}")
        assert r.status_code == 500
        assert f"cannot read key '{gkey}' of 'broken'" in r.text
        # Verbatim serving does not decode: the corrupt bytes are what is stored.
        assert requests.get(f"{base}/broken/{ckey}").content == b"this is not a blosc frame"
        at = lambda p: (0, *map(int, p.relative_to(store / "0" / "c").parts))
        header, payload = fetch_batch(base, "broken", [at(corrupt), at(gone), at(fine)], "raw")
        bad, loop, ok = header["bricks"]
        assert bad["status"] == "error" and f"key '{ckey}'" in bad["error"], bad
        assert loop["status"] == "error" and f"key '{gkey}'" in loop["error"], loop
        assert ok["status"] == "ok"
        assert requests.get(f"{base}/broken/{fkey}").content == fine.read_bytes()
        assert requests.get(f"{base}/healthz").text == "ok\n"
    finally:
        stop_server(proc)


def reroot(value, prefix):
    """A JSON Schema as embedded in the OpenAPI document: local `$ref`s under `prefix`, no `$id`."""
    if isinstance(value, dict):
        return {k: (prefix + v[1:] if k == "$ref" and v.startswith("#/") else reroot(v, prefix)) for k, v in value.items() if k != "$id"}
    if isinstance(value, list):
        return [reroot(v, prefix) for v in value]
    return value


def test_openapi_document_is_valid_and_matches_real_responses(stores):
    base, _ = stores
    doc = requests.get(f"{base}/openapi.json").json()
    validate_openapi(doc)
    comps = doc["components"]["schemas"]
    for comp, file in [
        ("DatasetList", "datasets.schema.json"),
        ("RegionAnswer", "region-answer.schema.json"),
        ("ApiError", "api-error.schema.json"),
        ("MinMaxHierarchyHeader", "minmax-hierarchy.schema.json"),
        ("BrickBatchHeader", "brick-batch.schema.json"),
        ("RegionMetadata", "region-metadata.schema.json"),
    ]:
        assert comps[comp] == reroot(schema(file), f"#/components/schemas/{comp}"), comp
    assert {"/datasets", "/{name}/regions", "/{name}/minmax", "/{name}/bricks", "/{name}/{key}", "/healthz", "/metrics"} <= set(doc["paths"])

    def check(path, response, status):
        spec = doc["paths"][path]["get"]["responses"][str(status)]["content"]
        media = response.headers["Content-Type"].split(";")[0]
        assert media in spec, (path, media)
        ref = spec[media]["schema"].get("$ref")
        if ref:
            jsonschema.Draft202012Validator({"$ref": ref, "components": doc["components"]}).validate(response.json())

    check("/datasets", requests.get(f"{base}/datasets"), 200)
    check("/", requests.get(f"{base}/"), 200)
    q = {"level": 0, "channel": 0, "min": "0,0,0", "max": "4,4,4"}
    check("/{name}/regions", requests.get(f"{base}/u16/regions", params=q), 200)
    check("/{name}/regions", requests.get(f"{base}/u16/regions", params={**q, "level": 50}), 400)
    check("/{name}/regions", requests.get(f"{base}/zz/regions", params=q), 404)
    check("/{name}/minmax", requests.get(f"{base}/u16/minmax?channel=0"), 200)
    check("/{name}/bricks", requests.get(f"{base}/u16/bricks?b=0,0,0,0,0"), 200)
    check("/{name}/bricks", requests.get(f"{base}/u16/bricks?b=0"), 400)
    check("/{name}/{key}", requests.get(f"{base}/u16/zarr.json"), 200)
    check("/metrics", requests.get(f"{base}/metrics"), 200)
    check("/healthz", requests.get(f"{base}/healthz"), 200)


def recv_all(sock, wait):
    """Reads until the peer closes (returns the bytes) or `wait` seconds pass (None)."""
    sock.settimeout(wait)
    data = b""
    try:
        while True:
            part = sock.recv(4096)
            if not part:
                return data
            data += part
    except socket.timeout:
        return None


def test_slow_and_idle_clients_are_disconnected(stores):
    _, paths = stores
    proc, base = start_server(paths["u16"], "--request-timeout", "1")
    host, port = base.removeprefix("http://").split(":")
    try:
        slow = socket.create_connection((host, int(port)))
        slow.sendall(b"GET /u16/zarr.json HTTP/1.1\r\nHost: x\r\n")  # headers never finish
        silent = socket.create_connection((host, int(port)))  # sends nothing
        idle = socket.create_connection((host, int(port)))
        idle.sendall(b"GET /healthz HTTP/1.1\r\nHost: x\r\n\r\n")  # then stays idle
        t0 = time.monotonic()
        for s in (slow, silent):
            closed = recv_all(s, 5)
            assert closed is not None and b"200 OK" not in closed
        first = recv_all(idle, 5)
        assert first is not None and first.startswith(b"HTTP/1.1 200 OK")
        assert time.monotonic() - t0 < 4.5
        assert requests.get(f"{base}/healthz").status_code == 200
    finally:
        stop_server(proc)


@pytest.mark.parametrize("threads", [[], ["--threads", "3"]], ids=["threads-per-core", "threads-3"])
def test_connection_limit_refuses_with_503_then_recovers(stores, threads):
    # The limit counts the connections of every serving thread (each has a listener of its own).
    _, paths = stores
    proc, base = start_server(paths["u16"], "--max-connections", "2", *threads)
    host, port = base.removeprefix("http://").split(":")
    try:
        held = [socket.create_connection((host, int(port))) for _ in range(2)]
        for s in held:
            s.sendall(b"GET /healthz HTTP/1.1\r\nHost: x\r\n\r\n")
            s.settimeout(5)
            assert s.recv(4096).startswith(b"HTTP/1.1 200 OK")
        extra = socket.create_connection((host, int(port)))
        reply = recv_all(extra, 5)
        assert reply.startswith(b"HTTP/1.1 503 Service Unavailable") and b"too many connections" in reply
        for s in held:
            s.close()
        # The server frees the two places when it sees the connections closed, a moment later
        # (longer on a loaded machine): until then it refuses, and counts, each try.
        # One session: the connection that is let in is kept for the metrics.
        refused_since, answer = 0, None
        with requests.Session() as s:
            for _ in range(100):
                time.sleep(0.1)
                try:
                    answer = s.get(f"{base}/healthz", timeout=10)
                except requests.ConnectionError:
                    # Refused and closed before the request was read.
                    refused_since += 1
                    continue
                if answer.status_code == 200:
                    break
                assert answer.status_code == 503 and "too many connections" in answer.text, answer.text
                refused_since += 1
            assert answer is not None and answer.status_code == 200, refused_since
            refused = metric(s.get(f"{base}/metrics").text, "brickserver_connections_refused_total")
            assert refused == 1 + refused_since
    finally:
        stop_server(proc)


@pytest.mark.parametrize("flag", ["--threads", "--max-connections", "--max-batch-bricks"])
def test_counts_below_one_are_refused_with_the_flags_named(stores, flag):
    _, paths = stores
    p = subprocess.run([str(BIN / "brickserver"), "serve", str(paths["u16"]), flag, "0", "--bind", "127.0.0.1:0"],
                       capture_output=True, text=True, timeout=30)
    assert p.returncode == 1
    assert p.stderr.strip().splitlines()[-1] == (
        "error: --max-connections, --max-batch-bricks and --threads must be at least 1")


def test_cache_hits_are_counted_and_the_cache_stays_within_budget(stores):
    _, paths = stores
    store = paths["u16"]
    meta = root_attributes(store)["residency"]
    budget = 6000
    proc, base = start_server(store, "--cache-bytes", str(budget))
    try:
        everything = all_bricks(meta, 2)
        some = [b for b in everything if b[0] == 0][:3]
        with requests.Session() as s:
            m = lambda name: metric(s.get(f"{base}/metrics").text, name)
            h0, m0 = m("brickserver_cache_hits_total"), m("brickserver_cache_misses_total")
            first = fetch_batch(base, "u16", some, "raw")
            assert (m("brickserver_cache_hits_total") - h0, m("brickserver_cache_misses_total") - m0) == (0, 3)
            assert fetch_batch(base, "u16", some, "raw") == first
            assert (m("brickserver_cache_hits_total") - h0, m("brickserver_cache_misses_total") - m0) == (3, 3)
            # Stored and decoded bytes are different entries.
            fetch_batch(base, "u16", some, "stored")
            assert m("brickserver_cache_misses_total") - m0 == 6
            total = 0
            for i in range(0, len(everything), 50):
                _, payload = fetch_batch(base, "u16", everything[i : i + 50], "raw")
                total += len(payload)
                assert 0 < m("brickserver_cache_bytes") <= budget
            assert total > 4 * budget
    finally:
        stop_server(proc)
