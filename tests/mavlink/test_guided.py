"""GUIDED through the sans-IO endpoint, pymavlink as the ground station, in simulated time:
accepted only with a position fix, SET_POSITION_TARGET_LOCAL_NED flown to within the fix's
noise, at a bounded speed, in bounded time; judged by the physics truth, which the controller
never reads."""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mav

from testbed.common.components import ActiveMode, ControlMode, PositionSetpoint
from testbed.common.geometry import euler_from_quat
from testbed.mavlink.endpoint import POSITION_FIX_TIMEOUT_S
from testbed.protocol import GoTo
from testbed.run.mavlink_gateway import run_gateway
from testbed.run.scenario import load_scenario
from testbed.vehicle.guidance import PositionGains
from tests.mavlink.gcs import SimGateway, SimGcs
from tests.mavlink.rt_session import GatewaySession

ACCEPTED = mav.MAV_RESULT_ACCEPTED
FAILED = mav.MAV_RESULT_FAILED
POSITION_ONLY = 0b1001_1111_1000  # x, y, z and yaw used; velocity, acceleration, yaw rate not
YAW_IGNORE = 1024
FIX_NOISE_M = 0.005  # s100-teleop-v1's [vehicle.sensors.position] noise_m (1σ per axis)
TOLERANCE_M = 0.05
"""Arrival tolerance [m], horizontal: 10σ of the fix's noise (the loop's only error source in
still water; its gain k_v·k_p = 24 N/m turns 5 mm of noise into 0.1 N) and 1.6 % of the 3.16-m
leg; the approach's exponential tail (time constant 1/k_p = 1.25 s) crosses it ≈ 2.9 s after
the speed limit lets go at 0.5/k_p = 0.63 m."""


def mode_acks(gcs: SimGcs) -> list[int]:
    """The mode change acknowledgements, in order: SET_MODE's (ArduPilot acknowledges it with
    its message id, 11) and COMMAND_LONG DO_SET_MODE's."""
    commands = (mav.MAVLINK_MSG_ID_SET_MODE, mav.MAV_CMD_DO_SET_MODE)
    return [m.result for m in gcs.of("COMMAND_ACK") if m.command in commands]


def target(
    gcs: SimGcs, frame: int, x: float, y: float, z: float, yaw: float | None = None
) -> object:
    mask = POSITION_ONLY | (YAW_IGNORE if yaw is None else 0)
    return gcs.mav.set_position_target_local_ned_encode(
        0, 1, 1, frame, mask, x, y, z, 0, 0, 0, 0, 0, 0, 0.0 if yaw is None else yaw, 0
    )


def test_guided_is_refused_without_a_position_fix() -> None:
    gcs = SimGcs(position_fix=False)
    try:
        gcs.send(gcs.heartbeat(), gcs.arm())
        gcs.run(1.0, gcs.flying())
        gcs.send(gcs.set_mode(4), gcs.command(mav.MAV_CMD_DO_SET_MODE, 1, 4))
        gcs.run(1.01, gcs.flying())
        assert mode_acks(gcs) == [FAILED, FAILED]
        assert gcs.last("HEARTBEAT").custom_mode == 19
        assert any(m.text == "Flight mode change failed" for m in gcs.of("STATUSTEXT"))
        gcs.send(target(gcs, mav.MAV_FRAME_LOCAL_NED, 3.0, 1.0, 1.0))
        gcs.run(0.1, gcs.flying())
        assert gcs.endpoint.rejected["not_guided"] == 1
        assert gcs.vehicle.world.get(gcs.vehicle.operator_entity, PositionSetpoint) is None
    finally:
        gcs.close()


def test_a_fix_older_than_the_timeout_is_no_position_estimate(gcs: SimGcs) -> None:
    gcs.run(1.0, gcs.flying())
    assert gcs.endpoint.has_position_estimate()
    gcs.vehicle.sensors.position = None  # the fix is lost: its last reading ages
    gcs.run(POSITION_FIX_TIMEOUT_S + 0.1, gcs.flying())
    gcs.send(gcs.set_mode(4))
    gcs.run(0.05, gcs.flying())
    assert mode_acks(gcs) == [FAILED]


@pytest.mark.parametrize(  # BODY_NED is what MAVProxy's `position` sends: ArduSub takes it
    "frame",  # as BODY_OFFSET_NED (a MAVLink user's review: it was refused)
    [mav.MAV_FRAME_BODY_OFFSET_NED, mav.MAV_FRAME_BODY_NED, mav.MAV_FRAME_BODY_FRD],
)
def test_guided_is_accepted_with_a_fix_and_flies_to_a_target_ahead_and_aside(
    gcs: SimGcs, frame: int
) -> None:
    gcs.send(gcs.heartbeat(), gcs.arm(), gcs.set_mode(2))
    gcs.run(1.0, gcs.flying())
    gcs.send(target(gcs, mav.MAV_FRAME_LOCAL_NED, 3.0, 1.0, 1.0))  # not in GUIDED: ignored
    gcs.send(gcs.set_mode(4))
    gcs.run(1.01, gcs.flying())
    assert mode_acks(gcs) == [ACCEPTED, ACCEPTED]
    assert gcs.endpoint.rejected["not_guided"] == 1
    hb = gcs.last("HEARTBEAT")
    assert (hb.custom_mode, hb.base_mode) == (4, 81 + 8 + 128)  # GUIDED flag, armed
    truth = gcs.vehicle.truth
    start = tuple(truth.position_ned_m)
    depth = start[2]
    heading = euler_from_quat(truth.quaternion_wxyz)[2]
    goal = (  # 3 m ahead, 1 m to the right of the heading, same depth
        start[0] + 3.0 * math.cos(heading) - 1.0 * math.sin(heading),
        start[1] + 3.0 * math.sin(heading) + 1.0 * math.cos(heading),
    )
    gcs.send(target(gcs, frame, 3.0, 1.0, 0.0))
    sent_s = gcs.now_s
    gains = PositionGains()
    leg = math.hypot(3.0, 1.0)
    reached_s = None
    top_speed = 0.0
    errors = []
    while gcs.now_s < sent_s + 25.0:
        gcs.run(0.1, gcs.flying())
        p, v = truth.position_ned_m, truth.velocity_m_s
        error = math.hypot(p[0] - goal[0], p[1] - goal[1])
        top_speed = max(top_speed, math.hypot(v[0], v[1]))
        errors.append(error)
        if reached_s is None and error < TOLERANCE_M:
            reached_s = gcs.now_s - sent_s
    assert reached_s is not None
    # bounded speed: never faster than the loop's limit (+ 10 % overshoot of the velocity loop)
    assert top_speed <= 1.1 * gains.max_speed_m_s
    # so not before the leg at that speed, and within it at the speed reached (> 0.3 m/s)
    # plus the tail: ln(0.63 / 0.05) / k_p ≈ 3.2 s
    assert leg / gains.max_speed_m_s <= reached_s <= leg / 0.3 + 4.0
    assert max(errors[-50:]) < TOLERANCE_M  # and stays: the last 5 s
    assert abs(truth.position_ned_m[2] - depth) < 0.05  # the depth hold held the depth
    assert abs(math.remainder(euler_from_quat(truth.quaternion_wxyz)[2] - heading, math.tau)) < (
        math.radians(3.0)
    )
    reported = gcs.last("LOCAL_POSITION_NED")
    assert math.hypot(reported.x - goal[0], reported.y - goal[1]) < TOLERANCE_M + 5 * FIX_NOISE_M
    assert gcs.endpoint.rejected.get("unsupported_target", 0) == 0


def test_an_absolute_target_with_a_heading_turns_and_dives_to_it(gcs: SimGcs) -> None:
    gcs.send(gcs.heartbeat(), gcs.arm(), gcs.set_mode(2))
    gcs.run(1.0, gcs.flying())
    gcs.send(gcs.command(mav.MAV_CMD_DO_SET_MODE, 1, 4))
    gcs.send(target(gcs, mav.MAV_FRAME_LOCAL_NED, -1.0, 1.5, 1.4, yaw=math.radians(90.0)))
    gcs.send(
        gcs.mav.set_position_target_local_ned_encode(  # an acceleration target: unsupported
            0, 1, 1, mav.MAV_FRAME_LOCAL_NED, 0b1100_0000_0111, 0, 0, 0, 0.2, 0, 0, 1, 0, 0, 0, 0
        )
    )
    gcs.run(20.0, gcs.flying())
    truth = gcs.vehicle.truth
    p = truth.position_ned_m
    assert math.hypot(p[0] + 1.0, p[1] - 1.5) < TOLERANCE_M
    assert abs(p[2] - 1.4) < 0.05
    yaw = euler_from_quat(truth.quaternion_wxyz)[2]
    assert abs(math.degrees(yaw) - 90.0) < 3.0
    assert gcs.endpoint.rejected["unsupported_target"] == 1
    active = gcs.vehicle.world.get(gcs.vehicle.entity, ActiveMode)
    assert active is not None and active.mode is ControlMode.GUIDED
    # leaving GUIDED for ALT_HOLD lets go of the target: the position loop's intent is zero
    gcs.send(gcs.set_mode(2))
    gcs.run(0.5, gcs.flying())
    loop = gcs.vehicle.controllers
    assert not loop.flags.guided and loop.position.velocity_ne_m_s == (0.0, 0.0)


def test_a_position_target_is_any_velocity_bit_and_any_acceleration_bit_as_ardusub(
    gcs: SimGcs,
) -> None:
    """ArduSub's ``vel_ignore`` and ``acc_ignore`` are each true for any one of their three
    bits: x, y, z used with VX and AX ignored is a position target (the other fields unread);
    no acceleration bit is no target ArduSub flies (no velocity bit is a position and
    velocity target: tests/mavlink/test_velocity_targets.py)."""
    gcs.send(gcs.heartbeat(), gcs.arm(), gcs.set_mode(2))
    gcs.run(1.0, gcs.flying())
    gcs.send(gcs.set_mode(4))
    gcs.run(1.01, gcs.flying())
    start = tuple(gcs.vehicle.truth.position_ned_m)
    entered = gcs.vehicle.world.get(gcs.vehicle.operator_entity, PositionSetpoint)
    assert entered is not None  # GUIDED's entry holds where the vehicle was

    def offset(mask: int) -> object:
        return gcs.mav.set_position_target_local_ned_encode(
            0, 1, 1, mav.MAV_FRAME_LOCAL_OFFSET_NED, mask, 2.0, 0, 0, 0.3, 0.3, 0, 1, 1, 0, 0, 0
        )

    gcs.send(offset(0b1100_0011_1000), offset(0b1100_0000_0000))  # no AX..AZ bit
    gcs.run(0.1, gcs.flying())
    assert gcs.endpoint.rejected["unsupported_target"] == 2
    setpoint = gcs.vehicle.world.get(gcs.vehicle.operator_entity, PositionSetpoint)
    assert setpoint is not None and setpoint.position_ned_m == entered.position_ned_m
    gcs.send(offset(YAW_IGNORE | 0b100_1000))  # VX and AX ignored only
    gcs.run(15.0, gcs.flying())
    p = gcs.vehicle.truth.position_ned_m
    assert math.hypot(p[0] - start[0] - 2.0, p[1] - start[1]) < TOLERANCE_M
    assert gcs.endpoint.rejected["unsupported_target"] == 2


def test_through_the_gateway_the_target_travels_as_one_goto_and_the_vehicle_flies_it() -> None:
    gw = SimGateway()
    try:
        gw.send(gw.mav.command_long_encode(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0))
        gw.send(gw.mav.set_mode_encode(1, 1, 2))
        gw.run(3.0)
        gw.send(gw.mav.set_mode_encode(1, 1, 4))  # GUIDED: the scenario's vehicle has a fix
        gw.run(3.0)  # two gaps: a reply answers before its order is applied
        acks = [m.result for m in gw.messages if m.get_type() == "COMMAND_ACK"]
        assert acks == [ACCEPTED, ACCEPTED, ACCEPTED]
        hb = gw.last("HEARTBEAT")
        assert (hb.custom_mode, hb.base_mode) == (4, 81 + 8 + 128)  # the vehicle's state
        truth = gw.vehicle.truth
        start = tuple(truth.position_ned_m)
        heading = euler_from_quat(truth.quaternion_wxyz)[2]
        goal = (
            start[0] + 3.0 * math.cos(heading) - 1.0 * math.sin(heading),
            start[1] + 3.0 * math.sin(heading) + 1.0 * math.cos(heading),
        )
        gw.send(
            gw.mav.set_position_target_local_ned_encode(
                0,
                1,
                1,
                mav.MAV_FRAME_BODY_OFFSET_NED,
                POSITION_ONLY | YAW_IGNORE,
                3.0,
                1.0,
                0.0,
                0,
                0,
                0,
                0,
                0,
                0,
                0,
                0,
            )
        )
        gw.run(22.0)
        gotos = [o for o in gw.orders if isinstance(o, GoTo)]
        # each setpoint travels once: GUIDED's entry (hold where the vehicle is), the target
        assert len(gotos) == 2
        hold = gotos[0]
        assert math.hypot(hold.x_cm / 100 - start[0], hold.y_cm / 100 - start[1]) < 0.03
        assert gw.far.counters.unsupported == 0
        p = truth.position_ned_m
        # the offset was taken from the reported state (1 cm, 1°, the fix's noise): + 3 cm
        assert math.hypot(p[0] - goal[0], p[1] - goal[1]) < TOLERANCE_M + 0.03
        assert abs(p[2] - start[2]) < 0.05
        reported = gw.last("LOCAL_POSITION_NED")
        assert math.hypot(reported.x - p[0], reported.y - p[1]) < 0.05  # the mirrored state
    finally:
        gw.vehicle.close()


@pytest.mark.slow
def test_guided_through_the_real_time_s100_gateway() -> None:
    """≈ 20 s real time: GUIDED and a body-offset target through ``run_gateway`` on s100."""
    scenario = load_scenario("s100-teleop-v1", ["metrics.settle_s=1"])
    session = GatewaySession(
        lambda links, stop: run_gateway(scenario, links, duration_s=120.0, stop=stop)
    )
    try:
        gcs = session.gcs
        assert gcs.wait_heartbeat(timeout=30.0) is not None
        session.pump(1.0)
        gcs.mav.command_long_send(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)
        assert session.ack(400) == ACCEPTED
        session.heartbeat(lambda hb: hb.base_mode & 128)
        gcs.mav.set_mode_send(1, mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 2)
        assert session.ack(mav.MAVLINK_MSG_ID_SET_MODE) == ACCEPTED
        gcs.mav.set_mode_send(1, mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 4)
        assert session.ack(mav.MAVLINK_MSG_ID_SET_MODE) == ACCEPTED
        session.heartbeat(lambda hb: hb.custom_mode == 4)  # the vehicle's own state
        session.pump(1.0)
        mask = POSITION_ONLY | YAW_IGNORE
        gcs.mav.set_position_target_local_ned_send(
            0, 1, 1, mav.MAV_FRAME_BODY_OFFSET_NED, mask, 2.0, 0.0, 0.0, 0, 0, 0, 0, 0, 0, 0, 0
        )
        session.pump(14.0)  # 2 m at ≤ 0.5 m/s and the tail, + a token gap and a crossing
        result = session.finish()
    finally:
        session.close()
    series = result.recorder.series()
    x, y = series["north_m"], series["east_m"]  # the truth
    assert abs(x[-1] - x[0] - 2.0) < TOLERANCE_M + 0.03  # the offset from the reported state
    assert abs(y[-1] - y[0]) < TOLERANCE_M + 0.03
    assert result.metrics["frames_rejected"] == {"uplink": 0, "downlink": 0}
