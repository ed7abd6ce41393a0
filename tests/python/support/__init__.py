"""Helpers shared by the external-client tests (tests/python/test_*.py); the fixtures built on
them are in tests/python/conftest.py. Test modules import from here, never from each other.

- `support.paths`: where the repository, the built binaries (RESIDENCY_BIN) and the JSON
  Schemas are.
- `support.binaries`: running `ingest` (whole or as partitions) and starting and stopping
  `brickserver serve`.
- `support.stores`: reading a store's files and metadata; a small store made by `ingest`.
- `support.reference`: the NumPy brute-force reference for pyramids, region metadata and
  histograms.
- `support.wire`: brickserver's binary framing and region boxes.
- `support.browser`: headless Chromium through playwright-core, and a static file server.
"""
