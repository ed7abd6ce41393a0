"""The JSON the viewer writes (`viewer render --stats`, `viewer compare --json`) validates
against its schemas in schemas/json/, on real output of the real binaries."""

import json
import subprocess

import jsonschema
import numpy as np
import tifffile

from support.binaries import run_ingest
from support.paths import BIN, SCHEMAS


def viewer(*args):
    p = subprocess.run([str(BIN / "viewer"), *map(str, args)], capture_output=True, text=True, env={"XDG_RUNTIME_DIR": "/tmp", "PATH": "/usr/bin:/bin"})
    assert p.returncode == 0, p.stderr
    return p.stdout


def test_render_stats_and_compare_output_validate(tmp_path):
    vol = np.zeros((16, 24, 24), np.uint16)
    vol[4:12, 6:18, 6:18] = 3000
    tifffile.imwrite(tmp_path / "v.tif", vol, photometric="minisblack")
    store = tmp_path / "v.ome.zarr"
    run_ingest("convert", tmp_path / "v.tif", "-o", store, "--chunk", "8", "--quiet")
    scene = ["--store", store, "--camera", "30,20,1.6", "--tf", "0:0:3000:0.3", "--width", "24", "--height", "24"]
    viewer("render", *scene, "--out", tmp_path / "gpu.exr", "--stats", tmp_path / "stats.json", "--max-level", "0")
    stats = json.loads((tmp_path / "stats.json").read_text())
    jsonschema.Draft202012Validator(json.loads((SCHEMAS / "render-stats.schema.json").read_text())).validate(stats)
    assert stats["converged"] is True and stats["width"] == 24
    assert stats["bricks_fetched"] == sum(f["bricks_fetched"] for f in stats["frames"])
    viewer("reference", *scene, "--out", tmp_path / "ref.exr")
    compare_schema = jsonschema.Draft202012Validator(json.loads((SCHEMAS / "compare.schema.json").read_text()))
    cmp = json.loads(viewer("compare", tmp_path / "gpu.exr", tmp_path / "ref.exr", "--json"))
    compare_schema.validate(cmp)
    assert cmp["psnr_db"] > 40 and cmp["ssim"] > 0.99
    same = json.loads(viewer("compare", tmp_path / "ref.exr", tmp_path / "ref.exr", "--json"))
    compare_schema.validate(same)
    assert same == {"psnr_db": None, "ssim": 1.0, "max_abs_error": 0.0, "mse": 0.0}
