"""A real S3 server on loopback for the object-store tests: s3s-fs (installed by
scripts/test.sh), serving a folder whose subfolders are buckets and whose files are the
objects, and the environment and runner that give the binaries its credentials."""

import os
import re
import shutil
import subprocess
import tempfile
import time

from support.paths import BIN

KEY = "AKRESIDENCYTEST"
SECRET = "residency-test-secret-0123456789"


def start_s3(root, key=KEY, secret=SECRET) -> tuple[subprocess.Popen, str]:
    """Starts s3s-fs serving `root` (its subfolders are the buckets) with the credentials
    `key` and `secret` (the tests' by default) on a port the kernel picks; returns (process,
    endpoint URL) once it says it listens. The port is its own from the start (`--port 0`,
    read back from the log it writes to stdout), so no other process can take it between
    choosing and binding. The log goes to an unnamed file that `server.stdout` reads, as
    `start_server`'s does, so that a pipe nobody reads can never fill and block it."""
    exe = shutil.which("s3s-fs") or shutil.which("s3s-fs", path=os.path.expanduser("~/.cargo/bin"))
    assert exe, "s3s-fs not installed: run scripts/test.sh (it installs it)"
    with tempfile.NamedTemporaryFile("w", prefix="s3s-fs-log-", delete=False) as log:
        try:
            server = subprocess.Popen(
                [exe, "--host", "127.0.0.1", "--port", "0", "--access-key", key,
                 "--secret-key", secret, str(root)],
                stdout=log, stderr=subprocess.STDOUT,
                env={**os.environ, "RUST_LOG": "s3s_fs=info", "NO_COLOR": "1"})
            server.stdout = open(log.name, errors="replace")
        finally:
            os.unlink(log.name)
    deadline = time.time() + 30
    seen = ""
    while True:
        seen += server.stdout.read()
        listening = re.search(r"server is running at (http://127\.0\.0\.1:\d+)", seen)
        if listening:
            return server, listening.group(1)
        assert server.poll() is None, f"s3s-fs exited:\n{seen}"
        assert time.time() < deadline, f"s3s-fs did not say it listens within 30 s:\n{seen}"
        time.sleep(0.05)


def env(secret=SECRET, **extra) -> dict:
    """This process's environment without its AWS variables, plus the test credentials and
    `extra`."""
    e = {k: v for k, v in os.environ.items() if not k.startswith("AWS_")}
    e.update(AWS_ACCESS_KEY_ID=KEY, AWS_SECRET_ACCESS_KEY=secret, **extra)
    e.setdefault("XDG_RUNTIME_DIR", "/tmp")
    return e


def run(exe, *args, secret=SECRET, extra_env=None, timeout=300):
    """Runs the built binary `exe` with `args` and the test credentials; returns the
    CompletedProcess (stdout/stderr as text)."""
    return subprocess.run([str(BIN / exe), *map(str, args)], capture_output=True, text=True,
                          env=env(secret, **(extra_env or {})), timeout=timeout)
