"""Telemetry: a :class:`~.vehicle_snapshot.VehicleSnapshot` as ArduSub's MAVLink messages.

:data:`BUILDERS` maps each telemetry message name to a function of the snapshot that returns the
pymavlink message (``ardupilotmega`` dialect), with ArduPilot's units, signs and integer
conversions (:func:`yaw_sensor_cd`, :func:`vfr_hud_throttle`); the fixed home and the flat-earth
conversions between local NED and latitude/longitude live here too. Reading the vehicle's state
from the world is :mod:`.vehicle_snapshot`'s, not this module's.

Conventions (REFERENCE.md §4.3): world NED, body FRD. Depth is positive down in the
components and negative below the surface on the wire (VFR_HUD.alt [m], GLOBAL_POSITION_INT
alt and relative_alt [mm], with the home at 0 m AMSL); LOCAL_POSITION_NED.z is depth [m].
GLOBAL_POSITION_INT lat/lon are the home plus the NED offset (flat earth, WGS-84 radius).
SCALED_PRESSURE2 is the external depth sensor (press_abs [hPa], temperature [cdegC]);
SCALED_PRESSURE the enclosure's barometer (fixed 1013.25 hPa, 25 °C: not simulated).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mav

from testbed.mavlink.ardusub import base_mode
from testbed.mavlink.vehicle_snapshot import VehicleSnapshot

__all__ = [
    "BUILDERS",
    "EARTH_RADIUS_M",
    "GPS_UNKNOWN_DOP",
    "HOME_LAT_LON_DEG",
    "MESSAGE_IDS",
    "SENSORS_HEALTHY",
    "VFR_HUD_AIRSPEED_M_S",
    "global_from_local",
    "local_from_global",
    "position_e7",
    "vfr_hud_throttle",
    "yaw_sensor_cd",
]

HOME_LAT_LON_DEG = (39.9945, -0.0686)
"""Fixed home [deg]: the harbour of Castelló, where Centelles et al. tested (any fixed point
would do; QGC needs one to draw the vehicle)."""
EARTH_RADIUS_M = 6378137.0
WATER_TEMPERATURE_CDEG = 1500
"""Reported water temperature [cdegC] (15 °C; the simulator has no temperature)."""
_SENSORS = (
    mav.MAV_SYS_STATUS_SENSOR_3D_GYRO
    | mav.MAV_SYS_STATUS_SENSOR_3D_ACCEL
    | mav.MAV_SYS_STATUS_SENSOR_3D_MAG
    | mav.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE
    | mav.MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL
    | mav.MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION
    | mav.MAV_SYS_STATUS_SENSOR_Z_ALTITUDE_CONTROL
    | mav.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS
    | mav.MAV_SYS_STATUS_SENSOR_BATTERY
    | mav.MAV_SYS_STATUS_AHRS
)
"""SYS_STATUS sensor bits present, enabled and healthy (pressure = the depth sensor; the AHRS,
which ArduPilot's ``GCS::update_sensor_status_flags`` reports present, enabled and healthy
while its estimate is)."""
VFR_HUD_AIRSPEED_M_S = 0.0
"""The airspeed ArduSub reports [m/s] (VFR_HUD's ``airspeed``, HIGH_LATENCY2's × 5):
ArduPilot's ``GCS_MAVLINK::vfr_hud_airspeed`` (``GCS_Common.cpp``; ArduSub's
``GCS_MAVLINK_Sub`` does not override it) is a healthy airspeed sensor's reading, else
``AP::gps().ground_speed()``; this vehicle has neither an airspeed sensor nor a GPS (no
DIFFERENTIAL_PRESSURE or GPS bit in :data:`SENSORS_HEALTHY`'s present set), so 0 — not the
horizontal speed, which is VFR_HUD's ``groundspeed`` (``ahrs.groundspeed()``)."""
SENSORS_HEALTHY = _SENSORS | mav.MAV_SYS_STATUS_GEOFENCE
"""SYS_STATUS health bits: also the geofence's, which ArduPilot reports healthy while no fence
is breached, present or not (MAVProxy's fence module announces "fence breach" without it).
HIGH_LATENCY2's failure flags are ArduPilot's reading of these (:mod:`.high_latency`)."""


def _i16(value: float) -> int:
    return max(-32768, min(32767, round(value)))


def _centiamps(current_a: float) -> int:
    """A current [A] as MAVLink's cA; −1 ("not measured") when unknown (NaN: a shore gateway,
    whose narrow link carries no thruster currents)."""
    return -1 if math.isnan(current_a) else _i16(current_a * 100.0)


def _heartbeat(s: VehicleSnapshot) -> mav.MAVLink_message:
    status = (
        mav.MAV_STATE_CRITICAL
        if s.critical
        else mav.MAV_STATE_ACTIVE
        if s.armed
        else mav.MAV_STATE_STANDBY
    )
    return mav.MAVLink_heartbeat_message(
        mav.MAV_TYPE_SUBMARINE,
        mav.MAV_AUTOPILOT_ARDUPILOTMEGA,
        base_mode(s.custom_mode, s.armed),
        s.custom_mode,
        status,
        3,
    )


def _attitude(s: VehicleSnapshot) -> mav.MAVLink_message:
    roll, pitch, yaw = s.euler_rad
    p, q, r = s.rates_rad_s
    return mav.MAVLink_attitude_message(s.time_boot_ms, roll, pitch, yaw, p, q, r)


def _attitude_quaternion(s: VehicleSnapshot) -> mav.MAVLink_message:
    w, x, y, z = s.quaternion_wxyz
    p, q, r = s.rates_rad_s
    return mav.MAVLink_attitude_quaternion_message(
        s.time_boot_ms, w, x, y, z, p, q, r, [0.0, 0.0, 0.0, 0.0]
    )


def yaw_sensor_cd(yaw_rad: float) -> int:
    """ArduPilot's ``ahrs.yaw_sensor`` [cdeg] for a yaw [rad]: ``AP_AHRS::update_cd_values``
    (``libraries/AP_AHRS``) sets ``yaw_sensor = degrees(yaw) * 100`` (an int32: the
    centidegrees truncated toward 0) and adds 36000 when it is negative, so 0..35999."""
    centideg = math.trunc(math.degrees(yaw_rad) * 100.0)
    return centideg + 36000 if centideg < 0 else centideg


def vfr_hud_throttle(throttle: float) -> int:
    """ArduSub's throttle [%] for VFR_HUD and HIGH_LATENCY2: ``GCS_MAVLINK_Sub::vfr_hud_throttle``
    (``ArduSub/GCS_MAVLink_Sub.cpp``) is ``(int16_t)(sub.motors.get_throttle() * 100)`` — the
    float ``throttle`` (0..1) times 100 in single precision, converted toward 0 (57.9 → 57,
    not rounded); the senders take its ``abs``."""
    return int(np.float32(throttle) * np.float32(100.0))


def _vfr_hud(s: VehicleSnapshot) -> mav.MAVLink_message:
    """ArduPilot's ``GCS_MAVLINK::send_vfr_hud`` (``GCS_Common.cpp``): heading
    ``(ahrs.yaw_sensor / 100) % 360`` in integers (whole degrees, truncated), throttle
    ``abs(vfr_hud_throttle())`` (:func:`vfr_hud_throttle`)."""
    vn, ve, vd = s.velocity_ned_m_s
    speed = math.hypot(vn, ve)
    heading = (yaw_sensor_cd(s.euler_rad[2]) // 100) % 360
    throttle = abs(vfr_hud_throttle(s.throttle))
    return mav.MAVLink_vfr_hud_message(
        VFR_HUD_AIRSPEED_M_S, speed, heading, throttle, -s.depth_m, -vd
    )


def global_from_local(north_m: float, east_m: float) -> tuple[float, float]:
    """(latitude, longitude) [deg] of a local NED point (``north_m``, ``east_m``) [m]: the home
    (:data:`HOME_LAT_LON_DEG`, the local origin) plus the offset, flat earth, WGS-84 radius,
    the east scale the home's cos(latitude)."""
    lat0, lon0 = HOME_LAT_LON_DEG
    lat = lat0 + math.degrees(north_m / EARTH_RADIUS_M)
    lon = lon0 + math.degrees(east_m / (EARTH_RADIUS_M * math.cos(math.radians(lat0))))
    return lat, lon


def local_from_global(lat_deg: float, lon_deg: float) -> tuple[float, float]:
    """(north, east) [m] of a global point, the inverse of :func:`global_from_local` (a point
    a ground station takes from GLOBAL_POSITION_INT comes back to the same local position)."""
    lat0, lon0 = HOME_LAT_LON_DEG
    north = math.radians(lat_deg - lat0) * EARTH_RADIUS_M
    east = math.radians(lon_deg - lon0) * EARTH_RADIUS_M * math.cos(math.radians(lat0))
    return north, east


def position_e7(s: VehicleSnapshot) -> tuple[int, int]:
    """(latitude, longitude) [1e-7 deg] of the reported position (GLOBAL_POSITION_INT's and
    HIGH_LATENCY2's)."""
    lat, lon = global_from_local(s.position_ned_m[0], s.position_ned_m[1])
    return round(lat * 1e7), round(lon * 1e7)


def _c_int(value: np.float32, bits: int) -> int:
    """C's conversion of a float to a signed ``bits``-bit integer: toward 0 (beyond the range,
    which C leaves undefined, saturated, as ARM's VCVT does)."""
    limit = 1 << (bits - 1)
    return max(-limit, min(limit - 1, math.trunc(float(value))))


def _global_position_int(s: VehicleSnapshot) -> mav.MAVLink_message:
    """ArduPilot's ``GCS_MAVLINK::send_global_position_int`` (``GCS_Common.cpp``): ``hdg`` is
    ``ahrs.yaw_sensor`` (:func:`yaw_sensor_cd`: truncated centidegrees, 0..35999), not the
    nearest centidegree; ``vx, vy, vz`` are ``vel * 100`` in single precision passed to int16
    fields, all converted toward 0, not rounded. ``alt`` and ``relative_alt`` are ArduSub 4.5's
    (``ArduSub/GCS_MAVLink_Sub.cpp``, PR #26649 backported to Sub-4.5 as #31564)
    ``static_cast<int32_t>(sub.get_alt_msl() * 1000.0f)`` and ``…get_alt_rel() * 1000.0f``:
    ``Sub::get_alt_msl`` is ``-(posD - origin.alt * 0.01f)``, ``get_alt_rel`` the same from the
    home, both at 0 m here, so both are the float ``-posD`` times 1000 in single precision,
    truncated — millimetres toward 0, the same integer (``relative_alt`` is also what the
    base class's ``posD *= -1000.0f`` gave before the backport)."""
    lat, lon = position_e7(s)
    hundred = np.float32(100.0)
    vn, ve, vd = (np.float32(v) * hundred for v in s.velocity_ned_m_s)
    up_mm = _c_int(-np.float32(s.position_ned_m[2]) * np.float32(1000.0), 32)
    return mav.MAVLink_global_position_int_message(
        s.time_boot_ms,
        lat,
        lon,
        up_mm,
        up_mm,
        _c_int(vn, 16),
        _c_int(ve, 16),
        _c_int(vd, 16),
        yaw_sensor_cd(s.euler_rad[2]),
    )


def _home_position(s: VehicleSnapshot) -> mav.MAVLink_message:
    """The home: :data:`HOME_LAT_LON_DEG` at the surface (0 m), the local frame's origin, as
    ArduPilot's ``GCS_MAVLINK::send_home_position`` (``GCS_Common.cpp``) fills the rest:
    ``q = {1.0f, 0.0f, 0.0f, 0.0f}``, x, y, z and the approach vector 0, ``time_usec`` the time
    since boot (``AP_HAL::micros64()``)."""
    lat0, lon0 = HOME_LAT_LON_DEG
    identity = (1.0, 0.0, 0.0, 0.0)
    return mav.MAVLink_home_position_message(
        round(lat0 * 1e7), round(lon0 * 1e7), 0, 0.0, 0.0, 0.0, identity, 0.0, 0.0, 0.0, s.time_usec
    )


def _gps_global_origin(s: VehicleSnapshot) -> mav.MAVLink_message:
    """The local frame's origin on the globe (ArduSub 4.5's ORIGIN_LAT/LON/ALT): the home, with
    ``time_usec`` the time since boot (``GCS_MAVLINK::send_gps_global_origin``'s
    ``AP_HAL::micros64()``)."""
    lat0, lon0 = HOME_LAT_LON_DEG
    return mav.MAVLink_gps_global_origin_message(
        round(lat0 * 1e7), round(lon0 * 1e7), 0, s.time_usec
    )


GPS_UNKNOWN_DOP = 65535
"""AP_GPS's ``GPS_UNKNOWN_DOP`` (UINT16_MAX): the hdop and vdop ``AP_GPS::detect_instance`` sets
while no receiver is found (``state[instance].hdop = GPS_UNKNOWN_DOP``)."""


def _gps_raw_int(s: VehicleSnapshot) -> mav.MAVLink_message:
    """GPS_RAW_INT of a vehicle with no GPS, as ArduPilot 4.5's ``AP_GPS::send_mavlink_gps_raw``
    (``libraries/AP_GPS/AP_GPS.cpp``) sends it: ArduSub streams MSG_GPS_RAW in its
    EXTENDED_STATUS group whether or not a receiver is found, and instance 0 then holds what
    ``detect_instance`` left — ``status(0)`` NO_GPS (fix_type 0), ``last_fix_time_ms(0) * 1000``
    0, the zero ``Location`` (lat, lon, alt 0), ``get_hdop/get_vdop`` :data:`GPS_UNKNOWN_DOP`,
    ground speed and course 0, no satellites; the accuracies stay the 0.0f they start at
    (``horizontal_accuracy`` etc. fail), the ellipsoid height 0 (no undulation) and
    ``gps_yaw_cdeg(0)`` 0 (no GPS yaw configured). The simulated vehicle has no GPS (no GPS bit in
    SYS_STATUS); its position, when it has one, is not a GPS fix."""
    del s
    return mav.MAVLink_gps_raw_int_message(
        0,
        mav.GPS_FIX_TYPE_NO_GPS,
        0,
        0,
        0,
        GPS_UNKNOWN_DOP,
        GPS_UNKNOWN_DOP,
        0,
        0,
        0,
        0,
        0,
        0,
        0,
        0,
        0,
    )


def _local_position_ned(s: VehicleSnapshot) -> mav.MAVLink_message:
    x, y, z = s.position_ned_m
    vx, vy, vz = s.velocity_ned_m_s
    return mav.MAVLink_local_position_ned_message(s.time_boot_ms, x, y, z, vx, vy, vz)


def _scaled_pressure(s: VehicleSnapshot) -> mav.MAVLink_message:
    return mav.MAVLink_scaled_pressure_message(s.time_boot_ms, 1013.25, 0.0, 2500, 0)


def _scaled_pressure2(s: VehicleSnapshot) -> mav.MAVLink_message:
    return mav.MAVLink_scaled_pressure2_message(
        s.time_boot_ms, s.pressure_pa / 100.0, 0.0, WATER_TEMPERATURE_CDEG, 0
    )


def _raw_imu(s: VehicleSnapshot) -> mav.MAVLink_message:
    p, q, r = s.rates_rad_s
    return mav.MAVLink_raw_imu_message(
        s.time_usec, 0, 0, -1000, _i16(p * 1000), _i16(q * 1000), _i16(r * 1000), 0, 0, 0, 0, 0
    )


def _sys_status(s: VehicleSnapshot) -> mav.MAVLink_message:
    return mav.MAVLink_sys_status_message(
        _SENSORS,
        _SENSORS,
        SENSORS_HEALTHY,
        100,
        round(s.voltage_v * 1000.0),
        _centiamps(s.current_a),
        s.remaining_pct,
        0,
        0,
        0,
        0,
        0,
        0,
    )


def _battery_status(s: VehicleSnapshot) -> mav.MAVLink_message:
    cells = [round(s.voltage_v * 1000.0)] + [65535] * 9
    return mav.MAVLink_battery_status_message(
        0,
        mav.MAV_BATTERY_FUNCTION_ALL,
        mav.MAV_BATTERY_TYPE_LION,
        32767,
        cells,
        _centiamps(s.current_a),
        -1,
        -1,
        s.remaining_pct,
    )


def _system_time(s: VehicleSnapshot) -> mav.MAVLink_message:
    clock_s = s.time_s if math.isnan(s.clock_s) else s.clock_s
    return mav.MAVLink_system_time_message(0, int(clock_s * 1000.0) & 0xFFFFFFFF)


def _servo_output_raw(s: VehicleSnapshot) -> mav.MAVLink_message:
    return mav.MAVLink_servo_output_raw_message(s.time_usec & 0xFFFFFFFF, 0, *s.servo_us)


def _rc_channels(s: VehicleSnapshot) -> mav.MAVLink_message:
    channels = list(s.rc_channels[:18])
    return mav.MAVLink_rc_channels_message(s.time_boot_ms, 11, *channels, 255)


BUILDERS: dict[str, Callable[[VehicleSnapshot], mav.MAVLink_message]] = {
    "HEARTBEAT": _heartbeat,
    "ATTITUDE": _attitude,
    "ATTITUDE_QUATERNION": _attitude_quaternion,
    "VFR_HUD": _vfr_hud,
    "GLOBAL_POSITION_INT": _global_position_int,
    "LOCAL_POSITION_NED": _local_position_ned,
    "HOME_POSITION": _home_position,
    "GPS_GLOBAL_ORIGIN": _gps_global_origin,
    "GPS_RAW_INT": _gps_raw_int,
    "SCALED_PRESSURE": _scaled_pressure,
    "SCALED_PRESSURE2": _scaled_pressure2,
    "RAW_IMU": _raw_imu,
    "SYS_STATUS": _sys_status,
    "BATTERY_STATUS": _battery_status,
    "SYSTEM_TIME": _system_time,
    "SERVO_OUTPUT_RAW": _servo_output_raw,
    "RC_CHANNELS": _rc_channels,
}
"""Telemetry message name → builder. NAMED_VALUE_FLOAT, STATUSTEXT and the replies are the
endpoint's (:mod:`testbed.mavlink.endpoint`)."""
MESSAGE_IDS = {
    name: getattr(mav, f"MAVLINK_MSG_ID_{name}")
    for name in (*BUILDERS, "NAMED_VALUE_FLOAT", "HIGH_LATENCY2")
}
"""Telemetry message name → MAVLink id (for SET_MESSAGE_INTERVAL, REQUEST_MESSAGE; HIGH_LATENCY2
is :mod:`.high_latency`'s, built by the endpoint)."""
