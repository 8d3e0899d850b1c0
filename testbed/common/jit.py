"""What compiled kernels that call plain functions of other modules need from numba.

Two things, both about calling one formula from both sides:

* :func:`math.fmod`, which numba does not compile, implemented for compiled callers with
  ``numpy.fmod`` (the C library's ``fmod`` either way, so both sides get the same bits); this
  lets :func:`~testbed.common.geometry.wrap_angle` be compiled as written.
* :func:`refresh_stale_caches`. A kernel compiled with ``cache=True`` is saved beside its own
  file together with every function it calls, and numba checks only its own file's time stamp
  before loading it: after an edit to a called function in another file (say
  :mod:`testbed.common.geometry`) it would load the old one. The kernel modules that call
  across files name those files, and their caches are emptied when one of them is newer than
  the saved index (numba then compiles afresh and saves again).

numba and numpy only.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np
from numba.extending import overload

__all__ = ["refresh_stale_caches"]


@overload(math.fmod)
def _fmod(x, y):  # type: ignore[no-untyped-def]  # pragma: no cover - numba's typing calls it
    # numba asks the implementation to have the typing function's signature, hints included
    def fmod(x, y):  # type: ignore[no-untyped-def]
        return np.fmod(x, y)

    return fmod


def refresh_stale_caches(kernels: Iterable[Any], dependencies: Iterable[ModuleType]) -> int:
    """Empty the disk cache of each kernel whose saved index is older than a dependency's file.

    Args:
        kernels: numba dispatchers defined with ``cache=True`` that call functions defined in
            ``dependencies``.
        dependencies: the modules whose functions they compile into themselves.

    Returns:
        How many caches were emptied (0 when every index is newer than every dependency, or
        when a kernel has no index yet).

    Raises:
        RuntimeError: a kernel has no disk cache (numba's internals moved: this guard would
            otherwise stop guarding without a sign).
    """
    newest = max((Path(str(module.__file__)).stat().st_mtime for module in dependencies), default=0)
    emptied = 0
    for kernel in kernels:
        cache = getattr(kernel, "_cache", None)
        index = getattr(getattr(cache, "_cache_file", None), "_index_path", None)
        if cache is None or index is None:
            raise RuntimeError(f"{kernel!r} has no numba disk cache to keep in step")
        try:
            saved = Path(index).stat().st_mtime
        except FileNotFoundError:
            continue  # nothing saved yet: the first call compiles and saves
        if saved < newest:
            try:
                cache.flush()
            except OSError:  # a read-only cache (an install's): numba cannot save there either
                continue
            emptied += 1
    return emptied
