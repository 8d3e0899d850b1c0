"""GUIDED's position law (testbed.vehicle.guidance) against hand-worked values, and the
vehicle's control_position system: nothing outside GUIDED, the fix (never the truth) steers."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from testbed.config import FieldError
from testbed.ecs.store import RowView
from testbed.run.scenario import load_scenario
from testbed.vehicle.components import (
    ArmRequest,
    ControlMode,
    FailsafeStatus,
    ForceIntent,
    ModeRequest,
    PositionReading,
    PositionSetpoint,
)
from testbed.vehicle.guidance import PositionController, PositionGains
from testbed.vehicle.sensors import PositionFix
from testbed.vehicle.vehicle import Vehicle

MAXIMA = (100.0, 80.0)


def test_far_target_demands_the_speed_limit_along_the_error_in_the_level_frame() -> None:
    loop = PositionController()
    g = loop.gains
    # 10 m north, heading east (+90°): the target is to the vehicle's left (−y)
    fx, fy = loop.update((10.0, 0.0), 0.0, (0.0, 0.0), math.pi / 2, MAXIMA)
    assert fx == pytest.approx(0.0, abs=1e-9)
    assert fy == pytest.approx(-g.kv_n_s_m * g.max_speed_m_s)  # 30 × 0.5 = 15 N, unclamped


def test_near_target_is_proportional_and_the_force_clamps_per_axis() -> None:
    loop = PositionController()
    g = loop.gains
    fx, fy = loop.update((0.2, -0.1), 0.0, (0.0, 0.0), 0.0, MAXIMA)
    assert (fx, fy) == pytest.approx((g.kv_n_s_m * g.kp_1_s * 0.2, -g.kv_n_s_m * g.kp_1_s * 0.1))
    stiff = PositionController(dataclasses.replace(g, kv_n_s_m=1000.0))
    fx, fy = stiff.update((0.0, 50.0), 0.0, (0.0, 0.0), 0.0, MAXIMA)
    assert (fx, fy) == pytest.approx((0.0, g.max_force_fraction * MAXIMA[1]))


def test_velocity_comes_from_successive_fixes_low_passed_and_damps() -> None:
    gains = PositionGains(velocity_tau_s=0.05)
    loop = PositionController(gains)
    loop.update((0.0, 0.0), 0.0, (0.0, 0.0), 0.0, MAXIMA)
    loop.update((0.0, 0.0), 0.0, (0.0, 0.0), 0.0, MAXIMA)  # the same fix again: no change
    assert loop.velocity_ne_m_s == (0.0, 0.0)
    fx, _ = loop.update((0.05, 0.0), 0.05, (0.05, 0.0), 0.0, MAXIMA)  # 1 m/s north, on target
    alpha = 0.05 / (0.05 + 0.05)
    assert loop.velocity_ne_m_s == pytest.approx((alpha * 1.0, 0.0))
    assert fx == pytest.approx(-gains.kv_n_s_m * alpha)  # moving on: braking
    loop.reset()
    assert loop.velocity_ne_m_s == (0.0, 0.0)


def test_gains_are_checked() -> None:
    with pytest.raises(FieldError):
        PositionGains(max_speed_m_s=0.0)
    with pytest.raises(FieldError):
        PositionGains(max_force_fraction=1.5)


class _BiasedFix:
    """A position fix that reads ``bias_m`` too far north (the vehicle's own sensor inside)."""

    def __init__(self, fix: PositionFix, bias_m: float) -> None:
        self._fix = fix
        self._bias_m = bias_m

    def due(self, time_s: float) -> bool:
        return self._fix.due(time_s)

    def sample(self, time_s: float, position: tuple[float, float, float]) -> PositionReading:
        x, y, z = position
        return self._fix.sample(time_s, (x + self._bias_m, y, z))

    def sample_into(
        self, time_s: float, position: tuple[float, float, float], row: RowView, tick: int
    ) -> None:
        x, y, z = position
        self._fix.sample_into(time_s, (x + self._bias_m, y, z), row, tick)


def _vehicle(fix_bias_m: float = 0.0) -> Vehicle:
    scenario = load_scenario("s100-teleop-v1", ["vehicle.sensors.position.noise_m=0"])
    vehicle = Vehicle(scenario.vehicle, np.random.default_rng(0))
    fix = vehicle.sensors.position
    assert fix is not None
    if fix_bias_m:
        vehicle.sensors.position = _BiasedFix(fix, fix_bias_m)  # type: ignore[assignment]
    return vehicle


def _position_intent(vehicle: Vehicle) -> ForceIntent:
    intent = vehicle.world.get(vehicle.controllers.intents["position"], ForceIntent)
    assert intent is not None
    return intent


def test_outside_guided_the_position_intent_stays_zero_even_with_a_setpoint() -> None:
    with _vehicle() as vehicle:
        world, intents = vehicle.world, vehicle.operator_entity
        world.set(intents, ArmRequest(True, 1))
        world.set(intents, ModeRequest(ControlMode.DEPTH_HOLD))
        world.set(intents, PositionSetpoint((5.0, 5.0, 1.0)))
        vehicle.advance(3.0)
        assert _position_intent(vehicle).wrench == (0.0,) * 6
        assert math.hypot(*vehicle.truth.position_ned_m[:2]) < 0.05


def test_guided_steers_by_the_fix_not_the_truth() -> None:
    with _vehicle(fix_bias_m=1.0) as vehicle:
        world, intents = vehicle.world, vehicle.operator_entity
        start = tuple(vehicle.truth.position_ned_m)
        world.set(intents, ArmRequest(True, 1))
        world.set(intents, ModeRequest(ControlMode.GUIDED))
        world.set(intents, PositionSetpoint((start[0], start[1], start[2])))
        vehicle.advance(15.0)
        # the fix says 1 m too far north, so the vehicle settles 1 m south of the target
        p = vehicle.truth.position_ned_m
        assert p[0] - start[0] == pytest.approx(-1.0, abs=0.05)
        assert p[1] - start[1] == pytest.approx(0.0, abs=0.05)


def test_goal_orders_keep_the_link_alive_for_the_failsafe() -> None:
    """A ground station flying GUIDED sends goals, not sticks: each new goal is operator contact,
    so goals 0.8 s apart keep the failsafe NOMINAL, while the same silence without them holds
    after ``hold_after_s`` (through the narrow link a GoTo takes a stick order's slot, and the
    vehicle went to HOLD for a third of a second at every target)."""

    def levels(goals: bool) -> set[str]:
        with _vehicle() as vehicle:
            world, intents = vehicle.world, vehicle.operator_entity
            hold_s = vehicle.config.failsafe.hold_after_s
            world.set(intents, ArmRequest(True, 1))
            world.set(intents, ModeRequest(ControlMode.GUIDED))
            seen = set()
            for k in range(1, 9):
                if goals:
                    world.set(intents, PositionSetpoint((0.1 * k, 0.0, 1.0)))
                vehicle.advance(0.8 * k)
                status = world.get(vehicle.entity, FailsafeStatus)
                seen.add("NOMINAL" if status is None else status.level.name)
            assert hold_s + 1.0 < 0.8 * 8  # long enough to hold without contact
            return seen

    assert levels(goals=True) == {"NOMINAL"}
    assert "HOLD" in levels(goals=False)
