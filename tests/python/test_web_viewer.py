"""The Residency web viewer (viewer/src/web, viewer/web) in a real browser: Debian's Chromium,
headless, WebGPU on its SwiftShader adapter, driven by playwright-core
(tests/browser/web_viewer.mjs), against `brickserver serve` on loopback, which serves the page
at /NAME/view. Images are compared with `viewer reference` of the same scene, as the native
renderer's are.

Needs the web build (scripts/build-web.sh writes target/release/web, which brickserver finds
beside its binary)."""

import json
import pathlib
import re
import subprocess
import urllib.parse
import urllib.request

import numpy as np
import pytest

from support.binaries import run_ingest, start_server, stop_server
from support.browser import read_png as read_png_channels
from support.browser import require_browser, run_pausing
from support.paths import BIN, ROOT

pytestmark = pytest.mark.browser

DRIVER = ROOT / "tests" / "browser" / "web_viewer.mjs"
SIZE = 128



@pytest.fixture(autouse=True)
def browser_and_web_build():
    """Fails (skips with RESIDENCY_SKIP_BROWSER=1) without Chromium and Node; fails without
    the web build."""
    require_browser()
    assert (BIN / "web" / "index.html").exists(), f"{BIN}/web not built: run scripts/build-web.sh"


def read_png(path):
    """A PNG as a (height, width, 3) int array (alpha dropped)."""
    return read_png_channels(path)[:, :, :3].astype(int)


def drive(url, steps, on_pause=None, **spec):
    """Runs the page driver; returns (results, console messages). At each `pause` step it
    calls `on_pause(step index)`, then lets the page go on."""
    spec = {"url": url, "steps": steps, **spec}
    last, code, err = run_pausing(DRIVER, spec, on_pause, 600)
    assert code == 0, f"browser driver failed:\n{last}\n{err}"
    out = json.loads(last)
    return out["results"], out["console"]


def compare(image, reference):
    """`viewer compare --json`: PSNR (dB) and SSIM."""
    p = subprocess.run(
        [str(BIN / "viewer"), "compare", "--json", str(image), str(reference)],
        capture_output=True,
        text=True,
    )
    assert p.returncode == 0, p.stderr
    m = json.loads(p.stdout)
    return m["psnr_db"], m["ssim"]


def reference(store, scene, out):
    """`viewer reference` of `scene` (a dict) on `store`, SIZE × SIZE, level 0."""
    path = out.with_suffix(".scene.json")
    path.write_text(json.dumps(scene))
    p = subprocess.run(
        [str(BIN / "viewer"), "reference", "--store", str(store), "--scene", str(path),
         "--width", str(SIZE), "--height", str(SIZE), "--out", str(out)],
        capture_output=True,
        text=True,
        env={"XDG_RUNTIME_DIR": "/tmp", "PATH": "/usr/bin:/bin"},
    )
    assert p.returncode == 0, p.stderr
    return out


def scene_of(fragment):
    """The scene JSON of a `#scene=...` fragment."""
    assert fragment.startswith("#scene="), fragment
    return json.loads(urllib.parse.unquote(fragment[len("#scene="):]))


def metric(base, name):
    """One counter of the server's /metrics."""
    text = urllib.request.urlopen(f"{base}/metrics").read().decode()
    m = re.search(rf"^{re.escape(name)} (\S+)$", text, re.M)
    return float(m.group(1)) if m else 0.0


def errors(console):
    return [m for m in console if m.startswith("error") or m.startswith("pageerror")]


@pytest.fixture(scope="module")
def stores(tmp_path_factory):
    """Small stores: u8 and f32 with one channel, u16 with three, u16 with twenty."""
    d = tmp_path_factory.mktemp("web")
    out = {}
    run_ingest("sample", "-o", d / "fl", "--size", "24,40,40")
    run_ingest("convert", d / "fl" / "membranes.ome.tif", "-o", d / "u8.ome.zarr")
    run_ingest("convert", *(d / "fl" / f"{n}.ome.tif" for n in ("nuclei", "membranes", "filaments")),
               "-o", d / "u16x3.ome.zarr")
    run_ingest("sample", "--kind", "dense", "-o", d / "dense", "--size", "32,32,32")
    dense = next((d / "dense").glob("*.tif"))
    run_ingest("convert", dense, "-o", d / "f32.ome.zarr")
    run_ingest("sample", "--kind", "cycif", "-o", d / "cycif", "--size", "8,48,48", "--channels", "20")
    run_ingest("convert", *sorted((d / "cycif").glob("*.tif")), "-o", d / "u16x20.ome.zarr")
    for name in ("u8", "f32", "u16x3", "u16x20"):
        out[name] = d / f"{name}.ome.zarr"
    return out


@pytest.fixture(scope="module")
def served(stores):
    proc, base = start_server(*stores.values())
    yield base
    proc.terminate()
    proc.wait()


def view_url(base, name, fragment=""):
    return f"{base}/{name}/view?width={SIZE}&height={SIZE}{fragment}"


@pytest.mark.parametrize("name", ["u8", "f32", "u16x3"])
def test_converged_page_equals_the_reference(served, stores, name, tmp_path):
    results, console = drive(
        view_url(served, name),
        [{"do": "converge"}, {"do": "hash"}, {"do": "snapshot", "path": str(tmp_path / "page.png")}],
    )
    state, fragment, png = results
    assert state["error"] is None and state["converged"], state
    assert state["bricks_fetched"] > 0
    assert errors(console) == []
    ref = reference(stores[name], scene_of(fragment), tmp_path / "ref.exr")
    psnr, ssim = compare(png, ref)
    assert psnr >= 40.0 and ssim >= 0.99, (psnr, ssim)


def test_twenty_channels_render_sixteen_at_once(served, tmp_path):
    results, console = drive(
        view_url(served, "u16x20"),
        [{"do": "converge"}, {"do": "hash"}, {"do": "snapshot", "path": str(tmp_path / "p.png")}],
    )
    state, fragment, png = results
    assert state["error"] is None and state["converged"], state
    scene = scene_of(fragment)
    assert [c["visible"] for c in scene["channels"]] == [True] * 16 + [False] * 4
    pixels = read_png(pathlib.Path(png))
    assert (pixels.max(axis=2) > 16).mean() > 0.05  # not blank
    assert errors(console) == []


def test_a_drag_moves_the_camera_and_the_link_reopens_the_view(served, tmp_path):
    results, _ = drive(view_url(served, "u16x3"), [{"do": "converge"}, {"do": "hash"}])
    before = results[1]
    results, _ = drive(
        view_url(served, "u16x3"),
        [
            {"do": "converge"},
            {"do": "drag", "dx": 40, "dy": 10},
            {"do": "converge"},
            {"do": "hash", "not": before},
            {"do": "snapshot", "path": str(tmp_path / "dragged.png")},
        ],
    )
    after = results[3]
    assert scene_of(after)["camera"] != scene_of(before)["camera"]
    reopened, _ = drive(
        view_url(served, "u16x3", after),
        [{"do": "converge"}, {"do": "snapshot", "path": str(tmp_path / "reopened.png")}],
    )
    a = read_png(tmp_path / "dragged.png")
    b = read_png(tmp_path / "reopened.png")
    assert np.array_equal(a, b)


def test_shift_or_right_drag_pans_and_a_drag_orbits(served):
    """A left drag orbits: the target stays, and so does the eye's distance to it. A drag with
    Shift held, or with the right button, pans: eye and target move together, across the view,
    by the pixels dragged at the target's distance (`camera_control::pan`)."""
    steps = [{"do": "converge"}, {"do": "hash"}]
    for drag in ({"dx": 40, "dy": 0, "shift": True}, {"dx": 0, "dy": 30, "button": "right"},
                 {"dx": 30, "dy": 20}):
        # Converged, the fragment holds the view after the whole drag.
        steps += [{"do": "drag", **drag}, {"do": "converge"}, {"do": "hash"}]
    results, console = drive(view_url(served, "u8"), steps)
    cams = [scene_of(results[i])["camera"] for i in (1, 4, 7, 10)]
    vec = lambda c, k: np.array(c[k], dtype=np.float64)
    offset = lambda c: vec(c, "eye") - vec(c, "target")
    for before, after, pixels in ((cams[0], cams[1], 40), (cams[1], cams[2], 30)):
        np.testing.assert_allclose(offset(after), offset(before), atol=1e-9)
        moved = vec(after, "target") - vec(before, "target")
        d = np.linalg.norm(offset(before))
        per_pixel = 2 * d * np.tan(np.radians(before["fov_y_degrees"]) / 2) / SIZE
        assert np.linalg.norm(moved) == pytest.approx(pixels * per_pixel, rel=1e-9), (before, after)
        assert abs(np.dot(moved, offset(before))) < 1e-9 * d * np.linalg.norm(moved)
    orbit_before, orbit_after = cams[2], cams[3]
    assert orbit_after["target"] == pytest.approx(orbit_before["target"], abs=1e-9)
    assert np.linalg.norm(offset(orbit_after)) == pytest.approx(np.linalg.norm(offset(orbit_before)), rel=1e-9)
    assert not np.allclose(offset(orbit_after), offset(orbit_before))
    assert errors(console) == []


def test_each_channel_shows_its_histogram_in_log_counts(served):
    """Each channel's panel draws its histogram over the whole volume (the server's region
    metadata for the coarsest level): bin i a bar log(1 + count) / log(1 + largest count) of
    the canvas high, checked to the pixel at the middle of every bin at least 3 pixels wide."""
    results, console = drive(view_url(served, "u16x3"), [{"do": "opened"}, {"do": "histograms"}])
    info, canvases = results
    assert len(canvases) == len(info["channels"]) == 3, info["channels"]
    level = len(info["levels"]) - 1
    z, y, x = info["levels"][level]
    checked = 0
    for c, canvas in enumerate(canvases):
        q = urllib.parse.urlencode({"level": level, "channel": c, "min": "0,0,0", "max": f"{x},{y},{z}"})
        with urllib.request.urlopen(f"{served}/u16x3/regions?{q}", timeout=30) as r:
            hist = json.loads(r.read())["histogram"]
        edges, counts = hist["edges"], hist["counts"]
        finite = [e for e in edges if e is not None]
        x0, x1 = finite[0], finite[-1]
        w, h = canvas["width"], canvas["height"]
        at = lambda v: (min(x1, max(x0, v)) - x0) / (x1 - x0) * w
        top = np.log1p(max(max(counts), 1))
        for i, n in enumerate(counts):
            a = at(x0 if edges[i] is None else edges[i])
            b = at(x1 if edges[i + 1] is None else edges[i + 1])
            if b - a < 3:
                continue
            column = int((a + b) / 2)
            # Rows the bar covers whole (its top row is blended).
            assert canvas["bars"][column] == int(np.log1p(n) / top * h + 1e-9), (c, i, n, canvas["bars"][column])
            checked += 1
        assert max(canvas["bars"]) == h
    assert checked >= 30, checked
    assert errors(console) == []


def test_a_two_finger_pinch_zooms(served):
    """Touch: two fingers moving twice as far apart halve the camera's distance to its target
    and, pinching about the canvas centre, keep the target."""
    results, console = drive(
        view_url(served, "u8"),
        [{"do": "converge"}, {"do": "hash"}, {"do": "pinch", "scale": 2.0}, {"do": "converge"}, {"do": "hash"}],
    )
    before, after = scene_of(results[1])["camera"], scene_of(results[4])["camera"]
    distance = lambda c: float(np.linalg.norm(np.subtract(c["eye"], c["target"])))
    assert distance(after) / distance(before) == pytest.approx(0.5, rel=1e-9)
    assert after["target"] == pytest.approx(before["target"], abs=1e-9)
    assert results[3]["error"] is None and results[3]["converged"]
    assert errors(console) == []


def test_the_dataset_list_link_opens_the_viewer_as_a_click_would(served):
    """`GET /` in a browser is the HTML list of datasets; clicking a row's viewer link opens that
    dataset in the viewer, sized to the window (no ?width/height), and it converges."""
    results, console = drive(
        f"{served}/",
        [
            {"do": "clickLink", "row": "u8", "text": "open in the Residency viewer"},
            {"do": "location"},
            {"do": "converge"},
        ],
        viewport={"width": 560, "height": 300},
    )
    location, state = results[1], results[2]
    assert location == "/u8/view"
    assert state["error"] is None and state["converged"] and state["bricks_fetched"] > 0, state
    assert errors(console) == []


def test_hiding_a_channel_or_moving_a_window_fetches_no_brick(served, tmp_path):
    results, _ = drive(view_url(served, "u16x3"), [{"do": "converge"}, {"do": "hash"}])
    scene = scene_of(results[1])
    hidden = json.loads(json.dumps(scene))
    hidden["channels"][1]["visible"] = False
    windowed = json.loads(json.dumps(hidden))
    for p in windowed["channels"][0]["opacity"]:
        p["value"] = p["value"] * 0.5
    served_ok = []
    results, console = drive(
        view_url(served, "u16x3"),
        [
            {"do": "converge"},
            {"do": "snapshot", "path": str(tmp_path / "a.png")},
            {"do": "pause"},
            {"do": "setScene", "scene": hidden},
            {"do": "converge"},
            {"do": "snapshot", "path": str(tmp_path / "hidden.png")},
            {"do": "setScene", "scene": windowed},
            {"do": "converge"},
            {"do": "snapshot", "path": str(tmp_path / "windowed.png")},
            {"do": "pause"},
        ],
        on_pause=lambda i: served_ok.append(metric(served, 'brickserver_requests_total{class="2xx"}')),
    )
    # At the server: between the two pauses, only the first /metrics request itself.
    assert served_ok[1] - served_ok[0] == 1, served_ok
    first, after_hide, after_window = results[0], results[4], results[7]
    # In the page (cumulative counters): nothing more fetched, the renderer never rebuilt.
    for s in (after_hide, after_window):
        assert s["error"] is None and s["converged"], s
        assert s["bricks_fetched"] == first["bricks_fetched"]
        assert s["renderer_builds"] == 1
    a = read_png(tmp_path / "a.png")
    h = read_png(tmp_path / "hidden.png")
    w = read_png(tmp_path / "windowed.png")
    assert np.abs(a - h).max() > 8 and np.abs(h - w).max() > 8
    assert errors(console) == []


def choose_in_menu(served, name, menu, value, tmp_path):
    """Opens dataset `name`, converges, picks `value` in the page's `menu` and converges
    again; returns (the state after, the scene of the link, the image before, the image
    after, the console messages)."""
    results, console = drive(
        view_url(served, name),
        [
            {"do": "converge"},
            {"do": "snapshot", "path": str(tmp_path / "before.png")},
            {"do": "select", "selector": menu, "value": value},
            {"do": "converge"},
            {"do": "hash"},
            {"do": "snapshot", "path": str(tmp_path / "after.png")},
        ],
    )
    return results[3], scene_of(results[4]), tmp_path / "before.png", tmp_path / "after.png", console


def test_the_filter_menu_renders_tricubic_as_the_reference_does(served, stores, tmp_path):
    """Choosing *tricubic* in the page's Filter menu builds a new renderer whose converged
    image equals `viewer reference` of the scene the page then carries (`"filter":
    "tricubic"`), and differs from the trilinear image."""
    state, scene, lin_png, cub_png, console = choose_in_menu(served, "u8", "#filter", "tricubic", tmp_path)
    assert state["error"] is None and state["converged"], state
    assert state["renderer_builds"] == 2, state
    assert scene["filter"] == "tricubic"
    ref = reference(stores["u8"], scene, tmp_path / "ref.exr")
    psnr, ssim = compare(cub_png, ref)
    assert psnr >= 40.0 and ssim >= 0.99, (psnr, ssim)
    assert np.abs(read_png(lin_png) - read_png(cub_png)).max() > 8
    assert errors(console) == []


def test_the_mode_menu_renders_mip_as_the_reference_does(served, stores, tmp_path):
    """Choosing *maximum intensity projection* in the page's Mode menu builds a new renderer
    whose converged image equals `viewer reference` of the scene the page then carries
    (`"mode": "mip"`), and differs from the volume rendering."""
    state, scene, dvr_png, mip_png, console = choose_in_menu(served, "u16x3", "#mode", "mip", tmp_path)
    assert state["error"] is None and state["converged"], state
    assert state["renderer_builds"] == 2, state
    assert scene["mode"] == "mip"
    # As a PNG: channels add, and where they sum past 1 the linear EXR keeps what the page's
    # 8 bits clamp.
    ref = reference(stores["u16x3"], scene, tmp_path / "ref.png")
    psnr, ssim = compare(mip_png, ref)
    assert psnr >= 40.0 and ssim >= 0.99, (psnr, ssim)
    assert np.abs(read_png(dvr_png) - read_png(mip_png)).max() > 8
    assert errors(console) == []


def test_the_mode_menu_draws_iso_surfaces_as_the_native_renderer_does(served, stores, tmp_path):
    """Choosing *iso-surfaces* builds a new renderer whose converged image (`"mode": "iso"` in
    the link) equals `viewer render`'s of the same scene at the same size, and differs from the
    volume rendering."""
    state, scene, dvr_png, iso_png, console = choose_in_menu(served, "u16x3", "#mode", "iso", tmp_path)
    assert state["error"] is None and state["converged"], state
    assert state["renderer_builds"] == 2, state
    assert scene["mode"] == "iso"
    path = tmp_path / "scene.json"
    path.write_text(json.dumps(scene))
    p = subprocess.run(
        [str(BIN / "viewer"), "render", "--store", str(stores["u16x3"]), "--scene", str(path),
         "--width", str(SIZE), "--height", str(SIZE), "--out", str(tmp_path / "native.png")],
        capture_output=True, text=True, env={"XDG_RUNTIME_DIR": "/tmp", "PATH": "/usr/bin:/bin"},
    )
    assert p.returncode == 0, p.stderr
    psnr, ssim = compare(iso_png, tmp_path / "native.png")
    # Measured identical (PSNR infinite, reported as null) on SwiftShader against lavapipe.
    assert (psnr is None or psnr >= 40.0) and ssim >= 0.99, (psnr, ssim)
    assert np.abs(read_png(dvr_png) - read_png(iso_png)).max() > 8
    assert errors(console) == []


def test_the_clip_sliders_cut_the_volume_without_a_new_renderer(served, stores, tmp_path):
    """Moving the x slider's high end to half the extent, and the front cut in, clips the
    scene (`"clip"` in the link: the box, `near`): the same renderer draws it (no brick fetched
    that the whole view had not), and the converged image equals `viewer reference` of that
    scene, and differs from the whole volume's."""
    info_extent = [40 * 0.5, 40 * 0.5, 24 * 2.0]  # ingest sample's voxel size: 2, 0.5, 0.5 µm
    results, console = drive(
        view_url(served, "u8"),
        [
            {"do": "converge"},
            {"do": "snapshot", "path": str(tmp_path / "whole.png")},
            {"do": "slide", "selector": "#clip-x-max", "value": 0.5},
            {"do": "slide", "selector": "#clip-near", "value": 0.3},
            {"do": "converge"},
            {"do": "hash"},
            {"do": "snapshot", "path": str(tmp_path / "clipped.png")},
        ],
    )
    whole, state, fragment = results[0], results[4], results[5]
    assert state["error"] is None and state["converged"], state
    assert state["renderer_builds"] == 1, state
    assert state["bricks_fetched"] == whole["bricks_fetched"], (whole, state)
    scene = scene_of(fragment)
    assert scene["clip"]["box"] == {"min": [0.0, 0.0, 0.0], "max": [info_extent[0] / 2, info_extent[1], info_extent[2]]}
    assert scene["clip"]["near"] > 0 and "planes" not in scene["clip"], scene["clip"]
    ref = reference(stores["u8"], scene, tmp_path / "ref.exr")
    psnr, ssim = compare(tmp_path / "clipped.png", ref)
    assert psnr >= 40.0 and ssim >= 0.99, (psnr, ssim)
    assert np.abs(read_png(tmp_path / "whole.png") - read_png(tmp_path / "clipped.png")).max() > 8
    assert errors(console) == []


def expected_orientation(camera, height):
    """The scale bar and the axes the page should show for `camera` (its own rule, written
    again here from crate::scene's camera frame)."""
    eye, target = np.array(camera["eye"]), np.array(camera["target"])
    up = np.array(camera.get("up", [0.0, -1.0, 0.0]))
    forward = (target - eye) / np.linalg.norm(target - eye)
    right = np.cross(forward, up)
    right /= np.linalg.norm(right)
    up2 = np.cross(right, forward)
    per_pixel = 2 * np.linalg.norm(target - eye) * np.tan(np.radians(camera.get("fov_y_degrees", 30)) / 2) / height
    axes = {n: [float(right[i]), float(-up2[i])] for i, n in enumerate("xyz")}
    return per_pixel, axes


def test_the_orientation_shows_a_scale_bar_in_micrometres_and_axes_that_turn(served):
    """Over the view: a scale bar of a round length in the store's unit (the sample's
    micrometres), about 100 pixels long, and x, y, z axes drawn along the camera's projection of
    each; an orbit turns the axes and keeps the bar's rule."""
    results, console = drive(
        view_url(served, "u8"),
        [
            {"do": "converge"},
            {"do": "hash"},
            {"do": "orientation"},
            {"do": "drag", "dx": 50, "dy": 0},
            {"do": "converge"},
            {"do": "hash", "not": None},
            {"do": "orientation"},
        ],
    )
    for fragment, shown in ((results[1], results[2]), (results[5], results[6])):
        per_pixel, axes = expected_orientation(scene_of(fragment)["camera"], SIZE)
        scale = shown["scale"]
        assert scale["unit"] == "µm", scale
        mantissa = scale["length"] / 10 ** np.floor(np.log10(scale["length"]))
        assert round(mantissa, 9) in (1.0, 2.0, 5.0), scale
        assert scale["pixels"] == pytest.approx(scale["length"] / per_pixel, rel=1e-9), scale
        assert 100 / 1.6 <= scale["pixels"] <= 100 * 1.6, scale
        for name in "xyz":
            assert shown["axes"][name] == pytest.approx(axes[name], abs=1e-9), (name, shown["axes"])
    assert results[2]["axes"]["x"] != pytest.approx(results[6]["axes"]["x"], abs=1e-3)
    assert errors(console) == []


def test_missing_dataset_and_no_webgpu_show_their_messages(served):
    (msg,), _ = drive(f"{served}/nope/view", [{"do": "waitMessage"}])
    assert "Cannot open dataset 'nope'" in msg and "no such dataset on the server" in msg
    (msg,), _ = drive(view_url(served, "u8"), [{"do": "waitMessage"}], noWebGPU=True)
    assert msg.startswith("This browser has no WebGPU, which the Residency viewer needs.")


def test_the_page_opens_a_dataset_on_another_server(served, stores, tmp_path):
    """`/viewer/?server=URL&dataset=NAME` on one brickserver draws NAME from another one
    (another origin: the bricks cross it under brickserver's CORS), converged, as `viewer
    reference` draws it; without a dataset the page says how to name one. The other server
    serves the store as `elsewhere`, a name the page's own server does not have."""
    proc, other = start_server("--name", f"elsewhere={stores['u8']}")
    try:
        url = (f"{served}/viewer/?server={urllib.parse.quote(other, safe='')}&dataset=elsewhere"
               f"&width={SIZE}&height={SIZE}")
        results, console = drive(
            url, [{"do": "converge"}, {"do": "hash"}, {"do": "snapshot", "path": str(tmp_path / "page.png")}]
        )
        answered_by_other = metric(other, 'brickserver_requests_total{class="2xx"}')
    finally:
        stop_server(proc)
    state, fragment, png = results
    assert state["error"] is None and state["converged"], state
    assert state["bricks_fetched"] > 0, state
    assert answered_by_other > 0
    assert errors(console) == []
    psnr, ssim = compare(png, reference(stores["u8"], scene_of(fragment), tmp_path / "ref.exr"))
    assert psnr >= 40.0 and ssim >= 0.99, (psnr, ssim)
    (msg,), _ = drive(f"{served}/viewer/", [{"do": "waitMessage"}])
    assert msg == "no dataset: open /NAME/view on a brickserver, or add ?server=URL&dataset=NAME", msg


def test_a_server_that_goes_away_shows_a_message(stores):
    proc, base = start_server(stores["u16x3"])

    def stop(_):
        proc.terminate()
        proc.wait()

    try:
        results, _ = drive(
            view_url(base, "u16x3"),
            # Stopped once the page has opened the dataset, before its first frame asks for
            # bricks (a frame takes seconds on SwiftShader).
            [{"do": "opened"}, {"do": "pause"}, {"do": "waitMessage"}],
            on_pause=stop,
        )
    finally:
        if proc.poll() is None:
            stop(None)
    msg = results[2]
    assert "Is the brick server still running?" in msg, msg
    assert "cannot reach the brick server" in msg, msg
