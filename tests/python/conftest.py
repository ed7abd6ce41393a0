"""The fixtures shared by the external-client tests. The helpers they use, and that the tests
import, are in the `support` package (support/__init__.py lists its modules); the markers
(`slow`, `browser`, `s3`) are registered in pytest.ini."""

import pytest

from support.binaries import run_ingest
from support.browser import BrowserSession, require_browser


@pytest.fixture
def ingest():
    """`support.binaries.run_ingest`: runs the built `ingest`."""
    return run_ingest


@pytest.fixture(scope="module")
def browser_session():
    """One headless Chromium for the test module (fails or skips as require_browser does)."""
    require_browser()
    session = BrowserSession()
    yield session
    session.close()
