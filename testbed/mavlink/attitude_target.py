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
- **64 set** (throttle ignored), whatever bit 128 says and whatever the mode: stored as
  ``set_attitude_target_no_gps`` (before the mask test that ends the handler), which ALT_HOLD
  flies (``ModeAlthold::run_pre``, roll, pitch and yaw as sent) while the last such message is
  under 5 s old, its depth still the pilot's; then the pilot's level attitude and the heading
  held before come back. A target stored in another mode is flown by an ALT_HOLD entered
  within those 5 s.
- **128 set, 64 clear** (attitude ignored) → nothing.

Here the first becomes the vehicle's targets while GUIDED is requested: the present
:class:`~testbed.common.components.PositionSetpoint` is removed (the position loop lets go;
through the teleop gateway the shore cancels the vehicle's ``GoTo`` for it:
:meth:`~testbed.mavlink.shore.ShoreEndpoint.release_position`), the attitude is an
``AttitudeSetpoint`` and the integrated depth a ``DepthSetpoint`` each update
(:class:`AttitudeTarget`); the second is kept (:class:`StoredAttitude`) and is an
``AttitudeSetpoint`` while DEPTH_HOLD (ALT_HOLD) is requested and it is fresh, then the level
attitude at the heading held when it began (the vehicle's ``ControlTargets``, or the present
heading when ALT_HOLD was only just requested: ``ModeAlthold::init`` holds that). Both-clear
in another mode is counted ``not_guided``, 128 alone ``unsupported_target``; a non-finite or
zero quaternion or a non-finite thrust that is used ``bad_field``; a stored target in any mode
``accepted``. A new position target, or another mode, ends GUIDED's attitude control. No reply
(ArduSub sends none).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from pymavlink.dialects.v20 import ardupilotmega as mav

from testbed.common.components import (
    ActiveMode,
    AttitudeSetpoint,
    ControlMode,
    ControlTargets,
    DepthSetpoint,
)
from testbed.common.geometry import euler_from_quat, quat_from_euler

if TYPE_CHECKING:
    from testbed.mavlink.channel import Channel
    from testbed.mavlink.endpoint import VehicleEndpoint

__all__ = [
    "ALT_HOLD_TIMEOUT_S",
    "GUIDED_TIMEOUT_S",
    "AttitudeTarget",
    "StoredAttitude",
    "climb_rate_m_s",
    "on_set_attitude_target",
    "update_attitude_target",
    "update_stored_attitude",
]

GUIDED_TIMEOUT_S = 1.0
"""GUIDED_ATTITUDE_TIMEOUT_MS: without a message this long [s], level and no climb."""
ALT_HOLD_TIMEOUT_S = 5.0
"""ALT_HOLD flies a throttle-ignored attitude target while it is younger than this [s]."""
_THROTTLE_IGNORE = 64  # ATTITUDE_TARGET_TYPEMASK_THROTTLE_IGNORE (1 << 6)
_ATTITUDE_IGNORE = 128  # ATTITUDE_TARGET_TYPEMASK_ATTITUDE_IGNORE (1 << 7)


@dataclass(slots=True)
class AttitudeTarget:
    """GUIDED's angle control a SET_ATTITUDE_TARGET started (mutable: the endpoint's state).

    Attributes:
        quaternion_wxyz: the attitude target, body → NED, roll and pitch limited.
        climb_m_s: climb rate [m/s, + up].
        received_s: when the last message arrived [s].
        depth_m: the integrated depth target [m, + down].
        updated_s: the time the depth target was integrated to [s].
        expired: the timeout acted (written once).
    """

    quaternion_wxyz: tuple[float, float, float, float]
    climb_m_s: float
    received_s: float
    depth_m: float
    updated_s: float
    expired: bool = False


@dataclass(slots=True)
class StoredAttitude:
    """ArduSub's ``set_attitude_target_no_gps``: the last throttle-ignored SET_ATTITUDE_TARGET,
    kept in any mode; ALT_HOLD flies it while it is under :data:`ALT_HOLD_TIMEOUT_S` old
    (mutable: the endpoint's state).

    Attributes:
        quaternion_wxyz: the attitude, body → NED (normalised).
        received_s: when it arrived [s].
        flying: ALT_HOLD is flying it (it is the attitude setpoint).
        held_yaw_rad: the heading ALT_HOLD held when it began flying it, to come back to
            (ArduSub's ``last_pilot_heading``) [rad].
    """

    quaternion_wxyz: tuple[float, float, float, float]
    received_s: float
    flying: bool = False
    held_yaw_rad: float = 0.0


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
    """SET_ATTITUDE_TARGET → ALT_HOLD's stored attitude or GUIDED's angle control (module
    docstring)."""
    del channel, arrived_s
    if not endpoint.for_us(message.target_system, message.target_component):
        return
    mask = int(message.type_mask)
    throttle_ignored = bool(mask & _THROTTLE_IGNORE)
    if mask & _ATTITUDE_IGNORE and not throttle_ignored:
        endpoint.reject("unsupported_target")
        return
    guided = not throttle_ignored and endpoint.requested_mode is ControlMode.GUIDED
    if not (guided or throttle_ignored):
        endpoint.reject("not_guided")
        return
    q = tuple(float(c) for c in message.q)
    thrust = float(message.thrust)
    norm = math.sqrt(sum(c * c for c in q)) if all(math.isfinite(c) for c in q) else math.nan
    if not (math.isfinite(norm) and norm > 1e-6 and (throttle_ignored or math.isfinite(thrust))):
        endpoint.reject("bad_field")
        return
    w, x, y, z = (c / norm for c in q)
    endpoint.accepted += 1
    if throttle_ignored:
        _store(endpoint, (w, x, y, z), now_s)
    else:
        _set_angle(endpoint, (w, x, y, z), thrust, now_s)


def _store(
    endpoint: VehicleEndpoint, attitude: tuple[float, float, float, float], now_s: float
) -> None:
    """Keep a throttle-ignored attitude (ArduSub stores it whatever the mode); ALT_HOLD flies
    it at once."""
    stored = endpoint.stored_attitude
    if stored is None or not stored.flying:
        endpoint.stored_attitude = StoredAttitude(attitude, now_s)
        update_stored_attitude(endpoint, now_s)
        return
    stored.quaternion_wxyz, stored.received_s = attitude, now_s
    endpoint.write(AttitudeSetpoint(attitude))


def _set_angle(
    endpoint: VehicleEndpoint,
    attitude: tuple[float, float, float, float],
    thrust: float,
    now_s: float,
) -> None:
    """GUIDED's ``guided_set_angle``: roll and pitch limited, the thrust a climb rate."""
    params = endpoint.params
    attitude = _limited(attitude, math.radians(params["ANGLE_MAX"] / 100.0))
    climb = climb_rate_m_s(
        thrust, params["WPNAV_SPEED_UP"] / 100.0, params["WPNAV_SPEED_DN"] / 100.0
    )
    target = endpoint.attitude_target
    if target is None:
        depth = endpoint.snapshot_now().depth_m
        endpoint.attitude_target = AttitudeTarget(attitude, climb, now_s, depth, now_s)
        # guided_angle_control_start: the position target let go, the depth held
        endpoint.release_position()
        endpoint.write(DepthSetpoint(depth))
    else:
        _integrate_depth(endpoint, target, now_s)  # at the old climb rate up to now
        target.quaternion_wxyz, target.climb_m_s = attitude, climb
        target.received_s, target.updated_s, target.expired = now_s, now_s, False
    endpoint.write(AttitudeSetpoint(attitude))


def update_attitude_target(endpoint: VehicleEndpoint, now_s: float) -> None:
    """Each update: GUIDED's depth target integrated from the climb rate while the last message
    is under :data:`GUIDED_TIMEOUT_S` old, then level, nothing once another mode is requested;
    and the stored attitude (:func:`update_stored_attitude`)."""
    target = endpoint.attitude_target
    if target is not None and endpoint.requested_mode is not ControlMode.GUIDED:
        endpoint.attitude_target = None
    elif target is not None:
        _integrate_depth(endpoint, target, now_s)
        if now_s - target.received_s > GUIDED_TIMEOUT_S and not target.expired:
            target.expired = True
            yaw = euler_from_quat(target.quaternion_wxyz)[2]
            endpoint.write(AttitudeSetpoint(quat_from_euler(0.0, 0.0, yaw)))
    update_stored_attitude(endpoint, now_s)


def update_stored_attitude(endpoint: VehicleEndpoint, now_s: float) -> None:
    """ALT_HOLD's ``run_pre``: the stored attitude flown while ALT_HOLD is requested and it is
    under :data:`ALT_HOLD_TIMEOUT_S` old (from the moment ALT_HOLD comes, if it comes in
    time); when it ages out while flown, the pilot's level attitude at the heading held before
    it. Forgotten once too old to fly."""
    stored = endpoint.stored_attitude
    if stored is None:
        return
    fresh = now_s - stored.received_s < ALT_HOLD_TIMEOUT_S
    if endpoint.requested_mode is not ControlMode.DEPTH_HOLD:
        stored.flying = False  # the next mode's entry sets its own targets
    elif fresh and not stored.flying:
        stored.flying, stored.held_yaw_rad = True, _held_yaw_rad(endpoint)
        setpoint = AttitudeSetpoint(stored.quaternion_wxyz)
        if endpoint.world.get(endpoint.intents, AttitudeSetpoint) == setpoint:
            # written before (an earlier ALT_HOLD): written again so the vehicle, whose mode
            # entry levelled its targets, takes it again
            endpoint.world.remove(
                endpoint.intents, AttitudeSetpoint, origin=endpoint.options.origin
            )
        endpoint.write(setpoint)
    elif not fresh and stored.flying:
        stored.flying = False
        endpoint.write(AttitudeSetpoint(quat_from_euler(0.0, 0.0, stored.held_yaw_rad)))
    if not fresh and not stored.flying:
        endpoint.stored_attitude = None


def _held_yaw_rad(endpoint: VehicleEndpoint) -> float:
    """ALT_HOLD's held heading [rad]: its attitude target's when the vehicle is in it, else
    the present heading (the one ALT_HOLD's entry holds, ArduSub's ``ModeAlthold::init``)."""
    world, vehicle = endpoint.world, endpoint.vehicle
    active = world.get(vehicle, ActiveMode)
    targets = world.get(vehicle, ControlTargets)
    if active is not None and active.mode is ControlMode.DEPTH_HOLD and targets is not None:
        return euler_from_quat(targets.quaternion_wxyz)[2]
    return euler_from_quat(endpoint.snapshot_now().quaternion_wxyz)[2]


def _integrate_depth(endpoint: VehicleEndpoint, target: AttitudeTarget, now_s: float) -> None:
    """GUIDED's depth target moved at the climb rate from its last update to ``now_s`` [s], no
    further than :data:`GUIDED_TIMEOUT_S` past the last message (ArduSub's climb rate is 0 then);
    written as a ``DepthSetpoint`` when it moved."""
    end = min(now_s, target.received_s + GUIDED_TIMEOUT_S)
    if end > target.updated_s and target.climb_m_s != 0.0:
        target.depth_m = max(0.0, target.depth_m - target.climb_m_s * (end - target.updated_s))
        endpoint.write(DepthSetpoint(target.depth_m))
    target.updated_s = max(target.updated_s, end)
