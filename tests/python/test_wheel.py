"""The `residency` wheel (scripts/build-wheel.sh, python/pyproject.toml) installed by pip into a
fresh virtual environment whose PATH holds no Rust toolchain, and the tour run from there:
`ingest sample`, `ingest convert`, `brickserver serve` read by zarr-python, `viewer render` on
lavapipe, and the page the wheel's server serves opened in Chromium. What the wheel's programs
write is byte for byte what the workspace's build writes; the Python API (`residency`) answers
as the command line does, errors included.

Needs target/wheels/residency-*.whl (scripts/build-wheel.sh; scripts/test.sh builds it)."""

import json
import os
import re
import shutil
import subprocess
import sys
import time
import tomllib
import zipfile
from types import SimpleNamespace

import numpy as np
import pytest
import requests
import tifffile
import zarr

from support.browser import require_browser, run_pausing
from support.paths import BIN, ROOT
from support.readme import sections, sh_blocks

WHEELS = ROOT / "target" / "wheels"
DRIVER = ROOT / "tests" / "browser" / "web_viewer.mjs"
# The README's bound on the wheel's size (it says "under 50 MB").
MAX_WHEEL_BYTES = 50_000_000


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """The wheel pip-installed into a new virtual environment of the interpreter the tests run
    on, offline (its one dependency, numpy, from target/wheels/deps); its environment for
    subprocesses: PATH is the environment's bin and the system's folders only, no Cargo or
    rustup variables."""
    wheels = sorted(WHEELS.glob("residency-*.whl"))
    assert len(wheels) == 1, f"{WHEELS} holds {wheels}: run scripts/build-wheel.sh"
    root = tmp_path_factory.mktemp("wheel") / "env"
    base = getattr(sys, "_base_executable", sys.executable)
    subprocess.run([base, "-m", "venv", root], check=True)
    env = {k: v for k, v in os.environ.items() if not k.startswith(("CARGO", "RUSTUP", "RUST"))}
    env.pop("VIRTUAL_ENV", None)
    env["PATH"] = f"{root / 'bin'}:/usr/local/bin:/usr/bin:/bin"
    env.setdefault("XDG_RUNTIME_DIR", "/tmp")
    start = time.monotonic()
    p = subprocess.run([root / "bin" / "pip", "install", "--no-index", "--find-links", WHEELS / "deps", "-q", wheels[0]],
                       env=env, capture_output=True, text=True)
    install_s = time.monotonic() - start
    assert p.returncode == 0, p.stderr
    print(f"\n{wheels[0].name}: {wheels[0].stat().st_size / 2**20:.1f} MiB, installed in {install_s:.1f} s")
    return SimpleNamespace(root=root, bin=root / "bin", env=env, wheel=wheels[0])


def run(installed, *args, check=True):
    """Runs a program of the environment (`args[0]` in its bin) with its environment."""
    p = subprocess.run([installed.bin / args[0], *map(str, args[1:])], env=installed.env,
                       capture_output=True, text=True)
    if check:
        assert p.returncode == 0, f"{args}: {p.stderr}"
    return p


def run_workspace(*args):
    """Runs a program of the workspace's build (target/release)."""
    p = subprocess.run([BIN / args[0], *map(str, args[1:])], capture_output=True, text=True)
    assert p.returncode == 0, f"{args}: {p.stderr}"
    return p


def files(folder):
    """Every file under `folder` by its relative path, with its bytes."""
    return {str(f.relative_to(folder)): f.read_bytes() for f in sorted(folder.rglob("*")) if f.is_file()}


def test_the_wheel_holds_the_programs_the_page_and_the_package(installed):
    names = zipfile.ZipFile(installed.wheel).namelist()
    version = tomllib.loads((ROOT / "Cargo.toml").read_text())["workspace"]["package"]["version"]
    data = f"residency-{version}.data"
    for name in ("ingest", "brickserver", "viewer"):
        assert f"{data}/scripts/{name}" in names, names
    assert f"{data}/data/share/residency/web/index.html" in names
    assert {"residency/__init__.py", "residency/_native.pyi", "residency/py.typed"} <= set(names)
    assert installed.wheel.stat().st_size < MAX_WHEEL_BYTES, installed.wheel.stat().st_size
    # The platform the README names: CPython 3.10 or newer (abi3), and its glibc.
    glibc = re.search(r"with glibc (\d+)\.(\d+) or newer", (ROOT / "README.md").read_text())
    assert glibc, "the README names no glibc"
    assert installed.wheel.name.endswith(f"-cp310-abi3-manylinux_{glibc[1]}_{glibc[2]}_x86_64.whl"), installed.wheel.name
    # No Rust toolchain where the environment's programs run.
    for tool in ("cargo", "rustc", "rustup"):
        assert shutil.which(tool, path=installed.env["PATH"]) is None, tool
    # The programs are on the PATH, the page under the environment's share folder.
    for name in ("ingest", "brickserver", "viewer"):
        assert shutil.which(name, path=installed.env["PATH"]) == str(installed.bin / name)
    assert (installed.root / "share" / "residency" / "web" / "index.html").is_file()
    p = run(installed, "python", "-c", "import residency; print(residency.__version__)")
    assert p.stdout == f"{version}\n"


def test_the_tour_runs_from_the_wheel_and_writes_what_the_build_writes(installed, tmp_path):
    wheel, build = tmp_path / "wheel", tmp_path / "build"
    # ingest sample: the same TIFF stacks.
    run(installed, "ingest", "sample", "-o", wheel / "sample", "--size", "16,48,48")
    run_workspace("ingest", "sample", "-o", build / "sample", "--size", "16,48,48")
    assert files(wheel / "sample") == files(build / "sample")
    tiffs = [f"{n}.ome.tif" for n in ("nuclei", "membranes", "filaments")]
    # ingest convert: the same store, byte for byte.
    run(installed, "ingest", "convert", *(wheel / "sample" / t for t in tiffs), "-o", wheel / "tour.ome.zarr", "--chunk", "16")
    run_workspace("ingest", "convert", *(build / "sample" / t for t in tiffs), "-o", build / "tour.ome.zarr", "--chunk", "16")
    assert files(wheel / "tour.ome.zarr") == files(build / "tour.ome.zarr")
    # viewer render on lavapipe: the same PNG.
    flags = ["--width", "64", "--height", "48", "--camera", "30,20,1.6"]
    run(installed, "viewer", "render", "--store", wheel / "tour.ome.zarr", *flags, "--out", wheel / "tour.png")
    run_workspace("viewer", "render", "--store", build / "tour.ome.zarr", *flags, "--out", build / "tour.png")
    assert (wheel / "tour.png").read_bytes() == (build / "tour.png").read_bytes()
    # brickserver serve: zarr-python reads every level over HTTP as from the folder, and the
    # page's files come from the environment's share folder.
    server, base = start(installed, wheel / "tour.ome.zarr")
    try:
        remote = zarr.open_group(f"{base}/tour/", mode="r")
        local = zarr.open_group(str(wheel / "tour.ome.zarr"), mode="r")
        levels = [d["path"] for d in local.attrs["ome"]["multiscales"][0]["datasets"]]
        assert len(levels) >= 2, levels
        for level in levels:
            np.testing.assert_array_equal(remote[level][...], local[level][...])
        web = installed.root / "share" / "residency" / "web"
        page = requests.get(f"{base}/tour/view", timeout=10)
        assert page.status_code == 200, page.text[:200]
        assert page.text == (web / "index.html").read_text().replace("%VIEWER_BASE%", "../viewer/")
        wasm = requests.get(f"{base}/viewer/residency_viewer_bg.wasm", timeout=10)
        assert wasm.status_code == 200 and wasm.content == (web / "residency_viewer_bg.wasm").read_bytes()
    finally:
        stop(server)


def start(installed, *stores):
    """`brickserver serve STORES --bind 127.0.0.1:0` from the environment; (process, base URL)."""
    proc = subprocess.Popen([installed.bin / "brickserver", "serve", *map(str, stores), "--bind", "127.0.0.1:0"],
                            env=installed.env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    for line in proc.stdout:
        if line.startswith("listening on "):
            return proc, line.split("listening on ")[1].strip()
    raise AssertionError(f"the wheel's brickserver did not start:\n{proc.stderr.read()}")


def stop(proc):
    """Stops a server `start` started, and checks it is gone."""
    proc.terminate()
    assert proc.wait(timeout=10) == 0


@pytest.mark.browser
def test_the_page_the_wheels_server_serves_converges_in_chromium(installed, tmp_path):
    require_browser()
    run(installed, "ingest", "sample", "-o", tmp_path / "sample", "--size", "16,48,48")
    run(installed, "ingest", "convert", tmp_path / "sample" / "nuclei.ome.tif", "-o", tmp_path / "page.ome.zarr", "--quiet")
    server, base = start(installed, tmp_path / "page.ome.zarr")
    try:
        spec = {"url": f"{base}/page/view?width=96&height=96", "steps": [{"do": "converge"}]}
        last, code, err = run_pausing(DRIVER, spec, None, 600)
        assert code == 0, f"browser driver failed:\n{last}\n{err}"
        out = json.loads(last)
        [state] = out["results"]
        assert state["error"] is None and state["converged"] and state["bricks_fetched"] > 0, state
        assert [m for m in out["console"] if m.startswith(("error", "pageerror"))] == []
    finally:
        stop(server)


def test_inspect_from_python_prints_what_ingest_inspect_prints(installed, tmp_path):
    run(installed, "ingest", "sample", "-o", tmp_path / "sample", "--size", "16,32,32")
    store = tmp_path / "x.ome.zarr"
    run(installed, "ingest", "convert", tmp_path / "sample" / "membranes.ome.tif", "-o", store, "--quiet")
    cli = run(installed, "ingest", "inspect", store).stdout
    assert "region metadata" in cli, cli
    api = run(installed, "python", "-c", f"import residency, sys; sys.stdout.write(residency.inspect({str(store)!r}))")
    assert api.stdout == cli
    # A failure: the exception's message is the command line's, after its `error: `.
    missing = tmp_path / "missing.ome.zarr"
    cli = run(installed, "ingest", "inspect", missing, check=False)
    assert cli.returncode != 0 and cli.stderr.startswith("error: "), cli.stderr
    api = run(installed, "python", "-c", f"""
import residency
try:
    residency.inspect({str(missing)!r})
except residency.ResidencyError as e:
    print(type(e).__name__, e)
""")
    assert api.stdout == f"ResidencyError {cli.stderr.removeprefix('error: ')}", (api.stdout, cli.stderr)


REGIONS_SCRIPT = """
import json, sys
import numpy as np
import residency
r = residency.regions(sys.argv[1], int(sys.argv[2]), int(sys.argv[3]))
np.savez(sys.argv[4], **{k: v for k, v in r.items() if isinstance(v, np.ndarray)})
print(json.dumps({k: (str(v.dtype), v.shape) if isinstance(v, np.ndarray) else v for k, v in r.items()}))
"""


def test_regions_from_python_are_the_stores_region_arrays(installed, tmp_path):
    """`residency.regions` gives what zarr-python reads from the arrays the store's `residency`
    attributes name: the finest min/max grid with its halo and exact, and the brick histograms
    with the channel's bin edges."""
    run(installed, "ingest", "sample", "-o", tmp_path / "sample", "--size", "16,48,48")
    store = tmp_path / "r.ome.zarr"
    run(installed, "ingest", "convert", *(tmp_path / "sample" / f"{n}.ome.tif" for n in ("nuclei", "filaments")),
        "-o", store, "--chunk", "16", "--quiet")
    group = zarr.open_group(str(store), mode="r")
    meta = group.attrs["residency"]
    assert len(meta["levels"]) >= 2 and len(meta["channels"]) == 2
    for level, channel in [(0, 0), (0, 1), (1, 1)]:
        out = tmp_path / f"r{level}{channel}.npz"
        p = run(installed, "python", "-c", REGIONS_SCRIPT, store, level, channel, out)
        shown = json.loads(p.stdout)
        got = np.load(out)
        at = meta["levels"][level]
        grid = group[at["minmax"][0]["path"]][channel]
        exact = group[at["range"][0]["path"]][channel]
        histograms = group[at["histogram"]][channel]
        assert shown["cell_shape"] == at["minmax"][0]["cell_shape"] and shown["halo"] == meta["halo"]
        assert shown["brick_shape"] == meta["brick_shape"]
        assert shown["min"] == ["float64", list(grid.shape[1:])], shown
        assert shown["histograms"] == ["uint32", list(histograms.shape)], shown
        np.testing.assert_array_equal(got["min"], grid[0].astype(np.float64))
        np.testing.assert_array_equal(got["max"], grid[1].astype(np.float64))
        np.testing.assert_array_equal(got["exact_min"], exact[0].astype(np.float64))
        np.testing.assert_array_equal(got["exact_max"], exact[1].astype(np.float64))
        np.testing.assert_array_equal(got["histograms"], histograms)
        edges = [np.inf if e is None else e for e in meta["channels"][channel]["histogram_edges"]]
        np.testing.assert_array_equal(got["histogram_edges"], np.array(edges, np.float64))
        assert got["max"].max() > 0 and histograms.sum() > 0
    # What it cannot answer, it says.
    for args, message in [
        ((store, 9, 0), f"{store}: no level 9 (the store has {len(meta['levels'])})"),
        ((store, 0, 2), f"{store}: no channel 2 (the store has 2)"),
    ]:
        p = run(installed, "python", "-c", f"""
import residency
try:
    residency.regions(*{tuple(map(str, args[:1])) + args[1:]!r})
except residency.ResidencyError as e:
    print(e)
""")
        assert p.stdout == f"{message}\n", p.stdout


RENDER_SCRIPT = """
import json, sys
import numpy as np
import residency
volume, out, scene = sys.argv[1], sys.argv[2], json.loads(sys.argv[3])
kwargs = {"dataset": sys.argv[4]} if len(sys.argv) > 4 else {}
np.save(out, residency.render(volume, scene, 64, 48, **kwargs))
"""


def test_render_from_python_gives_the_pixels_viewer_render_writes(installed, tmp_path):
    """`residency.render` of a store and of the same store served by the wheel's `brickserver`,
    with the default scene and with a scene file's dict, gives the pixels of `viewer render`'s
    PNG for the same volume, scene and size."""
    from support.browser import read_png

    run(installed, "ingest", "sample", "-o", tmp_path / "sample", "--size", "16,48,48")
    store = tmp_path / "v.ome.zarr"
    run(installed, "ingest", "convert", *(tmp_path / "sample" / f"{n}.ome.tif" for n in ("nuclei", "membranes")),
        "-o", store, "--chunk", "16", "--quiet")
    scene = {
        "camera": {"eye": [60.0, -20.0, -30.0], "target": [12.0, 12.0, 16.0]},
        "channels": [{"channel": 0, "visible": True, "color": [1.0, 0.5, 0.2],
                      "opacity": [{"value": 100.0, "opacity": 0.0}, {"value": 3000.0, "opacity": 0.5}]}],
        "mode": "mip",
    }
    (tmp_path / "scene.json").write_text(json.dumps(scene))
    server, base = start(installed, store)
    try:
        for label, scene_arg, cli_scene in [("default", None, []), ("scene", scene, ["--scene", tmp_path / "scene.json"])]:
            png = tmp_path / f"{label}.png"
            run(installed, "viewer", "render", "--store", store, *cli_scene, "--width", "64", "--height", "48", "--out", png)
            want = read_png(png)[:, :, :3]
            assert want.max() > 0, label
            for where, extra in [("store", [store]), ("server", [base, "v"])]:
                out = tmp_path / f"{label}-{where}.npy"
                volume, *dataset = extra
                run(installed, "python", "-c", RENDER_SCRIPT, volume, out, json.dumps(scene_arg), *dataset)
                got = np.load(out)
                assert got.dtype == np.uint8 and got.shape == (48, 64, 3), (label, where, got.dtype, got.shape)
                np.testing.assert_array_equal(got, want, err_msg=f"{label} from the {where}")
    finally:
        stop(server)
    # What it cannot draw, it says as `viewer render` does.
    bad = {**scene, "channels": [{"channel": 5, "visible": True, "color": [1, 1, 1], "opacity": []}]}
    (tmp_path / "bad.json").write_text(json.dumps(bad))
    cli = run(installed, "viewer", "render", "--store", store, "--scene", tmp_path / "bad.json", "--out", tmp_path / "x.png", check=False)
    assert cli.returncode != 0, cli.stderr
    p = run(installed, "python", "-c", f"""
import residency
try:
    residency.render({str(store)!r}, {bad!r})
except residency.ResidencyError as e:
    print(e)
""")
    assert "channel 5" in p.stdout and cli.stderr == f"error: {p.stdout}", (p.stdout, cli.stderr)


SERVER_SCRIPT = """
import os, socket, sys, time
import residency

def threads():
    return len(os.listdir("/proc/self/task"))

before = threads()
with residency.Server(sys.argv[1]) as server:
    print(server.url, flush=True)
    sys.stdin.readline()  # the test reads from it meanwhile
host, port = server.url.removeprefix("http://").rsplit(":", 1)
try:
    socket.create_connection((host, int(port)), timeout=2).close()
    print("still listening")
except ConnectionRefusedError:
    print("closed")
deadline = time.monotonic() + 10
while threads() != before and time.monotonic() < deadline:
    time.sleep(0.05)
print("threads", before, threads())
try:
    residency.Server(sys.argv[1] + ".missing")
except residency.ResidencyError as e:
    print("error", e)
"""


def test_server_from_python_serves_until_closed_and_leaves_nothing_behind(installed, tmp_path):
    """`residency.Server` serves a store in the Python process: zarr-python reads it over HTTP
    as from the folder and the page's files come from the wheel's share folder; once the `with`
    block ends, the port refuses connections and the server's threads are gone; a store that
    cannot be served is `brickserver serve`'s error."""
    run(installed, "ingest", "sample", "-o", tmp_path / "sample", "--size", "16,48,48")
    store = tmp_path / "cells.ome.zarr"
    run(installed, "ingest", "convert", tmp_path / "sample" / "nuclei.ome.tif", "-o", store, "--chunk", "16", "--quiet")
    proc = subprocess.Popen([installed.bin / "python", "-c", SERVER_SCRIPT, store], env=installed.env,
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        url = proc.stdout.readline().strip()
        assert url.startswith("http://127.0.0.1:"), (url, proc.stderr.read() if proc.poll() is not None else "")
        remote = zarr.open_group(f"{url}/cells/", mode="r")
        local = zarr.open_group(str(store), mode="r")
        for level in ("0", "1"):
            np.testing.assert_array_equal(remote[level][...], local[level][...])
        web = installed.root / "share" / "residency" / "web"
        page = requests.get(f"{url}/cells/view", timeout=10)
        assert page.status_code == 200
        assert page.text == (web / "index.html").read_text().replace("%VIEWER_BASE%", "../viewer/")
        out, err = proc.communicate("done\n", timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err
    lines = out.splitlines()
    assert lines[0] == "closed", out
    _, before, after = lines[1].split()
    assert before == after, out
    cli = run(installed, "brickserver", "serve", f"{store}.missing", "--bind", "127.0.0.1:0", check=False)
    assert cli.returncode != 0
    assert lines[2] == f"error {cli.stderr.removeprefix('error: ').strip()}", (lines[2], cli.stderr)


CONVERT_SCRIPT = """
import json, sys
import residency
calls = []
summary = residency.convert(sys.argv[2:], sys.argv[1], chunk=(8, 16, 16), channel_names=["a", "b"],
                            progress=lambda done, total: calls.append((done, total)))
print(json.dumps({"summary": summary, "calls": calls}))
"""


def test_convert_from_python_writes_what_ingest_convert_writes(installed, tmp_path):
    """`residency.convert` with `ingest convert`'s options writes the same store, byte for byte,
    tells its progress callback the input read up to the whole, and fails with the command
    line's message."""
    run(installed, "ingest", "sample", "-o", tmp_path / "sample", "--size", "16,48,48")
    tiffs = [tmp_path / "sample" / f"{n}.ome.tif" for n in ("nuclei", "filaments")]
    api, cli = tmp_path / "api" / "c.ome.zarr", tmp_path / "cli" / "c.ome.zarr"
    cli.parent.mkdir()
    p = run(installed, "python", "-c", CONVERT_SCRIPT, api, *tiffs)
    run(installed, "ingest", "convert", *tiffs, "-o", cli, "--chunk", "8,16,16", "--channel-names", "a,b", "--quiet")
    assert files(api) == files(cli)
    out = json.loads(p.stdout)
    summary, calls = out["summary"], out["calls"]
    assert summary["output"] == str(api) and summary["report"].startswith(f"wrote {api} (uint16)\n"), summary
    assert summary["input_bytes"] == 2 * 16 * 48 * 48 * 2
    assert calls and all(total == summary["input_bytes"] for _, total in calls), calls
    assert [done for done, _ in calls] == sorted(done for done, _ in calls) and calls[-1][0] == calls[-1][1], calls
    # nuclei (uint16) and filaments (uint8) are promoted to uint16: every plane is decoded.
    assert summary["planes_in_place"] == 0 and "read in place" not in summary["report"], summary
    # nuclei alone is read in place from its file unless `map_inputs=False` (a page whose
    # samples start at an odd offset is copied out of the file); the stores are the same.
    nuclei = tiffs[0]
    aligned = sum(page.dataoffsets[0] % 2 == 0 for page in tifffile.TiffFile(nuclei).pages)
    assert aligned > 0
    summaries = {}
    for map_inputs in (True, False):
        out = tmp_path / f"map-{map_inputs}" / "n.ome.zarr"
        p = run(installed, "python", "-c", f"""
import json, residency
s = residency.convert([{str(nuclei)!r}], {str(out)!r}, map_inputs={map_inputs})
print(json.dumps(s))
""")
        summaries[map_inputs] = json.loads(p.stdout)
    assert summaries[True]["planes_in_place"] == aligned, summaries[True]
    line = f"  {aligned} of 16 planes read in place from the input files (memory-mapped)\n"
    assert line in summaries[True]["report"], summaries[True]["report"]
    assert summaries[False]["planes_in_place"] == 0, summaries[False]
    assert "read in place" not in summaries[False]["report"], summaries[False]["report"]
    assert files(tmp_path / "map-True" / "n.ome.zarr") == files(tmp_path / "map-False" / "n.ome.zarr")
    # A failure: the exception's message is the command line's, after its `error: `.
    missing = tmp_path / "missing.tif"
    cli_err = run(installed, "ingest", "convert", missing, "-o", tmp_path / "x.ome.zarr", "--quiet", check=False)
    assert cli_err.returncode != 0
    p = run(installed, "python", "-c", f"""
import residency
try:
    residency.convert([{str(missing)!r}], {str(tmp_path / 'x.ome.zarr')!r})
except residency.ResidencyError as e:
    print(e)
""")
    assert p.stdout == cli_err.stderr.removeprefix("error: "), (p.stdout, cli_err.stderr)
    assert not (tmp_path / "x.ome.zarr").exists()


def test_the_readmes_wheel_commands_run_as_written(installed, tmp_path):
    """The commands of the README's "Install without Rust" block after the install, run as
    written (with `env/` the installed environment) in a fresh folder: the sample converts and
    `residency.regions` prints the shape of the finest min/max grid of level 0, channel 0."""
    [block] = sh_blocks(sections()["Install without Rust: the Python wheel"])
    commands = [c for c in block if c.startswith("env/bin/")]
    assert len(commands) == 2, block
    (tmp_path / "env").symlink_to(installed.root)
    p = subprocess.run(["bash", "-euo", "pipefail", "-c", "\n".join(commands)], cwd=tmp_path,
                       env=installed.env, capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr
    group = zarr.open_group(str(tmp_path / "sample.ome.zarr"), mode="r")
    finest = group.attrs["residency"]["levels"][0]["minmax"][0]["path"]
    assert p.stdout.splitlines()[-1] == str(tuple(group[finest][0].shape[1:])), p.stdout
