"""The vehicle at one instant, as the MAVLink endpoint reports it: read from the ECS world.

:func:`read_vehicle` takes one :class:`VehicleSnapshot` of what the vehicle owns and publishes
(:class:`~testbed.common.components.ImuReading`, ``DepthReading``, ``Odometry``, ``Armed``,
``ActiveMode``, ``ThrusterOutput``, ``PositionReading``) from a world, plus what the endpoint
itself keeps (battery, RC inputs, gain, failsafe); it reads components only, so a shore-side
gateway reading the operator's mirrored copies gets the same snapshot. :class:`VelocityEstimator`
differentiates the reported position and attitude, as a mirrored copy carries no velocity or
body rates of its own.

Frames (REFERENCE.md §4.3): world NED, body FRD; depth positive down. How a snapshot becomes
ArduSub's MAVLink messages (units, signs, ArduPilot's rounding) is :mod:`.telemetry`'s, not
this module's: nothing here encodes a message.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

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
from testbed.mavlink.motors import ServoOutputs

__all__ = ["VehicleSnapshot", "VelocityEstimator", "read_vehicle"]


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
