"""The operator's end-effector GoTo over the narrow link, flown by the vehicle-manipulator
system's own tree (uvms-station-keeping-v1, shortened, the supervisor pilot added).

Truth: the link model's closed form for the order's crossing (intrinsic delay + airtime of
the 16-B EndEffectorGoTo frame + propagation), the tree's tick for when the goal is taken up,
and the goal itself (the end effector ends within the tree's tolerance of the point the
operator sent, measured on the physics truth through the arm's forward kinematics, which
tests/vehicle/test_arm_kinematics.py checks against pybullet's).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from testbed.channel import EventKind
from testbed.protocol import encode_frame
from testbed.run.runner import RunResult, run_scenario
from testbed.run.scenario import load_scenario

GOAL_NED_M = (0.9, 0.3, 1.1)
EE_GOTO_FRAME_BYTES = len(encode_frame(bytes(10)))  # 2-B header + 8-B EndEffectorGoTo body
TICK_S = 0.05  # the mission tree's tick
FRAME_S = 0.01 + 1 / 240  # a vehicle frame, plus the physics step it may land on


@pytest.fixture(scope="module")
def reach() -> RunResult:
    overrides = [
        "duration_s=22",
        "trials=1",
        "link.ber=0",
        "metrics.settle_s=0",
        "pilot.goals=[{t_s=4.0, position_ned_m=[0.9, 0.3, 1.1], frame='end_effector'}]",
    ]
    return run_scenario(load_scenario("uvms-station-keeping-v1", overrides), seed=3)


def test_the_end_effector_goto_crosses_the_link_once_and_is_taken_up_at_the_next_tick(
    reach: RunResult,
) -> None:
    trace = reach.recorder.trace
    sent = [
        e
        for e in trace.of_kind(EventKind.ENQUEUE)
        if e.src == "operator" and e.size_bytes == EE_GOTO_FRAME_BYTES
    ]
    assert len(sent) == 1  # acknowledged by the first reply: never sent again
    frame = sent[0].frame_id
    (start,) = [e.t_s for e in trace.of_kind(EventKind.TX_START) if e.frame_id == frame]
    (delivered,) = [e.t_s for e in trace.of_kind(EventKind.DELIVER) if e.frame_id == frame]
    channel = reach.scenario.link.channel
    latency = channel.intrinsic_delay_s + channel.airtime_s(EE_GOTO_FRAME_BYTES)
    assert latency <= delivered - start <= latency + 20.0 / channel.propagation.speed_mps
    taken = [e.t_s for e in reach.recorder.events if e.kind == "mission_goal"]
    assert len(taken) == 2  # the packaged mission's start, then the operator's goal
    assert 0.0 <= taken[1] - delivered <= TICK_S + FRAME_S
    assert reach.metrics["mission"]["orders_acknowledged"] == 1


def test_the_end_effector_ends_at_the_operators_point(reach: RunResult) -> None:
    series = reach.recorder.series()
    ee = np.column_stack([series["ee_n"], series["ee_e"], series["ee_d"]])
    target = np.column_stack([series[f"ee_target_{k}"] for k in "ned"])
    assert np.allclose(target[-1], GOAL_NED_M, atol=1e-9)  # the order's 1-cm grid holds it
    tolerance = reach.scenario.vehicle.autonomy.tree.goal_tolerance_m  # type: ignore[union-attr]
    assert math.dist(ee[-1], GOAL_NED_M) < tolerance
    mission = reach.metrics["mission"]
    assert mission["frame"] == "end_effector"
    assert mission["goals_reached"] >= 1
