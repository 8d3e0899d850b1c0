"""Benchmark settings: the benchmarks run in one process, never split across xdist workers.

The default test run distributes tests over two worker processes (``-n 2`` in pyproject's
addopts). A benchmark measured beside another worker's tests would time the machine's load,
pytest-benchmark disables itself under xdist, and ``-s`` output would not reach the terminal; so
collecting this directory turns distribution off, as ``-n 0`` would.
"""

from __future__ import annotations

import pytest


@pytest.hookimpl(tryfirst=True)
def pytest_configure(config: pytest.Config) -> None:
    """Turn xdist's distribution off before its own (trylast) configure reads it."""
    if hasattr(config.option, "numprocesses"):
        config.option.numprocesses = 0
        config.option.dist = "no"
        config.option.tx = []
