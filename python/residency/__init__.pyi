"""Type stubs of the package ``residency`` (python/residency/__init__.py)."""

import os

from ._native import ResidencyError as ResidencyError
from ._native import __version__ as __version__
from ._native import convert as convert
from ._native import inspect as inspect
from ._native import regions as regions
from ._native import render as render

class Server:
    """``brickserver serve STORES`` in this process, until :meth:`close` (or the end of a
    ``with`` block)."""

    def __init__(
        self,
        *stores: str | os.PathLike[str],
        bind: str = "127.0.0.1:0",
        viewer_dir: str | os.PathLike[str] | None = None,
        s3_endpoint: str | None = None,
    ) -> None: ...
    @property
    def url(self) -> str:
        """The base URL, ``http://HOST:PORT`` (a dataset is at ``{url}/NAME/``)."""
    def close(self) -> None:
        """Stops serving: open requests finish and the server's threads end."""
    def __enter__(self) -> "Server": ...
    def __exit__(self, *exc: object) -> bool: ...
