"""WP_YAW_BEHAVIOR and GUIDED's entry yaw as ArduSub 4.5 has them, pymavlink as the ground
station, in simulated time, judged by the physics truth's heading.

Independent truth: ArduSub restated from its source, not from the endpoint's code —
``ArduSub/config.h`` (WP_YAW_BEHAVIOR_DEFAULT = WP_YAW_BEHAVIOR_CORRECT_XTRACK, 4) and
``Parameters.cpp`` (``GSCALAR(wp_yaw_behavior, "WP_YAW_BEHAVIOR", WP_YAW_BEHAVIOR_DEFAULT)``,
XTRACK_ANG_LIM 45); ``mode_guided.cpp``: ``guided_pos_control_start`` (entering GUIDED) clears
``yaw_rate_only`` and sets ``get_default_auto_yaw_mode(false)`` (0 HOLD, 4 CORRECT_XTRACK);
``guided_pos_control_run`` replaces that mode each loop unless the pilot-input failsafe is
active (then HOLD turns at the pilot's rate, 0, and CORRECT_XTRACK flies
``get_auto_heading``: the bearing from ``wp_nav``'s origin to its destination, both the
stopping point at entry — ``AC_WPNav::wp_and_spline_init``, ``set_wp_destination`` — so a
zero-length track, ``get_bearing_cd`` = atan2(0, 0) = 0°, north; a later destination makes
the old one the origin).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mav

from testbed.common.geometry import euler_from_quat
from testbed.mavlink.telemetry import global_from_local
from tests.mavlink.gcs import SimGcs

RATE_ONLY = 0b0101_1111_1000  # a position, the yaw ignored, the yaw rate used
YAW = 0b1001_1111_1000  # a position, the yaw used, the yaw rate ignored
HEADING_TOLERANCE_DEG = 3.0  # the heading hold's settling (test_guided_yaw.py)


def heading_deg(gcs: SimGcs) -> float:
    return math.degrees(euler_from_quat(gcs.vehicle.truth.quaternion_wxyz)[2])


def off_deg(a: float, b: float) -> float:
    return abs(math.remainder(a - b, 360.0))


def here(gcs: SimGcs) -> tuple[float, float, float]:
    p = gcs.vehicle.truth.position_ned_m
    return (float(p[0]), float(p[1]), float(p[2]))


def local_target(gcs: SimGcs, mask: int, yaw: float, yaw_rate: float) -> Any:
    return gcs.mav.set_position_target_local_ned_encode(
        0, 1, 1, mav.MAV_FRAME_LOCAL_NED, mask, *here(gcs), 0, 0, 0, 0, 0, 0, yaw, yaw_rate
    )


def heartbeats_only(gcs: SimGcs) -> Callable[[int], list[Any]]:
    """A heartbeat a second and no sticks: the pilot-input failsafe's condition."""
    return lambda k: [gcs.heartbeat()] if k % 100 == 0 else []


def read_param(gcs: SimGcs, name: str) -> float:
    gcs.send(gcs.mav.param_request_read_encode(1, 1, name.encode(), -1))
    gcs.run(0.05)
    values = [m for m in gcs.of("PARAM_VALUE") if m.param_id == name]
    assert values, name
    return float(values[-1].param_value)


def test_the_default_is_ardusubs_correct_xtrack(gcs: SimGcs) -> None:
    """WP_YAW_BEHAVIOR boots at ArduSub's WP_YAW_BEHAVIOR_DEFAULT, 4 (it was 0), and
    XTRACK_ANG_LIM at 45."""
    assert read_param(gcs, "WP_YAW_BEHAVIOR") == 4.0
    assert read_param(gcs, "XTRACK_ANG_LIM") == 45.0


def _guided_under_the_pilot_failsafe(gcs: SimGcs, behaviour: int) -> None:
    """FS_PILOT_INPUT 1 (warn only) and WP_YAW_BEHAVIOR ``behaviour``; GUIDED facing east
    (a look-at heading of 90°), then ALT_HOLD, the sticks let go until the failsafe, and GUIDED
    entered again under it."""
    gcs.send(gcs.param_set("FS_PILOT_INPUT", 1), gcs.param_set("WP_YAW_BEHAVIOR", behaviour))
    gcs.enter_guided()
    gcs.send(local_target(gcs, YAW, math.radians(90.0), 0.0))
    gcs.run(6.0, gcs.flying())
    assert off_deg(heading_deg(gcs), 90.0) < HEADING_TOLERANCE_DEG
    gcs.send(gcs.set_mode(2))
    gcs.run(1.0, gcs.flying())
    gcs.clear()
    gcs.run(4.0, heartbeats_only(gcs))  # FS_PILOT_TIMEOUT 3 s without sticks
    assert "Lost manual control" in [m.text for m in gcs.of("STATUSTEXT")]
    assert gcs.endpoint.failsafe.pilot_input and gcs.last("HEARTBEAT").base_mode & 128
    assert off_deg(heading_deg(gcs), 90.0) < HEADING_TOLERANCE_DEG  # ALT_HOLD kept it
    gcs.send(gcs.set_mode(4))
    gcs.run(5.0, heartbeats_only(gcs))
    assert gcs.last("HEARTBEAT").custom_mode == 4


def test_entered_under_the_pilot_failsafe_correct_xtrack_points_along_the_track(
    gcs: SimGcs,
) -> None:
    """WP_YAW_BEHAVIOR 4: GUIDED entered under the failsafe flies CORRECT_XTRACK, whose track
    is zero-length at entry — north, not the look-at heading of 90° it kept before; a
    DO_REPOSITION 4 m east makes a track from the hold point eastward, and the vehicle turns
    along it."""
    _guided_under_the_pilot_failsafe(gcs, 4)
    assert off_deg(heading_deg(gcs), 0.0) < HEADING_TOLERANCE_DEG
    north, east, depth = here(gcs)
    lat, lon = global_from_local(north, east + 4.0)
    gcs.send(
        gcs.mav.command_int_encode(
            1, 1, 6, mav.MAV_CMD_DO_REPOSITION, 0, 0, -1, 0, 0, math.nan,
            round(lat * 1e7), round(lon * 1e7), -depth,
        )
    )  # fmt: skip
    gcs.run(3.0, heartbeats_only(gcs))
    assert off_deg(heading_deg(gcs), 90.0) < 10.0  # the track's bearing, ± the correction
    assert here(gcs)[1] > east + 0.5  # flying it


def test_entered_under_the_pilot_failsafe_hold_keeps_the_heading(gcs: SimGcs) -> None:
    """WP_YAW_BEHAVIOR 0: GUIDED entered under the failsafe is in HOLD, at the pilot's rate of
    0: the heading stays at 90°; once the sticks are back, the loop picks the look-at heading
    (90° too) and keeps it."""
    _guided_under_the_pilot_failsafe(gcs, 0)
    assert off_deg(heading_deg(gcs), 90.0) < HEADING_TOLERANCE_DEG
    gcs.run(3.0, gcs.flying())
    assert not gcs.endpoint.failsafe.pilot_input
    assert off_deg(heading_deg(gcs), 90.0) < HEADING_TOLERANCE_DEG


def test_entering_guided_ends_a_yaw_rate_alone(gcs: SimGcs) -> None:
    """``guided_pos_control_start`` clears ``yaw_rate_only``: a vehicle turning at a yaw rate
    alone (0.3 rad/s, 17°/s), taken to ALT_HOLD and back to GUIDED, turns to the look-at
    heading it never set (north, from boot) at the last slew and stops there, rather than
    turning for ever."""
    gcs.enter_guided()
    gcs.send(local_target(gcs, RATE_ONLY, 0.0, 0.3))
    gcs.run(3.0, gcs.flying())
    gcs.send(gcs.set_mode(2))
    gcs.run(1.0, gcs.flying())
    gcs.send(gcs.set_mode(4))
    gcs.run(360.0 / 17.0 + 1.0, gcs.flying())  # at most a turn at 17°/s
    assert off_deg(heading_deg(gcs), 0.0) < HEADING_TOLERANCE_DEG
    before = heading_deg(gcs)
    gcs.run(2.0, gcs.flying())
    assert off_deg(heading_deg(gcs), before) < 1.0
