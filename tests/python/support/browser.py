"""Helpers for the tests that drive a real browser: Debian's Chromium, headless, through
playwright-core (tests/browser/browser.mjs; WebGPU and WebGL on SwiftShader).

    from support.browser import require_browser, run_page, read_png, StaticServer

    def test_page(browser_session, tmp_path):          # conftest.py's fixture: one Chromium per test module
        out = browser_session.run_page(url, [
            {"do": "waitFor", "js": "window.app?.ready"},
            {"do": "stable", "selector": "canvas", "path": str(tmp_path / "a.png")},
        ], width=512, height=512)
        assert out.console_errors() == []
        pixels = read_png(tmp_path / "a.png")

`run_page(url, steps)` does the same in a browser of its own. The steps are those listed in
tests/browser/browser.mjs (`goto`, `eval`, `waitFor`, `sleep`, `frames`, `screenshot`,
`stable`, `dataUrl`, `click`, `drag`, `wheel`, `press`, `type`, `viewport`, `pause`); `js`
fields are JavaScript expressions evaluated in the page (awaited; `arg` is the step's `arg`).

Where the browser is missing (no /usr/bin/chromium, no Node.js 20 or newer, or
tests/browser/node_modules not installed: run scripts/setup.sh), the tests fail, unless RESIDENCY_SKIP_BROWSER=1, which makes
them skip instead."""

import base64
import http.server
import json
import os
import pathlib
import shutil
import subprocess
import threading
import urllib.parse

import imagecodecs
import pytest

from support.paths import ROOT

BROWSER_DIR = ROOT / "tests" / "browser"
CHROMIUM = os.environ.get("CHROMIUM", "/usr/bin/chromium")


def _node():
    """The Node.js that scripts/setup.sh installed into tests/browser/.node where the system's is
    older than 20 (playwright-core's minimum), else `node` on the PATH."""
    local = sorted((BROWSER_DIR / ".node" / "node_modules").glob("node-linux-*/bin/node"))
    return str(local[0]) if local else (shutil.which("node") or "node")


NODE = _node()


def browser_missing():
    """Why the browser tests cannot run here, or None when they can."""
    if not os.access(CHROMIUM, os.X_OK):
        return f"{CHROMIUM} not found (Debian package chromium; scripts/setup.sh installs it)"
    if shutil.which(NODE) is None:
        return "node not found (Debian package nodejs; scripts/setup.sh installs it)"
    version = subprocess.run([NODE, "--version"], capture_output=True, text=True).stdout.strip()
    if int(version.lstrip("v").split(".")[0] or 0) < 20:
        return f"{NODE} is {version}, playwright-core needs 20 or newer (scripts/setup.sh installs one)"
    if not (BROWSER_DIR / "node_modules" / "playwright-core").is_dir():
        return f"{BROWSER_DIR}/node_modules missing (scripts/setup.sh runs npm ci there)"
    return None


def require_browser():
    """Fails the calling test if the browser is missing; skips it instead when
    RESIDENCY_SKIP_BROWSER=1."""
    reason = browser_missing()
    if reason is None:
        return
    if os.environ.get("RESIDENCY_SKIP_BROWSER") == "1":
        pytest.skip(f"{reason}; RESIDENCY_SKIP_BROWSER=1")
    pytest.fail(f"{reason}; set RESIDENCY_SKIP_BROWSER=1 to skip the browser tests", pytrace=False)


def run_node(script, args=None, *, timeout=300, cwd=None, check=True):
    """Runs `node SCRIPT JSON(args)` (SCRIPT relative to tests/browser unless absolute) and returns
    the JSON object printed on the last line of its stdout."""
    script = BROWSER_DIR / script
    cmd = [NODE, str(script)] + ([json.dumps(args)] if args is not None else [])
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, cwd=cwd)
    lines = p.stdout.strip().splitlines()
    if (check and p.returncode != 0) or not lines:
        raise AssertionError(f"{' '.join(cmd[:2])} exited with {p.returncode}:\n{p.stdout[-4000:]}\n{p.stderr[-4000:]}")
    return json.loads(lines[-1])


class PageRun:
    """The outcome of one page: `results` (one per step), `console` ("type: text" lines, page
    errors as "pageerror: message"), `page_errors`, and `error`/`step` for a failed step."""

    def __init__(self, out):
        self.results = out.get("results", [])
        self.console = out.get("console", [])
        self.page_errors = out.get("pageErrors", [])
        self.error = out.get("error")
        self.step = out.get("step")

    def console_errors(self, ignore=()):
        """Console errors and uncaught page errors, except those containing a string of `ignore`."""
        return [
            m for m in self.console
            if (m.startswith("error") or m.startswith("pageerror")) and not any(s in m for s in ignore)
        ]

    def check(self):
        """Raises if a step failed, with the console for context."""
        if self.error is not None:
            tail = "\n".join(self.console[-40:])
            raise AssertionError(f"browser step {self.step} failed: {self.error}\nconsole:\n{tail}")
        return self

    def __repr__(self):
        return f"PageRun(error={self.error!r}, step={self.step}, results={self.results!r})"


def _spec(url, steps, width, height, timeout_s, no_webgpu):
    return {"url": url, "steps": steps, "width": width, "height": height, "timeout_s": timeout_s, "noWebGPU": no_webgpu}


def run_pausing(script, spec, on_pause, timeout):
    """Runs `node SCRIPT JSON(spec)`; at each `{"paused": i}` line it prints, calls
    `on_pause(i)` and then lets the script go on (a line on its stdin). Returns (the last line
    printed or None, the exit code, stderr)."""
    p = subprocess.Popen(
        [NODE, str(script), json.dumps(spec)],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    last = None
    for line in p.stdout:
        last = line
        if line.startswith('{"paused"'):
            on_pause(json.loads(line)["paused"])
            p.stdin.write("go\n")
            p.stdin.flush()
    err = p.stderr.read()
    return last, p.wait(timeout=timeout), err


def run_page(url, steps, *, width=1024, height=768, timeout_s=120, no_webgpu=False, on_pause=None, allow_error=False):
    """Opens `url` in a headless Chromium of its own, runs `steps`, returns a PageRun (raising on
    a failed step unless allow_error). At a `pause` step it calls `on_pause(step index)` and then
    lets the page go on."""
    require_browser()
    spec = _spec(url, steps, width, height, timeout_s, no_webgpu)
    last, code, err = run_pausing(BROWSER_DIR / "run_page.mjs", spec, on_pause, timeout_s + 60)
    if last is None:
        raise AssertionError(f"run_page.mjs exited with {code} and printed nothing:\n{err[-4000:]}")
    out = PageRun(json.loads(last))
    return out if allow_error else out.check()


class BrowserSession:
    """One headless Chromium (tests/browser/session.mjs) for many pages, each in a fresh
    incognito context."""

    def __init__(self):
        self._proc = subprocess.Popen(
            [NODE, str(BROWSER_DIR / "session.mjs")],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        )
        self._next = 0
        hello = self._proc.stdout.readline()
        if not hello or not json.loads(hello).get("ready"):
            self._proc.kill()
            raise AssertionError(f"browser session did not start: {hello}\n{self._proc.stderr.read()[-4000:]}")
        self.version = json.loads(hello)["version"]

    def _send(self, obj):
        self._proc.stdin.write(json.dumps(obj) + "\n")
        self._proc.stdin.flush()

    def run_page(self, url, steps, *, width=1024, height=768, timeout_s=120, no_webgpu=False, on_pause=None, allow_error=False):
        """As the module's run_page, in this session's browser."""
        self._next += 1
        rid = self._next
        self._send({"id": rid, "spec": _spec(url, steps, width, height, timeout_s, no_webgpu)})
        for line in self._proc.stdout:
            msg = json.loads(line)
            if msg.get("id") != rid:
                continue
            if "paused" in msg:
                on_pause(msg["paused"])
                self._send({"resume": rid})
                continue
            out = PageRun(msg)
            return out if allow_error else out.check()
        raise AssertionError(f"browser session ended:\n{self._proc.stderr.read()[-4000:]}")

    def close(self):
        """Ends the session: closes its stdin and waits for the browser to exit (kills it after 30 s)."""
        if self._proc.poll() is None:
            self._proc.stdin.close()
            try:
                self._proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                self._proc.kill()
                self._proc.wait()


def read_png(path):
    """A PNG file (as the screenshot steps write) as a (height, width, channels) uint8 array."""
    return imagecodecs.png_decode(pathlib.Path(path).read_bytes())


def data_url_bytes(url):
    """The bytes of a base64 data: URL (e.g. a canvas' toDataURL())."""
    head, _, data = url.partition(",")
    assert head.startswith("data:") and head.endswith(";base64"), head[:64]
    return base64.b64decode(data)


class _Handler(http.server.SimpleHTTPRequestHandler):
    routes = {}

    def translate_path(self, path):
        path = urllib.parse.unquote(urllib.parse.urlsplit(path).path)
        for prefix, folder in sorted(self.routes.items(), key=lambda kv: -len(kv[0])):
            if path.startswith(prefix):
                rest = path[len(prefix):].lstrip("/")
                target = (folder / rest).resolve()
                if target == folder or folder in target.parents:
                    return str(target)
        return str(pathlib.Path("/nonexistent") / "404")

    def end_headers(self):
        self.send_header("Cache-Control", "no-store")
        super().end_headers()

    def log_message(self, *args):
        pass


class StaticServer:
    """Serves folders over HTTP on 127.0.0.1 (a free port) from a thread: `routes` maps URL
    prefixes ("/v/app/") to folders. Use as a context manager; `url(path)` gives the full URL."""

    def __init__(self, routes):
        handler = type("Handler", (_Handler,), {"routes": {p: pathlib.Path(f).resolve() for p, f in routes.items()}})
        handler.extensions_map = {**http.server.SimpleHTTPRequestHandler.extensions_map, ".wasm": "application/wasm", ".js": "text/javascript", ".mjs": "text/javascript"}
        self._server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
        self._server.daemon_threads = True
        self.base = f"http://127.0.0.1:{self._server.server_address[1]}"
        self._thread = threading.Thread(target=self._server.serve_forever, daemon=True)

    def url(self, path="/"):
        """The full URL of `path` on this server."""
        return self.base + path

    def __enter__(self):
        self._thread.start()
        return self

    def __exit__(self, *exc):
        self._server.shutdown()
        self._server.server_close()
