"""Telemetry: the vehicle's ECS components as ArduSub's MAVLink messages.

:func:`read_vehicle` takes one :class:`VehicleSnapshot` of what the vehicle owns and publishes
(:class:`~testbed.common.components.ImuReading`, ``DepthReading``, ``Odometry``, ``Armed``,
``ActiveMode``, ``ThrusterOutput``, ``PositionReading``) from a world; it reads components
only, so a shore-side gateway reading the operator's mirrored copies gets the same messages.
:data:`BUILDERS` maps each telemetry message name to a function of the snapshot that returns the
pymavlink message (``ardupilotmega`` dialect). :class:`VelocityEstimator` differentiates the
reported position, as the vehicle reports no velocity of its own.

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
from dataclasses import dataclass, field

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mav

from testbed.common.components import (
    ActiveMode,
    Armed,
    DepthReading,
    ImuReading,
    Odometry,
    PositionReading,
    ThrusterOutput,
)
from testbed.common.geometry import euler_from_quat, quat_conjugate, quat_multiply
from testbed.common.hydrostatics import ardusub_pressure_pa
from testbed.ecs import Entity, World
from testbed.mavlink.ardusub import base_mode
from testbed.mavlink.motors import ServoOutputs

__all__ = [
    "BUILDERS",
    "EARTH_RADIUS_M",
    "HOME_LAT_LON_DEG",
    "MESSAGE_IDS",
    "SENSORS_HEALTHY",
    "VFR_HUD_AIRSPEED_M_S",
    "VehicleSnapshot",
    "VelocityEstimator",
    "global_from_local",
    "local_from_global",
    "position_e7",
    "read_vehicle",
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


Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]


@dataclass(slots=True)
class VelocityEstimator:
    """NED velocity [m/s] from successive positions and body rates [rad/s] from successive
    attitudes: finite differences, low-passed (a shore gateway's mirrored state has neither).

    Body rates: the rotation q₀* ⊗ q₁ between successive attitudes (q body → NED: in the
    earlier body frame), its angle about its axis over the step's time.

    Args:
        time_constant_s: first-order filter time constant [s].
    """

    time_constant_s: float = 0.3
    velocity_ned_m_s: Vec3 = (0.0, 0.0, 0.0)
    rates_rad_s: Vec3 = (0.0, 0.0, 0.0)
    _last: tuple[float, Vec3, Quat | None] | None = field(default=None, repr=False)

    def update(self, t_s: float, position_ned_m: Vec3, quaternion_wxyz: Quat | None = None) -> None:
        """Fold in the position (and attitude, body → NED) at ``t_s`` [s] (ignored unless newer
        than the last)."""
        last = self._last
        if last is not None and t_s <= last[0]:
            return
        self._last = (t_s, position_ned_m, quaternion_wxyz)
        if last is None:
            return
        dt = t_s - last[0]
        alpha = dt / (self.time_constant_s + dt)
        self.velocity_ned_m_s = _low_pass(
            self.velocity_ned_m_s,
            tuple((p1 - p0) / dt for p1, p0 in zip(position_ned_m, last[1], strict=True)),
            alpha,
        )
        q0 = last[2]
        if q0 is not None and quaternion_wxyz is not None:
            w, x, y, z = quat_multiply(quat_conjugate(q0), quaternion_wxyz)
            half = math.hypot(x, y, z)  # sin of half the angle turned
            # the angle over the step (the short way round) about the unit axis, per second
            scale = 2.0 * math.atan2(half, abs(w)) / (half * dt) if half > 0.0 else 0.0
            if w < 0.0:
                scale = -scale
            self.rates_rad_s = _low_pass(self.rates_rad_s, (scale * x, scale * y, scale * z), alpha)


def _low_pass(state: Vec3, sample: tuple[float, ...], alpha: float) -> Vec3:
    a, b, c = state
    x, y, z = sample
    return (a + alpha * (x - a), b + alpha * (y - b), c + alpha * (z - c))


@dataclass(frozen=True, slots=True)
class VehicleSnapshot:
    """What the telemetry says at one instant.

    Attributes:
        time_s: vehicle time [s] (``time_boot_ms`` = 1000 × it).
        armed: the vehicle's armed state.
        custom_mode: ArduSub mode number.
        quaternion_wxyz: attitude, body → NED.
        rates_rad_s: (p, q, r) body rates [rad/s], FRD (estimated from the attitude without
            an IMU reading: a shore gateway).
        depth_m: depth [m, positive down].
        pressure_pa: external (depth sensor) absolute pressure [Pa] (from the depth without a
            reading: a shore gateway).
        position_ned_m: (3,) position [m], NED (x, y 0 without a position fix).
        velocity_ned_m_s: (3,) velocity [m/s], NED (estimated from the position).
        servo_us: (16,) SERVO1..16 pulse widths [µs] in ArduSub's motor numbering
            (:class:`~testbed.mavlink.motors.ServoOutputs`), 0 = unused (also before the first
            allocation).
        current_a: total thruster current [A]; NaN when unknown (a shore gateway).
        voltage_v: battery voltage [V].
        remaining_pct: battery remaining [%].
        rc_channels: (18,) RC inputs [µs], 0 = none.
        throttle: heave command as ArduSub's throttle, 0..1 (0.5 neutral).
        gain: the joystick gain.
        critical: a failsafe is active (heartbeat system_status CRITICAL).
        has_position: the vehicle has a position fix.
        clock_s: the endpoint's own time now [s] (SYSTEM_TIME); NaN = ``time_s``. A shore
            gateway reports the state's sample time in ``time_s`` and its clock here, so a
            ground station sees how old the state is.
    """

    time_s: float
    armed: bool
    custom_mode: int
    quaternion_wxyz: tuple[float, float, float, float]
    rates_rad_s: tuple[float, float, float]
    depth_m: float
    pressure_pa: float
    position_ned_m: tuple[float, float, float]
    velocity_ned_m_s: tuple[float, float, float]
    servo_us: tuple[int, ...]
    current_a: float
    voltage_v: float
    remaining_pct: int
    rc_channels: tuple[int, ...]
    throttle: float
    gain: float
    critical: bool
    has_position: bool
    clock_s: float = math.nan

    @property
    def time_boot_ms(self) -> int:
        return int(self.time_s * 1000.0) & 0xFFFFFFFF

    @property
    def time_usec(self) -> int:
        return int(self.time_s * 1e6)

    @property
    def euler_rad(self) -> tuple[float, float, float]:
        """(roll, pitch, yaw) [rad], yaw in (−π, π]."""
        return euler_from_quat(self.quaternion_wxyz)

    @property
    def heading_deg(self) -> float:
        """Heading [deg] in [0, 360)."""
        return math.degrees(self.euler_rad[2]) % 360.0


def read_vehicle(
    world: World,
    vehicle: Entity,
    *,
    time_s: float,
    velocity: VelocityEstimator,
    voltage_v: float,
    remaining_pct: int,
    rc_channels: tuple[int, ...],
    gain: float,
    critical: bool,
    servos: ServoOutputs,
    clock_s: float = math.nan,
) -> VehicleSnapshot:
    """Snapshot the vehicle-owned components of ``vehicle``, a state of time ``time_s`` [s]
    read at the endpoint's ``clock_s`` [s] (NaN: the same); the rest is the endpoint's
    (battery, RC inputs, gain, failsafe); ``servos`` puts the thrusters' pulses on ArduSub's
    servo outputs. ``velocity`` is folded the new position. Attitude:
    the IMU's, else the odometry's (a mirrored copy on shore). ArduSub's throttle is read from
    RC channel 3 (1100..1900 µs → 0..1)."""
    imu = world.get(vehicle, ImuReading)
    depth = world.get(vehicle, DepthReading)
    odometry = world.get(vehicle, Odometry)
    armed = world.get(vehicle, Armed)
    mode = world.get(vehicle, ActiveMode)
    output = world.get(vehicle, ThrusterOutput)
    if imu is not None:
        q = imu.quaternion_wxyz
    elif odometry is not None:  # a mirrored copy (shore gateway): the odometry's attitude
        q = odometry.quaternion_wxyz
    else:
        q = (1.0, 0.0, 0.0, 0.0)
    position = (0.0, 0.0, 0.0) if odometry is None else odometry.position_ned_m
    if depth is not None:
        position = (position[0], position[1], depth.depth_m)
    # rates: the IMU's, else (a mirrored copy on shore) from the odometry's attitudes
    velocity.update(time_s if odometry is None else odometry.sampled_s, position, q)
    return VehicleSnapshot(
        time_s=time_s,
        armed=armed is not None and armed.armed,
        custom_mode=int(mode.mode) if mode is not None else 19,
        quaternion_wxyz=q,
        rates_rad_s=velocity.rates_rad_s if imu is None else imu.rates_rad_s,
        depth_m=position[2],
        # a mirrored copy (shore gateway) has no reading: the pressure that gives its depth
        pressure_pa=ardusub_pressure_pa(position[2]) if depth is None else depth.pressure_pa,
        position_ned_m=position,
        velocity_ned_m_s=velocity.velocity_ned_m_s,
        servo_us=servos.pulses(() if output is None else output.pwm_us),
        current_a=math.nan if output is None else float(sum(output.currents_a)),
        voltage_v=voltage_v,
        remaining_pct=remaining_pct,
        rc_channels=rc_channels,
        throttle=min(1.0, max(0.0, (rc_channels[2] - 1100) / 800.0)),
        gain=gain,
        critical=critical,
        has_position=world.has(vehicle, PositionReading),
        clock_s=clock_s,
    )


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


def _global_position_int(s: VehicleSnapshot) -> mav.MAVLink_message:
    down = s.position_ned_m[2]
    lat, lon = position_e7(s)
    vn, ve, vd = s.velocity_ned_m_s
    return mav.MAVLink_global_position_int_message(
        s.time_boot_ms,
        lat,
        lon,
        round(-down * 1000.0),
        round(-down * 1000.0),
        _i16(vn * 100.0),
        _i16(ve * 100.0),
        _i16(vd * 100.0),
        round(s.heading_deg * 100.0) % 36000,
    )


def _home_position(s: VehicleSnapshot) -> mav.MAVLink_message:
    """The home: :data:`HOME_LAT_LON_DEG` at the surface (0 m), the local frame's origin."""
    del s
    lat0, lon0 = HOME_LAT_LON_DEG
    identity = (1.0, 0.0, 0.0, 0.0)
    return mav.MAVLink_home_position_message(
        round(lat0 * 1e7), round(lon0 * 1e7), 0, 0.0, 0.0, 0.0, identity, 0.0, 0.0, 0.0
    )


def _gps_global_origin(s: VehicleSnapshot) -> mav.MAVLink_message:
    """The local frame's origin on the globe (ArduSub 4.5's ORIGIN_LAT/LON/ALT): the home."""
    del s
    lat0, lon0 = HOME_LAT_LON_DEG
    return mav.MAVLink_gps_global_origin_message(round(lat0 * 1e7), round(lon0 * 1e7), 0)


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
