"""Server benchmark: `brickserver` against nginx serving the same store directory, in one run,
with `wrk` (default) or `oha` as the load generator on the same machine (client and servers
share the cores, or are pinned apart: see the loads).

    python3 benchmarks/server_bench.py [--client wrk|oha] [--duration 10] [--soak 300] [--docs]

Needs `wrk` (Debian `wrk`; random keys from benchmarks/wrk_random_keys.lua) or `oha`
(`cargo install oha`), nginx (Debian `nginx-light`) and a release build. nginx, with
`sendfile`, is the loopback ceiling: the fastest static file server at hand. Beside requests/s
and latency, each row gives the CPU time each server spent per request (user + system, from
/proc/PID/stat over the run). Loads:

Both servers run at once; each load runs on one, then the other, `--repeat` times, and the
median run is reported, so background load hits both alike.

- random chunk GETs, uniform over a 20,000-chunk store of random bytes with log-normal sizes
  (median 40 KiB), at 256, 16 and 1 connections;
- `If-None-Match` revalidations answered 304, at 256 connections;
- with two or more CPUs, each of these loads again with the server on the upper half of the
  CPUs and the client on the lower half (on 2 CPUs, the last and the first: "pinned apart",
  the client has cores of its own, and both servers the same ones, a placement the scheduler
  does not give them at 1 connection);
- region queries (`/NAME/regions`, random unaligned boxes) on a store made by `ingest`, at 16
  connections (nginx has no equivalent);
- optionally a soak: random chunk GETs at 256 connections for `--soak` seconds, sampling the
  server's RSS, open descriptors and threads every 5 s, counting every non-200 answer and
  transport error; meanwhile `--soak-evict` random chunk files a second are dropped from the
  page cache (`POSIX_FADV_DONTNEED`), so that chunks read from the disk (on the server's
  blocking threads) are served all through it, not only when the machine happens to drop them.

Each server's peak RSS (VmHWM, summed over nginx's processes) is read after its loads.
Results go to docs/benchmarks/server.md and server-soak.md (with --docs, docs/benchmarks.md
links to them between its `server-bench` and `server-soak` markers).

With `--s3`, it measures instead `brickserver` serving the same stores from an S3 server on
loopback (s3s-fs, as the tests use: `scripts/test.sh` installs it) against `brickserver` serving
them from disk: random chunk GETs at 16 and 1 connections, 304 revalidations and region queries
at 16 connections. Results go to docs/benchmarks/server-s3.md (docs/benchmarks.md markers
`server-s3-bench`, with --docs).
"""

import argparse
import contextlib
import datetime
import json
import os
import pathlib
import platform
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
import urllib.request

import numpy as np

from docs_page import point_page_at, write_result

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "python"))
from support.s3 import start_s3  # noqa: E402

BIN = pathlib.Path(os.environ.get("RESIDENCY_BIN", ROOT / "target" / "release"))
GRID = (20, 25, 40)  # 20,000 chunks, z, y, x
OHA = shutil.which("oha") or str(pathlib.Path.home() / ".cargo" / "bin" / "oha")
WRK_SCRIPT = pathlib.Path(__file__).resolve().parent / "wrk_random_keys.lua"
# wrk's threads: half the CPUs (the client's share when pinned apart), at least 2.
WRK_THREADS = max(2, len(os.sched_getaffinity(0)) // 2)
CLIENT = "wrk"  # set from --client in main()
# Chunk files each server holds open: brickserver's default `--open-files`, and the same
# for each nginx worker (`open_file_cache max=`); each holds a fifth of the store's files.
OPEN_FILES = 4096


def make_store(path: pathlib.Path):
    """A Zarr-like store of 20,000 chunk files of random bytes, log-normal sizes (median 40 KiB)."""
    if (path / "done").exists():
        return
    rng = np.random.default_rng(7)
    sizes = np.clip(rng.lognormal(np.log(40 * 1024), 0.6, GRID), 512, 1 << 20).astype(int)
    blob = rng.integers(0, 256, int(sizes.max()), dtype=np.uint8).tobytes()
    (path / "0" / "c" / "0").mkdir(parents=True, exist_ok=True)
    (path / "zarr.json").write_text('{"zarr_format": 3, "node_type": "group", "attributes": {}}')
    for z in range(GRID[0]):
        for y in range(GRID[1]):
            d = path / "0" / "c" / "0" / str(z) / str(y)
            d.mkdir(parents=True, exist_ok=True)
            for x in range(GRID[2]):
                off = int(rng.integers(0, 64))
                (d / str(x)).write_bytes(blob[off : off + int(sizes[z, y, x])][: int(sizes[z, y, x])])
    (path / "done").write_text("")


def bench_store(work: pathlib.Path) -> pathlib.Path:
    """The chunk store under `work` (`www/bench`, inside nginx's root), made if missing."""
    store = work / "www" / "bench"
    store.mkdir(parents=True, exist_ok=True)
    make_store(store)
    return store


def key_regex(base: str) -> str:
    z, y, x = (f"({'|'.join(str(i) for i in range(n))})" for n in GRID)
    return f"{base}/0/c/0/{z}/{y}/{x}"


def status_mb(pids, field) -> float:
    """A /proc/PID/status memory field (VmHWM: peak RSS, VmRSS: current), summed over `pids`, in MB."""
    total = 0
    for pid in pids:
        try:
            for line in pathlib.Path(f"/proc/{pid}/status").read_text().splitlines():
                if line.startswith(field + ":"):
                    total += int(line.split()[1])
        except FileNotFoundError:
            pass
    return total / 1024


def rss_mb(pids) -> float:
    return status_mb(pids, "VmHWM")


def current_rss_mb(pids) -> float:
    return status_mb(pids, "VmRSS")


def proc_entries(pid, folder) -> int:
    """How many entries `/proc/PID/FOLDER` lists: `fd`, the open descriptors (sockets and files
    held open); `task`, the threads (serving threads, and blocking-pool threads that read what
    the page cache does not hold). 0 once the process has gone."""
    try:
        return len(os.listdir(f"/proc/{pid}/{folder}"))
    except FileNotFoundError:
        return 0


def cpu_seconds(pids) -> float:
    """User + system CPU time of `pids` (and their waited-for children), in seconds."""
    tick = os.sysconf("SC_CLK_TCK")
    total = 0
    for pid in pids:
        try:
            fields = pathlib.Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
            total += sum(int(f) for f in fields[11:15])
        except FileNotFoundError:
            pass
    return total / tick


def wrk_command(base, connections, seconds, etag=None):
    """The wrk command of random chunk GETs under `base` (scheme://host:port/PREFIX), or with
    `etag` revalidations of one chunk, for `seconds` at `connections` connections."""
    origin, prefix = base.split("/", 3)[2], "/" + base.split("/", 3)[3]
    cmd = ["wrk", f"-t{min(WRK_THREADS, connections)}", f"-c{connections}", f"-d{seconds}s", "--latency",
           "-s", str(WRK_SCRIPT), f"http://{origin}", "--", prefix, *map(str, GRID)]
    return cmd + [etag] if etag else cmd


def wrk(base, connections, seconds, etag=None):
    """One wrk load (see `wrk_command`), its results as `oha` gives them."""
    out = subprocess.run(wrk_command(base, connections, seconds, etag), capture_output=True, text=True, check=True).stdout
    return wrk_result(out, etag)


def wrk_result(out, etag=None):
    """The results of wrk's output `out` (the script's RESULT line)."""
    line = next(l for l in out.splitlines() if l.startswith("RESULT "))
    r = {k: int(v) for k, v in (kv.split("=") for kv in line.split()[1:])}
    secs = r["duration_us"] / 1e6
    expected = 304 if etag else 200
    bad = r["errors"]
    return {
        "rps": r["requests"] / secs,
        "mbps": r["bytes"] / secs / 1e6,
        "p50_ms": r["p50_us"] / 1e3,
        "p99_ms": r["p99_us"] / 1e3,
        # wrk counts answers that are not 2xx/3xx, and transport errors, together.
        "codes": {expected: r["requests"] - bad, 0: bad} if bad else {expected: r["requests"]},
        "errors": 0,
    }


def chunk_load(base, connections, seconds, etag=None):
    """One chunk load with the chosen client (see `wrk`)."""
    if CLIENT == "wrk":
        return wrk(base, connections, seconds, etag)
    if etag:
        return oha(f"{base}/0/c/0/0/0/0", connections, seconds, headers=[f"If-None-Match: {etag}"], regex=False)
    return oha(key_regex(base), connections, seconds)


def oha(url, connections, seconds, headers=(), regex=True):
    cmd = [OHA, "-z", f"{seconds}s", "-c", str(connections), "--no-tui", "--output-format", "json", "--disable-compression"]
    for h in headers:
        cmd += ["-H", h]
    if regex:
        cmd += ["--rand-regex-url"]
    cmd.append(url)
    out = subprocess.run(cmd, capture_output=True, text=True, check=True).stdout
    r = json.loads(out)
    codes = {int(k): v for k, v in r.get("statusCodeDistribution", {}).items()}
    # Requests cut off by the end of the run are not errors of the server.
    errors = sum(v for k, v in r.get("errorDistribution", {}).items() if "deadline" not in k)
    summary = r["summary"]
    lat = r.get("latencyPercentiles", {})
    return {
        "rps": summary["requestsPerSec"],
        "mbps": summary.get("sizePerSec", 0) / 1e6,
        "p50_ms": (lat.get("p50") or 0) * 1e3,
        "p99_ms": (lat.get("p99") or 0) * 1e3,
        "codes": codes,
        "errors": errors,
    }


def start_brickserver(store, name, *extra, env=None):
    p = subprocess.Popen(
        [str(BIN / "brickserver"), "serve", f"--name={name}={store}", "--bind", "127.0.0.1:0", *extra],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
        env=env,
    )
    for line in p.stdout:
        if line.startswith("listening on "):
            return p, [p.pid], line.split("listening on ")[1].strip()
    raise RuntimeError("brickserver did not start")


# The fields of brickserver's chunk answers that nginx adds only when told to (`add_header`):
# the caching and CORS fields that let browsers cache chunks and read them from pages of other
# origins, as every host of OME-Zarr for web viewers configures. nginx is given the values of
# brickserver's own answer (`mirrored_fields`), so that both servers send the same answers.
MIRRORED = ("cache-control", "access-control-allow-origin", "access-control-expose-headers")


def mirrored_fields(chunk_url):
    """The `MIRRORED` fields of the answer to a GET of `chunk_url`, as nginx `add_header` lines."""
    headers = urllib.request.urlopen(chunk_url).headers
    missing = [name for name in MIRRORED if headers[name] is None]
    if missing:
        raise RuntimeError(f"{chunk_url}: no {', '.join(missing)} in the answer")
    return "".join(f'  add_header {name} "{headers[name]}";\n' for name in MIRRORED)


def start_nginx(root: pathlib.Path, work: pathlib.Path, port: int, fields: str = ""):
    """nginx serving `root` on `port` (its files in `work`), adding `fields` (`add_header`
    lines) to its answers."""
    conf = work / "nginx.conf"
    conf.write_text(f"""
worker_processes auto;
worker_rlimit_nofile 20000;
pid {work}/nginx.pid;
error_log {work}/nginx-error.log warn;
daemon off;
events {{ worker_connections 4096; }}
http {{
  access_log off;
  sendfile on; tcp_nopush on; tcp_nodelay on;
  open_file_cache max={OPEN_FILES} inactive=60s;  # per worker, as many as brickserver holds
  keepalive_requests 1000000;
  keepalive_timeout 65;
  default_type application/octet-stream;
{fields}  client_body_temp_path {work}/tmp; proxy_temp_path {work}/tmp; fastcgi_temp_path {work}/tmp;
  uwsgi_temp_path {work}/tmp; scgi_temp_path {work}/tmp;
  server {{ listen 127.0.0.1:{port}; root {root}; }}
}}
""")
    (work / "tmp").mkdir(exist_ok=True)
    p = subprocess.Popen(["nginx", "-c", str(conf), "-p", str(work)], stderr=subprocess.DEVNULL)
    for _ in range(100):
        try:
            urllib.request.urlopen(f"http://127.0.0.1:{port}/bench/zarr.json", timeout=1)
            break
        except Exception:
            time.sleep(0.05)
    children = subprocess.run(["pgrep", "-P", str(p.pid)], capture_output=True, text=True).stdout.split()
    return p, [p.pid, *map(int, children)], f"http://127.0.0.1:{port}"


def stop(p, sig=signal.SIGTERM, timeout=20):
    """Sends server `p` the signal `sig` and waits for it to exit."""
    p.send_signal(sig)
    p.wait(timeout=timeout)


@contextlib.contextmanager
def chunk_servers(work: pathlib.Path, store: pathlib.Path):
    """nginx (its root `work`/www, with brickserver's caching and CORS fields: `MIRRORED`) and
    brickserver serving `store` as the dataset `bench`, both stopped on leaving, whatever
    happened: name -> (the dataset's base URL, the processes)."""
    with tempfile.TemporaryDirectory(prefix="nginx-") as ng_work, contextlib.ExitStack() as stops:
        bs, bs_pids, bs_base = start_brickserver(store, "bench", f"--open-files={OPEN_FILES}")
        stops.callback(stop, bs)
        fields = mirrored_fields(f"{bs_base}/bench/0/c/0/0/0/0")
        ng, ng_pids, ng_base = start_nginx(work / "www", pathlib.Path(ng_work), 18080, fields)
        stops.callback(stop, ng, signal.SIGQUIT, 10)
        yield {"nginx": (f"{ng_base}/bench", ng_pids), "brickserver": (f"{bs_base}/bench", bs_pids)}


def turn_order(names, i):
    """`names` in order in even rounds and reversed in odd ones, so that none always runs first."""
    names = list(names)
    return names if i % 2 == 0 else names[::-1]


def etag_of(url):
    return urllib.request.urlopen(url).headers["ETag"]


def median_run(runs):
    """The run with the median requests/s (latencies come from that same run)."""
    return sorted(runs, key=lambda r: r["rps"])[len(runs) // 2]


def thread_ids(pids):
    """The threads of `pids` now (none of a process that has gone)."""
    tids = []
    for pid in pids:
        try:
            tids += [int(t) for t in os.listdir(f"/proc/{pid}/task")]
        except OSError:
            pass
    return tids


def pin(tids, cpus):
    """Runs each thread in `tids` on `cpus`; returns each one's mask before, to restore."""
    before = {}
    for tid in tids:
        try:
            before[tid] = os.sched_getaffinity(tid)
            os.sched_setaffinity(tid, cpus)
        except OSError:
            pass
    return before


def unpin(before):
    """Gives each thread its mask back (`pin`'s answer); threads gone are skipped."""
    for tid, cpus in before.items():
        try:
            os.sched_setaffinity(tid, cpus)
        except OSError:
            pass


def cpu_list(cpus) -> str:
    """`cpus` as words: "CPU 1", or "CPUs 8–15" for a run."""
    c = sorted(cpus)
    if len(c) == 1:
        return f"CPU {c[0]}"
    if c == list(range(c[0], c[-1] + 1)):
        return f"CPUs {c[0]}–{c[-1]}"
    return "CPUs " + ", ".join(map(str, c))


def halves():
    """The CPUs this process may use, split for `pinned_load`: (the client's, the servers'),
    the lower half and the upper half (on 2 CPUs, the first and the last)."""
    every = sorted(os.sched_getaffinity(0))
    return set(every[: len(every) // 2]), set(every[len(every) // 2 :])


def pinned_load(b, c, seconds, server_pids, etag=None):
    """A chunk load (`chunk_load`) with the server's threads on the upper half of the CPUs and
    the client on the lower half (`halves`), so that the client has cores of its own and both
    servers run where the other one did. Left to the scheduler, at 1 connection the two servers do not run alike beside
    the client, and CPU time per request moves by several µs with that alone
    (docs/benchmarks.md § Server): pinned apart, they cost the same. Threads the server starts
    meanwhile inherit the pinned mask from the thread that starts them, and keep it."""
    every = os.sched_getaffinity(0)
    client, servers = halves()
    before = {}
    try:
        before = pin(thread_ids(server_pids), servers)
        os.sched_setaffinity(0, client)
        return chunk_load(b, c, seconds, etag)
    finally:
        os.sched_setaffinity(0, every)
        unpin(before)


def loads(bases, seconds, repeat, pids):
    """The shared loads against every server in `bases` (name -> URL ending in the dataset
    path), interleaved: each load runs on each server in turn, `repeat` times, so a change in
    background load hits both alike; the order of the servers turns round each time, so that
    neither always runs first. Returns name -> load -> the median run, with the server's CPU
    time per request and every round's requests/s (`rounds_rps`, in order; `pids`: name -> its
    processes). With two or more CPUs, each load runs a second time with server and client
    pinned apart (`pinned_load`)."""
    out = {name: {} for name in bases}
    etags = {name: etag_of(f"{b}/0/c/0/0/0/0") for name, b in bases.items()}
    shared = [(f"GET, {c} conn", c, False) for c in (256, 16, 1)] + [("304, 256 conn", 256, True)]
    plan = [(load, c, revalidate, False) for load, c, revalidate in shared]
    if len(os.sched_getaffinity(0)) >= 2:
        plan += [(f"{load}, pinned apart", c, revalidate, True) for load, c, revalidate in shared]
    for load, c, revalidate, pinned in plan:
        runs = {name: [] for name in bases}
        for i in range(repeat):
            for name in turn_order(bases, i):
                b = bases[name]
                before = cpu_seconds(pids[name])
                etag = etags[name] if revalidate else None
                if pinned:
                    r = pinned_load(b, c, seconds, pids[name], etag)
                else:
                    r = chunk_load(b, c, seconds, etag)
                r["cpu_us"] = (cpu_seconds(pids[name]) - before) / max(r["rps"] * seconds, 1) * 1e6
                runs[name].append(r)
        for name in bases:
            out[name][load] = dict(median_run(runs[name]), rounds_rps=[r["rps"] for r in runs[name]])
    return out


def rounds_ratio(ours, theirs):
    """The median and range of the rounds' requests/s ratios `ours` / `theirs` (runs of one load,
    round by round), as text: "1.02 (0.95–1.08)"."""
    ratios = sorted(o / t for o, t in zip(ours["rounds_rps"], theirs["rounds_rps"]))
    return f"{ratios[len(ratios) // 2]:.2f} ({ratios[0]:.2f}–{ratios[-1]:.2f})"


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--duration", type=int, default=10, help="seconds per load")
    ap.add_argument("--repeat", type=int, default=3, help="runs per load and server, interleaved; the median is reported")
    ap.add_argument("--soak", type=int, default=0, help="seconds of soak at 256 connections (0: none)")
    ap.add_argument("--soak-only", action="store_true", help="run only the soak")
    ap.add_argument("--soak-evict", type=int, default=200, help="chunk files a second dropped from the page cache during the soak")
    ap.add_argument("--work", default=str(ROOT / "bench-data" / "server"))
    ap.add_argument("--docs", action="store_true", help="point docs/benchmarks.md at this run")
    ap.add_argument("--s3", action="store_true", help="brickserver from an S3 server (s3s-fs) against from disk")
    ap.add_argument("--client", choices=["wrk", "oha"], default="wrk", help="the load generator of the chunk loads")
    a = ap.parse_args()
    global CLIENT
    CLIENT = a.client
    work = pathlib.Path(a.work)
    store = bench_store(work)
    sample = work / "sample"
    region_store = work / "regions.ome.zarr"
    if not region_store.exists():
        subprocess.run([BIN / "ingest", "sample", "-o", sample, "--size", "128,256,256", "--quiet"], check=True)
        subprocess.run([BIN / "ingest", "convert", sample / "nuclei.ome.tif", sample / "membranes.ome.tif", "-o", region_store, "--quiet"], check=True)

    if a.s3:
        s3 = run_s3_loads(a, work, store, region_store)
        report = render_s3(s3, a)
        result = write_result("server-s3.md", report)
        write_result("server-s3.json", json.dumps(s3, indent=1))
        print(report)
        if a.docs:
            point_page_at("server-s3-bench", result, report)
        return
    # Each part's report is written as soon as it is measured, so a later part that fails
    # loses only its own.
    if not a.soak_only:
        results = run_loads(a, work, store, region_store)
        # One result per client: wrk's is the default, oha's sits beside it.
        suffix = "" if a.client == "wrk" else f"-{a.client}"
        publish(a, f"server-bench{suffix}", render(results, a), f"server{suffix}", results)
    if a.soak:
        soak = run_soak(a, store)
        publish(a, "server-soak", render_soak(soak, a), "server-soak", soak)


def publish(a, marker, report, name, results):
    """Writes `report` to docs/benchmarks/`name`.md and `results` to `name`.json, prints the
    report, and with --docs points docs/benchmarks.md's `marker` at it."""
    result = write_result(f"{name}.md", report)
    write_result(f"{name}.json", json.dumps(results, indent=1))
    print(report)
    if a.docs:
        point_page_at(marker, result, report)


def run_loads(a, work, store, region_store):
    """The interleaved loads against nginx and brickserver, then the region queries."""
    with chunk_servers(work, store) as servers:
        # Warm the page cache once for both (they serve the same files).
        chunk_load(servers["nginx"][0], 16, 3)
        results = loads({n: base for n, (base, _) in servers.items()}, a.duration, a.repeat,
                        {n: pids for n, (_, pids) in servers.items()})
        for name, (_, pids) in servers.items():
            results[name]["rss"] = rss_mb(pids)

    if not pathlib.Path(OHA).exists():
        print("oha not installed: no region query loads (they need oha's random URLs)")
        return results
    rs, rs_pids, rs_base = start_brickserver(region_store, "regions")
    try:
        url = f"{rs_base}/regions/regions\\?level=0&channel=[01]&min=[0-9]{{1,2}},[0-9]{{1,2}},[0-9]{{1,2}}&max=2[0-4][0-9],2[0-4][0-9],12[0-8]"
        subprocess.run(["curl", "-sf", f"{rs_base}/regions/regions?level=0&channel=0&min=0,0,0&max=1,1,1"], check=True, capture_output=True)
        results["regions"] = oha(url, 16, a.duration)
        results["regions_1"] = oha(url, 1, a.duration)
        results["regions"]["rss"] = rss_mb(rs_pids)
    finally:
        stop(rs)
    return results


S3_KEY, S3_SECRET = "AKRESIDENCYBENCH", "residency-bench-secret-0123456789"


def start_s3s_fs(root: pathlib.Path):
    """s3s-fs on a loopback port of its own serving `root` (its subfolders are buckets), with
    the bench's credentials: the tests' `start_s3`."""
    return start_s3(root, key=S3_KEY, secret=S3_SECRET)


def run_s3_loads(a, work, store, region_store):
    """The chunk and region loads against brickserver from disk and from s3s-fs, interleaved."""
    bucket = work / "s3" / "bucket"
    if not (bucket / "bench" / "done").exists():
        shutil.rmtree(work / "s3", ignore_errors=True)
        bucket.mkdir(parents=True)
        # Hard links: the same files, no second gigabyte.
        subprocess.run(["cp", "-al", str(store), str(bucket / "bench")], check=True)
        subprocess.run(["cp", "-al", str(region_store), str(bucket / "regions.ome.zarr")], check=True)
    s3, endpoint = start_s3s_fs(work / "s3")
    env = {k: v for k, v in os.environ.items() if not k.startswith("AWS_")}
    env.update(AWS_ACCESS_KEY_ID=S3_KEY, AWS_SECRET_ACCESS_KEY=S3_SECRET)
    servers = {}
    try:
        for name, chunks, regions, extra in [
            ("disk", store, region_store, []),
            ("s3", "s3://bucket/bench", "s3://bucket/regions.ome.zarr", ["--s3-endpoint", endpoint]),
        ]:
            p, pids, base = start_brickserver(chunks, "bench", "--name", f"regions={regions}", *extra, env=env)
            servers[name] = (p, pids, base)
        bases = {name: f"{base}/bench" for name, (_, _, base) in servers.items()}
        etags = {name: etag_of(f"{b}/0/c/0/0/0/0") for name, b in bases.items()}
        region_url = "/regions/regions\\?level=0&channel=[01]&min=[0-9]{1,2},[0-9]{1,2},[0-9]{1,2}&max=2[0-4][0-9],2[0-4][0-9],12[0-8]"
        for name, (_, _, base) in servers.items():
            # Warm both alike: the page cache for the files, the region index for the queries.
            oha(key_regex(bases[name]), 16, 3)
            subprocess.run(["curl", "-sf", f"{base}/regions/regions?level=0&channel=0&min=0,0,0&max=1,1,1"], check=True, capture_output=True)
        plan = [("GET, 16 conn", 16, "get"), ("GET, 1 conn", 1, "get"), ("304, 16 conn", 16, "304"), ("regions, 16 conn", 16, "regions")]
        out = {name: {} for name in servers}
        for load, c, kind in plan:
            runs = {name: [] for name in servers}
            for _ in range(a.repeat):
                for name, (_, _, base) in servers.items():
                    if kind == "304":
                        r = oha(f"{bases[name]}/0/c/0/0/0/0", c, a.duration, headers=[f"If-None-Match: {etags[name]}"], regex=False)
                    elif kind == "regions":
                        r = oha(base + region_url, c, a.duration)
                    else:
                        r = oha(key_regex(bases[name]), c, a.duration)
                    runs[name].append(r)
            for name in servers:
                out[name][load] = median_run(runs[name])
        for name, (_, pids, _) in servers.items():
            out[name]["rss"] = rss_mb(pids)
        out["s3s_fs_rss"] = rss_mb([s3.pid])
        out["s3s_fs_version"] = subprocess.run([shutil.which("s3s-fs") or "s3s-fs", "--version"], capture_output=True, text=True).stdout.strip()
        return out
    finally:
        for p, _, _ in servers.values():
            stop(p)
        s3.terminate()
        s3.wait(timeout=10)


def render_s3(s3, a):
    disk, obj = s3["disk"], s3["s3"]
    lines = [
        f"Measured {datetime.date.today()} on {os.cpu_count()} cores ({cpu_name()}), Linux {platform.release()}, "
        f"by `benchmarks/server_bench.py --s3 --duration {a.duration} --repeat {a.repeat}`: one brickserver reads the stores from disk, "
        f"one from {s3['s3s_fs_version']} on loopback serving the same files (the S3 server, both brickservers and oha share the cores). "
        "Chunk loads: 20,000 chunks of random bytes (median 40 KiB, about 1 GB, four times the default 256 MB memory cache), keys uniform at random. "
        "Region queries: random unaligned boxes of a 2-channel 128×256×256 `ingest sample` store. "
        "The median of the interleaved runs is shown; ratios are S3 / disk.",
        "",
        "| Load | disk req/s | S3 req/s | ratio | disk p50 / p99 ms | S3 p50 / p99 ms | p99 ratio |",
        "|---|---|---|---|---|---|---|",
    ]
    for load, d in disk.items():
        if load == "rss":
            continue
        o = obj[load]
        lines.append(
            f"| {load} | {d['rps']:,.0f} | {o['rps']:,.0f} | {o['rps'] / d['rps']:.2f}x | "
            f"{d['p50_ms']:.2f} / {d['p99_ms']:.2f} | {o['p50_ms']:.2f} / {o['p99_ms']:.2f} | {o['p99_ms'] / max(d['p99_ms'], 1e-9):.2f}x |"
        )
    lines.append("")
    bad = sum(n for side in (disk, obj) for k, v in side.items() if k != "rss" for c, n in v["codes"].items() if c not in (200, 304))
    errors = sum(v["errors"] for side in (disk, obj) for k, v in side.items() if k != "rss")
    lines.append(f"Peak RSS: brickserver from disk {disk['rss']:.0f} MB, from S3 {obj['rss']:.0f} MB, s3s-fs {s3['s3s_fs_rss']:.0f} MB. "
                 f"Answers other than 200/304: {bad}; transport errors: {errors}.")
    return "\n".join(lines) + "\n"


def evict_chunks(store: pathlib.Path, per_second: int, stop: threading.Event):
    """Until `stop` is set, drops `per_second` random chunk files of `store` from the page cache
    every second (`POSIX_FADV_DONTNEED`), so that the server must read them from the disk."""
    rng = np.random.default_rng(11)
    while per_second > 0 and not stop.wait(1.0):
        for z, y, x in zip(*(rng.integers(0, n, per_second) for n in GRID)):
            fd = os.open(store / "0" / "c" / "0" / str(z) / str(y) / str(x), os.O_RDONLY)
            try:
                os.posix_fadvise(fd, 0, 0, os.POSIX_FADV_DONTNEED)
            finally:
                os.close(fd)


def run_soak(a, store):
    """Random chunk GETs at 256 connections for `a.soak` seconds, sampling the server's RSS,
    open descriptors and threads every 5 s."""
    bs, bs_pids, bs_base = start_brickserver(store, "bench", f"--open-files={OPEN_FILES}")
    samples = []
    try:
        if CLIENT == "wrk":
            cmd = wrk_command(f"{bs_base}/bench", 256, a.soak)
        else:
            cmd = [OHA, "-z", f"{a.soak}s", "-c", "256", "--no-tui", "--output-format", "json", "--rand-regex-url", key_regex(f"{bs_base}/bench")]
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True)
        stopping = threading.Event()
        evictor = threading.Thread(target=evict_chunks, args=(store, a.soak_evict, stopping))
        evictor.start()
        t0 = time.time()
        try:
            while proc.poll() is None:
                samples.append((round(time.time() - t0), current_rss_mb(bs_pids), proc_entries(bs.pid, "fd"), proc_entries(bs.pid, "task")))
                time.sleep(5)
        finally:
            stopping.set()
            evictor.join()
        if CLIENT == "wrk":
            r = wrk_result(proc.stdout.read())
            soak = {"seconds": a.soak, "requests": sum(r["codes"].values()), "non_200": r["codes"].get(0, 0),
                    "errors": 0, "rps": r["rps"], "rss_samples": samples}
        else:
            r = json.loads(proc.stdout.read())
            codes = {int(k): v for k, v in r.get("statusCodeDistribution", {}).items()}
            soak = {
                "seconds": a.soak,
                "requests": sum(codes.values()),
                "non_200": sum(v for k, v in codes.items() if k != 200),
                "errors": sum(v for k, v in r.get("errorDistribution", {}).items() if "deadline" not in k),
                "rps": r["summary"]["requestsPerSec"],
                "rss_samples": samples,
            }
    finally:
        stop(bs)
    soak["evicted_per_second"] = a.soak_evict
    return soak


def cpu_name():
    for line in pathlib.Path("/proc/cpuinfo").read_text().splitlines():
        if line.startswith("model name"):
            return line.split(":", 1)[1].strip()
    return platform.processor()


def client_version(client):
    """The load generator and its version, as it reports it."""
    if client == "wrk":
        out = subprocess.run(["wrk", "--version"], capture_output=True, text=True)
        return (out.stdout + out.stderr).split(" [")[0].strip() or "wrk"
    return "oha " + subprocess.run([OHA, "--version"], capture_output=True, text=True).stdout.split()[-1]


def render(results, a):
    ng, bs = results["nginx"], results["brickserver"]
    placement = "they share the cores"
    if any(load.endswith(", pinned apart") for load in ng):
        client, servers = halves()
        placement += (", except in the rows pinned apart, where the servers' threads run on "
                      f"{cpu_list(servers)} and the client on {cpu_list(client)}")
    lines = [
        f"Measured {datetime.date.today()} on {os.cpu_count()} cores ({cpu_name()}), Linux {platform.release()}, "
        f"by `benchmarks/server_bench.py --client {a.client} --duration {a.duration} --repeat {a.repeat}`: {client_version(a.client)}"
        f"{f' ({WRK_THREADS} threads)' if a.client == 'wrk' else ''} on the same machine as the servers ({placement}), 20,000 chunks of random bytes (median 40 KiB), keys uniform at random; "
        f"each server holds up to {OPEN_FILES:,} chunk files open (nginx's `open_file_cache`, per worker; brickserver's `--open-files`, shared); "
        "nginx adds brickserver's caching and CORS fields to its answers (`add_header` of brickserver's own `cache-control`, "
        "`access-control-allow-origin` and `access-control-expose-headers`), so both send the fields web viewers need; "
        "each load ran on nginx and brickserver in turn, repeatedly (which ran first turning round each time), and the median run of each is shown, "
        "with the median and range of the rounds' ratios (each round's brickserver run against its nginx run). "
        "Ratios are brickserver / nginx: above 1 is better for requests/s and MB/s, below 1 is better for latency.",
        "",
        "| Load | nginx req/s | brickserver req/s | ratio | rounds' ratios | nginx MB/s | brickserver MB/s | nginx p50 / p99 ms | brickserver p50 / p99 ms | p99 ratio | CPU µs/req nginx / brickserver |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for load in ng:
        if load == "rss":
            continue
        n, b = ng[load], bs[load]
        lines.append(
            f"| {load} | {n['rps']:,.0f} | {b['rps']:,.0f} | {b['rps'] / n['rps']:.2f}x | {rounds_ratio(b, n)} | {n['mbps']:,.0f} | {b['mbps']:,.0f} | "
            f"{n['p50_ms']:.2f} / {n['p99_ms']:.2f} | {b['p50_ms']:.2f} / {b['p99_ms']:.2f} | {b['p99_ms'] / max(n['p99_ms'], 1e-9):.2f}x | "
            f"{n.get('cpu_us', 0):.0f} / {b.get('cpu_us', 0):.0f} |"
        )
    lines.append("")
    lines.append(f"Peak RSS under these loads: nginx {ng['rss']:.0f} MB (all processes), brickserver {bs['rss']:.0f} MB (default settings; both read the ~1 GB of chunks from the page cache).")
    bad = {k: {c: n for c, n in v["codes"].items() if c not in (200, 304)} for k, v in {**ng, **bs}.items() if k != "rss"}
    lines.append(f"Answers other than 200/304: {sum(sum(v.values()) for v in bad.values())}; transport errors: nginx {sum(v['errors'] for k, v in ng.items() if k != 'rss')}, brickserver {sum(v['errors'] for k, v in bs.items() if k != 'rss')}.")
    if "regions" not in results:
        return "\n".join(lines) + "\n"
    r, r1 = results["regions"], results["regions_1"]
    lines.append("")
    lines.append(
        f"Region queries (random unaligned boxes of a 2-channel 128×256×256 `ingest sample` store): "
        f"1 connection {r1['rps']:,.0f} req/s, p50 {r1['p50_ms']:.3f} ms, p99 {r1['p99_ms']:.3f} ms; "
        f"16 connections {r['rps']:,.0f} req/s, p50 {r['p50_ms']:.3f} ms, p99 {r['p99_ms']:.3f} ms; "
        f"non-200 answers {sum(v for c, v in r['codes'].items() if c != 200) + sum(v for c, v in r1['codes'].items() if c != 200)}; server peak RSS {r['rss']:.0f} MB."
    )
    return "\n".join(lines) + "\n"


def render_soak(soak, a):
    rss = [s[1] for s in soak["rss_samples"]]
    fds = [s[2] for s in soak["rss_samples"]]
    threads = [s[3] for s in soak["rss_samples"]]
    at60 = rss[min(12, len(rss) - 1)]
    return (
        f"Soak measured {datetime.date.today()} on {os.cpu_count()} cores ({cpu_name()}) by "
        f"`benchmarks/server_bench.py --client {a.client} --soak {soak['seconds']} --soak-only --soak-evict {soak['evicted_per_second']}`: {soak['seconds']} s of random chunk GETs "
        f"at 256 connections ({client_version(a.client)} on the same machine), {soak['evicted_per_second']} random chunk files a second dropped from the page cache meanwhile, {soak['requests']:,} requests ({soak['rps']:,.0f}/s), "
        f"{soak['non_200']} non-200 answers, {soak['errors']} transport errors"
        f"{' (wrk counts both as errors)' if a.client == 'wrk' else ''}. Server RSS sampled every 5 s: "
        f"first {rss[0]:.0f} MB, at 60 s {at60:.0f} MB, last {rss[-1]:.0f} MB, max {max(rss):.0f} MB. "
        f"Open descriptors (the 256 connections and the chunk files held open, at most {OPEN_FILES:,}): "
        f"first {fds[0]:,}, last {fds[-1]:,}, max {max(fds):,}. Threads: first {threads[0]}, last {threads[-1]}, max {max(threads)}.\n"
    )


if __name__ == "__main__":
    main()
