"""Interrupts that arrive wrapped in another error.

Ctrl-C (or the CLI's SIGTERM, raised as a ``KeyboardInterrupt``) is raised wherever the program
is, also inside Python code that compiled code called back into: numba's kernels call
``numba.core.serialize._numba_unpickle`` (each time one hands a new array back: the
navigation filter's did every frame), and report an exception raised there as their own
``SystemError("... returned a result with an exception set")``, caused by it. A run that keeps
its work on an interrupt recognises it there too (:func:`interrupt_of`).

Work that must not be cut short once the simulation has ended (reducing a finished run to its
metrics) runs under :func:`deferred_interrupts`: Ctrl-C there is noted and honoured after it.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Callable, Iterator
from typing import Any

__all__ = ["deferred_interrupts", "interrupt_of"]


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


@contextlib.contextmanager
def deferred_interrupts() -> Iterator[list[KeyboardInterrupt]]:
    """Hold SIGINT and SIGTERM while the body runs, then report them instead of raising.

    In the main thread, each of the two signals whose handler is a Python callable (the
    default Ctrl-C handler, the CLI's SIGTERM handler) is noted instead of handled while the
    body runs. Afterwards the handlers are restored and the first signal noted is handed to
    its handler; the interrupt that raises is appended to the yielded list (empty when no
    signal came), for the caller to act on. Elsewhere (another thread, signals ignored) the
    body runs as it is.
    """
    noted: list[signal.Signals] = []
    interrupts: list[KeyboardInterrupt] = []
    previous: dict[signal.Signals, Callable[[int, Any], Any]] = {}

    def note(received: int, _frame: Any) -> None:
        noted.append(signal.Signals(received))

    if threading.current_thread() is threading.main_thread():
        for signum in (signal.SIGINT, signal.SIGTERM):
            handler = signal.getsignal(signum)
            if callable(handler):
                previous[signum] = handler
                signal.signal(signum, note)
    try:
        yield interrupts
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
    for signum in noted[:1]:
        try:
            previous[signum](signum, None)
        except BaseException as error:  # the handler's interrupt, reported instead of raised
            interrupt = interrupt_of(error)
            if interrupt is None:
                raise
            interrupts.append(interrupt)
