"""An interrupt landing anywhere: for tests of code a Ctrl-C (or the CLI's SIGTERM) may cut."""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from types import FrameType
from typing import Any

import numpy as np

from testbed.common import jit
from testbed.vehicle.filter_kernels import propagate


@contextmanager
def interrupt_at_line(k: int, function: Callable[..., Any]) -> Iterator[dict[str, int]]:
    """Raise KeyboardInterrupt at the k-th line run inside ``function`` (and what it calls)
    within the block, and swallow it there, as a run that keeps its work on an interrupt does.

    Python runs signal handlers only at calls and loops; a line is finer, so code that holds
    together under every ``k`` holds together under a real signal. Yields ``{"lines": …,
    "raised": 0 or 1}``: ``raised`` stays 0 once ``k`` is past the last line run inside it.
    """
    seen = {"lines": 0, "raised": 0}
    depth = [0]  # calls of ``function`` under way

    def inside(frame: FrameType, event: str, arg: object) -> Any:
        if event == "line":
            seen["lines"] += 1
            if seen["lines"] == k:
                seen["raised"] = 1
                raise KeyboardInterrupt
        elif event == "return" and frame.f_code is function.__code__:  # also when it raised
            depth[0] -= 1
        return inside

    def calls(frame: FrameType, event: str, arg: object) -> Any:
        if frame.f_code is function.__code__:
            depth[0] += 1
            return inside
        return inside if depth[0] else None

    previous = sys.gettrace()
    sys.settrace(calls)
    try:
        yield seen
    except KeyboardInterrupt:
        pass
    finally:
        sys.settrace(previous)


_PREDICTION = jit.entry(propagate, jit.VECTOR, *[jit.TABLE] * 4, jit.VECTOR)
_X, _P, _G = np.zeros(6), np.eye(6), np.zeros((6, 3))


def call_back() -> None:
    """Call a compiled kernel that hands new arrays back, which numba does by calling back into
    Python (``numba.core.serialize._numba_unpickle``): the filter's prediction, called as the
    frame calls its kernels (at the machine code's entry, :func:`testbed.common.jit.entry`).

    The navigation filter's kernels did that every frame; since its bookkeeping was compiled
    (they return only a status) no kernel of a run calls back, so the tests of an interrupt in
    a kernel's callback bring their own (:func:`calling_back`). An exception raised in a
    process's first callback crashes it (the CLI puts signals off there); in a later one it
    comes out as ``SystemError``, caused by it.
    """
    _PREDICTION(_X, _P, _P, _G, _P, np.zeros(0))


def calling_back(method: Callable[..., Any]) -> Callable[..., Any]:
    """``method``, first making a kernel's callback (:func:`call_back`)."""

    def method_calling_back(*args: Any, **kwargs: Any) -> Any:
        call_back()
        return method(*args, **kwargs)

    return method_calling_back
