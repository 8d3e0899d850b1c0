"""SET_ATTITUDE_TARGET as ArduSub takes it: GUIDED's angle control and ALT_HOLD's attitude target.

ArduSub 4.5 (``ArduSub/GCS_Mavlink.cpp``, ``handle_message``, SET_ATTITUDE_TARGET; the modes
in ``mode_guided.cpp`` and ``mode_althold.cpp``) reads only the attitude quaternion and the
thrust; the body-rate fields are never used. It checks no mode on receipt; what the message
does depends on the mode and on two ``type_mask`` bits, 64 (throttle ignore) and 128 (attitude
ignore):

- **both clear** → ``ModeGuided::guided_set_angle``: GUIDED leaves its position target for angle
  control. The roll and pitch are limited together to ANGLE_MAX (their norm, scaled back), the
  heading taken as sent; the thrust, constrained to 0..1, is a climb rate, (thrust − 0.5) × 2 ×
  WPNAV_SPEED_UP above 0.5 and × WPNAV_SPEED_DN below [cm/s], integrated into the depth target
  from the depth at the switch (``D_set_pos_target_from_climb_rate_cms``). With no message for
  1 s (GUIDED_ATTITUDE_TIMEOUT_MS) roll and pitch return to level and the climb rate to 0; the
  heading stays. Only in GUIDED does it act (the mode's run function is the only reader).
- **64 set** (throttle ignored, attitude used) → ``set_attitude_target_no_gps``, which ALT_HOLD
  flies (``ModeAlthold::run_pre``) while the last such message is under 5 s old, its depth still
  the pilot's; then the pilot's level attitude and the heading held before come back.
- otherwise (attitude ignored) nothing.

Here the first becomes the vehicle's targets while GUIDED is requested: the present
:class:`~testbed.common.components.PositionSetpoint` is removed (the position loop lets go), the
attitude is an ``AttitudeSetpoint`` and the integrated depth a ``DepthSetpoint`` each update;
the second an ``AttitudeSetpoint`` while DEPTH_HOLD (ALT_HOLD) is requested, then the level
attitude at the heading target held before the first message (the vehicle's ``ControlTargets``).
A message the requested mode does not use is counted ``not_guided``, one with the attitude
ignored ``unsupported_target``; a non-finite or zero quaternion or a non-finite thrust
``bad_field``. A new position target, or another mode, ends the attitude control. No reply
(ArduSub sends none).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from pymavlink.dialects.v20 import ardupilotmega as mav

from testbed.common.components import (
    AttitudeSetpoint,
    ControlMode,
    ControlTargets,
    DepthSetpoint,
    PositionSetpoint,
)
from testbed.common.geometry import euler_from_quat, quat_from_euler

if TYPE_CHECKING:
    from testbed.mavlink.endpoint import Channel, VehicleEndpoint

__all__ = [
    "ALT_HOLD_TIMEOUT_S",
    "GUIDED_TIMEOUT_S",
    "AttitudeTarget",
    "climb_rate_m_s",
    "on_set_attitude_target",
    "update_attitude_target",
]

GUIDED_TIMEOUT_S = 1.0
"""GUIDED_ATTITUDE_TIMEOUT_MS: without a message this long [s], level and no climb."""
ALT_HOLD_TIMEOUT_S = 5.0
"""ALT_HOLD flies a throttle-ignored attitude target while it is younger than this [s]."""
_THROTTLE_IGNORE = 64  # ATTITUDE_TARGET_TYPEMASK_THROTTLE_IGNORE (1 << 6)
_ATTITUDE_IGNORE = 128  # ATTITUDE_TARGET_TYPEMASK_ATTITUDE_IGNORE (1 << 7)


@dataclass(slots=True)
class AttitudeTarget:
    """The attitude control a SET_ATTITUDE_TARGET started (mutable: the endpoint's state).

    Attributes:
        mode: the mode it flies in (GUIDED: angle control; DEPTH_HOLD: ALT_HOLD's target).
        quaternion_wxyz: the attitude target, body → NED (GUIDED: roll and pitch limited).
        climb_m_s: climb rate [m/s, + up] (GUIDED).
        received_s: when the last message arrived [s].
        depth_m: the integrated depth target [m, + down] (GUIDED).
        updated_s: the time the depth target was integrated to [s].
        held_yaw_rad: the heading to come back to when an ALT_HOLD target expires [rad].
        expired: the timeout acted (written once).
    """

    mode: ControlMode
    quaternion_wxyz: tuple[float, float, float, float]
    climb_m_s: float
    received_s: float
    depth_m: float
    updated_s: float
    held_yaw_rad: float
    expired: bool = False


def climb_rate_m_s(thrust: float, speed_up_m_s: float, speed_down_m_s: float) -> float:
    """ArduSub's thrust → climb rate [m/s, + up]: thrust constrained to 0..1, 0.5 holds, above
    it up to ``speed_up_m_s``, below down to ``speed_down_m_s`` (WPNAV_SPEED_UP/DN)."""
    thrust = min(1.0, max(0.0, thrust))
    scale = speed_up_m_s if thrust > 0.5 else speed_down_m_s
    return (thrust - 0.5) * 2.0 * scale


def _limited(
    quaternion_wxyz: tuple[float, float, float, float], angle_max_rad: float
) -> tuple[float, float, float, float]:
    """The attitude with roll and pitch scaled back together to a norm ≤ ``angle_max_rad``
    (``guided_angle_control_run``), the heading kept."""
    roll, pitch, yaw = euler_from_quat(quaternion_wxyz)
    total = math.hypot(roll, pitch)
    if total > angle_max_rad > 0.0:
        ratio = angle_max_rad / total
        roll, pitch = roll * ratio, pitch * ratio
    return quat_from_euler(roll, pitch, yaw)


def on_set_attitude_target(
    endpoint: VehicleEndpoint,
    channel: Channel,
    message: mav.MAVLink_message,
    now_s: float,
    arrived_s: float,
) -> None:
    """SET_ATTITUDE_TARGET → GUIDED's angle control or ALT_HOLD's attitude (module docstring)."""
    del channel, arrived_s
    if not endpoint.for_us(message.target_system, message.target_component):
        return
    mask = int(message.type_mask)
    if mask & _ATTITUDE_IGNORE:
        endpoint.reject("unsupported_target")
        return
    mode = endpoint.requested_mode
    guided = mode is ControlMode.GUIDED and not mask & _THROTTLE_IGNORE
    alt_hold = mode is ControlMode.DEPTH_HOLD and bool(mask & _THROTTLE_IGNORE)
    if not (guided or alt_hold):
        endpoint.reject("not_guided")
        return
    mode = ControlMode.GUIDED if guided else ControlMode.DEPTH_HOLD
    q = tuple(float(c) for c in message.q)
    thrust = float(message.thrust)
    norm = math.sqrt(sum(c * c for c in q)) if all(math.isfinite(c) for c in q) else math.nan
    if not (math.isfinite(norm) and norm > 1e-6 and math.isfinite(thrust)):
        endpoint.reject("bad_field")
        return
    w, x, y, z = (c / norm for c in q)
    attitude = (w, x, y, z)
    climb = 0.0
    if guided:
        params = endpoint.params
        attitude = _limited(attitude, math.radians(params["ANGLE_MAX"] / 100.0))
        climb = climb_rate_m_s(
            thrust, params["WPNAV_SPEED_UP"] / 100.0, params["WPNAV_SPEED_DN"] / 100.0
        )
    target = endpoint.attitude_target
    if target is None or target.mode is not mode:
        snapshot = endpoint.snapshot_now()
        targets = endpoint.world.get(endpoint.vehicle, ControlTargets)
        held = snapshot.quaternion_wxyz if targets is None else targets.quaternion_wxyz
        depth = snapshot.depth_m
        endpoint.attitude_target = AttitudeTarget(
            mode, attitude, climb, now_s, depth, now_s, euler_from_quat(held)[2]
        )
        if guided:  # guided_angle_control_start: the position target let go, the depth held
            origin = endpoint.options.origin
            endpoint.world.remove(endpoint.intents, PositionSetpoint, origin=origin)
            endpoint.write(DepthSetpoint(depth))
    else:
        _integrate_depth(endpoint, target, now_s)  # at the old climb rate up to now
        target.quaternion_wxyz, target.climb_m_s = attitude, climb
        target.received_s, target.updated_s, target.expired = now_s, now_s, False
    endpoint.accepted += 1
    endpoint.write(AttitudeSetpoint(attitude))


def update_attitude_target(endpoint: VehicleEndpoint, now_s: float) -> None:
    """Each update: GUIDED's depth target integrated from the climb rate while the last message
    is under :data:`GUIDED_TIMEOUT_S` old, then level; ALT_HOLD's target given back after
    :data:`ALT_HOLD_TIMEOUT_S`; nothing once the mode requested is another."""
    target = endpoint.attitude_target
    if target is None:
        return
    if endpoint.requested_mode is not target.mode:
        endpoint.attitude_target = None
        return
    if target.mode is ControlMode.GUIDED:
        _integrate_depth(endpoint, target, now_s)
        if now_s - target.received_s > GUIDED_TIMEOUT_S and not target.expired:
            target.expired = True
            yaw = euler_from_quat(target.quaternion_wxyz)[2]
            endpoint.write(AttitudeSetpoint(quat_from_euler(0.0, 0.0, yaw)))
    elif now_s - target.received_s >= ALT_HOLD_TIMEOUT_S:
        endpoint.attitude_target = None  # the pilot's attitude: level, the heading held before
        endpoint.write(AttitudeSetpoint(quat_from_euler(0.0, 0.0, target.held_yaw_rad)))


def _integrate_depth(endpoint: VehicleEndpoint, target: AttitudeTarget, now_s: float) -> None:
    """GUIDED's depth target moved at the climb rate from its last update to ``now_s`` [s], no
    further than :data:`GUIDED_TIMEOUT_S` past the last message (ArduSub's climb rate is 0 then);
    written as a ``DepthSetpoint`` when it moved."""
    end = min(now_s, target.received_s + GUIDED_TIMEOUT_S)
    if end > target.updated_s and target.climb_m_s != 0.0:
        target.depth_m = max(0.0, target.depth_m - target.climb_m_s * (end - target.updated_s))
        endpoint.write(DepthSetpoint(target.depth_m))
    target.updated_s = max(target.updated_s, end)
