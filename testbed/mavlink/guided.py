"""GUIDED's position target: SET_POSITION_TARGET_LOCAL_NED → a PositionSetpoint.

ArduSub's ``handle_set_position_target_local_ned``, for the position part: the message is acted on
only while GUIDED is requested (else ignored, as ArduSub, and counted ``not_guided``); it must be a
position target (x, y, z not ignored in ``type_mask``; velocity and acceleration targets are
counted ``unsupported_target``) in MAV_FRAME_LOCAL_NED (absolute, the position fix's NED frame),
LOCAL_OFFSET_NED (from the reported position) or BODY_OFFSET_NED, BODY_NED or BODY_FRD (from the
reported position, x ahead and y right of the reported heading); z is down, the depth target [m];
yaw [rad] when not ignored, else the present heading is kept. Non-finite or out-of-range fields are
counted ``bad_field``, other frames ``unsupported_frame``. The target becomes a
:class:`~testbed.common.components.PositionSetpoint` on the endpoint's intents entity; no reply
(ArduSub sends none either).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from pymavlink.dialects.v20 import ardupilotmega as mav

from testbed.common.components import ControlMode, ModeRequest

if TYPE_CHECKING:
    from testbed.mavlink.endpoint import Channel, VehicleEndpoint

__all__ = ["on_set_position_target_local_ned"]

_POSITION_IGNORE = 0b111  # POSITION_TARGET_TYPEMASK_X/Y/Z_IGNORE
_MOTION_IGNORE = 0b1_1111_1000  # VX..VZ, AX..AZ ignore bits
_YAW_IGNORE = 1024
_BODY_FRAMES = (mav.MAV_FRAME_BODY_OFFSET_NED, mav.MAV_FRAME_BODY_NED, mav.MAV_FRAME_BODY_FRD)
"""Frames whose target is an offset from the reported position along the reported heading
(ArduSub takes BODY_NED, which MAVProxy's ``position`` sends, as BODY_OFFSET_NED; BODY_FRD is
MAVLink's name for the same)."""
_MAX_TARGET_M = 1.0e4
"""Largest accepted |coordinate| of a position target [m] (the vehicle's start range)."""


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
    request = endpoint.world.get(endpoint.intents, ModeRequest)
    if request is None or request.mode is not ControlMode.GUIDED:
        endpoint.reject("not_guided")
        return
    mask = int(message.type_mask)
    if mask & _POSITION_IGNORE or (~mask) & _MOTION_IGNORE:
        endpoint.reject("unsupported_target")
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
    if max(abs(x), abs(y), abs(z)) > _MAX_TARGET_M:
        endpoint.reject("bad_field")
        return
    endpoint.accepted += 1
    endpoint.request_position((x, y, z), math.remainder(yaw, math.tau) if use_yaw else None)
