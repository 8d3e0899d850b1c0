"""The console's link counters against the medium's own: a half-duplex s100 link where both
ends send at random times, so copies are lost to the receiver transmitting (``deaf``) and to
bit errors; the monitor, reading the trace, must count what the receiving modem counted."""

from __future__ import annotations

import numpy as np
import pytest
import simpy

from testbed.channel.config import load_link_config
from testbed.channel.medium import Medium, Modem
from testbed.channel.trace import EventKind, Trace
from testbed.live.monitor import LinkMonitor


def _send_at(env: simpy.Environment, modem: Modem, t_s: float, data: bytes) -> None:
    env.timeout(t_s).callbacks.append(lambda _: modem.send(data))


def test_the_monitor_counts_what_the_receiving_modem_counted() -> None:
    config = load_link_config("s100", ["ber=5e-4"])
    env, trace = simpy.Environment(), Trace()
    medium = Medium(env, config, np.random.default_rng(3), trace)
    operator, vehicle = medium.attach("operator"), medium.attach("vehicle")
    rng = np.random.default_rng(4)
    for k in range(400):
        sender = operator if k % 2 else vehicle
        _send_at(env, sender, float(rng.uniform(0.0, 120.0)), bytes(int(rng.integers(8, 40))))
    monitor = LinkMonitor(trace)
    for stop in (30.0, 60.0, 200.0):  # in steps, as the console polls
        env.run(until=stop)
        monitor.update()
    assert trace.of_kind(EventKind.DEAF), "the schedule must make the ends talk over each other"
    for direction, sender, receiver in (
        ("uplink", operator, vehicle),
        ("downlink", vehicle, operator),
    ):
        counts = monitor.counts[direction]
        rx = receiver.counters
        assert counts["collided"] == rx.rx_collided > 0 and rx.rx_deaf > 0
        assert counts["corrupted"] == rx.rx_corrupted
        assert counts["sent"] == sender.counters.frames_offered
        shown = monitor.direction(direction, delivered=rx.rx_delivered)
        lost = rx.rx_collided + rx.rx_corrupted
        assert shown["per"] == pytest.approx(lost / (lost + rx.rx_delivered))
