"""Any OME-Zarr viewer, shown rather than claimed: stores written by `ingest` (OME-Zarr 0.4 on
Zarr v2, 0.5 on Zarr v3, 0.5 sharded) and served by `brickserver serve` open in two viewers
nobody here wrote, in headless Chromium (tests/python/support/browser.py):

- neuroglancer: the static client of the `neuroglancer` PyPI package, served from loopback,
  opened with the `#!` state of the link that brickserver's /datasets gives (what a user clicks);
- Viv (`@hms-dbmi/viv`): a tiny page (tests/browser/viv) bundled with esbuild that opens the
  store with Viv's `loadOmeZarr` and shows its middle z plane with the omero window.

The volume is u16 with a dim background (100..300) and a bright cube (2000..3000) in the
top-right corner of every plane through its middle (small y, large x). Each check screenshots
the view and compares it with what zarr-python reads: the view must not be blank or saturated
(the fraction of bright pixels is close to the fraction of voxels above the middle of the omero
window, so a missing display range, which leaves u16 data black, fails), and its brightest
quadrant must be the one where the data's is (so a flipped or transposed axis fails). Where the
data lands on screen is computed from the state each viewer reports (position and zoom)."""

import importlib.util
import json
import pathlib
import signal
import urllib.parse

import numpy as np
import pytest
import requests
import zarr

from support.binaries import run_ingest, start_server
from support.browser import StaticServer, read_png, require_browser, run_node
from support.stores import root_attributes

pytestmark = pytest.mark.browser

SHAPE = (64, 64, 64)  # z, y, x
CUBE = (slice(12, 52), slice(4, 28), slice(36, 60))  # top right in an x-right, y-down view
FORMS = {
    "v04": ["--ome-zarr-version", "0.4"],
    "v05": [],
    "sharded": ["--shard", "32"],
}
VIEW = 512  # page width and height, CSS pixels = screenshot pixels
NG_SCALE = 0.25  # neuroglancer crossSectionScale: voxels per screen pixel (64 voxels: 256 px)
# Other than the data: the Python-integration build of neuroglancer polls its (absent) Python
# server, and zarrita probes for Zarr v2 and v3 metadata; both show as 404s in the console.
EXPECTED_404 = ("Failed to load resource: the server responded with a status of 404",)


@pytest.fixture(scope="module", autouse=True)
def _browser_available():
    """Fails (or skips, RESIDENCY_SKIP_BROWSER=1) before building anything if the browser is missing."""
    require_browser()


def volume():
    rng = np.random.default_rng(7)
    v = rng.integers(100, 300, SHAPE, dtype=np.uint16)
    v[CUBE] = rng.integers(2000, 3000, v[CUBE].shape, dtype=np.uint16)
    return v


@pytest.fixture(scope="module")
def stores(tmp_path_factory):
    """The same volume in the three forms, by dataset name."""
    d = tmp_path_factory.mktemp("peers")
    raw = d / f"cube_{SHAPE[2]}x{SHAPE[1]}x{SHAPE[0]}_uint16.raw"
    volume().tofile(raw)
    out = {}
    for name, args in FORMS.items():
        store = d / f"{name}.ome.zarr"
        run_ingest("convert", raw, "-o", store, "--chunk", "16", "--quiet", *args)
        out[name] = store
    assert (out["v04"] / ".zattrs").exists() and (out["v05"] / "zarr.json").exists()
    shard_meta = json.loads((out["sharded"] / "0" / "zarr.json").read_text())
    assert shard_meta["codecs"][0]["name"] == "sharding_indexed"
    return out


@pytest.fixture(scope="module")
def served(stores):
    """brickserver on loopback; yields its /datasets entries by name."""
    proc, base = start_server(*stores.values())
    try:
        listing = requests.get(f"{base}/datasets", timeout=10).json()["datasets"]
        yield {d["name"]: d for d in listing}
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.wait(timeout=10)


def neuroglancer_client_dir():
    spec = importlib.util.find_spec("neuroglancer")
    client = pathlib.Path(spec.submodule_search_locations[0]) / "static" / "client" if spec else None
    if client is None or not (client / "index.html").exists():
        pytest.fail("the neuroglancer PyPI package (with its static client) is not installed: run scripts/setup.sh")
    return client


@pytest.fixture(scope="module")
def neuroglancer_client():
    """The neuroglancer client on loopback. It is the package's Python-integration build, which
    wants its page under /v/TOKEN/; with a #! state in the URL it shows that state (its attempts
    to reach the Python server only log)."""
    with StaticServer({"/v/residency/": neuroglancer_client_dir()}) as server:
        yield server.url("/v/residency/")


@pytest.fixture(scope="module")
def viv_page(tmp_path_factory):
    """The Viv page, bundled with esbuild, on loopback."""
    out = tmp_path_factory.mktemp("viv")
    run_node("viv/build.mjs", {"out": str(out)})
    assert (out / "viv.js").stat().st_size > 100_000
    with StaticServer({"/": out}) as server:
        yield server.url("/index.html")


# --- what the view should show ------------------------------------------------------------


def omero_window(store):
    attrs = root_attributes(store)
    window = attrs.get("ome", attrs)["omero"]["channels"][0]["window"]
    return window["start"], window["end"]


def axis_names(store):
    attrs = root_attributes(store)
    return [a["name"] for a in attrs.get("ome", attrs)["multiscales"][0]["axes"]]


def plane(store, horizontal, vertical, fixed):
    """Level 0 of channel 0 as a 2D array (vertical, horizontal), the other spatial axis at
    `fixed` ({name: index}), read with zarr-python."""
    names = axis_names(store)
    data = zarr.open_group(str(store), mode="r")["0"][...]
    index = tuple(0 if n == "c" else fixed.get(n, slice(None)) for n in names)
    kept = [n for n in names if n != "c" and n not in fixed]
    a = data[index]
    return a if kept == [vertical, horizontal] else a.T


def quadrant_means(a):
    """Means of the top-left, top-right, bottom-left, bottom-right quadrants of a 2D array."""
    h, w = a.shape[0] // 2, a.shape[1] // 2
    return np.array([a[:h, :w].mean(), a[:h, w:].mean(), a[h:, :w].mean(), a[h:, w:].mean()])


QUADRANTS = ["top left", "top right", "bottom left", "bottom right"]


def check_view(shot, box, data, window, what):
    """`shot`: the screenshot (RGB[A]); `box`: (x0, y0, x1, y1), where the data's extent lies
    in it; `data`: the 2D plane shown (vertical, horizontal), as zarr-python reads it."""
    x0, y0, x1, y1 = box
    h, w = shot.shape[:2]
    assert 0 <= x0 < x1 <= w and 0 <= y0 < y1 <= h, f"{what}: the data ({box}) is not all in view ({w}x{h})"
    # A margin of 2 screen pixels keeps edges (outlines, half-covered pixels) out.
    crop = shot[int(np.ceil(y0)) + 2:int(y1) - 2, int(np.ceil(x0)) + 2:int(x1) - 2, :3].max(axis=2).astype(np.float64)
    start, end = window
    bright_data = (data.astype(np.float64) > (start + end) / 2).mean()
    bright_seen = (crop > 96).mean()
    want = quadrant_means(data.astype(np.float64))
    seen = quadrant_means(crop)
    expected = int(np.argmax(want))
    others = np.delete(seen, expected)
    assert bright_data > 0.05 and want[expected] > 4 * np.delete(want, expected).max()  # the data's own contrast
    report = (
        f"{what}: bright pixels {bright_seen:.3f} (data: {bright_data:.3f}); quadrant means "
        f"{np.round(seen, 1).tolist()} (data: {np.round(want, 1).tolist()}), expected brightest: "
        f"{QUADRANTS[expected]}"
    )
    assert 0.5 * bright_data <= bright_seen <= 1.5 * bright_data, f"blank, dim or saturated: {report}"
    assert int(np.argmax(seen)) == expected, f"wrong quadrant: {report}"
    assert seen[expected] >= 64 and seen[expected] >= 4 * others.max(), f"too little contrast: {report}"


# --- neuroglancer -------------------------------------------------------------------------

# Every data source of every layer: "loaded", "error: MESSAGE", or null while loading.
NG_SOURCES = """
  viewer.layerManager.managedLayers.flatMap((ml) =>
    (ml.layer?.dataSources ?? [null]).map((ds) =>
      !ds || ds.loadState === undefined ? null
        : ds.loadState.error ? `error: ${ds.loadState.error.message}` : "loaded"))
"""


def neuroglancer_steps(shot):
    sources = f"(() => {{ const s = {NG_SOURCES}; return s.length && s.every((x) => x) ? s : null; }})()"
    return [
        {"do": "waitFor", "js": f"window.viewer && {sources}", "timeout_s": 60},
        # A deterministic view, as a user would set it from the toolbar: one 2D panel of the
        # x/y plane (at the position the link gives), 4 screen pixels per voxel, without axis
        # lines, bounding box and scale bar. The layers stay as the link made them. The status
        # line ("Disconnected from Python server. Retrying in N seconds.", from the Python build
        # standing alone) is hidden: it overlaps the panel and changes every second.
        {
            "do": "eval",
            "arg": NG_SCALE,
            "js": """(() => {
              const style = document.createElement("style");
              style.textContent = ".neuroglancer-status-container { display: none !important; }";
              document.head.append(style);
              viewer.layout.restoreState("xy");
              viewer.displayDimensions.restoreState(["x", "y", "z"]);
              viewer.crossSectionScale.restoreState(arg);
              viewer.showAxisLines.value = false;
              viewer.showDefaultAnnotations.value = false;
              viewer.showScaleBar.value = false;
              return true;
            })()""",
        },
        {"do": "waitFor", "js": f"viewer.isReady() || {NG_SOURCES}.some((s) => s !== 'loaded')", "timeout_s": 60},
        {"do": "stable", "selector": ".neuroglancer-rendered-data-panel", "path": str(shot), "timeout_s": 60},
        {
            "do": "eval",
            "js": """({
              ready: viewer.isReady(),
              state: viewer.state.toJSON(),
              panel: (() => {
                const r = document.querySelector(".neuroglancer-rendered-data-panel").getBoundingClientRect();
                return { x: r.x, y: r.y, width: r.width, height: r.height };
              })(),
            })""",
        },
    ]


@pytest.mark.slow
@pytest.mark.parametrize("name", list(FORMS))
def test_neuroglancer_opens_the_link_and_shows_the_bright_corner(name, stores, served, neuroglancer_client, browser_session, tmp_path):
    link = served[name]["neuroglancer"]
    fragment = urllib.parse.urlsplit(link).fragment
    assert fragment.startswith("!"), link
    shot = tmp_path / "neuroglancer.png"
    out = browser_session.run_page(f"{neuroglancer_client}#{fragment}", neuroglancer_steps(shot), width=VIEW, height=VIEW)
    sources, _, _, stable, final = out.results
    assert sources == ["loaded"], f"neuroglancer cannot open {link}: {sources}"
    assert final["ready"], final
    state, panel = final["state"], final["panel"]
    dims = list(state["dimensions"])
    assert sorted(dims) == ["x", "y", "z"], state["dimensions"]
    assert all(state["dimensions"][d] == [1, ""] for d in dims), state["dimensions"]  # voxel units
    assert state.get("crossSectionOrientation") in (None, [0, 0, 0, 1]), state
    position = dict(zip(dims, state["position"]))
    scale = state["crossSectionScale"]
    assert scale == pytest.approx(NG_SCALE)
    # The panel's centre shows `position`; x grows to the right, y downwards, a voxel i spans
    # [i, i + 1) in these coordinates, and the plane shown is the voxel holding position z.
    store = stores[name]
    extent = dict(zip(["z", "y", "x"], SHAPE))
    shot_box = stable["box"]
    cx = panel["x"] + panel["width"] / 2 - shot_box["x"]
    cy = panel["y"] + panel["height"] / 2 - shot_box["y"]
    box = (
        cx + (0 - position["x"]) / scale, cy + (0 - position["y"]) / scale,
        cx + (extent["x"] - position["x"]) / scale, cy + (extent["y"] - position["y"]) / scale,
    )
    z = int(np.clip(np.floor(position["z"]), 0, extent["z"] - 1))
    data = plane(store, "x", "y", {"z": z})
    check_view(read_png(shot), box, data, omero_window(store), f"neuroglancer {name} (z={z})")


# --- Viv ----------------------------------------------------------------------------------


def viv_steps(shot):
    return [
        {"do": "waitFor", "js": "window.viv && window.viv.status !== 'loading' ? window.viv.status : null", "timeout_s": 60},
        {"do": "frames", "n": 3},
        {"do": "stable", "selector": "#viewer", "path": str(shot), "timeout_s": 60},
        {"do": "eval", "js": "window.viv"},
    ]


@pytest.mark.slow
@pytest.mark.parametrize("name", list(FORMS))
def test_viv_shows_the_bright_corner(name, stores, served, viv_page, browser_session, tmp_path):
    source = served[name]["url"]
    shot = tmp_path / "viv.png"
    url = f"{viv_page}?" + urllib.parse.urlencode({"source": source, "width": VIEW, "height": VIEW})
    out = browser_session.run_page(url, viv_steps(shot), width=VIEW, height=VIEW)
    status, _, _, viv = out.results
    assert status == "loaded" and viv["error"] is None, viv
    assert out.console_errors(ignore=EXPECTED_404) == []
    assert viv["labels"] == ["c", "z", "y", "x"] and viv["shape"] == [1, *SHAPE] and viv["dtype"] == "Uint16"
    store = stores[name]
    assert viv["contrastLimits"] == [list(omero_window(store))]
    (tx, ty, _), zoom = viv["viewState"]["target"], viv["viewState"]["zoom"]
    k = 2.0 ** zoom  # screen pixels per image pixel; the target at the canvas' centre
    cx, cy = viv["width"] / 2, viv["height"] / 2
    box = (cx - tx * k, cy - ty * k, cx + (SHAPE[2] - tx) * k, cy + (SHAPE[1] - ty) * k)
    data = plane(store, "x", "y", {"z": viv["z"]})
    check_view(read_png(shot), box, data, omero_window(store), f"Viv {name} (z={viv['z']})")


def test_viv_without_z_mapping_indexes_past_coarse_levels(stores, served, viv_page, browser_session):
    """Viv as it is (hms-dbmi/viv#901): its 2D layers ask every pyramid level for the level-0
    plane, and our pyramid halves z too (64, 32, 16 planes), so the middle plane (32) is past
    the end of the coarsest level, which Viv always loads as the background image. This is the
    peer's limit (vizarr maps z per level; so does our Viv page unless zmap=none)."""
    url = f"{viv_page}?" + urllib.parse.urlencode({"source": served["v05"]["url"], "zmap": "none"})
    out = browser_session.run_page(
        url,
        [{"do": "waitFor", "js": "window.viv?.error", "timeout_s": 60}, {"do": "eval", "js": "window.viv"}],
        width=VIEW, height=VIEW,
    )
    error, viv = out.results
    assert viv["z"] == 32 and viv["shape"] == [1, *SHAPE]
    assert error == "index out of bounds for dimension with length 16", viv
