"""Type stubs of the extension module ``residency._native`` (python/src/lib.rs)."""

import os
from collections.abc import Callable, Sequence
from typing import Any, TypedDict

import numpy as np
import numpy.typing as npt

__version__: str

class ResidencyError(Exception):
    """A failure of a Residency call, with the message the command line prints for it."""

class ConvertSummary(TypedDict):
    """What :func:`convert` wrote."""

    output: str
    """The store written."""
    input_bytes: int
    """Bytes of input read."""
    planes_in_place: int
    """Level-0 planes (of all channels) read where they lie in the input files (memory-mapped),
    not copied."""
    stored_bytes: int
    """Bytes of the store."""
    seconds: float
    """Wall time of the conversion."""
    report: str
    """The text ``ingest convert`` prints."""

def convert(
    inputs: Sequence[str],
    output: str | os.PathLike[str],
    *,
    chunk: int | tuple[int, int, int] | None = None,
    shard: int | tuple[int, int, int] | None = None,
    voxel_size: tuple[float, float, float] | None = None,
    unit: str | None = None,
    ome_zarr_version: str = "0.5",
    levels: int | None = None,
    channel_names: Sequence[str] | None = None,
    overwrite: bool = False,
    memory_limit: int | None = None,
    map_inputs: bool = True,
    dims: tuple[int, int, int] | None = None,
    dtype: str | None = None,
    endian: str = "little",
    header_bytes: int = 0,
    progress: Callable[[int, int], object] | None = None,
) -> ConvertSummary:
    """``ingest convert INPUTS -o OUTPUT`` in this process: the inputs (TIFF, OME-TIFF, ImageJ
    files, folders or globs of slices, raw files; each one or more channels, in order) into the
    OME-Zarr store ``output`` (a folder) with region metadata. The options are ``ingest
    convert``'s flags (``chunk`` is ``--chunk``: an edge or ``(z, y, x)``; ``dims`` is raw
    input's ``(x, y, z)``; ``map_inputs=False`` is ``--no-mmap``). ``progress(done, total)`` is
    called as the input is read (bytes).

    Raises :class:`ResidencyError` with ``ingest convert``'s message; an exception ``progress``
    raised is raised once the conversion has finished."""

def inspect(store: str, *, s3_endpoint: str | None = None) -> str:
    """The report ``ingest inspect STORE`` prints: the store's version, multiscales, levels,
    arrays, codecs and region metadata. ``store`` is a folder or ``s3://BUCKET/PREFIX``;
    ``s3_endpoint`` an S3-compatible server's URL (default: ``AWS_ENDPOINT_URL``, else AWS).

    Raises :class:`ResidencyError` where the store cannot be read, with ``ingest inspect``'s
    message."""

class Regions(TypedDict):
    """One channel's region metadata at one level (:func:`regions`)."""

    cell_shape: tuple[int, int, int]
    """Edge of a min/max cell in voxels of the level, ``z, y, x``."""
    halo: int
    """Voxels added on every side of a cell for its ``min`` and ``max``."""
    brick_shape: tuple[int, int, int]
    """Brick shape, ``z, y, x``."""
    min: npt.NDArray[np.float64]
    """Each cell's minimum over its voxels and halo, ``[gz, gy, gx]`` (NaN: all NaN)."""
    max: npt.NDArray[np.float64]
    """Each cell's maximum over its voxels and halo, ``[gz, gy, gx]``."""
    exact_min: npt.NDArray[np.float64] | None
    """Each cell's minimum over its own voxels (``None`` in stores of layout 0.1)."""
    exact_max: npt.NDArray[np.float64] | None
    """Each cell's maximum over its own voxels (``None`` in stores of layout 0.1)."""
    histograms: npt.NDArray[np.uint32]
    """Each brick's histogram, ``[bz, by, bx, bins]``."""
    histogram_edges: npt.NDArray[np.float64]
    """The channel's bin edges (at most ``bins + 1``), shared by every brick and level."""

def regions(store: str, level: int = 0, channel: int = 0, *, s3_endpoint: str | None = None) -> Regions:
    """Channel ``channel``'s region metadata at level ``level`` (0: the finest) of ``store``,
    read whole from its ``residency`` arrays.

    Raises :class:`ResidencyError` where the store cannot be read, has no region metadata, or
    has no such level or channel."""

def render(
    volume: str,
    scene: dict[str, Any] | str | None = None,
    width: int = 256,
    height: int = 256,
    *,
    dataset: str | None = None,
    s3_endpoint: str | None = None,
) -> npt.NDArray[np.uint8]:
    """``volume`` rendered as ``viewer render`` renders it with the same scene and size: a
    ``uint8`` array ``[height, width, 3]`` of the 8-bit sRGB pixels its PNG holds.

    ``volume`` is a store (a folder or ``s3://BUCKET/PREFIX``) or a ``brickserver`` URL with
    ``dataset`` the dataset's name; ``scene`` a scene (``schemas/json/scene.schema.json``) as a
    dict or JSON text, ``None`` for the volume's default scene. Rendered on the GPU (Mesa's
    lavapipe where there is none) until no brick is outstanding, or 64 frames.

    Raises :class:`ResidencyError` with ``viewer render``'s message where the volume cannot be
    opened, the scene is not one of it, or the GPU fails."""

class Server:
    """``brickserver serve STORES`` in this process (``residency.Server`` wraps it)."""

    def __init__(
        self,
        stores: list[str],
        bind: str = "127.0.0.1:0",
        viewer_dir: str | None = None,
        s3_endpoint: str | None = None,
    ) -> None: ...
    @property
    def url(self) -> str:
        """The base URL, ``http://HOST:PORT``."""
    def close(self) -> None:
        """Stops serving: open requests finish and the server's threads end."""
