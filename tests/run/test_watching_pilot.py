"""A pilot that flies by what it sees: ``see(odometry)`` before each sample hands it the
vehicle's state as the operator received it (the seam a model of a person at the console
plugs into).

Truth: the recorder's own record of when the operator took in newer vehicle state (the
pilot must see exactly those, once each, and nothing sooner), the link's closed-form token
round trip (the first thing a pilot can see, on S100 and on m64), and the pilot's own law
closing the loop through the link (the vehicle turns to the heading it asks for).
"""

from __future__ import annotations

import math

import pytest

from testbed.common.components import Odometry
from testbed.common.geometry import euler_from_quat
from testbed.operator.pilots import PilotSample, is_pure
from testbed.run.run_metrics import token_cycle
from testbed.run.runner import RunResult, run_scenario
from testbed.run.scenario import load_scenario

TARGET_DEG = 90.0


class HeadingPilot:
    """Turns the vehicle to a heading with the yaw stick, proportional to the heading error it
    sees in the operator's odometry (stick 0 until it has seen any)."""

    pure_function_of_time = True  # a false claim: watching the vehicle makes it not pure

    def __init__(self, gain: float = 0.5) -> None:
        self.gain = gain
        self.yaw_stick = 0.0
        self.seen: list[Odometry] = []
        self.sampled: list[tuple[float, int]] = []  # (t, how many states seen by then)

    def see(self, odometry: Odometry) -> None:
        self.seen.append(odometry)
        _, _, yaw = euler_from_quat(odometry.quaternion_wxyz)
        error = math.remainder(math.radians(TARGET_DEG) - yaw, math.tau)
        self.yaw_stick = max(-1.0, min(1.0, self.gain * error))

    def sample(self, t_s: float) -> PilotSample:
        self.sampled.append((t_s, len(self.seen)))
        return PilotSample((0.0, 0.0, 0.0, 0.0, 0.0, self.yaw_stick))


def _fly(name: str) -> tuple[RunResult, HeadingPilot]:
    pilot = HeadingPilot()
    result = run_scenario(load_scenario(name, ["duration_s=60", "link.ber=0"]), pilot=pilot)
    return result, pilot


@pytest.mark.parametrize("name", ["s100-teleop-v1", "m64-teleop-v1"])
def test_the_pilot_sees_what_the_operator_received_once_each_and_nothing_sooner(
    name: str,
) -> None:
    result, pilot = _fly(name)
    arrivals = [applied for applied, _ in result.recorder.odometry_updates]
    # over the teleop codec the operator's odometry carries its arrival time (no time on the
    # wire): the states seen are the arrivals the recorder saw, in order, each once
    assert [o.sampled_s for o in pilot.seen] == arrivals and len(arrivals) >= 9
    # each is seen at the first operator sample at or after its arrival
    for k, arrival in enumerate(arrivals):
        t_first = next(t for t, seen in pilot.sampled if seen > k)
        assert t_first >= arrival
        assert all(t < arrival for t, seen in pilot.sampled if seen <= k)
    # the first state a pilot can see: an order's and a reply's delivery, and the vehicle
    # modem's turn-round (the closed form), after the first order leaves at t = 0
    cycle = token_cycle(result.scenario)
    assert cycle is not None
    gap_s = result.scenario.link.channel.queue_gap_s
    assert arrivals[0] == pytest.approx(cycle.round_trip_s, abs=0.1 * gap_s)
    assert not is_pure(pilot)
    assert result.recorder.stick_source == "operator samples"


def test_the_loop_closes_through_the_link() -> None:
    result, _ = _fly("s100-teleop-v1")
    series = result.recorder.series()
    yaw = series["yaw_deg"]
    assert abs(yaw[0]) < 5.0  # it starts facing north
    late = series["t_s"] > 50.0
    assert max(abs(math.remainder(y - TARGET_DEG, 360.0)) for y in yaw[late]) < 15.0
    before = series["t_s"] < 0.3  # the first state arrives at 0.31 s: the stick is centred
    assert set(series["cmd_yaw"][before]) == {0.0}
