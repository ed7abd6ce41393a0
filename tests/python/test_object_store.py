"""Stores in an S3-compatible object store, written by `ingest convert` and `ingest index`, read
by `ingest inspect` and `viewer render`, and served by `brickserver` replicas, through a real S3
server on loopback: s3s-fs (installed by scripts/test.sh), serving a folder whose subfolders are
buckets and whose files are the objects. What they read or serve over S3 must equal what they
read or serve from a folder, and what `convert` writes must be byte for byte what it writes to a
folder."""

import os
import pathlib
import shutil
import subprocess

import pytest

from support.binaries import run_ingest, start_server
from support.paths import BIN
from support.s3 import KEY, SECRET, env, run, start_s3
from support.stores import files

pytestmark = pytest.mark.s3


@pytest.fixture(scope="module")
def s3(tmp_path_factory):
    """An s3s-fs server on loopback with bucket `bucket` holding `sample.ome.zarr` (a sparse
    32³ u16 store with 16³ bricks), and that store's local copy."""
    tmp = tmp_path_factory.mktemp("s3")
    samples = tmp / "samples"  # also the converts' input
    run_ingest("sample", "-o", samples, "--kind", "sparse", "--size", "32,32,32", "--quiet")
    local = tmp / "sample.ome.zarr"
    run_ingest("convert", *sorted(samples.glob("*.tif")), "-o", local, "--chunk", "16", "--quiet")
    root = tmp / "root"
    shutil.copytree(local, root / "bucket" / "sample.ome.zarr")
    server, endpoint = start_s3(root)
    yield {"endpoint": endpoint, "local": local, "root": root,
           "inputs": sorted(samples.glob("*.tif"))}
    server.terminate()
    server.wait(timeout=10)


def test_inspect_over_s3_reports_what_the_folder_holds(s3):
    remote = run("ingest", "inspect", "s3://bucket/sample.ome.zarr", "--s3-endpoint",
                 s3["endpoint"])
    assert remote.returncode == 0, remote.stderr
    local = run("ingest", "inspect", s3["local"])
    assert local.returncode == 0, local.stderr
    r, l = remote.stdout.splitlines(), local.stdout.splitlines()
    assert r[0] == "s3://bucket/sample.ome.zarr: OME-Zarr 0.5"
    assert l[0] == f"{s3['local']}: OME-Zarr 0.5"
    assert r[1:] == l[1:]
    assert any(line.startswith("region metadata: ") for line in r)


def test_object_store_errors_name_the_store_and_the_problem(s3):
    missing = run("ingest", "inspect", "s3://bucket/nothing.ome.zarr", "--s3-endpoint",
                  s3["endpoint"])
    assert missing.returncode == 1
    assert missing.stderr == (
        "error: s3://bucket/nothing.ome.zarr: not an OME-Zarr image (no zarr.json or .zattrs)\n")
    denied = run("ingest", "inspect", "s3://bucket/sample.ome.zarr", "--s3-endpoint",
                 s3["endpoint"], secret="not-the-secret-0123456789")
    assert denied.returncode == 1
    assert denied.stderr.startswith("error: s3://bucket/sample.ome.zarr/zarr.json: ")
    assert "403 Forbidden" in denied.stderr
    bad = run("ingest", "inspect", "s3://bucket")
    assert bad.returncode == 2
    assert ("invalid value 's3://bucket' for '<STORE>': s3://bucket: an S3 location is "
            "s3://BUCKET/PREFIX (the store's root), with both parts") in bad.stderr
    scheme = run("viewer", "render", "--store", "gs://bucket/x.ome.zarr", "--out", "x.png")
    assert scheme.returncode == 2
    assert ("gs://bucket/x.ome.zarr: unknown scheme (stores are local paths, file:// or s3:// "
            "URLs)") in scheme.stderr


def assert_renders_the_local_image(s3, tmp_path, *source):
    """`viewer render` from `source` (its flags) draws exactly the image it draws from the
    local copy of the store."""
    flags = ["--tf", "0:800:6000:0.6", "--width", "64", "--height", "64"]
    remote = run("viewer", "render", *source, *flags, "--out", tmp_path / "remote.exr")
    assert remote.returncode == 0, remote.stderr
    local = run("viewer", "render", "--store", s3["local"], *flags, "--out",
                tmp_path / "local.exr")
    assert local.returncode == 0, local.stderr
    same = run("viewer", "compare", tmp_path / "remote.exr", tmp_path / "local.exr")
    assert same.returncode == 0, same.stderr
    assert same.stdout.splitlines() == ["PSNR inf dB", "SSIM 1.000000", "max abs error 0.000000"]


def test_viewer_renders_the_same_image_from_s3_as_from_the_folder(s3, tmp_path):
    assert_renders_the_local_image(s3, tmp_path, "--store", "s3://bucket/sample.ome.zarr",
                                   "--s3-endpoint", s3["endpoint"])


def test_convert_to_s3_writes_the_bytes_of_a_local_convert_root_metadata_last(s3, tmp_path):
    url = "s3://bucket/converted/sample.ome.zarr"
    up = run("ingest", "convert", *s3["inputs"], "-o", url, "--s3-endpoint", s3["endpoint"],
             "--chunk", "16", "--quiet")
    assert up.returncode == 0, up.stderr
    assert up.stdout.startswith(f"wrote {url} (uint16)\n")
    local = tmp_path / "sample.ome.zarr"
    run_ingest("convert", *s3["inputs"], "-o", local, "--chunk", "16", "--quiet")
    remote = s3["root"] / "bucket" / "converted" / "sample.ome.zarr"
    assert files(remote) == files(local)
    # The objects were put in order: the root metadata after every other key.
    others = [p.stat().st_mtime_ns for p in remote.rglob("*") if p.is_file()
              and p.name != "zarr.json"]
    assert (remote / "zarr.json").stat().st_mtime_ns >= max(others)
    again = run("ingest", "convert", *s3["inputs"], "-o", url, "--s3-endpoint", s3["endpoint"],
                "--quiet")
    assert again.returncode == 1
    assert again.stderr == f"error: {url}: output already exists (pass --overwrite to replace it)\n"
    # Replaced: the old store's keys are gone, the new store's bytes are there.
    replaced = run("ingest", "convert", *s3["inputs"], "-o", url, "--s3-endpoint",
                   s3["endpoint"], "--chunk", "32", "--overwrite", "--quiet")
    assert replaced.returncode == 0, replaced.stderr
    local32 = tmp_path / "32" / "sample.ome.zarr"
    run_ingest("convert", *s3["inputs"], "-o", local32, "--chunk", "32", "--quiet")
    assert files(remote) == files(local32)


def test_convert_to_s3_with_nobody_reading_its_report_uploads_and_cleans_up(s3, tmp_path):
    """`ingest convert ... -o s3://... | head -0`: the store is uploaded whole, the report to
    the closed pipe ends the program with success, and its local staging folder is removed
    on the way out (TMPDIR is a folder of the test's own)."""
    url = "s3://bucket/piped/sample.ome.zarr"
    staging = tmp_path / "tmp"
    staging.mkdir()
    read, write = os.pipe()
    os.close(read)
    try:
        p = subprocess.run([str(BIN / "ingest"), "convert", *map(str, s3["inputs"]), "-o", url,
                            "--s3-endpoint", s3["endpoint"], "--chunk", "16"],
                           stdout=write, stderr=subprocess.PIPE, text=True, timeout=300,
                           env=env(TMPDIR=str(staging)))
    finally:
        os.close(write)
    assert (p.returncode, p.stderr) == (0, "")
    assert list(staging.iterdir()) == []
    local = tmp_path / "sample.ome.zarr"
    run_ingest("convert", *s3["inputs"], "-o", local, "--chunk", "16", "--quiet")
    assert files(s3["root"] / "bucket" / "piped" / "sample.ome.zarr") == files(local)


def test_index_in_s3_writes_what_a_local_index_writes_root_metadata_last(s3, tmp_path):
    import numpy as np
    import zarr
    rng = np.random.default_rng(7)
    vol = (rng.random((1, 12, 20, 24)) * 3000).astype(np.uint16)
    foreign = tmp_path / "foreign.ome.zarr"
    root = zarr.open_group(str(foreign), mode="w", zarr_format=3)
    root.create_array("0", data=vol, chunks=(1, 8, 8, 8), dimension_names=("c", "z", "y", "x"))
    root.create_array("1", data=vol[:, :, ::2, ::2].copy(), chunks=(1, 8, 8, 8),
                      dimension_names=("c", "z", "y", "x"))
    root.attrs["ome"] = {
        "version": "0.5",
        "multiscales": [{
            "axes": [{"name": "c", "type": "channel"}] + [{"name": a, "type": "space"} for a in "zyx"],
            "datasets": [{"path": str(i), "coordinateTransformations": [
                {"type": "scale", "scale": [1.0, 1.0, 2.0**i, 2.0**i]}]} for i in range(2)],
        }],
    }
    remote = s3["root"] / "bucket" / "foreign" / "foreign.ome.zarr"
    shutil.copytree(foreign, remote)
    before = files(remote)
    p = run("ingest", "index", "s3://bucket/foreign/foreign.ome.zarr", "--s3-endpoint",
            s3["endpoint"])
    assert p.returncode == 0, p.stderr
    assert p.stdout == "indexed s3://bucket/foreign/foreign.ome.zarr: 2 levels, 1 channels, bricks [8, 8, 8]\n"
    run_ingest("index", foreign)
    after = files(remote)
    assert after == files(foreign)
    # The image's keys are untouched; the region metadata is new; the root document last.
    assert {k: v for k, v in after.items() if k in before and k != "zarr.json"} == \
        {k: v for k, v in before.items() if k != "zarr.json"}
    assert any(k.startswith("residency/") for k in after)
    others = [p.stat().st_mtime_ns for p in remote.rglob("*") if p.is_file()
              and p.name != "zarr.json" and str(p.relative_to(remote)) not in before]
    assert (remote / "zarr.json").stat().st_mtime_ns >= max(others)


@pytest.fixture(scope="module")
def replicas(s3):
    """Two brickserver replicas serving the store in the bucket, one more without a memory cache
    (every answer then comes from the S3 server), and one serving its local copy: their base
    URLs."""
    procs = []
    bases = {}
    url = "s3://bucket/sample.ome.zarr"
    for name, where, extra in [("a", url, []), ("b", url, []),
                               ("uncached", url, ["--cache-bytes", "0"]),
                               ("local", s3["local"], [])]:
        proc, base = start_server(where, "--s3-endpoint", s3["endpoint"], *extra, env=env())
        procs.append(proc)
        bases[name] = base
    yield bases
    for proc in procs:
        proc.terminate()
        proc.wait(timeout=10)


def keys_of(folder: pathlib.Path):
    return sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file())


def test_replicas_on_s3_answer_every_key_alike_and_as_the_folder_does(s3, replicas):
    import requests
    keys = keys_of(s3["local"])
    assert len(keys) > 10 and "zarr.json" in keys
    with requests.Session() as http:
        for key in keys:
            a = http.get(f"{replicas['a']}/sample/{key}")
            b = http.get(f"{replicas['b']}/sample/{key}")
            local = http.get(f"{replicas['local']}/sample/{key}")
            assert a.status_code == b.status_code == 200, key
            assert a.content == b.content == local.content == (s3["local"] / key).read_bytes(), key
            # The ETag is the object store's, so both replicas give the same one.
            assert a.headers["ETag"] == b.headers["ETag"], key
            for h in ["Content-Type", "Cache-Control", "Accept-Ranges", "Content-Length"]:
                assert a.headers[h] == local.headers[h], (key, h)
        # Answered the second time from the replica's memory cache: the same.
        key = next(k for k in keys if "/c/" in k)
        again = http.get(f"{replicas['a']}/sample/{key}")
        assert again.content == (s3["local"] / key).read_bytes()
        missing = http.get(f"{replicas['a']}/sample/0/c/9/9/9/9")
        assert (missing.status_code, missing.text) == (404, "no key '0/c/9/9/9/9' in 'sample'\n")
        refused = http.get(f"{replicas['a']}/sample/0/%2e%2e/zarr.json")
        assert (refused.status_code, refused.text) == (400, "refused: relative path segment\n")


def test_ranges_and_revalidation_from_s3(s3, replicas):
    import requests
    key = max((k for k in keys_of(s3["local"]) if "/c/" in k),
              key=lambda k: (s3["local"] / k).stat().st_size)
    data = (s3["local"] / key).read_bytes()
    n = len(data)
    assert n > 40
    url = f"{replicas['b']}/sample/{key}"
    etag = requests.get(url).headers["ETag"]
    cases = [("bytes=2-9", 206, data[2:10], f"bytes 2-9/{n}"),
             ("bytes=-4", 206, data[-4:], f"bytes {n - 4}-{n - 1}/{n}"),
             (f"bytes={n - 3}-", 206, data[-3:], f"bytes {n - 3}-{n - 1}/{n}"),
             (f"bytes=10-{n + 100}", 206, data[10:], f"bytes 10-{n - 1}/{n}"),
             (f"bytes={n}-", 416, b"", f"bytes */{n}"),
             ("bytes=-0", 416, b"", f"bytes */{n}"),
             ("bytes=0-1,4-5", 200, data, None)]
    assert requests.get(f"{replicas['a']}/sample/{key}").content == data
    for value, status, body, content_range in cases:
        # Replica a answers from its memory cache (it has read the chunk whole); the uncached
        # one turns each range into a ranged read of the object.
        for base in [replicas["a"], replicas["uncached"]]:
            r = requests.get(f"{base}/sample/{key}", headers={"Range": value})
            assert (r.status_code, r.content) == (status, body), (base, value)
            assert r.headers.get("Content-Range") == content_range, (base, value)
    for base in [replicas["a"], replicas["uncached"]]:
        same = requests.get(f"{base}/sample/{key}", headers={"If-None-Match": etag})
        assert (same.status_code, same.content, same.headers["ETag"]) == (304, b"", etag)
        other = requests.get(f"{base}/sample/{key}", headers={"If-None-Match": '"other"'})
        assert (other.status_code, other.content) == (200, data)
        meta = requests.get(f"{base}/sample/zarr.json")
        assert requests.get(f"{base}/sample/zarr.json",
                            headers={"If-None-Match": meta.headers["ETag"]}).status_code == 304


def test_region_api_and_batched_bricks_from_s3_are_those_from_disk(replicas):
    import requests
    paths = ["datasets", "sample/minmax?channel=0",
             "sample/regions?level=0&channel=0&min=0,0,0&max=32,32,32",
             "sample/regions?level=1&channel=0&min=4,0,8&max=16,16,16",
             "sample/bricks?b=0,0,0,0,0&b=0,0,1,1,1&b=1,0,0,0,0&encoding=raw",
             "sample/bricks?b=0,0,1,0,1&b=0,0,0,1,0",
             "sample/bricks?b=0,0,9,9,9"]
    for path in paths:
        a, b, local = (requests.get(f"{replicas[n]}/{path}") for n in ["a", "b", "local"])
        assert a.status_code == b.status_code == local.status_code, path
        assert a.headers["Content-Type"] == local.headers["Content-Type"], path
        if path == "datasets":
            # The listing differs only in the links' host and port (plain and URL-encoded).
            import re
            host = re.compile(r"127(\.|%2E)0(\.|%2E)0(\.|%2E)1(:|%3A)[0-9]+")
            for doc, base in [(a, replicas["a"]), (b, replicas["b"]), (local, replicas["local"])]:
                assert doc.text.count(base) > 0
            assert host.sub("HOST", a.text) == host.sub("HOST", b.text) == host.sub("HOST", local.text)
        else:
            assert a.content == b.content == local.content, path
    assert requests.get(f"{replicas['a']}/sample/bricks?b=0,0,0,0,0").status_code == 200


def test_zarr_python_and_the_viewer_read_the_s3_store_through_brickserver(s3, replicas, tmp_path):
    import numpy as np
    import zarr
    from ome_zarr_models import open_ome_zarr
    remote = zarr.open_group(f"{replicas['a']}/sample/", mode="r")
    local = zarr.open_group(str(s3["local"]), mode="r")
    levels = [k for k, _ in local.arrays()]
    assert len(levels) >= 2
    for level in levels:
        np.testing.assert_array_equal(remote[level][...], local[level][...])
    open_ome_zarr(remote)
    assert_renders_the_local_image(s3, tmp_path, "--server", replicas["b"], "--dataset", "sample")


def test_brickserver_refuses_an_s3_location_without_a_store(s3):
    p = run("brickserver", "serve", "s3://bucket/nothing.ome.zarr", "--s3-endpoint",
            s3["endpoint"], "--bind", "127.0.0.1:0")
    assert p.returncode == 1
    assert p.stderr.endswith(
        "error: s3://bucket/nothing.ome.zarr: no store there (none of zarr.json, .zgroup, "
        ".zattrs at its root)\n")


def test_partitions_write_into_the_bucket_the_bytes_of_one_local_convert(s3, tmp_path):
    url = "s3://bucket/parted/sample.ome.zarr"
    flags = ["--chunk", "8", "--s3-endpoint", s3["endpoint"], "--quiet"]
    procs = [subprocess.Popen([str(BIN / "ingest"), "convert", *map(str, s3["inputs"]), "-o", url,
                               *flags, "--partition", f"{i}/3"],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env())
             for i in range(3)]
    for p in procs:
        out, err = p.communicate(timeout=300)
        assert p.returncode == 0, err
        assert out.startswith(f"wrote partition {procs.index(p)}/3 into {url}: "), out
    remote = s3["root"] / "bucket" / "parted" / "sample.ome.zarr"
    # In the bucket: the partitions' bricks and hand-over files, and no root metadata.
    assert not (remote / "zarr.json").exists()
    assert sorted(p.name for p in (remote / ".partitions").iterdir()) == [
        ".records", "0-of-3", "1-of-3", "2-of-3", "plan"]
    # Each partition's records of region metadata, level by level, beside its hand-over file.
    records = sorted(p.name for p in (remote / ".partitions" / ".records").iterdir())
    levels = len(records) // 6
    assert levels >= 1 and records == sorted(
        f"{i}-of-3.{l}.{kind}" for i in range(3) for l in range(levels)
        for kind in ("cells", "histograms"))
    done = run("ingest", "finalize", "-o", url, "--s3-endpoint", s3["endpoint"], "--quiet")
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith(f"wrote {url} (uint16)\n")
    local = tmp_path / "sample.ome.zarr"
    run_ingest("convert", *s3["inputs"], "-o", local, "--chunk", "8", "--quiet")
    assert files(remote) == files(local)
    others = [p.stat().st_mtime_ns for p in remote.rglob("*") if p.is_file()
              and p.name != "zarr.json"]
    assert (remote / "zarr.json").stat().st_mtime_ns >= max(others)
    # Served from the bucket, it draws the local store's image.
    proc, base = start_server(url, "--s3-endpoint", s3["endpoint"], env=env())
    try:
        assert_renders_the_local_image(s3, tmp_path, "--server", base, "--dataset", "sample")
    finally:
        proc.terminate()
        proc.wait(timeout=10)
    # Once finished, it is a store: partitions and finalize refuse to mix into it.
    again = run("ingest", "finalize", "-o", url, "--s3-endpoint", s3["endpoint"])
    assert (again.returncode, again.stderr) == (
        1, f"error: {url}: output already exists (pass --overwrite to replace it)\n")
    mixed = run("ingest", "convert", *s3["inputs"], "-o", url, "--s3-endpoint", s3["endpoint"],
                "--partition", "0/3", "--overwrite")
    assert (mixed.returncode, mixed.stderr) == (
        1, f"error: {url}: --overwrite does not combine with partitions in an object store (their "
           "keys would mix with the old store's); delete the old store first\n")


def test_files_larger_than_a_part_go_up_in_parts(s3, tmp_path):
    """A 24 MiB chunk (random bytes: LZ4 cannot shrink them) goes up as a multipart upload of
    8 MiB parts; the bucket holds the bytes of a local convert, and the object's ETag is the
    multipart kind (ending in `-N`, N the part count)."""
    import numpy as np
    import requests
    raw = tmp_path / "noise_1024x1024x24_uint8.raw"
    raw.write_bytes(np.random.default_rng(3).integers(0, 256, 24 << 20, dtype=np.uint8).tobytes())
    flags = ["--chunk", "24,1024,1024", "--quiet"]
    url = "s3://bucket/big/noise.ome.zarr"
    up = run("ingest", "convert", raw, "-o", url, "--s3-endpoint", s3["endpoint"], *flags)
    assert up.returncode == 0, up.stderr
    local = tmp_path / "noise.ome.zarr"
    run_ingest("convert", raw, "-o", local, *flags)
    remote = s3["root"] / "bucket" / "big" / "noise.ome.zarr"
    assert files(remote) == files(local)
    key, size = max(((k, len(v)) for k, v in files(local).items()), key=lambda kv: kv[1])
    assert size > 16 << 20 and key.startswith("0/c/")
    proc, base = start_server(url, "--s3-endpoint", s3["endpoint"], env=env())
    try:
        got = requests.get(f"{base}/noise/{key}")
        assert got.content == (local / key).read_bytes()
        parts = -(-size // (8 << 20))  # 24 MiB of samples and Blosc's header: 4 parts
        assert parts == 4
        assert got.headers["ETag"].endswith(f'-{parts}"'), got.headers["ETag"]
    finally:
        proc.terminate()
        proc.wait(timeout=10)


def test_credentials_region_and_endpoint_from_an_aws_profile(s3, tmp_path):
    """With no AWS_ACCESS_KEY_ID in the environment, the keys, region and endpoint of the
    profile AWS_PROFILE names are used; a missing profile is named."""
    credentials, config = tmp_path / "credentials", tmp_path / "config"
    credentials.write_text(
        f"[lab]\naws_access_key_id = {KEY}\naws_secret_access_key = {SECRET}\n\n"
        f"[wrong]\naws_access_key_id = {KEY}\naws_secret_access_key = not-the-secret-0123456789\n")
    config.write_text(f"[profile lab]\nregion = eu-west-1\nendpoint_url = {s3['endpoint']}\n\n"
                      f"[profile wrong]\nendpoint_url = {s3['endpoint']}\n")
    base = {k: v for k, v in env().items() if k not in ("AWS_ACCESS_KEY_ID", "AWS_SECRET_ACCESS_KEY")}
    base.update(AWS_SHARED_CREDENTIALS_FILE=str(credentials), AWS_CONFIG_FILE=str(config))

    def inspect(profile):
        return subprocess.run([str(BIN / "ingest"), "inspect", "s3://bucket/sample.ome.zarr"],
                              capture_output=True, text=True, env={**base, "AWS_PROFILE": profile},
                              timeout=120)

    lab = inspect("lab")
    assert lab.returncode == 0, lab.stderr
    assert lab.stdout.splitlines()[0] == "s3://bucket/sample.ome.zarr: OME-Zarr 0.5"
    wrong = inspect("wrong")
    assert wrong.returncode == 1 and "403 Forbidden" in wrong.stderr, wrong.stderr
    missing = inspect("nope")
    assert (missing.returncode, missing.stderr) == (1, (
        f"error: AWS profile 'nope' (AWS_PROFILE) is in neither {credentials} nor {config}\n"))
