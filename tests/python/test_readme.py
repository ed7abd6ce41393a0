"""The README's promises about itself: it stays short (at most 400 lines, with the two commands
first), the first of them (`scripts/demo.sh`) and its ten-minute tour run as written, every
flag its usage blocks name is one the program accepts, and its links and the docs' lead to
files and headings that exist.

The tour's commands are read from README.md, not copied here, so editing the README edits the
test. They run in a scratch folder with the built binaries first on the PATH; the server of step
2 gets a free port in place of the README's 8000. Step 3 (`scripts/build-web.sh`) is left to
test_web_viewer.py, which builds and opens the page."""

import functools
import json
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import urllib.request

import pytest

from support.binaries import stop_server
from support.paths import BIN, ROOT
from support.readme import README, sections, sh_blocks


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_the_readme_is_short_and_opens_with_the_two_commands():
    lines = README.read_text().splitlines()
    assert len(lines) <= 400, f"README.md has {len(lines)} lines (at most 400): move detail into docs/"
    opening = [line.split()[0] for line in lines[2:6]]
    assert opening == ["```sh", "./scripts/demo.sh", "./scripts/test.sh", "```"], lines[:6]


@pytest.mark.slow
def test_the_tour_runs_as_written(tmp_path):
    tour = sections()["A ten-minute tour"]
    blocks = sh_blocks(tour)
    assert [b[0].split()[0] for b in blocks] == ["cargo", "ingest", "brickserver", "curl", "scripts/build-web.sh", "viewer"], blocks
    port = free_port()
    env = dict(os.environ, PATH=f"{BIN}{os.pathsep}{os.environ['PATH']}")

    def run(command):
        command = command.replace("127.0.0.1:8000", f"127.0.0.1:{port}")
        p = subprocess.run(["bash", "-c", command], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
        assert p.returncode == 0, f"README command failed: {command}\n{p.stderr}"
        return p.stdout

    for command in blocks[1]:
        run(command)
    assert "levels" in run("ingest inspect demo/tour/sample.ome.zarr")

    # The inline zarr-python check, with this interpreter in place of .venv/bin/python.
    inline = re.search(r"\(`(\.venv/bin/python -c .*?)`\n", tour).group(1)
    shape = run(inline.replace(".venv/bin/python", sys.executable))
    assert shape.strip() == "(3, 96, 256, 256)", shape

    [serve] = blocks[2]
    # A port free now, not minutes ago before the conversion (`run` reads it when called).
    port = free_port()
    server = subprocess.Popen(["bash", "-c", f"exec {serve} --bind 127.0.0.1:{port}"], cwd=tmp_path, env=env,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        said = [server.stdout.readline() for _ in range(2)]
        assert said[1] == f"listening on http://127.0.0.1:{port}\n", said
        assert shutil.which("curl"), "curl is needed to run the tour's step 2 as written"
        datasets, regions = (run(c) for c in blocks[3])
        assert '"sample"' in datasets, datasets
        assert regions.startswith("{") and '"min"' in regions and '"max"' in regions, regions
        for command in blocks[5]:
            out = run(command)
        assert re.search(r"PSNR", out), out
    finally:
        stop_server(server)
    for name in ("served.png", "served-stats.json", "direct.png", "reference.png"):
        assert (tmp_path / "demo/tour" / name).stat().st_size > 0, name


@pytest.mark.slow
def test_the_demo_writes_its_store_and_render_and_serves_them(tmp_path):
    """The README's first command, `scripts/demo.sh`, with `--serve` and `BIND`: it writes
    OUT/sample.ome.zarr and OUT/sample.png (the render through brickserver, converged), prints
    the link, and keeps serving the sample and its page where `BIND` says. It builds what it
    runs (a no-op after scripts/test.sh's builds), so it runs only on the workspace's own build.
    The demo runs in a process group of its own, ended whatever happens, and is killed if it
    takes over 15 minutes."""
    if BIN.resolve() != (ROOT / "target" / "release").resolve():
        pytest.skip("the demo builds and runs target/release, not $RESIDENCY_BIN")
    out = tmp_path / "demo"
    port = free_port()
    env = dict(os.environ, BIND=f"127.0.0.1:{port}")
    with tempfile.TemporaryFile("w+") as log:
        demo = subprocess.Popen(["bash", str(ROOT / "scripts" / "demo.sh"), "--serve", str(out)], cwd=ROOT,
                                env=env, stdout=subprocess.PIPE, stderr=log, text=True, start_new_session=True)
        watchdog = threading.Timer(900, os.killpg, (demo.pid, signal.SIGKILL))
        watchdog.start()

        def said_and_log(said):
            log.seek(0)
            return "".join(said) + "\n--- stderr (end) ---\n" + log.read()[-4000:]

        try:
            said = []
            for line in demo.stdout:
                said.append(line)
                # brickserver's second line, once it listens (after the demo's own lines).
                if line.startswith("listening on "):
                    break
            assert said and said[-1] == f"listening on http://127.0.0.1:{port}\n", said_and_log(said)
            text = "".join(said)
            serving = f"Serving on http://127.0.0.1:{port}: open http://127.0.0.1:{port}/sample/view"
            assert serving in text, said_and_log(said)
            assert f"The OME-Zarr store is {out}/sample.ome.zarr\n" in text, text
            assert "then open http://127.0.0.1:8000/sample/view" in text, text
            stats = json.loads((out / "sample-stats.json").read_text())
            assert stats["converged"] is True and (stats["width"], stats["height"]) == (384, 384), stats
            png = (out / "sample.png").read_bytes()
            assert png[:8] == b"\x89PNG\r\n\x1a\n" and png[16:24] == (384).to_bytes(4, "big") * 2
            assert json.loads((out / "sample.ome.zarr" / "zarr.json").read_text())["attributes"]["residency"]["levels"]
            base = f"http://127.0.0.1:{port}"
            with urllib.request.urlopen(f"{base}/datasets", timeout=30) as r:
                datasets = json.loads(r.read())
            assert [d["name"] for d in datasets["datasets"]] == ["sample"], datasets
            # The printed link: the page, from the web build the demo made.
            with urllib.request.urlopen(f"{base}/sample/view", timeout=30) as r:
                assert r.status == 200 and r.headers["content-type"].startswith("text/html"), r.headers
        finally:
            watchdog.cancel()
            for sig in (signal.SIGTERM, signal.SIGKILL):
                try:
                    os.killpg(demo.pid, sig)
                except ProcessLookupError:
                    pass
                try:
                    demo.wait(timeout=10)
                    break
                except subprocess.TimeoutExpired:
                    continue


def flags_by_command():
    """{(program, subcommand...): {flags}} from the usage blocks under "Using the programs"."""
    usage = {}
    for heading in ("`ingest`", "`brickserver`", "`viewer`"):
        for block in sh_blocks(sections()[heading]):
            for command in block:
                words = command.split()
                if words[0] not in ("ingest", "brickserver", "viewer"):
                    continue
                sub = [w for w in words[1:3] if re.fullmatch(r"[a-z]+", w)]
                if words[0] == "viewer" and sub[:1] != ["bench"]:
                    sub = sub[:1]
                key = (words[0], *sub)
                usage.setdefault(key, set()).update(re.findall(r"(?<![\w-])(--[a-z][a-z0-9-]*)", command))
    return usage


def test_every_flag_in_the_usage_blocks_is_accepted():
    usage = flags_by_command()
    assert ("ingest", "convert") in usage and ("viewer", "bench", "run") in usage, sorted(usage)
    assert len(usage) == 15, sorted(usage)
    for (program, *sub), flags in sorted(usage.items()):
        p = subprocess.run([str(BIN / program), *sub, "--help"], capture_output=True, text=True)
        assert p.returncode == 0, p.stderr
        missing = sorted(f for f in flags if not re.search(rf"(?<![\w-]){re.escape(f)}\b", p.stdout))
        assert missing == [], f"{program} {' '.join(sub)} --help does not list {missing}"


@functools.cache
def heading_anchors(md):
    """The anchors GitHub gives the headings of the Markdown file `md`: lower case, punctuation
    but `-` and `_` dropped, spaces as `-`, and `-1`, `-2`, ... after a repeated one. Read once
    per file, however many links lead to it."""
    anchors, seen = set(), {}
    text = re.sub(r"^```.*?^```", "", md.read_text(), flags=re.S | re.M)
    for m in re.finditer(r"^#{1,6} (.*)$", text, flags=re.M):
        slug = re.sub(r"[^\w\- ]", "", m.group(1).replace("`", "").strip().lower()).replace(" ", "-")
        n = seen.get(slug, 0)
        seen[slug] = n + 1
        anchors.add(slug if n == 0 else f"{slug}-{n}")
    return anchors


def test_every_relative_link_in_the_readme_and_docs_resolves():
    """Each link of README.md and docs/ to a file of the repository names one that exists, and
    a link to a heading (`FILE.md#anchor`) one that the file has."""
    broken = []
    pages = [README, *sorted((ROOT / "docs").rglob("*.md"))]
    for page in pages:
        text = re.sub(r"^```.*?^```", "", page.read_text(), flags=re.S | re.M)
        for target in re.findall(r"\]\(([^)\s]+)\)", text):
            if re.match(r"[a-z]+:", target):
                continue
            path, _, anchor = target.partition("#")
            linked = (page.parent / path).resolve() if path else page
            if not linked.exists():
                broken.append(f"{page.relative_to(ROOT)}: {target} (no such file)")
            elif anchor and linked.suffix == ".md" and anchor not in heading_anchors(linked):
                broken.append(f"{page.relative_to(ROOT)}: {target} (no such heading)")
    assert len(pages) > 10
    assert broken == [], "\n".join(broken)
    # The check itself finds the anchors of headings that links elsewhere use.
    assert {"volumetric-depth-images", "standard-zarr-access-any-viewer"} <= (
        heading_anchors(ROOT / "docs" / "viewer.md") | heading_anchors(ROOT / "docs" / "server.md"))
