"""Residency from Python.

The wheel installs the three programs on the PATH (``ingest``, ``brickserver``, ``viewer``)
and the web viewer where ``brickserver`` finds it. This package calls the Rust libraries
directly (no subprocess):

- :func:`inspect` -- the report ``ingest inspect`` prints for a store.

Failures raise :class:`ResidencyError` with the message the command line prints for them.
"""

from ._native import ResidencyError, __version__, inspect

__all__ = ["ResidencyError", "__version__", "inspect"]
