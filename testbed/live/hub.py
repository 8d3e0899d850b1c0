"""The one place the web server's thread and the simulation's thread meet.

* browser → simulation: :meth:`Hub.submit` (server thread) queues a parsed control message
  with its receive stamp; the session's 1-ms poll takes them (:meth:`Hub.take`). Stick samples
  bypass it into the :class:`~testbed.operator.live_pilot.LivePilot`'s own queue.
* simulation → browser: :meth:`Hub.publish` (simulation thread) replaces the latest state (a
  finished JSON-ready dict, never mutated afterwards) and wakes the server's sender through
  ``loop.call_soon_threadsafe``; the server reads :attr:`Hub.latest`.

Neither side ever waits for the other: a queue put, a reference swap and a wake-up call.
"""

from __future__ import annotations

import asyncio
import contextlib
import queue
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Any, TypeVar

from testbed.live.messages import InputCounters, Message

__all__ = ["Hub"]

_NOTES = 20
"""Console notices kept (refusals, link changes)."""


class Hub:
    """Thread-safe mailbox between the server and the session.

    Attributes:
        counters: what came in from the browsers (written by the server thread).
        latest: the newest published state, or None before the first.
        version: publications so far.
        pixel_latencies_ms: state → pixels latencies reported by the pilot's browser [ms].
        round_trips_ms: input → intent acknowledged round trips reported by the browser [ms].
        notes: recent notices for the console (newest last), e.g. a refused GoTo.
        viewers: browsers connected now.
    """

    def __init__(self) -> None:
        self._inbox: queue.SimpleQueue[tuple[Message, int]] = queue.SimpleQueue()
        self._lock = threading.Lock()
        self._waker: Callable[[], None] | None = None
        self.counters = InputCounters()
        self.latest: dict[str, Any] | None = None
        self.version = 0
        self.pixel_latencies_ms: deque[float] = deque(maxlen=100_000)
        self.round_trips_ms: deque[float] = deque(maxlen=100_000)
        self.notes: deque[str] = deque(maxlen=_NOTES)
        self.viewers = 0
        self._seats: queue.SimpleQueue[tuple[str, str]] = queue.SimpleQueue()

    def submit(self, message: Message, received_ns: int | None = None) -> None:
        """Queue a control message for the session (any thread)."""
        self._inbox.put((message, time.monotonic_ns() if received_ns is None else received_ns))

    def take(self) -> list[tuple[Message, int]]:
        """Every queued control message, oldest first (the session's thread)."""
        return _drained(self._inbox)

    def seat_event(self, kind: str, detail: str) -> None:
        """Queue a change of who is connected or holds the pilot's seat (any thread): the
        session records it in ``events.csv`` (``live,KIND,DETAIL``) at its next poll."""
        self._seats.put((kind, detail))

    def take_seat_events(self) -> list[tuple[str, str]]:
        """Every queued seat event, oldest first (the session's thread)."""
        return _drained(self._seats)

    def set_waker(self, loop: asyncio.AbstractEventLoop, event: asyncio.Event) -> None:
        """The server's loop and the event it awaits for new state."""

        def wake() -> None:
            with contextlib.suppress(RuntimeError):  # a closed loop: the server is gone
                loop.call_soon_threadsafe(event.set)

        with self._lock:
            self._waker = wake

    def publish(self, state: dict[str, Any]) -> None:
        """Make ``state`` the latest and wake the server (the session's thread)."""
        with self._lock:
            self.latest = state
            self.version += 1
            waker = self._waker
        if waker is not None:
            waker()

    def note(self, text: str) -> None:
        """A notice for the console (any thread)."""
        with self._lock:
            self.notes.append(text)


T = TypeVar("T")


def _drained(inbox: queue.SimpleQueue[T]) -> list[T]:
    """Everything ``inbox`` holds now, oldest first, without waiting."""
    out: list[T] = []
    while True:
        try:
            out.append(inbox.get_nowait())
        except queue.Empty:
            return out
