"""The pilot's yaw stick in GUIDED, as ArduSub 4.5 flies it, through the sans-IO endpoint with
pymavlink as the ground station, in simulated time, judged by the ATTITUDE pymavlink decodes and
the physics truth.

Independent truth: ArduSub 4.5's source, restated here — ``mode_guided.cpp``
``guided_pos_control_run`` (and the velocity and position-velocity runs): unless
``failsafe.pilot_input``, ``target_yaw_rate = get_pilot_desired_yaw_rate(channel_yaw->
get_control_in())``; not zero → ``AUTO_YAW_HOLD``, the attitude target turned at that rate
(``input_euler_angle_roll_pitch_euler_rate_yaw``) while the waypoint controller holds the
position; zero → ``AUTO_YAW_LOOK_AT_HEADING`` (``AUTO_YAW_RATE`` when rate-only), so the
look-at heading comes back at its slew. ``Attitude.cpp``: ``get_pilot_desired_yaw_rate`` =
``stick_angle * g.acro_yaw_p`` [cd/s]; ``config.h`` ACRO_YAW_P 3.375 (``Parameters.cpp``: range
1–10), ``ROLL_PITCH_INPUT_MAX`` 4500; ``radio.cpp`` ``channel_yaw->set_angle(4500)``,
``set_default_dead_zone(40)``; ``RC_Channel::pwm_to_angle_dz_trim``: ``4500 × (pwm − 1540) /
(1900 − 1540)`` above the dead zone (RCn_MIN/TRIM/MAX 1100/1500/1900); ``joystick.cpp``: a
MANUAL_CONTROL ``r`` is ``1500 + r × 0.4 × gain`` µs (gain 0.5 at boot). So ``r`` = 500 is
1600 µs, 750, 25.3125°/s; 1400 µs is −750, −25.3125°/s; 1530 µs is in the dead zone, 0.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from pymavlink.dialects.v20 import ardupilotmega as mav

from testbed.common.geometry import euler_from_quat
from tests.mavlink.gcs import SimGateway, SimGcs

YAW = 0b1001_1111_1000  # a position, the yaw used, the yaw rate ignored
ACRO_YAW_P = 3.375  # ArduSub's config.h default
RATE_TOLERANCE_DEG_S = 0.5
"""The turn rate the ground station measures may differ from ArduSub's by this much [°/s]: the
endpoint advances the heading target at exactly the pilot's rate each update, and the vehicle's
heading hold (a PID with an integral) follows a ramp with a constant lag, so the slope of
ATTITUDE's yaw over 3 s after the first second is the rate up to the hold's ripple (measured
within 0.1°/s). The nearest wrong answers are ≥ 8°/s away: no dead zone (1600 µs read as 100 of
400 µs: 37.97°/s), Copter's ACRO_YAW_P 4.5 (33.75°/s), the stick ignored (0)."""
HELD_M = 0.05
"""How far from the position target the vehicle may stray while the pilot turns it [m]: the
position loop's hold (the fix's 5-mm noise; measured 3 mm)."""
HEADING_TOLERANCE_DEG = 3.0  # the heading hold's settling (test_guided_yaw.py)


def heading_deg(gcs: SimGcs) -> float:
    """The truth's heading [deg, (−180, 180]]."""
    return math.degrees(euler_from_quat(gcs.vehicle.truth.quaternion_wxyz)[2])


def off_deg(a: float, b: float) -> float:
    return abs(math.remainder(a - b, 360.0))


def held_north(gcs: SimGcs) -> tuple[float, float, float]:
    """GUIDED, a position target where the vehicle is with a yaw of 0 (north: the look-at
    heading, slewed to at 60°/s); settled. The target [m, NED]."""
    gcs.enter_guided()
    p = gcs.vehicle.truth.position_ned_m
    here = (float(p[0]), float(p[1]), float(p[2]))
    gcs.send(
        gcs.mav.set_position_target_local_ned_encode(
            0, 1, 1, mav.MAV_FRAME_LOCAL_NED, YAW, *here, 0, 0, 0, 0, 0, 0, 0.0, 0.0
        )
    )
    gcs.run(4.0, gcs.flying())
    assert off_deg(heading_deg(gcs), 0.0) < HEADING_TOLERANCE_DEG
    return here


def turn_rate_deg_s(gcs: SimGcs, seconds: float, each: Callable[[int], list[Any]]) -> float:
    """Fly ``seconds`` with ``each``'s messages; the slope of ATTITUDE's yaw [°/s] from 1 s in
    (the ground station's view)."""
    gcs.clear()
    gcs.run(seconds, each)
    attitude = gcs.of("ATTITUDE")
    t = np.array([m.time_boot_ms / 1000.0 for m in attitude])
    yaw = np.unwrap([m.yaw for m in attitude])
    late = t >= t[0] + 1.0
    assert late.sum() >= 20  # 10 Hz (SR0_EXTRA1) for the 3 s after the first
    return math.degrees(float(np.polyfit(t[late], yaw[late], 1)[0]))


def sticks(gcs: SimGcs, r: int) -> Callable[[int], list[Any]]:
    """MANUAL_CONTROL with yaw ``r`` at 25 Hz, a heartbeat at 1 Hz."""

    def each(k: int) -> list[Any]:
        out = [gcs.sticks(r=r)] if k % 4 == 0 else []
        return out + ([gcs.heartbeat()] if k % 100 == 0 else [])

    return each


def overrides(gcs: SimGcs, chan4_us: int) -> Callable[[int], list[Any]]:
    """RC_CHANNELS_OVERRIDE with channel 4 at ``chan4_us`` (the others ignored) at 25 Hz, a
    heartbeat at 1 Hz."""
    ignored = [65535] * 18
    ignored[3] = chan4_us

    def each(k: int) -> list[Any]:
        out = [gcs.mav.rc_channels_override_encode(1, 1, *ignored)] if k % 4 == 0 else []
        return out + ([gcs.heartbeat()] if k % 100 == 0 else [])

    return each


def expected_deg_s(pwm_us: int, acro_yaw_p: float = ACRO_YAW_P) -> float:
    """ArduSub's pilot yaw rate [°/s] for a channel-4 pulse, restated: ``pwm_to_angle_dz_trim``
    with min 1100, trim 1500, max 1900, dead zone 40 (int32, truncated toward zero), ×
    ACRO_YAW_P [cd/s]."""
    if pwm_us > 1540:
        control_in = int(4500 * (pwm_us - 1540) / (1900 - 1540))
    elif pwm_us < 1460:
        control_in = int(4500 * (pwm_us - 1460) / (1460 - 1100))
    else:
        control_in = 0
    return control_in * acro_yaw_p / 100.0


@pytest.mark.parametrize(
    ("how", "value", "acro_yaw_p"),
    [
        ("manual_control", 500, None),  # 1600 µs: 25.3125°/s
        ("override", 1400, None),  # −25.3125°/s, the other way
        ("override", 1530, None),  # inside RC4_DZ: no turn
        ("manual_control", 500, 6.75),  # ACRO_YAW_P doubled: 50.625°/s
    ],
)
def test_the_yaw_stick_turns_the_vehicle_at_ardusubs_rate_and_the_position_is_held(
    gcs: SimGcs, how: str, value: int, acro_yaw_p: float | None
) -> None:
    here = held_north(gcs)
    if acro_yaw_p is not None:
        gcs.send(gcs.param_set("ACRO_YAW_P", acro_yaw_p))
    each = sticks(gcs, value) if how == "manual_control" else overrides(gcs, value)
    pwm = 1500 + round(value * 0.4 * 0.5) if how == "manual_control" else value
    expected = expected_deg_s(pwm, acro_yaw_p or ACRO_YAW_P)
    measured = turn_rate_deg_s(gcs, 4.0, each)
    assert abs(measured - expected) < RATE_TOLERANCE_DEG_S, (measured, expected)
    strayed = math.dist(gcs.vehicle.truth.position_ned_m[:2], here[:2])
    assert strayed < HELD_M


def test_the_look_at_heading_comes_back_when_the_stick_is_centred(gcs: SimGcs) -> None:
    """ArduSub leaves AUTO_YAW_HOLD the loop the stick reads 0: the look-at heading (north) is
    slewed back to at 60°/s (AUTO_YAW_SLEW_RATE), within 5° held."""
    held_north(gcs)
    gcs.run(4.0, sticks(gcs, 500))
    away = heading_deg(gcs)
    assert off_deg(away, 0.0) > 90.0  # turned ≈ 100° at 25.3°/s
    gcs.run(off_deg(away, 0.0) / 60.0 + 1.5, gcs.flying())  # the slew, and the hold's settling
    assert off_deg(heading_deg(gcs), 0.0) < HEADING_TOLERANCE_DEG


def test_under_the_pilot_input_failsafe_the_heading_stays_where_the_pilot_left_it(
    gcs: SimGcs,
) -> None:
    """FS_PILOT_INPUT 1 (warn): the failsafe centres the sticks, and ArduSub's GUIDED then skips
    the pilot's block, so ``auto_yaw_mode`` stays HOLD at a rate of 0: no turn back north
    (without the failsafe the centred stick would bring the look-at heading back)."""
    gcs.send(gcs.param_set("FS_PILOT_INPUT", 1))
    held_north(gcs)
    gcs.run(3.0, sticks(gcs, 500))
    gcs.run(3.5, lambda k: [gcs.heartbeat()] if k % 100 == 0 else [])  # FS_PILOT_TIMEOUT 3 s
    assert "Lost manual control" in [m.text for m in gcs.of("STATUSTEXT")]
    left = heading_deg(gcs)
    gcs.run(5.0, lambda k: [gcs.heartbeat()] if k % 100 == 0 else [])
    assert off_deg(heading_deg(gcs), left) < HEADING_TOLERANCE_DEG
    assert off_deg(left, 0.0) > 60.0


def test_through_the_gateway_the_pilot_yaw_in_guided_is_said_not_to_cross() -> None:
    """The shore flies no moving heading (a ``GoTo`` every token gap) and the vehicle's GUIDED
    ignores a ``Move``'s sticks: it says so once and notes ``pilot_yaw``."""
    gateway = SimGateway()
    gateway.send(gateway.mav.command_long_encode(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0))
    gateway.send(gateway.mav.set_mode_encode(1, 1, 2))
    gateway.run(3.0)
    gateway.send(gateway.mav.set_mode_encode(1, 1, 4))
    gateway.run(3.0)
    gateway.yaw_r = 500
    gateway.run(2.0)
    texts = [m.text for m in gateway.messages if m.get_type() == "STATUSTEXT"]
    assert texts.count("Pilot yaw in GUIDED does not cross the link") == 1
    assert "pilot_yaw" in gateway.endpoint.setpoints_not_sent
