"""Interrupts that arrive wrapped in another error.

Ctrl-C (or the CLI's SIGTERM, raised as a ``KeyboardInterrupt``) is raised wherever the program
is, also inside Python code that compiled code called back into: numba's kernels call
``numba.core.serialize._numba_unpickle`` (each time one hands a new array back: the
navigation filter's did every frame), and report an exception raised there as their own
``SystemError("... returned a result with an exception set")``, caused by it. A run that keeps
its work on an interrupt recognises it there too (:func:`interrupt_of`).
"""

from __future__ import annotations

__all__ = ["interrupt_of"]


def interrupt_of(error: BaseException) -> KeyboardInterrupt | None:
    """The ``KeyboardInterrupt`` that ``error`` is, or that caused it, or None.

    Follows ``__cause__`` (an error raised *from* it) and ``__context__`` (one raised while
    handling it) back to the first exception.
    """
    seen: set[int] = set()
    current: BaseException | None = error
    while current is not None and id(current) not in seen:
        if isinstance(current, KeyboardInterrupt):
            return current
        seen.add(id(current))
        current = current.__cause__ or current.__context__
    return None
