"""GUIDED's position targets: SET_POSITION_TARGET_LOCAL_NED, SET_POSITION_TARGET_GLOBAL_INT and
DO_REPOSITION → a PositionSetpoint.

**SET_POSITION_TARGET_LOCAL_NED** (ArduSub's ``handle_set_position_target_local_ned``, the
position part): acted on only while GUIDED is requested (else ignored, as ArduSub, and counted
``not_guided``); it must be a position target by ArduSub's ``type_mask`` test (no x, y, z bit
set, and any one velocity bit and any one acceleration bit set: ArduSub's ``vel_ignore`` and
``acc_ignore`` are each true for any of their three bits; other targets are counted
``unsupported_target``) in MAV_FRAME_LOCAL_NED (absolute, the position fix's NED frame),
LOCAL_OFFSET_NED (from the reported position) or BODY_OFFSET_NED, BODY_NED or BODY_FRD (from
the reported position, x ahead and y right of the reported heading); z is down, the depth
target [m]; yaw [rad] when not ignored, else the present heading is kept.

**SET_POSITION_TARGET_GLOBAL_INT** (ArduSub 4.5 ``GCS_MAVLINK_Sub::handle_message``): in
ALT_HOLD with z not ignored, only the depth: the target's ``alt`` [m, up] as the depth target,
whatever the frame (``set_pos_desired_U_cm(alt × 100)``; above the surface, the surface). In
GUIDED a position target by the same ``type_mask`` test (others counted
``unsupported_target``), lat/lon in range (else ``bad_field``), in MAV_FRAME_GLOBAL(_INT)
(altitude above mean sea level) or GLOBAL_RELATIVE_ALT(_INT) (above home): both the same here,
the home and origin at the surface, 0 m (GPS_GLOBAL_ORIGIN, HOME_POSITION); lat/lon to north and
east with :func:`~testbed.mavlink.telemetry.local_from_global` (the inverse of
GLOBAL_POSITION_INT's), the depth −alt; the heading is kept (ArduSub's ``guided_set_destination``
of a position only, its yaw fields "for future use"). GLOBAL_TERRAIN_ALT(_INT) needs terrain
data the simulator has not, and other frames are not global: ignored, counted
``unsupported_frame``. Other modes: ignored, ``not_guided``.

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

Non-finite or out-of-range fields are counted ``bad_field``, and every target beyond
:data:`MAX_TARGET_M` too. The target becomes a
:class:`~testbed.common.components.PositionSetpoint` on the endpoint's intents entity; the
messages get no reply (ArduSub sends none either).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mav

from testbed.common.components import ControlMode, DepthSetpoint
from testbed.mavlink.telemetry import local_from_global

if TYPE_CHECKING:
    from testbed.mavlink.endpoint import Channel, VehicleEndpoint

__all__ = [
    "GLOBAL_FRAMES",
    "MAX_TARGET_M",
    "do_reposition",
    "on_set_position_target_global_int",
    "on_set_position_target_local_ned",
]

_POSITION_IGNORE = 0b111  # POSITION_TARGET_TYPEMASK_X/Y/Z_IGNORE
_VELOCITY_IGNORE = 0b11_1000  # POSITION_TARGET_TYPEMASK_VX/VY/VZ_IGNORE
_YAW_IGNORE = 1024
_BODY_FRAMES = (mav.MAV_FRAME_BODY_OFFSET_NED, mav.MAV_FRAME_BODY_NED, mav.MAV_FRAME_BODY_FRD)
"""Frames whose target is an offset from the reported position along the reported heading
(ArduSub takes BODY_NED, which MAVProxy's ``position`` sends, as BODY_OFFSET_NED; BODY_FRD is
MAVLink's name for the same)."""
MAX_TARGET_M = 1.0e4
"""Largest accepted |coordinate| of a position target [m] (the vehicle's start range)."""
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


def on_set_position_target_local_ned(
    endpoint: VehicleEndpoint,
    channel: Channel,
    message: mav.MAVLink_message,
    now_s: float,
    arrived_s: float,
) -> None:
    """GUIDED's position target → a PositionSetpoint (module docstring)."""
    del channel, now_s, arrived_s
    if not endpoint.for_us(message.target_system, message.target_component):
        return
    if endpoint.requested_mode is not ControlMode.GUIDED:
        endpoint.reject("not_guided")
        return
    mask = int(message.type_mask)
    if not _position_only(endpoint, mask):
        return
    x, y, z, yaw = (float(message.x), float(message.y), float(message.z), float(message.yaw))
    use_yaw = not mask & _YAW_IGNORE
    if not all(math.isfinite(v) for v in (x, y, z, yaw)):
        endpoint.reject("bad_field")
        return
    frame = int(message.coordinate_frame)
    if frame != mav.MAV_FRAME_LOCAL_NED:
        snapshot = endpoint.snapshot_now()
        if frame in _BODY_FRAMES:
            heading = snapshot.euler_rad[2]
            c, s = math.cos(heading), math.sin(heading)
            x, y = c * x - s * y, s * x + c * y
            if use_yaw:
                yaw += heading
        elif frame != mav.MAV_FRAME_LOCAL_OFFSET_NED:
            endpoint.reject("unsupported_frame")
            return
        px, py, pz = snapshot.position_ned_m
        x, y, z = x + px, y + py, z + pz
    if max(abs(x), abs(y), abs(z)) > MAX_TARGET_M:
        endpoint.reject("bad_field")
        return
    endpoint.accepted += 1
    endpoint.request_position((x, y, z), math.remainder(yaw, math.tau) if use_yaw else None)


def _position_only(endpoint: VehicleEndpoint, mask: int) -> bool:
    """Whether ``type_mask`` asks for a position target only, by ArduSub's test
    (``!pos_ignore && vel_ignore && acc_ignore``, each true when any of its three bits is set):
    no position bit set, at least one velocity bit and one acceleration bit set; anything else
    is counted ``unsupported_target``."""
    if mask & _POSITION_IGNORE or not mask & _VELOCITY_IGNORE or not mask & _ACCELERATION_IGNORE:
        endpoint.reject("unsupported_target")
        return False
    return True


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
    """GUIDED's global position target, ALT_HOLD's depth (module docstring)."""
    del channel, now_s, arrived_s
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
    if not _position_only(endpoint, mask):
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
    endpoint.accepted += 1
    endpoint.request_position(target, None)


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
    endpoint.request_position(target, None)
    return int(mav.MAV_RESULT_ACCEPTED)
