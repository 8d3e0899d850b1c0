"""What compiled kernels need from numba beyond ``numba.njit``.

Calling one formula from both sides:

* :func:`math.fmod`, which numba does not compile, implemented for compiled callers with
  ``numpy.fmod`` (the C library's ``fmod`` either way, so both sides get the same bits); this
  lets :func:`~testbed.common.geometry.wrap_angle` be compiled as written.
* :func:`refresh_stale_caches`. A kernel compiled with ``cache=True`` is saved beside its own
  file together with every function it calls, and numba checks only its own file's time stamp
  before loading it: after an edit to a called function in another file (say
  :mod:`testbed.common.geometry`) it would load the old one. The kernel modules that call
  across files name those files, and their caches are emptied when one of them is newer than
  the saved index (numba then compiles afresh and saves again).

Calling a kernel every frame:

* :func:`entry`, a kernel's machine code for one declared signature, called without numba's
  dispatcher. A dispatcher call works out the type of every argument and picks the machine
  code that matches (0.1–0.4 µs a call, most for tuples; a frame makes about fourteen such
  calls, about 4 µs of a 36-µs frame); the machine code's own entry point only converts the
  arguments. It does not check them: an array of another dtype, dimension or layout than
  declared is misread, not refused. So only a call site whose arguments have those types by
  construction (the frame's own arrays, made once) calls an entry, with the types declared
  beside the call (the aliases below). Numbers and tuples are safe: the entry converts them
  or raises (a tuple of the wrong length, a string). With ``TESTBED_CHECK_KERNELS=1`` in the
  environment every entry also checks its array arguments against its declaration and raises
  :class:`TypeError` on a mismatch (the tests run the frame that way too).

Compiling: an entry compiles its kernel, or loads it from numba's disk cache, when it is made.
A fresh checkout has no cache, and its first run compiles for tens of seconds; the first entry
made with nothing saved prints :data:`COLD_CACHE_NOTICE` on stderr, once a process, so the wait
is explained. Kernels only some vehicles need (the navigation filter's, the ISMC's) make their
entries when the first such object is built, not at import.

numba and numpy only.
"""

from __future__ import annotations

import math
import os
import sys
from collections.abc import Callable, Iterable
from pathlib import Path
from types import ModuleType
from typing import Any, TypeVar, cast

import numba
import numpy as np
from numba import types
from numba.extending import overload

__all__ = [
    "BOOL",
    "CONST_TABLE",
    "CONST_VECTOR",
    "F64",
    "I64",
    "INTS",
    "MARK",
    "MARKS",
    "TABLE",
    "VECTOR",
    "entry",
    "floats",
    "refresh_stale_caches",
    "tuple_of",
]

F64 = types.float64
I64 = types.int64
BOOL = types.boolean
VECTOR = types.Array(types.float64, 1, "C")
"""A contiguous float64 vector (a store row, a kernel's state)."""
CONST_VECTOR = types.Array(types.float64, 1, "C", readonly=True)
TABLE = types.Array(types.float64, 2, "C")
"""A contiguous float64 matrix (a store table, a configuration matrix)."""
CONST_TABLE = types.Array(types.float64, 2, "C", readonly=True)
INTS = types.Array(types.int64, 1, "C")
"""A contiguous int64 vector."""
MARK = INTS
"""A store row's (tick, write count)."""
MARKS = types.Array(types.int64, 2, "C")
COLD_CACHE_NOTICE = (
    "testbed: compiling the vehicle's kernels into numba's disk cache "
    "(once per checkout: ≈ 10-25 s; later runs load them)"
)
"""What :func:`entry` prints to stderr, once a process, before compiling a kernel that has
nothing saved yet: a fresh checkout's first run otherwise waits that long without a word."""
_told_cold = False
CHECKED = os.environ.get("TESTBED_CHECK_KERNELS", "") not in ("", "0")
"""Whether entries check their arguments (``TESTBED_CHECK_KERNELS``, read at import)."""


def tuple_of(item: types.Type, n: int) -> types.Type:
    """A tuple of ``n`` items of one type."""
    return types.UniTuple(item, n)  # type: ignore[no-untyped-call]  # numba's, untyped


def floats(n: int) -> types.Type:
    """A tuple of ``n`` floats."""
    return tuple_of(types.float64, n)


Kernel = TypeVar("Kernel", bound=Callable[..., Any])


def entry(kernel: Kernel, *signature: types.Type) -> Kernel:
    """``kernel``'s machine code for ``signature`` (compiled, or loaded from numba's disk cache,
    now), to call without the dispatcher (module docstring: the caller guarantees the types).

    Args:
        kernel: a ``numba.njit`` dispatcher.
        signature: the numba type of each argument, in order.

    Returns:
        The compiled function (typed as ``kernel``); with :data:`CHECKED`, a wrapper that
        first checks the arguments' types.
    """
    dispatcher: Any = kernel
    _tell_if_cold(dispatcher)
    dispatcher.compile(signature)
    code: Callable[..., Any] = dispatcher.get_overload(signature)
    if not CHECKED:
        return cast(Kernel, code)
    name, typeof = dispatcher.__name__, numba.typeof
    # what numba.typeof would say, checked on the array itself (typeof costs microseconds)
    arrays = [
        (i, t, np.dtype(str(t.dtype)), t.ndim, not t.mutable)
        for i, t in enumerate(signature)
        if isinstance(t, types.Array) and t.layout == "C"
    ]

    def checked(*args: Any) -> Any:
        for i, declared, dtype, ndim, readonly in arrays:  # numbers and tuples: the entry's
            a = args[i]
            if not (
                type(a) is np.ndarray
                and a.dtype == dtype
                and a.ndim == ndim
                and a.flags.c_contiguous
                and a.flags.writeable is not readonly
            ):
                given = typeof(a)  # type: ignore[no-untyped-call]  # numba's, untyped
                raise TypeError(f"{name}: argument {i} is {given}, declared {declared}")
        return code(*args)

    return cast(Kernel, checked)


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
        cache, index = _disk_cache(kernel)
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


def _disk_cache(kernel: Any) -> tuple[Any, str | None]:
    """A ``cache=True`` dispatcher's disk cache and the path of its saved index (numba's
    internals; ``(None, None)`` without a cache)."""
    cache = getattr(kernel, "_cache", None)
    return cache, getattr(getattr(cache, "_cache_file", None), "_index_path", None)


def _tell_if_cold(kernel: Any) -> None:
    """Print :data:`COLD_CACHE_NOTICE` the first time this process is about to compile a kernel
    whose disk cache has no saved index (a fresh checkout)."""
    global _told_cold
    if _told_cold:
        return
    _, index = _disk_cache(kernel)
    if index is not None and not os.path.exists(index):
        _told_cold = True
        print(COLD_CACHE_NOTICE, file=sys.stderr, flush=True)
