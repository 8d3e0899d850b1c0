"""Telemetry a shore gateway builds from the mirrored state the narrow link carries (odometry,
armed, mode: no IMU reading, no depth reading, no thruster output), against closed forms: the
depth sensor's pressure that ArduSub turns back into the depth, body rates of a known rotation,
and currents reported as MAVLink's "unknown" rather than a plausible zero."""

from __future__ import annotations

import math

import pytest

from testbed.common.components import Odometry
from testbed.common.geometry import quat_from_axis_angle, quat_from_euler, quat_multiply
from testbed.ecs import World
from testbed.mavlink.motors import ServoOutputs
from testbed.mavlink.telemetry import BUILDERS
from testbed.mavlink.vehicle_snapshot import VehicleSnapshot, VelocityEstimator, read_vehicle


def _snapshot(world: World, entity: int, t: float, velocity: VelocityEstimator) -> VehicleSnapshot:
    return read_vehicle(
        world,
        entity,  # type: ignore[arg-type]
        time_s=t,
        velocity=velocity,
        voltage_v=14.8,
        remaining_pct=100,
        rc_channels=(1500,) * 18,
        gain=0.5,
        critical=False,
        servos=ServoOutputs(),
    )


def test_pressure_rates_and_currents_from_a_mirrored_state() -> None:
    world = World()
    entity = world.spawn()
    velocity = VelocityEstimator()
    yawed = quat_from_euler(0.0, 0.0, math.pi / 2)  # heading east
    pitch_rate = 0.2  # rad/s about the body's own y axis
    dt = 0.1
    for k in range(80):  # 8 s: the low-pass settles (time constant 0.3 s)
        t = k * dt
        q = quat_multiply(yawed, quat_from_axis_angle((0.0, 1.0, 0.0), pitch_rate * t))
        world.set(entity, Odometry(t, (1.0, 2.0, 2.96), q))
        snapshot = _snapshot(world, entity, t, velocity)
    # body rates in the body frame: a pure pitch, whatever the heading
    assert snapshot.rates_rad_s == pytest.approx((0.0, pitch_rate, 0.0), abs=1e-6)
    attitude = BUILDERS["ATTITUDE"](snapshot)
    assert attitude.pitchspeed == pytest.approx(pitch_rate, abs=1e-6)
    # ArduSub: depth = (p - p0) / (9800 Pa/m · SG): the pressure that gives 2.96 m back
    pressure = BUILDERS["SCALED_PRESSURE2"](snapshot)
    assert (pressure.press_abs * 100.0 - 101325.0) / 9800.0 == pytest.approx(2.96, abs=1e-4)
    status = BUILDERS["SYS_STATUS"](snapshot)
    assert status.current_battery == -1  # not measured: no thruster currents cross the link
    assert BUILDERS["BATTERY_STATUS"](snapshot).current_battery == -1
