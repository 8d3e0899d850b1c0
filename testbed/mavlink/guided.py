"""GUIDED's targets: SET_POSITION_TARGET_LOCAL_NED, SET_POSITION_TARGET_GLOBAL_INT and
DO_REPOSITION → a PositionSetpoint, fixed or moving at a velocity.

**SET_POSITION_TARGET_LOCAL_NED** (ArduSub 4.5 ``GCS_MAVLINK_Sub::handle_message``): acted on
only while GUIDED is requested (else ignored, as ArduSub, and counted ``not_guided``). Its
``type_mask`` picks one of ArduSub's three GUIDED submodes by ArduSub's own test, each
``*_ignore`` true when any one of its three bits is set: position (``!pos_ignore && vel_ignore
&& acc_ignore``, ``guided_set_destination``), position and velocity (``!pos_ignore &&
!vel_ignore && acc_ignore``, ``guided_set_destination_posvel``) and velocity
(``pos_ignore && !vel_ignore && acc_ignore``, ``guided_set_velocity``); any other mask (an
acceleration used, or neither position nor velocity) is ignored by ArduSub and counted
``unsupported_target`` here. Frames MAV_FRAME_LOCAL_NED (absolute, the position fix's NED
frame), LOCAL_OFFSET_NED (a position from the reported position) or BODY_OFFSET_NED, BODY_NED
or BODY_FRD (a position from the reported position, x ahead and y right of the reported
heading, and a velocity along them); z is down, the depth target [m]. The yaw and the yaw rate
set ArduSub's auto-yaw state, which steers GUIDED's heading (:mod:`~testbed.mavlink.guided_yaw`:
the yaw is a heading from north in every frame but BODY_OFFSET_NED, where it is relative).

A velocity moves the target (:class:`MovingTarget`, ArduSub's ``Guided_PosVel``
``posvel_pos_target_cm += vel × dt`` each loop): the position target (the message's, or for a
velocity alone the moving target's where it was, else the reported position, where ArduSub's
velocity controller starts) advances at the velocity each update, its climb limited to
WPNAV_SPEED_UP and its descent to WPNAV_SPEED_DN (ArduSub's ``guided_posvel_control_start``);
:data:`VELOCITY_TIMEOUT_S` after the last such message the velocity is 0 and the target stays
where it got (``GUIDED_POSVEL_TIMEOUT_MS``). Horizontally the target is leashed: it does not
run further ahead of the reported position, along its velocity, than
:attr:`~testbed.mavlink.options.EndpointOptions.guided_leash_m` (the distance from which the
vehicle's position loop already asks for its top speed), so a velocity the vehicle cannot fly
stores no distance for it to run on after the timeout (ArduSub's vehicle, flying its velocity
controller, stops where it is).
The vehicle's position loop flies the moving point: it trails it by about the speed over the
loop's gain (0.8 /s) and, once the target stops, closes that gap, where ArduSub's velocity
controller would stop at once.

**SET_POSITION_TARGET_GLOBAL_INT** (ArduSub 4.5 ``GCS_MAVLINK_Sub::handle_message``): in
ALT_HOLD with z not ignored, only the depth: the target's ``alt`` [m, up] as the depth target,
whatever the frame (``set_pos_desired_U_cm(alt × 100)``; above the surface, the surface). In
GUIDED the same three submodes by the same ``type_mask`` test (others counted
``unsupported_target``); a velocity is north, east, down [m/s], whatever the frame; a position
needs lat/lon in range (else ``bad_field``), in MAV_FRAME_GLOBAL(_INT) (altitude above mean
sea level) or GLOBAL_RELATIVE_ALT(_INT) (above home): both the same here, the home and origin
at the surface, 0 m (GPS_GLOBAL_ORIGIN, HOME_POSITION); lat/lon to north and east with
:func:`~testbed.mavlink.telemetry.local_from_global` (the inverse of GLOBAL_POSITION_INT's),
the depth −alt; the heading the auto-yaw state's, untouched (ArduSub's yaw fields are "for
future use").
GLOBAL_TERRAIN_ALT(_INT) needs terrain data the simulator has not, and other frames are not
global: a position in them is ignored, counted ``unsupported_frame``. Other modes: ignored,
``not_guided``.

**DO_REPOSITION** (COMMAND_INT; a COMMAND_LONG's params 5, 6 are latitude and longitude in
degrees and its frame MAV_FRAME_GLOBAL, as ArduPilot converts it): the handler ArduSub gained
after 4.5 (ArduPilot PR #27637, ``handle_command_int_do_reposition``, Copter's): DENIED outside
GUIDED unless param2 has MAV_DO_REPOSITION_FLAGS_CHANGE_MODE (1) (``not_guided``), DENIED for a
frame that is not global (``unsupported_frame``), lat/lon out of range, a NaN altitude, lat =
lon = 0 or a relative altitude of 0 cm (``bad_field``): ``location_from_command_t`` stores
``int32_t(z * 100)``, float32 truncated toward zero, so under 1 cm is 0 and
``Location::sanitize`` would have changed it; FAILED for a terrain frame (no terrain data,
``unsupported_frame``) or when the change to GUIDED is refused (no position estimate,
``mode_refused``); else ACCEPTED (``accepted``) and flown as above to the altitude in whole
centimetres (param1 speed and param4 yaw unused, as ArduSub).

**Entering GUIDED** from another mode sets the target at ArduSub's stopping point
(:mod:`~testbed.mavlink.guided_entry`), so no target from an earlier GUIDED is flown again;
GUIDED asked for again changes nothing.

Non-finite or out-of-range fields that are used are counted ``bad_field``, and every position
target beyond :data:`MAX_TARGET_M` too. The target becomes a
:class:`~testbed.common.components.PositionSetpoint` on the endpoint's intents entity, its
heading the auto-yaw state's (:mod:`~testbed.mavlink.guided_yaw`); the messages get no reply
(ArduSub sends none either). A shore gateway flies no moving target
(:attr:`~testbed.mavlink.endpoint.VehicleEndpoint.flies_moving_targets`): its velocity and
position-and-velocity targets are counted ``unsupported_target``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mav

from testbed.common.components import ControlMode, DepthSetpoint, PositionSetpoint
from testbed.mavlink import guided_yaw
from testbed.mavlink.telemetry import local_from_global

if TYPE_CHECKING:
    from testbed.mavlink.channel import Channel
    from testbed.mavlink.endpoint import VehicleEndpoint

__all__ = [
    "GLOBAL_FRAMES",
    "MAX_TARGET_M",
    "VELOCITY_TIMEOUT_S",
    "MovingTarget",
    "do_reposition",
    "on_set_position_target_global_int",
    "on_set_position_target_local_ned",
    "update_moving_target",
]

_POSITION_IGNORE = 0b111  # POSITION_TARGET_TYPEMASK_X/Y/Z_IGNORE
_VELOCITY_IGNORE = 0b11_1000  # POSITION_TARGET_TYPEMASK_VX/VY/VZ_IGNORE
_YAW_IGNORE = 1024
_YAW_RATE_IGNORE = 2048
_BODY_FRAMES = (mav.MAV_FRAME_BODY_OFFSET_NED, mav.MAV_FRAME_BODY_NED, mav.MAV_FRAME_BODY_FRD)
"""Frames whose position and velocity are an offset from the reported position and a velocity
along the reported heading (ArduSub takes BODY_NED, which MAVProxy's ``position`` sends, and
BODY_FRD as BODY_OFFSET_NED for those; not for the yaw, relative in BODY_OFFSET_NED only)."""
MAX_TARGET_M = 1.0e4
"""Largest accepted |coordinate| of a position target [m] (the vehicle's start range)."""
VELOCITY_TIMEOUT_S = 3.0
"""GUIDED_POSVEL_TIMEOUT_MS: a velocity is 0 this long after its last message [s]."""
GLOBAL_FRAMES = {
    mav.MAV_FRAME_GLOBAL: "absolute",
    mav.MAV_FRAME_GLOBAL_INT: "absolute",
    mav.MAV_FRAME_GLOBAL_RELATIVE_ALT: "above_home",
    mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT: "above_home",
    mav.MAV_FRAME_GLOBAL_TERRAIN_ALT: "above_terrain",
    mav.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT: "above_terrain",
}
"""MAV_FRAME → ArduPilot's ``Location::AltFrame`` (its
``mavlink_coordinate_frame_to_location_alt_frame``); the home and the origin are at 0 m, so
"absolute" and "above_home" altitudes are the same here."""
_Z_IGNORE = 0b100  # POSITION_TARGET_TYPEMASK_Z_IGNORE
_ACCELERATION_IGNORE = 0b1_1100_0000  # AX..AZ ignore bits
_LAT_E7_MAX = 900_000_000
_LON_E7_MAX = 1_800_000_000


@dataclass(slots=True)
class MovingTarget:
    """GUIDED's position target moving at a velocity (ArduSub's ``Guided_PosVel``; mutable:
    the endpoint's state).

    Attributes:
        position_ned_m: (3,) the target [m], NED (z the depth), as advanced to ``updated_s``.
        velocity_ned_m_s: (3,) its velocity [m/s], NED, the climb limited (module docstring).
        received_s: when its last message arrived [s].
        updated_s: the time the target was advanced to [s].
    """

    position_ned_m: tuple[float, float, float]
    velocity_ned_m_s: tuple[float, float, float]
    received_s: float
    updated_s: float


def on_set_position_target_local_ned(
    endpoint: VehicleEndpoint,
    channel: Channel,
    message: mav.MAVLink_message,
    now_s: float,
    arrived_s: float,
) -> None:
    """GUIDED's local target → a fixed or moving PositionSetpoint (module docstring)."""
    del channel, arrived_s
    if not endpoint.for_us(message.target_system, message.target_component):
        return
    if endpoint.requested_mode is not ControlMode.GUIDED:
        endpoint.reject("not_guided")
        return
    mask = int(message.type_mask)
    kind = _submode(endpoint, mask)
    if kind is None:
        return
    x, y, z = (float(message.x), float(message.y), float(message.z))
    vx, vy, vz = (float(message.vx), float(message.vy), float(message.vz))
    yaw = None if mask & _YAW_IGNORE else float(message.yaw)
    yaw_rate = None if mask & _YAW_RATE_IGNORE else float(message.yaw_rate)
    used = ((x, y, z) if kind != "velocity" else ()) + ((vx, vy, vz) if kind != "position" else ())
    used += () if yaw is None else (yaw,)
    if not all(math.isfinite(v) for v in used) or not (
        yaw_rate is None or guided_yaw.yaw_rate_fits(yaw_rate)
    ):
        endpoint.reject("bad_field")
        return
    frame = int(message.coordinate_frame)
    yaw_state = (yaw, yaw_rate, frame == mav.MAV_FRAME_BODY_OFFSET_NED)  # ArduSub's yaw_relative
    if frame != mav.MAV_FRAME_LOCAL_NED:
        snapshot = endpoint.snapshot_now()
        if frame in _BODY_FRAMES:
            heading = snapshot.euler_rad[2]
            c, s = math.cos(heading), math.sin(heading)
            x, y = c * x - s * y, s * x + c * y
            vx, vy = c * vx - s * vy, s * vx + c * vy
        elif frame != mav.MAV_FRAME_LOCAL_OFFSET_NED:
            endpoint.reject("unsupported_frame")
            return
        px, py, pz = snapshot.position_ned_m
        x, y, z = x + px, y + py, z + pz
    if kind != "velocity" and max(abs(x), abs(y), abs(z)) > MAX_TARGET_M:
        endpoint.reject("bad_field")
        return
    position = None if kind == "velocity" else (x, y, z)
    if kind == "position":
        endpoint.accepted += 1
        guided_yaw.set_yaw_state(endpoint, *yaw_state)
        endpoint.request_position((x, y, z))
        return
    _move(endpoint, position, (vx, vy, vz), now_s, yaw_state)


def _submode(endpoint: VehicleEndpoint, mask: int) -> str | None:
    """ArduSub's GUIDED submode of a ``type_mask`` (``pos_ignore``, ``vel_ignore`` and
    ``acc_ignore`` each true when any one of its three bits is set; the acceleration must be
    ignored): "position", "posvel" or "velocity"; None for anything else, counted
    ``unsupported_target``."""
    pos_ignore, vel_ignore = bool(mask & _POSITION_IGNORE), bool(mask & _VELOCITY_IGNORE)
    if not mask & _ACCELERATION_IGNORE or (pos_ignore and vel_ignore):
        endpoint.reject("unsupported_target")
        return None
    if pos_ignore:
        return "velocity"
    return "position" if vel_ignore else "posvel"


def _move(
    endpoint: VehicleEndpoint,
    position_ned_m: tuple[float, float, float] | None,
    velocity_ned_m_s: tuple[float, float, float],
    now_s: float,
    yaw_state: tuple[float | None, float | None, bool] | None = None,
) -> None:
    """A position target moving at a velocity (module docstring): from ``position_ned_m``, or
    for a velocity alone (None) from where the moving target is, else from the reported
    position; counted ``accepted``, or ``unsupported_target`` by an endpoint that flies none.
    ``yaw_state``: the yaw, the yaw rate and whether the yaw is relative, for
    :func:`~testbed.mavlink.guided_yaw.set_yaw_state` (None: a message without them)."""
    if not endpoint.flies_moving_targets:
        endpoint.reject("unsupported_target")
        endpoint.statustext_once(mav.MAV_SEVERITY_WARNING, "Velocity targets do not cross the link")
        return
    endpoint.accepted += 1
    if yaw_state is not None:
        guided_yaw.set_yaw_state(endpoint, *yaw_state)
    moving = endpoint.moving_target
    if position_ned_m is None:
        if moving is not None:
            _advance(endpoint, moving, now_s)
            position_ned_m = moving.position_ned_m
        else:
            position_ned_m = endpoint.snapshot_now().position_ned_m
    velocity = _limited_climb(endpoint, velocity_ned_m_s)
    endpoint.request_position(position_ned_m)  # ends any other GUIDED target
    endpoint.moving_target = MovingTarget(position_ned_m, velocity, now_s, now_s)


def _limited_climb(
    endpoint: VehicleEndpoint, velocity_ned_m_s: tuple[float, float, float]
) -> tuple[float, float, float]:
    """The velocity [m/s, NED] with its climb limited to WPNAV_SPEED_UP and its descent to
    WPNAV_SPEED_DN."""
    vn, ve, vd = velocity_ned_m_s
    up, down = endpoint.params["WPNAV_SPEED_UP"] / 100.0, endpoint.params["WPNAV_SPEED_DN"] / 100.0
    return (vn, ve, min(down, max(-up, vd)))


def _advance(endpoint: VehicleEndpoint, moving: MovingTarget, now_s: float) -> None:
    """The target moved at its velocity from its last update to ``now_s`` [s], no further
    than :data:`VELOCITY_TIMEOUT_S` past its last message, horizontally only while it leads
    the reported position by less than the leash along its velocity; written when it moved
    (the depth no higher than the surface, the coordinates within :data:`MAX_TARGET_M`)."""
    end = min(now_s, moving.received_s + VELOCITY_TIMEOUT_S)
    dt = end - moving.updated_s
    if dt > 0.0 and any(moving.velocity_ned_m_s):
        (n0, e0, d0), (vn, ve, vd) = moving.position_ned_m, moving.velocity_ned_m_s
        n, e = n0 + vn * dt, e0 + ve * dt
        here = endpoint.snapshot_now().position_ned_m
        speed = math.hypot(vn, ve)
        lead = ((n0 - here[0]) * vn + (e0 - here[1]) * ve) / speed if speed > 0.0 else 0.0
        if lead >= endpoint.options.guided_leash_m:
            n, e = n0, e0  # on the leash: the vehicle is behind, already at its top speed
        bound = MAX_TARGET_M
        n, e = max(-bound, min(bound, n)), max(-bound, min(bound, e))
        moving.position_ned_m = (n, e, max(0.0, min(bound, d0 + vd * dt)))
        yaw = guided_yaw.setpoint_heading(endpoint)
        setpoint = PositionSetpoint(
            moving.position_ned_m, 0.0 if yaw is None else yaw, yaw is not None
        )
        endpoint.write(setpoint)
    moving.updated_s = max(moving.updated_s, end)


def update_moving_target(endpoint: VehicleEndpoint, now_s: float) -> None:
    """Each update: the moving target advanced (:func:`_advance`); forgotten once another mode
    than GUIDED is requested."""
    moving = endpoint.moving_target
    if moving is None:
        return
    if endpoint.requested_mode is not ControlMode.GUIDED:
        endpoint.moving_target = None
        return
    _advance(endpoint, moving, now_s)


def _in_range(lat_e7: int, lon_e7: int) -> bool:
    """ArduPilot's ``check_latlng``: |lat| ≤ 90°, |lon| ≤ 180° (in 1e-7 degrees)."""
    return abs(lat_e7) <= _LAT_E7_MAX and abs(lon_e7) <= _LON_E7_MAX


def _local_target(lat_e7: int, lon_e7: int, alt_m: float) -> tuple[float, float, float] | None:
    """The NED target [m] of a global point (altitude [m, up] from the surface home), or None
    beyond :data:`MAX_TARGET_M`."""
    north, east = local_from_global(lat_e7 * 1e-7, lon_e7 * 1e-7)
    target = (north, east, -alt_m)
    return None if max(abs(c) for c in target) > MAX_TARGET_M else target


def on_set_position_target_global_int(
    endpoint: VehicleEndpoint,
    channel: Channel,
    message: mav.MAVLink_message,
    now_s: float,
    arrived_s: float,
) -> None:
    """GUIDED's global target (fixed or moving), ALT_HOLD's depth (module docstring)."""
    del channel, arrived_s
    if not endpoint.for_us(message.target_system, message.target_component):
        return
    mode = endpoint.requested_mode
    mask = int(message.type_mask)
    alt = float(message.alt)
    if mode is ControlMode.DEPTH_HOLD and not mask & _Z_IGNORE:  # ArduSub: the depth only
        if not math.isfinite(alt) or abs(alt) > MAX_TARGET_M:
            endpoint.reject("bad_field")
            return
        endpoint.accepted += 1
        endpoint.write(DepthSetpoint(max(0.0, -alt)))
        return
    if mode is not ControlMode.GUIDED:
        endpoint.reject("not_guided")
        return
    kind = _submode(endpoint, mask)
    if kind is None:
        return
    velocity = (float(message.vx), float(message.vy), float(message.vz))
    if kind != "position" and not all(math.isfinite(v) for v in velocity):
        endpoint.reject("bad_field")
        return
    if kind == "velocity":  # no position: neither lat/lon nor the frame is read
        _move(endpoint, None, velocity, now_s)
        return
    lat_e7, lon_e7 = int(message.lat_int), int(message.lon_int)
    if not (_in_range(lat_e7, lon_e7) and math.isfinite(alt)):
        endpoint.reject("bad_field")
        return
    if GLOBAL_FRAMES.get(int(message.coordinate_frame), "above_terrain") == "above_terrain":
        endpoint.reject("unsupported_frame")  # not global, or no terrain data to convert it
        return
    target = _local_target(lat_e7, lon_e7, alt)
    if target is None:
        endpoint.reject("bad_field")
        return
    if kind == "posvel":
        _move(endpoint, target, velocity, now_s)
        return
    endpoint.accepted += 1
    endpoint.request_position(target)


def do_reposition(
    endpoint: VehicleEndpoint, frame: int, params: tuple[float, ...], lat_e7: int, lon_e7: int
) -> int:
    """MAV_CMD_DO_REPOSITION as ArduSub's ``handle_command_int_do_reposition`` (module
    docstring): the MAV_RESULT; counted ``accepted`` when ACCEPTED, else once under the reason
    it was refused.

    Args:
        endpoint: the endpoint.
        frame: the command's MAV_FRAME (MAV_FRAME_GLOBAL for a COMMAND_LONG).
        params: (param1 … param4, x, y, z) as received; param2 the flags, z the altitude [m].
        lat_e7: the target's latitude [1e-7 deg].
        lon_e7: its longitude [1e-7 deg].
    """
    flags, alt = params[1], params[6]
    change_mode = math.isfinite(flags) and int(flags) & mav.MAV_DO_REPOSITION_FLAGS_CHANGE_MODE
    guided = endpoint.requested_mode is ControlMode.GUIDED
    if not guided and not change_mode:
        endpoint.reject("not_guided")
        return int(mav.MAV_RESULT_DENIED)
    alt_frame = GLOBAL_FRAMES.get(frame)
    if alt_frame is None:  # location_from_command_t: not a global frame
        endpoint.reject("unsupported_frame")
        return int(mav.MAV_RESULT_DENIED)
    if not (_in_range(lat_e7, lon_e7) and math.isfinite(alt) and abs(alt) <= MAX_TARGET_M):
        endpoint.reject("bad_field")
        return int(mav.MAV_RESULT_DENIED)
    alt_cm = int(np.float32(alt) * np.float32(100.0))  # location_from_command_t: truncated
    if (lat_e7, lon_e7) == (0, 0) or (alt_cm == 0 and alt_frame != "absolute"):
        endpoint.reject("bad_field")  # Location::sanitize would have changed it
        return int(mav.MAV_RESULT_DENIED)
    target = _local_target(lat_e7, lon_e7, alt_cm / 100.0)
    if target is None:
        endpoint.reject("bad_field")
        return int(mav.MAV_RESULT_DENIED)
    if alt_frame == "above_terrain":  # guided_set_destination: no terrain data
        endpoint.reject("unsupported_frame")
        return int(mav.MAV_RESULT_FAILED)
    if not guided and endpoint.set_mode(mav.SUB_MODE_GUIDED) != mav.MAV_RESULT_ACCEPTED:
        return int(mav.MAV_RESULT_FAILED)  # counted mode_refused
    endpoint.accepted += 1
    endpoint.request_position(target)
    return int(mav.MAV_RESULT_ACCEPTED)
