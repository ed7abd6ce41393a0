"""A seeded fault proxy: an HTTP/1.1 reverse proxy (standard library only, one thread per
connection) on loopback in front of an S3 server, which answers a share of requests with a 500
or 503 (an S3 error document), resets a share of connections (before the answer's headers, or
after part of its body), and stalls a share for a while before answering, for the fault tests
(tests/python/test_faults.py) and benchmarks.

Each request draws its fate from one random generator seeded per run, in the order the
requests arrive: one client making one request at a time gets the same faults on every run.
Requests are forwarded with their headers untouched (`Host` included, so S3 signatures hold),
and answers are sent with the target's headers and a `Content-Length`.

    python3 tests/python/support/fault_proxy.py --target http://127.0.0.1:9000 --port 9001 \\
        --error-rate 0.2 --reset-rate 0.05 --stall-rate 0.01 --stall-s 5 --seed 7

    from support.fault_proxy import FaultProxy
    with FaultProxy("http://127.0.0.1:9000", error_rate=0.2, seed=7) as proxy:
        url = proxy.url             # the endpoint to give the client
        proxy.set_mode("fail")      # every request answered 503 from now on
        proxy.set_mode("healthy")   # every request forwarded untouched
        proxy.stats()               # {"requests": ..., "errors_500": ..., ...}

Its answers to `GET /__fault__/stats` (the counters as JSON) and `POST /__fault__/mode/MODE`
let another process read and steer it (`__fault__` is no valid bucket name, so no S3 key is
hidden by them).
"""

import argparse
import http.client
import json
import random
import signal
import socket
import struct
import threading
import time
import urllib.parse
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

MODES = ("faults", "healthy", "fail")
"""`faults`: each request draws its fate at the configured rates; `healthy`: every request is
forwarded; `fail`: every request is answered 503 (or, with `fail_kind="reset"`, its connection
is reset before the answer)."""

COUNTERS = ("requests", "forwarded", "errors_500", "errors_503", "resets_before_headers",
            "resets_mid_body", "stalls")
"""What `FaultProxy.stats` counts: requests received, answered by the target, answered 500 or
503 by the proxy, reset before the headers or after part of the body, and stalled."""

CONTROL = "/__fault__/"
"""The path prefix of the proxy's own control requests."""

S3_ERRORS = {
    500: ("InternalError", "We encountered an internal error. Please try again."),
    503: ("SlowDown", "Please reduce your request rate."),
}
"""The S3 error code and message of each injected status."""


def s3_error_body(status: int, path: str, request_id: str) -> bytes:
    """The S3 XML error document of an injected `status` for `path`."""
    code, message = S3_ERRORS[status]
    return (f'<?xml version="1.0" encoding="UTF-8"?>\n<Error><Code>{code}</Code>'
            f"<Message>{message}</Message><Resource>{path}</Resource>"
            f"<RequestId>{request_id}</RequestId></Error>").encode()


class BackgroundServer:
    """An HTTP server (`self._server`, made by the subclass) served on a background thread:
    started and stopped, or used as a context manager."""

    def start(self):
        """Starts serving on a background thread."""
        self._thread = threading.Thread(target=self._server.serve_forever, daemon=True)
        self._thread.start()
        return self

    def stop(self):
        """Stops serving and closes the listening socket."""
        self._server.shutdown()
        self._server.server_close()

    def __enter__(self):
        return self.start()

    def __exit__(self, *_):
        self.stop()


class FaultProxy(BackgroundServer):
    """The proxy, listening on `127.0.0.1:port` (0: a free port) in front of `target`
    (`http://host:port`) from `start()` (or `with`) until `stop()`.

    Rates are shares of requests in `faults` mode, drawn in this order: `error_rate` answered
    500 or 503 (half each), `reset_rate` reset (half before the headers, half after about half
    of the body; an answer without a body is reset before its headers), `stall_rate` held
    `stall_s` seconds before being forwarded. Their sum must not exceed 1. With `fail_after`,
    the proxy switches itself to `fail` mode once it has received that many requests (a store
    that goes down in the middle of a run). `fail_when(method, path)`, if given, picks requests
    that are always answered 503 (in `faults` mode), such as the uploads of one key."""

    def __init__(self, target: str, port: int = 0, *, error_rate: float = 0.0,
                 reset_rate: float = 0.0, stall_rate: float = 0.0, stall_s: float = 5.0,
                 seed: int = 0, mode: str = "faults", fail_kind: str = "503",
                 fail_after: int | None = None, fail_when=None):
        parsed = urllib.parse.urlsplit(target)
        if parsed.scheme != "http" or not parsed.hostname or not parsed.port:
            raise ValueError(f"{target}: the target is http://HOST:PORT")
        for name, rate in [("error_rate", error_rate), ("reset_rate", reset_rate),
                           ("stall_rate", stall_rate)]:
            if not 0.0 <= rate <= 1.0:
                raise ValueError(f"{name} must lie in [0, 1], got {rate}")
        if error_rate + reset_rate + stall_rate > 1.0:
            raise ValueError(f"the rates add up to more than 1: {error_rate} + {reset_rate} + "
                             f"{stall_rate}")
        if stall_s < 0:
            raise ValueError(f"stall_s must not be negative, got {stall_s}")
        self.target = (parsed.hostname, parsed.port)
        self.error_rate, self.reset_rate, self.stall_rate = error_rate, reset_rate, stall_rate
        self.stall_s = stall_s
        self.seed = seed
        self.fail_after = fail_after
        self.fail_when = fail_when
        self._rng = random.Random(seed)
        self._lock = threading.Lock()
        self._counts = dict.fromkeys(COUNTERS, 0)
        self._in_flight = 0
        self._paths = []
        self._max_in_flight = 0
        self._mode = "faults"
        self._fail_kind = "503"
        self.set_mode(mode, fail_kind)
        self._server = _Server(("127.0.0.1", port), _handler_for(self))
        self._server.daemon_threads = True
        self.port = self._server.server_address[1]
        self.url = f"http://127.0.0.1:{self.port}"
        self._thread = None

    def set_mode(self, mode: str, fail_kind: str = "503"):
        """Switches to `mode` (see `MODES`) for the requests that arrive from now on;
        `fail_kind` (`503`, `500` or `reset`) is how `fail` fails them."""
        if mode not in MODES:
            raise ValueError(f"unknown mode {mode!r} (one of {', '.join(MODES)})")
        if fail_kind not in ("503", "500", "reset"):
            raise ValueError(f"unknown fail kind {fail_kind!r} (503, 500 or reset)")
        with self._lock:
            self._mode, self._fail_kind = mode, fail_kind

    def stats(self) -> dict:
        """The counters (see `COUNTERS`), with `faults`: all requests the proxy failed or
        stalled, the mode, and `max_in_flight`: the most requests it held at once, each from
        its arrival until its answer starts (a client that fetches concurrently shows here)."""
        with self._lock:
            counts = dict(self._counts)
            mode = self._mode
            counts["max_in_flight"] = self._max_in_flight
        counts["faults"] = sum(counts[k] for k in COUNTERS[2:])
        counts["mode"] = mode
        return counts

    def paths(self) -> list:
        """The path (with its query) of every request received but the proxy's own, in order."""
        with self._lock:
            return list(self._paths)

    def _enter(self):
        with self._lock:
            self._in_flight += 1
            self._max_in_flight = max(self._max_in_flight, self._in_flight)

    def _leave(self):
        with self._lock:
            self._in_flight -= 1

    def _count(self, name: str):
        with self._lock:
            self._counts[name] += 1

    def _fate(self, method: str, path: str) -> str:
        """The fate of a request for `path`: `forward`, `500`, `503`, `reset_headers`,
        `reset_body` or `stall`, drawn (in `faults` mode) from the seeded generator."""
        with self._lock:
            self._counts["requests"] += 1
            self._paths.append(path)
            if self.fail_after is not None and self._counts["requests"] > self.fail_after:
                self._mode, self.fail_after = "fail", None
            if self._mode == "healthy":
                return "forward"
            if self._mode == "fail":
                return {"503": "503", "500": "500", "reset": "reset_headers"}[self._fail_kind]
            if self.fail_when is not None and self.fail_when(method, path):
                return "503"
            u, half = self._rng.random(), self._rng.random() < 0.5
        if u < self.error_rate:
            return "500" if half else "503"
        u -= self.error_rate
        if u < self.reset_rate:
            return "reset_body" if half else "reset_headers"
        u -= self.reset_rate
        if u < self.stall_rate:
            return "stall"
        return "forward"


class _Server(ThreadingHTTPServer):
    """A threading HTTP server whose listen queue holds a client's burst of connections
    (socketserver's default of 5 drops some, which the client tries again a second later)."""
    request_queue_size = 128


def _reset(sock: socket.socket):
    """Closes `sock` with a TCP reset (SO_LINGER 0) instead of an orderly close."""
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
    except OSError:
        pass


def _handler_for(proxy: FaultProxy):
    class Handler(BaseHTTPRequestHandler):
        """Forwards one request at a time of a keep-alive connection, or fails it."""

        protocol_version = "HTTP/1.1"

        def log_message(self, *_):
            pass

        def _body(self) -> bytes:
            """The request's body (by `Content-Length`, or chunked)."""
            if self.headers.get("Transfer-Encoding", "").lower() == "chunked":
                parts = []
                while True:
                    size = int(self.rfile.readline().split(b";")[0].strip(), 16)
                    if size == 0:
                        while self.rfile.readline() not in (b"\r\n", b"\n", b""):
                            pass
                        return b"".join(parts)
                    parts.append(self.rfile.read(size))
                    self.rfile.readline()
            return self.rfile.read(int(self.headers.get("Content-Length") or 0))

        def _control(self):
            path = self.path[len(CONTROL):]
            if self.command == "GET" and path == "stats":
                self._send(200, json.dumps(proxy.stats()).encode(), "application/json")
            elif self.command == "POST" and path.startswith("mode/"):
                try:
                    mode, _, kind = path[len("mode/"):].partition("/")
                    proxy.set_mode(mode, kind or "503")
                    self._send(200, b"ok\n", "text/plain")
                except ValueError as e:
                    self._send(400, f"{e}\n".encode(), "text/plain")
            else:
                self._send(404, b"no such control path\n", "text/plain")

        def _answering(self):
            """Marks this request no longer held, before its first byte of answer (or its reset)
            goes out: a client that sends its next request as soon as this one's answer arrives
            must not find it still counted in flight."""
            if not self._answered:
                self._answered = True
                proxy._leave()

        def send_response(self, code, message=None):
            """Every answer starts here: the request stops being held first."""
            self._answering()
            super().send_response(code, message)

        def _reset_connection(self):
            """Ends the request with a TCP reset, after it stops being held."""
            self._answering()
            _reset(self.connection)
            self.close_connection = True

        def _send(self, status: int, body: bytes, content_type: str, extra=()):
            self.send_response(status)
            self.send_header("Content-Type", content_type)
            self.send_header("Content-Length", str(len(body)))
            for name, value in extra:
                self.send_header(name, value)
            self.end_headers()
            if self.command != "HEAD":
                self.wfile.write(body)

        def _forward(self, body: bytes):
            """The target's answer: (status, reason, headers, body)."""
            conn = http.client.HTTPConnection(*proxy.target, timeout=60)
            try:
                conn.putrequest(self.command, self.path, skip_host=True,
                                skip_accept_encoding=True)
                for name, value in self.headers.items():
                    if name.lower() not in ("transfer-encoding", "content-length",
                                            "connection"):
                        conn.putheader(name, value)
                if body or self.command in ("PUT", "POST"):
                    conn.putheader("Content-Length", str(len(body)))
                conn.endheaders(body)
                answer = conn.getresponse()
                data = answer.read()
                return answer.status, answer.reason, answer.getheaders(), data
            finally:
                conn.close()

        def _handle(self):
            if self.path.startswith(CONTROL):
                self._body()
                self._control()
                return
            body = self._body()
            fate = proxy._fate(self.command, self.path)
            if fate in ("500", "503"):
                status = int(fate)
                proxy._count(f"errors_{status}")
                request_id = f"fault-{proxy.seed}-{proxy.stats()['requests']}"
                extra = [("Retry-After", "1")] if status == 503 else []
                self._send(status, s3_error_body(status, self.path, request_id),
                           "application/xml", extra)
                return
            if fate == "reset_headers":
                proxy._count("resets_before_headers")
                self._reset_connection()
                return
            if fate == "stall":
                proxy._count("stalls")
                time.sleep(proxy.stall_s)
            try:
                status, reason, headers, data = self._forward(body)
            except OSError as e:
                message = f"fault proxy: target unreachable: {e}".encode()
                self._send(502, message, "text/plain")
                return
            cut = fate == "reset_body"
            if cut and (self.command == "HEAD" or len(data) < 2):
                proxy._count("resets_before_headers")
                self._reset_connection()
                return
            proxy._count("resets_mid_body" if cut else "forwarded")
            self.send_response(status, reason)
            for name, value in headers:
                if name.lower() not in ("transfer-encoding", "content-length", "connection",
                                        "date", "server"):
                    self.send_header(name, value)
            length = next((v for k, v in headers if k.lower() == "content-length"), None)
            if self.command == "HEAD" and length is not None:
                self.send_header("Content-Length", length)
            else:
                self.send_header("Content-Length", str(len(data)))
            self.end_headers()
            if self.command == "HEAD":
                return
            if cut:
                self.wfile.write(data[:len(data) // 2])
                self.wfile.flush()
                self._reset_connection()
                return
            self.wfile.write(data)

        def _serve(self):
            proxy._enter()
            self._answered = False
            try:
                self._handle()
            except (BrokenPipeError, ConnectionResetError):
                self.close_connection = True
            finally:
                self._answering()

        do_GET = do_HEAD = do_PUT = do_POST = do_DELETE = _serve

    return Handler


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--target", required=True, help="the S3 server, http://HOST:PORT")
    parser.add_argument("--port", type=int, default=0, help="port on 127.0.0.1 (0: any)")
    parser.add_argument("--error-rate", type=float, default=0.0,
                        help="share of requests answered 500 or 503")
    parser.add_argument("--reset-rate", type=float, default=0.0,
                        help="share of connections reset (before headers or mid-body)")
    parser.add_argument("--stall-rate", type=float, default=0.0,
                        help="share of requests held --stall-s seconds")
    parser.add_argument("--stall-s", type=float, default=5.0)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--mode", choices=MODES, default="faults")
    args = parser.parse_args()
    try:
        proxy = FaultProxy(args.target, args.port, error_rate=args.error_rate,
                           reset_rate=args.reset_rate, stall_rate=args.stall_rate,
                           stall_s=args.stall_s, seed=args.seed, mode=args.mode)
    except (ValueError, OSError) as e:
        parser.exit(2, f"error: {e}\n")
    print(f"fault proxy on {proxy.url} -> {args.target}", flush=True)
    proxy.start()

    def interrupted(*_):
        raise KeyboardInterrupt

    # Stopped by SIGTERM too (a benchmark's `terminate()`): the counters are printed.
    signal.signal(signal.SIGTERM, interrupted)
    try:
        while True:
            time.sleep(3600)
    except KeyboardInterrupt:
        proxy.stop()
        print(json.dumps(proxy.stats()))


if __name__ == "__main__":
    main()
