"""A person at a console as the operator's pilot: sticks fed from another thread.

:class:`LivePilot` is a :class:`~testbed.operator.pilots.Pilot` whose sticks come from outside
the simulation — the live console's web server (:mod:`testbed.live`) runs on its own thread
and calls :meth:`LivePilot.submit` with each stick sample the browser sends. Submissions go
into a thread-safe queue; the operator node's thread drains it when it samples the pilot
(:meth:`LivePilot.sample`, once per operator frame) or when the live session's poll asks
(:meth:`LivePilot.drain`, every millisecond), so nothing but the queue is shared between
threads and simpy is only ever called from its own thread.

Dead man: sticks held longer than ``hold_s`` without a new sample (a closed tab, a frozen
browser) return to centre, counted in :attr:`LivePilot.timeouts`; the vehicle then sees
centred sticks, not the last ones forever.

Latency (instrumentation): each sample carries the instant the server received it
(:func:`time.monotonic_ns`); :meth:`drain` records, per sample taken in, how long it waited
[ns] — the console's share of the input → operator intent path.

Imports: the standard library only.
"""

from __future__ import annotations

import math
import queue
import time
from collections import deque
from collections.abc import Callable

from testbed.operator.pilots import PilotSample, Sticks

__all__ = ["HOLD_S", "LivePilot"]

HOLD_S = 1.0
"""Default dead-man time [s]: sticks without news for this long return to centre."""

_CENTRE: Sticks = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
_LATENCY_SAMPLES = 100_000
"""Input latencies kept (the newest)."""


class LivePilot:
    """Sticks held by a person, submitted from any thread.

    Args:
        hold_s: dead-man time [s of the clock], > 0.
        clock_ns: monotonic clock [ns] (injectable for tests); the server's receive stamps must
            come from the same clock.

    Attributes:
        sticks: the sticks held now (surge, sway, heave, roll, pitch, yaw in [−1, 1]).
        taken: samples taken in from the queue.
        timeouts: times the dead man centred the sticks.
        latencies_ns: per sample taken in, receive stamp → taken in [ns] (newest kept).
        last_input_ns: clock time the newest sample was received [ns] (−inf before any).
    """

    def __init__(
        self, hold_s: float = HOLD_S, clock_ns: Callable[[], int] = time.monotonic_ns
    ) -> None:
        if not hold_s > 0.0:
            raise ValueError(f"hold_s must be > 0, got {hold_s}")
        self._queue: queue.SimpleQueue[tuple[Sticks, int]] = queue.SimpleQueue()
        self._hold_ns = round(hold_s * 1e9)
        self._clock_ns = clock_ns
        self.sticks: Sticks = _CENTRE
        self.taken = 0
        self.timeouts = 0
        self.latencies_ns: deque[int] = deque(maxlen=_LATENCY_SAMPLES)
        self.last_input_ns: float = -math.inf

    def submit(self, sticks: Sticks, received_ns: int | None = None) -> None:
        """Queue a stick sample (any thread). ``sticks`` must already be checked (finite, in
        [−1, 1]; :mod:`testbed.live.messages` does); ``received_ns`` is when it arrived
        [ns, the pilot's clock], now if None."""
        self._queue.put((sticks, self._clock_ns() if received_ns is None else received_ns))

    def drain(self) -> int:
        """Take in every queued sample (the simulation's thread); returns how many. The newest
        wins; then the dead man is checked."""
        count = 0
        now = self._clock_ns()
        while True:
            try:
                sticks, received_ns = self._queue.get_nowait()
            except queue.Empty:
                break
            count += 1
            self.sticks = sticks
            self.last_input_ns = received_ns
            self.latencies_ns.append(now - received_ns)
        self.taken += count
        if self.sticks != _CENTRE and now - self.last_input_ns > self._hold_ns:
            self.sticks = _CENTRE
            self.timeouts += 1
        return count

    def sample(self, t_s: float) -> PilotSample:
        """The sticks held now (``t_s`` is not used: a person is not a function of time)."""
        del t_s
        self.drain()
        return PilotSample(self.sticks)
