"""Remote-session bench: the web page over a throttled link, rendering a VDI from `viewer serve`
(the remote mode) against streaming bricks from brickserver and ray casting them itself (the
streaming mode), along the same recorded camera path, on the same store, in the same run. The
remote mode runs twice: reading the VDIs with the nearest list (`?vdi_filter=nearest`) and with
the linear filter across lists (`?vdi_filter=linear`). The page's default, `auto`, draws as the
second at rest, and while the camera moves as the second where its frames hold the target frame
rate, else as the first.

    python3 benchmarks/remote_session_bench.py [--short] [--docs] [--out-dir DIR] [--data-dir DIR]
        [--mbit 100] [--rtt-ms 20]

Both of the page's links go through benchmarks/throttle_proxy.py (each way `--mbit` Mbit/s,
`--rtt-ms` round trip): page ↔ brickserver (the page, its metadata, and in the streaming mode
the bricks) and page ↔ `viewer serve` (the VDIs, in the remote mode). The page runs in Debian's
Chromium, headless, WebGPU on SwiftShader; `viewer serve` on this machine's wgpu adapter
(lavapipe here). tests/browser/remote_session.mjs replays the path in the page (a steady
orbit, two fast moves, a zoom in and out, each followed by a rest) on a fixed wall-clock
schedule through `window.residency.setScene`, and records at fixed times the page's state and
its canvas. Afterwards each recorded image is compared (`viewer compare`: SSIM, PSNR) with the
converged DVR of the path's camera at that time, rendered by `viewer render` (the reference):
what the user should see then, so lag and subsampling while moving count against a mode.

Writes remote-session.md and remote-session.json to docs/benchmarks/ (full; `--short`:
benchmarks/data/short-remote-session/) unless --out-dir says otherwise. `--short` (CI's mode,
about a minute): a 48³ store, a shorter path, samples every 0.5 s. The full run: the 128³ sparse
store of benchmarks/render_bench.py, about 35 s of path per mode; 96 × 72 in both (a VDI of
the 128³ store at 192 × 144 takes lavapipe 7–9 s to make here).
`--docs` also writes docs/benchmarks.md's summary line between its remote-session markers.
Needs target/release/{ingest,brickserver,viewer}, the web build (scripts/build-web.sh), and the
browser of the browser tests (scripts/setup.sh). With REMOTE_SESSION_LOG_DIR=DIR, the logs of
brickserver and `viewer serve` go to DIR/brickserver.log and DIR/viewer.log.
"""

import argparse
import base64
import datetime
import json
import os
import pathlib
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import threading
import time

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from render_bench import BIN, ROOT, Data, ingest_has_kind  # noqa: E402
from throttle_proxy import ThrottleProxy  # noqa: E402

DRIVER = ROOT / "tests" / "browser" / "remote_session.mjs"
ENV = {**os.environ, "XDG_RUNTIME_DIR": os.environ.get("XDG_RUNTIME_DIR", "/tmp")}
MODES = ("remote", "remote-linear", "streaming")
"""The page's modes: remote with each VDI filter, and streaming."""
TITLES = {
    "remote": "Remote: VDIs from `viewer serve`, ray cast in the page with the nearest list (`?vdi_filter=nearest`)",
    "remote-linear": "Remote, linear filter: the same, each VDI read with `?vdi_filter=linear`",
    "streaming": "Streaming: the page fetches bricks and ray casts them itself",
}


def node():
    """The Node.js of the browser tests (tests/python/support/browser.py's choice)."""
    local = sorted((ROOT / "tests" / "browser" / ".node" / "node_modules").glob("node-linux-*/bin/node"))
    return str(local[0]) if local else (shutil.which("node") or "node")


def path_plan(short: bool):
    """The camera path: keys [t, azimuth°, elevation°, distance factor], named segments (start,
    end of the move, end of the rest), and the sample times."""
    # (name, seconds of move, change of azimuth, elevation, distance factor, seconds of rest)
    # Rests long enough for a VDI made on lavapipe to arrive (seconds at these sizes).
    rest = 2.0 if short else 5.0
    moves = [
        ("steady orbit", 6.0, 90, 0, 1.0, rest),
        ("fast move: orbit", 0.5, 60, 0, 1.0, rest),
        ("fast move: tilt", 0.5, -30, 35, 1.0, rest),
        ("zoom in", 1.5, 0, 0, 0.55, rest),
        ("zoom out", 1.0, 0, 0, 1 / 0.55, rest),
    ]
    scale, every = (0.5, 0.5) if short else (1.0, 0.25)
    keys, segments = [[0.0, 0.0, 0.0, 1.0]], []
    t, az, el, d = 0.0, 0.0, 0.0, 1.0
    for name, move, daz, delv, dd, rest in moves:
        move_end = round(t + move * scale, 3)
        az, el, d = az + daz, el + delv, d * dd
        keys.append([move_end, az, el, round(d, 6)])
        end = round(move_end + rest, 3)
        keys.append([end, az, el, round(d, 6)])
        segments.append({"name": name, "start": t, "move_end": move_end, "end": end})
        t = end
    samples = [round(i * every, 3) for i in range(1, int(t / every + 1e-9) + 1)]
    if samples[-1] < t:
        samples.append(t)  # the path's end, rested
    return keys, segments, samples


def start(cmd, ready):
    """Starts `cmd`; returns (process, the rest of the first stderr/stdout line containing
    `ready`, the lines before it); its output is drained from then on."""
    proc = subprocess.Popen([str(c) for c in cmd], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=ENV)
    seen = []
    for line in proc.stdout:
        seen.append(line)
        if ready in line:
            log = os.environ.get("REMOTE_SESSION_LOG_DIR")
            sink = open(pathlib.Path(log) / f"{pathlib.Path(str(cmd[0])).name}.log", "w") if log else None
            threading.Thread(target=lambda: [sink.write(x) if sink else None for x in proc.stdout], daemon=True).start()
            return proc, line.split(ready, 1)[1].strip(), seen
    raise SystemExit(f"{cmd[0]} did not start (exit {proc.wait()}):\n{''.join(seen)[-4000:]}")


def stop(proc):
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def session(url, spec, proxies, timeout):
    """Runs the driver on `url`; at its start and end marks reads the proxies' counters.
    Returns (the driver's output, {link: {start, end}})."""
    spec = {**spec, "url": url}
    p = subprocess.Popen([node(), str(DRIVER), json.dumps(spec)], stdin=subprocess.PIPE,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    marks, last = {}, None
    timer = threading.Timer(timeout, p.kill)
    timer.start()
    try:
        for line in p.stdout:
            last = line
            if line.startswith('{"mark"'):
                name = json.loads(line)["mark"]
                marks[name] = {link: proxy.stats() for link, proxy in proxies.items()}
                p.stdin.write("go\n")
                p.stdin.flush()
        err = p.stderr.read()
        code = p.wait()
    finally:
        timer.cancel()
    if code != 0 or last is None or not last.startswith('{"scene"'):
        raise SystemExit(f"remote_session.mjs failed ({code}) on {url}:\n{(last or '')[-2000:]}\n{err[-4000:]}")
    return json.loads(last), marks


def compare(image, reference):
    p = subprocess.run([str(BIN / "viewer"), "compare", "--json", str(image), str(reference)],
                       capture_output=True, text=True, env=ENV)
    if p.returncode != 0:
        raise SystemExit(f"viewer compare {image} {reference} failed:\n{p.stderr}")
    m = json.loads(p.stdout)
    return m["ssim"], m["psnr_db"]


def render_reference(store, scene, size, out):
    path = out.with_suffix(".scene.json")
    path.write_text(json.dumps(scene))
    p = subprocess.run([str(BIN / "viewer"), "render", "--store", str(store), "--scene", str(path),
                        "--width", str(size[0]), "--height", str(size[1]), "--out", str(out)],
                       capture_output=True, text=True, env=ENV)
    if p.returncode != 0:
        raise SystemExit(f"viewer render of {path} failed:\n{p.stderr[-4000:]}")


def median(values):
    values = [v for v in values if v is not None]
    return statistics.median(values) if values else None


def measure(args):
    short = args.short
    # A VDI of the 128³ store takes lavapipe about 1 s to make at 96 × 72 here, 4–5 s at
    # 128 × 96 with the browser busy, 7–9 s at 192 × 144: larger images would leave the remote
    # mode waiting through every rest.
    size = (96, 72)
    data = Data(args.data_dir, ingest_has_kind())
    store = data.store("sparse", (48, 48, 48) if short else (128, 128, 128), 16 if short else 32)
    name = store.name.removesuffix(".ome.zarr")
    keys, segments, samples = path_plan(short)
    work = pathlib.Path(tempfile.mkdtemp(prefix="remote-session-"))
    brick, brick_url, _ = start([BIN / "brickserver", "serve", store, "--bind", "127.0.0.1:0"], "listening on ")
    service, service_url, service_log = start(
        [BIN / "viewer", "serve", "--store", store, "--bind", "127.0.0.1:0"], "listening on http://")
    service_url = "http://" + service_url.split()[0]
    service_adapter = next((line.split(" on ", 1)[1].strip() for line in service_log if "serving VDIs of" in line), None)
    host_port = lambda u: tuple(u.split("//")[1].rsplit(":", 1))  # noqa: E731
    runs = {}
    try:
        with ThrottleProxy(host_port(brick_url), mbit=args.mbit, rtt_ms=args.rtt_ms) as bp, \
                ThrottleProxy(host_port(service_url), mbit=args.mbit, rtt_ms=args.rtt_ms) as sp:
            link = bp.settings()
            page_base = f"http://127.0.0.1:{bp.port}/{name}/view?width={size[0]}&height={size[1]}"
            remote_url = f"http://127.0.0.1:{sp.port}"
            spec = {"viewport": {"width": max(size[0] + 420, 800), "height": max(size[1] + 200, 600)},
                    "keys": keys, "segments": segments, "samples": samples, "input_ms": 33,
                    "timeout_s": 300, "converge_s": 180, "final_s": 60}
            urls = {"remote": page_base + "&render=" + remote_url + "&vdi_filter=nearest",
                    "remote-linear": page_base + "&render=" + remote_url + "&vdi_filter=linear",
                    "streaming": page_base}
            for mode in MODES:
                t = time.time()
                out, marks = session(urls[mode], spec, {"brick": bp, "service": sp}, 400)
                print(f"  {time.time() - t:6.1f} s  {mode} session", flush=True)
                runs[mode] = {"out": out, "marks": marks, "origins": {"brick": f"http://127.0.0.1:{bp.port}",
                                                                     "service": remote_url}}
    finally:
        stop(brick)
        stop(service)
    # References: the converged DVR of every camera sampled (every mode samples the same ones).
    t = time.time()
    refs, shots = {}, work / "shots"
    shots.mkdir()
    scene = runs["remote"]["out"]["scene"]
    for mode in MODES:
        for i, s in enumerate(runs[mode]["out"]["samples"]):
            key = json.dumps(s["camera"], sort_keys=True)
            if key not in refs:
                refs[key] = work / f"ref-{len(refs):03}.png"
                render_reference(store, {**scene, "camera": s["camera"]}, size, refs[key])
            png = shots / f"{mode}-{i:03}.png"
            png.write_bytes(base64.b64decode(s["png"].split(",", 1)[1]))
            s["ssim"], s["psnr_db"] = compare(png, refs[key])
            del s["png"]
        final = runs[mode]["out"]["final"]
        png = shots / f"{mode}-final.png"
        png.write_bytes(base64.b64decode(final.pop("png").split(",", 1)[1]))
        last = runs[mode]["out"]["samples"][-1]["camera"]
        final["ssim"], final["psnr_db"] = compare(png, refs[json.dumps(last, sort_keys=True)])
    print(f"  {time.time() - t:6.1f} s  {len(refs)} references and {sum(len(r['out']['samples']) for r in runs.values())} comparisons", flush=True)
    shutil.rmtree(work, ignore_errors=True)
    return {
        "short": short, "store": name, "width": size[0], "height": size[1], "link": link,
        "machine": machine(runs["remote"]["out"]["adapter"], service_adapter),
        "path": {"keys": keys, "segments": segments, "samples": samples},
        "scenes_equal": all(runs[m]["out"]["scene"] == runs["remote"]["out"]["scene"] for m in MODES),
        "modes": {mode: summarize(mode, runs[mode], segments) for mode in MODES},
    }


def machine(page_adapter, service_adapter):
    cpu = platform.processor() or platform.machine()
    try:
        for line in pathlib.Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    chromium = subprocess.run([os.environ.get("CHROMIUM", "/usr/bin/chromium"), "--version"],
                              capture_output=True, text=True).stdout.strip()
    return {"cpu": cpu, "cores": os.cpu_count(), "page_adapter": page_adapter,
            "service_adapter": service_adapter, "browser": chromium}


def page_costs(samples, before):
    """The page's own cost of each VDI it drew on the path, as its samples saw them: per VDI
    (by the count received, past the `before` received before the path), the worker's read
    (`vdi_decode_ms`) and the main thread's setup (`vdi_setup_ms`), ms; None where they saw
    none (the streaming mode)."""
    seen = {}
    for s in samples:
        remote = s["state"].get("remote") or {}
        if remote.get("vdis_received", 0) > before and remote.get("vdi_setup_ms") is not None:
            seen[remote["vdis_received"]] = (remote["vdi_decode_ms"], remote["vdi_setup_ms"])
    if not seen:
        return None
    reads, setups = zip(*seen.values())
    return {"vdis_seen": len(seen), "read_ms_median": median(list(reads)),
            "setup_ms_median": median(list(setups)), "setup_ms_max": round(max(setups), 1)}


def summarize(mode, run, segments):
    """Per segment and overall: frame intervals, SSIM/PSNR, bytes, time to the rested image."""
    out, marks, origins = run["out"], run["marks"], run["origins"]
    samples = out["samples"]
    draws = out["draws"]
    link_bytes = {link: {d: marks["end"][link][f"{d}_bytes"] - marks["start"][link][f"{d}_bytes"] for d in ("up", "down")}
                  for link in ("brick", "service")}
    page_bytes = {link: out["end"]["bytes"].get(o, 0) - out["start"]["bytes"].get(o, 0) for link, o in origins.items()}
    page_fetches = {link: out["end"]["fetches"].get(o, 0) - out["start"]["fetches"].get(o, 0) for link, o in origins.items()}
    rows = []
    prev = {"bytes": out["start"]["bytes"], "state": out["start"]["state"]}
    for i, g in enumerate(segments):
        # A sample at a rest's end is the next move's first (that move begins then); the path's
        # last sample ends the last rest.
        last_segment = i == len(segments) - 1
        inside = [s for s in samples
                  if g["start"] <= s["t"] < g["end"] or (last_segment and s["t"] == g["end"])]
        # The move's samples: after its start (the sample there shows the rest before it).
        moving = [s for s in inside if g["start"] < s["t"] <= g["move_end"]]
        times = [b - a for a, b in zip(draws, draws[1:]) if g["start"] <= a < g["move_end"]]
        last = inside[-1]
        got = {link: last["bytes"].get(o, 0) - prev["bytes"].get(o, 0) for link, o in origins.items()}
        rows.append({
            "segment": g["name"], "samples": len(inside),
            "frames_while_moving": len(times),
            "frame_ms_median": None if not times else round(1000 * statistics.median(times), 1),
            "page_frame_ms_median": median([(s["state"].get("remote") or {}).get("frame_ms") if mode != "streaming"
                                            else s["state"].get("gpu_time_ms") for s in moving]),
            "ssim_median": round(median([s["ssim"] for s in inside]), 4),
            "ssim_min": round(min(s["ssim"] for s in inside), 4),
            "ssim_moving_median": median([s["ssim"] for s in moving]),
            "psnr_median_db": median([s["psnr_db"] for s in inside]),
            "ssim_rested": last["ssim"], "psnr_rested_db": last["psnr_db"],
            "converged_at_end": last["state"]["converged"],
            "rested_s": None if out["rested"][i] is None else round(out["rested"][i], 3),
            "page_bytes": got,
            "bricks_fetched": last["state"]["bricks_fetched"] - prev["state"]["bricks_fetched"],
            "vdis_received": ((last["state"].get("remote") or {}).get("vdis_received", 0)
                              - (prev["state"].get("remote") or {}).get("vdis_received", 0)),
        })
        prev = last
    end, start = out["end"]["state"], out["start"]["state"]
    remote_end, remote_start = end.get("remote") or {}, start.get("remote") or {}
    return {
        "segments": rows,
        "samples": [{k: s[k] for k in ("t", "late_ms", "ssim", "psnr_db")} | {
            "converged": s["state"]["converged"], "bricks_fetched": s["state"]["bricks_fetched"],
            "bytes_fetched": s["state"]["bytes_fetched"],
            "vdis_received": (s["state"].get("remote") or {}).get("vdis_received"),
            "d_i": (s["state"].get("remote") or {}).get("d_i"),
            "frame_ms": (s["state"].get("remote") or {}).get("frame_ms"),
            "gpu_time_ms": s["state"].get("gpu_time_ms")} for s in samples],
        "frames": len(draws),
        "frame_ms_median": round(1000 * statistics.median([b - a for a, b in zip(draws, draws[1:])]), 1) if len(draws) > 1 else None,
        "link_bytes": link_bytes, "page_bytes": page_bytes, "page_fetches": page_fetches,
        "page_fetches_failed": {link: out["end"]["failed"].get(o, 0) - out["start"]["failed"].get(o, 0) for link, o in origins.items()},
        # What the page aborted: of the bodies cut short, the bytes their Content-Length promised
        # and the page never read, and how many had no Content-Length; the requests aborted
        # before their answer's headers; and the largest whole body, which bounds those answers.
        "page_bytes_unread": {link: out["end"]["unread"].get(o, 0) - out["start"]["unread"].get(o, 0) for link, o in origins.items()},
        "page_fetches_unbounded": {link: out["end"]["unbounded"].get(o, 0) - out["start"]["unbounded"].get(o, 0) for link, o in origins.items()},
        "page_fetches_unanswered": {link: out["end"]["unanswered"].get(o, 0) - out["start"]["unanswered"].get(o, 0) for link, o in origins.items()},
        "page_largest_body": {link: out["end"]["largest"].get(o, 0) for link, o in origins.items()},
        "bricks_fetched": end["bricks_fetched"] - start["bricks_fetched"],
        "bytes_fetched": end["bytes_fetched"] - start["bytes_fetched"],
        "bricks_before": start["bricks_fetched"],
        "vdis_received": remote_end.get("vdis_received", 0) - remote_start.get("vdis_received", 0),
        "requests_sent": remote_end.get("requests_sent", 0) - remote_start.get("requests_sent", 0),
        "requests_aborted": remote_end.get("requests_aborted", 0) - remote_start.get("requests_aborted", 0),
        "remote_mode": remote_end.get("mode", "off"),
        "vdi_filter": remote_end.get("vdi_filter"),
        "remote_end": remote_end or None,
        "page_costs": page_costs(samples, remote_start.get("vdis_received", 0)),
        "last_sample": {"ssim": samples[-1]["ssim"], "psnr_db": samples[-1]["psnr_db"], "converged": samples[-1]["state"]["converged"]},
        "final": {"ssim": out["final"]["ssim"], "psnr_db": out["final"]["psnr_db"],
                  "converged": out["final"]["state"]["converged"], "waited_s": round(out["final"]["waited_s"], 2)},
        "errors": [m for m in out["console"] if m.startswith("error") or m.startswith("pageerror")],
    }


def mib(n):
    return f"{n / (1 << 20):.2f} MiB"


def fmt(v, spec="{:.3f}", none="—"):
    return none if v is None else spec.format(v)


def ratio(a, b, key):
    """`a[key] / b[key]`, or None where either is missing or zero."""
    return None if not a[key] or not b[key] else a[key] / b[key]


def report(result, stamp):
    m, link = result["machine"], result["link"]
    lines = [
        "# Remote session over a throttled link",
        "",
        f"Measured {stamp} by `python3 benchmarks/remote_session_bench.py{' --short' if result['short'] else ''}`: "
        f"store `{result['store']}`, {result['width']} × {result['height']} pixels, both of the page's links "
        f"(page ↔ brickserver, page ↔ `viewer serve`) through benchmarks/throttle_proxy.py at "
        f"{link['mbit_per_s']:g} Mbit/s each way and {link['rtt_ms']:g} ms round trip.",
        "",
        f"Machine: {m['cpu']} ({m['cores']} cores); the page in {m['browser']} headless on "
        f"**{m['page_adapter']}** (WebGPU), the render service on **{m['service_adapter']}**. Both adapters "
        "are CPU renderers sharing these cores with each other and the browser, so the absolute "
        "times are not a GPU user's: the point is the ratio between the modes over the same "
        "throttled link, path and store.",
        "",
        "The path (tests/browser/remote_session.mjs replays it in the page at a fixed wall-clock "
        "schedule; each segment is a move followed by a rest):",
        "",
        "| segment | move (s) | rest until (s) |",
        "|---|---|---|",
    ]
    for g in result["path"]["segments"]:
        lines.append(f"| {g['name']} | {g['start']:g}–{g['move_end']:g} | {g['end']:g} |")
    lines += [
        "",
        f"Samples every {result['path']['samples'][0]:g} s ({len(result['path']['samples'])} per mode); each "
        "is compared with the converged DVR (`viewer render`) of the path's camera at that time. "
        "Frame time: median interval between frames drawn into the canvas while the camera moves "
        "(the page draws nothing once converged); page frame ms: the page's own median measure "
        "while moving (remote: `remote.frame_ms`, the VDI's ray cast and present; streaming: "
        "`gpu_time_ms`). Rested: seconds from the end of the move until "
        "the page is converged on the rested camera (remote: the VDI of that camera drawn at full "
        "resolution; streaming: every brick the view needs resident and drawn); — when not before "
        "the segment ends. Bytes received: the bodies of the page's fetch() calls in the segment "
        "(the proxies' counts, headers included, are given for the whole path). A segment's samples "
        "run from its move's start to just before its rest's end, the last segment's to the path's "
        "end (SSIM rested: the rest's last sample); the statistics while moving take the samples "
        "after the move's start, to its end. The modes run one after the other, in the order of the tables, against the same "
        "brickserver and render service, so the later sessions find the service's bricks loaded.",
    ]
    for mode in MODES:
        r = result["modes"][mode]
        lines += [
            "",
            f"## {TITLES[mode]}",
            "",
            "| segment | frames while moving | frame time (ms) | page frame ms | SSIM median | SSIM min | PSNR median (dB) | SSIM rested | rested (s) | bytes received | bricks | VDIs |",
            "|---|---|---|---|---|---|---|---|---|---|---|---|",
        ]
        for row in r["segments"]:
            got = row["page_bytes"]["brick"] + row["page_bytes"]["service"]
            lines.append(
                f"| {row['segment']} | {row['frames_while_moving']} | {fmt(row['frame_ms_median'], '{:.1f}')} | "
                f"{fmt(row['page_frame_ms_median'], '{:.1f}')} | {row['ssim_median']:.4f} | {row['ssim_min']:.4f} | "
                f"{fmt(row['psnr_median_db'], '{:.1f}')} | {row['ssim_rested']:.4f} | {fmt(row['rested_s'], '{:.2f}')} | "
                f"{mib(got)} | {row['bricks_fetched']} | {row['vdis_received']} |")
        lb = r["link_bytes"]
        lines += [
            "",
            f"Over the whole path: {r['frames']} frames drawn (median interval {fmt(r['frame_ms_median'], '{:.1f}')} ms); "
            f"the proxies carried {mib(lb['brick']['down'])} down / {mib(lb['brick']['up'])} up on the brick link and "
            f"{mib(lb['service']['down'])} down / {mib(lb['service']['up'])} up on the service link; the page's "
            f"fetch() bodies: {mib(r['page_bytes']['brick'])} in {r['page_fetches']['brick']} fetches from brickserver, "
            f"{mib(r['page_bytes']['service'])} in {r['page_fetches']['service']} from the service. "
            f"Bricks fetched {r['bricks_fetched']} ({mib(r['bytes_fetched'])}; {r['bricks_before']} before the path "
            f"started, for the first image), VDIs received {r['vdis_received']} of {r['requests_sent']} requests "
            f"({r['requests_aborted']} aborted). At the end of the path: SSIM {r['last_sample']['ssim']:.4f}, "
            f"converged {str(r['last_sample']['converged']).lower()}; converged on its last camera "
            f"{r['final']['waited_s']:g} s later: SSIM {r['final']['ssim']:.4f}, PSNR {fmt(r['final']['psnr_db'], '{:.1f}')} dB.",
        ]
        if r["page_costs"] is not None:
            c = r["page_costs"]
            lines[-1] += (
                f" The page's own cost of the {c['vdis_seen']} VDIs its samples saw drawn: read in its worker in a "
                f"median {fmt(c['read_ms_median'], '{:.1f}')} ms, set up from the main thread in a median "
                f"{fmt(c['setup_ms_median'], '{:.1f}')} ms (at most {c['setup_ms_max']:.1f} ms; `remote.vdi_decode_ms` "
                "and `vdi_setup_ms`).")
    rm, st = result["modes"]["remote"], result["modes"]["streaming"]
    lines += ["", "## Remote against streaming", "", "| segment | frame time remote / streaming | SSIM median remote − streaming | rested remote / streaming (s) |", "|---|---|---|---|"]
    for a, b in zip(rm["segments"], st["segments"]):
        lines.append(f"| {a['segment']} | {fmt(ratio(a, b, 'frame_ms_median'), '{:.2f}')} | {a['ssim_median'] - b['ssim_median']:+.4f} | "
                     f"{fmt(a['rested_s'], '{:.2f}')} / {fmt(b['rested_s'], '{:.2f}')} |")
    li = result["modes"]["remote-linear"]
    lines += ["", "## Linear filter against nearest list (remote)", "",
              "Separate sessions on the same path: VDIs arrive at other moments, so a sample compares "
              "what each page showed at that time, not the same VDI through two filters.", "",
              "| segment | frame time linear / nearest | page frame ms linear / nearest | SSIM median linear − nearest | SSIM median while moving, linear − nearest |",
              "|---|---|---|---|---|"]
    for a, b in zip(li["segments"], rm["segments"]):
        moving = (None if a["ssim_moving_median"] is None or b["ssim_moving_median"] is None
                  else a["ssim_moving_median"] - b["ssim_moving_median"])
        lines.append(f"| {a['segment']} | {fmt(ratio(a, b, 'frame_ms_median'), '{:.2f}')} | "
                     f"{fmt(ratio(a, b, 'page_frame_ms_median'), '{:.2f}')} | {a['ssim_median'] - b['ssim_median']:+.4f} | "
                     f"{fmt(moving, '{:+.4f}')} |")
    lines += ["", "Raw data: remote-session.json (every sample: time, lateness, SSIM, PSNR, the page's state).", ""]
    return "\n".join(lines)


def summary_line(result):
    """One line for docs/benchmarks.md."""
    rm, st = result["modes"]["remote"], result["modes"]["streaming"]
    li = result["modes"]["remote-linear"]
    link = result["link"]
    def total(r):
        return r["link_bytes"]["brick"]["down"] + r["link_bytes"]["service"]["down"]
    return (f"Over {link['mbit_per_s']:g} Mbit/s and {link['rtt_ms']:g} ms, {result['width']} × {result['height']}, "
            f"`{result['store']}`: remote frame time {fmt(rm['frame_ms_median'], '{:.1f}')} ms against streaming "
            f"{fmt(st['frame_ms_median'], '{:.1f}')} ms (median over the path); SSIM median "
            f"{median([s['ssim'] for s in rm['samples']]):.4f} against {median([s['ssim'] for s in st['samples']]):.4f}, "
            f"converged at the last pose {rm['final']['ssim']:.4f} against {st['final']['ssim']:.4f}; "
            f"{mib(total(rm))} against {mib(total(st))} down the links. With the linear filter across "
            f"lists: frame time {fmt(li['frame_ms_median'], '{:.1f}')} ms, SSIM median "
            f"{median([s['ssim'] for s in li['samples']]):.4f}.")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--short", action="store_true", help="CI's mode: a 48³ store, a shorter path (about a minute)")
    ap.add_argument("--docs", action="store_true", help="also write the summary into docs/benchmarks.md")
    ap.add_argument("--out-dir", type=pathlib.Path, help="where to write remote-session.md/.json")
    ap.add_argument("--data-dir", type=pathlib.Path, default=ROOT / "benchmarks" / "data")
    ap.add_argument("--mbit", type=float, default=100.0, help="link rate each way, Mbit/s (default 100)")
    ap.add_argument("--rtt-ms", type=float, default=20.0, help="round-trip latency, ms (default 20)")
    args = ap.parse_args()
    for exe in ("ingest", "brickserver", "viewer"):
        if not (BIN / exe).exists():
            raise SystemExit(f"{BIN / exe} not built: run cargo build --release --workspace --bins")
    if not (BIN / "web" / "index.html").exists():
        raise SystemExit(f"{BIN}/web not built: run scripts/build-web.sh")
    out_dir = args.out_dir or (ROOT / "benchmarks" / "data" / "short-remote-session" if args.short else ROOT / "docs" / "benchmarks")
    out_dir.mkdir(parents=True, exist_ok=True)
    t = time.time()
    result = measure(args)
    stamp = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    result["measured"] = stamp
    result["seconds"] = round(time.time() - t, 1)
    (out_dir / "remote-session.json").write_text(json.dumps(result, indent=1) + "\n")
    (out_dir / "remote-session.md").write_text(report(result, stamp))
    line = summary_line(result)
    print(line)
    if args.docs:
        write_docs_summary(line)
    print(f"wrote {out_dir}/remote-session.md and .json in {result['seconds']} s")


BEGIN, END = "<!-- remote-session:begin -->", "<!-- remote-session:end -->"


def write_docs_summary(line):
    """Replaces the text between docs/benchmarks.md's remote-session markers with `line`."""
    page = ROOT / "docs" / "benchmarks.md"
    text = page.read_text()
    if BEGIN not in text or END not in text:
        raise SystemExit(f"{page}: no {BEGIN} … {END} markers to write the summary between")
    head, rest = text.split(BEGIN, 1)
    _, tail = rest.split(END, 1)
    page.write_text(f"{head}{BEGIN}\n{line}\n{END}{tail}")


if __name__ == "__main__":
    main()
