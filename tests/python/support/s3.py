"""A real S3 server on loopback for the object-store tests: s3s-fs (installed by
scripts/test.sh), serving a folder whose subfolders are buckets and whose files are the
objects, and the environment and runner that give the binaries its credentials."""

import os
import re
import shutil
import subprocess
import time

from support.binaries import spawn_logging_to_a_file
from support.paths import BIN

KEY = "AKRESIDENCYTEST"
SECRET = "residency-test-secret-0123456789"


def start_s3(root, key=KEY, secret=SECRET) -> tuple[subprocess.Popen, str]:
    """Starts s3s-fs serving `root` (its subfolders are the buckets) with the credentials
    `key` and `secret` (the tests' by default) on a port the kernel picks; returns (process,
    endpoint URL) once it says it listens. The port is its own from the start (`--port 0`,
    read back from the log it writes to stdout), so no other process can take it between
    choosing and binding. The log goes to an unnamed file that `server.stdout` reads
    (`spawn_logging_to_a_file`)."""
    exe = shutil.which("s3s-fs") or shutil.which("s3s-fs", path=os.path.expanduser("~/.cargo/bin"))
    assert exe, "s3s-fs not installed: run scripts/test.sh (it installs it)"
    server = spawn_logging_to_a_file(
        [exe, "--host", "127.0.0.1", "--port", "0", "--access-key", key, "--secret-key", secret,
         str(root)], "stdout", stderr=subprocess.STDOUT,
        # Its start-up line, and not the request spans of `s3s_fs::s3` (logged at info,
        # formatted for every request even when nothing is printed).
        env={**os.environ, "RUST_LOG": "s3s_fs=info,s3s_fs::s3=warn"})
    deadline = time.monotonic() + 30
    seen = ""
    try:
        while True:
            seen += server.stdout.read()
            # Whole lines only: a line caught half-written could name part of the port.
            complete = seen[: seen.rfind("\n") + 1]
            listening = re.search(r"server is running at (http://127\.0\.0\.1:\d+)\s*$", complete, re.M)
            if listening:
                return server, listening.group(1)
            if server.poll() is not None:
                raise RuntimeError(f"s3s-fs exited:\n{seen}")
            if time.monotonic() > deadline:
                raise RuntimeError(f"s3s-fs ({exe}; scripts/test.sh installs 0.14.1) did not say it "
                                   f"listens within 30 s:\n{seen}")
            time.sleep(0.05)
    except BaseException:
        server.kill()
        server.wait()
        raise


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
