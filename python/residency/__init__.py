"""Residency from Python.

The wheel installs the three programs on the PATH (``ingest``, ``brickserver``, ``viewer``)
and the web viewer where ``brickserver`` finds it. This package calls the Rust libraries
directly (no subprocess):

- :func:`convert` -- ``ingest convert``: inputs to an OME-Zarr store with region metadata,
  with a progress callback;
- :func:`inspect` -- the report ``ingest inspect`` prints for a store;
- :func:`regions` -- one channel's region metadata at one level as NumPy arrays: the min/max
  grid (with its halo, and exact) and the per-brick histograms with their bin edges;
- :func:`render` -- an image of a store or a served dataset as a NumPy array, the pixels
  ``viewer render`` writes;
- :class:`Server` -- ``brickserver serve`` in this process, as a context manager.

Failures raise :class:`ResidencyError` with the message the command line prints for them.
"""

import os
import sys

from . import _native
from ._native import ResidencyError, __version__, convert, inspect, regions, render

__all__ = ["ResidencyError", "Server", "__version__", "convert", "inspect", "regions", "render"]


def _shipped_viewer():
    """The web viewer the wheel installed (``ENV/share/residency/web``), or None."""
    web = os.path.join(sys.prefix, "share", "residency", "web")
    return web if os.path.isfile(os.path.join(web, "index.html")) else None


class Server:
    """``brickserver serve STORES`` in this process, until :meth:`close` (or the end of a
    ``with`` block)::

        with residency.Server("cells.ome.zarr") as server:
            zarr.open_group(f"{server.url}/cells/")      # also the page at {server.url}/cells/view

    ``stores`` are folders or ``s3://BUCKET/PREFIX`` (``str`` or path-like), each served as the
    dataset its last path component names; ``bind`` is ``HOST:PORT`` (port 0: a free one);
    ``viewer_dir`` the web viewer's files (default: the ones the wheel installed);
    ``s3_endpoint`` an S3-compatible server's URL. Raises :class:`ResidencyError` with
    ``brickserver serve``'s message where a store cannot be served or the address is taken.
    """

    def __init__(self, *stores, bind="127.0.0.1:0", viewer_dir=None, s3_endpoint=None):
        viewer = os.fspath(viewer_dir) if viewer_dir is not None else _shipped_viewer()
        self._native = _native.Server([os.fspath(s) for s in stores], bind, viewer, s3_endpoint)

    @property
    def url(self):
        """The base URL, ``http://HOST:PORT`` (a dataset is at ``{url}/NAME/``)."""
        return self._native.url

    def close(self):
        """Stops serving: open requests finish (for at most 10 s) and the server's threads
        end. Closing twice does nothing."""
        self._native.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False
