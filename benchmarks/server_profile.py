"""Where brickserver's and nginx's CPU time per request goes, under the same chunk load: the
server bench's store and servers (`benchmarks/server_bench.py`), each loaded in turn by wrk for
`--seconds` at `--connections`, for `--rounds` rounds (which server goes first turning round
each round), while `perf record -g -e cpu-clock` samples the server's threads and `perf stat`
counts its system calls, packets sent, context switches and CPU migrations (`--revalidate`: the
server bench's 304 load instead, one chunk's `ETag` sent back as `If-None-Match`). Each sample's time
(its period, in ns of CPU) goes to one bucket by the kernel functions on its call stack (the
first bucket that matches, by name prefix):

- waking the client: `sock_def_readable`, the kernel waking the reader of a socket the server
  wrote to (on loopback the client's receive path runs inside the server's send, and wakes the
  client from there; the rest of that receive path counts as sending). It would also hold the
  server's own socket's wake-ups run in the server's context, which a request-answer load
  hardly has;
- sleeping and switching: the server's own thread going to sleep and coming back (`schedule`);
- sending: the rest of writing answers (`sendfile`, `sendmsg`, TCP, loopback);
- receiving: reading requests;
- opening files: path lookups, `open`, `stat`, `close`;
- other kernel;
- user space: samples whose innermost frame is not the kernel's (the server's own code and its
  libraries).

It prints, per server, the medians over rounds of requests/s, CPU µs per request (from
/proc, as the server bench counts it), each bucket's µs per request, the sampled total and the
counters per request; `--markdown F` writes the same as a table.

    .venv/bin/python benchmarks/server_profile.py [--connections 1] [--seconds 6] [--rounds 3]
                                                  [--revalidate] [--work DIR] [--markdown F]

Needs what the server bench needs (wrk, nginx, a release build, numpy) and `perf` (Debian's
`linux-perf`), run as root or with `kernel.perf_event_paranoid` at most 1.
"""

import argparse
import datetime
import os
import pathlib
import signal
import statistics
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import server_bench as sb  # noqa: E402

FREQUENCY = 4999  # samples a second asked of perf (each sample carries its own period)
KERNEL_START = 0xFFFF800000000000  # x86-64 and arm64: addresses from here on are the kernel's
# (bucket, prefixes of kernel functions that put a stack in it), first match wins; user space
# is the samples whose innermost frame is not the kernel's.
BUCKETS = [
    ("waking the client", ("sock_def_readable",)),
    ("sleeping and switching", ("schedule",)),
    ("sending", ("do_sendfile", "tcp_sendmsg", "sock_sendmsg", "__tcp_push_pending_frames", "do_tcp_setsockopt", "tcp_write_xmit")),
    ("receiving", ("tcp_recvmsg", "sock_recvmsg", "__sys_recvfrom", "ksys_read")),
    ("opening files", ("path_openat", "do_sys_openat2", "vfs_statx", "vfs_fstat", "__x64_sys_close", "filp_close")),
]
USER = "user space"
OTHER = "other kernel"
ORDER = [b for b, _ in BUCKETS] + [OTHER, USER]
# perf's event -> what the report calls it.
COUNTERS = {"raw_syscalls:sys_enter": "system calls", "net:net_dev_queue": "packets sent",
            "context-switches": "context switches", "cpu-migrations": "CPU migrations"}


def bucket_of(stack):
    """The bucket of one sample's call stack (innermost frame first, `(is_kernel, symbol)`)."""
    if not stack or not stack[0][0]:
        return USER
    kernel = [symbol for is_kernel, symbol in stack if is_kernel]
    for name, prefixes in BUCKETS:
        if any(symbol.startswith(prefix) for symbol in kernel for prefix in prefixes):
            return name
    return OTHER


def samples(script: str):
    """The samples in `perf script -F period,ip,sym` output: `(period, stack)`, the stack
    innermost frame first, each frame `(is_kernel, symbol)`. A sample is a line of its period,
    then a tab-indented line per frame; lines of any other shape are skipped."""
    period, stack = None, []
    for line in script.splitlines():
        if line.startswith("\t"):
            parts = line.split(None, 1)
            try:
                ip = int(parts[0], 16)
            except (IndexError, ValueError):
                continue
            stack.append((ip >= KERNEL_START, parts[1] if len(parts) > 1 else ""))
            continue
        if period is not None and stack:
            yield period, stack
        period, stack = None, []
        if line.strip().isdigit():
            period = int(line)
    if period is not None and stack:
        yield period, stack


def time_by_bucket(data: pathlib.Path):
    """Nanoseconds of CPU per bucket in a `perf record -g -e cpu-clock` file."""
    script = subprocess.run(["perf", "script", "-i", str(data), "-F", "period,ip,sym"], capture_output=True, text=True, check=True).stdout
    ns = dict.fromkeys(ORDER, 0)
    for period, stack in samples(script):
        ns[bucket_of(stack)] += period
    return ns


def counters(path: pathlib.Path):
    """`perf stat -x,` output: counter → value."""
    found = {}
    for line in path.read_text().splitlines():
        fields = line.split(",")
        if len(fields) > 3 and fields[0].replace(".", "").isdigit():
            found[fields[2]] = float(fields[0])
    return found


def profile(name, base, pids, connections, seconds, scratch: pathlib.Path, etag=None):
    """One load of `base` by wrk (with `etag`, its revalidations answered 304), sampled and
    counted: requests/s and per-request figures."""
    data, stat = scratch / f"{name}.data", scratch / f"{name}.stat"
    targets = ",".join(map(str, pids))
    record = subprocess.Popen(["perf", "record", "-q", "-e", "cpu-clock", "-F", str(FREQUENCY), "-g", "-p", targets, "-o", str(data)],
                              stdout=subprocess.DEVNULL)
    count = subprocess.Popen(["perf", "stat", "-x,", "-e", ",".join(COUNTERS), "-p", targets, "-o", str(stat)])
    try:
        time.sleep(0.5)  # both attached before the load begins (the server idles meanwhile)
        cpu = sb.cpu_seconds(pids)
        result = sb.wrk(base, connections, seconds, etag)
        cpu = sb.cpu_seconds(pids) - cpu
    finally:
        for p in (record, count):
            p.send_signal(signal.SIGINT)
            p.wait()
    requests = sum(result["codes"].values())
    us = {b: ns / 1e3 / requests for b, ns in time_by_bucket(data).items()}
    found = counters(stat)
    return {
        "rps": result["rps"],
        "cpu_us": cpu / requests * 1e6,
        "sampled_us": sum(us.values()),
        "buckets": us,
        "counters": {name: found.get(event, 0.0) / requests for event, name in COUNTERS.items()},
    }


def medians(runs):
    """Per figure, the median over rounds."""
    med = statistics.median
    return {
        "rps": med(r["rps"] for r in runs),
        "cpu_us": med(r["cpu_us"] for r in runs),
        "sampled_us": med(r["sampled_us"] for r in runs),
        "buckets": {b: med(r["buckets"][b] for r in runs) for b in ORDER},
        "counters": {c: med(r["counters"][c] for r in runs) for c in COUNTERS.values()},
    }


def table(results, a):
    """The report: one column per server."""
    names = list(results)
    rows = [f"| | {' | '.join(names)} |", "|---|" + "---|" * len(names)]

    def row(label, value, form):
        rows.append(f"| {label} | " + " | ".join(format(value(results[n]), form) for n in names) + " |")

    row("requests/s", lambda r: r["rps"], ",.0f")
    row("CPU µs a request (/proc)", lambda r: r["cpu_us"], ".1f")
    row("sampled µs a request (median of the rounds' sums)", lambda r: r["sampled_us"], ".1f")
    for b in ORDER:
        row(f"— {b}", lambda r: r["buckets"][b], ".1f")
    for c in COUNTERS.values():
        row(f"{c} a request", lambda r: r["counters"][c], ".3f")
    load = "one chunk's revalidations answered 304" if a.revalidate else "random chunk GETs"
    flag = " --revalidate" if a.revalidate else ""
    head = (f"Measured {datetime.date.today().isoformat()} on {sb.cpu_name()} ({os.cpu_count()} CPUs) by "
            f"`benchmarks/server_profile.py --connections {a.connections} --seconds {a.seconds} --rounds {a.rounds}{flag}`: "
            f"wrk, {load}, servers and client sharing the CPUs; medians of {a.rounds} rounds.")
    return head + "\n\n" + "\n".join(rows) + "\n"


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--connections", type=int, default=1, help="wrk's connections [1]")
    ap.add_argument("--seconds", type=int, default=6, help="seconds per load [6]")
    ap.add_argument("--rounds", type=int, default=3, help="loads per server, alternating [3]")
    ap.add_argument("--revalidate", action="store_true", help="the 304 load: one chunk revalidated with its ETag")
    ap.add_argument("--work", default=str(sb.ROOT / "bench-data" / "server"), help="the server bench's work folder (its store is made there if missing)")
    ap.add_argument("--markdown", type=pathlib.Path, help="write the table here too")
    a = ap.parse_args()
    work = pathlib.Path(a.work)
    store = sb.bench_store(work)
    runs = {"brickserver": [], "nginx": []}  # the report's columns, in this order
    with sb.chunk_servers(work, store) as servers, tempfile.TemporaryDirectory(prefix="server-profile-") as scratch:
        for base, _ in servers.values():
            sb.wrk(base, 16, 3)  # the page cache and both servers' open files warm
        etags = {name: sb.etag_of(f"{base}/0/c/0/0/0/0") if a.revalidate else None
                 for name, (base, _) in servers.items()}
        for i in range(a.rounds):
            for name in sb.turn_order(runs, i):
                base, pids = servers[name]
                runs[name].append(profile(name, base, pids, a.connections, a.seconds, pathlib.Path(scratch),
                                          etags[name]))
    report = table({n: medians(r) for n, r in runs.items()}, a)
    print(report)
    if a.markdown:
        a.markdown.write_text(report)


if __name__ == "__main__":
    main()
