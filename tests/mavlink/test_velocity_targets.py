"""GUIDED's velocity targets through the sans-IO endpoint, pymavlink as the ground station, in
simulated time, judged by the physics truth: SET_POSITION_TARGET_LOCAL_NED and _GLOBAL_INT with
a velocity alone or a position and a velocity, as ArduSub 4.5 flies them.

Independent truth: ArduSub's rules restated from ``GCS_MAVLINK_Sub::handle_message`` and
``mode_guided.cpp`` — the submode by ``type_mask`` (position and/or velocity used, the
acceleration ignored), the position target advanced by the velocity each loop
(``posvel_pos_target_cm += vel × dt``), the velocity zeroed ``GUIDED_POSVEL_TIMEOUT_MS`` = 3 s
after the last message, a velocity alone starting where the vehicle is. So a vehicle that
stops must stop at the commanded position plus the velocity times the time from the message
to the timeout; and while the target moves the truth's speed is the commanded one."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mav

from testbed.common.components import Odometry, PositionSetpoint
from testbed.common.geometry import euler_from_quat
from testbed.ecs import Origin
from testbed.mavlink import EndpointOptions
from testbed.mavlink.shore import ShoreEndpoint
from testbed.run.mavlink_gateway import GatewayStation, gateway_link_facts
from testbed.run.scenario import load_scenario
from testbed.vehicle.guidance import PositionGains
from tests.mavlink.gcs import NO_VEHICLE_FAILSAFE, SimGcs

VELOCITY_ONLY = 0b1101_1100_0111  # x, y, z and the acceleration ignored, yaw and its rate too
POSVEL = 0b1101_1100_0000  # position and velocity used
MAVPROXY_VELOCITY = 4039  # MAVProxy's `velocity`: VELOCITY_ONLY | FORCE, BODY_NED
TIMEOUT_S = 3.0  # GUIDED_POSVEL_TIMEOUT_MS
WPNAV_SPEED_DN_M_S = 1.5  # the table's WPNAV_SPEED_DN 150 cm/s (ArduSub's default)
TOLERANCE_M = 0.05  # the GUIDED loop's arrival tolerance (test_guided.py)
RATE_HZ = 4.0  # the ground station's message rate


def local(
    gcs: SimGcs,
    mask: int,
    velocity: tuple[float, float, float],
    position: tuple[float, float, float] = (0.0, 0.0, 0.0),
    frame: int = mav.MAV_FRAME_LOCAL_NED,
) -> Any:
    return gcs.mav.set_position_target_local_ned_encode(
        0, 1, 1, frame, mask, *position, *velocity, 0, 0, 0, 0, 0
    )


def stream(gcs: SimGcs, seconds: float, message: Callable[[float], Any]) -> list[float]:
    """``message(t)`` at :data:`RATE_HZ` for ``seconds`` with the sticks; the send times."""
    sticks = gcs.flying()
    sent: list[float] = []
    every = round(1.0 / (RATE_HZ * 0.01))

    def each(k: int) -> list[Any]:
        if k % every:
            return sticks(k)
        sent.append(gcs.now_s)
        return [*sticks(k), message(gcs.now_s)]

    gcs.run(seconds, each)
    return sent


def truth(gcs: SimGcs) -> tuple[float, float, float]:
    p = gcs.vehicle.truth.position_ned_m
    return (float(p[0]), float(p[1]), float(p[2]))


def reported(gcs: SimGcs) -> tuple[float, float, float]:
    return gcs.endpoint.snapshot_now().position_ned_m


def test_a_velocity_alone_moves_the_vehicle_at_it_until_three_seconds_after_the_last(
    gcs: SimGcs,
) -> None:
    gcs.enter_guided()
    velocity = (0.2, -0.1, 0.05)  # north, east, down [m/s]
    start = reported(gcs)  # where ArduSub's velocity controller starts: the estimate
    sent = stream(gcs, 10.0, lambda t: local(gcs, VELOCITY_ONLY, velocity))
    # while it moves, the truth's speed is the command's (8 s in, the loop's lag settled)
    before = truth(gcs)
    gcs.run(1.0, gcs.flying())
    after = truth(gcs)
    for axis in range(3):
        assert (after[axis] - before[axis]) == pytest.approx(velocity[axis], abs=0.01)
    gcs.run(15.0, gcs.flying())
    moved_s = sent[-1] + TIMEOUT_S - sent[0]  # the first message to the timeout
    end = truth(gcs)
    goal = [s + v * moved_s for s, v in zip(start, velocity, strict=True)]
    assert math.hypot(end[0] - goal[0], end[1] - goal[1]) < TOLERANCE_M
    assert end[2] == pytest.approx(goal[2], abs=0.05)  # the depth hold's tolerance
    assert gcs.endpoint.rejected.get("unsupported_target", 0) == 0


def test_mavproxys_velocity_command_is_along_the_heading_and_keeps_it(gcs: SimGcs) -> None:
    """MAVProxy's ``velocity 0.3 0 0``: once, in BODY_NED, yaw and its rate ignored: 0.3 m/s
    ahead for ArduSub's 3-s timeout, 0.9 m, the heading kept."""
    gcs.enter_guided()
    heading = euler_from_quat(gcs.vehicle.truth.quaternion_wxyz)[2]
    start = reported(gcs)
    gcs.send(local(gcs, MAVPROXY_VELOCITY, (0.3, 0.0, 0.0), frame=mav.MAV_FRAME_BODY_NED))
    gcs.run(15.0, gcs.flying())
    end = truth(gcs)
    ahead = 0.3 * TIMEOUT_S
    goal = (start[0] + ahead * math.cos(heading), start[1] + ahead * math.sin(heading))
    assert math.hypot(end[0] - goal[0], end[1] - goal[1]) < TOLERANCE_M
    yaw = euler_from_quat(gcs.vehicle.truth.quaternion_wxyz)[2]
    assert abs(math.remainder(yaw - heading, math.tau)) < math.radians(3.0)


def test_a_position_and_velocity_target_moves_from_the_position_given(gcs: SimGcs) -> None:
    """One message: the target is its position, then moves at its velocity for 3 s. A
    trajectory streamed at 4 Hz (the position and its velocity at each instant, as a
    trajectory follower sends them): the vehicle rides it, and stops 3 s of velocity past
    its last point."""
    gcs.enter_guided()
    here = reported(gcs)
    position = (here[0] + 1.0, here[1], here[2])
    velocity = (0.0, 0.1, 0.0)
    gcs.send(local(gcs, POSVEL, velocity, position))
    gcs.run(20.0, gcs.flying())
    end = truth(gcs)
    goal = (position[0], position[1] + velocity[1] * TIMEOUT_S)
    assert math.hypot(end[0] - goal[0], end[1] - goal[1]) < TOLERANCE_M

    start, t0 = reported(gcs), gcs.now_s
    line = (-0.15, 0.15, 0.0)  # 0.21 m/s north-west

    def point(t: float) -> Any:
        n, e, d = (s + v * (t - t0) for s, v in zip(start, line, strict=True))
        return local(gcs, POSVEL, line, (n, e, d))

    sent = stream(gcs, 8.0, point)
    gcs.run(15.0, gcs.flying())
    end = truth(gcs)
    flown_s = sent[-1] - t0 + TIMEOUT_S
    goal = (start[0] + line[0] * flown_s, start[1] + line[1] * flown_s)
    assert math.hypot(end[0] - goal[0], end[1] - goal[1]) < TOLERANCE_M


def test_a_velocity_the_vehicle_cannot_fly_keeps_the_target_on_its_leash(gcs: SimGcs) -> None:
    """2 m/s north and 9 m/s down asked once. North: the vehicle flies at its loop's top speed
    and the target stays within the leash ahead (top speed ÷ gain, 0.5 m/s ÷ 0.8 /s =
    0.625 m: from there on the loop already asks for its top speed), as ArduPilot's position
    controller leashes its target; so after ArduSub's 3 s the vehicle stops within the leash
    of where it was then, not the 6 m on that 2 m/s × 3 s would leave it. Down: the target
    descends at WPNAV_SPEED_DN, 1.5 m/s (ArduSub's posvel limit), 4.5 m."""
    gcs.enter_guided()
    gains = PositionGains()
    leash = gains.max_speed_m_s / gains.kp_1_s
    start = reported(gcs)
    gcs.send(local(gcs, VELOCITY_ONLY, (2.0, 0.0, 9.0)))
    sent = gcs.now_s
    top, at_timeout = 0.0, None
    for _ in range(200):
        gcs.run(0.1, gcs.flying())
        v = gcs.vehicle.truth.velocity_m_s
        top = max(top, math.hypot(v[0], v[1]))
        if at_timeout is None and gcs.now_s >= sent + TIMEOUT_S:
            at_timeout = truth(gcs)
    assert at_timeout is not None
    end = truth(gcs)
    assert top <= 1.1 * gains.max_speed_m_s
    assert 0.0 < end[0] - at_timeout[0] < leash + TOLERANCE_M
    assert abs(end[1] - start[1]) < TOLERANCE_M
    assert end[2] - start[2] == pytest.approx(WPNAV_SPEED_DN_M_S * TIMEOUT_S, abs=0.05)


def test_a_global_velocity_is_north_east_down_whatever_the_frame(gcs: SimGcs) -> None:
    gcs.enter_guided()
    start = reported(gcs)
    velocity = (-0.1, 0.2, 0.0)
    terrain = mav.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT  # no position: the frame is not read
    message = gcs.mav.set_position_target_global_int_encode(
        0, 1, 1, terrain, VELOCITY_ONLY, 0, 0, 0, *velocity, 0, 0, 0, 0, 0
    )
    sent = stream(gcs, 2.0, lambda t: message)
    gcs.run(15.0, gcs.flying())
    end = truth(gcs)
    moved_s = sent[-1] + TIMEOUT_S - sent[0]
    goal = (start[0] + velocity[0] * moved_s, start[1] + velocity[1] * moved_s)
    assert math.hypot(end[0] - goal[0], end[1] - goal[1]) < TOLERANCE_M
    assert gcs.endpoint.rejected.get("unsupported_frame", 0) == 0


def test_masks_ardusub_ignores_are_counted_and_other_targets_end_the_motion(
    gcs: SimGcs,
) -> None:
    """An acceleration used, or neither a position nor a velocity: ArduSub flies nothing
    (counted ``unsupported_target``); a NaN velocity is ``bad_field``. A position target, a
    mode change or SET_ATTITUDE_TARGET's angle control ends a moving target."""
    gcs.enter_guided()
    intents = gcs.vehicle.operator_entity
    entered = gcs.vehicle.world.get(intents, PositionSetpoint)  # where GUIDED was entered
    assert entered is not None
    accel = 0b1100_0000_0111  # velocity and acceleration used
    nothing = 0b1101_1111_1111  # every position and velocity bit set
    gcs.send(
        local(gcs, accel, (0.2, 0.0, 0.0)),
        local(gcs, nothing, (0.2, 0.0, 0.0)),
        local(gcs, VELOCITY_ONLY, (math.nan, 0.0, 0.0)),
    )
    gcs.run(0.1, gcs.flying())
    rejected = gcs.endpoint.rejected
    assert (rejected["unsupported_target"], rejected["bad_field"]) == (2, 1)
    assert gcs.vehicle.world.get(intents, PositionSetpoint) == entered
    for end in (
        local(gcs, 0b1101_1111_1000, (0, 0, 0), reported(gcs)),  # a position target
        gcs.mav.set_attitude_target_encode(0, 1, 1, 7, [1, 0, 0, 0], 0, 0, 0, 0.5),
        gcs.set_mode(2),
    ):
        if gcs.last("HEARTBEAT").custom_mode != 4:
            gcs.enter_guided()
        gcs.send(local(gcs, VELOCITY_ONLY, (0.2, 0.0, 0.0)))
        gcs.run(0.5, gcs.flying())
        assert gcs.endpoint.moving_target is not None
        gcs.send(end)
        gcs.run(0.5, gcs.flying())
        assert gcs.endpoint.moving_target is None
        setpoint = gcs.vehicle.world.get(intents, PositionSetpoint)
        gcs.run(0.5, gcs.flying())
        assert gcs.vehicle.world.get(intents, PositionSetpoint) == setpoint  # it stays put


def test_through_the_gateway_a_velocity_target_is_refused_and_said_once() -> None:
    """A moving target would be a new GoTo in every token gap, leaving none for the Move that
    carries a disarm or a mode change: the shore counts it ``unsupported_target`` and says so
    once; a position target still goes (test_guided.py flies one through the codec)."""
    scenario = load_scenario("s100-teleop-v1", list(NO_VEHICLE_FAILSAFE))
    station = GatewayStation()
    options = EndpointOptions(origin=Origin.LOCAL)
    shore = ShoreEndpoint(station.world, station.entity, gateway_link_facts(scenario), options)
    channel = shore.open_channel("gcs")
    sender = SimGcs.make_sender(255)
    decoder = mav.MAVLink(None)
    mirrored = station.world.spawn()  # the vehicle's state, as the first reply leaves it
    odometry = Odometry(1.0, (0.5, -0.5, 1.0), (1.0, 0.0, 0.0, 0.0))
    station.world.set(mirrored, odometry, origin=Origin.REMOTE)
    shore.update(1.0)
    shore.receive(channel, sender.set_mode_encode(1, 1, 4).pack(sender), 1.0)  # GUIDED
    entered = station.world.get(station.entity, PositionSetpoint)  # the hold where entered
    assert entered is not None and entered.position_ned_m == odometry.position_ned_m
    for k in range(3):
        velocity = sender.set_position_target_local_ned_encode(
            0, 1, 1, mav.MAV_FRAME_LOCAL_NED, VELOCITY_ONLY, 0, 0, 0, 0.2, 0, 0, 0, 0, 0, 0, 0
        )
        shore.receive(channel, velocity.pack(sender), 1.0 + 0.1 * (k + 1))
        shore.update(1.0 + 0.1 * (k + 1))
    replies = [m for p in channel.take() for m in decoder.parse_buffer(p) or []]
    texts = [m.text for m in replies if m.get_type() == "STATUSTEXT"]
    assert texts.count("Velocity targets do not cross the link") == 1
    assert shore.rejected["unsupported_target"] == 3
    assert station.world.get(station.entity, PositionSetpoint) == entered
    position = sender.set_position_target_local_ned_encode(
        0, 1, 1, mav.MAV_FRAME_LOCAL_NED, 0b1101_1111_1000, 1, 2, 1, 0, 0, 0, 0, 0, 0, 0, 0
    )
    shore.receive(channel, position.pack(sender), 1.5)
    setpoint = station.world.get(station.entity, PositionSetpoint)
    assert setpoint is not None and setpoint.position_ned_m == (1.0, 2.0, 1.0)
