"""Real-time links give up a mis-framed candidate at the modem's packet boundary, as the
simulated link does (``LinkPort._receive`` flushes its decoder at the end of a transmission).

Over the modem emulator (s100 preset, BER 0), orders of 13 B are written through an s100
endpoint on port A at the s100 scenario's token gap (0.594 s); one of them has its length byte
corrupted to 200, a candidate of 206 B that, left to wait for its claimed length, would hold
the next 14 intact orders (about 8 s, far past the vehicle's 1-s failsafe). The endpoint on
port B must decode every following intact order within its model latency (the emulator's idle
gap, the intrinsic delay and the airtime of the frame and its CR LF, as in
tests/run/test_realtime.py) plus the scheduler lateness measured in the same test
(tests/emulator/conftest.py's :class:`Lateness`): none is held.

Without the flush at the packet boundary no following order arrives at all within the test (the
candidate still waits for bytes), so the test fails.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator

import pytest

from testbed.channel import load_link_config
from testbed.emulator.ptys import ModemEmulator
from testbed.hil import LinkEndpoint, PortSettings, open_endpoint
from testbed.protocol import CorruptFrame, Frame, encode_frame
from testbed.run.nodes import FRAME_OVERHEAD
from testbed.run.scenario import load_scenario
from tests.emulator.conftest import IDLE_S, Lateness, WakeProbe
from tests.run.emulated_link import CRLF

ORDER_PAYLOAD = 7
"""A move order's payload [B]: a 13-B frame."""
BEFORE, AFTER = 2, 5
"""Intact orders sent before and after the corrupted one."""


@pytest.fixture(name="lateness")
def _lateness() -> Iterator[Lateness]:
    """tests/emulator/conftest.py's ``lateness``: the wake probe running for the whole test."""
    probe = WakeProbe()
    probe.start()
    try:
        yield Lateness(probe)
    finally:
        probe.stop()


class Collector:
    """A thread taking every frame event from an endpoint, with the instant it got it."""

    def __init__(self, endpoint: LinkEndpoint) -> None:
        self.events: list[tuple[float, Frame | CorruptFrame]] = []
        self._endpoint = endpoint
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="collector", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            for event in self._endpoint.wait(0.05):
                self.events.append((time.monotonic(), event))

    def frames(self) -> dict[bytes, float]:
        return {e.payload: t for t, e in self.events if isinstance(e, Frame)}

    def stop(self) -> None:
        self._stop.set()
        self._thread.join()


def test_orders_behind_a_corrupted_length_byte_arrive_on_time(lateness: Lateness) -> None:
    scenario = load_scenario("s100-teleop-v1")
    gap_s = scenario.link.ipg_policy.gap_after(ORDER_PAYLOAD + FRAME_OVERHEAD)
    assert gap_s == pytest.approx(0.594, abs=0.001)
    config = load_link_config("s100", ["ber=0"])
    model_s = IDLE_S + config.intrinsic_delay_s + config.airtime_s(13 + CRLF)
    payloads = [bytes([k]) * ORDER_PAYLOAD for k in range(BEFORE + 1 + AFTER)]
    bad = BEFORE
    with ModemEmulator(config, seed=1, idle_s=IDLE_S) as emulator:
        a = open_endpoint(PortSettings(emulator.paths[0], "s100", "operator"))
        b = open_endpoint(PortSettings(emulator.paths[1], "s100", "vehicle"))
        collector = Collector(b)
        sent_s: dict[bytes, float] = {}
        try:
            for k, payload in enumerate(payloads):
                frame = bytearray(encode_frame(payload))
                if k == bad:
                    frame[3] = 200  # the length byte: a 206-B candidate
                sent_s[payload] = time.monotonic()
                a.send(bytes(frame))
                time.sleep(gap_s)
            deadline = time.monotonic() + 5.0
            while len(collector.frames()) < len(payloads) - 1 and time.monotonic() < deadline:
                time.sleep(0.05)
        finally:
            collector.stop()
            a.close()
            b.close()
        allowance_s = lateness.allowance_s(emulator, wakes=4)  # + the transports' two threads
    got = collector.frames()
    assert payloads[bad] not in got
    late = {
        k: None if p not in got else round(got[p] - sent_s[p], 3)
        for k, p in enumerate(payloads)
        if k != bad and (p not in got or got[p] - sent_s[p] > model_s + allowance_s)
    }
    assert not late, f"held or lost (order: latency s), bound {model_s + allowance_s:.3f} s"
    corrupt = [e for _, e in collector.events if isinstance(e, CorruptFrame)]
    assert len(corrupt) == 1 and b.corrupt_frames == 1  # the corrupted order, given up
    # the idle line ended packets (how many the reader tells apart depends on how the host
    # schedules it: two packets read in one go are one), the corrupted order's among them
    assert b.transport.packet_ends >= 1
