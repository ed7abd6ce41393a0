"""A throttling TCP proxy (asyncio, standard library only): forwards a local port to a target
and shapes the link, as a building or home network would, for the remote-session bench
(benchmarks/remote_session_bench.py).

Each direction is one shared link (all connections together, as over one network path): a
chunk of N bytes leaves the link when the N bytes before it have (the link serialises them at
`mbit` Mbit/s) and arrives `delay_ms` later (one-way latency; a round trip costs twice that plus
the serialisation). The proxy reads from a side only as fast as the link drains, so TCP flow
control pushes back on the sender as a slow link does.

    python3 benchmarks/throttle_proxy.py --target 127.0.0.1:8000 --listen 127.0.0.1:8001 \\
        --mbit 100 --rtt-ms 20

    from throttle_proxy import ThrottleProxy
    with ThrottleProxy(("127.0.0.1", 8000), mbit=100, rtt_ms=20) as proxy:
        url = f"http://127.0.0.1:{proxy.port}"
        ...
        proxy.stats()  # {"up_bytes": ..., "down_bytes": ..., "connections": ...}

`up` is client → target (requests), `down` target → client (answers).
"""

import argparse
import asyncio
import collections
import threading
import time

CHUNK = 16 * 1024
"""Bytes read and forwarded at a time (about 1.3 ms of a 100 Mbit/s link)."""

BACKLOG_S = 0.02
"""How far ahead of the link the proxy reads (seconds of the link's time)."""


class Link:
    """One direction of the shaped link: serialisation at `bytes_per_s`, then `delay_s`."""

    def __init__(self, bytes_per_s: float, delay_s: float):
        if bytes_per_s <= 0:
            raise ValueError(f"link rate must be positive, got {bytes_per_s} bytes/s")
        if delay_s < 0:
            raise ValueError(f"link delay must not be negative, got {delay_s} s")
        self.bytes_per_s = bytes_per_s
        self.delay_s = delay_s
        self.free_at = 0.0
        self.bytes = 0

    def send(self, n: int, now: float) -> tuple[float, float]:
        """Books `n` bytes sent at `now`: returns (when they have left the link, when they
        arrive at the far end)."""
        departure = max(now, self.free_at) + n / self.bytes_per_s
        self.free_at = departure
        self.bytes += n
        return departure, departure + self.delay_s


async def _pump(reader, writer, link: Link):
    """Forwards `reader` to `writer` through `link` until EOF, then half-closes `writer`."""
    loop = asyncio.get_running_loop()
    queue = collections.deque()
    arrived = asyncio.Event()
    done = False

    async def deliver():
        while True:
            while not queue:
                if done:
                    return
                arrived.clear()
                await arrived.wait()
            due, data = queue.popleft()
            wait = due - loop.time()
            if wait > 0:
                await asyncio.sleep(wait)
            if data is None:
                return
            writer.write(data)
            await writer.drain()

    delivery = asyncio.create_task(deliver())
    try:
        while True:
            data = await reader.read(CHUNK)
            now = loop.time()
            if not data:
                queue.append((now + link.delay_s, None))
                arrived.set()
                break
            left, due = link.send(len(data), now)
            queue.append((due, data))
            arrived.set()
            # Read on only once the link has nearly taken this chunk: back pressure on the
            # sender, with a little backlog so that the timer's lateness never idles the link.
            if left - now > BACKLOG_S:
                await asyncio.sleep(left - now - BACKLOG_S)
    except (ConnectionError, OSError):
        pass
    finally:
        done = True
        arrived.set()
        try:
            await delivery
            if writer.can_write_eof():
                writer.write_eof()
        except (ConnectionError, OSError):
            pass


class ThrottleProxy:
    """Forwards `listen` (default 127.0.0.1 on a free port) to `target` (host, port) through a
    link of `mbit` Mbit/s each way and `rtt_ms` of round-trip latency (half each way), on an
    event loop in a thread of its own. Use as a context manager; `port` is where it listens."""

    def __init__(self, target, *, mbit: float = 100.0, rtt_ms: float = 20.0, listen=("127.0.0.1", 0)):
        self.target = (target[0], int(target[1]))
        self.mbit = float(mbit)
        self.rtt_ms = float(rtt_ms)
        rate = self.mbit * 1e6 / 8
        self.up = Link(rate, self.rtt_ms / 2000)
        self.down = Link(rate, self.rtt_ms / 2000)
        self.connections = 0
        self._listen = (listen[0], int(listen[1]))
        self._loop = asyncio.new_event_loop()
        self._server = None
        self._thread = threading.Thread(target=self._loop.run_forever, daemon=True)
        self.port = None

    async def _handle(self, client_reader, client_writer):
        self.connections += 1
        try:
            target_reader, target_writer = await asyncio.open_connection(*self.target)
        except OSError:
            client_writer.close()
            return
        await asyncio.gather(
            _pump(client_reader, target_writer, self.up),
            _pump(target_reader, client_writer, self.down),
        )
        for w in (client_writer, target_writer):
            w.close()

    async def _start(self):
        self._server = await asyncio.start_server(self._handle, *self._listen)
        return self._server.sockets[0].getsockname()[1]

    def start(self):
        """Starts listening; returns the port."""
        self._thread.start()
        self.port = asyncio.run_coroutine_threadsafe(self._start(), self._loop).result(timeout=10)
        return self.port

    def stop(self):
        """Stops listening and ends the event loop (connections still open are dropped)."""

        async def close():
            self._server.close()
            tasks = [t for t in asyncio.all_tasks() if t is not asyncio.current_task()]
            for t in tasks:
                t.cancel()
            await asyncio.gather(*tasks, return_exceptions=True)

        if self._server is not None:
            asyncio.run_coroutine_threadsafe(close(), self._loop).result(timeout=10)
        self._loop.call_soon_threadsafe(self._loop.stop)
        self._thread.join(timeout=10)
        self._loop.close()

    def stats(self) -> dict:
        """Bytes that have entered the link each way so far, and connections accepted."""
        return {"up_bytes": self.up.bytes, "down_bytes": self.down.bytes, "connections": self.connections}

    def settings(self) -> dict:
        """The link: rate each way and round-trip latency."""
        return {"mbit_per_s": self.mbit, "rtt_ms": self.rtt_ms, "one_way_delay_ms": self.rtt_ms / 2}

    def __enter__(self):
        self.start()
        return self

    def __exit__(self, *exc):
        self.stop()


def _address(text):
    host, sep, port = text.rpartition(":")
    if not sep or not port.isdigit():
        raise argparse.ArgumentTypeError(f"expected HOST:PORT, got {text!r}")
    return host, int(port)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--target", type=_address, required=True, help="HOST:PORT to forward to")
    ap.add_argument("--listen", type=_address, default=("127.0.0.1", 0), help="HOST:PORT to listen on (default: a free port on 127.0.0.1)")
    ap.add_argument("--mbit", type=float, default=100.0, help="link rate each way, Mbit/s (default 100)")
    ap.add_argument("--rtt-ms", type=float, default=20.0, help="round-trip latency, ms (default 20)")
    args = ap.parse_args()
    with ThrottleProxy(args.target, mbit=args.mbit, rtt_ms=args.rtt_ms, listen=args.listen) as proxy:
        print(f"listening on {args.listen[0]}:{proxy.port} -> {args.target[0]}:{args.target[1]} "
              f"({args.mbit:g} Mbit/s, {args.rtt_ms:g} ms RTT)", flush=True)
        try:
            while True:
                time.sleep(3600)
        except KeyboardInterrupt:
            pass


if __name__ == "__main__":
    main()
