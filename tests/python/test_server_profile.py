"""`benchmarks/server_profile.py`'s sorting of perf samples: stacks parsed from `perf script`
output, each put in the first bucket whose kernel function it holds, user space by its innermost
frame; and `perf stat -x,` output read. The loads themselves need perf and nginx, so they run in
the benchmark, not here."""

import sys

from support.paths import ROOT

sys.path.insert(0, str(ROOT / "benchmarks"))
import server_profile as sp  # noqa: E402

SCRIPT = """
\tffffffff82250979 _raw_spin_unlock_irqrestore
\tffffffff81ef0001 sock_def_readable
\tffffffff8207fc95 __tcp_push_pending_frames
\tffffffff816dad3a do_sendfile
\t           fc80a sendfile

\tffffffff813aecd3 finish_task_switch.isra.0
\tffffffff82248b73 schedule
\tffffffff8175837e do_epoll_wait
\t          108f36 epoll_wait

\tffffffff816dad3a do_sendfile
\t           fc80a sendfile

\t          55aa10 residency_brickserver::http1::parse_head
\t          55ab20 residency_brickserver::http1::connection

\tffffffff81700000 path_openat
\tffffffff81700100 do_sys_openat2

\tffffffff81200000 handle_softirqs
"""


def test_stacks_are_parsed_innermost_frame_first_with_the_kernels_marked():
    stacks = list(sp.stacks(SCRIPT))
    assert len(stacks) == 6
    assert stacks[0][0] == (True, "_raw_spin_unlock_irqrestore")
    assert stacks[0][-1] == (False, "sendfile")
    assert stacks[3] == [(False, "residency_brickserver::http1::parse_head"), (False, "residency_brickserver::http1::connection")]


def test_each_sample_goes_to_the_first_bucket_that_matches():
    buckets = [sp.bucket_of(s) for s in sp.stacks(SCRIPT)]
    # Waking the client comes before sending, though that stack holds both.
    assert buckets == ["waking the client", "sleeping and switching", "sending", "user space", "opening files", "other kernel"]


def test_perf_stat_counters_are_read_by_name(tmp_path):
    text = (
        "# started on Sun Dec  6 03:40:00 2026\n\n"
        "383140,,raw_syscalls:sys_enter,6012345678,100.00,,\n"
        "63812,,net:net_dev_queue,6012345678,100.00,,\n"
        "51234,,context-switches,6012345678,100.00,,\n"
        "<not counted>,,cpu-migrations,0,0.00,,\n"
    )
    path = tmp_path / "server.stat"
    path.write_text(text)
    assert sp.counters(path) == {"raw_syscalls:sys_enter": 383140.0, "net:net_dev_queue": 63812.0, "context-switches": 51234.0}
