"""Benchmark settings: the benchmarks run in one process, never split across xdist workers.

The default test run distributes tests over two worker processes (``-n 2`` in pyproject's
addopts). A benchmark measured beside another worker's tests would time the machine's load,
pytest-benchmark disables itself under xdist, and ``-s`` output would not reach the terminal; so
collecting this directory turns distribution off, as ``-n 0`` would.

The process keeps 64 MiB of free heap at its top (glibc's ``M_TOP_PAD``) rather than
returning it to the system after each free. Measured 2026-12-06: in a fresh process the bare
pybullet floor (a box stepped with reads, force and torque) took 43-60 µs a 100-Hz frame until
something else in the process had shaped the heap (building a ``Physics`` did: 12-18 µs
afterwards, 10-13 µs on a quiet machine); with the pad it took 12 µs from its second round on.
Bullet's stepping allocates and frees at the heap's top, and glibc trimmed the top after each
free, so each step paid for system calls and fresh pages. The vehicle's own figures did not
move with the pad (49 µs a frame with and without, interleaved): the floor measured beside them
now sits in the same allocator state every time, whatever ran before it in the process.
"""

from __future__ import annotations

import ctypes
import ctypes.util

import pytest

_M_TOP_PAD = -2
"""glibc's ``mallopt`` parameter for the free memory kept at the heap's top (malloc.h)."""


def _pad_the_heap(pad_bytes: int = 64 << 20) -> None:
    """Keep ``pad_bytes`` at the heap's top (glibc only; elsewhere nothing happens)."""
    name = ctypes.util.find_library("c")
    if name is None:
        return
    mallopt = getattr(ctypes.CDLL(name), "mallopt", None)
    if mallopt is not None:
        mallopt(_M_TOP_PAD, pad_bytes)


@pytest.hookimpl(tryfirst=True)
def pytest_configure(config: pytest.Config) -> None:
    """Turn xdist's distribution off before its own (trylast) configure reads it; pad the
    heap (module docstring)."""
    _pad_the_heap()
    if hasattr(config.option, "numprocesses"):
        config.option.numprocesses = 0
        config.option.dist = "no"
        config.option.tx = []
