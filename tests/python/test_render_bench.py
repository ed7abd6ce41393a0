"""The renderer benchmark's short mode (CI's): `benchmarks/render_bench.py --short` runs every
experiment of `viewer bench` on tiny datasets into a temporary folder; its outputs exist, every
results file validates against schemas/json/render-bench.schema.json, every method produced
finite times and an image compared with the reference, each sweep has a Pareto front, and the
maximum intensity projection and iso-surface runs have their rows beside DVR's.
Nothing here is about speed."""

import json
import math
import os
import subprocess
import sys

import jsonschema
import pytest

from support.paths import BIN, ROOT

SCHEMA = ROOT / "schemas" / "json" / "render-bench.schema.json"
# Bytes per sample of each type a results file names.
SAMPLE_BYTES = {"uint8": 1, "uint16": 2, "int16": 2, "uint32": 4, "int32": 4, "float32": 4}


@pytest.mark.slow
def test_short_mode_runs_every_experiment_and_validates(tmp_path):
    out, data = tmp_path / "report", tmp_path / "data"
    env = dict(os.environ, RESIDENCY_BIN=str(BIN), XDG_RUNTIME_DIR=os.environ.get("XDG_RUNTIME_DIR", "/tmp"))
    p = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "render_bench.py"), "--short", "--out-dir", str(out), "--data-dir", str(data)],
        capture_output=True,
        text=True,
        env=env,
        timeout=900,
    )
    assert p.returncode == 0, p.stdout[-3000:] + p.stderr[-3000:]
    assert "| Dataset |" in p.stdout

    report = (out / "render-bench.md").read_text()
    for section in ("## Table 1", "## Run time against error", "## Skipped work", "## Scaling"):
        assert section in report, section
    assert (out / "summary.md").read_text().strip()
    pngs = sorted(out.glob("*.png"))
    assert any(p.name.startswith("sweep-") for p in pngs) and (out / "scaling-size.png").exists()
    assert (out / "scaling-channels.png").exists()
    for png in pngs:
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", png

    validator = jsonschema.Draft202012Validator(json.loads(SCHEMA.read_text()))
    files = [out / "raw" / name for name in json.loads((out / "raw" / "index.json").read_text())]
    assert len(files) >= 5
    methods = set()
    sweeps = 0
    probes = 0
    modes = {}
    for f in files:
        r = json.loads(f.read_text())
        validator.validate(r)
        assert r["device"]["adapter"] and r["device"]["cpu"]
        for run in r["runs"]:
            if run["experiment"] == "table1":
                methods.add(run["label"])
            assert math.isfinite(run["wall_ms"]) and run["wall_ms"] > 0, (f.name, run["label"])
            if r["device"]["timestamps"]:
                assert run["gpu_ms"] is not None and math.isfinite(run["gpu_ms"]) and run["gpu_ms"] >= 0
            for v in run["views"]:
                # An image was rendered and compared with the reference of the same view.
                assert 0 < v["ssim"] <= 1 and math.isfinite(v["max_abs_error"]), (f.name, run["label"])
                assert v["psnr_db"] is None or math.isfinite(v["psnr_db"])
                assert v["samples"] > 0
        for s in r["skipped"]:
            assert s["naive_bricks"] >= s["naive_fill_bricks"] and s["naive_bricks"] >= 1
            assert s["ours_bricks_fetched"] >= 1 and 0 < s["ours_ssim"] <= 1
            # The bricks the converged image reads were fetched (none is read unfetched), and
            # the ceiling is naive bytes over their bytes.
            d = r["dataset"]
            brick = d["brick_shape"][0] * d["brick_shape"][1] * d["brick_shape"][2] * SAMPLE_BYTES[d["sample_type"]]
            assert 1 <= s["ours_bricks_read"] <= s["ours_bricks_fetched"], (f.name, s)
            assert s["bytes_ceiling"] == s["naive_bytes"] / (s["ours_bricks_read"] * brick), (f.name, s)
        modes[r["settings"]["mode"]] = modes.get(r["settings"]["mode"], 0) + 1
        if r["settings"]["mode"] != "dvr" and any(run["experiment"] == "table1" for run in r["runs"]):
            # The limit probe marches emission–absorption: it says so, and has no rows.
            assert r["probe_error"] == (
                f"the limit probe marches emission–absorption only (the scene's mode is {r['settings']['mode']})"
            ) and r["probe"] == [], f.name
        elif any(run["experiment"] == "table1" for run in r["runs"]):
            # The limit probe ran beside Table 1, by hand and (lavapipe filters R32Float) by
            # the texture unit, and its image matches the reference as the renderer's does.
            assert r["probe_error"] is None, r["probe_error"]
            assert [p["filter"] for p in r["probe"]] == ["manual", "hardware"], f.name
            for p in r["probe"]:
                assert p["samples"] > 0 and p["samples_per_s"] > 0, (f.name, p)
                assert p["psnr_db"] is None or p["psnr_db"] >= 30, (f.name, p)
            probes += 1
        if any(run["experiment"] == "sweep" for run in r["runs"]):
            sweeps += 1
            assert sum(run["is_default"] for run in r["runs"] if run["experiment"] == "sweep") == 1
    assert {"page-table", "octree", "residency", "residency (no skipping)", "sparseleap", "rasterize"} <= methods
    # The other papers' renderers rasterised boxes into ray segment lists in every view.
    for f in files:
        for run in json.loads(f.read_text())["runs"]:
            boxes = [v["segment_boxes"] for v in run["views"]]
            if run["method"] in ("sparseleap", "rasterize"):
                assert all(b > 0 for b in boxes), (f.name, run["label"], boxes)
            else:
                assert all(b == 0 for b in boxes), (f.name, run["label"], boxes)
    # Their table, with the papers' speed-ups beside ours, in the report and the summary.
    assert "### The other papers' renderers" in report
    assert "(King Snake 0.92%)" in report and "2.63× (2.18–4.23×)" in report
    assert "| Octree/SparseLeap (paper) |" in (out / "summary.md").read_text()
    assert sweeps >= 1
    # Every dataset kind has a time–error sweep holding every method.
    swept = {}
    for f in files:
        r = json.loads(f.read_text())
        runs = [run for run in r["runs"] if run["experiment"] == "sweep"]
        if runs:
            swept.setdefault(r["dataset"]["kind"], set()).update(run["method"] for run in runs)
    every = {"residency", "page-table", "octree", "sparseleap", "rasterize"}
    assert all(swept.get(k) == every for k in ("sparse", "dense", "cycif")), swept
    # The Rayleigh–Taylor stand-in (pure fluids) and its worst case both run Table 1, and the
    # CyCIF-like store renders all 16 of its channels, as the paper's CyCIF Small row does.
    datasets = [json.loads(f.read_text())["dataset"] for f in files]
    assert {"sparse", "mixing", "dense", "cycif"} <= {d["kind"] for d in datasets}
    assert [d["visible_channels"] for d in datasets if d["kind"] == "cycif"] == [16, 16, 16]
    # Maximum intensity projection has its Table 1 and skipped-work rows beside DVR's, for the
    # sparse, dense and CyCIF stores.
    assert modes.get("mip") == 3 and modes.get("dvr", 0) >= 5, modes
    for label in ("sparse 32³ MIP", "dense 32³ MIP", "cycif 8×64×64 MIP"):
        assert report.count(f"| {label} |") >= 2, label
    # So have iso-surfaces, run by the methods that draw them (the segment-list renderers
    # decline the mode), each with its skipping: ours and both baselines beside no skipping.
    assert modes.get("iso") == 3, modes
    for f in files:
        r = json.loads(f.read_text())
        if r["settings"]["mode"] == "iso":
            table1 = sorted(run["label"] for run in r["runs"] if run["experiment"] == "table1")
            assert table1 == ["octree", "page-table", "residency", "residency (no skipping)"], (f.name, table1)
            assert r["skipped"], f.name
    for label in ("sparse 32³ iso", "dense 32³ iso", "cycif 8×64×64 iso"):
        assert report.count(f"| {label} |") >= 2, label
    assert probes >= 1 and "### Ours against the limit probe" in report
    assert "| Ours / manual |" in (out / "summary.md").read_text()
    # The report marks a non-empty Pareto front for every sweep.
    assert report.count("| on front |") >= sweeps
