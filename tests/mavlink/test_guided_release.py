"""The ground station's latest GUIDED intent wins: a position target is let go of when
SET_ATTITUDE_TARGET takes over, and GUIDED entered again holds where the vehicle is, directly
and through the teleop gateway (pymavlink as the ground station, simulated time, the physics
truth as the judge).

Independent truth: ArduSub 4.5 — ``ModeGuided::guided_set_angle`` starts the angle controller,
which has no position target (only the depth's climb rate); ``Sub::set_mode`` → ``ModeGuided::
init`` → ``guided_pos_control_start`` sets the waypoint destination to the stopping point, so
GUIDED entered again flies no earlier target (the same mode requested again changes nothing)."""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mav

from testbed.common.components import Odometry, PositionSetpoint
from testbed.common.geometry import euler_from_quat, quat_from_euler
from testbed.ecs import Origin
from testbed.mavlink import EndpointOptions
from testbed.mavlink.shore import ShoreEndpoint
from testbed.protocol import GoTo
from testbed.run.mavlink_gateway import GatewayStation, gateway_link_facts, run_gateway
from testbed.run.scenario import load_scenario
from testbed.vehicle.guidance import PositionGains
from tests.mavlink.gcs import NO_VEHICLE_FAILSAFE, SimGateway, SimGcs
from tests.mavlink.rt_session import GatewaySession

AHEAD = 0b1101_1111_1000  # a position, yaw and yaw rate ignored (MAVProxy's `position`)
HEADING_TOLERANCE_DEG = 3.0
STOPPED_M = 0.1
"""How far from where GUIDED was entered again through the gateway, nearly at rest, the vehicle
may end (the shore holds the reported position): the hold settling on it, the fix's 5-mm noise
and the last of the coast (measured 2.3 cm, the reported position 0.5 s old); the old target
was 1.6–2 m on."""
COASTED_M = 0.15
"""Directly, the endpoint holds at the stopping point of the speed it estimates (≈ 0.07 m/s
left of the coast: 0.085 m on): the end may differ from that distance of the truth's speed by
the estimate's error over the loop's gain — its lag while the vehicle slows (the 0.3-s
low-pass: ≈ 0.1 m/s² × 0.3 s / 0.8 /s ≈ 4 cm) and 3σ of its noise (3 × 2.6 cm/s / 0.8 /s ≈
10 cm) — and the hold's settling (1 cm); measured 7 cm. The old target was 1.6–2 m on."""


def heading_deg(gateway: SimGateway) -> float:
    """The truth's heading [deg]."""
    return math.degrees(euler_from_quat(gateway.vehicle.truth.quaternion_wxyz)[2])


def ahead(sender: mav.MAVLink, metres: float) -> object:
    return sender.set_position_target_local_ned_encode(
        0, 1, 1, mav.MAV_FRAME_BODY_OFFSET_NED, AHEAD, metres, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0
    )


def test_guided_entered_again_holds_where_it_is_not_the_earlier_target(gcs: SimGcs) -> None:
    """3 m ahead, then ALT_HOLD 3 s on the way (it coasts nearly to a stop), then GUIDED again:
    it holds at the stopping point of the speed it still had, ≤ 0.5 m/s / 0.8 /s on
    (test_guided_entry.py), not the 3-m target it used to fly on to; GUIDED asked again changes
    nothing."""
    gcs.send(gcs.heartbeat(), gcs.arm(), gcs.set_mode(2))
    gcs.run(1.0, gcs.flying())
    gcs.send(gcs.set_mode(4))
    gcs.run(1.01, gcs.flying())
    start = tuple(gcs.vehicle.truth.position_ned_m)
    gcs.send(ahead(gcs.mav, 3.0))
    gcs.run(2.0, gcs.flying())
    gcs.send(gcs.set_mode(2))
    gcs.run(3.0, gcs.flying())
    stopped = tuple(gcs.vehicle.truth.position_ned_m)
    assert 0.3 < math.dist(stopped[:2], start[:2]) < 2.0  # on the way
    speed = math.hypot(*gcs.vehicle.truth.velocity_m_s[:2])  # body axes: the horizontal speed
    gains = PositionGains()
    coast = min(speed, gains.max_speed_m_s) / gains.kp_1_s  # the stopping distance
    gcs.send(gcs.set_mode(4))
    gcs.run(5.0, gcs.flying())
    gcs.send(gcs.set_mode(4))  # the same mode again: nothing new
    gcs.run(10.0, gcs.flying())
    end = tuple(gcs.vehicle.truth.position_ned_m)
    assert abs(math.dist(end[:2], stopped[:2]) - coast) < COASTED_M


def guided_gateway() -> SimGateway:
    gateway = SimGateway()
    gateway.send(gateway.mav.command_long_encode(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0))
    gateway.send(gateway.mav.set_mode_encode(1, 1, 2))
    gateway.run(3.0)
    gateway.send(gateway.mav.set_mode_encode(1, 1, 4))
    gateway.run(3.0)
    return gateway


def test_through_the_gateway_set_attitude_target_lets_go_of_the_goto_and_turns() -> None:
    """A GoTo 2 m ahead, flown; then SET_ATTITUDE_TARGET 60° to the right: ArduSub's angle
    control has no position target, so the vehicle turns to 60° (the GoTo's heading used to
    hold it, the position loop still on). The shore cancels the GoTo (the order's cancel bit);
    the vehicle's position target is gone. The same 2-m target sent again is a new GoTo."""
    gateway = guided_gateway()
    try:
        vehicle = gateway.vehicle
        gateway.send(ahead(gateway.mav, 2.0))
        gateway.run(15.0)
        start = heading_deg(gateway)
        q = quat_from_euler(0.0, 0.0, math.radians(start + 60.0))
        for _ in range(16):
            gateway.send(gateway.mav.set_attitude_target_encode(0, 1, 1, 7, list(q), 0, 0, 0, 0.5))
            gateway.run(0.25)
        gateway.run(6.0)
        turned = math.remainder(heading_deg(gateway) - start - 60.0, 360.0)
        assert abs(turned) < HEADING_TOLERANCE_DEG
        assert gateway.far.counters.cancels == 1
        assert vehicle.world.get(vehicle.operator_entity, PositionSetpoint) is None
        assert vehicle.controllers.position.velocity_ne_m_s == (0.0, 0.0)  # the loop let go
        gotos = len([o for o in gateway.orders if isinstance(o, GoTo)])
        position = gateway.last("LOCAL_POSITION_NED")
        gateway.send(
            gateway.mav.set_position_target_local_ned_encode(
                0, 1, 1, 1, AHEAD, position.x, position.y, position.z, 0, 0, 0, 0, 0, 0, 0, 0
            )
        )
        gateway.run(2.0)
        assert len([o for o in gateway.orders if isinstance(o, GoTo)]) == gotos + 1
        assert vehicle.world.get(vehicle.operator_entity, PositionSetpoint) is not None
    finally:
        gateway.vehicle.close()


def test_through_the_gateway_guided_entered_again_holds_where_it_is() -> None:
    """As directly: a GoTo 3 m ahead, ALT_HOLD on the way, GUIDED again: the shore sends a
    GoTo where the vehicle is (the old one used to be flown on to)."""
    gateway = guided_gateway()
    try:
        truth = gateway.vehicle.truth
        start = tuple(truth.position_ned_m)
        gateway.send(ahead(gateway.mav, 3.0))
        gateway.run(3.0)
        gateway.send(gateway.mav.set_mode_encode(1, 1, 2))
        gateway.run(4.0)
        stopped = tuple(truth.position_ned_m)
        assert 0.3 < math.dist(stopped[:2], start[:2]) < 2.0
        gateway.send(gateway.mav.set_mode_encode(1, 1, 4))
        gateway.run(15.0)
        end = tuple(truth.position_ned_m)
        assert math.dist(end[:2], stopped[:2]) < STOPPED_M
    finally:
        gateway.vehicle.close()


@pytest.mark.slow
def test_through_the_real_time_s100_gateway_set_attitude_target_lets_go_of_the_goto() -> None:
    """≈ 25 s real time: ``run_gateway`` on s100, pymavlink's ``mavutil`` on 127.0.0.1. A
    target 1.5 m ahead, flown; SET_ATTITUDE_TARGET 60° to the right at 4 Hz for 3 s: the
    recorded truth turns 60° and the vehicle's position target is let go (``target_n``
    NaN: no go-to flown)."""
    scenario = load_scenario("s100-teleop-v1", ["metrics.settle_s=1"])
    session = GatewaySession(
        lambda links, stop: run_gateway(scenario, links, duration_s=120.0, stop=stop)
    )
    try:
        gcs = session.gcs
        assert gcs.wait_heartbeat(timeout=30.0) is not None
        session.pump(1.0)
        gcs.mav.command_long_send(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)
        assert session.ack(400) == mav.MAV_RESULT_ACCEPTED
        session.heartbeat(lambda hb: hb.base_mode & 128)
        gcs.mav.set_mode_send(1, mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 4)
        assert session.ack(mav.MAVLINK_MSG_ID_SET_MODE) == mav.MAV_RESULT_ACCEPTED
        session.heartbeat(lambda hb: hb.custom_mode == 4)  # the vehicle's own state
        gcs.mav.set_position_target_local_ned_send(
            0, 1, 1, mav.MAV_FRAME_BODY_NED, AHEAD, 1.5, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0
        )
        session.pump(10.0)  # 1.5 m at ≤ 0.5 m/s and the tail, + a token gap and a crossing
        start = math.degrees(session.latest["ATTITUDE"].yaw)
        q = quat_from_euler(0.0, 0.0, math.radians(start + 60.0))
        for _ in range(12):
            gcs.mav.set_attitude_target_send(0, 1, 1, 7, list(q), 0, 0, 0, 0.5)
            session.pump(0.25)
        session.pump(4.0)
        result = session.finish()
    finally:
        session.close()
    series = result.recorder.series()
    turned = math.remainder(series["yaw_deg"][-1] - start - 60.0, 360.0)
    assert abs(turned) < HEADING_TOLERANCE_DEG
    assert math.isnan(series["target_n"][-1])  # no go-to flown any more


def test_through_the_gateway_guided_is_refused_before_the_vehicles_position_arrives() -> None:
    """The shore's hold where GUIDED is entered needs the vehicle's position: before the first
    reply brings it, GUIDED is refused as ArduSub refuses it without a position estimate
    (FAILED, "Flight mode change failed"), not entered to hold the origin; once a state is
    mirrored it is accepted and holds there."""
    scenario = load_scenario("s100-teleop-v1", list(NO_VEHICLE_FAILSAFE))
    station = GatewayStation()
    options = EndpointOptions(origin=Origin.LOCAL)
    shore = ShoreEndpoint(station.world, station.entity, gateway_link_facts(scenario), options)
    channel = shore.open_channel("gcs")
    sender = SimGcs.make_sender(255)
    decoder = mav.MAVLink(None)
    guided = sender.set_mode_encode(1, mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 4)
    shore.receive(channel, guided.pack(sender), 0.0)
    shore.update(0.01)
    mirrored = station.world.spawn()  # the first reply's state
    odometry = Odometry(0.3, (4.0, -2.0, 1.5), (1.0, 0.0, 0.0, 0.0))
    station.world.set(mirrored, odometry, origin=Origin.REMOTE)
    shore.update(0.3)
    shore.receive(channel, guided.pack(sender), 0.35)
    replies = [m for p in channel.take() for m in decoder.parse_buffer(p) or []]
    acks = [m.result for m in replies if m.get_type() == "COMMAND_ACK"]
    assert acks == [mav.MAV_RESULT_FAILED, mav.MAV_RESULT_ACCEPTED]
    setpoint = station.world.get(station.entity, PositionSetpoint)
    assert setpoint is not None and setpoint.position_ned_m == odometry.position_ned_m
