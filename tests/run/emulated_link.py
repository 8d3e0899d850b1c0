"""The emulated S100 link of the real-time tests: its closed form, and a probe that measures how
much longer a loaded host makes a frame take to cross it.

A frame written on an emulator port arrives after the idle gap that closes the burst
(:data:`IDLE_S`), the intrinsic delay and the airtime of the frame and its CR LF
(:data:`CRLF`; REFERENCE §1.10: every S100 packet ends in CR LF): :func:`crossing_s`.
:class:`LinkProbe` measures, at the same time as a test's run, the host's excess over that
model on the same kind of path. Used by tests/run/hil_window.py and tests/run/test_realtime.py.
"""

from __future__ import annotations

import threading
import time

import numpy as np

from testbed.channel import LinkConfig
from testbed.hil import LinkEndpoint, PortSettings, open_endpoint
from testbed.protocol import Frame, encode_frame

IDLE_S = 0.003
"""Emulator idle gap that closes a burst [s] (its default, set explicitly)."""
CRLF = 2
"""The S100 adapter's CR LF after each frame [B]."""


def crossing_s(config: LinkConfig, size: int) -> float:
    """Model latency of one frame of ``size`` B on the emulated link: the idle gap that closes
    the burst, the intrinsic delay and the airtime [s]."""
    return IDLE_S + config.intrinsic_delay_s + config.airtime_s(size)


class LinkProbe:
    """Measures, while the window runs, how much longer than the model a frame takes to cross
    an emulated link under this machine's load: a thread in this process sends a frame through
    an s100 endpoint on port A of the fourth emulator and waits for it on an endpoint on port B
    (the run's own transports, adapters and threads: writer, PTYs, emulator, reader, queue),
    records the time taken less the model (idle gap + intrinsic delay + airtime), then waits
    ``gap_s`` and records how late that wait ended. The excess is the scheduler lateness the
    run's frames meet on the same path (transport threads, GIL, PTYs, the emulator's threads),
    measured at the same time and over the same exposure (one crossing).

    A stall (the host doing nothing on that path for a while) shows in full in one or the other
    record except for the part of it before the probe's frame was written, which is at most
    one crossing (:attr:`model_s`) or one wait: :meth:`worst_s` adds that.

    The probe waits for each frame, so a stall is one sample of its excess however long it
    lasts, while the run's orders go out on a schedule and a stall of D holds up every order
    written in it (about D/IPG of them): the statistics of :attr:`excess_s` bound a typical
    crossing, and :meth:`seen_s` tells what the probe saw while a given frame was alive (its
    timeline, :attr:`sent_s`)."""

    PAYLOAD = b"probe!!"  # a 13-B WAFrame, 15 B with its CR LF: the size of an order

    def __init__(self, paths: tuple[str, str], config: LinkConfig, gap_s: float = 0.1) -> None:
        size = len(encode_frame(self.PAYLOAD)) + CRLF
        self.model_s = crossing_s(config, size)
        self.excess_s: list[float] = []
        self.sent_s: list[float] = []
        """Monotonic instant each crossing's frame was written [s] (one per :attr:`excess_s`)."""
        self.wait_late_s: list[float] = [0.0]
        self.lost = 0
        self._paths = paths
        self._gap_s = gap_s
        self._stop = threading.Event()
        self._crossed = threading.Event()
        self._thread = threading.Thread(target=self._run, name="link-probe", daemon=True)

    def _run(self) -> None:
        a = open_endpoint(PortSettings(self._paths[0], "s100", "operator"))
        b = open_endpoint(PortSettings(self._paths[1], "s100", "vehicle"))
        frame = encode_frame(self.PAYLOAD)
        try:
            while not self._stop.is_set():
                t0 = time.monotonic()
                a.send(frame)
                self._await(b, t0)
                self._pause()
        finally:
            a.close()
            b.close()

    def _await(self, b: LinkEndpoint, t0: float) -> None:
        """Wait for the probe's frame however long the host stalls it (a stall longer than any
        fixed timeout is the one the bounds most need); stopped while waiting, record the time
        waited so far, a lower bound of that crossing's excess."""
        while not self._stop.is_set():
            frames = b.wait(0.25)
            if frames:
                if frames == [Frame(self.PAYLOAD)]:
                    self.excess_s.append(time.monotonic() - t0 - self.model_s)
                    self.sent_s.append(t0)
                    self._crossed.set()
                else:
                    self.lost += 1
                return
        self.excess_s.append(time.monotonic() - t0 - self.model_s)
        self.sent_s.append(t0)

    def _pause(self) -> None:
        due = time.monotonic() + self._gap_s
        if not self._stop.wait(self._gap_s):
            self.wait_late_s.append(max(0.0, time.monotonic() - due))

    def __enter__(self) -> LinkProbe:
        """Start probing; return once a first frame has crossed (or 60 s passed), so that the
        record covers what follows."""
        self._thread.start()
        self._crossed.wait(60.0)
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()

    def quantile(self, q: float) -> float:
        """The ``q`` quantile of the excess [s] (never below 0: the model is a lower bound)."""
        return max(0.0, float(np.quantile(self.excess_s, q)))

    def worst_s(self) -> float:
        """The longest stall the probe can have met [s]: its largest excess or late wait, plus
        the part of a stall it can miss (one crossing, or one wait if longer)."""
        seen = max(self.quantile(1.0), max(self.wait_late_s))
        return seen + max(self.model_s, self._gap_s)

    def seen_s(self, first_s: float, last_s: float) -> float:
        """The largest excess the probe saw on the crossings that cover the monotonic instants
        ``first_s`` to ``last_s`` [s] (each crossing covers the time from the previous one's
        arrival to its own, so an instant between two is covered by the next: a stall that
        began there lasts into it); :meth:`worst_s` when the span is not inside the record."""
        if not self.sent_s:
            return self.worst_s()
        if first_s < self.sent_s[0] or last_s > self.sent_s[-1] + self.model_s + self.excess_s[-1]:
            return self.worst_s()
        seen = 0.0
        since = self.sent_s[0]
        for sent, excess in zip(self.sent_s, self.excess_s, strict=True):
            arrived = sent + self.model_s + excess
            if since <= last_s and arrived >= first_s:
                seen = max(seen, excess)
            since = arrived
        return seen
