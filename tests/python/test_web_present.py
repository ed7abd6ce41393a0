"""How the web viewer's frames reach the screen (viewer/src/web/present.rs, viewer/web/main.js):
on the GPU through a WebGPU canvas context, no image read back a frame, or by the CPU path
(`?present=cpu`: each frame read back and drawn with putImageData). Debian's Chromium,
headless, WebGPU on SwiftShader, driven by tests/browser/web_viewer.mjs against
`brickserver serve` on loopback.

Needs the web build (scripts/build-web.sh)."""

import pathlib

import numpy as np
import pytest

from support.binaries import run_ingest, start_server
from test_web_viewer import SIZE, browser_and_web_build, drive, errors, read_png  # noqa: F401

pytestmark = pytest.mark.browser


@pytest.fixture(scope="module")
def served(tmp_path_factory):
    """brickserver serving one three-channel u16 store."""
    d = tmp_path_factory.mktemp("present")
    run_ingest("sample", "-o", d / "fl", "--size", "24,40,40")
    run_ingest("convert", *(d / "fl" / f"{n}.ome.tif" for n in ("nuclei", "membranes", "filaments")),
               "-o", d / "u16x3.ome.zarr")
    proc, base = start_server(d / "u16x3.ome.zarr")
    yield base
    proc.terminate()
    proc.wait()


def url(base, present=None):
    extra = f"&present={present}" if present else ""
    return f"{base}/u16x3/view?width={SIZE}&height={SIZE}{extra}"


def converged_frame(base, present, tmp_path):
    """Converges the page, then reads its state, presented canvas and snapshot, and the state
    after the snapshot: (state, presented PNG path, snapshot PNG path, state after, console)."""
    shown, snap = tmp_path / f"{present}-shown.png", tmp_path / f"{present}-snapshot.png"
    results, console = drive(
        url(base, present),
        [{"do": "converge"}, {"do": "presented", "path": str(shown)},
         {"do": "snapshot", "path": str(snap)}, {"do": "state"}],
    )
    state, _, _, after = results
    return state, shown, snap, after, console


def test_the_page_presents_on_the_gpu_without_reading_frames_back(served, tmp_path):
    state, shown, snap, after, console = converged_frame(served, None, tmp_path)
    assert state["error"] is None and state["converged"], state
    assert state["present"] == "gpu", state
    assert state["present_error"] is None
    assert state["frame"] >= 1
    # No frame was read back while presenting on the GPU; one snapshot, one readback.
    assert state["image_readbacks"] == 0
    assert after["image_readbacks"] == 1
    # What the canvas shows is the snapshot, within one 8-bit step.
    canvas, png = read_png(shown), read_png(snap)
    assert canvas.shape == png.shape == (SIZE, SIZE, 3)
    assert int(np.abs(canvas - png).max()) <= 1
    assert png.max() > 0  # something was drawn
    assert errors(console) == []


def test_the_cpu_path_reads_each_frame_back_and_shows_the_same_image(served, tmp_path):
    gpu_state, _, gpu_snap, _, _ = converged_frame(served, "gpu", tmp_path)
    assert gpu_state["present"] == "gpu", gpu_state
    state, shown, snap, after, console = converged_frame(served, "cpu", tmp_path)
    assert state["error"] is None and state["converged"], state
    assert state["present"] == "cpu", state
    assert state["present_error"] is None
    # One readback a frame (one renderer: its frame counter counts every frame), none more for
    # the snapshot.
    assert state["renderer_builds"] == 1
    assert state["image_readbacks"] == state["frame"]
    assert after["image_readbacks"] == state["image_readbacks"]
    # The canvas is the snapshot, and both paths' snapshots are the same PNG, byte for byte.
    assert np.array_equal(read_png(shown), read_png(snap))
    assert pathlib.Path(snap).read_bytes() == pathlib.Path(gpu_snap).read_bytes()
    assert errors(console) == []


def test_without_a_webgpu_canvas_the_page_falls_back_to_the_cpu_path(served, tmp_path):
    snap = tmp_path / "fallback.png"
    (state, _), console = drive(url(served), [{"do": "converge"}, {"do": "snapshot", "path": str(snap)}],
                                noWebGPUCanvas=True)
    assert state["error"] is None and state["converged"], state
    assert state["present"] == "cpu", state
    assert state["present_error"] is not None
    assert state["present_error"].startswith("cannot make a WebGPU surface of the canvas"), state
    assert state["image_readbacks"] == state["frame"] >= 1
    assert any(m.startswith("warning: no WebGPU canvas context") for m in console), console
    assert read_png(snap).max() > 0


def test_present_gpu_without_a_webgpu_canvas_is_an_error(served):
    (msg,), _ = drive(url(served, "gpu"), [{"do": "waitMessage"}], noWebGPUCanvas=True)
    assert msg.startswith("cannot present on the GPU (?present=gpu): cannot make a WebGPU surface of the canvas"), msg


def test_a_bad_present_value_shows_a_message(served):
    (msg,), _ = drive(url(served, "metal"), [{"do": "waitMessage"}])
    assert msg == "?present= must be auto, gpu or cpu, not 'metal'"
