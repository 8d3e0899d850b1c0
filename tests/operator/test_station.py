"""Operator station: pilot sampling per frame, the session plan, attitude setpoints, state age."""

from __future__ import annotations

import math
from collections.abc import Callable

import pytest
from scipy.spatial.transform import Rotation

from testbed.common.components import (
    ArmRequest,
    AttitudeSetpoint,
    ControlMode,
    DepthSetpoint,
    ModeRequest,
    MovementCommand,
    Odometry,
)
from testbed.common.geometry import Quaternion
from testbed.common.teleop import TeleopOperatorEnd, TeleopVehicleEnd
from testbed.ecs import Phase, Replicate, World
from testbed.operator.pilots import PilotSample, ScriptedPilot
from testbed.operator.station import OperatorStation, SessionPlan


class FnPilot:
    """A pilot from a function of time."""

    def __init__(self, fn: Callable[[float], PilotSample]) -> None:
        self.sample = fn


class ramp_pilot:  # noqa: N801 - used like the factory function it replaced
    """A pilot whose surge stick is the time it is asked at (and which logs the times)."""

    def __init__(self, calls: list[float]) -> None:
        self.calls = calls

    def sample(self, t_s: float) -> PilotSample:
        self.calls.append(t_s)
        return PilotSample((t_s, 0.0, -0.5, 0.0, 0.0, 0.25))


def euler_to_quat_wxyz(roll_rad: float, pitch_rad: float, yaw_rad: float) -> Quaternion:
    """Z-Y-X Euler → quaternion as a product of the three axis rotations q_z·q_y·q_x."""

    def mul(a: Quaternion, b: Quaternion) -> Quaternion:
        aw, ax, ay, az = a
        bw, bx, by, bz = b
        return (
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        )

    qx = (math.cos(roll_rad / 2), math.sin(roll_rad / 2), 0.0, 0.0)
    qy = (math.cos(pitch_rad / 2), 0.0, math.sin(pitch_rad / 2), 0.0)
    qz = (math.cos(yaw_rad / 2), 0.0, 0.0, math.sin(yaw_rad / 2))
    return mul(qz, mul(qy, qx))


def test_pilot_sampled_every_frame_with_increasing_seq_and_sample_time() -> None:
    calls: list[float] = []
    station = OperatorStation(ramp_pilot(calls), SessionPlan(arm_at_s=100.0))
    assert station.latest_command() is None
    times = [0.0, 0.05, 0.1, 0.4, 0.45]
    for k, t in enumerate(times, start=1):
        station.frame(t)
        assert station.latest_command() == MovementCommand(k, t, (t, 0.0, -0.5, 0.0, 0.0, 0.25))
    assert calls == times
    assert station.frames == len(times)
    # the same sticks twice are still a new sample: a new seq, a recorded change
    station.world.advance()
    before = station.world.changed_tick(station.entity, MovementCommand)
    station.frame(0.45)
    command = station.latest_command()
    assert command is not None and command.seq == len(times) + 1
    assert station.world.changed_tick(station.entity, MovementCommand) > before


def test_intents_entity_is_replicated() -> None:
    station = OperatorStation(ScriptedPilot(), SessionPlan())
    assert station.world.get(station.entity, Replicate) == Replicate()


def test_session_requested_once_at_arm_time() -> None:
    plan = SessionPlan(mode=ControlMode.STABILIZE, arm_at_s=1.0, depth_m=2.5, precision=True)
    station = OperatorStation(ScriptedPilot(), plan)
    world, entity = station.world, station.entity
    for t in (0.0, 0.5, 0.999):
        station.frame(t)
        for cls in (ModeRequest, DepthSetpoint, ArmRequest):
            assert world.get(entity, cls) is None
    station.frame(1.0)
    assert world.get(entity, ModeRequest) == ModeRequest(ControlMode.STABILIZE, True)
    assert world.get(entity, DepthSetpoint) == DepthSetpoint(2.5)
    assert world.get(entity, ArmRequest) == ArmRequest(True, 1)
    ticks = {
        cls: world.changed_tick(entity, cls) for cls in (ModeRequest, DepthSetpoint, ArmRequest)
    }
    # someone (a console, a test) changes an intent: the plan does not write it again
    world.set(entity, ArmRequest(False, 2))
    for t in (1.5, 2.0, 30.0):
        station.frame(t)
    assert world.get(entity, ArmRequest) == ArmRequest(False, 2)
    for cls in (ModeRequest, DepthSetpoint):
        assert world.changed_tick(entity, cls) == ticks[cls]


def test_session_without_depth_holds_the_present_depth() -> None:
    station = OperatorStation(ScriptedPilot(), SessionPlan(arm_at_s=0.0))
    station.frame(0.0)
    assert station.world.get(station.entity, DepthSetpoint) is None
    assert station.world.get(station.entity, ModeRequest) == ModeRequest(ControlMode.DEPTH_HOLD)
    assert station.world.get(station.entity, ArmRequest) == ArmRequest(True, 1)


def test_late_first_frame_still_requests_the_session() -> None:
    station = OperatorStation(ScriptedPilot(), SessionPlan(arm_at_s=1.0))
    station.frame(5.0)
    assert station.world.get(station.entity, ArmRequest) == ArmRequest(True, 1)


@pytest.mark.parametrize(
    "attitude_deg", [(0.0, 0.0, 0.0), (15.0, -10.0, 20.0), (-30.0, 45.0, -170.0), (5.0, 2.0, 179.0)]
)
def test_attitude_pilot_writes_the_attitude_setpoint(
    attitude_deg: tuple[float, float, float],
) -> None:
    station = OperatorStation(
        FnPilot(lambda t: PilotSample((0.3,) * 6, attitude_deg)), SessionPlan(arm_at_s=100.0)
    )
    station.frame(0.0)
    setpoint = station.world.get(station.entity, AttitudeSetpoint)
    assert setpoint is not None
    expected = euler_to_quat_wxyz(*(math.radians(a) for a in attitude_deg))
    assert setpoint.quaternion_wxyz == pytest.approx(expected, abs=1e-12)
    # and a second, independent check: SciPy's intrinsic Z-Y-X
    roll, pitch, yaw = attitude_deg
    x, y, z, w = Rotation.from_euler("ZYX", [yaw, pitch, roll], degrees=True).as_quat()
    dot = sum(a * b for a, b in zip(setpoint.quaternion_wxyz, (w, x, y, z), strict=True))
    assert abs(dot) == pytest.approx(1.0, abs=1e-12)
    # a setpoint-driven pilot does not send sticks
    assert station.latest_command() is None


def test_unchanged_attitude_is_not_a_change() -> None:
    station = OperatorStation(
        FnPilot(lambda t: PilotSample((0.0,) * 6, (0.0, 0.0, 10.0 if t < 1.0 else 20.0))),
        SessionPlan(arm_at_s=100.0),
    )
    world = station.world
    station.frame(0.0)
    world.advance()
    first = world.changed_tick(station.entity, AttitudeSetpoint)
    station.frame(0.5)
    assert world.changed_tick(station.entity, AttitudeSetpoint) == first
    station.frame(1.0)
    assert world.changed_tick(station.entity, AttitudeSetpoint) > first


def test_added_systems_run_around_the_pilot_in_phase_order() -> None:
    station = OperatorStation(ramp_pilot([]), SessionPlan(arm_at_s=100.0))
    seen: list[tuple[str, int | None]] = []

    def seq_now(world: World) -> int | None:
        command = world.get(station.entity, MovementCommand)
        return None if command is None else command.seq

    def ingest(world: World) -> None:
        seen.append(("pre", seq_now(world)))

    def publish(world: World) -> None:
        seen.append(("post", seq_now(world)))

    station.add_system(Phase.PRE_UPDATE, ingest)
    station.add_system(Phase.POST_UPDATE, publish)
    station.frame(0.0)
    station.frame(0.1)
    assert seen == [("pre", None), ("post", 1), ("pre", 1), ("post", 2)]


def test_vehicle_state_age_over_the_teleop_codec() -> None:
    station = OperatorStation(ScriptedPilot(), SessionPlan())
    assert station.vehicle_odometry() is None
    assert station.vehicle_state_age_s(3.0) == math.inf

    vehicle_world = World()
    vehicle = vehicle_world.spawn(Odometry(1.0, (0.0, 0.0, 0.3), (1.0, 0.0, 0.0, 0.0)))
    vehicle_end = TeleopVehicleEnd(vehicle_world, vehicle, vehicle_world.spawn())
    operator_end = TeleopOperatorEnd(station.world, station.entity)
    assert operator_end.apply_reply(vehicle_end.encode_reply(), 2.5)  # arrives at 2.5 s

    odometry = station.vehicle_odometry()
    assert odometry is not None and odometry.position_ned_m == (0.0, 0.0, 0.3)
    assert station.vehicle_state_age_s(2.5) == 0.0
    assert station.vehicle_state_age_s(3.75) == pytest.approx(1.25, abs=1e-15)
    operator_end.apply_reply(vehicle_end.encode_reply(), 4.0)
    assert station.vehicle_state_age_s(4.5) == pytest.approx(0.5, abs=1e-15)


def test_station_session_through_the_teleop_codec() -> None:
    """The first order after the arm time carries the pilot's sticks, the mode and the arm flag."""
    station = OperatorStation(
        FnPilot(lambda t: PilotSample((0.5, 0.0, -0.25, 0.0, 0.0, 1.0))),
        SessionPlan(mode=ControlMode.DEPTH_HOLD, arm_at_s=0.0, depth_m=1.0),
    )
    end = TeleopOperatorEnd(station.world, station.entity)
    station.frame(0.0)
    # seq 1 | move; x = 64, y = 0, z = round(−31.75) = −32 = 0xE0, yaw = 127 = 0x7F; arm | mode 2
    assert end.encode_order() == bytes((0x00, 0x81, 0x40, 0x00, 0xE0, 0x7F, 0x82))
