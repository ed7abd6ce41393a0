"""The web page's remote mode in a real browser (Debian's Chromium, headless, WebGPU on
SwiftShader, driven by tests/browser/web_viewer.mjs): `brickserver serve` serves the page and
the dataset's metadata, `viewer serve` (on lavapipe) renders VDIs of the page's views, both on
loopback. The page opened with `?render=URL&render_token=TOKEN` streams no bricks: it asks the
service for VDIs and ray casts them itself (viewer/src/web/remote.rs).

Needs the release binaries and the web build (scripts/build-web.sh)."""

import json
import shutil
import subprocess
import sys
import threading
import urllib.parse
import urllib.request

import jsonschema
import numpy as np
import pytest

from support.binaries import run_ingest, start_server, stop_server
from support.browser import read_png, require_browser, run_pausing
from support.paths import BIN, ROOT, schema
from support.service_proxy import INJECTED_ERROR, ServiceProxy

sys.path.insert(0, str(ROOT / "benchmarks"))
from throttle_proxy import ThrottleProxy  # noqa: E402

pytestmark = pytest.mark.browser

DRIVER = ROOT / "tests" / "browser" / "web_viewer.mjs"
SIZE = 96
TOKEN = "remote-s3cret"
ENV = {"XDG_RUNTIME_DIR": "/tmp", "PATH": "/usr/bin:/bin"}


@pytest.fixture(autouse=True)
def browser_and_web_build():
    """Fails (skips with RESIDENCY_SKIP_BROWSER=1) without Chromium and Node; fails without
    the web build."""
    require_browser()
    assert (BIN / "web" / "index.html").exists(), f"{BIN}/web not built: run scripts/build-web.sh"


def drive(url, steps):
    """Runs the page driver; returns (results, console messages)."""
    last, code, err = run_pausing(DRIVER, {"url": url, "steps": steps}, None, 600)
    assert code == 0, f"browser driver failed:\n{last}\n{err}"
    out = json.loads(last)
    return out["results"], out["console"]


def errors(console, expected=()):
    """Console errors and page errors, but those containing a string of `expected`."""
    return [m for m in console
            if (m.startswith("error") or m.startswith("pageerror")) and not any(e in m for e in expected)]


def scene_of(fragment):
    """The scene JSON of a `#scene=...` fragment."""
    assert fragment.startswith("#scene="), fragment
    return json.loads(urllib.parse.unquote(fragment[len("#scene="):]))


def viewer_of_scene(command, scene, out, *flags):
    """`viewer COMMAND ... --scene S --width SIZE --height SIZE --out OUT` with `scene` written
    beside `out`; returns `out`."""
    path = out.with_suffix(".scene.json")
    path.write_text(json.dumps(scene))
    p = subprocess.run(
        [str(BIN / "viewer"), command, *map(str, flags), "--scene", str(path),
         "--width", str(SIZE), "--height", str(SIZE), "--out", str(out)],
        capture_output=True, text=True, env=ENV,
    )
    assert p.returncode == 0, p.stderr
    return out


def dvr(store, scene, out):
    """`viewer render` (DVR, converged) of `scene` on `store`, SIZE × SIZE, as a PNG."""
    return viewer_of_scene("render", scene, out, "--store", store)


def assert_matches(image, reference):
    """The page's 8-bit image equals `viewer render`'s (DVR: within the supersegment
    approximation): no channel off by more than 2 of 255, PSNR ≥ 60 dB (or none: the same
    pixels) and SSIM ≥ 0.9999
    (`viewer compare`; measured against DVR: 1 of 255, 77–86 dB), and it is not blank."""
    p = subprocess.run([str(BIN / "viewer"), "compare", "--json", str(image), str(reference)],
                       capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    m = json.loads(p.stdout)
    a = read_png(image)[:, :, :3].astype(int)
    b = read_png(reference)[:, :, :3].astype(int)
    assert np.abs(a - b).max() <= 2, np.abs(a - b).max()
    # `psnr_db` is null for identical images.
    assert (m["psnr_db"] is None or m["psnr_db"] >= 60.0) and m["ssim"] >= 0.9999, m
    assert (a.max(axis=2) > 16).mean() > 0.1


def start_service(store, token_file):
    """Starts `viewer serve --store STORE --bind 127.0.0.1:0` with a token; returns (process,
    base URL) once it logs the address it listens on."""
    proc = subprocess.Popen(
        [str(BIN / "viewer"), "serve", "--store", str(store), "--serve-token-file", str(token_file),
         "--bind", "127.0.0.1:0"],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, env=ENV,
    )
    for line in proc.stderr:
        if "listening on http://" in line:
            # Its log is drained, so that it never blocks on a full pipe.
            threading.Thread(target=proc.stderr.read, daemon=True).start()
            return proc, "http://" + line.split("listening on http://")[1].strip().split()[0]
    raise AssertionError(f"viewer serve did not start (exit {proc.wait()})")


@pytest.fixture(scope="module")
def stores(tmp_path_factory):
    """Two tiny stores: three u16 channels, and one u8."""
    d = tmp_path_factory.mktemp("remote")
    run_ingest("sample", "-o", d / "fl", "--size", "24,40,40")
    run_ingest("convert", *(d / "fl" / f"{n}.ome.tif" for n in ("nuclei", "membranes", "filaments")),
               "-o", d / "u16x3.ome.zarr")
    run_ingest("convert", d / "fl" / "membranes.ome.tif", "-o", d / "u8.ome.zarr")
    return {"u16x3": d / "u16x3.ome.zarr", "u8": d / "u8.ome.zarr", "dir": d}


@pytest.fixture(scope="module")
def servers(stores):
    """brickserver with both stores, and a render service of u16x3 guarded by TOKEN."""
    token_file = stores["dir"] / "token.txt"
    token_file.write_text(TOKEN + "\n")
    brick, base = start_server(stores["u16x3"], stores["u8"])
    service, url = start_service(stores["u16x3"], token_file)
    yield base, url
    stop_server(brick)
    service.terminate()
    service.wait(timeout=10)


def page(base, name, service, token=TOKEN, extra=""):
    return (f"{base}/{name}/view?width={SIZE}&height={SIZE}&render={urllib.parse.quote(service)}"
            f"&render_token={token}{extra}")


def test_remote_mode_converges_to_the_dvr_image_and_asks_again_after_an_orbit(servers, stores, tmp_path):
    base, service = servers
    # A frame rate no device holds: while the camera moves, D_I drops below 1.
    results, console = drive(
        page(base, "u16x3", service, extra="&target_fps=1000"),
        [
            {"do": "converge"},
            {"do": "hash"},
            {"do": "snapshot", "path": str(tmp_path / "first.png")},
            # 40 px: 23° of orbit, past the 10° threshold during the drag, in moves 50 ms apart
            # (a frame each, the camera moving).
            {"do": "drag", "dx": 40, "dy": 0, "moves": 8, "delay_ms": 50},
            {"do": "waitState", "when": "s.remote.requests_sent >= 2"},
            {"do": "converge"},
            {"do": "hash", "not": None},
            {"do": "snapshot", "path": str(tmp_path / "orbited.png")},
            {"do": "workers"},
        ],
    )
    first, first_hash, orbited, orbited_hash = results[0], results[1], results[5], results[6]
    # The page reads the answers in its worker, off its main thread (the only worker it runs).
    assert results[8] == [f"{base}/viewer/vdi_worker.js"], results[8]
    assert first["error"] is None and first["converged"], first
    remote = first["remote"]
    assert remote["mode"] == "on" and remote["converged"] and remote["last_error"] is None, remote
    assert (remote["requests_sent"], remote["vdis_received"], remote["requests_aborted"]) == (1, 1, 0)
    # No brick streamed: the page draws the service's VDIs only.
    assert first["bricks_requested"] == 0 and first["bricks_fetched"] == 0, first
    # `auto` by default: at rest the linear filter, whose pipeline is compiled while the view
    # rests (from the VDI's own camera the nearest pipeline draws it: the two coincide there).
    assert remote["d_i"] == 1.0 and remote["vdi_filter"] == "auto" and remote["frame_filter"] == "linear", remote
    # `auto` compression: the first request knows nothing of the link, so it asks for LZ4.
    assert (remote["vdi_compression"], remote["answer_compression"]) == ("auto", "shuffled_lz4"), remote
    assert remote["linear_compiled"], remote
    # The page's share of the answer's latency: the VDI read (in the worker), then its buffers
    # taken in and uploaded for the ray caster (on the main thread).
    for took in ("vdi_decode_ms", "vdi_setup_ms"):
        assert remote[took] is not None and 0 <= remote[took] < 60_000, remote
    scene = scene_of(first_hash)
    assert remote["vdi_camera"] == scene["camera"]
    assert_matches(tmp_path / "first.png", dvr(stores["u16x3"], scene, tmp_path / "dvr1.png"))

    # After the orbit: asked again, and the VDI drawn is the newest, of the rested camera.
    assert orbited["error"] is None and orbited["converged"], orbited
    remote = orbited["remote"]
    moved = scene_of(orbited_hash)
    assert moved["camera"] != scene["camera"]
    assert remote["vdi_camera"] == moved["camera"]
    assert remote["requests_sent"] >= 2 and remote["vdis_received"] >= 2, remote
    assert remote["drawn_request"] == remote["requests_sent"], remote
    # The first answer (about 340 KB) measured the loopback link, and the latest request asked
    # by the rate measured before it: LZ4 at 300 Mbit/s and above (far above, unless the
    # machine stalled the transfer), zstd below.
    asked = remote["request_link_mbit_per_s"]
    assert asked is not None and remote["link_mbit_per_s"] is not None, remote
    assert remote["answer_compression"] == ("shuffled_lz4" if asked >= 300 else "shuffled_zstd"), remote
    # Subsampled while moving, full resolution at rest.
    assert remote["frames_subsampled"] >= 1 and remote["d_i"] == 1.0, remote
    assert orbited["bricks_fetched"] == 0
    assert_matches(tmp_path / "orbited.png", dvr(stores["u16x3"], moved, tmp_path / "dvr2.png"))
    assert errors(console) == []


def test_a_newer_request_aborts_the_one_in_flight_and_service_errors_show(servers, stores, tmp_path):
    """Hiding a channel asks for a new VDI, which a proxy holds (as a service busy for seconds
    would); a colour change sent meanwhile supersedes that request: its fetch is aborted and
    only the newer VDI is drawn. Then a scene the service refuses shows its message."""
    base, service = servers
    results, _ = drive(page(base, "u16x3", service), [{"do": "converge"}, {"do": "hash"}])
    scene = scene_of(results[1])
    hidden = json.loads(json.dumps(scene))
    hidden["channels"][1]["visible"] = False
    recoloured = json.loads(json.dumps(hidden))
    recoloured["channels"][0]["color"] = [1.0, 0.25, 0.0]
    nothing = json.loads(json.dumps(recoloured))
    for c in nothing["channels"]:
        c["visible"] = False
    with ServiceProxy(service, hold=[2]) as proxy:
        results, console = drive(
            page(base, "u16x3", proxy.url),
            [
                {"do": "converge"},
                {"do": "setScene", "scene": hidden},
                {"do": "waitState", "when": "s.remote.in_flight === 2"},
                {"do": "setScene", "scene": recoloured},
                {"do": "converge"},
                {"do": "hash"},
                {"do": "snapshot", "path": str(tmp_path / "recoloured.png")},
                {"do": "setScene", "scene": nothing},
                {"do": "waitMessage"},
                {"do": "state"},
            ],
        )
        posts = proxy.posts()
    assert [p.status for p in posts] == [200, 0, 200, 400], posts
    state, fragment, message, failed = results[4], results[5], results[8], results[9]
    assert state["error"] is None and state["converged"], state
    remote = state["remote"]
    assert (remote["requests_sent"], remote["requests_aborted"], remote["vdis_received"]) == (3, 1, 2), remote
    assert remote["drawn_request"] == 3 and remote["scene_current"], remote
    assert scene_of(fragment) == recoloured
    assert_matches(tmp_path / "recoloured.png", dvr(stores["u16x3"], recoloured, tmp_path / "dvr.png"))
    assert message == f"Render service {proxy.url}: scene: no channel is visible"
    assert failed["remote"]["last_error"] == "scene: no channel is visible"
    # The VDI of the last good scene stays drawn, no longer current.
    assert failed["remote"]["drawn_request"] == 3 and not failed["remote"]["scene_current"]
    # Chromium logs the refused request itself.
    assert errors(console, ["the server responded with a status of 400 (Bad Request)"]) == []


def test_a_wrong_token_and_another_dataset_show_the_service_message(servers):
    """The service's refusal shows on the page; switching *Remote* off, the page streams bricks
    and renders them itself."""
    base, service = servers
    results, _ = drive(
        page(base, "u16x3", service, token="wrong"),
        [{"do": "waitMessage"}, {"do": "state"}, {"do": "click", "selector": "#remote"},
         {"do": "converge"}, {"do": "message"}],
    )
    assert results[0] == f"Render service {service}: missing or wrong bearer token"
    assert results[1]["remote"]["mode"] == "starting" and results[1]["remote"]["requests_sent"] == 0
    assert results[1]["bricks_requested"] == 0
    local = results[3]
    assert local["error"] is None and local["converged"] and local["bricks_fetched"] > 0, local
    assert local["remote"]["mode"] == "off" and local["remote"]["requests_sent"] == 0
    assert results[4] is None
    results, _ = drive(page(base, "u8", service), [{"do": "waitMessage"}])
    assert results[0] == f"Render service {service}: it serves dataset 'u16x3', not 'u8'"


def service_info(service):
    """The service's `GET /info`, with the token, checked against its JSON Schema."""
    request = urllib.request.Request(f"{service}/info", headers={"authorization": f"Bearer {TOKEN}"})
    with urllib.request.urlopen(request, timeout=30) as r:
        info = json.loads(r.read())
    jsonschema.validate(info, schema("vdi-service-info.schema.json"))
    return info


def test_info_names_the_gpu_and_a_busy_service_is_asked_again_after_retry_after(servers):
    """Through a proxy that answers the first POST /vdi 503 with `Retry-After: 4` and the
    second 429 without one, the page sends the same request again 4 s, then 1 s later, draws
    the third answer's VDI and counts its bytes; its report names the service's GPU adapter as
    /info does."""
    base, service = servers
    info = service_info(service)
    assert set(info["adapter"]) == {"name", "backend"}, info["adapter"]
    assert info["adapter"]["backend"] in ("vulkan", "metal", "dx12", "gl"), info["adapter"]
    assert info["adapter"]["name"] != ""
    with ServiceProxy(service, failures=[(503, "4"), (429, None)]) as proxy:
        results, console = drive(page(base, "u16x3", proxy.url), [{"do": "converge"}, {"do": "message"}])
        posts = proxy.posts()
    state, message = results
    assert state["error"] is None and state["converged"], state
    remote = state["remote"]
    assert remote["service_adapter"] == info["adapter"]
    assert (remote["requests_sent"], remote["requests_retried"], remote["vdis_received"],
            remote["last_error"]) == (1, 2, 1, None), remote
    assert message is None
    assert [p.status for p in posts] == [503, 429, 200], posts
    assert posts[1].at_s - posts[0].at_s >= 4.0, posts
    assert 1.0 <= posts[2].at_s - posts[1].at_s < 4.0, posts
    assert remote["vdi_bytes_received"] == posts[2].body_bytes > 0, (remote, posts)
    assert errors(console, ["status of 503", "status of 429"]) == []


def test_a_request_refused_more_than_three_times_shows_the_last_refusal(servers):
    """`Retry-After: 0` four times: three retries, then the fourth answer is the page's error."""
    base, service = servers
    with ServiceProxy(service, failures=[(503, "0")] * 4) as proxy:
        results, console = drive(page(base, "u16x3", proxy.url), [{"do": "waitMessage"}, {"do": "state"}])
        posts = proxy.posts()
    message, state = results
    expected = INJECTED_ERROR.format(status=503)
    assert message == f"Render service {proxy.url}: {expected}"
    remote = state["remote"]
    assert (remote["requests_sent"], remote["requests_retried"], remote["vdis_received"],
            remote["vdi_bytes_received"], remote["last_error"]) == (1, 3, 0, 0, expected), remote
    assert (remote["vdi_decode_ms"], remote["vdi_setup_ms"]) == (None, None), remote
    assert [p.status for p in posts] == [503] * 4, posts
    assert errors(console, ["status of 503"]) == []


def test_a_request_waiting_to_be_retried_is_superseded_by_a_newer_view(servers):
    """The first POST /vdi is answered 503 with `Retry-After: 6`; while the page waits to send
    it again, the camera moves: the newer request is sent as soon as the view rests, the old
    one is not sent again (not in the 6 s nor in the 8 s after the newer VDI is drawn; the
    proxy records a request once it is answered, and the service would answer a stale one at
    once with 409), and the page draws the newer view's VDI."""
    base, service = servers
    results, _ = drive(page(base, "u16x3", service), [{"do": "converge"}, {"do": "hash"}])
    scene = scene_of(results[1])
    closer = json.loads(json.dumps(scene))
    cam = closer["camera"]
    cam["eye"] = [t + 0.75 * (e - t) for e, t in zip(cam["eye"], cam["target"])]
    with ServiceProxy(service, failures=[(503, "6")]) as proxy:
        results, console = drive(
            page(base, "u16x3", proxy.url),
            [
                {"do": "waitState", "when": "s.remote && s.remote.requests_retried >= 1"},
                {"do": "setScene", "scene": closer},
                {"do": "waitState", "when": "s.remote.requests_sent >= 2"},
                {"do": "converge"},
                {"do": "sleep", "ms": 8000},
                {"do": "state"},
            ],
        )
        posts = proxy.posts()
    waiting, state, later = results[0], results[3], results[5]
    assert waiting["remote"]["vdis_received"] == 0, waiting
    assert state["error"] is None and state["converged"], state
    remote = state["remote"]
    assert (remote["requests_sent"], remote["requests_retried"], remote["requests_aborted"],
            remote["vdis_received"], remote["drawn_request"], remote["last_error"]) == \
        (2, 1, 1, 1, 2, None), remote
    assert remote["vdi_camera"] == closer["camera"]
    assert later["remote"] == remote, later
    assert [p.status for p in posts] == [503, 200], posts
    assert posts[1].at_s - posts[0].at_s < 6.0, posts
    assert errors(console, ["status of 503"]) == []


def test_a_camera_only_set_scene_moves_the_camera_without_rebuilding_the_controls(servers):
    """setScene with only another camera keeps the channel controls (built once, when the page
    opened) and the link follows the camera; a style change rebuilds them."""
    base, service = servers
    results, _ = drive(page(base, "u16x3", service), [{"do": "converge"}, {"do": "hash"}])
    scene, opened = scene_of(results[1]), results[0]
    assert opened["controls_built"] == 1, opened
    closer = json.loads(json.dumps(scene))
    cam = closer["camera"]
    cam["eye"] = [t + 0.75 * (e - t) for e, t in zip(cam["eye"], cam["target"])]
    recoloured = json.loads(json.dumps(closer))
    recoloured["channels"][0]["color"] = [1.0, 0.25, 0.0]
    results, console = drive(
        page(base, "u16x3", service),
        [
            {"do": "converge"},
            {"do": "hash"},
            {"do": "setScene", "scene": closer},
            {"do": "waitState", "when": "s.remote.requests_sent >= 2"},
            {"do": "converge"},
            {"do": "hash", "not": results[1]},
            {"do": "setScene", "scene": recoloured},
            {"do": "waitState", "when": "s.remote.requests_sent >= 3"},
            {"do": "converge"},
        ],
    )
    moved, fragment, restyled = results[4], results[5], results[8]
    assert moved["error"] is None and moved["converged"], moved
    assert moved["controls_built"] == 1, moved
    assert scene_of(fragment) == closer
    assert moved["remote"]["vdi_camera"] == closer["camera"]
    assert restyled["converged"] and restyled["controls_built"] == 2, restyled
    assert restyled["remote"]["scene_current"] and restyled["remote"]["drawn_request"] == 3, restyled
    assert errors(console) == []


def orbited(scene, degrees):
    """`scene` with its camera's eye turned `degrees` about its target, around its up axis."""
    moved = json.loads(json.dumps(scene))
    cam = moved["camera"]
    up = np.array(cam["up"], float)
    up /= np.linalg.norm(up)
    target = np.array(cam["target"], float)
    v = np.array(cam["eye"], float) - target
    a = np.radians(degrees)
    # Rodrigues' rotation of v about up.
    v = v * np.cos(a) + np.cross(up, v) * np.sin(a) + up * np.dot(up, v) * (1 - np.cos(a))
    cam["eye"] = (target + v).tolist()
    return moved


def vdi_render(vdi, scene, vdi_filter, out):
    """`viewer render --vdi VDI` of `scene`'s camera with `vdi_filter`, SIZE × SIZE, as a PNG."""
    return viewer_of_scene("render", scene, out, "--vdi", vdi, "--vdi-filter", vdi_filter)


def test_the_page_reads_a_vdi_with_the_filter_asked_for_from_a_moved_camera(servers, stores, tmp_path):
    """Opened with `?vdi_filter=linear`, the page draws the first VDI; the camera then turns
    20° while the service (through a proxy) answers 503 with `Retry-After: 60`, so the page
    keeps drawing the first VDI from the new camera: with the linear filter, as `viewer render
    --vdi --vdi-filter linear` draws that VDI there; after the *VDI filter* menu picks
    `nearest`, as the nearest filter draws it; and after it picks `auto`, at rest, with the
    linear filter again, without asking the service again. An unknown filter is refused with
    its name."""
    base, service = servers
    results, _ = drive(page(base, "u16x3", service), [{"do": "converge"}, {"do": "hash"}])
    scene = scene_of(results[1])
    moved = orbited(scene, 20.0)
    with ServiceProxy(service, failures=[None, (503, "60")]) as proxy:
        results, console = drive(
            page(base, "u16x3", proxy.url, extra="&vdi_filter=linear"),
            [
                {"do": "converge"},
                {"do": "setScene", "scene": moved},
                # Rested: the last frame drew the first VDI for the moved camera at full
                # resolution, while the request for that camera waits to be sent again.
                {"do": "waitState", "when": "s.remote.requests_retried >= 1 && s.remote.frame_current"},
                {"do": "snapshot", "path": str(tmp_path / "linear.png")},
                {"do": "select", "selector": "#vdi-filter", "value": "nearest"},
                {"do": "waitState", "when": "s.remote.vdi_filter === 'nearest' && s.remote.frame_current"},
                {"do": "snapshot", "path": str(tmp_path / "nearest.png")},
                {"do": "select", "selector": "#vdi-filter", "value": "auto"},
                {"do": "waitState", "when": "s.remote.vdi_filter === 'auto' && s.remote.frame_current"},
                {"do": "snapshot", "path": str(tmp_path / "auto.png")},
            ],
        )
        posts = proxy.posts()
    first, linear, nearest, auto = results[0], results[2], results[5], results[8]
    assert first["converged"] and first["remote"]["vdi_filter"] == "linear", first
    # Compiled while the first view rested (a frame at rest from the VDI's camera is drawn by
    # the nearest pipeline).
    assert first["remote"]["linear_compiled"], first
    for state, name, frame_filter in ((linear, "linear", "linear"), (nearest, "nearest", "nearest"),
                                      (auto, "auto", "linear")):
        remote = state["remote"]
        assert remote["vdi_filter"] == name and remote["frame_current"], remote
        assert remote["frame_filter"] == frame_filter, remote
        assert remote["vdi_camera"] == scene["camera"] and remote["d_i"] == 1.0, remote
        assert not remote["converged"] and not state["converged"], remote
        assert (remote["requests_sent"], remote["vdis_received"], remote["in_flight"]) == (2, 1, 2), remote
    assert auto["remote"]["frames"] > nearest["remote"]["frames"] > linear["remote"]["frames"]
    assert [p.status for p in posts] == [200, 503], posts

    # The service's VDI of the first view, made again here: the page drew it as `viewer render
    # --vdi` draws it from the moved camera, with each filter.
    vdi = viewer_of_scene("vdi", scene, tmp_path / "first.vdi", "--store", stores["u16x3"])
    want_linear = vdi_render(vdi, moved, "linear", tmp_path / "want-linear.png")
    want_nearest = vdi_render(vdi, moved, "nearest", tmp_path / "want-nearest.png")
    assert_matches(tmp_path / "linear.png", want_linear)
    assert_matches(tmp_path / "nearest.png", want_nearest)
    assert_matches(tmp_path / "auto.png", want_linear)
    # The two filters draw that view differently, so each match above says which was used.
    a = read_png(want_linear)[:, :, :3].astype(int)
    b = read_png(want_nearest)[:, :, :3].astype(int)
    assert np.abs(a - b).max() >= 16, np.abs(a - b).max()  # measured: 44 of 255
    assert errors(console, ["status of 503"]) == []

    results, _ = drive(page(base, "u16x3", service, extra="&vdi_filter=cubic"), [{"do": "waitMessage"}])
    assert results[0] == "?vdi_filter: unknown VDI filter 'cubic' (auto, nearest or linear)"


def test_auto_moves_with_the_linear_filter_where_its_frames_hold_the_target(servers):
    """Under `auto` (the default) a moving camera's frames read the VDI with the linear filter,
    at full resolution, where the last frame the linear filter drew at full resolution held the
    target frame time, and with the nearest list at the controller's D_I where it did not. The
    page draws the first VDI, the camera turns 20° while the service (through a proxy) answers
    503 with `Retry-After: 60` (so the first VDI stays drawn and the view rests on a frame the
    linear filter draws), then a drag turns it on: with 1 frame a second to hold, the drag's
    frames are linear and none is subsampled; with 1000, none is linear and they are
    subsampled."""
    base, service = servers
    results, _ = drive(page(base, "u16x3", service), [{"do": "converge"}, {"do": "hash"}])
    moved = orbited(scene_of(results[1]), 20.0)
    for fps in (1, 1000):
        with ServiceProxy(service, failures=[None] + [(503, "60")] * 8) as proxy:
            results, console = drive(
                page(base, "u16x3", proxy.url, extra=f"&target_fps={fps}"),
                [
                    {"do": "converge"},
                    {"do": "setScene", "scene": moved},
                    {"do": "waitState", "when": "s.remote.requests_retried >= 1 && s.remote.frame_current"},
                    # 12 px, about 7° of orbit, in moves 50 ms apart (a frame each).
                    {"do": "drag", "dx": 12, "dy": 0, "moves": 6, "delay_ms": 50},
                    {"do": "waitState", "when": "s.remote.frame_current"},
                ],
            )
        first, rested, dragged = results[0]["remote"], results[2]["remote"], results[4]["remote"]
        # From the VDI's own camera the nearest pipeline draws the frame at rest: nothing
        # learnt of the linear filter yet, so the frames of the turn read the nearest list.
        assert first["linear_frame_ms"] is None and first["moving_frames_linear"] == 0, first
        assert rested["frame_filter"] == "linear" and rested["moving_frames_linear"] == 0, rested
        assert 0 < rested["linear_frame_ms"] < 1000, rested
        assert rested["vdis_received"] == 1 and dragged["vdis_received"] == 1, dragged
        assert dragged["frames"] > rested["frames"], (rested, dragged)
        assert dragged["frame_filter"] == "linear" and dragged["d_i"] == 1.0, dragged
        if fps == 1:
            # Every frame since the rest was a moving linear one, and the last of them, at
            # full resolution with the filter at rest, is the frame at rest too.
            assert dragged["moving_frames_linear"] == dragged["frames"] - rested["frames"] >= 1, (rested, dragged)
            assert dragged["frames_subsampled"] == rested["frames_subsampled"], (rested, dragged)
        else:
            # On SwiftShader (a real GPU might draw it within the 1 ms, and 1.1 ms of slack).
            assert rested["linear_frame_ms"] > 1.1, rested
            assert dragged["moving_frames_linear"] == 0, dragged
            assert dragged["frames_subsampled"] > rested["frames_subsampled"], (rested, dragged)
        assert errors(console, ["status of 503"]) == []


def test_the_page_draws_zstd_vdis_as_the_dvr_image_and_refuses_an_unknown_compression(servers, stores, tmp_path):
    """Opened with `?vdi_compression=shuffled_zstd`, the page asks for zstd (every request),
    reads the service's zstd answer (zstd's C library compiled to WebAssembly) and draws it as
    DVR draws the view. An unknown compression is refused with its name."""
    base, service = servers
    results, console = drive(
        page(base, "u16x3", service, extra="&vdi_compression=shuffled_zstd"),
        [{"do": "converge"}, {"do": "hash"}, {"do": "snapshot", "path": str(tmp_path / "zstd.png")}],
    )
    state, fragment = results[0], results[1]
    assert state["error"] is None and state["converged"], state
    remote = state["remote"]
    assert (remote["vdi_compression"], remote["answer_compression"]) == ("shuffled_zstd", "shuffled_zstd"), remote
    assert remote["vdis_received"] == 1 and remote["last_error"] is None, remote
    assert_matches(tmp_path / "zstd.png", dvr(stores["u16x3"], scene_of(fragment), tmp_path / "dvr.png"))
    assert errors(console) == []

    results, _ = drive(page(base, "u16x3", service, extra="&vdi_compression=brotli"), [{"do": "waitMessage"}])
    assert results[0] == "?vdi_compression: unknown VDI compression 'brotli' (auto, shuffled_lz4 or shuffled_zstd)"


def test_auto_asks_for_zstd_once_an_answer_crossed_a_slow_link(servers, stores, tmp_path):
    """Under `auto` (the default) the first request asks for LZ4 (nothing is known of the
    link); its answer (about 340 KB here, over the 64 KiB that weigh the link) crosses a
    20 Mbit/s link (benchmarks/throttle_proxy.py), far below the 300 Mbit/s where zstd pays,
    so the request after an orbit asks for zstd, and its VDI is drawn as DVR draws the view.
    The zstd answer (about 200 KB) measures the link again. (The rate is timed from the body's
    first byte, which the proxy may pass on with the headers, so it reads somewhat above the
    link's.)"""
    base, service = servers
    host, port = urllib.parse.urlsplit(service).netloc.split(":")
    with ThrottleProxy((host, int(port)), mbit=20, rtt_ms=10) as proxy:
        results, _ = drive(page(base, "u16x3", f"http://127.0.0.1:{proxy.port}"), [{"do": "converge"}, {"do": "hash"}])
        first = results[0]
        moved = orbited(scene_of(results[1]), 20.0)
        results, console = drive(
            page(base, "u16x3", f"http://127.0.0.1:{proxy.port}"),
            [
                {"do": "converge"},
                {"do": "state"},
                {"do": "setScene", "scene": moved},
                {"do": "waitState", "when": "s.remote.requests_sent >= 2"},
                {"do": "converge"},
                {"do": "snapshot", "path": str(tmp_path / "zstd.png")},
            ],
        )
    before, after = results[1], results[4]
    for state in (first, before):
        remote = state["remote"]
        assert state["converged"] and remote["vdi_compression"] == "auto", state
        assert remote["answer_compression"] == "shuffled_lz4", remote
        assert remote["vdi_bytes_received"] >= 64 * 1024, remote
        assert 4 < remote["link_mbit_per_s"] < 150, remote
    remote = after["remote"]
    assert after["converged"] and remote["drawn_request"] == 2, after
    assert remote["answer_compression"] == "shuffled_zstd", remote
    # Asked by the rate the LZ4 answer measured.
    assert remote["request_link_mbit_per_s"] == before["remote"]["link_mbit_per_s"], remote
    zstd_bytes = remote["vdi_bytes_received"] - before["remote"]["vdi_bytes_received"]
    assert 64 * 1024 <= zstd_bytes < before["remote"]["vdi_bytes_received"], remote
    assert 4 < remote["link_mbit_per_s"] < 150 and remote["link_mbit_per_s"] != before["remote"]["link_mbit_per_s"], remote
    assert remote["vdi_camera"] == moved["camera"], remote
    assert_matches(tmp_path / "zstd.png", dvr(stores["u16x3"], moved, tmp_path / "dvr.png"))
    assert errors(console) == []


def moved_scene(base, service):
    """The page's default scene of u16x3 (as its link holds it) with the eye moved aside."""
    results, _ = drive(page(base, "u16x3", service), [{"do": "converge"}, {"do": "hash"}])
    moved = scene_of(results[1])
    moved["camera"]["eye"][0] += 0.5 * (moved["camera"]["eye"][0] - moved["camera"]["target"][0]) + 1.0
    return moved


def copy_of_web(tmp_path):
    """A copy of the web build in `tmp_path`, to change a file of."""
    web = tmp_path / "web"
    shutil.copytree(BIN / "web", web)
    return web


def test_an_answer_that_is_no_vdi_shows_the_decoders_message_and_the_next_one_is_drawn(servers):
    """Through a proxy that garbles the first VDI's magic, the page shows the message the
    decoder gave in the page's worker; the view moved (`setScene`, as the message box covers
    this small canvas), the next answer is read and drawn, and the message goes."""
    base, service = servers
    moved = moved_scene(base, service)
    with ServiceProxy(service, garble=1) as proxy:
        results, console = drive(
            page(base, "u16x3", proxy.url),
            [{"do": "waitMessage"}, {"do": "state"}, {"do": "setScene", "scene": moved},
             {"do": "converge"}, {"do": "message"}],
        )
        posts = proxy.posts()
    message, failed, _, drawn, after = results
    error = "its answer is not a VDI: the render service's answer: not a VDI (bad magic)"
    assert message == f"Render service {proxy.url}: {error}"
    remote = failed["remote"]
    assert (remote["last_error"], remote["vdis_received"], remote["vdi_decode_ms"]) == (error, 0, None), remote
    assert drawn["error"] is None and drawn["converged"], drawn
    remote = drawn["remote"]
    assert remote["last_error"] is None and remote["vdis_received"] >= 1, remote
    assert remote["vdi_decode_ms"] is not None and remote["drawn_request"] == remote["requests_sent"] == 2, remote
    assert remote["vdi_camera"] == moved["camera"], remote
    assert after is None
    assert [p.status for p in posts] == [200, 200], posts
    assert errors(console) == []


def drive_with_web(web, store, url, steps):
    """`drive` on a brickserver of `store` serving the viewer folder `web`."""
    brick, base = start_server(store, "--viewer-dir", web)
    try:
        return base, *drive(url(base), steps)
    finally:
        stop_server(brick)


def test_a_page_without_its_vdi_reader_says_so(stores, servers, tmp_path):
    """A viewer folder without vdi_worker.js (a deployment missing a file): the remote mode's
    error names the reader, and the page still draws from bricks with *Remote* off."""
    _, service = servers
    web = copy_of_web(tmp_path)
    (web / "vdi_worker.js").unlink()
    _, results, console = drive_with_web(
        web, stores["u16x3"], lambda base: page(base, "u16x3", service),
        [{"do": "waitMessage"}, {"do": "state"}, {"do": "click", "selector": "#remote"},
         {"do": "converge"}],
    )
    message, failed, _, local = results
    error = "the page's VDI reader (vdi_worker.js) failed: it did not load"
    assert message == f"Render service {service}: {error}"
    assert (failed["remote"]["last_error"], failed["remote"]["vdis_received"]) == (error, 0), failed
    assert local["error"] is None and local["converged"] and local["bricks_fetched"] > 0, local
    assert errors(console, ["vdi_worker.js", "404"]) == []


def test_a_reader_that_traps_is_replaced_and_the_next_answer_drawn(stores, servers, tmp_path):
    """A trap in the worker's WebAssembly while it reads (simulated: the worker's call throws
    a RuntimeError for request 1, as a panic or running out of memory would): the page shows
    the reader's failure, makes a new worker, and reads and draws the next view's answer."""
    base, service = servers
    moved = moved_scene(base, service)
    web = copy_of_web(tmp_path)
    worker = (web / "vdi_worker.js").read_text()
    call = "    read = read_vdi_answer(new Uint8Array(bytes));\n"
    assert call in worker
    (web / "vdi_worker.js").write_text(worker.replace(
        call, '    if (sequence === 1) throw new WebAssembly.RuntimeError("unreachable");\n' + call))
    base, results, console = drive_with_web(
        web, stores["u16x3"], lambda base: page(base, "u16x3", service),
        [{"do": "waitMessage"}, {"do": "state"}, {"do": "setScene", "scene": moved},
         {"do": "converge"}, {"do": "message"}, {"do": "workers"}],
    )
    message, failed, _, drawn, after, workers = results
    error = "the page's VDI reader (vdi_worker.js) failed: RuntimeError: unreachable"
    assert message == f"Render service {service}: {error}"
    remote = failed["remote"]
    assert (remote["last_error"], remote["vdis_received"]) == (error, 0), remote
    # The trapped answer's body was received whole: counted, and it measured the link.
    assert remote["vdi_bytes_received"] > 0 and remote["link_mbit_per_s"] is not None, remote
    assert drawn["error"] is None and drawn["converged"], drawn
    remote = drawn["remote"]
    assert (remote["last_error"], remote["vdis_received"], remote["drawn_request"]) == (None, 1, 2), remote
    assert remote["vdi_camera"] == moved["camera"], remote
    assert after is None
    assert workers == [f"{base}/viewer/vdi_worker.js"], workers
    assert errors(console) == []
