"""The README as the tests read it: its sections by heading and the commands of its ```sh
blocks, so that a test runs what the README says rather than a copy of it."""

import re

from support.paths import ROOT

README = ROOT / "README.md"


def sections():
    """README.md as {heading: text} for its `##` and `###` headings."""
    out, heading = {}, ""
    for line in README.read_text().splitlines(keepends=True):
        m = re.match(r"#{2,3} (.*)", line)
        if m:
            heading = m.group(1).strip()
        out[heading] = out.get(heading, "") + line
    return out


def sh_blocks(text):
    """The ```sh blocks of `text`, each as a list of commands (continuation lines joined,
    comments dropped)."""
    blocks = []
    for body in re.findall(r"```sh\n(.*?)```", text, flags=re.S):
        commands = []
        for command in body.replace("\\\n", " ").splitlines():
            command = re.sub(r"\s+#.*$", "", command).strip()
            if command:
                commands.append(command)
        blocks.append(commands)
    return blocks
