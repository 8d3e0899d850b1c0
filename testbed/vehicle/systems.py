"""The vehicle's ECS systems, in the ECS paper's three phases, and the resources they share.

Frame order (each a plain ``verb_noun(world) -> None``):

- PRE_UPDATE: :func:`read_sensors` (truth → sensor readings, at each sensor's rate),
  :func:`ingest_commands` (operator intents → armed, mode, targets, command status);
- UPDATE: :func:`supervise_failsafe` (stale commands → hold, then surface and disarm; runs
  first so every controller sees this frame's targets), :func:`run_pilot_interface`,
  :func:`control_position` (GUIDED only), :func:`control_depth`, :func:`control_attitude`
  (each writes its :class:`ForceIntent`),
  :func:`allocate_thrust` (Σ intents → allocator → thruster commands);
- POST_UPDATE: :func:`actuate_thrusters` (commands → thruster plant, stepped over the interval
  to the next frame → the wrench the physics applies, ``T @ actual forces``, recorded),
  :func:`meter_power` (actual forces → thruster current and energy drawn),
  :func:`publish_odometry` (sensor readings → the :class:`Odometry` the operator is sent).

A node adds its link systems around these (:func:`build_schedule`'s ``inbound``/``outbound``).

Controllers read only sensor readings (:class:`ImuReading`, :class:`DepthReading`,
:class:`PositionReading`); the
physics truth enters through :class:`PlantTruth` and only :func:`read_sensors` reads it (observers
of a run, such as the recorder, read it too, from outside the schedule's control path).
Controller objects and the allocator are mutable resources; components stay frozen values.

The frame's own components (the sensor readings, the control targets, the force intents, the
thruster output, the applied wrench, the odometry) live in the vehicle's frame store
(:mod:`testbed.ecs.store`): the world shows them as frozen components with change ticks, and
the systems' compiled kernels write their rows directly (the sensors' models, the pilot
interface, the depth and attitude loops, the allocation, the thrusters, the odometry), each
system a short shell around its kernel. The event systems (ingest, failsafe, the position
loop, the autonomy's) set components from Python as before. A row is found with
:func:`vehicle_row` once the vehicle has the component; rows are never freed (the vehicle's
components are never removed).

Size: over the 500-line guideline, kept whole: the systems run in this order in one frame and
share these resources; split, the frame's order would be read across files.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from testbed.common import jit
from testbed.common.geometry import (
    Quaternion,
    euler_from_quat,
    quat_from_euler,
    quat_normalize,
    yaw_only,
)
from testbed.common.jit import BOOL, F64, I64, MARK, VECTOR, floats
from testbed.ecs import Entity, Phase, Schedule, System, World
from testbed.ecs.store import Layout, RowView, Table
from testbed.vehicle.allocation import Allocator
from testbed.vehicle.components import (
    ActiveMode,
    Armed,
    ArmRequest,
    AttitudeSetpoint,
    CommandStatus,
    ControlMode,
    ControlTargets,
    DepthReading,
    DepthSetpoint,
    EndEffectorSetpoint,
    FailsafeLevel,
    FailsafeStatus,
    GoalCancel,
    ImuReading,
    ModeRequest,
    MovementCommand,
    Odometry,
    PoseTarget,
    PositionReading,
    PositionSetpoint,
    ThrusterOutput,
)
from testbed.vehicle.control import (
    AttitudeController,
    DepthController,
    FailsafeConfig,
    failsafe_level,
)
from testbed.vehicle.control_kernels import (
    pilot_rows,
    pilot_shape,
    put_attitude_target,
    put_depth_target,
    put_targets,
)
from testbed.vehicle.guidance import PositionController
from testbed.vehicle.mission import MAX_POSITION_M
from testbed.vehicle.pilot import (
    SURFACE_HOLD_DEPTH_M,
    PilotGains,
    level_to_body,
    pilot_gains_array,
)
from testbed.vehicle.sensor_kernels import odometry_rows
from testbed.vehicle.sensors import DepthSensor, Imu, PositionFix
from testbed.vehicle.thrust_kernels import interval_wrench, put_wrench
from testbed.vehicle.thrusters import ThrusterDynamics

MAX_SETPOINT_DEPTH_M = MAX_POSITION_M
"""Deepest depth setpoint the vehicle takes [m] (the world's extent, as for positions)."""

__all__ = [
    "MAX_SETPOINT_DEPTH_M",
    "Actuation",
    "ControlFlags",
    "Controllers",
    "PlantTruth",
    "PowerMeter",
    "SensorSuite",
    "SimClock",
    "actuate_thrusters",
    "allocate_thrust",
    "applied_sticks",
    "build_schedule",
    "control_attitude",
    "control_depth",
    "control_position",
    "ingest_commands",
    "mean_force_weight",
    "meter_power",
    "publish_odometry",
    "read_sensors",
    "run_pilot_interface",
    "set_intent",
    "set_targets",
    "shaped_sticks",
    "supervise_failsafe",
    "vehicle_row",
    "wrench_of",
]

Wrench6 = tuple[float, float, float, float, float, float]
ZERO6: Wrench6 = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
LEVEL: Quaternion = (1.0, 0.0, 0.0, 0.0)
_ODOMETRY = Layout(Odometry(0.0, (0.0, 0.0, 0.0), LEVEL))
_UNUSED_TARGETS = RowView.detached(Layout(ControlTargets(0.0, LEVEL)).width)
"""The pilot kernel's targets row outside the hold modes (neither read nor written then)."""
_LEVEL_IMU = np.array([0.0, *LEVEL, 0.0, 0.0, 0.0])
"""An ImuReading row reading level (the pilot's attitude before the IMU's first reading)."""
_LEVELS = (FailsafeLevel.NOMINAL, FailsafeLevel.HOLD, FailsafeLevel.SURFACE)  # by value
_FLAG_TYPES = (Armed, ActiveMode, FailsafeStatus)
"""What the modes in effect follow from (:func:`_update_flags`)."""
_INTENT_TYPES = (MovementCommand, ArmRequest, ModeRequest, DepthSetpoint, AttitudeSetpoint)
_GOAL_TYPES = (PositionSetpoint, EndEffectorSetpoint, GoalCancel)
"""Operator orders read by the position loop or the mission tree: contact too (a GoTo that
took a stick order's slot must not look like a silent link to the failsafe)."""
"""What :func:`ingest_commands` reacts to."""
# The systems' kernels, called without numba's dispatcher (testbed.common.jit.entry): rows and
# marks are the store's contiguous float64/int64 vectors, the rest floats, bools and tuples.
_PUT_WRENCH = jit.entry(put_wrench, VECTOR, MARK, I64, *(F64,) * 6)
_PUT_TARGETS = jit.entry(put_targets, VECTOR, MARK, I64, F64, floats(4))
_PUT_DEPTH_TARGET = jit.entry(put_depth_target, VECTOR, MARK, I64, F64)
_PUT_ATTITUDE_TARGET = jit.entry(put_attitude_target, VECTOR, MARK, I64, floats(4))
_PILOT_MODE = (floats(6), floats(6), VECTOR, BOOL, BOOL, BOOL)  # sticks, maxima, gains, flags
_PILOT_ROWS = jit.entry(pilot_rows, *_PILOT_MODE, VECTOR, VECTOR, F64, VECTOR, MARK, MARK, I64)
_PILOT_SHAPE = jit.entry(pilot_shape, *_PILOT_MODE)
_ODOMETRY_ROWS = jit.entry(odometry_rows, VECTOR, VECTOR, VECTOR, BOOL, VECTOR, MARK, I64)


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
        acceleration_ned_m_s2: (3,) mean NED acceleration of the body origin over the last
            frame interval [m/s²] (the NED velocity's change over it; kept only for a vehicle
            with an accelerometer, else zero).
    """

    quaternion_wxyz: Quaternion = LEVEL
    rates_rad_s: tuple[float, float, float] = (0.0, 0.0, 0.0)
    position_ned_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    velocity_m_s: tuple[float, float, float] = (0.0, 0.0, 0.0)
    acceleration_ned_m_s2: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass(slots=True)
class PowerMeter:
    """The thrusters' electrical draw: what a battery monitor would read.

    Attributes:
        supply_voltage_v: the thrusters' supply [V].
        current_of: (n,) float64 thruster forces [N] → total current [A] (the T200 model's,
            :meth:`~testbed.vehicle.t200.T200.total_current_a`).
        current_a: total current of this frame's actual forces [A].
        energy_j: energy drawn since the start [J], ``Σ current · voltage · dt``.
    """

    supply_voltage_v: float
    current_of: Callable[[np.ndarray], float]
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
    guided: bool = False
    velocity: bool = False


@dataclass(slots=True)
class Controllers:
    """Controller objects and per-vehicle control settings.

    Attributes:
        vehicle: the vehicle's own entity (state components live there).
        attitude, depth: the closed loops.
        position: GUIDED mode's horizontal position loop.
        pilot: stick shaping and gains.
        failsafe: command-staleness failsafe timeouts.
        axis_maxima: (6,) allocator axis maxima [N, N·m] (stick scaling; 0 disables an axis).
        intents: the ForceIntent entity of each source (pilot, depth, attitude, position).
        intent_rows: each source's ForceIntent row (:func:`set_intent` writes it).
        rows: the vehicle's own store-backed components' rows, by type, from the first time a
            system asks for one the vehicle has (:func:`vehicle_row`).
        sticks: the last accepted stick positions.
        last_contact_s: vehicle time of the last accepted operator intent [s].
        flags: the modes in effect this frame.
        flags_tick: the world tick they were last worked out at (0: never).
        ignored_setpoints: operator setpoints that could not be applied (a depth that is not a
            number in [0, :data:`MAX_SETPOINT_DEPTH_M`] m, an attitude that is not finite or of zero
            norm), counted and otherwise ignored (the targets stay as they were).
        pilot_gains: ``pilot`` as the pilot interface's kernel reads it
            (:func:`~testbed.vehicle.pilot.pilot_gains_array`; fixed at construction, as
            ``pilot`` is).
        autonomous: the vehicle flies itself (:mod:`testbed.vehicle.autonomy`): it owns its
            mode (operator mode requests are not applied) and a link HOLD keeps GUIDED flying.
        velocity_control: in GUIDED the autonomy's velocity controller (the ISMC) flies all
            six axes; the depth, attitude and position loops stand down.
    """

    vehicle: Entity
    attitude: AttitudeController
    depth: DepthController
    pilot: PilotGains
    failsafe: FailsafeConfig
    axis_maxima: tuple[float, ...]
    intents: dict[str, Entity] = field(default_factory=dict)
    intent_rows: dict[str, RowView] = field(default_factory=dict)
    rows: dict[type, RowView] = field(default_factory=dict)
    sticks: tuple[float, ...] = ZERO6
    last_contact_s: float = 0.0
    flags: ControlFlags = field(default_factory=ControlFlags)
    flags_tick: int = 0
    ignored_setpoints: int = 0
    pilot_gains: np.ndarray = field(init=False)
    position: PositionController = field(default_factory=PositionController)
    autonomous: bool = False
    velocity_control: bool = False

    def __post_init__(self) -> None:
        self.pilot_gains = pilot_gains_array(self.pilot)

    @property
    def attitude_axes(self) -> tuple[bool, bool, bool]:
        """Which of roll, pitch, yaw the thruster layout can torque (axis maximum > 0)."""
        m = self.axis_maxima
        return (m[3] > 0.0, m[4] > 0.0, m[5] > 0.0)


@dataclass(slots=True)
class Actuation:
    """The allocator, the thruster plant and the wrench handed to the physics.

    Attributes:
        allocator: the controller's allocation (:meth:`~.Allocator.step_rows` per frame).
        dynamics: the plant's thrusters (first-order lag of ``time_constant_s``, faults).
        matrix: (6, n) the *physical* configuration ``T`` [N, N·m per N], body FRD (the
            plant's geometry, whatever the allocator believes).
        intents: the store's :class:`ForceIntent` table (the frame's intents, summed by row).
        output: the vehicle's :class:`ThrusterOutput` row, written by the allocation.
        applied: the vehicle's :class:`AppliedWrench` row, written by the actuation.
        interval_s: time until the next frame [s] (the plant holds the command that long);
            set by the vehicle before each frame.
        commanded_forces_n: (n,) forces commanded this frame [N] (0 when disarmed; written in
            place by the allocation).
        actual_forces_n: (n,) the thrusters' actual forces [N] (the plant's own array,
            :attr:`~.ThrusterDynamics.live_forces_n`: at the end of the interval once actuated).
        requested: (6,) the summed intents of this frame [N, N·m].
        plant_wrench: (6,) the wrench the physics applies until the next frame [N, N·m], FRD
            (the plant's :attr:`~.physics.Physics.held_wrench`, written in place).
        mean_weight: ``((interval_s, time_constant_s), c)``, the last weight of the interval's
            mean force (see :func:`actuate_thrusters`), kept while both stay the same.
    """

    allocator: Allocator
    dynamics: ThrusterDynamics
    matrix: np.ndarray
    intents: Table
    output: RowView
    applied: RowView
    interval_s: float = 0.01
    commanded_forces_n: np.ndarray = field(default_factory=lambda: np.zeros(0))
    requested: np.ndarray = field(default_factory=lambda: np.zeros(6))
    plant_wrench: np.ndarray = field(default_factory=lambda: np.zeros(6))
    mean_weight: tuple[tuple[float, float], float] = ((math.nan, math.nan), 0.5)

    def __post_init__(self) -> None:
        self.matrix = np.ascontiguousarray(self.matrix, dtype=np.float64)
        n = self.matrix.shape[1]
        if self.commanded_forces_n.size == 0:
            self.commanded_forces_n = np.zeros(n)
        # compiled (or loaded) now, not in the first frame of a timed run (pure: no state)
        interval_wrench(self.matrix, self.actual_forces_n, self.actual_forces_n, 0.0)

    @property
    def actual_forces_n(self) -> np.ndarray:
        return self.dynamics.live_forces_n


# -------------------------------------------------------------------------------- helpers


def _is_armed(world: World, vehicle: Entity) -> bool:
    armed = world.get(vehicle, Armed)
    return armed is not None and armed.armed


def _update_flags(world: World, ctl: Controllers) -> None:
    """Work out the modes in effect this frame from the vehicle's state components (again
    only after one of them changed)."""
    if ctl.flags_tick and not world.changed_any(*_FLAG_TYPES, since=ctl.flags_tick):
        return
    ctl.flags_tick = world.tick
    vehicle = ctl.vehicle
    flags = ctl.flags
    mode = world.get(vehicle, ActiveMode)
    status = world.get(vehicle, FailsafeStatus)
    failsafe = status is not None and status.level is not FailsafeLevel.NOMINAL
    m = ControlMode.MANUAL if mode is None else mode.mode
    flags.armed = _is_armed(world, vehicle)
    flags.failsafe = failsafe
    flags.precision = mode is not None and mode.precision
    # under autonomy a link HOLD keeps the mission flying; SURFACE never does
    link_hold = status is not None and status.level is FailsafeLevel.HOLD
    holding = failsafe and not (ctl.autonomous and link_hold)
    flags.guided = not holding and m is ControlMode.GUIDED
    flags.velocity = flags.guided and ctl.velocity_control
    loops = not flags.velocity
    flags.depth_hold = loops and (failsafe or m in (ControlMode.DEPTH_HOLD, ControlMode.GUIDED))
    flags.attitude_hold = loops and (failsafe or m is not ControlMode.MANUAL)


def _measured_targets(world: World, vehicle: Entity) -> ControlTargets:
    """Targets equal to what the sensors read now (level at the current heading)."""
    imu = world.get(vehicle, ImuReading)
    depth = world.get(vehicle, DepthReading)
    q = LEVEL if imu is None else yaw_only(imu.quaternion_wxyz)
    return ControlTargets(0.0 if depth is None else depth.depth_m, q)


def vehicle_row(world: World, ctl: Controllers, cls: type) -> RowView | None:
    """The vehicle's ``cls`` row, or None while it has no ``cls``, and None in a world that
    does not keep ``cls`` in a frame store (the frame's systems need the vehicle's store, which
    :class:`~testbed.vehicle.vehicle.Vehicle` makes; a system that also sets its component from
    Python, such as the navigation filter's position reading, then does only that).

    The vehicle's store-backed components are never removed, so a row once found stays valid.
    """
    row = ctl.rows.get(cls)
    if row is None and world.has(ctl.vehicle, cls):
        try:
            row = ctl.rows[cls] = world.row_view(ctl.vehicle, cls)
        except LookupError:  # not store-backed in this world
            return None
    return row


def set_targets(
    world: World, ctl: Controllers, depth_m: float, quaternion_wxyz: Quaternion
) -> None:
    """The vehicle's :class:`ControlTargets` (depth [m, + down], attitude body → NED): set as
    its component the first time, then written into its row
    (:func:`~.control_kernels.put_targets`; a change only when they differ)."""
    row = vehicle_row(world, ctl, ControlTargets)
    if row is None:
        world.set(ctl.vehicle, ControlTargets(depth_m, quaternion_wxyz))
    else:
        _PUT_TARGETS(row.values, row.mark, world.tick, depth_m, quaternion_wxyz)


def _set_depth_target(world: World, ctl: Controllers, depth_m: float) -> None:
    """:func:`set_targets` of an operator's depth setpoint [m, + down] (no shallower than
    :data:`~testbed.vehicle.pilot.SURFACE_HOLD_DEPTH_M`), the attitude target kept."""
    depth_m = max(SURFACE_HOLD_DEPTH_M, depth_m)
    row = vehicle_row(world, ctl, ControlTargets)
    if row is None:
        targets = world.get(ctl.vehicle, ControlTargets) or _measured_targets(world, ctl.vehicle)
        set_targets(world, ctl, depth_m, targets.quaternion_wxyz)
    else:
        _PUT_DEPTH_TARGET(row.values, row.mark, world.tick, depth_m)


def _set_attitude_target(world: World, ctl: Controllers, quaternion_wxyz: Quaternion) -> None:
    """:func:`set_targets` of a new attitude target (body → NED), the depth target kept."""
    row = vehicle_row(world, ctl, ControlTargets)
    if row is None:
        targets = world.get(ctl.vehicle, ControlTargets) or _measured_targets(world, ctl.vehicle)
        set_targets(world, ctl, targets.depth_m, quaternion_wxyz)
    else:
        _PUT_ATTITUDE_TARGET(row.values, row.mark, world.tick, quaternion_wxyz)


def set_intent(world: World, controllers: Controllers, source: str, wrench: Wrench6) -> None:
    """Write ``source``'s :class:`ForceIntent` wrench [N, N·m], FRD, into its row (a change
    only when it differs)."""
    row = controllers.intent_rows[source]
    _PUT_WRENCH(row.values, row.mark, world.tick, *wrench)


# ------------------------------------------------------------------------------ PRE_UPDATE


def read_sensors(world: World) -> None:
    """Sample each due sensor from the plant truth and store its reading on the vehicle.

    A sensor's first reading is set as a component; later ones are written into its row.
    """
    t = world.resource(SimClock).time_s
    truth = world.resource(PlantTruth)
    sensors = world.resource(SensorSuite)
    ctl = world.resource(Controllers)
    tick = world.tick
    imu = sensors.imu
    if imu.due(t):
        row = vehicle_row(world, ctl, ImuReading)
        if row is not None:
            imu.sample_into(t, truth.quaternion_wxyz, truth.rates_rad_s, row, tick)
        else:
            world.set(ctl.vehicle, imu.sample(t, truth.quaternion_wxyz, truth.rates_rad_s))
    depth = sensors.depth
    if depth.due(t):
        row = vehicle_row(world, ctl, DepthReading)
        if row is not None:
            depth.sample_into(t, truth.position_ned_m[2], row, tick)
        else:
            world.set(ctl.vehicle, depth.sample(t, truth.position_ned_m[2]))
    fix = sensors.position
    if fix is not None and fix.due(t):
        row = vehicle_row(world, ctl, PositionReading)
        if row is not None:
            fix.sample_into(t, truth.position_ned_m, row, tick)
        else:
            world.set(ctl.vehicle, fix.sample(t, truth.position_ned_m))


def ingest_commands(world: World) -> None:
    """Apply new operator intents: sticks (newer seq only), arm, mode and setpoints."""
    if not world.changed_any(*_INTENT_TYPES, *_GOAL_TYPES):  # most frames: nothing new arrived
        return
    clock = world.resource(SimClock)
    ctl = world.resource(Controllers)
    vehicle = ctl.vehicle
    now = clock.time_s
    if world.changed_any(*_GOAL_TYPES):
        ctl.last_contact_s = now  # a goal order (the loops and the tree read it themselves)
    for _, cmd in world.query1(MovementCommand, changed=True):
        status = world.get(vehicle, CommandStatus)
        # newer, or the first after a silence past the hold timeout: a restarted sender, or a
        # sequence number a corrupted payload pushed far ahead (2**63 − 1 locked the pilot out)
        resync = status is not None and now - status.received_s > ctl.failsafe.hold_after_s
        if status is None or cmd.seq > status.seq or resync:
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
                measured = _measured_targets(world, vehicle)
                set_targets(world, ctl, measured.depth_m, measured.quaternion_wxyz)
    for _, mode in world.query1(ModeRequest, changed=True):
        ctl.last_contact_s = now
        if ctl.autonomous:
            continue  # the autonomy owns the mode
        previous = world.get(vehicle, ActiveMode)
        world.set(vehicle, ActiveMode(mode.mode, mode.precision))
        if previous is None or previous.mode is not mode.mode:
            # entering a hold mode holds the present depth, level at the present heading;
            # setpoints (applied below) override
            measured = _measured_targets(world, vehicle)
            targets = world.get(vehicle, ControlTargets) or measured
            if mode.mode in (ControlMode.DEPTH_HOLD, ControlMode.GUIDED):
                targets = ControlTargets(measured.depth_m, targets.quaternion_wxyz)
            if mode.mode is not ControlMode.MANUAL:
                targets = ControlTargets(targets.depth_m, measured.quaternion_wxyz)
            set_targets(world, ctl, targets.depth_m, targets.quaternion_wxyz)
    for _, depth_sp in world.query1(DepthSetpoint, changed=True):
        ctl.last_contact_s = now
        if not 0.0 <= depth_sp.depth_m <= MAX_SETPOINT_DEPTH_M:  # NaN, inf, above the surface
            ctl.ignored_setpoints += 1  # a value from the link, not an error
            continue
        _set_depth_target(world, ctl, depth_sp.depth_m)
    for _, att_sp in world.query1(AttitudeSetpoint, changed=True):
        ctl.last_contact_s = now
        try:
            if not all(math.isfinite(c) for c in att_sp.quaternion_wxyz):
                raise ValueError("not finite")
            attitude = quat_normalize(att_sp.quaternion_wxyz)
        except ValueError:  # a zero or non-finite quaternion from the link: a value
            ctl.ignored_setpoints += 1
            continue
        _set_attitude_target(world, ctl, attitude)


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
        # from here: the loops' targets start from what the sensors read (also entering SURFACE
        # under autonomy, whose mission flew on through the HOLD and left the targets behind)
        fresh = status.level is FailsafeLevel.NOMINAL or ctl.autonomous
        if level is not FailsafeLevel.NOMINAL and fresh:
            measured = _measured_targets(world, vehicle)
            set_targets(world, ctl, measured.depth_m, measured.quaternion_wxyz)
        status = FailsafeStatus(level, now)
        world.set(vehicle, status)
    if level is FailsafeLevel.SURFACE:
        targets = world.get(vehicle, ControlTargets) or _measured_targets(world, vehicle)
        depth = max(0.0, targets.depth_m - ctl.failsafe.ascent_rate_m_s * clock.dt_s)
        set_targets(world, ctl, depth, targets.quaternion_wxyz)
        reading = world.get(vehicle, DepthReading)
        if reading is not None and reading.depth_m <= ctl.failsafe.surfaced_depth_m:
            world.set(vehicle, Armed(False))


def run_pilot_interface(world: World) -> None:
    """Sticks → pilot force intent; in hold modes the sticks also trim the targets."""
    ctl = world.resource(Controllers)
    flags = ctl.flags
    sticks = applied_sticks(ctl)
    if not any(sticks):
        set_intent(world, ctl, "pilot", ZERO6)
        return
    vehicle = ctl.vehicle
    depth_hold, attitude_hold = flags.depth_hold, flags.attitude_hold
    imu = vehicle_row(world, ctl, ImuReading)
    targets = vehicle_row(world, ctl, ControlTargets)
    if targets is None and (depth_hold or attitude_hold):  # the first: measured, trimmed below
        measured = _measured_targets(world, vehicle)
        set_targets(world, ctl, measured.depth_m, measured.quaternion_wxyz)
        targets = vehicle_row(world, ctl, ControlTargets)
    row = _UNUSED_TARGETS if targets is None else targets  # read and written in a hold mode
    intent = ctl.intent_rows["pilot"]
    _PILOT_ROWS(
        sticks,
        ctl.axis_maxima,
        ctl.pilot_gains,
        flags.precision,
        depth_hold,  # translation in the level (yaw-only) frame, rotated into the body
        attitude_hold,
        _LEVEL_IMU if imu is None else imu.values,
        row.values,
        world.resource(SimClock).dt_s,
        intent.values,
        intent.mark,
        row.mark,
        world.tick,
    )


def applied_sticks(ctl: Controllers) -> tuple[float, ...]:
    """The sticks the pilot interface flies this frame: the operator's last, or all centred
    while disarmed, in a failsafe or in GUIDED (where the sticks are ignored)."""
    flags = ctl.flags
    if not flags.armed or flags.failsafe or flags.guided:
        return ZERO6
    return ctl.sticks


def shaped_sticks(
    ctl: Controllers, sticks: tuple[float, ...]
) -> tuple[Wrench6, tuple[float, float, float, float]]:
    """The pilot's level wrench and trims for ``sticks`` in the present mode (the pilot
    interface's law, compiled: :func:`~testbed.vehicle.control_kernels.pilot_shape`)."""
    flags = ctl.flags
    gains, maxima = ctl.pilot_gains, ctl.axis_maxima
    return _PILOT_SHAPE(
        sticks, maxima, gains, flags.precision, flags.depth_hold, flags.attitude_hold
    )


def control_position(world: World) -> None:
    """GUIDED: the position setpoint → level-frame horizontal force intent, and its depth
    (and heading, when it sets one) as the depth and attitude holds' targets.

    The setpoint is the autonomy's :class:`PoseTarget` when it has one (its heading always
    applies), else the operator's :class:`PositionSetpoint`. Acts only armed, in GUIDED, not
    under the velocity controller, with a setpoint, an IMU reading and a fresh
    :class:`PositionReading` (no older than the loop's ``fix_timeout_s``); otherwise its intent
    is zero and the vehicle holds depth and attitude as in DEPTH_HOLD.
    """
    ctl = world.resource(Controllers)
    flags = ctl.flags
    if not (flags.guided and flags.armed) or flags.velocity:
        ctl.position.reset()
        set_intent(world, ctl, "position", ZERO6)
        return
    vehicle = ctl.vehicle
    now = world.resource(SimClock).time_s
    fix = world.get(vehicle, PositionReading)
    imu = world.get(vehicle, ImuReading)
    pose = world.get(vehicle, PoseTarget)
    if pose is not None:
        setpoint: PositionSetpoint | None = PositionSetpoint(
            pose.position_ned_m, pose.yaw_rad, True
        )
    else:
        setpoints = [sp for _, sp in world.query1(PositionSetpoint)]
        setpoint = setpoints[-1] if setpoints else None
    loop = ctl.position
    if (
        setpoint is None
        or imu is None
        or fix is None
        or now - fix.time_s > loop.gains.fix_timeout_s
    ):
        loop.reset()
        set_intent(world, ctl, "position", ZERO6)
        return
    targets = world.get(vehicle, ControlTargets) or _measured_targets(world, vehicle)
    q = targets.quaternion_wxyz
    if setpoint.use_yaw:
        q = quat_from_euler(0.0, 0.0, setpoint.yaw_rad)
    target = setpoint.position_ned_m
    set_targets(world, ctl, max(SURFACE_HOLD_DEPTH_M, target[2]), q)
    m = ctl.axis_maxima
    fx, fy = loop.update(
        (target[0], target[1]),
        fix.time_s,
        (fix.position_ned_m[0], fix.position_ned_m[1]),
        euler_from_quat(imu.quaternion_wxyz)[2],
        (m[0], m[1]),
    )
    bx, by, bz = level_to_body((fx, fy, 0.0), imu.quaternion_wxyz)
    set_intent(world, ctl, "position", (bx, by, bz, 0.0, 0.0, 0.0))


def control_depth(world: World) -> None:
    """Depth hold → world-vertical force intent rotated into the body frame."""
    ctl = world.resource(Controllers)
    flags = ctl.flags
    targets = vehicle_row(world, ctl, ControlTargets)
    reading = vehicle_row(world, ctl, DepthReading)
    imu = vehicle_row(world, ctl, ImuReading)
    if not (flags.armed and flags.depth_hold) or None in (reading, imu, targets):
        ctl.depth.reset()
        set_intent(world, ctl, "depth", ZERO6)
        return
    assert reading is not None and imu is not None and targets is not None
    dt = world.resource(SimClock).dt_s
    ctl.depth.update_rows(targets, reading, imu, dt, ctl.intent_rows["depth"], world.tick)


def control_attitude(world: World) -> None:
    """Attitude hold → body torque intent (axes the thrusters cannot torque stay off)."""
    ctl = world.resource(Controllers)
    flags = ctl.flags
    targets = vehicle_row(world, ctl, ControlTargets)
    imu = vehicle_row(world, ctl, ImuReading)
    if not (flags.armed and flags.attitude_hold) or imu is None or targets is None:
        ctl.attitude.reset()
        set_intent(world, ctl, "attitude", ZERO6)
        return
    dt = world.resource(SimClock).dt_s
    intent = ctl.intent_rows["attitude"]
    ctl.attitude.update_rows(targets, imu, dt, ctl.attitude_axes, intent, world.tick)


def allocate_thrust(world: World) -> None:
    """Σ force intents → allocator → per-thruster commands (all off when disarmed).

    The intents are summed in the order of their rows in the store (the order their entities
    were spawned in); the allocation writes the vehicle's :class:`ThrusterOutput` row.
    """
    ctl = world.resource(Controllers)
    act = world.resource(Actuation)
    if not ctl.flags.armed:
        act.allocator.reset()  # re-arming slews up from 0 N
        n = act.matrix.shape[1]
        act.requested[:] = 0.0
        act.commanded_forces_n[:] = 0.0
        world.set(ctl.vehicle, ThrusterOutput((0.0,) * n, (1500.0,) * n, (0.0,) * n, 1.0))
        return
    dt = world.resource(SimClock).dt_s
    commanded = act.commanded_forces_n
    act.allocator.step_rows(act.intents, dt, act.requested, act.output, world.tick, commanded)


# ---------------------------------------------------------------------------- POST_UPDATE


def mean_force_weight(interval_s: float, time_constant_s: float) -> float:
    """c, the weight of the end force in the mean force over an interval of a first-order lag
    with the command held: ``F0 + (F1 − F0)·c`` with ``c = 1/(1 − e) − τ/h``, ``e = exp(−h/τ)``
    (0.5 where e is 1, a zero interval)."""
    tau, h = time_constant_s, interval_s
    e = math.exp(-h / tau) if tau > 0.0 else 0.0
    return 1.0 / (1.0 - e) - tau / h if e < 1.0 else 0.5


def actuate_thrusters(world: World) -> None:
    """Step the thruster plant over the coming interval; hand its wrench to the physics.

    The command is held until the next frame, so the plant's first-order lag is stepped once,
    exactly, over ``Actuation.interval_s``. The physics applies, at each of its steps in that
    interval, the wrench of the interval's *mean* thruster forces, which gives exactly the
    impulse the lagged forces deliver: with ``e = exp(−h/τ)``, a force going from ``F0`` to
    ``F1`` over ``h`` averages ``F0 + (F1 − F0)·(1/(1 − e) − τ/h)``. Faulty thrusters are
    whatever the plant makes them; the wrench is ``T @ mean actual forces``, not the request.
    """
    act = world.resource(Actuation)
    h = act.interval_s
    dynamics = act.dynamics
    key = (h, dynamics.time_constant_s)
    if act.mean_weight[0] == key:  # the interval is almost always the same
        c = act.mean_weight[1]
    else:
        c = mean_force_weight(h, key[1])
        act.mean_weight = (key, c)
    dynamics.step_applied(
        act.commanded_forces_n,
        h,
        act.matrix,
        c,
        act.requested,
        act.applied,
        world.tick,
        act.plant_wrench,
    )


def meter_power(world: World) -> None:
    """POST_UPDATE: the current of the thrusters' actual forces, and the energy it draws over
    the time since the last frame."""
    meter = world.resource(PowerMeter)
    current = meter.current_of(world.resource(Actuation).actual_forces_n)
    meter.current_a = current
    meter.energy_j += current * meter.supply_voltage_v * world.resource(SimClock).dt_s


def wrench_of(forces_n: np.ndarray, matrix: np.ndarray) -> Wrench6:
    """``T @ forces`` as a (6,) tuple [N, N·m], body FRD, for (n,) forces and (6, n) T."""
    return interval_wrench(matrix, forces_n, forces_n, 0.0)


# ------------------------------------------------------------------------------ schedule


def publish_odometry(world: World) -> None:
    """POST_UPDATE: the vehicle's own estimate for the operator, from its sensors only.

    Position: the position fix when fitted (else north and east 0) with the depth sensor's
    depth; attitude: the IMU's (:func:`~.sensor_kernels.odometry_rows`). Written only when a
    reading changed.
    """
    ctl = world.resource(Controllers)
    imu = vehicle_row(world, ctl, ImuReading)
    depth = vehicle_row(world, ctl, DepthReading)
    if imu is None or depth is None:
        return
    fix = vehicle_row(world, ctl, PositionReading)
    odometry = vehicle_row(world, ctl, Odometry)
    # the first is set as a component (from a row of its own), the rest written into its row
    row = odometry or RowView.detached(_ODOMETRY.width)
    fix_values = imu.values if fix is None else fix.values  # read only with a fix
    _ODOMETRY_ROWS(
        imu.values, depth.values, fix_values, fix is not None, row.values, row.mark, world.tick
    )
    if odometry is None:
        world.set(ctl.vehicle, _ODOMETRY.read(row.values))


def build_schedule(
    inbound: Sequence[System] = (),
    outbound: Sequence[System] = (),
    *,
    estimators: Sequence[System] = (),
    planners: Sequence[System] = (),
    controllers: Sequence[System] = (),
) -> Schedule:
    """The vehicle frame: sensors and inbound commands; failsafe, pilot, loops, allocation;
    actuation and odometry.

    Args:
        inbound: link systems run first in PRE_UPDATE (they write the operator's intents the
            frames brought, before :func:`ingest_commands` reads them).
        outbound: link or recording systems run last in POST_UPDATE.
        estimators: PRE_UPDATE systems run right after :func:`read_sensors` (localization).
        planners: UPDATE systems run right after :func:`supervise_failsafe` (the mission).
        controllers: UPDATE systems run after the built-in loops, before
            :func:`allocate_thrust` (the autonomy's velocity controller).
    """
    schedule = Schedule()
    for system in inbound:
        schedule.add(Phase.PRE_UPDATE, system)
    schedule.add(Phase.PRE_UPDATE, read_sensors)
    for system in estimators:
        schedule.add(Phase.PRE_UPDATE, system)
    schedule.add(Phase.PRE_UPDATE, ingest_commands)
    schedule.add(Phase.UPDATE, supervise_failsafe)
    for system in planners:
        schedule.add(Phase.UPDATE, system)
    schedule.add(Phase.UPDATE, run_pilot_interface)
    schedule.add(Phase.UPDATE, control_position)
    schedule.add(Phase.UPDATE, control_depth)
    schedule.add(Phase.UPDATE, control_attitude)
    for system in controllers:
        schedule.add(Phase.UPDATE, system)
    schedule.add(Phase.UPDATE, allocate_thrust)
    schedule.add(Phase.POST_UPDATE, actuate_thrusters)
    schedule.add(Phase.POST_UPDATE, meter_power)
    schedule.add(Phase.POST_UPDATE, publish_odometry)
    for system in outbound:
        schedule.add(Phase.POST_UPDATE, system)
    return schedule
