"""Stores on disk: their files, their metadata, and a small one made by `ingest`."""

import json
import pathlib

import numpy as np
import tifffile

from support.binaries import run_ingest


def files(folder: pathlib.Path) -> dict:
    """Every file under `folder` (relative path → bytes)."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


def root_attributes(store: pathlib.Path) -> dict:
    """The image group's attributes, for Zarr v3 or v2."""
    if (store / "zarr.json").exists():
        return json.loads((store / "zarr.json").read_text())["attributes"]
    return json.loads((store / ".zattrs").read_text())


def multiscale(store: pathlib.Path) -> dict:
    """The image's first (only) OME-Zarr multiscale, for OME-Zarr 0.5 or 0.4."""
    attrs = root_attributes(store)
    ome = attrs.get("ome", attrs)
    return ome["multiscales"][0]


def level_factors(store: pathlib.Path):
    """Per-level downsampling factors (z, y, x) from the scale transforms."""
    ds = multiscale(store)["datasets"]
    scales = [np.array(d["coordinateTransformations"][0]["scale"][1:]) for d in ds]
    return [tuple(int(round(f)) for f in s / scales[0]) for s in scales]


def small_store(tmp_path):
    """A one-channel store made by `ingest` from a tiny TIFF."""
    src = tmp_path / "a.tif"
    tifffile.imwrite(src, np.ones((2, 8, 8), np.uint8), photometric="minisblack")
    store = tmp_path / "a.ome.zarr"
    run_ingest("convert", src, "-o", store, "--quiet")
    return store
