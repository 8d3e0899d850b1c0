"""GUIDED's heading as ArduSub 4.5 flies it: SET_POSITION_TARGET_LOCAL_NED's ``yaw`` and
``yaw_rate``, and the auto-yaw state they leave behind.

**The message** (ArduSub 4.5 ``GCS_MAVLINK_Sub::handle_message``): ``yaw`` [rad] is used unless
``type_mask`` has bit 1024 (YAW_IGNORE), ``yaw_rate`` [rad/s] unless bit 2048
(YAW_RATE_IGNORE). The yaw is relative (``yaw_relative``) in MAV_FRAME_BODY_OFFSET_NED only: in
BODY_NED and BODY_FRD, whose position and velocity are along the heading, and in LOCAL_NED and
LOCAL_OFFSET_NED, it is a heading from north. Then ``ModeGuided::guided_set_yaw_state``:

- yaw used: ``ModeAuto::set_auto_yaw_look_at_heading``. The look-at heading
  (``yaw_look_at_heading``, int32 centidegrees in [0, 36000)) is the yaw, or, relative, the
  attitude target's yaw plus the yaw, or minus it when ArduSub's ``direction`` is negative.
  That direction is the sign of ``wrap_PI(wrap_2PI(yaw in degrees) − heading)``: the yaw in
  degrees wrapped as if it were radians (``euler_yaw_angle = wrap_2PI(yaw_cd * 0.01f)``), so it
  is no turning direction, and a relative yaw turns one way or the other by the present
  heading (:func:`ardusub_direction`; +0.5 rad turns +28.6° facing east, −28.6° facing
  north). The slew (``yaw_look_at_heading_slew``, int16 °/s) is AUTO_YAW_SLEW_RATE (60°/s)
  without a yaw rate (or a rate of 0), else min(rate, 60°/s) truncated toward 0. Not rate-only.
- yaw rate alone: ``ModeAuto::set_yaw_rate``: slew = min(rate, 60°/s), truncated; rate-only.
- neither: not rate-only, auto-yaw HOLD (the look-at heading and the slew stay as they were;
  the next loop leaves HOLD, below, unless the pilot-input failsafe is active).

That state is ArduSub's (``Sub.h``): kept across messages and modes, from boot (look-at 0°,
north; slew 0). GUIDED's other targets (SET_POSITION_TARGET_GLOBAL_INT, DO_REPOSITION, the hold
on entering GUIDED) do not touch it.

**Entering GUIDED** (``ModeGuided::init`` → ``guided_pos_control_start``) clears
``yaw_rate_only`` and sets the auto-yaw mode WP_YAW_BEHAVIOR names
(``get_default_auto_yaw_mode(false)``: 0 HOLD, 1 and 2 LOOK_AT_NEXT_WP, 3 LOOK_AHEAD, 4
CORRECT_XTRACK — ArduSub's default, ``config.h`` WP_YAW_BEHAVIOR_DEFAULT). The first loop
below replaces that mode, so it only steers while the pilot-input failsafe (FS_PILOT_INPUT 1,
warn only) keeps the loop from choosing, and until a SET_POSITION_TARGET_LOCAL_NED sets the
yaw state. Then CORRECT_XTRACK (``get_auto_heading``) points along the track from ``wp_nav``'s
origin to its destination (``get_bearing_cd``; at entry both are the stopping point, a
zero-length track whose bearing is 0°, north; a SET_POSITION_TARGET_GLOBAL_INT or DO_REPOSITION
makes the old destination the origin, ``AC_WPNav::set_wp_destination``), turned toward the
position controller's target velocity by at most XTRACK_ANG_LIM (45°) when that velocity is
at least 10 % of the top speed (here the vehicle's loop's demand stands for it, as for
HIGH_LATENCY2's ``airspeed_sp``); HOLD keeps the heading (the pilot's rate is 0). 1, 2 and 3
keep the heading here too: ArduSub's ``wp_nav`` yaw (the attitude target's until its S-curve
flies a leg of 2 m or more) and look-ahead follow its path planner's velocity, which this
vehicle has none of (docs/mavlink.md, "Not yet").

**Each loop** of GUIDED's position, velocity and position-velocity controllers
(``mode_guided.cpp`` ``guided_pos_control_run``, ``guided_vel_control_run``,
``guided_posvel_control_run``; not the angle controller's, which has no pilot yaw), unless the
pilot-input failsafe is active, the pilot's yaw stick picks the auto-yaw mode first: its desired
rate (``Sub::get_pilot_desired_yaw_rate``: RC channel 4's ``control_in`` ×
ACRO_YAW_P [centidegrees/s], :func:`pilot_yaw_rate_rad_s`) not zero → ``AUTO_YAW_HOLD``, else
``AUTO_YAW_RATE`` when rate-only, else ``AUTO_YAW_LOOK_AT_HEADING``. Under the pilot-input
failsafe the mode stays as it was and the pilot's rate is 0. Then the attitude target's yaw:

- HOLD (``input_euler_angle_roll_pitch_euler_rate_yaw``): turns at the pilot's rate. The
  position target is flown meanwhile; the look-at heading and the slew are kept, so once the
  stick is centred the next mode takes over from the heading the pilot left: the vehicle turns
  back to the look-at heading at the slew (within 5°: at once), or, rate-only, turns at it
  again;
- rate-only (``AUTO_YAW_RATE``): turns at the slew, for ever (no timeout in 4.5);
- else (``AUTO_YAW_LOOK_AT_HEADING``, ``AC_AttitudeControl_Sub::input_euler_angle_roll_pitch_
  slew_yaw``): while the heading is more than MAX_YAW_ERROR (5°) from the look-at heading, turns
  toward it the short way at the slew (a negative slew, from a negative ``yaw_rate``, turns
  away from it: the long way round); within 5° it is the look-at heading. So a slew of 0 — no
  yaw since boot, or a rate under 1°/s — keeps the heading, but takes the look-at heading
  (north, at boot) when the vehicle is within 5° of it; and a later target that ignores the yaw
  turns the vehicle back to the last look-at heading, at the last slew.

Here: :class:`AutoYaw` holds that state on the endpoint, the pilot's stick read from the RC
inputs each update (MANUAL_CONTROL's ``r`` as ``joystick.cpp`` scales it, or
RC_CHANNELS_OVERRIDE's channel 4; RC4_MIN/TRIM/MAX/DZ/REVERSED as ``RC_Channel`` reads them). In
GUIDED, not under a SET_ATTITUDE_TARGET's angle control, each update moves the heading of
GUIDED's
:class:`~testbed.common.components.PositionSetpoint` as ArduSub moves its attitude target (the
vehicle's heading hold follows it; it turns at up to ≈ 100°/s, faster than the 60°/s slew).
Through a gateway (no moving targets: a heading changing every update would be a ``GoTo``
every token gap) a setpoint carries the heading the state settles at (:func:`settled_heading_rad`):
the look-at heading, which the vehicle turns to at its own rate, or none (the heading kept);
a yaw rate does not cross (STATUSTEXT once "Yaw rates do not cross the link", noted
``yaw_rate``), nor does the pilot's yaw stick in GUIDED (the vehicle's GUIDED ignores the
sticks a ``Move`` carries; STATUSTEXT once "Pilot yaw in GUIDED does not cross the link", noted
``pilot_yaw``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from testbed.common.components import ControlMode, ControlTargets, PositionSetpoint
from testbed.common.geometry import euler_from_quat
from testbed.common.velocity_demand import velocity_demand_ne
from testbed.mavlink.ardusub import rc_angle

if TYPE_CHECKING:
    from testbed.mavlink.endpoint import VehicleEndpoint

__all__ = [
    "AUTO_YAW_SLEW_RATE_DEG_S",
    "MAX_YAW_ERROR_RAD",
    "WP_YAW_BEHAVIOR_CORRECT_XTRACK",
    "WP_YAW_BEHAVIOR_NONE",
    "AutoYaw",
    "ardusub_direction",
    "held_yaw_rad",
    "new_destination",
    "pilot_yaw_rate_rad_s",
    "set_yaw_state",
    "setpoint_heading",
    "settled_heading_rad",
    "start_position_control",
    "update_auto_yaw",
    "xtrack_heading_rad",
    "yaw_rate_fits",
]

AUTO_YAW_SLEW_RATE_DEG_S = 60
"""ArduSub's AUTO_YAW_SLEW_RATE (``config.h``): the default and greatest slew [°/s]."""
MAX_YAW_ERROR_RAD = math.radians(5.0)
"""``AC_AttitudeControl_Sub.h`` MAX_YAW_ERROR: within this of the look-at heading it is held
rather than slewed to [rad]."""
WP_YAW_BEHAVIOR_NONE = 0
"""WP_YAW_BEHAVIOR 0 (``defines.h``): GUIDED entered in auto-yaw HOLD."""
WP_YAW_BEHAVIOR_CORRECT_XTRACK = 4
"""WP_YAW_BEHAVIOR 4, ArduSub's default: GUIDED entered in auto-yaw CORRECT_XTRACK."""
_XTRACK_MIN_SPEED_FRACTION = 0.1
"""``get_auto_heading``: the target velocity turns the heading from the track only from this
fraction of the top speed on."""
_INT16_MIN = -32768
_FLT_EPSILON = 1.1920929e-07  # ArduPilot's is_zero: |x| < FLT_EPSILON


@dataclass(slots=True)
class AutoYaw:
    """ArduSub's auto-yaw state, and the yaw target GUIDED flies from it (mutable: the
    endpoint's state; module docstring).

    Attributes:
        look_at_cd: ``yaw_look_at_heading`` [centidegrees, 0..35999, from north].
        slew_deg_s: ``yaw_look_at_heading_slew`` [°/s, int16].
        rate_only: ``yaw_rate_only``: turn at the slew.
        pilot_hold: ``auto_yaw_mode`` is ``AUTO_YAW_HOLD``: the pilot's yaw stick turns the
            heading (module docstring).
        target_rad: the heading the endpoint has GUIDED fly [rad] (ArduSub's attitude target
            yaw), None when GUIDED does not fly one (another mode, angle control).
        updated_s: the time ``target_rad`` was advanced to [s] (None: not yet, it starts at
            the next update).
        xtrack: ``auto_yaw_mode`` is CORRECT_XTRACK, as entering GUIDED with WP_YAW_BEHAVIOR 4
            left it and no loop or message has changed it since (module docstring).
        track_ne: ``wp_nav``'s origin and destination, north and east [m] (None before any
            GUIDED target).
    """

    look_at_cd: int = 0
    slew_deg_s: int = 0
    rate_only: bool = False
    pilot_hold: bool = False
    target_rad: float | None = None
    updated_s: float | None = None
    xtrack: bool = False
    track_ne: tuple[tuple[float, float], tuple[float, float]] | None = None

    @property
    def look_at_rad(self) -> float:
        """The look-at heading [rad, in (−π, π]]."""
        return math.remainder(math.radians(self.look_at_cd / 100.0), math.tau)


def _wrap_2pi(angle: float) -> float:
    return math.fmod(angle, math.tau) % math.tau


def _wrap_pi(angle: float) -> float:
    """ArduPilot's ``wrap_PI``: (−π, π]."""
    wrapped = _wrap_2pi(angle)
    return wrapped - math.tau if wrapped > math.pi else wrapped


def ardusub_direction(yaw_deg: float, heading_rad: float) -> int:
    """``guided_set_yaw_state``'s ``direction`` (module docstring): ±1 by the sign of
    ``wrap_PI(wrap_2PI(yaw_deg) − wrap_2PI(heading_rad))``, the degrees wrapped as radians."""
    return -1 if _wrap_pi(_wrap_2pi(yaw_deg) - _wrap_2pi(heading_rad)) < 0.0 else 1


def held_yaw_rad(endpoint: VehicleEndpoint) -> float:
    """The attitude target's yaw [rad]: the one GUIDED flies, else the vehicle's heading hold's
    (its ``ControlTargets``), else the reported heading (a gateway sees no targets)."""
    state = endpoint.auto_yaw
    if state.target_rad is not None:
        return state.target_rad
    targets = endpoint.world.get(endpoint.vehicle, ControlTargets)
    if targets is not None:
        return euler_from_quat(targets.quaternion_wxyz)[2]
    return endpoint.snapshot_now().euler_rad[2]


def set_yaw_state(
    endpoint: VehicleEndpoint,
    yaw_rad: float | None,
    yaw_rate_rad_s: float | None,
    relative: bool,
) -> None:
    """ArduSub's ``guided_set_yaw_state`` for an accepted target (module docstring).

    Args:
        endpoint: the endpoint.
        yaw_rad: the message's yaw [rad], None when masked.
        yaw_rate_rad_s: its yaw rate [rad/s] (:func:`yaw_rate_fits`), None when masked.
        relative: the frame makes the yaw relative (MAV_FRAME_BODY_OFFSET_NED).
    """
    state = endpoint.auto_yaw
    state.xtrack = False  # every branch sets a mode (look-at heading, rate, HOLD)
    rate_dps = None if yaw_rate_rad_s is None else math.degrees(yaw_rate_rad_s)
    turning = rate_dps is not None and abs(rate_dps) >= _FLT_EPSILON  # ArduPilot's !is_zero
    slew = 0 if rate_dps is None else int(min(rate_dps, AUTO_YAW_SLEW_RATE_DEG_S))
    if yaw_rad is not None:
        yaw_deg = math.degrees(yaw_rad)
        if relative:
            if ardusub_direction(yaw_deg, endpoint.snapshot_now().euler_rad[2]) < 0:
                yaw_deg = -yaw_deg
            yaw_deg += math.degrees(held_yaw_rad(endpoint))
        state.look_at_cd = int(math.fmod(yaw_deg * 100.0, 36000.0) % 36000.0)
        state.slew_deg_s = slew if turning else AUTO_YAW_SLEW_RATE_DEG_S
        state.rate_only = False
    elif rate_dps is not None:
        state.slew_deg_s, state.rate_only = slew, True
    else:
        state.rate_only, state.pilot_hold = False, True  # ArduSub: set_auto_yaw_mode(HOLD)
    if turning and not endpoint.flies_moving_targets:
        endpoint.setpoint_not_sent("yaw_rate", "Yaw rates do not cross the link")


def yaw_rate_fits(yaw_rate_rad_s: float) -> bool:
    """Whether ArduSub's int16 °/s slew holds the yaw rate once limited to 60°/s (a finite
    rate no lower than −32768°/s; below, its float conversion is undefined: counted
    ``bad_field``)."""
    return math.isfinite(yaw_rate_rad_s) and math.degrees(yaw_rate_rad_s) >= _INT16_MIN


def pilot_yaw_rate_rad_s(endpoint: VehicleEndpoint) -> float:
    """The pilot's desired yaw rate [rad/s, clockwise from above] (ArduSub's
    ``get_pilot_desired_yaw_rate(channel_yaw->get_control_in())``): RC channel 4's
    ``control_in`` (:func:`~testbed.mavlink.ardusub.rc_angle` with RC4_MIN, RC4_TRIM, RC4_MAX,
    RC4_DZ, RC4_REVERSED) × ACRO_YAW_P [centidegrees/s]. At the default gain 0.5 a MANUAL_CONTROL
    ``r`` of 500 is 1600 µs, ``control_in`` 750, 750 × 3.375 = 25.3°/s."""
    p = endpoint.params
    control_in = rc_angle(
        endpoint.rc.channels[3],
        minimum=int(p["RC4_MIN"]),
        trim=int(p["RC4_TRIM"]),
        maximum=int(p["RC4_MAX"]),
        dead_zone=int(p["RC4_DZ"]),
        reversed_=bool(p["RC4_REVERSED"]),
    )
    return math.radians(control_in * p["ACRO_YAW_P"] / 100.0)


def _pilot_turn(endpoint: VehicleEndpoint) -> float:
    """Each GUIDED loop: the pilot's rate [rad/s] picks the auto-yaw mode (module docstring),
    HOLD while it is not zero; 0 and the mode kept under the pilot-input failsafe."""
    state = endpoint.auto_yaw
    if endpoint.failsafe.pilot_input:
        return 0.0
    rate = pilot_yaw_rate_rad_s(endpoint)
    state.pilot_hold = abs(rate) >= math.radians(_FLT_EPSILON / 100.0)  # !is_zero, in cd/s
    state.xtrack = False  # the loop chose HOLD, RATE or LOOK_AT_HEADING
    return rate


def start_position_control(
    endpoint: VehicleEndpoint, hold_ned_m: tuple[float, float, float]
) -> None:
    """Entering GUIDED (``guided_pos_control_start``): not rate-only, the auto-yaw mode
    WP_YAW_BEHAVIOR names, ``wp_nav``'s origin and destination both the hold point
    ``hold_ned_m`` [m, NED] (module docstring)."""
    state = endpoint.auto_yaw
    behaviour = int(endpoint.params["WP_YAW_BEHAVIOR"])
    state.rate_only = False
    state.xtrack = behaviour == WP_YAW_BEHAVIOR_CORRECT_XTRACK
    state.pilot_hold = not state.xtrack  # HOLD (0); 1, 2, 3 keep the heading too, here
    state.track_ne = (hold_ned_m[0], hold_ned_m[1]), (hold_ned_m[0], hold_ned_m[1])


def new_destination(endpoint: VehicleEndpoint, position_ned_m: tuple[float, float, float]) -> None:
    """A GUIDED position target: ``wp_nav``'s previous destination becomes its origin
    (``AC_WPNav::set_wp_destination``)."""
    state = endpoint.auto_yaw
    destination = (position_ned_m[0], position_ned_m[1])
    origin = destination if state.track_ne is None else state.track_ne[1]
    state.track_ne = origin, destination


def xtrack_heading_rad(endpoint: VehicleEndpoint) -> float:
    """CORRECT_XTRACK's heading [rad, from north] (``ModeGuided::get_auto_heading``): the
    track's bearing (0 for a zero-length track), turned toward the target velocity's — here
    the vehicle's loop's demand toward the destination — by at most XTRACK_ANG_LIM when that
    speed is at least 10 % of the loop's top speed."""
    state = endpoint.auto_yaw
    if state.track_ne is None:
        return held_yaw_rad(endpoint)
    (on, oe), (dn, de) = state.track_ne
    track = _wrap_2pi(math.atan2(de - oe, dn - on))  # get_bearing_rad: atan2(0, 0) = 0
    error = 0.0
    loop = endpoint.options.guided_loop
    if loop is not None:
        north, east, _ = endpoint.snapshot_now().position_ned_m
        vn, ve = velocity_demand_ne((dn - north, de - east), loop.gain_1_s, loop.max_speed_m_s)
        if math.hypot(vn, ve) >= _XTRACK_MIN_SPEED_FRACTION * loop.max_speed_m_s:
            error = _wrap_pi(math.atan2(ve, vn) - track)
    limit = math.radians(endpoint.params["XTRACK_ANG_LIM"])
    return track + max(-limit, min(limit, error))


def settled_heading_rad(endpoint: VehicleEndpoint) -> float | None:
    """Where the state leaves the heading [rad]: none while rate-only (it turns for ever) or
    with a slew of 0 more than 5° from the look-at heading (it stays), else the look-at
    heading."""
    state = endpoint.auto_yaw
    if state.rate_only:
        return None
    look = state.look_at_rad
    error = _wrap_pi(look - endpoint.snapshot_now().euler_rad[2])
    if state.slew_deg_s == 0 and abs(error) > MAX_YAW_ERROR_RAD:
        return None
    return look


def setpoint_heading(endpoint: VehicleEndpoint) -> float | None:
    """The heading [rad] GUIDED's position setpoint carries now (None: keep the present one):
    the yaw target the endpoint moves (started at the attitude target's yaw), or through a
    gateway the settled heading (module docstring)."""
    if not endpoint.flies_moving_targets:
        return settled_heading_rad(endpoint)
    state = endpoint.auto_yaw
    if state.target_rad is None:
        state.target_rad, state.updated_s = held_yaw_rad(endpoint), None
    return state.target_rad


def update_auto_yaw(endpoint: VehicleEndpoint, now_s: float) -> None:
    """Each update in GUIDED, not under angle control, on an endpoint that flies moving targets:
    the pilot's stick picks the auto-yaw mode and the yaw target is advanced as ArduSub's loop
    advances its attitude target (module docstring), written as the position setpoint's heading;
    elsewhere none (the next GUIDED starts from the attitude target's yaw)."""
    state = endpoint.auto_yaw
    guided = endpoint.requested_mode is ControlMode.GUIDED and endpoint.attitude_target is None
    setpoint = endpoint.world.get(endpoint.intents, PositionSetpoint)
    if guided and not endpoint.flies_moving_targets and pilot_yaw_rate_rad_s(endpoint) != 0.0:
        endpoint.setpoint_not_sent("pilot_yaw", "Pilot yaw in GUIDED does not cross the link")
    if not (guided and endpoint.flies_moving_targets and setpoint is not None):
        state.target_rad = None
        return
    target = setpoint_heading(endpoint)
    assert target is not None  # an endpoint that flies moving targets always has one
    dt = 0.0 if state.updated_s is None else max(0.0, now_s - state.updated_s)
    state.updated_s = now_s
    pilot_rate = _pilot_turn(endpoint)
    slew_rad_s = math.radians(state.slew_deg_s)
    if state.xtrack:  # under the pilot-input failsafe only (module docstring)
        target = xtrack_heading_rad(endpoint)
    elif state.pilot_hold:
        target += pilot_rate * dt
    elif state.rate_only:
        target += slew_rad_s * dt
    else:
        look = state.look_at_rad
        error = _wrap_pi(look - endpoint.snapshot_now().euler_rad[2])
        if abs(error) > MAX_YAW_ERROR_RAD:
            target += slew_rad_s * dt * (-1.0 if error < 0.0 else 1.0)
        else:
            target = look
    state.target_rad = math.remainder(target, math.tau)
    endpoint.write(PositionSetpoint(setpoint.position_ned_m, state.target_rad, True))
