"""Fixtures of the browser tests."""

from __future__ import annotations

import pytest

from tests.live.livesession import chromium


@pytest.fixture(scope="module")
def browser_path() -> str:
    pytest.importorskip("playwright.sync_api", reason="Playwright is not installed")
    path = chromium()
    if path is None:
        pytest.skip("no Chromium executable (apt-get install chromium)")
    return path
