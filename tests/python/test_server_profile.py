"""`benchmarks/server_profile.py`'s sorting of perf samples: samples parsed from `perf script -F
period,ip,sym` output (a line of the period, then a tab-indented line per frame), each put in
the first bucket whose kernel function it holds, user space by its innermost frame; and `perf
stat -x,` output read. The loads themselves need perf and nginx, so they run in the benchmark,
not here."""

import sys

from support.paths import ROOT

sys.path.insert(0, str(ROOT / "benchmarks"))
import server_profile as sp  # noqa: E402

# As perf prints it: a blank line before each sample, one after.
SCRIPT = """
    200040 
\tffffffff82250979 _raw_spin_unlock_irqrestore
\tffffffff81ef0001 sock_def_readable
\tffffffff8207fc95 __tcp_push_pending_frames
\tffffffff816dad3a do_sendfile
\t           fc80a sendfile
\t               0 [unknown]


    200040 
\tffffffff813aecd3 finish_task_switch.isra.0
\tffffffff82248b73 schedule
\tffffffff8175837e do_epoll_wait
\t          108f36 epoll_wait


    100020 
\tffffffff816dad3a do_sendfile
\t           fc80a sendfile


    200040 
\t          55aa10 residency_brickserver::http1::parse_head
\t          55ab20 schedule_the_next_request
\tDEFERRED CALLCHAIN
\t          55ab30 residency_brickserver::http1::connection


    200040 
\tffffffff81700000 path_openat
\tffffffff81700100 do_sys_openat2


    300060 
\tffffffff81200000 handle_softirqs
\t          400000 schedule_in_user_space

"""


def test_samples_are_parsed_with_their_periods_innermost_frame_first():
    found = list(sp.samples(SCRIPT))
    assert [period for period, _ in found] == [200040, 200040, 100020, 200040, 200040, 300060]
    first = found[0][1]
    assert first[0] == (True, "_raw_spin_unlock_irqrestore")
    assert first[-2:] == [(False, "sendfile"), (False, "[unknown]")]
    # A line that is not a frame (no address) is skipped, not fatal.
    assert [symbol for _, symbol in found[3][1]] == [
        "residency_brickserver::http1::parse_head",
        "schedule_the_next_request",
        "residency_brickserver::http1::connection",
    ]


def test_each_sample_goes_to_the_first_bucket_whose_kernel_function_it_holds():
    buckets = [sp.bucket_of(stack) for _, stack in sp.samples(SCRIPT)]
    # Waking the client comes before sending, though that stack holds both; user-space frames
    # named like a kernel function put nothing in a kernel bucket.
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
