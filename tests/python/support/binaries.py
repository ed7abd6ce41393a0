"""Running the built binaries: `ingest` (whole or as partitions) and `brickserver serve`."""

import os
import signal
import subprocess
import tempfile

from support.paths import BIN


def run_ingest(*args, check=True, **kwargs):
    """Runs `ingest` with `args`; returns the CompletedProcess (stdout/stderr as text)."""
    exe = BIN / "ingest"
    assert exe.exists(), f"{exe} not built: run cargo build --release"
    p = subprocess.run([str(exe), *map(str, args)], capture_output=True, text=True, **kwargs)
    if check and p.returncode != 0:
        raise AssertionError(f"ingest {' '.join(map(str, args))} failed:\n{p.stderr}")
    return p


def run_partitions(inputs, output, n, *flags, only=None):
    """Runs partitions `only` (default: all N) of a conversion as separate processes at once."""
    procs = [subprocess.Popen([str(BIN / "ingest"), "convert", *map(str, inputs), "-o", str(output),
                               *flags, "--quiet", "--partition", f"{i}/{n}"],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for i in (range(n) if only is None else only)]
    for p in procs:
        out, err = p.communicate(timeout=300)
        assert p.returncode == 0, err
        assert out.startswith("wrote partition "), out


def spawn_logging_to_a_file(args, log_stream, **popen_kwargs):
    """Starts `args` with its `log_stream` ("stdout" or "stderr"; the other one as
    `popen_kwargs` say) written to an unnamed file, which the returned process's attribute of
    that name reads from the start. A pipe nobody reads would fill and block a program that
    logs a lot (an object store's retries, a server's requests); the file never does, and the
    log stays readable after the process ends."""
    with tempfile.NamedTemporaryFile("w", prefix="residency-log-", delete=False) as log:
        try:
            proc = subprocess.Popen(args, **{log_stream: log}, **popen_kwargs)
            setattr(proc, log_stream, open(log.name, errors="replace"))
        finally:
            os.unlink(log.name)
    return proc


def start_server(*args, env=None, preexec_fn=None):
    """Starts `brickserver serve ARGS --bind 127.0.0.1:0` (in `env`, default this process's
    environment; `preexec_fn` runs in the child before it starts); returns (process, base URL)
    once it announces that it listens. Its log goes to an unnamed file that `proc.stderr`
    reads (`spawn_logging_to_a_file`)."""
    proc = spawn_logging_to_a_file(
        [str(BIN / "brickserver"), "serve", *map(str, args), "--bind", "127.0.0.1:0"], "stderr",
        stdout=subprocess.PIPE, text=True, env=env, preexec_fn=preexec_fn)
    for line in proc.stdout:
        if line.startswith("listening on "):
            return proc, line.split("listening on ")[1].strip()
    raise AssertionError(f"brickserver did not start:\n{proc.stderr.read()}")


def stop_server(proc):
    """Stops a server started by `start_server` (SIGTERM) unless it has exited already, and
    waits up to 10 s for it."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
        proc.wait(timeout=10)
