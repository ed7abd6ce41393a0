"""`brickserver` with real clients: zarr-python and ome-zarr-models over HTTP, plain HTTP
requests for headers, and raw requests for path traversal."""

import http.client
import json
import os
import pathlib
import resource
import shutil
import signal
import socket
import subprocess
import time
import urllib.parse

import numpy as np
import pytest
import requests
import tifffile
import zarr
from ome_zarr_models import open_ome_zarr

from support.binaries import run_ingest, start_server, stop_server
from support.paths import BIN
from support.stores import small_store
from support.wire import metric


@pytest.fixture(scope="module")
def served(tmp_path_factory):
    """A store made by `ingest` (3 levels, empty bricks included), served on a free port.
    Yields (base URL, store path, server process)."""
    d = tmp_path_factory.mktemp("served")
    rng = np.random.default_rng(3)
    vol = np.zeros((2, 24, 40, 36), np.uint16)
    vol[:, 4:20, 5:30, 3:20] = rng.integers(1, 4000, (2, 16, 25, 17))
    src = d / "data.ome.tif"
    tifffile.imwrite(src, vol, ome=True, photometric="minisblack", metadata={"axes": "CZYX"})
    store = d / "cells.ome.zarr"
    run_ingest("convert", src, "-o", store, "--chunk", "8", "--quiet")
    (d / "secret.txt").write_text("TOP SECRET")
    os.symlink(d / "secret.txt", store / "escape")
    proc, base = start_server(store)
    yield base, store, proc
    stop_server(proc)


def test_zarr_python_reads_every_level_over_http(served):
    base, store, _ = served
    remote = zarr.open_group(f"{base}/cells/", mode="r")
    local = zarr.open_group(str(store), mode="r")
    for level in ["0", "1", "2"]:
        np.testing.assert_array_equal(remote[level][...], local[level][...])
    open_ome_zarr(remote)


def test_every_key_is_served_verbatim(served):
    base, store, _ = served
    files = [p for p in store.rglob("*") if p.is_file() and not p.is_symlink()]
    assert len(files) > 20
    with requests.Session() as s:
        for p in files:
            key = p.relative_to(store).as_posix()
            r = s.get(f"{base}/cells/{key}")
            assert r.status_code == 200, key
            assert r.content == p.read_bytes(), key


def test_headers_etag_range_cache_and_types(served):
    base, store, _ = served
    chunk = next(p for p in (store / "0" / "c").rglob("*") if p.is_file())
    key = chunk.relative_to(store).as_posix()
    data = chunk.read_bytes()
    r = requests.get(f"{base}/cells/{key}")
    assert r.headers["Content-Type"] == "application/octet-stream"
    assert r.headers["Cache-Control"] == "public, max-age=31536000, immutable"
    assert r.headers["Accept-Ranges"] == "bytes"
    assert r.headers["Access-Control-Allow-Origin"] == "*"
    etag = r.headers["ETag"]
    assert requests.get(f"{base}/cells/{key}", headers={"If-None-Match": etag}).status_code == 304
    assert requests.get(f"{base}/cells/{key}", headers={"If-None-Match": '"other"'}).status_code == 200
    part = requests.get(f"{base}/cells/{key}", headers={"Range": "bytes=2-9"})
    assert part.status_code == 206 and part.content == data[2:10]
    assert part.headers["Content-Range"] == f"bytes 2-9/{len(data)}"
    tail = requests.get(f"{base}/cells/{key}", headers={"Range": "bytes=-4"})
    assert tail.content == data[-4:]
    bad = requests.get(f"{base}/cells/{key}", headers={"Range": f"bytes={len(data)}-"})
    assert bad.status_code == 416 and bad.headers["Content-Range"] == f"bytes */{len(data)}"
    head = requests.head(f"{base}/cells/{key}")
    assert head.status_code == 200 and head.content == b"" and int(head.headers["Content-Length"]) == len(data)
    meta = requests.get(f"{base}/cells/zarr.json")
    assert meta.headers["Content-Type"] == "application/json"
    assert meta.headers["Cache-Control"] == "public, no-cache"


def test_missing_chunk_is_404_and_cors_preflight_works(served):
    base, store, _ = served
    assert not (store / "0" / "c" / "0" / "0" / "4" / "0").exists()  # an empty brick (y 32..40)
    assert requests.get(f"{base}/cells/0/c/0/0/4/0").status_code == 404
    assert requests.get(f"{base}/nosuch/zarr.json").status_code == 404
    pre = requests.options(
        f"{base}/cells/zarr.json",
        headers={"Origin": "http://viewer.example", "Access-Control-Request-Method": "GET", "Access-Control-Request-Headers": "range"},
    )
    assert pre.status_code == 200
    assert pre.headers["Access-Control-Allow-Origin"] == "*"
    assert "GET" in pre.headers["Access-Control-Allow-Methods"]


@pytest.mark.parametrize("method", ["POST", "PUT", "DELETE", "PATCH"])
def test_read_only(served, method):
    base, _, _ = served
    assert requests.request(method, f"{base}/cells/zarr.json").status_code == 405


@pytest.mark.parametrize(
    "path",
    [
        "/cells/../secret.txt",
        "/cells/%2e%2e/secret.txt",
        "/cells/%2E%2E%2Fsecret.txt",
        "/cells/..%2fsecret.txt",
        "/cells/..\\secret.txt",
        "/cells/%5c..%5csecret.txt",
        "/cells//etc/passwd",
        "/cells/%2fetc%2fpasswd",
        "/cells/zarr.json%00",
        "/cells/escape",
    ],
)
def test_nothing_outside_a_dataset_is_reachable(served, path):
    base, _, _ = served
    host, port = base.removeprefix("http://").split(":")
    conn = http.client.HTTPConnection(host, int(port), timeout=5)
    conn.putrequest("GET", path, skip_accept_encoding=True)  # sent exactly as written
    conn.endheaders()
    r = conn.getresponse()
    body = r.read()
    assert 400 <= r.status < 500, (path, r.status)
    assert b"TOP SECRET" not in body and b"root:" not in body


def neuroglancer_state(link):
    """The viewer state in a neuroglancer link's fragment."""
    prefix = "https://neuroglancer-demo.appspot.com/#!"
    assert link.startswith(prefix), link
    return json.loads(urllib.parse.unquote(link[len(prefix):]))


def test_listing_links_open_each_dataset(served):
    base, store, _ = served
    omero = json.loads((store / "zarr.json").read_text())["attributes"]["ome"]["omero"]["channels"]
    for path in ["/", "/datasets"]:
        items = requests.get(base + path).json()["datasets"]
        assert [d["name"] for d in items] == ["cells"]
        assert items[0]["url"] == f"{base}/cells/"
        assert items[0]["view"] == f"{base}/cells/view"
        assert items[0]["vizarr"] == f"https://hms-dbmi.github.io/vizarr/?source={base}/cells/"
        # OME-Zarr 0.5 (Zarr v3): zarr3://, one layer per channel with its omero window and
        # colour, so 16-bit data does not open black.
        state = neuroglancer_state(items[0]["neuroglancer"])
        assert [layer["source"] for layer in state["layers"]] == [f"zarr3://{base}/cells/"] * 2
        for i, (layer, channel) in enumerate(zip(state["layers"], omero)):
            window = channel["window"]
            assert layer["localDimensions"] == {"c'": [1, ""]}
            assert layer["localPosition"] == [i + 0.5]
            assert layer["shaderControls"]["normalized"]["range"] == [window["start"], window["end"]]
            assert layer["shaderControls"]["color"] == "#" + channel["color"].lower()
    assert requests.get(base + "/healthz").text == "ok\n"


def test_listing_links_of_a_zarr_v2_store_and_behind_a_proxy(tmp_path):
    src = tmp_path / "a.tif"
    tifffile.imwrite(src, np.arange(2 * 8 * 8, dtype=np.uint16).reshape(2, 8, 8) * 500, photometric="minisblack")
    store = tmp_path / "old.ome.zarr"
    run_ingest("convert", src, "-o", store, "--ome-zarr-version", "0.4", "--quiet")
    proc, base = start_server(store)
    try:
        (item,) = requests.get(base + "/datasets").json()["datasets"]
        state = neuroglancer_state(item["neuroglancer"])
        # zarr3:// reads zarr.json only ("No zarr metadata found" on a v2 store).
        assert [layer["source"] for layer in state["layers"]] == [f"zarr://{base}/old/"]
        window = json.loads((store / ".zattrs").read_text())["omero"]["channels"][0]["window"]
        assert state["layers"][0]["shaderControls"]["normalized"]["range"] == [window["start"], window["end"]]
        # Behind a TLS reverse proxy: its scheme and host.
        proxied = {"X-Forwarded-Proto": "https", "X-Forwarded-Host": "data.example.org"}
        (item,) = requests.get(base + "/datasets", headers=proxied).json()["datasets"]
        assert item["url"] == "https://data.example.org/old/"
        assert item["view"] == "https://data.example.org/old/view"
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.wait(timeout=10)
    proc, base = start_server(store, "--public-url", "https://example.org/residency/")
    try:
        (item,) = requests.get(base + "/", headers={"X-Forwarded-Host": "other"}).json()["datasets"]
        assert item["url"] == "https://example.org/residency/old/"
        assert neuroglancer_state(item["neuroglancer"])["layers"][0]["source"] == "zarr://https://example.org/residency/old/"
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.wait(timeout=10)


def test_graceful_shutdown_on_sigterm(tmp_path):
    proc, _ = start_server(small_store(tmp_path))
    proc.send_signal(signal.SIGTERM)
    assert proc.wait(timeout=10) == 0


def test_bad_dataset_is_a_clear_error(tmp_path):
    p = subprocess.run([str(BIN / "brickserver"), "serve", str(tmp_path / "missing.ome.zarr")], capture_output=True, text=True)
    assert p.returncode != 0
    assert "missing.ome.zarr: cannot open dataset" in p.stderr


def test_a_closed_stdout_does_not_stop_the_server(tmp_path):
    """`brickserver serve ... | head -1` leaves the server a stdout nobody reads: it says
    where it listens to nobody, and serves."""
    store = small_store(tmp_path)
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    read, write = os.pipe()
    os.close(read)
    proc = subprocess.Popen([str(BIN / "brickserver"), "serve", str(store), "--bind", f"127.0.0.1:{port}"],
                            stdout=write, stderr=subprocess.PIPE, text=True)
    os.close(write)
    try:
        for _ in range(100):
            try:
                if requests.get(f"http://127.0.0.1:{port}/healthz", timeout=1).status_code == 200:
                    break
            except requests.ConnectionError:
                time.sleep(0.05)
        assert requests.get(f"http://127.0.0.1:{port}/a/zarr.json").content == (store / "zarr.json").read_bytes()
        assert proc.poll() is None
    finally:
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=10) == 0
        assert "panicked" not in proc.stderr.read()


def test_token_file_guards_everything_but_health(tmp_path):
    store = small_store(tmp_path)
    token_file = tmp_path / "token"
    token_file.write_text("s3cret-token\n")
    proc, base = start_server(store, "--token-file", token_file)
    try:
        good = {"Authorization": "Bearer s3cret-token"}
        for path in ["/a/zarr.json", "/datasets", "/", "/a/0/zarr.json"]:
            assert requests.get(base + path).status_code == 401, path
            assert requests.get(base + path, headers={"Authorization": "Bearer wrong"}).status_code == 401, path
            r = requests.get(base + path, headers=good)
            assert r.status_code == 200, path
        assert requests.get(base + "/a/zarr.json").headers["WWW-Authenticate"] == "Bearer"
        assert requests.get(base + "/healthz").status_code == 200
        assert requests.get(base + "/a/zarr.json", headers=good).content == (store / "zarr.json").read_bytes()
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.wait(timeout=10)


def test_empty_token_file_is_refused(tmp_path):
    store = small_store(tmp_path)
    (tmp_path / "token").write_text("  \n")
    p = subprocess.run([str(BIN / "brickserver"), "serve", str(store), "--token-file", str(tmp_path / "token")], capture_output=True, text=True)
    assert p.returncode != 0 and "token file is empty" in p.stderr


def test_metrics_count_requests_bytes_and_latency(served):
    base, store, _ = served
    chunk = next(p for p in (store / "0" / "c").rglob("*") if p.is_file())
    key = chunk.relative_to(store).as_posix()
    # One keep-alive connection, whose requests the server answers (and counts) in order: a
    # request on a new connection could be answered before the last one's answer is counted.
    with requests.Session() as session:
        first = session.get(base + "/metrics")
        assert first.headers["Content-Type"].startswith("application/openmetrics-text")
        session.get(f"{base}/cells/{key}")
        session.get(f"{base}/cells/no/such/key")
        second = session.get(base + "/metrics").text
    t1 = first.text
    assert metric(second, 'brickserver_requests_total{class="2xx"}') - metric(t1, 'brickserver_requests_total{class="2xx"}') == 2
    assert metric(second, 'brickserver_requests_total{class="4xx"}') - metric(t1, 'brickserver_requests_total{class="4xx"}') == 1
    not_found = len(f"no key 'no/such/key' in 'cells'\n")
    assert metric(second, "brickserver_response_bytes_total") - metric(t1, "brickserver_response_bytes_total") == len(first.content) + chunk.stat().st_size + not_found
    assert metric(second, "brickserver_request_duration_seconds_count") - metric(t1, "brickserver_request_duration_seconds_count") == 3
    assert 'brickserver_request_duration_seconds_bucket{le="0.001"}' in second


def test_web_viewer_pages_files_and_html_listing(tmp_path):
    store = small_store(tmp_path)
    web = tmp_path / "web"
    web.mkdir()
    (web / "index.html").write_text('<script src="%VIEWER_BASE%main.js"></script>')
    (web / "residency_viewer_bg.wasm").write_bytes(b"\0asm\1\0\0\0")
    (tmp_path / "secret.txt").write_text("TOP SECRET")
    proc, base = start_server(store, "--viewer-dir", web)
    try:
        r = requests.get(f"{base}/a/view")
        assert (r.status_code, r.headers["content-type"]) == (200, "text/html; charset=utf-8")
        assert r.text == '<script src="../viewer/main.js"></script>'
        r = requests.get(f"{base}/nope/view")
        assert (r.status_code, r.text) == (404, '<script src="../viewer/main.js"></script>')
        for path in ["/viewer/", "/viewer/index.html"]:
            assert requests.get(base + path).text == '<script src="./main.js"></script>'
        r = requests.get(f"{base}/viewer/residency_viewer_bg.wasm")
        assert (r.status_code, r.headers["content-type"], r.content) == (200, "application/wasm", b"\0asm\1\0\0\0")
        for bad in ["/viewer/..%2fsecret.txt", "/viewer/.hidden", "/viewer/missing.js"]:
            r = requests.get(base + bad)
            assert r.status_code == 404, bad
        # A store key is still a store key.
        assert requests.get(f"{base}/a/zarr.json").json()["zarr_format"] == 3
        # For a browser, `/` is an HTML page linking each dataset's viewer; JSON otherwise.
        r = requests.get(base + "/", headers={"Accept": "text/html,application/xhtml+xml"})
        assert r.headers["content-type"] == "text/html; charset=utf-8"
        assert '<a href="a/view">open in the Residency viewer</a>' in r.text
        assert requests.get(base + "/").json()["datasets"][0]["name"] == "a"
    finally:
        proc.terminate()
        proc.wait()
    proc, base = start_server(store, "--viewer-dir", tmp_path / "not-built")
    try:
        r = requests.get(f"{base}/a/view")
        assert r.status_code == 503
        assert r.text == (
            "the web viewer is not built: run scripts/build-web.sh, or pass --viewer-dir "
            f"(looked for index.html in {tmp_path / 'not-built'})\n"
        )
        assert requests.get(f"{base}/viewer/main.js").status_code == 503
    finally:
        proc.terminate()
        proc.wait()


def store_files_held(pid, store):
    """The files of `store` that server `pid` holds open (a deleted one ends in " (deleted)")."""
    held = []
    for fd in pathlib.Path(f"/proc/{pid}/fd").iterdir():
        try:
            target = os.readlink(fd)
        except FileNotFoundError:
            continue
        if target.startswith(str(store) + "/"):
            held.append(target[len(str(store)) + 1 :])
    return sorted(held)


def test_chunk_files_held_open_are_let_go_when_replaced_changed_or_deleted(tmp_path):
    """A chunk's bytes are answered from its file held open only while the file still has a
    name and its length and modification time: one renamed over, truncated or rewritten in
    place, or deleted, is let go and its key opened again, so each answer's bytes are those of
    its ETag, and a deleted store's files are closed. With `--open-files 0` each request opens
    its file."""
    store = small_store(tmp_path)
    # Keys the server serves verbatim beside the store's chunk.
    key, long_key = "0/c/0/0/0/0", "0/c/0/0/0/8"
    (store / long_key).write_bytes(bytes(range(256)) * 40)
    old = (store / key).read_bytes()
    proc, base = start_server(store)
    try:
        first = requests.get(f"{base}/a/{key}")
        assert (first.status_code, first.content) == (200, old)
        assert requests.get(f"{base}/a/{long_key}").content == bytes(range(256)) * 40
        assert store_files_held(proc.pid, store) == [key, long_key]
        assert requests.get(f"{base}/a/{key}", headers={"If-None-Match": first.headers["ETag"]}).status_code == 304
        # Renamed over, the way files are replaced atomically.
        (store / "replacement").write_bytes(old + b"more bytes")
        os.replace(store / "replacement", store / key)
        renamed = requests.get(f"{base}/a/{key}")
        assert renamed.content == old + b"more bytes" and renamed.headers["ETag"] != first.headers["ETag"]
        assert requests.get(f"{base}/a/{key}", headers={"If-None-Match": first.headers["ETag"]}).status_code == 200
        # Rewritten in place with the same length: its modification time tells.
        same_length = bytes(reversed(old + b"more bytes"))
        with open(store / key, "r+b") as f:
            f.write(same_length)
        os.utime(store / key, ns=(time.time_ns(), time.time_ns() + 5_000_000_000))
        # A revalidation that matches the held file's ETag is answered without a look at the
        # file (as nginx does within open_file_cache_valid); an answer with bytes looks.
        assert requests.get(f"{base}/a/{key}", headers={"If-None-Match": renamed.headers["ETag"]}).status_code == 304
        rewritten = requests.get(f"{base}/a/{key}")
        assert rewritten.content == same_length and rewritten.headers["ETag"] != renamed.headers["ETag"]
        # Cut short in place, within its page (sent from the file) and by pages (read by the router).
        os.truncate(store / key, 3)
        assert requests.get(f"{base}/a/{key}").content == same_length[:3]
        os.truncate(store / long_key, 100)
        short = requests.get(f"{base}/a/{long_key}")
        assert (short.content, short.headers["Content-Length"]) == (bytes(range(100)), "100")
        assert store_files_held(proc.pid, store) == [key, long_key]
        shutil.rmtree(store)
        assert store_files_held(proc.pid, store) == [f"{key} (deleted)", f"{long_key} (deleted)"]
        assert requests.get(f"{base}/a/{key}").status_code == 404
        assert requests.get(f"{base}/a/{long_key}").status_code == 404
        assert store_files_held(proc.pid, store) == []
    finally:
        stop_server(proc)

    (tmp_path / "again").mkdir()
    store = small_store(tmp_path / "again")
    proc, base = start_server(store, "--open-files", "0")
    try:
        assert requests.get(f"{base}/a/{key}").content == old
        assert requests.get(f"{base}/a/{key}").content == old
        # Each answer closes its file once sent, a moment after the client has it (up to 10 s
        # on a loaded machine).
        for _ in range(500):
            if not store_files_held(proc.pid, store):
                break
            time.sleep(0.02)
        assert store_files_held(proc.pid, store) == []
    finally:
        stop_server(proc)


def test_open_files_beyond_a_quarter_of_the_open_file_limit_are_lowered(tmp_path):
    def limit_files():
        resource.setrlimit(resource.RLIMIT_NOFILE, (1024, 1024))

    proc, _ = start_server(small_store(tmp_path), preexec_fn=limit_files)
    stop_server(proc)
    assert "--open-files 4096 lowered to 256, a quarter of the open-file limit (1024)" in proc.stderr.read()
