"""Where things are: the repository, the built binaries and the JSON Schemas."""

import json
import os
import pathlib

ROOT = pathlib.Path(__file__).resolve().parents[3]
"""The repository's root."""

BIN = pathlib.Path(os.environ.get("RESIDENCY_BIN", ROOT / "target" / "release"))
"""The folder of the built binaries (`ingest`, `brickserver`, `viewer`, the web build):
$RESIDENCY_BIN, else target/release."""

SCHEMAS = ROOT / "schemas" / "json"
"""The JSON Schemas of the documents the binaries write and serve."""


def schema(name):
    """The JSON Schema schemas/json/NAME, parsed."""
    return json.loads((SCHEMAS / name).read_text())
