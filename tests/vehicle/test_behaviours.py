"""The mission tree against a fake first-order vehicle: disarm fallback, missions, GoTo, cancel.

The fake vehicle is exact: each tick its position moves toward the setpoint held over the tick,
``p ← s + (p − s)·exp(−dt/τ)`` (τ = 0.5 s), and its heading likewise; it arms or disarms on
the tick after it is asked. Time is the tick count times 50 ms (Angler's 20 Hz).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import astuple, dataclass

import pytest

from testbed.config import FieldError
from testbed.vehicle.behaviours import MissionRunner
from testbed.vehicle.mission import Mission, load_packaged_mission
from testbed.vehicle.mission_context import GoalRequest, MissionConfig, MissionContext, PoseSetpoint

DT = 0.05
TAU = 0.5


@dataclass
class FakeVehicle:
    """A first-order kinematic vehicle (module docstring)."""

    position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    yaw: float = 0.0
    armed: bool = False
    can_move: bool = True
    can_arm: bool = True

    def step(self, context: MissionContext) -> None:
        if context.request_arm is not None and (self.can_arm or not context.request_arm):
            self.armed = context.request_arm
        setpoint = context.pose_setpoint
        if setpoint is None or not self.armed or not self.can_move:
            return
        k = math.exp(-DT / TAU)
        s = setpoint.position_ned
        self.position = (
            s[0] + (self.position[0] - s[0]) * k,
            s[1] + (self.position[1] - s[1]) * k,
            s[2] + (self.position[2] - s[2]) * k,
        )
        self.yaw = setpoint.yaw_rad + (self.yaw - setpoint.yaw_rad) * k


class Rig:
    """A runner, its context and the fake vehicle, stepped together."""

    def __init__(self, mission: Mission | None, config: MissionConfig | None = None) -> None:
        self.runner = MissionRunner(mission, config)
        self.vehicle = FakeVehicle()
        self.context = MissionContext()
        self.k = 0

    def tick(self) -> MissionContext:
        ctx = self.context
        ctx.time_s = self.k * DT
        ctx.armed = self.vehicle.armed
        ctx.estimate_position_ned = self.vehicle.position
        ctx.estimate_yaw_rad = self.vehicle.yaw
        self.runner.tick(ctx)
        self.vehicle.step(ctx)
        self.k += 1
        return ctx

    def run_until(self, time_s: float) -> Iterator[MissionContext]:
        while self.k * DT < time_s - 1e-9:
            yield self.tick()


@pytest.fixture
def square() -> Iterator[Rig]:
    rig = Rig(load_packaged_mission("square"))
    yield rig
    rig.runner.close()


def _distance(a: tuple[float, ...], b: tuple[float, ...]) -> float:
    return math.dist(a, b)


def test_setup_arms_then_waits_for_an_order(square: Rig) -> None:
    first = square.tick()
    assert first.request_arm is True and first.pose_setpoint is None
    assert first.status == "setup: arming the vehicle"
    after = square.tick()
    assert after.request_arm is None  # armed: no further request
    assert after.pose_setpoint is None
    assert after.status == "idle: waiting for a mission start or a goal"


def test_square_visits_the_corners_in_order_and_ends_reached(square: Rig) -> None:
    square.tick()  # arming
    square.context.start_requested = True
    start_time = square.k * DT
    track = [(ctx.time_s, square.vehicle.position) for ctx in square.run_until(70.0)]
    assert square.context.start_requested is False  # consumed
    corners = [p.position_ned for p in load_packaged_mission("square").waypoints]
    times = [start_time + p.time_from_start_s for p in load_packaged_mission("square").waypoints]
    visits = []
    for corner, due in zip(corners, times, strict=True):
        # the ramp is followed 0.1 m behind (v·τ = 0.2 m/s × 0.5 s): near each corner when due
        window = [(t, p) for t, p in track if due - 1.0 <= t <= due + 1.5]
        t_best, p_best = min(window, key=lambda item: _distance(item[1], corner))
        assert _distance(p_best, corner) < 0.15, (corner, p_best)
        visits.append(t_best)
    assert visits == sorted(visits)
    ctx = square.context
    assert ctx.goal_reached and ctx.reached_count == 1 and ctx.plan_count == 1
    assert ctx.status == "holding station at the goal"
    assert ctx.pose_setpoint == PoseSetpoint((0.0, 0.0, 1.0), 0.0)
    assert _distance(square.vehicle.position, (0.0, 0.0, 1.0)) < 0.01


def test_mission_ends_only_after_settling_within_tolerance(square: Rig) -> None:
    square.tick()
    square.context.start_requested = True
    reached_at = None
    for ctx in square.run_until(60.0):
        if ctx.goal_reached and reached_at is None:
            reached_at = ctx.time_s
    assert reached_at is not None
    # the end is at 50.05 s; 1 s of settling inside 0.2 m follows it (the lag is < 0.2 m there)
    assert 51.0 <= reached_at <= 51.2


def test_disarm_fallback_disarms_within_one_tick_and_setup_runs_again(square: Rig) -> None:
    square.tick()
    square.context.start_requested = True
    for _ in square.run_until(15.0):
        pass
    assert square.context.status == "executing square"
    assert square.context.pose_setpoint is not None
    square.context.disarm_requested = True
    ctx = square.tick()
    assert ctx.request_arm is False
    assert ctx.pose_setpoint is None
    assert ctx.status == "disarmed: disarm requested"
    assert ctx.disarm_count == 1 and not square.vehicle.armed
    for ctx in square.run_until(17.0):  # held: stays disarmed, counted once
        assert ctx.request_arm is False and ctx.pose_setpoint is None
    assert ctx.disarm_count == 1
    square.context.disarm_requested = False
    ctx = square.tick()
    assert ctx.request_arm is True and ctx.status == "setup: arming the vehicle"
    ctx = square.tick()
    assert square.vehicle.armed and ctx.pose_setpoint is None  # the plan was dropped
    assert ctx.status == "idle: waiting for a mission start or a goal"
    square.context.start_requested = True
    ctx = square.tick()
    assert ctx.plan_count == 2 and ctx.status == "executing square"


def test_a_start_pending_during_a_disarm_is_dropped(square: Rig) -> None:
    square.tick()
    square.context.disarm_requested = True
    square.context.start_requested = True
    square.tick()
    square.context.disarm_requested = False
    for ctx in square.run_until(2.0):
        assert ctx.plan_count == 0


def test_a_goto_goal_mid_mission_replaces_the_plan(square: Rig) -> None:
    square.tick()
    square.context.start_requested = True
    for _ in square.run_until(15.0):
        pass
    here = square.vehicle.position
    goal = (0.0, -2.0, 1.0)
    square.context.goal = GoalRequest(goal, None)
    ctx = square.tick()
    assert square.context.goal is None  # consumed
    assert ctx.plan_count == 2 and ctx.status == "executing goto"
    assert ctx.pose_setpoint is not None
    assert ctx.pose_setpoint.position_ned == here  # re-planned from the current estimate
    track = [square.vehicle.position for _ in square.run_until(45.0)]
    assert all(p[1] < 0.5 for p in track)  # never goes on to the square's east side
    assert square.context.goal_reached and square.context.reached_count == 1
    assert _distance(square.vehicle.position, goal) < 0.05


def test_cancel_holds_the_current_pose(square: Rig) -> None:
    square.tick()
    square.context.start_requested = True
    for _ in square.run_until(15.0):
        pass
    here, yaw = square.vehicle.position, square.vehicle.yaw
    square.context.cancel_requested = True
    ctx = square.tick()
    assert square.context.cancel_requested is False
    assert ctx.pose_setpoint == PoseSetpoint(here, yaw)
    assert ctx.status == "cancelled: holding the current pose"
    for ctx in square.run_until(30.0):
        assert ctx.pose_setpoint == PoseSetpoint(here, yaw)
    assert not ctx.goal_reached and ctx.reached_count == 0
    assert _distance(square.vehicle.position, here) < 1e-3


def test_goto_without_a_mission_and_a_start_without_one() -> None:
    rig = Rig(None)
    try:
        rig.tick()  # arming
        assert rig.tick().status == "idle: waiting for a mission start or a goal"
        rig.context.start_requested = True
        assert rig.tick().status == "start ignored: no mission loaded"
        assert rig.context.plan_count == 0 and rig.context.pose_setpoint is None
        rig.context.goal = GoalRequest((1.0, 0.0, 0.5), math.pi / 2)
        for _ in rig.run_until(20.0):
            pass
        assert rig.context.goal_reached
        assert _distance(rig.vehicle.position, (1.0, 0.0, 0.5)) < 0.01
        assert math.isclose(rig.vehicle.yaw, math.pi / 2, abs_tol=0.01)
    finally:
        rig.runner.close()


def test_goal_not_reached_in_time_holds_the_last_pose() -> None:
    rig = Rig(None, MissionConfig(goal_timeout_s=1.0))
    try:
        rig.vehicle.can_move = False
        rig.tick()
        rig.context.goal = GoalRequest((0.4, 0.0, 0.0))  # 2 s at 0.2 m/s
        for _ in rig.run_until(3.0):
            pass
        assert rig.context.status == "executing goto"
        for _ in rig.run_until(3.2):
            pass
        ctx = rig.context
        assert ctx.status == "goto: goal not reached within 1 s"
        assert ctx.pose_setpoint == PoseSetpoint((0.4, 0.0, 0.0), 0.0)
        assert not ctx.goal_reached
    finally:
        rig.runner.close()


def test_arming_timeout_fails_setup_and_retries() -> None:
    rig = Rig(None, MissionConfig(setup_timeout_s=1.0))
    try:
        rig.vehicle.can_arm = False
        statuses = [ctx.status for ctx in rig.run_until(1.2)]
        # asked from t = 0; more than 1 s later (t = 1.05) setup fails, the next tick retries
        assert statuses[:21] == ["setup: arming the vehicle"] * 21
        assert statuses[21] == "setup failed: vehicle not armed within 1 s"
        assert statuses[22] == "setup: arming the vehicle"
        assert rig.context.request_arm is True and not rig.vehicle.armed
    finally:
        rig.runner.close()


def _script(rig: Rig) -> list[tuple[object, ...]]:
    out: list[tuple[object, ...]] = []
    for ctx in rig.run_until(30.0):
        if rig.k == 20:
            ctx.start_requested = True
        if rig.k == 200:
            ctx.goal = GoalRequest((1.0, 1.0, 0.5), 1.0)
        if rig.k == 300:
            ctx.disarm_requested = True
        if rig.k == 310:
            ctx.disarm_requested = False
        if rig.k == 330:
            ctx.cancel_requested = True
        out.append((astuple(ctx), rig.vehicle.position, rig.vehicle.yaw))
    return out


def test_identical_inputs_give_identical_outputs() -> None:
    mission = load_packaged_mission("lawn_mower")
    first, second = Rig(mission), Rig(mission)
    try:
        assert _script(first) == _script(second)
        assert first.context.plan_count == 2 and first.context.disarm_count == 1
    finally:
        first.runner.close()
        second.runner.close()


def test_tree_shape_and_config_checks(square: Rig) -> None:
    text = square.runner.tree_ascii()
    for name in ("Gather data", "Disarm fallback", "Setup once", "Execute trajectory", "Idle"):
        assert name in text
    assert MissionConfig().tick_period_s == pytest.approx(0.05)
    with pytest.raises(FieldError, match="tick_rate_hz"):
        MissionConfig(tick_rate_hz=0.0)
    with pytest.raises(FieldError, match="goal_tolerance_m"):
        MissionConfig(goal_tolerance_m=math.nan)
