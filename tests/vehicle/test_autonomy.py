"""The vehicle's autonomy in its ECS frame: the mission tree's disarm fallback, supervision by
goals and cancels, the hold before any order, and the ISMC against the PD loop under a model
error and a current.

Each test builds a :class:`~testbed.vehicle.vehicle.Vehicle` on its own (no link), writes the
operator's intents on its operator entity as a link would, and steps it frame by frame.
"""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np
import pytest

from testbed.common.geometry import euler_from_quat
from testbed.config import ConfigError, build
from testbed.ecs import Origin
from testbed.vehicle.autonomy import Autonomy
from testbed.vehicle.components import (
    Armed,
    ArmRequest,
    FailsafeLevel,
    FailsafeStatus,
    GoalCancel,
    MissionStatus,
    PoseTarget,
    PositionSetpoint,
)
from testbed.vehicle.filter_values import NavigationEstimate
from testbed.vehicle.vehicle import Vehicle
from testbed.vehicle.vehicle_config import VehicleConfig

TICK_S = 0.05  # the tree's default tick (Angler: 20 Hz)
FRAME_S = 0.01


def heavy(**autonomy: Any) -> dict[str, Any]:
    """A BlueROV2 Heavy at (0, 0, 1) with motion capture and the given autonomy table; the
    link failsafe far away unless a test sets it."""
    return {
        "model": "bluerov2-heavy",
        "thrusters": "bluerov2-heavy",
        "start_position_ned_m": [0.0, 0.0, 1.0],
        "failsafe": {"hold_after_s": 86000.0, "surface_after_s": 86400.0},
        "navigation": {"motion_capture": {"rate_hz": 100.0, "noise_m": 0.001}},
        "autonomy": {"ismc": {"lambda_": 2.0}, **autonomy},
    }


def vehicle(data: dict[str, Any], seed: int = 0) -> Vehicle:
    return Vehicle(build(VehicleConfig, data, source="test"), np.random.default_rng(seed))


def step_until(v: Vehicle, condition: Any, limit_s: float) -> float:
    """Run frame by frame until ``condition(v)``; the time of the frame it first held at [s]."""
    while v.time_s < limit_s:
        v.advance(v.next_frame_s + 1e-6)  # just past the next frame: that frame runs
        if condition(v):
            return v.clock.time_s
    raise AssertionError(f"not within {limit_s} s")


def armed(v: Vehicle) -> bool:
    state = v.world.get(v.entity, Armed)
    return state is not None and state.armed


def test_the_tree_arms_and_holds_station_before_any_order() -> None:
    v = vehicle(heavy())
    t = step_until(v, armed, 1.0)
    assert t <= 2 * TICK_S  # the first tick with an estimate arms
    v.advance(5.0)
    target = v.world.get(v.entity, PoseTarget)
    assert target is not None and math.dist(target.position_ned_m, (0.0, 0.0, 1.0)) < 0.01
    assert math.dist(v.truth.position_ned_m, (0.0, 0.0, 1.0)) < 0.05


def test_an_operator_disarm_holds_until_the_operator_arms_again() -> None:
    v = vehicle(heavy())
    v.advance(3.0)
    v.world.set(v.operator_entity, ArmRequest(False, 1), origin=Origin.REMOTE)
    t0 = v.clock.time_s
    t = step_until(v, lambda v: not armed(v), t0 + 1.0)
    assert t - t0 <= FRAME_S + 1e-9  # applied at the next frame
    v.advance(t0 + 2.0)
    assert not armed(v) and v.world.get(v.entity, PoseTarget) is None  # the tree does not re-arm
    v.world.set(v.operator_entity, ArmRequest(True, 2), origin=Origin.REMOTE)
    t1 = v.clock.time_s
    assert step_until(v, armed, t1 + 1.0) - t1 <= TICK_S + FRAME_S + 1e-9


def test_the_link_failsafe_surfaces_the_vehicle_then_the_tree_keeps_it_disarmed() -> None:
    """No operator contact at all: HOLD at 0.5 s (the mission flies on), SURFACE at 1 s: the
    loops climb from the depth the vehicle is at, at the failsafe's ascent rate, and the
    failsafe disarms it at ``surfaced_depth_m`` (the Heavy is 1 N heavy in water: disarmed at
    depth it would sink); the tree's disarm fallback then latches within one tick and never
    re-arms without an operator's arm request."""
    data = heavy()
    data["failsafe"] = {"hold_after_s": 0.5, "surface_after_s": 1.0, "ascent_rate_m_s": 0.25}
    v = vehicle(data)
    step_until(v, armed, 0.5)

    def surfacing(v: Vehicle) -> bool:
        status = v.world.get(v.entity, FailsafeStatus)
        return status is not None and status.level is FailsafeLevel.SURFACE

    t_surface = step_until(v, surfacing, 2.0)
    depth_at_surface = v.truth.position_ned_m[2]
    assert depth_at_surface > 0.9  # still at the mission's depth: nothing disarmed it there
    t_disarm = step_until(v, lambda v: not armed(v), 20.0)
    assert v.truth.position_ned_m[2] <= 0.15 + 0.05  # disarmed at the surface, not at depth
    climb_s = (depth_at_surface - 0.15) / 0.25  # the target's ramp; the loop lags it a little
    assert climb_s <= t_disarm - t_surface <= climb_s + 2.0
    auto = v.world.resource(Autonomy)
    step_until(v, lambda v: v.world.resource(Autonomy).link_disarmed, t_disarm + TICK_S)
    v.advance(t_disarm + 3.0)
    assert not armed(v)  # latched: no re-arming
    assert auto.context.disarm_count == 1  # the fallback ran once, and holds


def test_a_goal_is_flown_and_reached_and_a_cancel_holds_where_the_vehicle_is() -> None:
    v = vehicle(heavy())
    v.advance(2.0)
    goal = PositionSetpoint((1.0, 0.0, 1.0), 0.0, True)
    v.world.set(v.operator_entity, goal, origin=Origin.REMOTE)
    v.advance(4.0)  # 0.2 m/s: halfway along the leg at about 4.5 s
    v.world.set(v.operator_entity, GoalCancel(1), origin=Origin.REMOTE)
    t0 = v.clock.time_s
    step_until(v, lambda v: v.world.resource(Autonomy).cancels == 1, t0 + 2 * TICK_S)
    estimate = v.world.get(v.entity, NavigationEstimate)
    assert estimate is not None
    v.advance(v.time_s + TICK_S)
    target = v.world.get(v.entity, PoseTarget)
    assert target is not None
    assert math.dist(target.position_ned_m, estimate.position_ned_m) < 0.02  # held here
    status = v.world.get(v.entity, MissionStatus)
    assert status is not None and status.cancelled and status.ready
    held = target.position_ned_m
    assert 0.1 < held[0] < 0.9
    v.advance(10.0)
    assert math.dist(v.truth.position_ned_m, held) < 0.05
    goal = PositionSetpoint((1.0, 0.5, 1.0), 0.0, True)  # a new goal after the cancel
    v.world.set(v.operator_entity, goal, origin=Origin.REMOTE)
    v.advance(25.0)
    status = v.world.get(v.entity, MissionStatus)
    assert status is not None and status.ready and not status.cancelled
    assert (status.goals, status.reached) == (2, 1)
    assert math.dist(v.truth.position_ned_m, goal.position_ned_m) < 0.05


@pytest.mark.parametrize(("rho", "expected_m"), [(0.0, None), (20.0, 0.0)])
def test_the_ismc_removes_a_buoyancy_error_the_nominal_law_leaves(
    rho: float, expected_m: float | None
) -> None:
    """The controller believes the vehicle 5 N more buoyant than it is (nothing else wrong, no
    current). At rest only g(η) is wrong: the plant sees an unmodelled d = 5 N down. With ρ = 0
    (the nominal computed-torque law) the heave velocity error settles at d/(M_zz·Kp_z), so the
    kinematic law's k·e_z must equal it: the vehicle sits e_z = d/(M_zz·Kp_z·k) deep of its
    target (M_zz = m + |Z_ẇ| of the controller's model). The ISMC's sliding term removes it."""
    data = heavy(mission="station_keeping")
    data["autonomy"]["ismc"]["rho"] = rho
    data["autonomy"]["mismatch"] = {"buoyancy_offset_n": 5.0}
    v = vehicle(data)
    v.advance(60.0)
    model = v.model
    mzz = model.mass_kg - model.added_mass[2]
    kp_z = v.world.resource(Autonomy).ismc.gains.kp[2]  # type: ignore[union-attr]
    k = v.config.autonomy.pose.k_position_1_s  # type: ignore[union-attr]
    offset = 5.0 / (mzz * kp_z * k) if expected_m is None else expected_m
    depth_error = v.truth.position_ned_m[2] - 1.0
    assert depth_error == pytest.approx(offset, abs=0.1 * 5.0 / (mzz * kp_z * k))


def test_a_mission_needs_a_known_mission_file() -> None:
    with pytest.raises(ConfigError, match="unknown mission 'no-such-mission'"):
        build(VehicleConfig, heavy(mission="no-such-mission"), source="test")


def test_surfacing_starts_from_where_the_mission_left_the_vehicle(tmp_path: Any) -> None:
    """The mission dives from 1 m to 2 m and turns to 90° through a link HOLD; SURFACE then
    climbs from the depth and heading the vehicle is at, not from the targets of the HOLD's
    start (1 m, heading 0), which the mission left behind."""
    mission = {
        "name": "dive",
        "parent": "map",
        "child": "base_link",
        "waypoints": [
            {"time_from_start": 0.0, "transform": _pose(1.0, 0.0)},
            {"time_from_start": 4.0, "transform": _pose(2.0, math.pi / 2)},
        ],
    }
    path = tmp_path / "dive.json"
    path.write_text(json.dumps(mission))
    data = heavy(mission=str(path))
    data["failsafe"] = {"hold_after_s": 0.5, "surface_after_s": 6.0, "ascent_rate_m_s": 0.1}
    v = vehicle(data)

    def surfacing(v: Vehicle) -> bool:
        status = v.world.get(v.entity, FailsafeStatus)
        return status is not None and status.level is FailsafeLevel.SURFACE

    step_until(v, surfacing, 7.0)
    depth, yaw = v.truth.position_ned_m[2], euler_from_quat(v.truth.quaternion_wxyz)[2]
    assert depth > 1.8 and yaw > 1.0  # where the mission took it (its yaw lags the plan)
    t0 = v.clock.time_s
    v.advance(t0 + 2.0)  # the ramp: 0.2 m up in 2 s, the heading held
    assert v.truth.position_ned_m[2] == pytest.approx(depth - 0.2, abs=0.1)
    assert abs(euler_from_quat(v.truth.quaternion_wxyz)[2] - yaw) < 0.1


def _pose(z: float, yaw: float) -> dict[str, float]:
    return {"x": 0.0, "y": 0.0, "z": z, "rx": 0.0, "ry": 0.0, "rz": yaw}


def test_a_remote_goal_above_the_surface_is_counted_refused_and_not_flown() -> None:
    """A GoTo to 2 m above the surface broached the hull: the tree planned and flew it. It is a
    remote value: counted refused, never raised, the vehicle holds where it was."""
    v = vehicle(heavy())
    v.advance(2.0)
    above = PositionSetpoint((1.0, 0.0, -2.0), 0.0, True)
    v.world.set(v.operator_entity, above, origin=Origin.REMOTE)
    v.advance(12.0)
    auto = v.world.resource(Autonomy)
    assert auto.refused == 1 and auto.goals == 0
    assert math.dist(v.truth.position_ned_m, (0.0, 0.0, 1.0)) < 0.05  # held, not broached
    goal = PositionSetpoint((0.5, 0.0, 1.0), 0.0, True)  # a later goal in the water is flown
    v.world.set(v.operator_entity, goal, origin=Origin.REMOTE)
    v.advance(20.0)
    assert (auto.refused, auto.goals) == (1, 1)
    assert math.dist(v.truth.position_ned_m, goal.position_ned_m) < 0.05
