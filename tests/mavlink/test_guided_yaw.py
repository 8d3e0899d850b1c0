"""GUIDED's heading from SET_POSITION_TARGET_LOCAL_NED's ``yaw`` and ``yaw_rate``, as ArduSub 4.5
flies it, through the sans-IO endpoint with pymavlink as the ground station, in simulated time,
judged by the physics truth's heading.

Independent truth: ArduSub 4.5 restated here from its source, not from the endpoint's code —
``GCS_MAVLINK_Sub::handle_message`` (the yaw is relative only in MAV_FRAME_BODY_OFFSET_NED;
``yaw_cd = degrees(yaw) * 100``, ``yaw_rate_cds`` likewise), ``ModeGuided::guided_set_yaw_state``
(``direction`` = the sign of ``wrap_PI(wrap_2PI(yaw_cd * 0.01) − wrap_2PI(heading))``: the yaw in
degrees wrapped as radians), ``ModeAuto::set_auto_yaw_look_at_heading`` and ``set_yaw_rate``
(the slew: AUTO_YAW_SLEW_RATE 60°/s without a rate, else min(rate, 60°/s) stored in an int16,
so truncated), ``AC_AttitudeControl_Sub::input_euler_angle_roll_pitch_slew_yaw`` (turn at the
slew while more than MAX_YAW_ERROR = 5° off the look-at heading, hold it within) and the guided
run functions (the rate-only turn has no timeout; the state lives in ``Sub``, kept across
targets and modes)."""

from __future__ import annotations

import math
from typing import Any

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mav

from testbed.common.geometry import euler_from_quat, quat_from_euler
from testbed.protocol import GoTo
from tests.mavlink.gcs import SimGateway, SimGcs

YAW = 0b1001_1111_1000  # a position, the yaw used, the yaw rate ignored
YAW_AND_RATE = 0b0001_1111_1000  # a position, the yaw and the yaw rate used
RATE_ONLY = 0b0101_1111_1000  # a position, the yaw ignored, the yaw rate used
NO_YAW = 0b1101_1111_1000  # a position only (MAVProxy's `position` sends 3576, the same + FORCE)
SLEW_DEG_S = 60.0  # AUTO_YAW_SLEW_RATE
HEADING_TOLERANCE_DEG = 3.0  # the heading hold's settling (test_guided.py, test_attitude_target)


def target(
    gcs: SimGcs,
    frame: int,
    mask: int,
    yaw: float = 0.0,
    yaw_rate: float = 0.0,
    position: tuple[float, float, float] = (0.0, 0.0, 0.0),
) -> Any:
    return gcs.mav.set_position_target_local_ned_encode(
        0, 1, 1, frame, mask, *position, 0, 0, 0, 0, 0, 0, yaw, yaw_rate
    )


def here(gcs: SimGcs) -> tuple[float, float, float]:
    p = gcs.vehicle.truth.position_ned_m
    return (float(p[0]), float(p[1]), float(p[2]))


def heading_deg(gcs: SimGcs) -> float:
    """The truth's heading [deg, (−180, 180]]."""
    return math.degrees(euler_from_quat(gcs.vehicle.truth.quaternion_wxyz)[2])


def off_deg(a: float, b: float) -> float:
    return abs(math.remainder(a - b, 360.0))


def face(gcs: SimGcs, heading: float) -> None:
    """Turn to ``heading`` [deg] with an absolute yaw where the vehicle is, and settle."""
    gcs.send(target(gcs, mav.MAV_FRAME_LOCAL_NED, YAW, math.radians(heading), 0.0, here(gcs)))
    gcs.run(6.0, gcs.flying())
    assert off_deg(heading_deg(gcs), heading) < HEADING_TOLERANCE_DEG


def ardusub_direction(yaw_deg: float, heading: float) -> int:
    """``guided_set_yaw_state``'s direction, restated: the yaw in degrees wrapped to [0, 2π) as
    if radians, less the heading in [0, 2π), wrapped to (−π, π]; −1 below zero."""
    euler = math.fmod(yaw_deg, math.tau) % math.tau
    current = math.radians(heading) % math.tau
    error = (euler - current) % math.tau
    error = error - math.tau if error > math.pi else error
    return -1 if error < 0.0 else 1


@pytest.mark.parametrize("frame", [mav.MAV_FRAME_BODY_NED, mav.MAV_FRAME_BODY_FRD])
def test_in_body_ned_and_body_frd_the_yaw_is_a_heading_from_north(gcs: SimGcs, frame: int) -> None:
    """ArduSub's ``yaw_relative`` is true in BODY_OFFSET_NED only: facing east, a BODY_NED or
    BODY_FRD target with yaw 0.5 rad turns the vehicle to 28.6° from north, not 90° + 28.6°."""
    gcs.enter_guided()
    face(gcs, 90.0)
    gcs.send(target(gcs, frame, YAW, 0.5))
    gcs.run(6.0, gcs.flying())
    assert off_deg(heading_deg(gcs), math.degrees(0.5)) < HEADING_TOLERANCE_DEG


@pytest.mark.parametrize("start", [90.0, 0.0])
def test_in_body_offset_ned_the_yaw_is_relative_turned_by_ardusubs_direction(
    gcs: SimGcs, start: float
) -> None:
    """BODY_OFFSET_NED: the look-at heading is the held heading plus the yaw, or minus it when
    ArduSub's direction (the degrees wrapped as radians) is negative: +0.5 rad turns right
    facing east and left facing north."""
    gcs.enter_guided()
    face(gcs, start)
    yaw_deg = math.degrees(0.5)
    direction = ardusub_direction(yaw_deg, start)
    assert direction == (1 if start == 90.0 else -1)  # the two cases differ
    gcs.send(target(gcs, mav.MAV_FRAME_BODY_OFFSET_NED, YAW, 0.5))
    gcs.run(6.0, gcs.flying())
    assert off_deg(heading_deg(gcs), start + direction * yaw_deg) < HEADING_TOLERANCE_DEG


def turn_rate_deg_s(gcs: SimGcs, seconds: float) -> float:
    """The truth's mean turn rate over the next ``seconds`` [deg/s]."""
    before = heading_deg(gcs)
    gcs.run(seconds, gcs.flying())
    return math.remainder(heading_deg(gcs) - before, 360.0) / seconds


def test_a_yaw_is_slewed_to_at_sixty_degrees_a_second_or_at_the_yaw_rate(gcs: SimGcs) -> None:
    """Without a yaw rate the look-at heading is slewed to at AUTO_YAW_SLEW_RATE, 60°/s; with
    0.2 rad/s (11.46°/s) at the int16 it is stored in, 11°/s; either way it ends on the yaw."""
    gcs.enter_guided()
    face(gcs, 0.0)
    gcs.send(target(gcs, mav.MAV_FRAME_LOCAL_NED, YAW, math.radians(90.0), 0.0, here(gcs)))
    gcs.run(0.5, gcs.flying())  # the heading hold's lag behind the slewing target settled
    assert turn_rate_deg_s(gcs, 0.75) == pytest.approx(SLEW_DEG_S, abs=3.0)
    gcs.run(3.0, gcs.flying())
    assert off_deg(heading_deg(gcs), 90.0) < HEADING_TOLERANCE_DEG

    rate = 0.2  # rad/s
    slew = int(min(math.degrees(rate), SLEW_DEG_S))  # 11
    gcs.send(target(gcs, mav.MAV_FRAME_LOCAL_NED, YAW_AND_RATE, math.radians(150.0), rate))
    gcs.run(1.0, gcs.flying())
    assert turn_rate_deg_s(gcs, 4.0) == pytest.approx(slew, abs=0.3)  # not 11.46
    gcs.run((60.0 - 5.0) / slew, gcs.flying())  # the rest of the turn (within 5°: held)
    assert off_deg(heading_deg(gcs), 150.0) < HEADING_TOLERANCE_DEG


def test_a_negative_yaw_rate_turns_the_long_way(gcs: SimGcs) -> None:
    """The slew min(rate, 60°/s) keeps a negative rate's sign, and the slew is multiplied by
    the direction toward the look-at heading: 30° to the right at −0.2 rad/s turns left at
    11°/s, round to it."""
    gcs.enter_guided()
    face(gcs, 0.0)
    gcs.send(target(gcs, mav.MAV_FRAME_LOCAL_NED, YAW_AND_RATE, math.radians(30.0), -0.2))
    gcs.run(1.0, gcs.flying())
    assert turn_rate_deg_s(gcs, 4.0) == pytest.approx(-11.0, abs=0.3)


def test_a_yaw_rate_alone_turns_for_ever_and_the_state_outlives_the_target(gcs: SimGcs) -> None:
    """A yaw rate alone (ArduSub's ``set_yaw_rate``, ``yaw_rate_only``) turns at it with no
    timeout (the velocity's 3 s do not apply), at 0.3 rad/s = 17.19°/s stored as 17°/s; a
    global target, which sets no yaw state, leaves it turning; a local target that ignores
    both clears ``yaw_rate_only``, and the look-at heading it never set (north, from boot) is
    slewed back to at the last slew, 17°/s."""
    gcs.enter_guided()
    gcs.send(target(gcs, mav.MAV_FRAME_LOCAL_NED, RATE_ONLY, 0.0, 0.3, here(gcs)))
    gcs.run(1.0, gcs.flying())
    assert turn_rate_deg_s(gcs, 8.0) == pytest.approx(17.0, abs=0.3)
    fix = gcs.last("GLOBAL_POSITION_INT")
    gcs.send(
        gcs.mav.set_position_target_global_int_encode(
            0, 1, 1, 6, NO_YAW, fix.lat, fix.lon, fix.alt / 1000.0, 0, 0, 0, 0, 0, 0, 0, 0
        )
    )
    gcs.run(1.0, gcs.flying())
    assert turn_rate_deg_s(gcs, 4.0) == pytest.approx(17.0, abs=0.3)
    gcs.send(target(gcs, mav.MAV_FRAME_LOCAL_NED, NO_YAW, 0.0, 0.0, here(gcs)))
    gcs.run(360.0 / 17.0 + 1.0, gcs.flying())  # at most a turn at 17°/s
    assert off_deg(heading_deg(gcs), 0.0) < HEADING_TOLERANCE_DEG
    assert turn_rate_deg_s(gcs, 2.0) == pytest.approx(0.0, abs=0.5)


def test_a_target_that_ignores_the_yaw_turns_back_to_the_last_yaw_asked(gcs: SimGcs) -> None:
    """The look-at heading and its slew outlive the target that set them: after a yaw of 90°,
    SET_ATTITUDE_TARGET's angle control turns the vehicle to 0°; a position target that
    ignores the yaw then turns it back to 90° (ArduSub's loop picks AUTO_YAW_LOOK_AT_HEADING
    again), where it had been kept at 0° before."""
    gcs.enter_guided()
    face(gcs, 90.0)
    q = quat_from_euler(0.0, 0.0, 0.0)
    for _ in range(8):
        gcs.send(gcs.mav.set_attitude_target_encode(0, 1, 1, 7, list(q), 0, 0, 0, 0.5))
        gcs.run(0.25, gcs.flying())
    gcs.run(2.0, gcs.flying())
    assert off_deg(heading_deg(gcs), 0.0) < HEADING_TOLERANCE_DEG
    gcs.send(target(gcs, mav.MAV_FRAME_LOCAL_NED, NO_YAW, 0.0, 0.0, here(gcs)))
    gcs.run(5.0, gcs.flying())
    assert off_deg(heading_deg(gcs), 90.0) < HEADING_TOLERANCE_DEG


def test_a_yaw_or_yaw_rate_is_read_only_when_used(gcs: SimGcs) -> None:
    """A NaN in an ignored yaw or yaw rate is not read (it used to refuse the target); a NaN
    in a used one, or a rate below the int16 °/s ArduSub stores, is ``bad_field``."""
    gcs.enter_guided()
    start = here(gcs)
    goal = (start[0] + 1.0, start[1], start[2])
    gcs.send(
        target(gcs, mav.MAV_FRAME_LOCAL_NED, YAW, math.nan, 0.0, goal),
        target(gcs, mav.MAV_FRAME_LOCAL_NED, YAW_AND_RATE, 0.0, math.nan, goal),
        target(gcs, mav.MAV_FRAME_LOCAL_NED, RATE_ONLY, 0.0, -1000.0, goal),  # −57 296°/s
    )
    gcs.run(0.1, gcs.flying())
    assert gcs.endpoint.rejected["bad_field"] == 3
    gcs.send(target(gcs, mav.MAV_FRAME_LOCAL_NED, NO_YAW, math.nan, math.nan, goal))
    gcs.run(12.0, gcs.flying())
    assert gcs.endpoint.rejected["bad_field"] == 3
    assert math.dist(here(gcs)[:2], goal[:2]) < 0.05


def test_through_the_gateway_the_yaw_crosses_in_the_goto_and_its_rate_is_said_not_to() -> None:
    """The teleop codec's ``GoTo`` carries a heading, not a turn rate: the shore sends the
    look-at heading (whole degrees) and says once that the yaw rate does not cross; the
    vehicle turns to it at its own rate."""
    gateway = SimGateway()
    try:
        gateway.send(gateway.mav.command_long_encode(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0))
        gateway.send(gateway.mav.set_mode_encode(1, 1, 2))
        gateway.run(3.0)
        gateway.send(gateway.mav.set_mode_encode(1, 1, 4))
        gateway.run(3.0)
        reported = gateway.last("LOCAL_POSITION_NED")
        position = (reported.x, reported.y, reported.z)
        for _ in range(2):
            gateway.send(
                gateway.mav.set_position_target_local_ned_encode(
                    0, 1, 1, 1, YAW_AND_RATE, *position, 0, 0, 0, 0, 0, 0, math.radians(90), 0.2
                )
            )
            gateway.run(0.5)
        gateway.run(8.0)
        gotos = [o for o in gateway.orders if isinstance(o, GoTo)]
        assert gotos[-1].heading == 90
        heading = math.degrees(euler_from_quat(gateway.vehicle.truth.quaternion_wxyz)[2])
        assert off_deg(heading, 90.0) < HEADING_TOLERANCE_DEG
        texts = [m.text for m in gateway.messages if m.get_type() == "STATUSTEXT"]
        assert texts.count("Yaw rates do not cross the link") == 1
        assert "yaw_rate" in gateway.endpoint.setpoints_not_sent
    finally:
        gateway.vehicle.close()
