"""The remote-session bench's throttling proxy (benchmarks/throttle_proxy.py): its rate over a
transfer of a few MB and the latency of a small round trip, against a local echo/sink server."""

import socket
import socketserver
import sys
import threading
import time

import pytest

from support.paths import ROOT

sys.path.insert(0, str(ROOT / "benchmarks"))
from throttle_proxy import Link, ThrottleProxy  # noqa: E402


class _Echo(socketserver.BaseRequestHandler):
    """Echoes a line `ping\\n`; to `send N\\n` answers N bytes; `sink\\n` reads to EOF and
    answers the count."""

    def handle(self):
        f = self.request.makefile("rb")
        for line in f:
            cmd = line.strip().split()
            if cmd[0] == b"ping":
                self.request.sendall(b"pong\n")
            elif cmd[0] == b"send":
                self.request.sendall(b"x" * int(cmd[1]))
            elif cmd[0] == b"sink":
                n = 0
                while chunk := f.read1(65536):
                    n += len(chunk)
                self.request.sendall(f"{n}\n".encode())
                return


@pytest.fixture(scope="module")
def echo():
    server = socketserver.ThreadingTCPServer(("127.0.0.1", 0), _Echo)
    server.daemon_threads = True
    threading.Thread(target=server.serve_forever, daemon=True).start()
    yield server.server_address
    server.shutdown()
    server.server_close()


def recv_exactly(sock, n):
    got = 0
    while got < n:
        chunk = sock.recv(min(1 << 20, n - got))
        assert chunk, f"connection closed after {got} of {n} bytes"
        got += len(chunk)
    return got


ROUNDS = 3


def assert_rate(transfer, ideal: float):
    """Runs `transfer` (it returns its seconds) `ROUNDS` times: every round takes at least 90 %
    of `ideal` (the link never runs fast), and the fastest at most 15 % (and 0.1 s) more. A
    busy machine can stall the proxy's thread in one round and leave the link idle; it rarely
    does in all three, while a link set too slow is slow in every round."""
    times = [transfer() for _ in range(ROUNDS)]
    assert min(times) >= 0.9 * ideal and min(times) <= 1.15 * ideal + 0.1, (times, ideal)


def test_downstream_rate_is_the_configured_one(echo):
    """4 MB at 50 Mbit/s take 0.64 s plus the 10 ms round trip (`assert_rate`'s bounds);
    every byte counted."""
    n = 4_000_000

    def transfer():
        with ThrottleProxy(echo, mbit=50, rtt_ms=10) as proxy:
            with socket.create_connection(("127.0.0.1", proxy.port)) as s:
                t = time.perf_counter()
                s.sendall(f"send {n}\n".encode())
                recv_exactly(s, n)
                elapsed = time.perf_counter() - t
            stats = proxy.stats()
        assert stats == {"up_bytes": len(f"send {n}\n"), "down_bytes": n, "connections": 1}
        return elapsed

    assert_rate(transfer, n * 8 / 50e6 + 0.010)


def test_upstream_rate_is_the_configured_one(echo):
    """3 MB uploaded at 40 Mbit/s take 0.6 s (`assert_rate`'s bounds); the target got every
    byte."""
    n = 3_000_000

    def transfer():
        with ThrottleProxy(echo, mbit=40, rtt_ms=10) as proxy:
            with socket.create_connection(("127.0.0.1", proxy.port)) as s:
                t = time.perf_counter()
                s.sendall(b"sink\n" + b"y" * n)
                s.shutdown(socket.SHUT_WR)
                answer = s.makefile("rb").readline()
                elapsed = time.perf_counter() - t
            stats = proxy.stats()
        assert answer == f"{n}\n".encode()
        assert stats["up_bytes"] == n + 5 and stats["down_bytes"] == len(answer)
        return elapsed

    assert_rate(transfer, (n + 5) * 8 / 40e6 + 0.010)


def test_a_small_round_trip_takes_at_least_the_rtt(echo):
    """A 5-byte ping and its answer: every one at least 40 ms with --rtt-ms 40, and the
    fastest of 5 at most 60 ms (a proxy that delayed each twice would take 80)."""
    with ThrottleProxy(echo, mbit=100, rtt_ms=40) as proxy:
        with socket.create_connection(("127.0.0.1", proxy.port)) as s:
            f = s.makefile("rb")
            times = []
            for _ in range(5):
                t = time.perf_counter()
                s.sendall(b"ping\n")
                assert f.readline() == b"pong\n"
                times.append(time.perf_counter() - t)
    assert 0.040 <= min(times) <= 0.060, times


def test_two_connections_share_the_link(echo):
    """Two 2 MB downloads at once over 50 Mbit/s take as long as one of 4 MB: the link is
    shared, not given to each connection."""
    n = 2_000_000

    def transfer():
        with ThrottleProxy(echo, mbit=50, rtt_ms=4) as proxy:
            def fetch():
                with socket.create_connection(("127.0.0.1", proxy.port)) as s:
                    s.sendall(f"send {n}\n".encode())
                    recv_exactly(s, n)

            t = time.perf_counter()
            threads = [threading.Thread(target=fetch) for _ in range(2)]
            for th in threads:
                th.start()
            for th in threads:
                th.join()
            elapsed = time.perf_counter() - t
            assert proxy.stats()["down_bytes"] == 2 * n and proxy.stats()["connections"] == 2
        return elapsed

    assert_rate(transfer, 2 * n * 8 / 50e6)


def test_the_link_refuses_nonsense_settings():
    with pytest.raises(ValueError, match="link rate must be positive, got 0 bytes/s"):
        Link(0, 0.01)
    with pytest.raises(ValueError, match="link delay must not be negative, got -1 s"):
        Link(1e6, -1)
