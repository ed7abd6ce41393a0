"""A reverse proxy (standard library only, one thread per connection) on loopback in front of
a render service (`viewer serve`), for the page's remote-mode tests
(tests/python/test_web_remote.py): it answers the first `POST /vdi` requests with the failures
it is given (a status and an optional `Retry-After`, with a JSON `{"error": ...}` body and the
CORS headers a page on another origin needs to read them), forwards everything else (the first
`garble` VDIs it forwards with their first four bytes replaced by `JUNK`: no VDI), holds the
`POST /vdi` requests named in `hold` until a later one arrives and then drops them (the page
has superseded them, and should have closed their connections), and records every `POST /vdi`
it receives: when, the status answered and the bytes of the body.

    from support.service_proxy import ServiceProxy
    with ServiceProxy("http://127.0.0.1:8123", failures=[(503, "2"), (429, None)]) as proxy:
        url = proxy.url        # the service's URL to give the page
        proxy.posts()          # [Post(at_s, status, body_bytes), ...]
"""

import http.client
import json
import socket
import threading
import time
import urllib.parse
from dataclasses import dataclass
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

from support.fault_proxy import BackgroundServer

HOP_BY_HOP = {"connection", "keep-alive", "transfer-encoding", "te", "trailer", "upgrade",
              "proxy-authorization", "proxy-authenticate", "content-length"}
"""Headers not passed on (the proxy sets its own `Content-Length`)."""

INJECTED_ERROR = "injected by the test proxy: HTTP {status}"
"""The `error` of an injected failure's JSON body."""


@dataclass(frozen=True)
class Post:
    """One `POST /vdi` the proxy received: seconds since the proxy started when it arrived,
    the status answered (for one held and dropped, 0 where the page closed its connection, -1
    where it kept it open), and the bytes of the answer's body."""

    at_s: float
    status: int
    body_bytes: int


class ServiceProxy(BackgroundServer):
    """The proxy, on `127.0.0.1` (a free port) in front of `target` (`http://host:port`), from
    `start()` (or `with`) until `stop()`. `failures`: `(status, retry_after)` answers of the
    first `POST /vdi` requests, in order (`retry_after` the `Retry-After` header's text, or
    None for none); an entry None forwards that request. `garble`: how many of the first VDIs
    answered 200 reach the page with `JUNK` for their magic. `hold`: the ordinals (from 1) of
    `POST /vdi` requests held, unanswered, until a later one arrives, then dropped: a request
    still in flight when the page sends the next, however fast the service (held requests
    take no entry of `failures`)."""

    def __init__(self, target: str, failures=(), garble=0, hold=()):
        parsed = urllib.parse.urlsplit(target)
        if parsed.scheme != "http" or not parsed.hostname or not parsed.port:
            raise ValueError(f"{target}: the target is http://HOST:PORT")
        self.target = (parsed.hostname, parsed.port)
        self._failures = list(failures)
        self._garble = garble
        self._hold = set(hold)
        self._arrived = 0
        self._posts = []
        self._lock = threading.Lock()
        self._later = threading.Condition(self._lock)
        self._start = time.monotonic()
        self._server = ThreadingHTTPServer(("127.0.0.1", 0), _handler_for(self))
        self._server.daemon_threads = True
        self.url = f"http://127.0.0.1:{self._server.server_address[1]}"
        self._thread = None

    def posts(self) -> list:
        """The `POST /vdi` requests received so far ([`Post`]), in order of arrival."""
        with self._lock:
            return sorted(self._posts, key=lambda p: p.at_s)

    def _arrive(self) -> bool:
        """Counts a `POST /vdi` arriving; if it is one to hold, waits (at most 60 s) until a
        later one arrives and returns True: drop it."""
        with self._later:
            self._arrived += 1
            ordinal = self._arrived
            self._later.notify_all()
            if ordinal not in self._hold:
                return False
            if not self._later.wait_for(lambda: self._arrived > ordinal, timeout=60):
                raise AssertionError(f"no POST /vdi came after the held request {ordinal}")
            return True

    def _failure(self):
        """The injected failure for the `POST /vdi` arriving now, if any."""
        with self._lock:
            return self._failures.pop(0) if self._failures else None

    def _garbled(self, answer):
        """`answer` (a VDI answered 200) as the page gets it: garbled while `garble` lasts."""
        with self._lock:
            if self._garble <= 0:
                return answer
            self._garble -= 1
        return b"JUNK" + answer[4:]

    def _record(self, at_s, status, body_bytes):
        with self._lock:
            self._posts.append(Post(at_s, status, body_bytes))


def _closed_by_peer(sock, wait_s=10.0) -> bool:
    """Whether the client closes `sock` within `wait_s` seconds, sending nothing more (a page
    that aborted its request closes the connection)."""
    sock.settimeout(wait_s)
    try:
        return sock.recv(1, socket.MSG_PEEK) == b""
    except ConnectionResetError:
        return True
    except TimeoutError:
        return False


def _handler_for(proxy: ServiceProxy):
    class Handler(BaseHTTPRequestHandler):
        protocol_version = "HTTP/1.1"

        def log_message(self, *_):
            pass

        def _answer(self, status, headers, body):
            self.send_response(status)
            for name, value in headers:
                if name.lower() not in HOP_BY_HOP:
                    self.send_header(name, value)
            self.send_header("Content-Length", str(len(body)))
            self.end_headers()
            self.wfile.write(body)

        def _handle(self):
            at_s = time.monotonic() - proxy._start
            length = int(self.headers.get("Content-Length") or 0)
            body = self.rfile.read(length) if length else b""
            vdi = self.command == "POST" and self.path == "/vdi"
            if vdi and proxy._arrive():
                proxy._record(at_s, 0 if _closed_by_peer(self.connection) else -1, 0)
                self.close_connection = True
                return
            failure = proxy._failure() if vdi else None
            if failure is not None:
                status, retry_after = failure
                answer = json.dumps({"error": INJECTED_ERROR.format(status=status)}).encode()
                headers = [("Content-Type", "application/json"),
                           ("Access-Control-Allow-Origin", "*"),
                           ("Access-Control-Expose-Headers", "retry-after")]
                if retry_after is not None:
                    headers.append(("Retry-After", retry_after))
                proxy._record(at_s, status, len(answer))
                self._answer(status, headers, answer)
                return
            conn = http.client.HTTPConnection(*proxy.target, timeout=600)
            try:
                headers = {k: v for k, v in self.headers.items() if k.lower() not in HOP_BY_HOP}
                conn.request(self.command, self.path, body=body or None, headers=headers)
                r = conn.getresponse()
                answer = r.read()
                if vdi:
                    if r.status == 200:
                        answer = proxy._garbled(answer)
                    proxy._record(at_s, r.status, len(answer))
                self._answer(r.status, r.getheaders(), answer)
            finally:
                conn.close()

        def _safely(self):
            try:
                self._handle()
            except (BrokenPipeError, ConnectionResetError):
                # The page aborted its fetch.
                self.close_connection = True

        do_GET = do_POST = do_OPTIONS = _safely

    return Handler
