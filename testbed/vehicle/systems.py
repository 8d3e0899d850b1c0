"""The vehicle's ECS systems, in the ECS paper's three phases, and the resources they share.

Frame order (each a plain ``verb_noun(world) -> None``):

- PRE_UPDATE: :func:`read_sensors` (truth → sensor readings, at each sensor's rate),
  :func:`ingest_commands` (operator intents → armed, mode, targets, command status);
- UPDATE: :func:`supervise_failsafe` (stale commands → hold, then surface and disarm; runs
  first so every controller sees this frame's targets), :func:`run_pilot_interface`,
  :func:`control_depth`, :func:`control_attitude` (each writes its :class:`ForceIntent`),
  :func:`allocate_thrust` (Σ intents → allocator → thruster commands);
- POST_UPDATE: :func:`actuate_thrusters` (commands → thruster plant, stepped over the interval
  to the next frame → the wrench the physics applies, ``T @ actual forces``, recorded),
  :func:`meter_power` (actual forces → thruster current and energy drawn),
  :func:`publish_odometry` (sensor readings → the :class:`Odometry` the operator is sent).

A node adds its link systems around these (:func:`build_schedule`'s ``inbound``/``outbound``).

Controllers read only sensor readings (:class:`ImuReading`, :class:`DepthReading`); the
physics truth enters through :class:`PlantTruth` and only :func:`read_sensors` reads it (observers
of a run, such as the recorder, read it too, from outside the schedule's control path).
Controller objects and the allocator are mutable resources; components stay frozen values.

Size: over the 500-line guideline, kept whole: the systems run in this order in one frame and
share these resources; split, the frame's order would be read across files.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from testbed.common.geometry import (
    Quaternion,
    Vec3,
    quat_conjugate,
    quat_from_axis_angle,
    quat_multiply,
    quat_normalize,
    quat_rotate,
    yaw_only,
)
from testbed.ecs import Entity, Phase, Schedule, System, World
from testbed.vehicle.components import (
    ActiveMode,
    AppliedWrench,
    Armed,
    ArmRequest,
    AttitudeSetpoint,
    CommandStatus,
    ControlMode,
    ControlTargets,
    DepthReading,
    DepthSetpoint,
    FailsafeLevel,
    FailsafeStatus,
    ForceIntent,
    ImuReading,
    ModeRequest,
    MovementCommand,
    Odometry,
    PositionReading,
    ThrusterOutput,
)
from testbed.vehicle.control import (
    AttitudeController,
    DepthController,
    FailsafeConfig,
    PilotGains,
    failsafe_level,
    pilot_wrench,
    shape_stick,
)
from testbed.vehicle.sensors import DepthSensor, Imu, PositionFix

__all__ = [
    "Actuation",
    "ControlFlags",
    "Controllers",
    "PlantTruth",
    "PowerMeter",
    "SensorSuite",
    "SimClock",
    "actuate_thrusters",
    "allocate_thrust",
    "build_schedule",
    "control_attitude",
    "control_depth",
    "ingest_commands",
    "meter_power",
    "publish_odometry",
    "read_sensors",
    "run_pilot_interface",
    "supervise_failsafe",
    "wrench_of",
]

Wrench6 = tuple[float, float, float, float, float, float]
ZERO6: Wrench6 = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
LEVEL: Quaternion = (1.0, 0.0, 0.0, 0.0)
_ZERO_INTENTS = {source: ForceIntent(source, ZERO6) for source in ("pilot", "depth", "attitude")}
_LEVELS = (FailsafeLevel.NOMINAL, FailsafeLevel.HOLD, FailsafeLevel.SURFACE)  # by value


# ------------------------------------------------------------------------------ resources


@dataclass(slots=True)
class SimClock:
    """Vehicle time at this frame and the time since the previous frame [s]."""

    time_s: float = 0.0
    dt_s: float = 0.01


@dataclass(slots=True)
class PlantTruth:
    """The physics truth at this frame: for the sensors and for observers of the run (the
    recorder), never for the controllers.

    Attributes:
        quaternion_wxyz: (4,) attitude, body → NED.
        rates_rad_s: (3,) body rates (p, q, r), FRD.
        position_ned_m: (3,) body-origin position, NED [m] (depth = down component).
        velocity_m_s: (3,) body velocity (u, v, w) at the body origin [m/s], FRD.
    """

    quaternion_wxyz: Quaternion = LEVEL
    rates_rad_s: tuple[float, float, float] = (0.0, 0.0, 0.0)
    position_ned_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    velocity_m_s: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass(slots=True)
class PowerMeter:
    """The thrusters' electrical draw: what a battery monitor would read.

    Attributes:
        supply_voltage_v: the thrusters' supply [V].
        current_of: (n,) thruster forces [N] → total current [A] (the T200 model's).
        current_a: total current of this frame's actual forces [A].
        energy_j: energy drawn since the start [J], ``Σ current · voltage · dt``.
    """

    supply_voltage_v: float
    current_of: Callable[[Sequence[float]], float]
    current_a: float = 0.0
    energy_j: float = 0.0


@dataclass(slots=True)
class SensorSuite:
    """The vehicle's sensors (``position`` may be absent)."""

    imu: Imu
    depth: DepthSensor
    position: PositionFix | None = None


@dataclass(slots=True)
class ControlFlags:
    """What is in effect this frame (set by :func:`supervise_failsafe`, read by the loops)."""

    armed: bool = False
    depth_hold: bool = False
    attitude_hold: bool = False
    precision: bool = False
    failsafe: bool = False


@dataclass(slots=True)
class Controllers:
    """Controller objects and per-vehicle control settings.

    Attributes:
        vehicle: the vehicle's own entity (state components live there).
        attitude, depth: the closed loops.
        pilot: stick shaping and gains.
        failsafe: command-staleness failsafe timeouts.
        axis_maxima: (6,) allocator axis maxima [N, N·m] (stick scaling; 0 disables an axis).
        intents: the ForceIntent entity of each source (pilot, depth, attitude).
        sticks: the last accepted stick positions.
        last_contact_s: vehicle time of the last accepted operator intent [s].
        flags: the modes in effect this frame.
        shaped: the pilot interface's values for the current sticks and mode (a cache).
    """

    vehicle: Entity
    attitude: AttitudeController
    depth: DepthController
    pilot: PilotGains
    failsafe: FailsafeConfig
    axis_maxima: tuple[float, ...]
    intents: dict[str, Entity] = field(default_factory=dict)
    sticks: tuple[float, ...] = ZERO6
    last_contact_s: float = 0.0
    flags: ControlFlags = field(default_factory=ControlFlags)
    shaped: _ShapedSticks | None = None

    @property
    def attitude_axes(self) -> tuple[bool, bool, bool]:
        """Which of roll, pitch, yaw the thruster layout can torque (axis maximum > 0)."""
        m = self.axis_maxima
        return (m[3] > 0.0, m[4] > 0.0, m[5] > 0.0)


@dataclass(slots=True)
class Actuation:
    """The allocator, the thruster plant and the wrench handed to the physics.

    Attributes:
        allocator: an object with ``allocate_floats(wrench, dt_s)`` returning
            ``(forces_n, pwm_us, currents_a, scale)`` (see
            :meth:`~testbed.vehicle.allocation.Allocator.allocate_floats`), and ``reset()``.
        dynamics: the plant's thrusters:
            ``step_floats(commanded_forces (n,), dt_s) -> actual (n,)`` with a first-order lag
            of ``time_constant_s`` (plus faults).
        matrix_columns: per thruster, its (6,) column of the *physical* ``T`` (the plant's
            geometry, whatever the allocator believes).
        interval_s: time until the next frame [s] (the plant holds the command that long);
            set by the vehicle before each frame.
        commanded_forces_n: (n,) forces commanded this frame (0 when disarmed).
        commanded_pwm_us: (n,) the matching PWM [µs] (1500 when disarmed).
        actual_forces_n: (n,) the thrusters' actual forces at the end of the interval.
        requested: (6,) the summed intents of this frame.
        plant_wrench: (6,) the wrench the physics applies until the next frame [N, N·m], FRD.
        mean_weight: ``((interval_s, time_constant_s), c)``, the last weight of the interval's
            mean force (see :func:`actuate_thrusters`), kept while both stay the same.
    """

    allocator: Any
    dynamics: Any
    matrix_columns: tuple[tuple[float, ...], ...]
    interval_s: float = 0.01
    commanded_forces_n: tuple[float, ...] = ()
    commanded_pwm_us: tuple[float, ...] = ()
    actual_forces_n: tuple[float, ...] = ()
    requested: Wrench6 = ZERO6
    plant_wrench: Wrench6 = ZERO6
    mean_weight: tuple[tuple[float, float], float] = ((math.nan, math.nan), 0.5)

    def __post_init__(self) -> None:
        n = len(self.matrix_columns)
        if not self.commanded_forces_n:
            self.commanded_forces_n = (0.0,) * n
        if not self.commanded_pwm_us:
            self.commanded_pwm_us = (1500.0,) * n
        if not self.actual_forces_n:
            self.actual_forces_n = (0.0,) * n


# -------------------------------------------------------------------------------- helpers


def _is_armed(world: World, vehicle: Entity) -> bool:
    armed = world.get(vehicle, Armed)
    return armed is not None and armed.armed


def _update_flags(world: World, ctl: Controllers) -> None:
    """Work out the modes in effect this frame from the vehicle's state components."""
    vehicle = ctl.vehicle
    flags = ctl.flags
    mode = world.get(vehicle, ActiveMode)
    status = world.get(vehicle, FailsafeStatus)
    failsafe = status is not None and status.level is not FailsafeLevel.NOMINAL
    m = ControlMode.MANUAL if mode is None else mode.mode
    flags.armed = _is_armed(world, vehicle)
    flags.failsafe = failsafe
    flags.precision = mode is not None and mode.precision
    flags.depth_hold = failsafe or m is ControlMode.DEPTH_HOLD
    flags.attitude_hold = failsafe or m is not ControlMode.MANUAL


def _measured_targets(world: World, vehicle: Entity) -> ControlTargets:
    """Targets equal to what the sensors read now (level at the current heading)."""
    imu = world.get(vehicle, ImuReading)
    depth = world.get(vehicle, DepthReading)
    q = LEVEL if imu is None else yaw_only(imu.quaternion_wxyz)
    return ControlTargets(0.0 if depth is None else depth.depth_m, q)


def _set_intent(world: World, controllers: Controllers, source: str, wrench: Wrench6) -> None:
    intent = _ZERO_INTENTS.get(source) if wrench == ZERO6 else None
    if intent is None:
        intent = ForceIntent(source, wrench)
    world.set(controllers.intents[source], intent)


# ------------------------------------------------------------------------------ PRE_UPDATE


def read_sensors(world: World) -> None:
    """Sample each due sensor from the plant truth and store its reading on the vehicle."""
    clock = world.resource(SimClock)
    truth = world.resource(PlantTruth)
    sensors = world.resource(SensorSuite)
    vehicle = world.resource(Controllers).vehicle
    t = clock.time_s
    if sensors.imu.due(t):
        world.set(vehicle, sensors.imu.sample(t, truth.quaternion_wxyz, truth.rates_rad_s))
    if sensors.depth.due(t):
        world.set(vehicle, sensors.depth.sample(t, truth.position_ned_m[2]))
    if sensors.position is not None and sensors.position.due(t):
        world.set(vehicle, sensors.position.sample(t, truth.position_ned_m))


def ingest_commands(world: World) -> None:
    """Apply new operator intents: sticks (newer seq only), arm, mode and setpoints."""
    clock = world.resource(SimClock)
    ctl = world.resource(Controllers)
    vehicle = ctl.vehicle
    now = clock.time_s
    for _, cmd in world.query1(MovementCommand, changed=True):
        status = world.get(vehicle, CommandStatus)
        if status is None or cmd.seq > status.seq:
            world.set(vehicle, CommandStatus(cmd.seq, now, now - cmd.sampled_s))
            ctl.sticks = cmd.sticks
            ctl.last_contact_s = now
    for _, request in world.query1(ArmRequest, changed=True):
        ctl.last_contact_s = now
        was_armed = _is_armed(world, vehicle)
        world.set(vehicle, Armed(request.armed))
        if request.armed and not was_armed:
            world.set(vehicle, FailsafeStatus(FailsafeLevel.NOMINAL, now))
            if not world.has(vehicle, ControlTargets):
                world.set(vehicle, _measured_targets(world, vehicle))
    for _, mode in world.query1(ModeRequest, changed=True):
        ctl.last_contact_s = now
        previous = world.get(vehicle, ActiveMode)
        world.set(vehicle, ActiveMode(mode.mode, mode.precision))
        if previous is None or previous.mode is not mode.mode:
            # entering a hold mode holds the present depth, level at the present heading;
            # setpoints (applied below) override
            measured = _measured_targets(world, vehicle)
            targets = world.get(vehicle, ControlTargets) or measured
            if mode.mode is ControlMode.DEPTH_HOLD:
                targets = ControlTargets(measured.depth_m, targets.quaternion_wxyz)
            if mode.mode is not ControlMode.MANUAL:
                targets = ControlTargets(targets.depth_m, measured.quaternion_wxyz)
            world.set(vehicle, targets)
    for _, depth_sp in world.query1(DepthSetpoint, changed=True):
        ctl.last_contact_s = now
        targets = world.get(vehicle, ControlTargets) or _measured_targets(world, vehicle)
        world.set(vehicle, ControlTargets(depth_sp.depth_m, targets.quaternion_wxyz))
    for _, att_sp in world.query1(AttitudeSetpoint, changed=True):
        ctl.last_contact_s = now
        targets = world.get(vehicle, ControlTargets) or _measured_targets(world, vehicle)
        world.set(vehicle, ControlTargets(targets.depth_m, quat_normalize(att_sp.quaternion_wxyz)))


# --------------------------------------------------------------------------------- UPDATE


def supervise_failsafe(world: World) -> None:
    """Stale operator commands: hold depth and heading, then surface and disarm.

    The age is measured from the last accepted operator intent of any kind. HOLD clears when
    commands resume; SURFACE is latched until the vehicle disarms (at the surface). Also works
    out the modes in effect this frame (``Controllers.flags``) for the systems after it.
    """
    ctl = world.resource(Controllers)
    _supervise(world, ctl)
    _update_flags(world, ctl)


def _supervise(world: World, ctl: Controllers) -> None:
    clock = world.resource(SimClock)
    vehicle = ctl.vehicle
    now = clock.time_s
    status = world.get(vehicle, FailsafeStatus) or FailsafeStatus(FailsafeLevel.NOMINAL, now)
    if not _is_armed(world, vehicle):
        if status.level is not FailsafeLevel.NOMINAL:
            world.set(vehicle, FailsafeStatus(FailsafeLevel.NOMINAL, now))
        return
    level = _LEVELS[failsafe_level(now - ctl.last_contact_s, ctl.failsafe)]
    if status.level is FailsafeLevel.SURFACE:
        level = FailsafeLevel.SURFACE
    if level is not status.level:
        if level is not FailsafeLevel.NOMINAL and status.level is FailsafeLevel.NOMINAL:
            world.set(vehicle, _measured_targets(world, vehicle))
        status = FailsafeStatus(level, now)
        world.set(vehicle, status)
    if level is FailsafeLevel.SURFACE:
        targets = world.get(vehicle, ControlTargets) or _measured_targets(world, vehicle)
        depth = max(0.0, targets.depth_m - ctl.failsafe.ascent_rate_m_s * clock.dt_s)
        world.set(vehicle, ControlTargets(depth, targets.quaternion_wxyz))
        reading = world.get(vehicle, DepthReading)
        if reading is not None and reading.depth_m <= ctl.failsafe.surfaced_depth_m:
            world.set(vehicle, Armed(False))


def run_pilot_interface(world: World) -> None:
    """Sticks → pilot force intent; in hold modes the sticks also trim the targets."""
    ctl = world.resource(Controllers)
    flags = ctl.flags
    sticks = ZERO6 if flags.failsafe else ctl.sticks
    if not flags.armed or not any(sticks):
        _set_intent(world, ctl, "pilot", ZERO6)
        return
    vehicle = ctl.vehicle
    depth_hold, attitude_hold = flags.depth_hold, flags.attitude_hold
    shaped = ctl.shaped
    if (
        shaped is None
        or shaped.sticks is not sticks
        or shaped.modes != (flags.precision, depth_hold, attitude_hold)
        or shaped.axis_maxima is not ctl.axis_maxima
        or shaped.gains is not ctl.pilot
    ):
        shaped = ctl.shaped = _ShapedSticks(ctl, sticks)
    if depth_hold:  # translation in the level (yaw-only) frame, rotated into the body
        imu = world.get(vehicle, ImuReading)
        attitude = LEVEL if imu is None else imu.quaternion_wxyz
        level_to_body = quat_multiply(quat_conjugate(attitude), yaw_only(attitude))
        fx, fy, fz = quat_rotate(level_to_body, shaped.force)
        tx, ty, tz = shaped.torque
        _set_intent(world, ctl, "pilot", (fx, fy, fz, tx, ty, tz))
    else:
        world.set(ctl.intents["pilot"], shaped.intent)
    if not (depth_hold or attitude_hold):
        return
    targets = world.get(vehicle, ControlTargets) or _measured_targets(world, vehicle)
    depth_m, q = targets.depth_m, targets.quaternion_wxyz
    dt = world.resource(SimClock).dt_s
    if depth_hold:
        depth_m = max(0.0, depth_m + shaped.depth_trim * dt)
    if attitude_hold:
        roll_trim, pitch_trim, yaw_trim = shaped.attitude_trims
        roll = roll_trim * dt
        pitch = pitch_trim * dt
        yaw = yaw_trim * dt
        if roll or pitch:  # about the target's own body axes
            angle = math.hypot(roll, pitch)
            q = quat_multiply(q, quat_from_axis_angle((roll / angle, pitch / angle, 0.0), angle))
        if yaw:  # about world down
            q = quat_multiply(quat_from_axis_angle((0.0, 0.0, 1.0), yaw), q)
        q = quat_normalize(q)
    world.set(vehicle, ControlTargets(depth_m, q))


class _ShapedSticks:
    """What the pilot interface derives from one set of sticks in one mode (kept while the
    sticks, the mode, the axis maxima and the gains stay the same: sticks change at the
    operator's rate, frames run at the control rate).

    The arithmetic is :func:`~testbed.vehicle.control.pilot_wrench`'s and the trims' own,
    operation for operation, so the results are identical; only the repetition is saved.
    """

    __slots__ = (
        "attitude_trims",
        "axis_maxima",
        "depth_trim",
        "force",
        "gains",
        "intent",
        "modes",
        "sticks",
        "torque",
    )

    def __init__(self, ctl: Controllers, sticks: tuple[float, ...]) -> None:
        flags = ctl.flags
        precision, depth_hold, attitude_hold = (
            flags.precision,
            flags.depth_hold,
            flags.attitude_hold,
        )
        gains = ctl.pilot
        self.sticks = sticks
        self.modes = (precision, depth_hold, attitude_hold)
        self.axis_maxima = ctl.axis_maxima
        self.gains = gains
        # pilot_wrench, without the rotation into the body (per frame, from the IMU)
        wrench = pilot_wrench(
            sticks,
            ctl.axis_maxima,
            LEVEL,
            gains=gains,
            precision=precision,
            depth_hold=False,
            attitude_hold=attitude_hold,
        )
        scale = gains.precision_scale if precision else gains.normal_scale
        dz = gains.dead_zone
        if depth_hold:  # pilot_wrench's depth-hold force gains, still in the level frame
            u = [shape_stick(sticks[k], scale, dz) * ctl.axis_maxima[k] for k in range(3)]
            tg = (
                gains.depth_hold_translation_precision
                if precision
                else gains.depth_hold_translation
            )
            self.force: Vec3 = (u[0] * tg[0], u[1] * tg[1], u[2] * tg[2])
        else:
            self.force = (wrench[0], wrench[1], wrench[2])
        self.torque: Vec3 = (wrench[3], wrench[4], wrench[5])
        self.intent = ForceIntent("pilot", wrench)
        # trim rates at these sticks: shape · rate (× dt per frame)
        self.depth_trim = (
            shape_stick(sticks[2], 1.0, dz) * gains.depth_trim_m_s[1 if precision else 0]
        )
        rates = gains.attitude_trim_precision_rad_s if precision else gains.attitude_trim_rad_s
        self.attitude_trims: Vec3 = (
            shape_stick(sticks[3], 1.0, dz) * rates[0],
            shape_stick(sticks[4], 1.0, dz) * rates[1],
            shape_stick(sticks[5], 1.0, dz) * rates[2],
        )


def control_depth(world: World) -> None:
    """Depth hold → world-vertical force intent rotated into the body frame."""
    clock = world.resource(SimClock)
    ctl = world.resource(Controllers)
    vehicle = ctl.vehicle
    reading = world.get(vehicle, DepthReading)
    imu = world.get(vehicle, ImuReading)
    targets = world.get(vehicle, ControlTargets)
    flags = ctl.flags
    if not (flags.armed and flags.depth_hold) or None in (reading, imu, targets):
        ctl.depth.reset()
        _set_intent(world, ctl, "depth", ZERO6)
        return
    assert reading is not None and imu is not None and targets is not None
    fx, fy, fz = ctl.depth.update(targets.depth_m, reading.depth_m, imu.quaternion_wxyz, clock.dt_s)
    _set_intent(world, ctl, "depth", (fx, fy, fz, 0.0, 0.0, 0.0))


def control_attitude(world: World) -> None:
    """Attitude hold → body torque intent (axes the thrusters cannot torque stay off)."""
    clock = world.resource(SimClock)
    ctl = world.resource(Controllers)
    vehicle = ctl.vehicle
    imu = world.get(vehicle, ImuReading)
    targets = world.get(vehicle, ControlTargets)
    flags = ctl.flags
    if not (flags.armed and flags.attitude_hold) or imu is None or targets is None:
        ctl.attitude.reset()
        _set_intent(world, ctl, "attitude", ZERO6)
        return
    tx, ty, tz = ctl.attitude.update(
        targets.quaternion_wxyz,
        imu.quaternion_wxyz,
        imu.rates_rad_s,
        clock.dt_s,
        ctl.attitude_axes,
    )
    _set_intent(world, ctl, "attitude", (0.0, 0.0, 0.0, tx, ty, tz))


def allocate_thrust(world: World) -> None:
    """Σ force intents → allocator → per-thruster commands (all off when disarmed)."""
    clock = world.resource(SimClock)
    ctl = world.resource(Controllers)
    act = world.resource(Actuation)
    n = len(act.matrix_columns)
    if not ctl.flags.armed:
        act.allocator.reset()  # re-arming slews up from 0 N
        act.requested = ZERO6
        act.commanded_forces_n = (0.0,) * n
        act.commanded_pwm_us = (1500.0,) * n
        world.set(ctl.vehicle, ThrusterOutput((0.0,) * n, (1500.0,) * n, (0.0,) * n, 1.0))
        return
    x = y = z = k = m = nn = 0.0
    for _, intent in world.query1(ForceIntent):
        w = intent.wrench
        x += w[0]
        y += w[1]
        z += w[2]
        k += w[3]
        m += w[4]
        nn += w[5]
    act.requested = (x, y, z, k, m, nn)
    forces, pwm, currents, scale = act.allocator.allocate_floats(act.requested, clock.dt_s)
    act.commanded_forces_n = forces
    act.commanded_pwm_us = pwm
    world.set(ctl.vehicle, ThrusterOutput(forces, pwm, currents, scale))


# ---------------------------------------------------------------------------- POST_UPDATE


def actuate_thrusters(world: World) -> None:
    """Step the thruster plant over the coming interval; hand its wrench to the physics.

    The command is held until the next frame, so the plant's first-order lag is stepped once,
    exactly, over ``Actuation.interval_s``. The physics applies, at each of its steps in that
    interval, the wrench of the interval's *mean* thruster forces, which gives exactly the
    impulse the lagged forces deliver: with ``e = exp(−h/τ)``, a force going from ``F0`` to
    ``F1`` over ``h`` averages ``F0 + (F1 − F0)·(1/(1 − e) − τ/h)``. Faulty thrusters are
    whatever the plant makes them; the wrench is ``T @ mean actual forces``, not the request.
    """
    ctl = world.resource(Controllers)
    act = world.resource(Actuation)
    h = act.interval_s
    f0 = act.actual_forces_n
    f1 = act.dynamics.step_floats(act.commanded_forces_n, h)
    tau = act.dynamics.time_constant_s
    key = (h, tau)
    if act.mean_weight[0] == key:  # the interval is almost always the same
        c = act.mean_weight[1]
    else:
        e = math.exp(-h / tau) if tau > 0.0 else 0.0
        c = 1.0 / (1.0 - e) - tau / h if e < 1.0 else 0.5
        act.mean_weight = (key, c)
    act.actual_forces_n = f1
    mean = [a + (b - a) * c for a, b in zip(f0, f1, strict=True)]
    act.plant_wrench = wrench_of(mean, act.matrix_columns)
    world.set(ctl.vehicle, AppliedWrench(act.requested, act.plant_wrench))


def meter_power(world: World) -> None:
    """POST_UPDATE: the current of the thrusters' actual forces, and the energy it draws over
    the time since the last frame."""
    meter = world.resource(PowerMeter)
    current = meter.current_of(world.resource(Actuation).actual_forces_n)
    meter.current_a = current
    meter.energy_j += current * meter.supply_voltage_v * world.resource(SimClock).dt_s


def wrench_of(forces_n: Sequence[float], columns: Sequence[Sequence[float]]) -> Wrench6:
    """``T @ forces`` as a (6,) tuple [N, N·m], body FRD (scalar loop: n is small)."""
    x = y = z = k = m = n = 0.0
    for f, col in zip(forces_n, columns, strict=True):
        if f:
            x += f * col[0]
            y += f * col[1]
            z += f * col[2]
            k += f * col[3]
            m += f * col[4]
            n += f * col[5]
    return (x, y, z, k, m, n)


# ------------------------------------------------------------------------------ schedule


def publish_odometry(world: World) -> None:
    """POST_UPDATE: the vehicle's own estimate for the operator, from its sensors only.

    Position: the position fix when fitted (else north and east 0) with the depth sensor's
    depth; attitude: the IMU's. Written only when a reading changed.
    """
    vehicle = world.resource(Controllers).vehicle
    imu = world.get(vehicle, ImuReading)
    depth = world.get(vehicle, DepthReading)
    if imu is None or depth is None:
        return
    fix = world.get(vehicle, PositionReading)
    north, east = (0.0, 0.0) if fix is None else fix.position_ned_m[:2]
    sampled_s = max(imu.time_s, depth.time_s)
    position = (north, east, depth.depth_m)
    world.set(vehicle, Odometry(sampled_s, position, imu.quaternion_wxyz))


def build_schedule(inbound: Sequence[System] = (), outbound: Sequence[System] = ()) -> Schedule:
    """The vehicle frame: sensors and inbound commands; failsafe, pilot, loops, allocation;
    actuation and odometry.

    Args:
        inbound: link systems run first in PRE_UPDATE (they write the operator's intents the
            frames brought, before :func:`ingest_commands` reads them).
        outbound: link or recording systems run last in POST_UPDATE.
    """
    schedule = Schedule()
    for system in inbound:
        schedule.add(Phase.PRE_UPDATE, system)
    schedule.add(Phase.PRE_UPDATE, read_sensors)
    schedule.add(Phase.PRE_UPDATE, ingest_commands)
    schedule.add(Phase.UPDATE, supervise_failsafe)
    schedule.add(Phase.UPDATE, run_pilot_interface)
    schedule.add(Phase.UPDATE, control_depth)
    schedule.add(Phase.UPDATE, control_attitude)
    schedule.add(Phase.UPDATE, allocate_thrust)
    schedule.add(Phase.POST_UPDATE, actuate_thrusters)
    schedule.add(Phase.POST_UPDATE, meter_power)
    schedule.add(Phase.POST_UPDATE, publish_odometry)
    for system in outbound:
        schedule.add(Phase.POST_UPDATE, system)
    return schedule
