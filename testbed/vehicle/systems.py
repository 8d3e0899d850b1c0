"""The vehicle's ECS systems, in the ECS paper's three phases, and the frame's order.

Frame order (each a plain ``verb_noun(world) -> None``; :func:`build_schedule`):

- PRE_UPDATE: :func:`read_sensors` (truth → sensor readings, at each sensor's rate),
  :func:`~testbed.vehicle.command_systems.ingest_commands` (operator intents → armed, mode,
  targets, command status);
- UPDATE: :func:`~testbed.vehicle.command_systems.supervise_failsafe` (stale commands → hold,
  then surface and disarm; runs first so every controller sees this frame's targets),
  :func:`run_pilot_interface`, :func:`control_position` (GUIDED only), :func:`control_depth`,
  :func:`control_attitude` (each writes its :class:`ForceIntent`), :func:`allocate_thrust`
  (Σ intents → allocator → thruster commands);
- POST_UPDATE: :func:`actuate_thrusters` (commands → thruster plant, stepped over the interval
  to the next frame → the wrench the physics applies, ``T @ actual forces``, recorded),
  :func:`meter_power` (actual forces → thruster current and energy drawn),
  :func:`publish_odometry` (sensor readings → the :class:`Odometry` the operator is sent).

A node adds its link systems around these (:func:`build_schedule`'s ``inbound``/``outbound``).
The systems that take the operator's commands are in :mod:`testbed.vehicle.command_systems`;
the resources all systems share, and the writers of the frame's targets and intents, in
:mod:`testbed.vehicle.resources`.

Controllers read only sensor readings (:class:`ImuReading`, :class:`DepthReading`,
:class:`PositionReading`); the physics truth enters through
:class:`~testbed.vehicle.resources.PlantTruth` and only :func:`read_sensors` reads it
(observers of a run, such as the recorder, read it too, from outside the schedule's control
path).

The frame's own components (the sensor readings, the control targets, the force intents, the
thruster output, the applied wrench, the odometry) live in the vehicle's frame store
(:mod:`testbed.ecs.store`): the world shows them as frozen components with change ticks, and
the systems' compiled kernels write their rows directly (the sensors' models, the pilot
interface, the depth and attitude loops, the allocation, the thrusters, the odometry), each
system a short shell around its kernel. The event systems (ingest, failsafe, the position
loop, the autonomy's) set components from Python. A row is found with
:func:`~testbed.vehicle.resources.vehicle_row` once the vehicle has the component; rows are
never freed (the vehicle's components are never removed).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TypeVar

import numpy as np

from testbed.common import jit
from testbed.common.geometry import (
    euler_from_quat,
    quat_from_euler,
)
from testbed.common.jit import BOOL, F64, I64, MARK, VECTOR, floats
from testbed.ecs import Entity, Phase, Schedule, System, World
from testbed.ecs.store import Layout, RowView
from testbed.vehicle.command_systems import ingest_commands, supervise_failsafe
from testbed.vehicle.components import (
    AttitudeSetpoint,
    ControlTargets,
    DepthReading,
    ImuReading,
    Odometry,
    PoseTarget,
    PositionReading,
    PositionSetpoint,
    ThrusterOutput,
)
from testbed.vehicle.control_kernels import pilot_rows, pilot_shape
from testbed.vehicle.control_laws import call_law, checked_vector
from testbed.vehicle.pilot import SURFACE_HOLD_DEPTH_M, level_to_body
from testbed.vehicle.resources import (
    LEVEL,
    ZERO6,
    Actuation,
    Controllers,
    PlantTruth,
    PowerMeter,
    SensorSuite,
    SimClock,
    Wrench6,
    measured_targets,
    set_intent,
    set_targets,
    vehicle_row,
)
from testbed.vehicle.sensor_kernels import odometry_rows
from testbed.vehicle.thrust_kernels import interval_wrench

__all__ = [
    "actuate_thrusters",
    "allocate_thrust",
    "applied_sticks",
    "build_schedule",
    "control_attitude",
    "control_depth",
    "control_position",
    "drive_thrusters",
    "mean_force_weight",
    "meter_power",
    "publish_odometry",
    "read_sensors",
    "run_pilot_interface",
    "shaped_sticks",
    "wrench_of",
]

_C = TypeVar("_C")
_ODOMETRY = Layout(Odometry(0.0, (0.0, 0.0, 0.0), LEVEL))
_UNUSED_TARGETS = RowView.detached(Layout(ControlTargets(0.0, LEVEL)).width)
"""The pilot kernel's targets row outside the hold modes (neither read nor written then)."""
_LEVEL_IMU = np.array([0.0, *LEVEL, 0.0, 0.0, 0.0])
"""An ImuReading row reading level (the pilot's attitude before the IMU's first reading)."""
# The systems' kernels, called without numba's dispatcher (testbed.common.jit.entry): rows and
# marks are the store's contiguous float64/int64 vectors, the rest floats, bools and tuples.
_PILOT_MODE = (floats(6), floats(6), VECTOR, BOOL, BOOL, BOOL)  # sticks, maxima, gains, flags
_PILOT_ROWS = jit.entry(pilot_rows, *_PILOT_MODE, VECTOR, VECTOR, F64, VECTOR, MARK, MARK, I64)
_PILOT_SHAPE = jit.entry(pilot_shape, *_PILOT_MODE)
_ODOMETRY_ROWS = jit.entry(odometry_rows, VECTOR, VECTOR, VECTOR, BOOL, VECTOR, MARK, I64)


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


# --------------------------------------------------------------------------------- UPDATE


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
        measured = measured_targets(world, vehicle)
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
    applies), else the operator's :class:`PositionSetpoint`. With neither (the operator's
    cancel removed it, or GUIDED was entered without one) a vehicle without autonomy holds the
    stopping point of its own fix and the loop's velocity estimate
    (:meth:`~testbed.vehicle.guidance.PositionController.latch_hold`, chosen once, from the
    second fix the loop sees), its depth and heading targets as the holds have them, as
    ArduSub's GUIDED always holds a position target; an :class:`AttitudeSetpoint` in GUIDED
    with no goal is ArduSub's angle control, which lets position go until the next goal.
    Acts only armed, in GUIDED, not under the velocity controller, with an IMU reading and a
    fresh :class:`PositionReading` (no older than the loop's ``fix_timeout_s``; a lost fix
    forgets the hold point, a new one is chosen when fixes come back); otherwise its intent
    is zero and the vehicle holds depth and attitude as in DEPTH_HOLD.
    """
    ctl = world.resource(Controllers)
    flags = ctl.flags
    loop = ctl.position
    if not (flags.guided and flags.armed) or flags.velocity:
        loop.reset()
        loop.released = False
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
    if setpoint is not None:
        loop.released = False
    elif ctl.autonomous or world.changed_any(AttitudeSetpoint):
        loop.released = True  # the autonomy's own (an end-effector reach), or angle control
    if imu is None or fix is None or now - fix.time_s > loop.gains.fix_timeout_s:
        loop.reset()
        set_intent(world, ctl, "position", ZERO6)
        return
    fix_ne = (fix.position_ned_m[0], fix.position_ned_m[1])
    if setpoint is not None:
        loop.hold_ne_m = None
        targets = world.get(vehicle, ControlTargets) or measured_targets(world, vehicle)
        q = targets.quaternion_wxyz
        if setpoint.use_yaw:
            q = quat_from_euler(0.0, 0.0, setpoint.yaw_rad)
        target = setpoint.position_ned_m
        set_targets(world, ctl, max(SURFACE_HOLD_DEPTH_M, target[2]), q)
        target_ne = (target[0], target[1])
    elif loop.released:
        loop.reset()
        set_intent(world, ctl, "position", ZERO6)
        return
    elif not loop.latch_hold(fix.time_s, fix_ne):  # the fix taken in, no velocity yet
        set_intent(world, ctl, "position", ZERO6)
        return
    else:
        assert loop.hold_ne_m is not None
        target_ne = loop.hold_ne_m  # depth and heading: the holds' targets as they are
    m = ctl.axis_maxima
    fx, fy = loop.update(
        target_ne,
        fix.time_s,
        fix_ne,
        euler_from_quat(imu.quaternion_wxyz)[2],
        (m[0], m[1]),
    )
    bx, by, bz = level_to_body((fx, fy, 0.0), imu.quaternion_wxyz)
    set_intent(world, ctl, "position", (bx, by, bz, 0.0, 0.0, 0.0))


def control_depth(world: World) -> None:
    """Depth hold → world-vertical force intent rotated into the body frame: the packaged PID,
    or the user's :class:`~testbed.vehicle.control_laws.DepthLaw` (``Controllers.depth_law``)
    given the targets and the readings."""
    ctl = world.resource(Controllers)
    flags = ctl.flags
    targets = vehicle_row(world, ctl, ControlTargets)
    reading = vehicle_row(world, ctl, DepthReading)
    imu = vehicle_row(world, ctl, ImuReading)
    law = ctl.depth_law
    if not (flags.armed and flags.depth_hold) or None in (reading, imu, targets):
        ctl.depth.reset() if law is None else call_law(law, "depth law", "reset")
        set_intent(world, ctl, "depth", ZERO6)
        return
    assert reading is not None and imu is not None and targets is not None
    dt = world.resource(SimClock).dt_s
    if law is None:
        ctl.depth.update_rows(targets, reading, imu, dt, ctl.intent_rows["depth"], world.tick)
        return
    vehicle = ctl.vehicle  # the law is handed the readings as components, never a row
    force = call_law(
        law,
        "depth law",
        "update",
        _get(world, vehicle, ControlTargets),
        _get(world, vehicle, DepthReading),
        _get(world, vehicle, ImuReading),
        dt,
    )
    x, y, z = checked_vector(law, force, "depth law's body force [N]")
    set_intent(world, ctl, "depth", (x, y, z, 0.0, 0.0, 0.0))


def control_attitude(world: World) -> None:
    """Attitude hold → body torque intent (axes the thrusters cannot torque stay off): the
    packaged PIDs, or the user's :class:`~testbed.vehicle.control_laws.AttitudeLaw`
    (``Controllers.attitude_law``) given the targets and the IMU's reading."""
    ctl = world.resource(Controllers)
    flags = ctl.flags
    targets = vehicle_row(world, ctl, ControlTargets)
    imu = vehicle_row(world, ctl, ImuReading)
    law = ctl.attitude_law
    if not (flags.armed and flags.attitude_hold) or imu is None or targets is None:
        ctl.attitude.reset() if law is None else call_law(law, "attitude law", "reset")
        set_intent(world, ctl, "attitude", ZERO6)
        return
    dt = world.resource(SimClock).dt_s
    axes = ctl.attitude_axes
    if law is None:
        intent = ctl.intent_rows["attitude"]
        ctl.attitude.update_rows(targets, imu, dt, axes, intent, world.tick)
        return
    vehicle = ctl.vehicle
    target = _get(world, vehicle, ControlTargets)
    torque = call_law(
        law, "attitude law", "update", target, _get(world, vehicle, ImuReading), dt, axes
    )
    k, m, n = checked_vector(law, torque, "attitude law's body torque [N·m]")
    torque = (k if axes[0] else 0.0, m if axes[1] else 0.0, n if axes[2] else 0.0)
    set_intent(world, ctl, "attitude", (0.0, 0.0, 0.0, *torque))


def _get(world: World, vehicle: Entity, cls: type[_C]) -> _C:
    """The vehicle's ``cls`` component, which the caller found it has (its row)."""
    value = world.get(vehicle, cls)
    assert value is not None
    return value


def allocate_thrust(world: World) -> None:
    """Σ force intents → allocator → per-thruster commands (all off when disarmed; while armed
    an operator's :class:`ThrusterTest` drives the thrusters at its pulses instead).

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
    test = ctl.thruster_test
    if test and len(test) == act.matrix.shape[1]:
        drive_thrusters(world, test)
        return
    dt = world.resource(SimClock).dt_s
    commanded = act.commanded_forces_n
    act.allocator.step_rows(act.intents, dt, act.requested, act.output, world.tick, commanded)


def drive_thrusters(world: World, pwm_us: Sequence[float]) -> None:
    """Drive the thrusters at the pulses ``pwm_us`` [µs] (per thruster, the ESC's: a CCW
    propeller's mirrored) instead of the allocation's, as an autopilot's motor test: the T200's
    forces for them are commanded, the allocator forgets its last command (the slew limit starts
    again from 0 N afterwards), and :class:`ThrusterOutput` reports the pulses, the forces and
    their currents (scale 1)."""
    act = world.resource(Actuation)
    allocator = act.allocator
    pwm = np.asarray(pwm_us, dtype=np.float64)
    forces = allocator.t200.forces_for_pwms(pwm, allocator.config.ccw_mask)
    allocator.reset()
    act.requested[:] = 0.0
    act.commanded_forces_n[:] = forces
    currents = allocator.t200.currents_for_forces(forces)
    output = ThrusterOutput(
        tuple(forces.tolist()), tuple(pwm.tolist()), tuple(currents.tolist()), 1.0
    )
    world.set(world.resource(Controllers).vehicle, output)


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


# ------------------------------------------------------------------------------ schedule


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
