"""`benchmarks/server_bench.py`'s placement of the rows "pinned apart" (the client on the lower
half of the CPUs, the servers on the upper half), how its report names those CPUs, wrk's
threads, and the answer fields nginx is given so that it sends brickserver's. The loads
themselves need nginx and wrk on quiet cores, so they run in the benchmark, not here."""

import sys

from support.paths import ROOT
from support.stores import small_store

sys.path.insert(0, str(ROOT / "benchmarks"))
import server_bench as sb  # noqa: E402


def test_pinned_apart_splits_the_cpus_in_halves(monkeypatch):
    for cpus, client, servers in [
        (set(range(16)), set(range(8)), set(range(8, 16))),
        ({0, 1}, {0}, {1}),  # the development machine: as before, the last CPU for the servers
        ({2, 5, 7}, {2}, {5, 7}),  # an odd count leaves the servers the larger half
    ]:
        monkeypatch.setattr(sb.os, "sched_getaffinity", lambda pid, cpus=cpus: cpus)
        assert sb.halves() == (client, servers)


def test_cpus_are_named_as_runs():
    assert sb.cpu_list({1}) == "CPU 1"
    assert sb.cpu_list(set(range(8, 16))) == "CPUs 8–15"
    assert sb.cpu_list({2, 5, 7}) == "CPUs 2, 5, 7"


def test_wrk_runs_its_threads_but_never_more_than_its_connections(monkeypatch):
    monkeypatch.setattr(sb, "WRK_THREADS", 8)
    tail = ["--latency", "-s", str(sb.WRK_SCRIPT), "http://127.0.0.1:9", "--", "/bench", "20", "25", "40"]
    assert sb.wrk_command("http://127.0.0.1:9/bench", 1, 4) == ["wrk", "-t1", "-c1", "-d4s", *tail]
    assert sb.wrk_command("http://127.0.0.1:9/bench", 256, 4) == ["wrk", "-t8", "-c256", "-d4s", *tail]


def test_nginx_is_given_brickserver_s_caching_and_cors_fields(tmp_path):
    server, _, base = sb.start_brickserver(small_store(tmp_path), "bench")
    try:
        fields = sb.mirrored_fields(f"{base}/bench/0/c/0/0/0/0")
    finally:
        sb.stop(server)
    assert fields == (
        '  add_header cache-control "public, max-age=31536000, immutable";\n'
        '  add_header access-control-allow-origin "*";\n'
        '  add_header access-control-expose-headers "etag,content-range,content-length,accept-ranges";\n'
    )
