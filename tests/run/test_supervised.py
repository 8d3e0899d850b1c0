"""Supervised control over the narrow link: GoTo orders on the S100, flown by the vehicle's own
mission tree (s100-supervised-v1, shortened).

Truth here is the link model's closed form (intrinsic delay + airtime of the GoTo frame +
propagation) and the tree's tick: a GoTo the operator sends at BER 0 reaches the tree one
order latency after it goes on the air, and is taken up at the tree's next tick (≤ one tick
plus one vehicle frame after delivery).
"""

from __future__ import annotations

import numpy as np
import pytest

from testbed.channel import EventKind
from testbed.protocol import encode_frame
from testbed.run.runner import RunResult, run_scenario
from testbed.run.scenario import load_scenario

GOTO_FRAME_BYTES = len(encode_frame(bytes(10)))  # 2-B header + 8-B GoTo body
TICK_S = 0.05  # the mission tree's default tick (Angler: 20 Hz)
FRAME_S = 0.01 + 1 / 240  # a vehicle frame, plus the physics step it may land on


def run(*overrides: str, seed: int = 0) -> RunResult:
    return run_scenario(load_scenario("s100-supervised-v1", list(overrides)), seed=seed)


@pytest.fixture(scope="module")
def one_goto() -> RunResult:
    return run(
        "duration_s=20",
        "link.ber=0",
        "metrics.settle_s=0",
        "pilot.goals=[{t_s=3.0, position_ned_m=[1.0, 0.0, 1.0], yaw_deg=0.0}]",
    )


def test_a_goto_is_taken_up_one_order_latency_and_at_most_a_tick_after_it_is_sent(
    one_goto: RunResult,
) -> None:
    result = one_goto
    trace = result.recorder.trace
    gotos = [
        e
        for e in trace.of_kind(EventKind.ENQUEUE)
        if e.src == "operator" and e.size_bytes == GOTO_FRAME_BYTES
    ]
    assert len(gotos) == 1  # acknowledged by the first reply: never sent again
    frame = gotos[0].frame_id
    (start,) = [e.t_s for e in trace.of_kind(EventKind.TX_START) if e.frame_id == frame]
    (delivered,) = [e.t_s for e in trace.of_kind(EventKind.DELIVER) if e.frame_id == frame]
    channel = result.scenario.link.channel
    latency = channel.intrinsic_delay_s + channel.airtime_s(GOTO_FRAME_BYTES)
    propagation_bound = 20.0 / channel.propagation.speed_mps  # within 20 m of the operator
    assert latency <= delivered - start <= latency + propagation_bound
    (taken,) = [e.t_s for e in result.recorder.events if e.kind == "mission_goal"]
    assert 0.0 <= taken - delivered <= TICK_S + FRAME_S
    mission = result.metrics["mission"]
    assert mission["goals"] == 1 and mission["orders_acknowledged"] == 1
    assert mission["goals_refused"] == 0


def test_the_goal_is_reached_and_the_vehicle_reports_ready(one_goto: RunResult) -> None:
    mission = one_goto.metrics["mission"]
    assert mission["goals_reached"] == 1
    assert mission["position_error_m"]["final"] < 0.05
    reached = [e.t_s for e in one_goto.recorder.events if e.kind == "mission_reached"]
    assert reached == [pytest.approx(mission["completion_s"])]


def test_a_lossy_link_still_delivers_every_goto_by_sending_it_again() -> None:
    """At BER 3e-3 a 16-B GoTo frame is lost with p = 1 − (1 − 3e-3)^128 ≈ 32 %: the operator
    sends it again, same sequence bit, until a reply acknowledges it. The first seed whose run
    lost a GoTo copy on the air (read from the trace) must still have both goals reached."""
    for seed in range(10):
        result = run(
            "duration_s=30",
            "link.ber=3e-3",
            "metrics.settle_s=0",
            "pilot.goals=[{t_s=3.0, position_ned_m=[1.0, 0.0, 1.0]},"
            " {t_s=12.0, position_ned_m=[1.0, 1.0, 1.0]}]",
            seed=seed,
        )
        trace = result.recorder.trace
        sent = {
            e.frame_id
            for e in trace.of_kind(EventKind.ENQUEUE)
            if e.src == "operator" and e.size_bytes == GOTO_FRAME_BYTES
        }
        intact = {e.frame_id for e in trace.of_kind(EventKind.DELIVER) if e.frame_id in sent}
        if sent - intact:
            break
    else:
        raise AssertionError("no seed of ten lost a GoTo copy")
    mission = result.metrics["mission"]
    assert len(sent) > 2  # sent again
    assert mission["goals"] == 2 and mission["orders_acknowledged"] == 2
    assert mission["goals_reached"] == 2


def test_over_the_change_set_codec_goals_and_cancels_replicate() -> None:
    """The tether's change-set codec carries the same intents as replicated components
    (PositionSetpoint, GoalCancel): the first goal is cancelled on the way (not reached), the
    second is reached."""
    result = run(
        'link={preset="tether", codec="changeset", mac="free"}',
        "duration_s=25",
        "metrics.settle_s=0",
        "pilot.goals=[{t_s=3.0, position_ned_m=[2.0, 0.0, 1.0]}, {t_s=6.0, cancel=true},"
        " {t_s=9.0, position_ned_m=[0.0, 1.0, 1.0]}]",
    )
    mission = result.metrics["mission"]
    assert (mission["goals"], mission["goals_reached"]) == (2, 1)
    assert mission["position_error_m"]["final"] < 0.05
    assert mission["orders_acknowledged"] is None  # no order acknowledgements on this codec
    series = result.recorder.series()
    t, target = series["t_s"], series["target_n"]
    moving = target[(t > 4.0) & (t < 5.9)]
    held = target[(t > 6.3) & (t < 8.9)]
    assert np.all(np.diff(moving) > 0)  # the leg's target walks north at 0.2 m/s
    assert np.ptp(held) == 0.0 and 0.3 < held[0] < 1.0  # after the cancel: held where it was


def test_events_tell_each_goals_story_by_its_number_and_the_cancel() -> None:
    """s100-supervised-v1 whole: five GoTo orders, a cancel at 70 s while goal 4 flies. The
    vehicle's events name each goal by its number (reached: 1, 2, 3 and 5; goal 4 was
    reached as a count of 4, which read as goal 4 until now) and the mission tree's status
    lines say when the cancel was honoured: after the cancel order crossed the link, before
    goal 5 was given."""
    result = run("link.ber=0")
    goals = result.scenario.pilot.goals
    cancel_s = next(goal.t_s for goal in goals if goal.cancel)
    given = [goal for goal in goals if not goal.cancel]
    overtaken = max(k for k, goal in enumerate(given, start=1) if goal.t_s < cancel_s)
    events = [e for e in result.recorder.events if e.node == "vehicle"]
    numbers = [int(e.detail) for e in events if e.kind == "mission_goal"]
    reached = [int(e.detail) for e in events if e.kind == "mission_reached"]
    assert numbers == list(range(1, len(given) + 1))
    assert reached == [k for k in numbers if k != overtaken]
    story = [(e.t_s, e.detail) for e in events if e.kind == "mission"]
    (cancelled_s,) = [t_s for t_s, line in story if line.startswith("cancelled")]
    next_goal_s = [e.t_s for e in events if e.kind == "mission_goal"][overtaken]
    assert cancel_s < cancelled_s < next_goal_s
    executing = [line for _, line in story if line.startswith("executing")]
    assert len(executing) == len(given)
