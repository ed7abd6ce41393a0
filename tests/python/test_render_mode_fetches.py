"""What `viewer render --server` fetches in each mode and under clipping, logged by a proxy in
front of brickserver (the fault proxy with no faults, its request hook recording each path).
The store: 32³ voxels of uint8 in bricks of 8³, a bright slab (x < 8: 200 to 240) before dimmer
matter (at most 180), seen from the −x side, so every ray enters through the slab. The level
of detail wants level 0 everywhere (`--lod-bias -20`); a cold render first asks for the
coarsest level where nothing is resident, and what stands in lets rays learn their maxima and
surfaces before any level-0 brick is asked for. (With the levels pinned to 0 nothing stands in,
and a cold first frame asks for every brick along the rays: see docs/viewer.md.)

- Emission–absorption of a faint ramp fetches bricks at every x.
- Maximum intensity projection never fetches the last quarter along x: behind the slab no
  brick can raise a ray's maximum.
- Iso-surfaces at the slab's value stop at its surface: only the first bricks along x.
- A clip box x ≤ 12 keeps the rays out of every brick past x index 1."""

import re
import subprocess
import urllib.parse

import numpy as np
import pytest

from support.binaries import run_ingest, start_server, stop_server
from support.fault_proxy import FaultProxy
from support.paths import BIN

NAME = "front"


@pytest.fixture(scope="module")
def proxied(tmp_path_factory):
    """(the proxy's URL, the list its hook appends each request path to)."""
    d = tmp_path_factory.mktemp("modes")
    z, y, x = np.mgrid[0:32, 0:32, 0:32].astype(float)
    slab = 220.0 + 20.0 * np.sin((y + z) * 0.4)
    dim = 120.0 + 60.0 * np.sin(x * 0.5) * np.cos(y * 0.3 + z * 0.2)
    volume = np.where(x < 8, slab, dim).round().astype(np.uint8)
    raw = d / "front_32x32x32_uint8.raw"
    volume.tofile(raw)
    run_ingest("convert", raw, "-o", d / f"{NAME}.ome.zarr", "--chunk", "8", "--quiet")
    proc, base = start_server(d / f"{NAME}.ome.zarr")
    paths = []
    proxy = FaultProxy(base, fail_when=lambda _method, path: paths.append(path) or False)
    proxy.start()
    yield proxy.url, paths
    proxy.stop()
    stop_server(proc)


def fetched_along_x(proxied, tmp_path, *flags):
    """Renders through the proxy with `flags`; returns the x indices of the level-0 bricks the
    viewer fetched (from the batches' `b=level,channel,z,y,x` keys)."""
    url, paths = proxied
    paths.clear()
    p = subprocess.run(
        [str(BIN / "viewer"), "render", "--server", url, "--dataset", NAME,
         "--camera", "-40,16,16:16,16,16", "--lod-bias", "-20",
         "--width", "32", "--height", "32", "--out", str(tmp_path / "out.png"), *flags],
        capture_output=True, text=True, env={"XDG_RUNTIME_DIR": "/tmp", "PATH": "/usr/bin:/bin"},
        timeout=300,
    )
    assert p.returncode == 0, p.stderr
    assert "converged" in p.stderr, p.stderr
    xs = set()
    for path in paths:
        query = urllib.parse.urlsplit(path).query
        for value in urllib.parse.parse_qs(query).get("b", []):
            for key in re.split(r"[;]", value):
                level, _channel, _z, _y, bx = map(int, key.split(","))
                if level == 0:
                    xs.add(bx)
    return sorted(xs)


def test_dvr_fetches_bricks_at_every_x(proxied, tmp_path):
    assert fetched_along_x(proxied, tmp_path, "--tf", "0:100:255:0.02") == [0, 1, 2, 3]


def test_mip_never_fetches_what_cannot_raise_a_rays_maximum(proxied, tmp_path):
    xs = fetched_along_x(proxied, tmp_path, "--tf", "0:100:255:0.02", "--mode", "mip")
    assert xs == [0, 1, 2], xs


def test_iso_surfaces_stop_at_the_first_surface(proxied, tmp_path):
    xs = fetched_along_x(proxied, tmp_path, "--tf", "0:190:210:0.02", "--mode", "iso")
    assert xs == [0], xs


def test_clipping_keeps_the_rays_out_of_the_bricks_it_cuts(proxied, tmp_path):
    for mode in ("dvr", "mip", "iso"):
        xs = fetched_along_x(proxied, tmp_path, "--tf", "0:100:255:0.02", "--mode", mode,
                             "--clip-box", "0,0,0,12,32,32")
        assert xs and max(xs) <= 1, (mode, xs)
