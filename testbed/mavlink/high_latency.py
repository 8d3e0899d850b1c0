"""MAVLink's high-latency protocol as ArduSub 4.5 runs it: HIGH_LATENCY2 and
MAV_CMD_CONTROL_HIGH_LATENCY.

ArduPilot 4.5 (``libraries/GCS_MAVLink``: ``GCS_Common.cpp`` ``GCS_MAVLINK::init``,
``initialise_message_intervals_from_streamrates``, ``get_default_interval_for_ap_message``,
``send_high_latency2``, ``handle_control_high_latency``; ``GCS.cpp``
``GCS::enable_high_latency_connections``, ``send_to_active_channels``; ``GCS_MAVLink.cpp``
``comm_send_buffer``; ArduSub's ``GCS_MAVLINK_Sub::high_latency_*`` overrides):

- A link is a **high-latency link** when its serial port's protocol is MAVLinkHL
  (SERIALn_PROTOCOL 43), fixed at boot; here a channel opened with ``high_latency=True``
  (:meth:`~testbed.mavlink.endpoint.VehicleEndpoint.open_channel`). On it HIGH_LATENCY2 is
  scheduled every :data:`~testbed.mavlink.streams.HIGH_LATENCY2_INTERVAL_S` (5 s) instead of the
  1-Hz HEARTBEAT; its SRn_* stream rates apply as on any link (ArduPilot's High Latency page has
  the port send HIGH_LATENCY2 alone, so SRn_* 0 on it: what an HL channel gets unless given
  rates); no TIMESYNC request and no broadcast NAMED_VALUE_FLOAT go to it.
- Every high-latency link is **disabled at boot**; while disabled *nothing* leaves it
  (``comm_send_buffer`` drops every byte: replies, STATUSTEXT, HIGH_LATENCY2, whose 5-s clock
  keeps running), while what arrives on it is handled as on any link.
  MAV_CMD_CONTROL_HIGH_LATENCY (2600) from any link enables (param1 1) or disables (param1 0)
  all of them at once (one GCS-wide flag), says "High Latency enabled" / "disabled" (NOTICE)
  and is ACCEPTED, also on a vehicle that has no high-latency link; any other param1 (NaN
  too) is FAILED. The ACK of a disable that came on the high-latency link itself is dropped
  (the link was disabled before the ACK was written); an enable's goes out on it.

HIGH_LATENCY2's fields, as ``send_high_latency2`` fills them for ArduSub, for this vehicle:

========================== ============================================================
timestamp [ms]             the state's time (``AP_HAL::millis()``; the sample time on a
                           shore gateway, as every message's ``time_boot_ms``)
type, autopilot            SUBMARINE (12), ARDUPILOTMEGA (3)
custom_mode                the ArduSub mode number (uint16)
latitude, longitude        the position as GLOBAL_POSITION_INT's [1e-7 deg]
altitude [m]               ``Location.alt`` [cm] × 0.01 as an int16: −depth, each step
                           truncated toward 0 (−1.7 m → −1)
target_altitude [m]        GUIDED (and AUTO): the target's altitude, −target depth
                           truncated (``alt + pos_error_U``); else 0
heading [deg/2]            ``((yaw_sensor / 100) % 360) / 2`` in integers: the heading's
                           whole degrees (centidegrees truncated), halved, floor
target_heading [deg/2]     GUIDED: the bearing to the target's horizontal position
                           (``wp_nav``'s bearing to destination), centidegrees wrapped
                           to 0..36000, / 200 truncated; else 0
target_distance [dam]      GUIDED: the horizontal distance to it, cm × 0.001 truncated
                           (10-m steps: 0 within 10 m); else 0
throttle [%]               ``abs((int16)(motors.get_throttle() × 100))``: RC 3's throttle
                           0..1 as VFR_HUD's, truncated
airspeed [m/s × 5]         0: ArduSub has no airspeed sensor and ``vfr_hud_airspeed``
                           falls back to the GPS's ground speed, 0 without a GPS (this
                           vehicle reports none in SYS_STATUS)
airspeed_sp [m/s × 5]      GUIDED: |the position controller's desired velocity| × 5
                           truncated (≤ 255); else 0 (below)
groundspeed [m/s × 5]      the horizontal speed of the velocity estimate × 5 truncated
                           (≤ 255), LOCAL_POSITION_NED's
windspeed, wind_heading    0 (ArduSub does not override them)
eph, epv, climb_rate       0 (ArduPilot sends 0)
temperature_air [°C]       −128 (INT8_MIN: no airspeed sensor's temperature on a sub)
battery [%]                the battery remaining, SYS_STATUS's (−1 unknown: a gateway)
wp_num                     0 (no mission)
failure_flags              HL_FAILURE_FLAG_* for every sensor of ArduPilot's map whose
                           SYS_STATUS health bit is clear (health alone, present or not):
                           GPS, differential pressure, terrain and RC receiver here
                           (2 + 64 + 256 + 1 = 323), and any the vehicle loses
custom0                    ``base_mode()`` (the heartbeat's: 81 / 209 / 217) as an int8
                           (209 → −47); custom1, custom2 0
========================== ============================================================

The desired velocity: this vehicle's GUIDED loops have no path planner, so their demand
stands for ArduSub's (as GUIDED's stopping point uses them, :mod:`.guided_entry`):
horizontally ``min(gain × error, max_speed)`` along the error to the target, vertically
``depth_gain × error`` within WPNAV_SPEED_UP / WPNAV_SPEED_DN, plus a moving target's velocity
(ArduSub's feed-forward); 0 without the loops (a gateway). In GUIDED's angle control (no
position target) only the depth target is known: the target altitude and the vertical demand.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from pymavlink.dialects.v20 import ardupilotmega as mav

from testbed.common.components import DepthSetpoint, PositionSetpoint
from testbed.common.velocity_demand import velocity_demand_ne
from testbed.mavlink.ardusub import base_mode
from testbed.mavlink.telemetry import (
    SENSORS_HEALTHY,
    VFR_HUD_AIRSPEED_M_S,
    position_e7,
    vfr_hud_throttle,
    yaw_sensor_cd,
)
from testbed.mavlink.vehicle_snapshot import VehicleSnapshot

if TYPE_CHECKING:
    from testbed.mavlink.channel import Channel
    from testbed.mavlink.endpoint import VehicleEndpoint

__all__ = [
    "FAILURE_MAP",
    "TARGET_MODES",
    "control_high_latency",
    "failure_flags",
    "high_latency2",
]

TARGET_MODES = frozenset({3, 4})
"""AUTO and GUIDED: the modes in which ArduSub fills the target fields."""
FAILURE_MAP: tuple[tuple[int, int], ...] = (
    (mav.MAV_SYS_STATUS_SENSOR_GPS, mav.HL_FAILURE_FLAG_GPS),
    (mav.MAV_SYS_STATUS_SENSOR_DIFFERENTIAL_PRESSURE, mav.HL_FAILURE_FLAG_DIFFERENTIAL_PRESSURE),
    (mav.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE, mav.HL_FAILURE_FLAG_ABSOLUTE_PRESSURE),
    (mav.MAV_SYS_STATUS_SENSOR_3D_ACCEL, mav.HL_FAILURE_FLAG_3D_ACCEL),
    (mav.MAV_SYS_STATUS_SENSOR_3D_GYRO, mav.HL_FAILURE_FLAG_3D_GYRO),
    (mav.MAV_SYS_STATUS_SENSOR_3D_MAG, mav.HL_FAILURE_FLAG_3D_MAG),
    (mav.MAV_SYS_STATUS_TERRAIN, mav.HL_FAILURE_FLAG_TERRAIN),
    (mav.MAV_SYS_STATUS_SENSOR_BATTERY, mav.HL_FAILURE_FLAG_BATTERY),
    (mav.MAV_SYS_STATUS_SENSOR_RC_RECEIVER, mav.HL_FAILURE_FLAG_RC_RECEIVER),
    (mav.MAV_SYS_STATUS_GEOFENCE, mav.HL_FAILURE_FLAG_GEOFENCE),
    (mav.MAV_SYS_STATUS_AHRS, mav.HL_FAILURE_FLAG_ESTIMATOR),
)
"""ArduPilot's ``send_high_latency2`` map: SYS_STATUS sensor bit → HL_FAILURE_FLAG."""
_FLT_EPSILON = 1.1920929e-07
"""``std::numeric_limits<float>::epsilon()``: ArduPilot's ``is_equal`` tolerance."""
_ACCEPTED: int = mav.MAV_RESULT_ACCEPTED
_FAILED: int = mav.MAV_RESULT_FAILED


def failure_flags(health: int = SENSORS_HEALTHY) -> int:
    """HIGH_LATENCY2's failure flags for the SYS_STATUS health bits ``health``: a flag for
    every mapped sensor whose bit is clear (:data:`FAILURE_MAP`)."""
    flags = 0
    for sensor, flag in FAILURE_MAP:
        if not health & sensor:
            flags |= flag
    return flags


def _i16(value: float) -> int:
    return max(-32768, min(32767, math.trunc(value)))


def _int8(value: int) -> int:
    """A uint8 written into an int8 field (C's conversion: 209 → −47)."""
    return value - 256 if value > 127 else value


def _heading_half_deg(yaw_rad: float) -> int:
    """ArduPilot's ``(((uint16_t)ahrs.yaw_sensor / 100) % 360) / 2``
    (:func:`~testbed.mavlink.telemetry.yaw_sensor_cd`)."""
    return ((yaw_sensor_cd(yaw_rad) // 100) % 360) // 2


def _target(
    endpoint: VehicleEndpoint, s: VehicleSnapshot
) -> tuple[tuple[float, float] | None, float | None, tuple[float, float, float]]:
    """GUIDED's target: its horizontal position [m] (None: angle control), its depth [m]
    (None: none known) and a moving target's velocity [m/s], NED."""
    setpoint = endpoint.world.get(endpoint.intents, PositionSetpoint)
    moving = endpoint.moving_target
    velocity = (0.0, 0.0, 0.0) if moving is None else moving.velocity_ned_m_s
    if setpoint is not None:
        north, east, depth = setpoint.position_ned_m
        return (north, east), depth, velocity
    depth_sp = endpoint.world.get(endpoint.intents, DepthSetpoint)
    return None, None if depth_sp is None else depth_sp.depth_m, velocity


def _desired_speed(
    endpoint: VehicleEndpoint,
    s: VehicleSnapshot,
    horizontal: tuple[float, float] | None,
    depth_m: float | None,
    feed_forward: tuple[float, float, float],
) -> float:
    """|the desired velocity| [m/s] (module docstring); 0 without the vehicle's loops."""
    loop = endpoint.options.guided_loop
    if loop is None:
        return 0.0
    vn, ve, vd = feed_forward
    if horizontal is not None:
        error = (horizontal[0] - s.position_ned_m[0], horizontal[1] - s.position_ned_m[1])
        dn, de = velocity_demand_ne(error, loop.gain_1_s, loop.max_speed_m_s)
        vn, ve = vn + dn, ve + de
    if depth_m is not None:
        ez = depth_m - s.position_ned_m[2]
        gain = loop.depth_gain_1_s
        demand_z = 0.0 if gain == 0.0 or ez == 0.0 else gain * ez
        up, down = endpoint.params["WPNAV_SPEED_UP"], endpoint.params["WPNAV_SPEED_DN"]
        vd += max(-up / 100.0, min(down / 100.0, demand_z))
    return math.sqrt(vn * vn + ve * ve + vd * vd)


def high_latency2(endpoint: VehicleEndpoint, s: VehicleSnapshot) -> mav.MAVLink_message:
    """HIGH_LATENCY2 for snapshot ``s`` as ArduSub 4.5 fills it (module docstring)."""
    lat, lon = position_e7(s)
    north, east, depth = s.position_ned_m
    altitude = _i16(math.trunc(-depth * 100.0) * 0.01)
    target_alt = target_heading = target_distance = speed_sp = 0
    if s.custom_mode in TARGET_MODES:
        horizontal, target_depth, feed_forward = _target(endpoint, s)
        if target_depth is not None:
            target_alt = _i16(-target_depth)
        if horizontal is not None:
            dn, de = horizontal[0] - north, horizontal[1] - east
            bearing_cd = math.degrees(math.atan2(de, dn)) * 100.0 % 36000.0
            target_heading = min(255, math.trunc(bearing_cd / 200.0))
            target_distance = min(65535, math.trunc(math.hypot(dn, de) * 100.0 * 0.001))
        desired = _desired_speed(endpoint, s, horizontal, target_depth, feed_forward)
        speed_sp = min(255, math.trunc(min(desired * 5.0, 255.0)))
    vn, ve, _ = s.velocity_ned_m_s
    groundspeed = math.trunc(min(math.hypot(vn, ve) * 5.0, 255.0))
    return mav.MAVLink_high_latency2_message(
        s.time_boot_ms,
        mav.MAV_TYPE_SUBMARINE,
        mav.MAV_AUTOPILOT_ARDUPILOTMEGA,
        s.custom_mode & 0xFFFF,
        lat,
        lon,
        altitude,
        target_alt,
        _heading_half_deg(s.euler_rad[2]),
        target_heading,
        target_distance,
        min(255, abs(vfr_hud_throttle(s.throttle))),
        min(255, math.trunc(VFR_HUD_AIRSPEED_M_S * 5.0)),
        speed_sp,
        groundspeed,
        0,  # windspeed
        0,  # wind_heading
        0,  # eph
        0,  # epv
        -128,  # temperature_air: INT8_MIN
        0,  # climb_rate
        max(-1, min(100, s.remaining_pct)),
        0,  # wp_num
        failure_flags(),
        _int8(base_mode(s.custom_mode, s.armed)),
        0,
        0,
    )


def control_high_latency(
    endpoint: VehicleEndpoint, channel: Channel, p: tuple[float, ...], now_s: float
) -> int:
    """MAV_CMD_CONTROL_HIGH_LATENCY: param1 0 disables, 1 enables every high-latency link
    (ArduPilot's ``is_equal``, within a float's epsilon); anything else FAILED. The
    MAV_RESULT."""
    del channel, now_s
    if abs(p[0]) < _FLT_EPSILON:
        enabled = False
    elif abs(p[0] - 1.0) < _FLT_EPSILON:
        enabled = True
    else:  # NaN too
        return _FAILED
    endpoint.high_latency_enabled = enabled
    endpoint.statustext(
        mav.MAV_SEVERITY_NOTICE, f"High Latency {'enabled' if enabled else 'disabled'}"
    )
    return _ACCEPTED
