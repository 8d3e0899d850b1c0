"""The attitude pilot's setpoint schedule against its closed form (the sine sampled at the
operator's update instants and held)."""

from __future__ import annotations

import math

import pytest

from testbed.config import FieldError
from testbed.operator.pilots import AttitudePilot
from testbed.run.scenario import load_scenario


def _pilot(rate_hz: float) -> AttitudePilot:
    return AttitudePilot(5.0, 0.0, 20.0, 0.0, 30.0, 20.0, 25.0, rate_hz)


def test_setpoint_changes_at_the_update_rate_and_holds_the_sine_between() -> None:
    pilot = _pilot(40.0)
    samples = [pilot.attitude_deg(5.0 + k / 1000.0)[2] for k in range(1000)]  # 1 s at 1 kHz
    assert len(set(samples)) == 40  # one value per 1/40 s
    for k, value in enumerate(samples):
        held = math.floor(k * 40 / 1000) / 40  # the last update instant after the start
        assert value == pytest.approx(20.0 * math.sin(2.0 * math.pi * held / 25.0), abs=1e-12)


def test_infinite_rate_follows_the_sine_and_nothing_moves_before_the_start() -> None:
    pilot = _pilot(math.inf)
    assert pilot.attitude_deg(4.999) == (0.0, 0.0, 0.0)
    tau = 3.21
    expected = 20.0 * math.sin(2.0 * math.pi * tau / 25.0)
    assert pilot.attitude_deg(5.0 + tau)[2] == pytest.approx(expected, abs=1e-12)


def test_scenarios_update_rate_reaches_the_pilot() -> None:
    scenario = load_scenario("ecs-yaw-4h-v1")
    pilot = scenario.pilot.pilot()
    assert isinstance(pilot, AttitudePilot)
    assert pilot.update_rate_hz == scenario.pilot.setpoint_rate_hz == 40.0


def test_a_non_positive_rate_is_refused() -> None:
    with pytest.raises(FieldError, match="update_rate_hz"):
        _pilot(0.0)
