"""The vehicle world's resources, shared by its systems (:mod:`testbed.vehicle.systems`,
:mod:`testbed.vehicle.command_systems`), and the writers of the frame's shared state.

Resources: :class:`SimClock` (vehicle time), :class:`PlantTruth` (the physics truth, for the
sensors and observers only), :class:`PowerMeter`, :class:`SensorSuite`, :class:`Controllers`
(the loops, the pilot's gains, the failsafe's settings and the modes in effect,
:class:`ControlFlags`) and :class:`Actuation` (the allocator, the thrusters and the wrench handed
to the physics). Controller objects and the allocator are mutable resources; components stay
frozen values.

Writers: :func:`set_targets` (and its depth-only and attitude-only forms) and :func:`set_intent`
write the vehicle's :class:`ControlTargets` and a source's ``ForceIntent`` into their frame-store
rows (a change only when a value differs); :func:`vehicle_row` finds a row;
:func:`update_flags` works out the modes in effect from the vehicle's state components.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from testbed.common import jit
from testbed.common.geometry import Quaternion, yaw_only
from testbed.common.jit import F64, I64, MARK, VECTOR, floats
from testbed.ecs import Entity, World
from testbed.ecs.store import RowView, Table
from testbed.vehicle.allocation import Allocator
from testbed.vehicle.components import (
    ActiveMode,
    Armed,
    ControlMode,
    ControlTargets,
    DepthReading,
    FailsafeLevel,
    FailsafeStatus,
    ImuReading,
)
from testbed.vehicle.control import AttitudeController, DepthController, FailsafeConfig
from testbed.vehicle.control_kernels import put_attitude_target, put_depth_target, put_targets
from testbed.vehicle.control_laws import AttitudeLaw, DepthLaw
from testbed.vehicle.guidance import PositionController
from testbed.vehicle.pilot import SURFACE_HOLD_DEPTH_M, PilotGains, pilot_gains_array
from testbed.vehicle.sensors import DepthSensor, Imu, PositionFix
from testbed.vehicle.thrust_kernels import interval_wrench, put_wrench
from testbed.vehicle.thrusters import ThrusterDynamics

__all__ = [
    "LEVEL",
    "ZERO6",
    "Actuation",
    "ControlFlags",
    "Controllers",
    "PlantTruth",
    "PowerMeter",
    "SensorSuite",
    "SimClock",
    "Wrench6",
    "is_armed",
    "measured_targets",
    "set_attitude_target",
    "set_depth_target",
    "set_intent",
    "set_targets",
    "update_flags",
    "vehicle_row",
]

Wrench6 = tuple[float, float, float, float, float, float]
ZERO6: Wrench6 = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
LEVEL: Quaternion = (1.0, 0.0, 0.0, 0.0)
_FLAG_TYPES = (Armed, ActiveMode, FailsafeStatus)
"""What the modes in effect follow from (:func:`update_flags`)."""
# The writers' kernels, called without numba's dispatcher (testbed.common.jit.entry): rows and
# marks are the store's contiguous float64/int64 vectors, the rest floats and tuples.
_PUT_WRENCH = jit.entry(put_wrench, VECTOR, MARK, I64, *(F64,) * 6)
_PUT_TARGETS = jit.entry(put_targets, VECTOR, MARK, I64, F64, floats(4))
_PUT_DEPTH_TARGET = jit.entry(put_depth_target, VECTOR, MARK, I64, F64)
_PUT_ATTITUDE_TARGET = jit.entry(put_attitude_target, VECTOR, MARK, I64, floats(4))


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
            number in [0, :data:`~testbed.vehicle.command_systems.MAX_SETPOINT_DEPTH_M`] m, an
            attitude that is not finite or of zero norm), counted and otherwise ignored (the
            targets stay as they were).
        pilot_gains: ``pilot`` as the pilot interface's kernel reads it
            (:func:`~testbed.vehicle.pilot.pilot_gains_array`; fixed at construction, as
            ``pilot`` is).
        autonomous: the vehicle flies itself (:mod:`testbed.vehicle.autonomy`): it owns its
            mode (operator mode requests are not applied) and a link HOLD keeps GUIDED flying.
        velocity_control: in GUIDED the autonomy's velocity controller (the ISMC) flies all
            six axes; the depth, attitude and position loops stand down.
        depth_law, attitude_law: a hold of the user's own that flies instead of ``depth`` or
            ``attitude`` (:mod:`testbed.vehicle.control_laws`); None: the packaged PID.
        thruster_test: the pulses of the operator's last
            :class:`~testbed.vehicle.components.ThrusterTest` [µs], per thruster (ingest keeps
            it, so the allocation reads an attribute, not a query, every frame); empty: none.
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
    depth_law: DepthLaw | None = None
    attitude_law: AttitudeLaw | None = None
    thruster_test: tuple[float, ...] = ()

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


# -------------------------------------------------------------------------------- writers


def is_armed(world: World, vehicle: Entity) -> bool:
    armed = world.get(vehicle, Armed)
    return armed is not None and armed.armed


def update_flags(world: World, ctl: Controllers) -> None:
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
    flags.armed = is_armed(world, vehicle)
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


def measured_targets(world: World, vehicle: Entity) -> ControlTargets:
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


def set_depth_target(world: World, ctl: Controllers, depth_m: float) -> None:
    """:func:`set_targets` of an operator's depth setpoint [m, + down] (no shallower than
    :data:`~testbed.vehicle.pilot.SURFACE_HOLD_DEPTH_M`), the attitude target kept."""
    depth_m = max(SURFACE_HOLD_DEPTH_M, depth_m)
    row = vehicle_row(world, ctl, ControlTargets)
    if row is None:
        targets = world.get(ctl.vehicle, ControlTargets) or measured_targets(world, ctl.vehicle)
        set_targets(world, ctl, depth_m, targets.quaternion_wxyz)
    else:
        _PUT_DEPTH_TARGET(row.values, row.mark, world.tick, depth_m)


def set_attitude_target(world: World, ctl: Controllers, quaternion_wxyz: Quaternion) -> None:
    """:func:`set_targets` of a new attitude target (body → NED), the depth target kept."""
    row = vehicle_row(world, ctl, ControlTargets)
    if row is None:
        targets = world.get(ctl.vehicle, ControlTargets) or measured_targets(world, ctl.vehicle)
        set_targets(world, ctl, targets.depth_m, quaternion_wxyz)
    else:
        _PUT_ATTITUDE_TARGET(row.values, row.mark, world.tick, quaternion_wxyz)


def set_intent(world: World, controllers: Controllers, source: str, wrench: Wrench6) -> None:
    """Write ``source``'s :class:`ForceIntent` wrench [N, N·m], FRD, into its row (a change
    only when it differs)."""
    row = controllers.intent_rows[source]
    _PUT_WRENCH(row.values, row.mark, world.tick, *wrench)
