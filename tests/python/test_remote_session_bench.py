"""The remote-session bench's short mode (CI's): `benchmarks/remote_session_bench.py --short`
replays the same camera path in the page in the remote mode (VDIs from `viewer serve`, read
with the nearest list and with the linear filter) and in the streaming mode (bricks from
brickserver), both links through the throttling proxy, into a temporary folder. What must hold
whatever the machine's speed: every mode is measured at every sample, the remote modes fetch
no brick (and read with their filter) and the streaming mode no VDI, the proxies
carried what the page received plus HTTP's overhead (and what the page aborted: at most the
rest of a body's Content-Length, or a whole answer), all converge on the last camera to
`viewer render`'s DVR image, and the report has its tables. Nothing here is about speed."""

import json
import os
import subprocess
import sys

import pytest

from support.browser import require_browser
from support.paths import BIN, ROOT

pytestmark = [pytest.mark.browser, pytest.mark.slow]

SEGMENTS = ["steady orbit", "fast move: orbit", "fast move: tilt", "zoom in", "zoom out"]

HEADERS = 1024
"""Most bytes of HTTP overhead per request over the link (request and answer headers, a CORS
preflight); measured about 200–400."""


@pytest.fixture(scope="module")
def bench(tmp_path_factory):
    """Runs the short bench once; returns (its JSON, its markdown report)."""
    require_browser()
    assert (BIN / "web" / "index.html").exists(), f"{BIN}/web not built: run scripts/build-web.sh"
    d = tmp_path_factory.mktemp("remote-session")
    env = dict(os.environ, RESIDENCY_BIN=str(BIN), XDG_RUNTIME_DIR=os.environ.get("XDG_RUNTIME_DIR", "/tmp"))
    p = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "remote_session_bench.py"), "--short",
         "--out-dir", str(d / "report"), "--data-dir", str(d / "data")],
        capture_output=True, text=True, env=env, timeout=600,
    )
    assert p.returncode == 0, p.stdout[-3000:] + p.stderr[-3000:]
    return json.loads((d / "report" / "remote-session.json").read_text()), (d / "report" / "remote-session.md").read_text()


def test_every_mode_is_measured_at_every_sample_on_the_same_path(bench):
    r, _ = bench
    assert r["short"] is True and (r["width"], r["height"]) == (96, 72)
    assert r["link"] == {"mbit_per_s": 100.0, "rtt_ms": 20.0, "one_way_delay_ms": 10.0}
    assert [g["name"] for g in r["path"]["segments"]] == SEGMENTS
    times = r["path"]["samples"]
    assert times[-1] == r["path"]["segments"][-1]["end"]
    assert r["scenes_equal"] is True
    for mode in ("remote", "remote-linear", "streaming"):
        m = r["modes"][mode]
        assert [s["t"] for s in m["samples"]] == times, mode
        assert [row["segment"] for row in m["segments"]] == SEGMENTS
        assert sum(row["samples"] for row in m["segments"]) == len(times)
        # A segment holds the samples from its move's start to before its rest's end (the
        # sample there is the next move's first), the last one to the path's end.
        for k, (row, g) in enumerate(zip(m["segments"], r["path"]["segments"])):
            last = k == len(SEGMENTS) - 1
            want = [t for t in times if g["start"] <= t < g["end"] or (last and t == g["end"])]
            assert row["samples"] == len(want), (mode, row, want)
        for s in m["samples"]:
            assert 0.0 <= s["ssim"] <= 1.0 and s["late_ms"] >= 0.0, (mode, s)
        for row, g in zip(m["segments"], r["path"]["segments"]):
            if row["rested_s"] is not None:
                assert 0.0 <= row["rested_s"] <= g["end"] - g["move_end"], (mode, row)
        assert m["frames"] > 0 and m["errors"] == [], (mode, m["errors"])
    assert r["machine"]["page_adapter"] and r["machine"]["service_adapter"], r["machine"]


def test_the_remote_modes_fetch_no_brick_and_the_streaming_mode_no_vdi(bench):
    r, _ = bench
    streaming = r["modes"]["streaming"]
    for mode, vdi_filter in (("remote", "nearest"), ("remote-linear", "linear")):
        remote = r["modes"][mode]
        assert remote["remote_mode"] == "on" and remote["vdi_filter"] == vdi_filter, mode
        assert remote["bricks_before"] == 0 and remote["bricks_fetched"] == 0
        assert remote["link_bytes"]["brick"] == {"up": 0, "down": 0}
        assert remote["vdis_received"] >= 1 and remote["requests_sent"] >= remote["vdis_received"]
        assert all(s["bricks_fetched"] == 0 for s in remote["samples"])
        # The page's own cost of the VDIs its samples saw drawn: the worker's read, the main
        # thread's setup.
        costs = remote["page_costs"]
        assert 1 <= costs["vdis_seen"] <= remote["vdis_received"], (mode, costs)
        assert costs["read_ms_median"] > 0 and 0 <= costs["setup_ms_median"] <= costs["setup_ms_max"], (mode, costs)
    assert streaming["page_costs"] is None
    assert streaming["remote_mode"] == "off" and streaming["vdi_filter"] is None and streaming["requests_sent"] == 0 and streaming["vdis_received"] == 0
    assert streaming["link_bytes"]["service"] == {"up": 0, "down": 0}
    assert streaming["page_bytes"]["service"] == 0
    # The first image needed bricks (fetched before the path started).
    assert streaming["bricks_before"] > 0


def test_the_proxies_carried_what_the_page_received_plus_http_overhead(bench):
    r, _ = bench
    for mode, link in (("remote", "service"), ("remote-linear", "service"), ("streaming", "brick")):
        m = r["modes"][mode]
        carried, received = m["link_bytes"][link]["down"], m["page_bytes"][link]
        requests = m["page_fetches"][link] + m["page_fetches_failed"][link] + m["requests_sent"]
        # What the page aborted (a superseded VDI) may have crossed the link further than the
        # page read it: a body cut short never past its Content-Length, an answer whose headers
        # were never read never more than the largest body.
        assert m["page_fetches_unbounded"][link] == 0, (mode, m["page_fetches_unbounded"])
        unread = m["page_bytes_unread"][link] + m["page_fetches_unanswered"][link] * m["page_largest_body"][link]
        requests += m["page_fetches_unanswered"][link]
        assert received <= carried <= received + unread + HEADERS * max(requests, 1), (mode, carried, received, unread, requests)
    remote = r["modes"]["remote"]
    # A VDI is the bulk of what came down: at least 1 KiB a VDI.
    assert remote["page_bytes"]["service"] >= 1024 * remote["vdis_received"]


def test_every_mode_converges_on_the_last_camera_to_the_dvr_image(bench):
    """Off the schedule, at rest: the VDI of the last camera ray cast at full resolution, and
    the page's own DVR, each against `viewer render`'s (measured SSIM 0.99999 and 1.0)."""
    r, _ = bench
    for mode in ("remote", "remote-linear", "streaming"):
        final = r["modes"][mode]["final"]
        assert final["converged"] is True, (mode, final)
        assert final["ssim"] >= 0.999, (mode, final)


def test_the_report_has_a_table_per_mode_and_the_link(bench):
    r, report = bench
    assert report.startswith("# Remote session over a throttled link\n")
    assert "at 100 Mbit/s each way and 20 ms round trip" in report
    assert f"headless on **{r['machine']['page_adapter']}**" in report
    for title in ("## Remote: VDIs from `viewer serve`, ray cast in the page with the nearest list (`?vdi_filter=nearest`)",
                  "## Remote, linear filter: the same, each VDI read with `?vdi_filter=linear`",
                  "## Streaming: the page fetches bricks and ray casts them itself",
                  "## Remote against streaming",
                  "## Linear filter against nearest list (remote)"):
        assert title in report
    for name in SEGMENTS:
        assert report.count(f"| {name} |") == 6, name
    for mode in ("remote", "remote-linear"):
        c = r["modes"][mode]["page_costs"]
        assert (f"The page's own cost of the {c['vdis_seen']} VDIs its samples saw drawn: read in its worker "
                f"in a median {c['read_ms_median']:.1f} ms") in report, mode
    assert report.count("The page's own cost of the") == 2
