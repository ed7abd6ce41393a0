"""Residency from Python.

The wheel installs the three programs on the PATH (``ingest``, ``brickserver``, ``viewer``)
and the web viewer where ``brickserver`` finds it. This package calls the Rust libraries
directly (no subprocess):

- :func:`inspect` -- the report ``ingest inspect`` prints for a store;
- :func:`regions` -- one channel's region metadata at one level as NumPy arrays: the min/max
  grid (with its halo, and exact) and the per-brick histograms with their bin edges;
- :func:`render` -- an image of a store or a served dataset as a NumPy array, the pixels
  ``viewer render`` writes.

Failures raise :class:`ResidencyError` with the message the command line prints for them.
"""

from ._native import ResidencyError, __version__, inspect, regions, render

__all__ = ["ResidencyError", "__version__", "inspect", "regions", "render"]
