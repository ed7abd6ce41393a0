"""A real S3 server on loopback for the object-store tests: s3s-fs (installed by
scripts/test.sh), serving a folder whose subfolders are buckets and whose files are the
objects, and the environment and runner that give the binaries its credentials."""

import os
import shutil
import socket
import subprocess
import time

from support.paths import BIN

KEY = "AKRESIDENCYTEST"
SECRET = "residency-test-secret-0123456789"


def free_port() -> int:
    """A TCP port free on 127.0.0.1 right now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def start_s3(root) -> tuple[subprocess.Popen, str]:
    """Starts s3s-fs serving `root` (its subfolders are the buckets) with the test
    credentials; returns (process, endpoint URL) once it listens."""
    exe = shutil.which("s3s-fs")
    assert exe, "s3s-fs not installed: run scripts/test.sh (it installs it)"
    port = free_port()
    server = subprocess.Popen(
        [exe, "--host", "127.0.0.1", "--port", str(port), "--access-key", KEY,
         "--secret-key", SECRET, str(root)],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 30
    while True:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=1).close()
            return server, f"http://127.0.0.1:{port}"
        except OSError:
            assert server.poll() is None, "s3s-fs exited"
            assert time.time() < deadline, "s3s-fs did not listen within 30 s"
            time.sleep(0.1)


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
