"""The VDI benchmark's short mode (CI's): `benchmarks/vdi_bench.py --short` runs `viewer bench
vdi` on tiny sparse, mixing and 16-channel datasets into a temporary folder; every results file
validates against schemas/json/vdi-bench.schema.json, sizes are consistent (16 bytes a GPU slot,
24 in the paper's raw layout, a file smaller than both), a VDI seen from its own camera matches
DVR there, and the report has each dataset's tables. Nothing here is about speed."""

import json
import math
import os
import subprocess
import sys

import jsonschema
import pytest

from support.paths import BIN, ROOT

SCHEMA = ROOT / "schemas" / "json" / "vdi-bench.schema.json"


@pytest.mark.slow
def test_short_mode_measures_every_dataset_and_validates(tmp_path):
    out, data = tmp_path / "report", tmp_path / "data"
    env = dict(os.environ, RESIDENCY_BIN=str(BIN), XDG_RUNTIME_DIR=os.environ.get("XDG_RUNTIME_DIR", "/tmp"))
    p = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "vdi_bench.py"), "--short", "--out-dir", str(out), "--data-dir", str(data)],
        capture_output=True,
        text=True,
        env=env,
        timeout=600,
    )
    assert p.returncode == 0, p.stdout[-3000:] + p.stderr[-3000:]
    report = (out / "vdi-bench.md").read_text()
    assert report.startswith("Measured ") and "# Volumetric depth images against direct volume rendering" in report
    validator = jsonschema.Draft202012Validator(json.loads(SCHEMA.read_text()))
    files = sorted((out / "vdi").glob("*.json"))
    assert [f.name[:3] for f in files] == ["00-", "01-", "02-"]
    for f in files:
        r = json.loads(f.read_text())
        validator.validate(r)
        assert f"### {r['label']} (32×32" in report
        png = f.with_suffix(".png")
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", png
        assert f"](vdi/{png.name})" in report
        pixels = r["width"] * r["height"]
        assert [s["supersegments"] for s in r["sizes"]] == [20]
        for s in r["sizes"]:
            assert s["gpu_bytes"] == pixels * 20 * 16 and s["paper_raw_bytes"] == pixels * 20 * 24
            assert 0 < s["file_bytes"] < s["gpu_bytes"], (f.name, s)
            assert 0 < s["zstd_file_bytes"] < s["gpu_bytes"], (f.name, s)
            assert 0 < s["mean_supersegments"] <= 20 and s["marches_per_ray"] >= 1
        assert [(v["supersegments"], v["deviation_degrees"]) for v in r["views"]] == [(20, 0.0), (20, 10.0)]
        for v in r["views"]:
            for k in ("vdi_ms", "vdi_no_skip_ms", "linear_ms", "dvr_ms"):
                assert math.isfinite(v[k]) and v[k] > 0, (f.name, k)
            assert 0 < v["ssim"] <= 1 and 0 < v["linear_ssim"] <= 1
            # The work counts: without skipping every step enters a list; skipping enters no
            # more lists and reads no more supersegments, and on the sparse volume off the
            # VDI's camera it takes fewer steps. (Along its own rays a ray stays in one list,
            # where skipping's steps over empty depth bins are extra: 1.38 against 0.81 a pixel
            # on the sparse volume; on the small dense CyCIF stack at 10°, 1.447 against 1.442.)
            work, walked = v["work"], v["work_no_skip"]
            assert walked["steps"] == walked["cells"] > 0, (f.name, walked)
            assert work["cells"] <= min(work["steps"], walked["cells"]), (f.name, work, walked)
            assert work["reads"] <= walked["reads"], (f.name, work, walked)
            if v["deviation_degrees"] > 0 and f.name.startswith("00-sparse"):
                assert work["steps"] < walked["steps"], (f.name, work, walked)
        at_origin = r["views"][0]
        # From its own camera a VDI gives back the DVR image, up to its half-float colour.
        psnr = at_origin["psnr_db"]
        assert at_origin["ssim"] > 0.99 and (psnr is None or psnr > 35), (f.name, at_origin)
        psnr = at_origin["linear_psnr_db"]
        assert at_origin["linear_ssim"] > 0.99 and (psnr is None or psnr > 35), (f.name, at_origin)
