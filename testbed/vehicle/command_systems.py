"""The vehicle's systems that take the operator's commands: :func:`ingest_commands`
(PRE_UPDATE: new intents → armed, mode, targets, command status) and
:func:`supervise_failsafe` (UPDATE's first: stale commands → hold, then surface and disarm; it
also works out the modes in effect for the systems after it). Both are event systems in
Python: most frames nothing new arrived and they return at once. The frame's order is
:func:`testbed.vehicle.systems.build_schedule`'s.
"""

from __future__ import annotations

import math

from testbed.common.geometry import quat_normalize
from testbed.ecs import World
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
    ModeRequest,
    MovementCommand,
    PositionSetpoint,
    ThrusterTest,
)
from testbed.vehicle.control import failsafe_level
from testbed.vehicle.mission import MAX_POSITION_M
from testbed.vehicle.resources import (
    Controllers,
    SimClock,
    is_armed,
    measured_targets,
    set_attitude_target,
    set_depth_target,
    set_targets,
    update_flags,
)

__all__ = ["MAX_SETPOINT_DEPTH_M", "ingest_commands", "supervise_failsafe"]

MAX_SETPOINT_DEPTH_M = MAX_POSITION_M
"""Deepest depth setpoint the vehicle takes [m] (the world's extent, as for positions)."""
_LEVELS = (FailsafeLevel.NOMINAL, FailsafeLevel.HOLD, FailsafeLevel.SURFACE)  # by value
_INTENT_TYPES = (
    MovementCommand,
    ArmRequest,
    ModeRequest,
    DepthSetpoint,
    AttitudeSetpoint,
    ThrusterTest,
)
"""What :func:`ingest_commands` reacts to."""
_GOAL_TYPES = (PositionSetpoint, EndEffectorSetpoint, GoalCancel)
"""Operator orders read by the position loop or the mission tree: contact too (a GoTo that
took a stick order's slot must not look like a silent link to the failsafe)."""


def ingest_commands(world: World) -> None:
    """Apply new operator intents: sticks (newer seq only), arm, mode, setpoints and a motor
    test's pulses (kept in ``Controllers.thruster_test`` for the allocation)."""
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
        was_armed = is_armed(world, vehicle)
        world.set(vehicle, Armed(request.armed))
        if request.armed and not was_armed:
            world.set(vehicle, FailsafeStatus(FailsafeLevel.NOMINAL, now))
            if not world.has(vehicle, ControlTargets):
                measured = measured_targets(world, vehicle)
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
            measured = measured_targets(world, vehicle)
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
        set_depth_target(world, ctl, depth_sp.depth_m)
    for _, test in world.query1(ThrusterTest, changed=True):
        ctl.thruster_test = test.pwm_us
    for _, att_sp in world.query1(AttitudeSetpoint, changed=True):
        ctl.last_contact_s = now
        try:
            if not all(math.isfinite(c) for c in att_sp.quaternion_wxyz):
                raise ValueError("not finite")
            attitude = quat_normalize(att_sp.quaternion_wxyz)
        except ValueError:  # a zero or non-finite quaternion from the link: a value
            ctl.ignored_setpoints += 1
            continue
        set_attitude_target(world, ctl, attitude)


def supervise_failsafe(world: World) -> None:
    """Stale operator commands: hold depth and heading, then surface and disarm.

    The age is measured from the last accepted operator intent of any kind. HOLD clears when
    commands resume; SURFACE is latched until the vehicle disarms (at the surface). Also works
    out the modes in effect this frame (``Controllers.flags``) for the systems after it.
    """
    ctl = world.resource(Controllers)
    _supervise(world, ctl)
    update_flags(world, ctl)


def _supervise(world: World, ctl: Controllers) -> None:
    clock = world.resource(SimClock)
    vehicle = ctl.vehicle
    now = clock.time_s
    status = world.get(vehicle, FailsafeStatus) or FailsafeStatus(FailsafeLevel.NOMINAL, now)
    if not is_armed(world, vehicle):
        if status.level is not FailsafeLevel.NOMINAL:
            world.set(vehicle, FailsafeStatus(FailsafeLevel.NOMINAL, now))
        return
    level = _LEVELS[failsafe_level(now - ctl.last_contact_s, ctl.failsafe)]
    if status.level is FailsafeLevel.SURFACE:
        level = FailsafeLevel.SURFACE
    if level is not status.level:
        fresh = status.level is FailsafeLevel.NOMINAL or ctl.autonomous
        if level is not FailsafeLevel.NOMINAL and fresh:
            _hold_targets(world, ctl)
        status = FailsafeStatus(level, now)
        world.set(vehicle, status)
    if level is FailsafeLevel.SURFACE:
        targets = world.get(vehicle, ControlTargets) or measured_targets(world, vehicle)
        depth = max(0.0, targets.depth_m - ctl.failsafe.ascent_rate_m_s * clock.dt_s)
        set_targets(world, ctl, depth, targets.quaternion_wxyz)
        reading = world.get(vehicle, DepthReading)
        if reading is not None and reading.depth_m <= ctl.failsafe.surfaced_depth_m:
            # surfaced: disarmed; the failsafe ends at the next frame (a disarmed vehicle's
            # status is NOMINAL), so for this frame SURFACE and disarmed say who disarmed it
            # (the autonomy's fallback latches on that)
            world.set(vehicle, Armed(False))


def _hold_targets(world: World, ctl: Controllers) -> None:
    """The targets the failsafe holds from this frame: a depth or attitude target the operator's
    hold was already flying is kept (as ArduSub's failsafe switching to ALT_HOLD leaves a
    vehicle already in it alone), the other axes start from what the sensors read (MANUAL's
    depth, say). GUIDED's leg and the autonomy's mission (which flew on through a HOLD and
    left the targets behind, when entering SURFACE) start from the sensors on both axes: the
    vehicle stops where it is."""
    vehicle = ctl.vehicle
    measured = measured_targets(world, vehicle)
    held = world.get(vehicle, ControlTargets)
    flags = ctl.flags  # the modes that flew up to this frame
    if held is None or ctl.autonomous or flags.guided:
        held = measured
    depth = held.depth_m if flags.depth_hold else measured.depth_m
    attitude = held.quaternion_wxyz if flags.attitude_hold else measured.quaternion_wxyz
    set_targets(world, ctl, depth, attitude)
