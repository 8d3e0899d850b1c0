"""Scheduler lateness for the emulator's real-time tests.

A frame's latency through the emulator is the channel model's closed form plus what the host
adds: how late the threads on its path ran (the emulator's reader and simulation threads, the
transports' reader and writer threads, the test's own thread waiting for the bytes). On a loaded
machine that is anything from microseconds to a few hundred milliseconds, so no fixed allowance
is both safe and meaningful. Tests measure it instead, in the same process and at the same time:

* the emulator's own instrumentation, ``ModemEmulator.scheduler_lateness_ms`` (how late its
  simulation thread's polls and its reader's burst closes ran);
* :class:`WakeProbe`, a thread passing a byte through a PTY of its own every 1 ms and recording
  how long it takes and how late its sleeps end: the lateness (CPU, GIL, the kernel's PTY
  work) that the threads which cannot be instrumented from a test (pyserial's, the
  transports') meet on each crossing of a PTY.

:meth:`Lateness.allowance_s` turns them into the bound a test adds to the model.
"""

from __future__ import annotations

import os
import select
import threading
import time
import tty
from collections.abc import Iterator

import pytest

from testbed.emulator.ptys import ModemEmulator

IDLE_S = 0.003
"""The emulator's burst idle gap (its default, which these tests use) [s]."""
EMULATOR_POLL_S = 0.001
"""The period at which the emulator's simulation thread takes bursts (its default) [s]."""
MARGIN_S = 0.005
"""Clock rounding, decoding and writing the bytes, per frame [s] (a few hundred µs measured on
an idle machine; 5 ms leaves room without hiding a real delay)."""


class WakeProbe:
    """A thread that, every ``period_s``, writes one byte into a pseudo-terminal of its own and
    waits for it on the other side, recording how long that took, and how late each of its
    sleeps ended [s]: the lateness a thread of this process meets when it is woken, and what
    the kernel adds to moving bytes through a PTY (its flip-buffer work runs on a kernel worker
    that a loaded machine also delays), both on the path of every emulated frame."""

    def __init__(self, period_s: float = 0.001) -> None:
        self._period_s = period_s
        self._stop = threading.Event()
        self.late_s: list[float] = [0.0]
        self._thread = threading.Thread(target=self._run, name="wake-probe", daemon=True)

    def _run(self) -> None:
        master, slave = os.openpty()
        tty.setraw(slave)
        try:
            while not self._stop.is_set():
                t0 = time.monotonic()
                os.write(slave, b"x")
                select.select([master], [], [], 1.0)
                os.read(master, 64)
                self.late_s.append(time.monotonic() - t0)
                due = time.monotonic() + self._period_s
                time.sleep(self._period_s)
                self.late_s.append(max(0.0, time.monotonic() - due))
        finally:
            os.close(master)
            os.close(slave)

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self._thread.join()


class Lateness:
    """The measured scheduler lateness of this test so far."""

    def __init__(self, probe: WakeProbe) -> None:
        self.probe = probe

    def allowance_s(self, emulator: ModemEmulator, *, packets: int = 1, wakes: int = 2) -> float:
        """What the host may add to one frame's model latency [s]. Per packet the frame is sent
        as (each its own burst on the port, with its own exchange with the emulator): the idle
        gap that closes the burst, one poll period of the emulator's simulation thread and its
        largest lateness, the reader's largest lateness closing a burst, and for each of
        ``wakes`` other threads woken on the way (the emulator's reader when the bytes arrive,
        the receiving thread; transports add their writer and reader) the largest lateness the
        probe saw; plus :data:`MARGIN_S` once. Maxima, so the bound holds for every frame
        measured before it is computed."""
        late = emulator.scheduler_lateness_ms
        simulation_s = ms_as_s(late["simulation"]["max"])
        reader_s = ms_as_s(late["reader"]["max"])
        per_packet_s = IDLE_S + EMULATOR_POLL_S + simulation_s + reader_s
        return packets * (per_packet_s + wakes * max(self.probe.late_s)) + MARGIN_S


def ms_as_s(value: float) -> float:
    """A lateness statistic [ms] as seconds, 0 when there is none yet (NaN)."""
    return value / 1e3 if value == value else 0.0


@pytest.fixture
def lateness() -> Iterator[Lateness]:
    """The wake probe running for the whole test."""
    probe = WakeProbe()
    probe.start()
    try:
        yield Lateness(probe)
    finally:
        probe.stop()
