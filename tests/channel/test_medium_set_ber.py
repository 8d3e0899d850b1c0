"""``Medium.set_ber``: a running medium's bit error probability changes from the next copy on."""

from __future__ import annotations

import numpy as np
import pytest
import simpy

from testbed.channel.config import LinkConfig
from testbed.channel.delivery import Delivery
from testbed.channel.medium import Medium


def test_set_ber_applies_to_transmissions_started_after_it() -> None:
    env = simpy.Environment()
    medium = Medium(env, LinkConfig(bitrate_bps=1000.0), np.random.default_rng(0))
    a, b = medium.attach("a"), medium.attach("b")
    got: list[Delivery] = []
    b.on_receive = got.append
    a.send(bytes(50))
    env.run(until=1.0)
    medium.set_ber(0.5)
    assert medium.config.ber == 0.5
    a.send(bytes(50))
    env.run(until=2.0)
    medium.set_ber(0.0)
    a.send(bytes(50))
    env.run(until=3.0)
    assert [d.bit_errors > 0 for d in got] == [False, True, False]


@pytest.mark.parametrize("ber", [-0.1, 1.5, float("nan")])
def test_set_ber_refuses_a_non_probability(ber: float) -> None:
    medium = Medium(simpy.Environment(), LinkConfig(bitrate_bps=1000.0), np.random.default_rng(0))
    with pytest.raises(ValueError, match="ber"):
        medium.set_ber(ber)
