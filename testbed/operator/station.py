"""The operator's station: its own ECS world, the pilot, and the intents it sends.

The operator node owns a :class:`~testbed.ecs.World` ticked like the vehicle's, in three phases:

- PRE_UPDATE — the link adapter has already written what arrived (the vehicle's replicated
  state, origin REMOTE) before :meth:`OperatorStation.frame` runs;
- UPDATE — :func:`sample_pilot` shows a pilot that watches the vehicle what arrived
  (:func:`show_pilot`), then writes this frame's :class:`MovementCommand` (a fresh sequence
  number and the time the sticks were sampled) or, for the attitude experiment, the
  :class:`AttitudeSetpoint`; :func:`request_session` asks for the mode, depth and arming the
  scenario wants, once each;
- POST_UPDATE — nothing here: the link adapter encodes what changed after the frame.

The operator owns intents (sticks, arm and mode requests, setpoints); it writes only those. It
sees the vehicle's state — odometry, armed, mode — as replicated components on the vehicle's
entity, and :meth:`OperatorStation.vehicle_state_age_s` says how old that state is.

Imports: ``common``, ``ecs`` and the standard library only (no simulator, no pybullet).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

from testbed.common.components import (
    ArmRequest,
    AttitudeSetpoint,
    ControlMode,
    DepthSetpoint,
    EndEffectorSetpoint,
    GoalCancel,
    ModeRequest,
    MovementCommand,
    Odometry,
    PositionSetpoint,
)
from testbed.common.geometry import quat_from_euler
from testbed.ecs import Entity, Phase, Replicate, Schedule, World
from testbed.operator.pilots import Pilot, PilotError, PilotSample, SampleHold
from testbed.operator.user_pilots import STICK_AXES, stick_problem

__all__ = [
    "STICK_AXES",
    "OperatorClock",
    "OperatorStation",
    "Pilot",
    "PilotSample",
    "SessionPlan",
    "check_sticks",
    "request_session",
    "sample_pilot",
]


@dataclass(frozen=True, slots=True)
class SessionPlan:
    """What the operator asks of the vehicle at the start of a session.

    Attributes:
        mode: control mode requested at ``arm_at_s``.
        arm_at_s: operator time the arm request goes out [s].
        depth_m: depth setpoint sent with the arm request [m, positive down], or None to hold
            the depth the vehicle is at.
        precision: precision stick scaling.
    """

    mode: ControlMode = ControlMode.DEPTH_HOLD
    arm_at_s: float = 0.0
    depth_m: float | None = None
    precision: bool = False


class OperatorClock:
    """Resource: the operator's time [s] for the frame being run."""

    __slots__ = ("time_s",)

    def __init__(self) -> None:
        self.time_s = 0.0


class _Session:
    """Resource: the pilot, the plan and what has been requested so far (mutable); ``see``
    is the pilot's own ``see`` method (a pilot that watches the vehicle, :func:`show_pilot`),
    or None."""

    __slots__ = ("entity", "pilot", "plan", "requested", "see", "seen", "seq")

    def __init__(self, entity: Entity, pilot: Pilot, plan: SessionPlan) -> None:
        self.entity = entity
        self.pilot = pilot
        self.plan = plan
        self.requested = False
        self.seq = 0
        inner = pilot.pilot if isinstance(pilot, SampleHold) else pilot
        see = getattr(inner, "see", None)
        self.see: Callable[[Odometry], object] | None = see if callable(see) else None
        self.seen: Odometry | None = None


def check_sticks(pilot: Pilot, sticks: tuple[float, ...]) -> None:
    """Refuse a stick sample that is not six finite positions in [−1, 1].

    A pilot is local code, so a bad sample is its bug, not a value to clamp: it is refused
    here, when the pilot is sampled, whatever codec carries the sticks (the teleop codec would
    otherwise refuse it while encoding and the change-set codec carry a NaN to the vehicle).
    A pilot of the user's in a run is checked before this, as it is called
    (:class:`~testbed.operator.user_pilots.UserPilot`, which also names its file and the time).

    Raises:
        PilotError: naming the pilot's type and the axis (a ValueError).
    """
    problem = stick_problem(sticks)
    if problem is not None:
        inner = pilot.pilot if isinstance(pilot, SampleHold) else pilot  # the user's, not the hold
        raise PilotError(f"pilot {type(inner).__name__}: {problem}")


def sample_pilot(world: World) -> None:
    """UPDATE: sample the pilot now; write the sticks (new seq) or the attitude setpoint, and
    a supervised goal (a position setpoint, an end-effector setpoint for a goal in the
    ``"end_effector"`` frame, or a cancel) when a new one is in force.

    Raises:
        PilotError: the pilot's sample is not a :class:`PilotSample` (a TypeError too), or its
            sticks are not six finite positions in [−1, 1] (:func:`check_sticks`).
    """
    now = world.resource(OperatorClock).time_s
    session = world.resource(_Session)
    if session.see is not None:
        show_pilot(world, session)
    sample = session.pilot.sample(float(now))  # a float, as the protocol says, from t = 0 on
    if not isinstance(sample, PilotSample):
        inner = session.pilot.pilot if isinstance(session.pilot, SampleHold) else session.pilot
        raise PilotError(
            f"pilot {type(inner).__name__}: sample() must return a PilotSample "
            f"(testbed.operator.pilots), got {type(sample).__name__}"
        )
    check_sticks(session.pilot, sample.sticks)
    goal = sample.goal
    if goal is not None:
        if goal.position_ned_m is None:
            world.set(session.entity, GoalCancel(goal.index + 1))
            # the goal goes too, as the teleop vehicle end removes it on a cancel (the
            # change-set codec replicates the removal: a vehicle without autonomy lets go)
            world.remove(session.entity, PositionSetpoint)
        else:
            use_yaw = goal.yaw_deg is not None
            yaw = math.remainder(math.radians(goal.yaw_deg or 0.0), math.tau)
            if goal.frame == "end_effector":
                world.set(session.entity, EndEffectorSetpoint(goal.position_ned_m, yaw, use_yaw))
            else:  # a GoTo is flown in GUIDED: the mode asked for from now on (as the console's)
                world.set(session.entity, PositionSetpoint(goal.position_ned_m, yaw, use_yaw))
                world.set(session.entity, ModeRequest(ControlMode.GUIDED, session.plan.precision))
    if sample.attitude_deg is not None:
        roll, pitch, yaw = (math.radians(a) for a in sample.attitude_deg)
        world.set(session.entity, AttitudeSetpoint(quat_from_euler(roll, pitch, yaw)))
        return
    session.seq += 1
    world.set(session.entity, MovementCommand(session.seq, now, sample.sticks))


def show_pilot(world: World, session: _Session) -> None:
    """Hand a pilot that watches the vehicle (one with a ``see(odometry)`` method) the
    vehicle's :class:`Odometry` the operator received since its last sample, once, before the
    sample: what a person at the console sees, as late as the link made it (never the
    vehicle's truth)."""
    assert session.see is not None
    for _, odometry in world.query1(Odometry):
        if odometry is not session.seen:  # each reply's state arrives as a new object
            session.seen = odometry
            session.see(odometry)
        return


def request_session(world: World) -> None:
    """UPDATE: once the arm time has come, request the mode, the depth and arming (once)."""
    now = world.resource(OperatorClock).time_s
    session = world.resource(_Session)
    plan = session.plan
    if session.requested or now < plan.arm_at_s:
        return
    session.requested = True
    world.set(session.entity, ModeRequest(plan.mode, plan.precision))
    if plan.depth_m is not None:
        world.set(session.entity, DepthSetpoint(plan.depth_m))
    world.set(session.entity, ArmRequest(True, 1))


class OperatorStation:
    """The operator node's world, schedule and pilot.

    Args:
        pilot: the :class:`~testbed.operator.pilots.Pilot` sampled each frame.
        plan: mode, depth and arming to request.

    Attributes:
        world: the operator's ECS world.
        entity: the entity carrying the operator's intents (marked :class:`Replicate`).
        frames: frames run so far.
    """

    def __init__(self, pilot: Pilot, plan: SessionPlan) -> None:
        self.world = World()
        self.entity: Entity = self.world.spawn(Replicate())
        self.clock = OperatorClock()
        self.world.insert_resource(self.clock)
        self.world.insert_resource(_Session(self.entity, pilot, plan))
        self.schedule = Schedule()
        self.schedule.add(Phase.UPDATE, request_session)
        self.schedule.add(Phase.UPDATE, sample_pilot)
        self.frames = 0

    def frame(self, now_s: float) -> None:
        """Run one frame at operator time ``now_s`` [s]."""
        self.clock.time_s = now_s
        self.schedule.run(self.world)
        self.frames += 1

    def add_system(self, phase: Phase, system: Callable[[World], None]) -> None:
        """Append a system (e.g. a link adapter's ingest or publish) to a phase."""
        self.schedule.add(phase, system)

    def latest_command(self) -> MovementCommand | None:
        """The sticks most recently sampled, or None before the first frame."""
        return self.world.get(self.entity, MovementCommand)

    def vehicle_odometry(self) -> Odometry | None:
        """The vehicle's odometry as last received, or None if none has arrived."""
        for _, odometry in self.world.query1(Odometry):
            return odometry
        return None

    def vehicle_state_age_s(self, now_s: float) -> float:
        """Age of the vehicle state the operator holds [s] (inf before the first)."""
        odometry = self.vehicle_odometry()
        return math.inf if odometry is None else now_s - odometry.sampled_s
