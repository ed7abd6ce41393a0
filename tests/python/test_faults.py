"""Under faults, nothing lost: `ingest convert`, `brickserver` and `viewer render` against an
S3 server (s3s-fs) behind a seeded fault proxy (support/fault_proxy.py) that answers a share
of requests 500 or 503, resets connections before the headers or in the middle of the body,
and stalls requests. Each either gives exactly what it gives from a healthy store, or fails
with a clear error naming the key (a 502/503 from brickserver); a failed upload leaves no root
metadata; brickserver recovers when the store does. Every test checks that faults were
really injected."""

import concurrent.futures
import time
import shutil

import pytest
import requests

from support.binaries import run_ingest, start_server, stop_server
from support.fault_proxy import FaultProxy
from support.s3 import env, run, start_s3
from support.stores import files
from support.wire import unframe

pytestmark = pytest.mark.s3

NAME = "sample"
"""The dataset's name in brickserver (from the store's folder name)."""


@pytest.fixture(scope="module")
def s3(tmp_path_factory):
    """s3s-fs on loopback with bucket `bucket` holding `sample.ome.zarr` (a sparse 48³ u16
    store, 16³ bricks, 27 chunks at level 0), the store's local copy and the conversion's
    inputs."""
    tmp = tmp_path_factory.mktemp("faults")
    samples = tmp / "samples"
    run_ingest("sample", "-o", samples, "--kind", "sparse", "--size", "48,48,48", "--quiet")
    inputs = sorted(samples.glob("*.tif"))
    local = tmp / "sample.ome.zarr"
    run_ingest("convert", *inputs, "-o", local, "--chunk", "16", "--quiet")
    root = tmp / "root"
    shutil.copytree(local, root / "bucket" / "sample.ome.zarr")
    server, endpoint = start_s3(root)
    yield {"endpoint": endpoint, "local": local, "root": root, "inputs": inputs}
    server.terminate()
    server.wait(timeout=10)


def keys_of(folder):
    return sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file())


def test_convert_through_faults_writes_the_bytes_of_a_clean_convert(s3):
    url = "s3://bucket/faulty/sample.ome.zarr"
    # Uploads' answers have no body, so their resets all come before the headers.
    with FaultProxy(s3["endpoint"], error_rate=0.2, reset_rate=0.1, stall_rate=0.05, stall_s=1.0,
                    seed=33) as proxy:
        up = run("ingest", "convert", *s3["inputs"], "-o", url, "--s3-endpoint", proxy.url,
                 "--chunk", "16", "--quiet")
        stats = proxy.stats()
    assert up.returncode == 0, up.stderr
    assert up.stdout.startswith(f"wrote {url} (uint16)\n")
    # Faults of every kind were injected, and the client got through them all.
    assert stats["errors_500"] + stats["errors_503"] > 0, stats
    assert stats["resets_before_headers"] > 0, stats
    assert stats["stalls"] > 0, stats
    assert stats["requests"] > stats["forwarded"] > len(keys_of(s3["local"])), stats
    remote = s3["root"] / "bucket" / "faulty" / "sample.ome.zarr"
    assert files(remote) == files(s3["local"])


def test_convert_to_a_store_that_goes_down_names_the_key_and_leaves_no_root_metadata(s3):
    url = "s3://bucket/down/sample.ome.zarr"
    remote = s3["root"] / "bucket" / "down" / "sample.ome.zarr"
    # Healthy for the existence checks and the first uploads, then every request fails.
    with FaultProxy(s3["endpoint"], fail_after=12) as proxy:
        up = run("ingest", "convert", *s3["inputs"], "-o", url, "--s3-endpoint", proxy.url,
                 "--chunk", "16", "--quiet")
        stats = proxy.stats()
    assert up.returncode == 1, up.stdout
    assert stats["mode"] == "fail" and stats["errors_503"] > 10, stats
    # The message names the object whose upload failed, and the store's answer.
    assert up.stderr.startswith(f"error: {url}/"), up.stderr
    key = up.stderr[len(f"error: {url}/"):].split(":")[0]
    assert key in keys_of(s3["local"]) and key != "zarr.json", up.stderr
    assert "503 Service Unavailable" in up.stderr, up.stderr
    assert "SlowDown" in up.stderr, up.stderr
    # Some objects went up, but no root document: no reader takes it for a store.
    assert remote.is_dir() and keys_of(remote), "no upload got through before the failures"
    for name in ["zarr.json", ".zgroup", ".zattrs"]:
        assert not (remote / name).exists(), name
    refused = run("ingest", "inspect", url, "--s3-endpoint", s3["endpoint"])
    assert refused.returncode == 1
    assert refused.stderr == f"error: {url}: not an OME-Zarr image (no zarr.json or .zattrs)\n"


def test_a_failed_root_document_takes_down_those_put_before_it(s3):
    """Zarr v2 has two root documents (`.zattrs`, then `.zgroup`): when the second cannot be
    put, the first is deleted again, so the bucket holds no root metadata."""
    url = "s3://bucket/v2/sample.ome.zarr"
    remote = s3["root"] / "bucket" / "v2" / "sample.ome.zarr"

    def zgroup_put(method, path):
        return method == "PUT" and path.split("?")[0].endswith("/sample.ome.zarr/.zgroup")

    with FaultProxy(s3["endpoint"], fail_when=zgroup_put) as proxy:
        up = run("ingest", "convert", *s3["inputs"], "-o", url, "--s3-endpoint", proxy.url,
                 "--chunk", "16", "--ome-zarr-version", "0.4", "--quiet")
        stats = proxy.stats()
    assert up.returncode == 1, up.stdout
    assert up.stderr.startswith(f"error: {url}/.zgroup: "), up.stderr
    assert stats["errors_503"] == 11, stats  # the first try and its 10 retries
    assert (remote / "0" / ".zarray").is_file()
    assert not (remote / ".zattrs").exists() and not (remote / ".zgroup").exists()


BRICKS = "bricks?b=0,0,0,0,0&b=0,0,1,1,1&b=0,0,2,2,2&b=1,0,0,0,0&b=1,0,1,1,1&encoding=raw"
REGIONS = "regions?level=0&channel=0&min=0,0,0&max=48,48,48"


@pytest.fixture(scope="module")
def served(s3):
    """brickserver on the bucket's store through a fault proxy (stalls longer than the
    client's 1 s request timeout among its faults), without a memory cache so that every
    answer comes from the store, and one on the local copy: (proxy, faulty base, local base)."""
    proxy = FaultProxy(s3["endpoint"], error_rate=0.12, reset_rate=0.08, stall_rate=0.02,
                       stall_s=1.5, seed=5).start()
    faulty, faulty_base = start_server("s3://bucket/sample.ome.zarr", "--s3-endpoint", proxy.url,
                                       "--cache-bytes", "0", env=env(AWS_TIMEOUT="1s"))
    local, local_base = start_server(s3["local"])
    yield proxy, faulty_base, local_base
    stop_server(faulty)
    stop_server(local)
    proxy.stop()


def assert_answers_the_local_bytes(s3, base, local_base, http, every=1):
    """Every `every`-th key of the store whole, every fourth of those in a range too, and a
    batch of bricks and a region query answer exactly what they answer from the local copy."""
    for i, key in enumerate(keys_of(s3["local"])[::every]):
        data = (s3["local"] / key).read_bytes()
        whole = http.get(f"{base}/{NAME}/{key}")
        assert (whole.status_code, whole.content) == (200, data), (key, whole.text[:300])
        if len(data) > 8 and i % 4 == 0:
            part = http.get(f"{base}/{NAME}/{key}", headers={"Range": "bytes=3-7"})
            assert (part.status_code, part.content) == (206, data[3:8]), key
    for path in [BRICKS, REGIONS]:
        remote, local = http.get(f"{base}/{NAME}/{path}"), http.get(f"{local_base}/{NAME}/{path}")
        assert (remote.status_code, remote.content) == (200, local.content), path
    header, _ = unframe(http.get(f"{base}/{NAME}/{BRICKS}").content, b"RSBRICKS")
    assert [b["status"] for b in header["bricks"]].count("ok") >= 1


def test_brickserver_through_faults_answers_exact_bytes(s3, served):
    proxy, base, local_base = served
    before = proxy.stats()
    with requests.Session() as http:
        assert_answers_the_local_bytes(s3, base, local_base, http, every=2)
    after = proxy.stats()
    assert after["errors_500"] + after["errors_503"] > before["errors_500"] + before["errors_503"]
    assert after["resets_before_headers"] + after["resets_mid_body"] > \
        before["resets_before_headers"] + before["resets_mid_body"], after
    assert after["resets_mid_body"] > 0, after
    assert after["stalls"] > 0, after


def test_brickserver_answers_502_or_503_naming_the_key_while_the_store_is_down_then_recovers(
        s3, served):
    proxy, base, local_base = served
    chunk = next(k for k in keys_of(s3["local"]) if "/c/" in k)
    shard = "zarr.json"

    def get(key):
        return requests.get(f"{base}/{NAME}/{key}", timeout=60)

    # The dataset's image arrays are loaded (see the next test for loads that fail).
    assert get(BRICKS).status_code == 200
    try:
        # A store that answers every request with an error: 502, the store's answer quoted,
        # and never a 200 with data: a batch's bricks that cannot be read are errors.
        proxy.set_mode("fail", "503")
        with concurrent.futures.ThreadPoolExecutor(2) as pool:
            answered = pool.submit(get, chunk)
            batch = pool.submit(get, "bricks?b=0,0,2,2,1&encoding=raw")
            answered, batch = answered.result(), batch.result()
        # One that resets every connection: 503 (unreachable), with Retry-After.
        proxy.set_mode("fail", "reset")
        gone = get(shard)
        assert answered.status_code == 502, answered.text
        assert answered.text.startswith(
            f"cannot read key '{chunk}' of '{NAME}': the object store answered an error ("), \
            answered.text
        assert "503 Service Unavailable" in answered.text and "SlowDown" in answered.text
        assert "Retry-After" not in answered.headers
        if batch.status_code == 200:
            header, payload = unframe(batch.content, b"RSBRICKS")
            assert [b["status"] for b in header["bricks"]] == ["error"], header
            assert payload == b""
        else:
            assert batch.status_code in (502, 503), batch.text
        assert gone.status_code == 503, gone.text
        assert gone.text.startswith(
            f"cannot read key '{shard}' of '{NAME}': the object store did not answer ("), gone.text
        assert gone.headers["Retry-After"] == "5"
        assert proxy.stats()["resets_before_headers"] > 10
    finally:
        proxy.set_mode("healthy")
    # The store is back: so are the answers, byte for byte.
    with requests.Session() as http:
        assert_answers_the_local_bytes(s3, base, local_base, http, every=5)


def test_a_dataset_that_cannot_be_loaded_answers_502_or_503_then_loads(s3, served):
    # A server of its own, whose image (for its region metadata and arrays) is first needed
    # while the store is down; failed loads are tried again after 3 s (a loaded machine's next
    # request comes well within them).
    proxy, _, local_base = served
    server, base = start_server("s3://bucket/sample.ome.zarr", "--s3-endpoint", proxy.url,
                                "--cache-bytes", "0", "--load-retry", "3",
                                env=env(AWS_TIMEOUT="1s"))
    try:
        proxy.set_mode("fail", "503")
        answered = requests.get(f"{base}/{NAME}/{REGIONS}", timeout=60)
        # The region index and the bricks share the image: its failure is kept for 3 s.
        kept = requests.get(f"{base}/{NAME}/{BRICKS}", timeout=60)
        time.sleep(3.2)
        proxy.set_mode("fail", "reset")
        gone = requests.get(f"{base}/{NAME}/{BRICKS}", timeout=60)
        proxy.set_mode("healthy")
        assert answered.status_code == 502, answered.text
        assert answered.json()["error"].startswith(f"dataset '{NAME}': "), answered.text
        assert "the object store answered an error (" in answered.json()["error"], answered.text
        assert "Retry-After" not in answered.headers
        assert (kept.status_code, kept.text) == (502, answered.text)
        assert gone.status_code == 503, gone.text
        assert "the object store did not answer (" in gone.json()["error"], gone.text
        assert gone.headers["Retry-After"] == "5"
        time.sleep(3.2)
        for path in [REGIONS, BRICKS]:
            remote = requests.get(f"{base}/{NAME}/{path}", timeout=60)
            local = requests.get(f"{local_base}/{NAME}/{path}", timeout=60)
            assert (remote.status_code, remote.content) == (200, local.content), path
    finally:
        proxy.set_mode("healthy")
        stop_server(server)


def test_viewer_renders_through_faults_the_image_of_the_local_store(s3, tmp_path):
    flags = ["--tf", "0:800:6000:0.6", "--width", "48", "--height", "48"]
    with FaultProxy(s3["endpoint"], error_rate=0.2, reset_rate=0.1, seed=9) as proxy:
        remote = run("viewer", "render", "--store", "s3://bucket/sample.ome.zarr",
                     "--s3-endpoint", proxy.url, *flags, "--out", tmp_path / "remote.exr")
        stats = proxy.stats()
    assert remote.returncode == 0, remote.stderr
    assert stats["faults"] > 0, stats
    local = run("viewer", "render", "--store", s3["local"], *flags, "--out", tmp_path / "local.exr")
    assert local.returncode == 0, local.stderr
    same = run("viewer", "compare", tmp_path / "remote.exr", tmp_path / "local.exr")
    assert same.returncode == 0, same.stderr
    assert same.stdout.splitlines() == ["PSNR inf dB", "SSIM 1.000000", "max abs error 0.000000"]


def test_the_proxy_is_seeded_and_counts_what_it_does(s3):
    """The same seed draws the same faults for the same requests; rates outside [0, 1] are
    refused."""
    def faults(seed):
        with FaultProxy(s3["endpoint"], error_rate=0.3, reset_rate=0.2, seed=seed) as proxy:
            fates = []
            for _ in range(40):
                try:
                    r = requests.get(f"{proxy.url}/bucket/sample.ome.zarr/zarr.json", timeout=10)
                    fates.append(r.status_code)
                except requests.RequestException:
                    fates.append("reset")
            return fates, proxy.stats()
    first, stats = faults(1)
    again, _ = faults(1)
    other, _ = faults(2)
    assert first == again != other
    assert stats["requests"] == 40
    assert stats["errors_500"] == first.count(500) and stats["errors_503"] == first.count(503)
    assert stats["resets_before_headers"] + stats["resets_mid_body"] == first.count("reset")
    # Unsigned requests: s3s-fs refuses them (403), and the proxy passes that on.
    assert stats["forwarded"] == first.count(403) > 0
    assert stats["faults"] == 40 - first.count(403)
    # Steered and read by another process over HTTP, as benchmarks do.
    with FaultProxy(s3["endpoint"], error_rate=1.0) as proxy:
        assert requests.get(f"{proxy.url}/bucket/x", timeout=10).status_code in (500, 503)
        assert requests.post(f"{proxy.url}/__fault__/mode/healthy", timeout=10).text == "ok\n"
        assert requests.get(f"{proxy.url}/bucket/x", timeout=10).status_code == 403
        bad = requests.post(f"{proxy.url}/__fault__/mode/sideways", timeout=10)
        assert (bad.status_code, bad.text) == (
            400, "unknown mode 'sideways' (one of faults, healthy, fail)\n")
        counted = requests.get(f"{proxy.url}/__fault__/stats", timeout=10).json()
        assert {k: counted[k] for k in ["requests", "forwarded", "faults", "mode"]} == \
            {"requests": 2, "forwarded": 1, "faults": 1, "mode": "healthy"}
    with pytest.raises(ValueError, match="error_rate must lie in"):
        FaultProxy(s3["endpoint"], error_rate=1.5)
    with pytest.raises(ValueError, match="the rates add up to more than 1"):
        FaultProxy(s3["endpoint"], error_rate=0.6, reset_rate=0.6)


def test_a_batch_of_bricks_is_fetched_from_the_store_concurrently(s3):
    """Every request to the store held 1 s (long enough for a loaded machine to start all of a
    batch's requests within it): the 8 level-0 bricks of a batch are all in
    flight at once (brickserver reads an object store's bricks 32 at a time, not one per
    core), and the batch answers the local copy's bytes."""
    proxy = FaultProxy(s3["endpoint"], stall_rate=1.0, stall_s=1.0, seed=1).start()
    faulty, base = start_server("s3://bucket/sample.ome.zarr", "--s3-endpoint", proxy.url,
                                "--cache-bytes", "0", env=env())
    local, local_base = start_server(s3["local"])
    try:
        batch = "bricks?" + "&".join(f"b=0,0,{z},{y},{x}" for z in (0, 1) for y in (0, 1)
                                     for x in (0, 1)) + "&encoding=stored"
        # The first query opens the pyramid: its root metadata, then its 3 levels' at once.
        assert requests.get(f"{base}/{NAME}/bricks?b=1,0,0,0,0", timeout=60).status_code == 200
        assert proxy.stats()["max_in_flight"] == 3
        remote = requests.get(f"{base}/{NAME}/{batch}", timeout=60)
        local_answer = requests.get(f"{local_base}/{NAME}/{batch}", timeout=60)
        assert (remote.status_code, remote.content) == (200, local_answer.content)
        assert proxy.stats()["max_in_flight"] == 8, proxy.stats()
    finally:
        stop_server(faulty)
        stop_server(local)
        proxy.stop()


def test_the_region_index_is_read_from_the_store_side_by_side(s3):
    """Every request to the store held 1 s (long enough for a loaded machine to start 16
    requests within it): brickserver's one-time load of the region index
    reads its 21 arrays 16 at a time (not one after another), each key once, and answers a
    region query with the local copy's bytes."""
    proxy = FaultProxy(s3["endpoint"], stall_rate=1.0, stall_s=1.0, seed=1).start()
    faulty, base = start_server("s3://bucket/sample.ome.zarr", "--s3-endpoint", proxy.url,
                                env=env())
    local, local_base = start_server(s3["local"])
    try:
        remote = requests.get(f"{base}/{NAME}/{REGIONS}", timeout=60)
        local_answer = requests.get(f"{local_base}/{NAME}/{REGIONS}", timeout=60)
        assert (remote.status_code, remote.content) == (200, local_answer.content)
        stats, paths = proxy.stats(), proxy.paths()
        arrays = [p for p in paths if p.startswith("/bucket/sample.ome.zarr/residency/")
                  and p.endswith("/zarr.json")]
        region = [p for p in paths if p.startswith("/bucket/sample.ome.zarr/residency/")]
        assert (len(arrays), len(region), len(set(region))) == (21, 45, 45), paths
        assert stats["max_in_flight"] == 16, stats
    finally:
        stop_server(faulty)
        stop_server(local)
        proxy.stop()


def test_the_image_is_opened_once_for_its_region_index_and_its_bricks(s3):
    """brickserver opens a dataset's image once and shares it between the region index and
    the bricks: a region query and then a batch of bricks read the store's root metadata and
    each level's metadata once (the server read the root metadata once more when it started,
    to check that the location holds a store)."""
    proxy = FaultProxy(s3["endpoint"], seed=1).start()
    server, base = start_server("s3://bucket/sample.ome.zarr", "--s3-endpoint", proxy.url,
                                env=env())
    try:
        store = "/bucket/sample.ome.zarr"
        assert proxy.paths() == [f"{store}/zarr.json"]
        assert requests.get(f"{base}/{NAME}/{REGIONS}", timeout=60).status_code == 200
        assert requests.get(f"{base}/{NAME}/bricks?b=1,0,0,0,0", timeout=60).status_code == 200
        image = [p for p in proxy.paths()[1:] if p.endswith("/zarr.json")
                 and not p.startswith(f"{store}/residency/")]
        levels = [f"{store}/{i}/zarr.json" for i in range(3)]
        assert sorted(image) == sorted([f"{store}/zarr.json", *levels]), proxy.paths()
        assert proxy.stats()["faults"] == 0
    finally:
        stop_server(server)
        proxy.stop()


def test_the_viewer_fetches_a_batch_of_bricks_from_the_store_concurrently(s3, tmp_path):
    """Every request to the store held 0.3 s, one fetch worker, and one core for rayon: the
    viewer has its first batch of level-0 bricks in flight at once (it reads an object store's
    bricks by futures, not one per core), reads each brick once, and draws the local copy's
    image."""
    flags = ["--tf", "0:800:6000:0.6", "--width", "48", "--height", "48", "--max-level", "0",
             "--workers", "1"]
    with FaultProxy(s3["endpoint"], stall_rate=1.0, stall_s=0.3, seed=1) as proxy:
        remote = run("viewer", "render", "--store", "s3://bucket/sample.ome.zarr",
                     "--s3-endpoint", proxy.url, *flags, "--out", tmp_path / "remote.exr",
                     extra_env={"RAYON_NUM_THREADS": "1"})
        stats, paths = proxy.stats(), proxy.paths()
    assert remote.returncode == 0, remote.stderr
    bricks = [p for p in paths if p.startswith("/bucket/sample.ome.zarr/0/c/")]
    assert len(bricks) == len(set(bricks)) == 24, paths
    # Every key is read once: a level's zarr.json too (its array is made from the document read).
    assert len(paths) == len(set(paths)), paths
    # The renderer asks for bricks as its frames find them missing, so how many wait at once
    # depends on timing (8 or 9 here); read one per core, at most one would.
    assert stats["max_in_flight"] >= 8, stats
    local = run("viewer", "render", "--store", s3["local"], *flags, "--out", tmp_path / "local.exr")
    assert local.returncode == 0, local.stderr
    same = run("viewer", "compare", tmp_path / "remote.exr", tmp_path / "local.exr")
    assert same.returncode == 0, same.stderr
    assert same.stdout.splitlines() == ["PSNR inf dB", "SSIM 1.000000", "max abs error 0.000000"]
