"""The vehicle's ThrusterTest (an autopilot's motor test): armed, the thrusters at the given
pulses instead of the allocation's, each pushing the T200 table's force for its pulse (a CCW
propeller's mirrored); disarmed or malformed, nothing of it reaches the thrusters."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest

from testbed.ecs import Origin
from testbed.vehicle.components import ThrusterOutput, ThrusterTest
from testbed.vehicle.thrusters import T200
from testbed.vehicle.vehicle import Vehicle
from testbed.vehicle.vehicle_config import VehicleConfig


@pytest.fixture
def vehicle() -> Iterator[Vehicle]:
    v = Vehicle(VehicleConfig(), np.random.default_rng(0))
    yield v
    v.close()


def output(vehicle: Vehicle) -> ThrusterOutput:
    out = vehicle.world.get(vehicle.entity, ThrusterOutput)
    assert out is not None
    return out


def test_armed_the_thrusters_run_at_the_tests_pulses(vehicle: Vehicle) -> None:
    layout = vehicle.thruster_config
    n = layout.n_thrusters
    ccw = next(i for i, t in enumerate(layout.thrusters) if t.handedness == "ccw")
    cw = next(i for i, t in enumerate(layout.thrusters) if t.handedness == "cw")
    pwm = [1500.0] * n
    pwm[ccw], pwm[cw] = 1700.0, 1700.0
    vehicle.arm()
    vehicle.command((1.0, 0.0, 0.0, 0.0, 0.0, 0.0))  # full surge: ignored while testing
    vehicle.world.set(vehicle.operator_entity, ThrusterTest(tuple(pwm)), origin=Origin.REMOTE)
    vehicle.advance(1.0)
    out = output(vehicle)
    assert out.pwm_us == tuple(pwm)
    t200 = T200.from_table(vehicle.config.supply_voltage_v)
    forward = t200.force_for_pwm(1700.0)  # the table's, a CW propeller at 1700 µs
    assert forward > 0.0
    assert out.forces_n[cw] == pytest.approx(forward)
    assert out.forces_n[ccw] == pytest.approx(t200.force_for_pwm(1300.0))  # mirrored
    assert out.forces_n[ccw] < 0.0
    others = [f for i, f in enumerate(out.forces_n) if i not in (cw, ccw)]
    assert others == [0.0] * (n - 2)
    assert out.currents_a[cw] == pytest.approx(t200.current_for_force(forward))
    # the plant follows the command (its first-order lag long settled)
    assert vehicle.actuation.actual_forces_n[cw] == pytest.approx(forward, rel=1e-3)
    # an empty test gives the thrusters back to the allocation (the surge stick)
    vehicle.world.set(vehicle.operator_entity, ThrusterTest(), origin=Origin.REMOTE)
    vehicle.advance(2.0)
    assert output(vehicle).pwm_us != tuple(pwm) and any(output(vehicle).forces_n)


def test_disarmed_or_malformed_a_test_does_not_reach_the_thrusters(vehicle: Vehicle) -> None:
    n = vehicle.thruster_config.n_thrusters
    vehicle.world.set(vehicle.operator_entity, ThrusterTest((1700.0,) * n), origin=Origin.REMOTE)
    vehicle.advance(0.5)
    assert set(output(vehicle).pwm_us) == {1500.0}  # disarmed
    vehicle.arm()
    vehicle.world.set(
        vehicle.operator_entity, ThrusterTest((1700.0,) * (n + 1)), origin=Origin.REMOTE
    )
    vehicle.advance(1.0)
    assert set(output(vehicle).pwm_us) == {1500.0}  # the wrong length: the allocation, idle
