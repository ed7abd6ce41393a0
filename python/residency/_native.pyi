"""Type stubs of the extension module ``residency._native`` (python/src/lib.rs)."""

__version__: str

class ResidencyError(Exception):
    """A failure of a Residency call, with the message the command line prints for it."""

def inspect(store: str, *, s3_endpoint: str | None = None) -> str:
    """The report ``ingest inspect STORE`` prints: the store's version, multiscales, levels,
    arrays, codecs and region metadata. ``store`` is a folder or ``s3://BUCKET/PREFIX``;
    ``s3_endpoint`` an S3-compatible server's URL (default: ``AWS_ENDPOINT_URL``, else AWS).

    Raises :class:`ResidencyError` where the store cannot be read, with ``ingest inspect``'s
    message."""
