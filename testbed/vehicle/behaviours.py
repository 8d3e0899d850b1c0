"""The mission behaviour tree (Angler's Fig. 4, adapted) on py_trees, against a plain context.

The tree, ticked once per :meth:`MissionRunner.tick` (Angler: every 50 ms)::

    Mission [Parallel, SuccessOnAll]
      Gather data                       context → blackboard (one-shot requests consumed)
      Tasks [Selector]
        Disarm fallback [Sequence]
          Disarm requested?             condition
          Stop setpoints                drop plan, hold pose, pending requests
          Disarm vehicle                request_arm = False
          Mark setup undone
        Mission [Sequence]
          Setup [Selector]
            Setup done?                 condition
            Setup once [Sequence, memory]
              Arm vehicle               request_arm = True until armed (timeout → failure)
              Arm manipulator           request_manipulator = True until armed (none: skip)
              Mark setup done
          Plan on request               cancel → hold here; GoTo → one leg; start → mission
          Execute or idle [Selector]
            Execute trajectory          pose setpoints until done and settled in tolerance
            Idle / hold station         the last pose held (or nothing, before any order)

**Frames.** A plan is flown by the vehicle's body origin or by the arm's end effector (a
mission whose ``child`` is the tool frame, :attr:`~testbed.vehicle.mission.Mission.end_effector`,
or an end-effector GoTo): it starts from, and its tolerance is checked against, that frame's
estimated position, and its setpoints say which frame they are for (:attr:`~testbed.vehicle.
mission_context.PoseSetpoint.end_effector`). The arm primitives are arming the manipulator
(setup), moving the end effector along a plan (execute) and holding it there (idle).

Composites without ``memory`` are re-evaluated from their first child every tick, so the
disarm fallback overrides execution within the tick its trigger is seen, and a new GoTo goal
replaces the plan at once (re-planned from the current estimate).

**Context.** :class:`~testbed.vehicle.mission_context.MissionContext` is a plain mutable
dataclass: the caller writes the inputs (time, arm state, estimate, requests) before a tick and
reads the outputs after it. The one-shot requests (``start_requested``, ``goal``,
``cancel_requested``) are *consumed*: the gatherer moves them onto the blackboard and clears
them in the context; a request pending while the disarm fallback runs is dropped (nothing
resumes by itself after a disarm).
``disarm_requested`` is a level, held true for as long as the pilot or link wants the vehicle
disarmed. All times come from ``time_s`` (simulation time), never the wall clock, so a run is
deterministic. Frames: world NED [m], yaw [rad] clockwise from north.

This module imports py_trees, :mod:`testbed.vehicle.mission` and
:mod:`testbed.vehicle.mission_context`; no ECS.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from typing import Any

import py_trees
from py_trees.common import Access, ParallelPolicy, Status
from py_trees.composites import Parallel, Selector, Sequence

from testbed.common.geometry import Vec3, wrap_angle
from testbed.vehicle.mission import Mission, Trajectory, plan, single_goal
from testbed.vehicle.mission_context import GoalRequest, MissionConfig, MissionContext, PoseSetpoint

__all__ = ["MissionRunner"]

_ZERO: Vec3 = (0.0, 0.0, 0.0)
_RUNNERS = itertools.count()


# Blackboard keys (relative to the runner's namespace) and their initial values.
_KEYS: dict[str, Any] = {
    # gathered inputs
    "time_s": 0.0,
    "armed": False,
    "disarm_requested": False,
    "position": _ZERO,
    "yaw": 0.0,
    "ee_position": None,
    "manipulator_armed": False,
    "start": False,
    "goal": None,
    "cancel": False,
    # tree state
    "disarm_latched": False,
    "setup_done": False,
    "trajectory": None,
    "end_effector": False,
    "settle_since": None,
    "hold": None,
    # outputs
    "request_arm": None,
    "request_manipulator": None,
    "setpoint": None,
    "status": "",
    "goal_reached": False,
    "plans": 0,
    "disarms": 0,
    "reached": 0,
}


class _Node(py_trees.behaviour.Behaviour):
    """A behaviour sharing the runner's blackboard client ``bb``."""

    def __init__(self, name: str, bb: py_trees.blackboard.Client) -> None:
        super().__init__(name)
        self.bb = bb


class _GatherData(_Node):
    """Copy the context's inputs onto the blackboard; move the one-shot requests there."""

    def __init__(self, bb: py_trees.blackboard.Client) -> None:
        super().__init__("Gather data", bb)
        self.context = MissionContext()

    def update(self) -> Status:
        ctx, bb = self.context, self.bb
        bb.time_s = ctx.time_s
        bb.armed = ctx.armed
        bb.disarm_requested = ctx.disarm_requested
        bb.position = ctx.estimate_position_ned
        bb.yaw = ctx.estimate_yaw_rad
        bb.ee_position = ctx.end_effector_position_ned
        bb.manipulator_armed = ctx.manipulator_armed
        if not ctx.disarm_requested:
            bb.disarm_latched = False
        if ctx.start_requested:
            bb.start, ctx.start_requested = True, False
        if ctx.goal is not None:
            bb.goal, ctx.goal = ctx.goal, None  # the latest order wins
        if ctx.cancel_requested:
            bb.cancel, ctx.cancel_requested = True, False
        return Status.SUCCESS


class _Check(_Node):
    """Condition: SUCCESS when ``predicate(bb)`` holds, else FAILURE."""

    def __init__(
        self, name: str, bb: py_trees.blackboard.Client, predicate: Callable[[Any], bool]
    ) -> None:
        super().__init__(name, bb)
        self.predicate = predicate

    def update(self) -> Status:
        return Status.SUCCESS if self.predicate(self.bb) else Status.FAILURE


class _Do(_Node):
    """Action that always succeeds at once: ``effect(bb)``."""

    def __init__(
        self, name: str, bb: py_trees.blackboard.Client, effect: Callable[[Any], None]
    ) -> None:
        super().__init__(name, bb)
        self.effect = effect

    def update(self) -> Status:
        self.effect(self.bb)
        return Status.SUCCESS


def _stop_setpoints(bb: Any) -> None:
    bb.trajectory = bb.hold = bb.setpoint = bb.goal = bb.settle_since = None
    bb.start = bb.cancel = False


def _disarm_vehicle(bb: Any) -> None:
    bb.request_arm = False
    if bb.ee_position is not None:
        bb.request_manipulator = False
    bb.status = "disarmed: disarm requested"
    if not bb.disarm_latched:
        bb.disarm_latched = True
        bb.disarms = bb.disarms + 1


class _ArmUntilArmed(_Node):
    """Ask for arming (``request`` key = True) until ``armed(bb)`` reports it; SUCCESS at once
    when ``fitted(bb)`` is false (nothing to arm); FAILURE after the setup timeout."""

    def __init__(
        self,
        bb: py_trees.blackboard.Client,
        what: str,
        timeout_s: float,
        request: str,
        armed: Callable[[Any], bool],
        fitted: Callable[[Any], bool] = lambda board: True,
    ) -> None:
        super().__init__(f"Arm {what}", bb)
        self.what = what
        self.timeout_s = timeout_s
        self.request = request
        self.armed = armed
        self.fitted = fitted
        self.since_s: float | None = None

    def initialise(self) -> None:
        self.since_s = None

    def update(self) -> Status:
        bb = self.bb
        if not self.fitted(bb) or self.armed(bb):
            return Status.SUCCESS
        bb.set(self.request, True)
        if self.since_s is None:
            self.since_s = bb.time_s
        if bb.time_s - self.since_s > self.timeout_s:
            bb.status = f"setup failed: {self.what} not armed within {self.timeout_s:g} s"
            return Status.FAILURE
        bb.status = f"setup: arming the {self.what}"
        return Status.RUNNING


def _frame_position(bb: Any, end_effector: bool) -> Vec3:
    """The estimated position of the frame a plan flies: the end effector's or the body's."""
    if end_effector and bb.ee_position is not None:
        position: Vec3 = bb.ee_position
        return position
    body: Vec3 = bb.position
    return body


class _PlanOnRequest(_Node):
    """Act on the pending requests: cancel, then a GoTo goal, then a mission start."""

    def __init__(
        self, bb: py_trees.blackboard.Client, mission: Mission | None, config: MissionConfig
    ) -> None:
        super().__init__("Plan on request", bb)
        self.mission = mission
        self.config = config

    def update(self) -> Status:
        bb = self.bb
        if bb.cancel:
            _stop_setpoints(bb)
            bb.hold = PoseSetpoint(bb.position, bb.yaw)
            bb.goal_reached = False
            bb.status = "cancelled: holding the current pose"
        elif bb.goal is not None:
            goal: GoalRequest = bb.goal
            cfg = self.config
            bb.end_effector = goal.end_effector and bb.ee_position is not None
            leg = single_goal(
                _frame_position(bb, bb.end_effector),
                bb.yaw,
                goal.position_ned,
                goal.yaw_rad,
                cfg.goto_speed_m_s,
                bb.time_s,
                yaw_rate_rad_s=cfg.goto_yaw_rate_rad_s,
            )
            self._start(leg)
        elif bb.start:
            if self.mission is None:
                bb.start = False
                bb.status = "start ignored: no mission loaded"
            else:
                bb.end_effector = self.mission.end_effector and bb.ee_position is not None
                start = _frame_position(bb, bb.end_effector)
                self._start(plan(self.mission, start, bb.yaw, bb.time_s))
        return Status.SUCCESS

    def _start(self, trajectory: Trajectory) -> None:
        bb = self.bb
        bb.goal = None
        bb.start = False
        bb.trajectory = trajectory
        bb.settle_since = None
        bb.goal_reached = False
        bb.plans = bb.plans + 1


class _ExecuteTrajectory(_Node):
    """Write the trajectory's pose each tick; SUCCESS once done and settled in tolerance.

    FAILURE when there is no trajectory, or when the pose is not within tolerance
    ``goal_timeout_s`` after the last point (then the last pose is held by the idle branch).
    """

    def __init__(self, bb: py_trees.blackboard.Client, config: MissionConfig) -> None:
        super().__init__("Execute trajectory", bb)
        self.config = config

    def update(self) -> Status:
        bb, cfg = self.bb, self.config
        trajectory: Trajectory | None = bb.trajectory
        if trajectory is None:
            return Status.FAILURE
        now = bb.time_s
        sample = trajectory.sample(now - trajectory.start_time_s)
        end_effector = bool(bb.end_effector)
        bb.setpoint = PoseSetpoint(
            sample.position_ned,
            sample.yaw_rad,
            sample.velocity_ned,
            end_effector,
            sample.yaw_rate_rad_s,
        )
        bb.status = f"executing {trajectory.name}"
        if not sample.done:
            return Status.RUNNING
        error_m = math.dist(_frame_position(bb, end_effector), sample.position_ned)
        error_rad = abs(wrap_angle(bb.yaw - sample.yaw_rad))
        if error_m < cfg.goal_tolerance_m and error_rad < cfg.yaw_tolerance_rad:
            if bb.settle_since is None:
                bb.settle_since = now
            if now - bb.settle_since >= cfg.settle_time_s:
                self._finish(trajectory)
                bb.goal_reached = True
                bb.reached = bb.reached + 1
                bb.status = f"{trajectory.name}: goal reached"
                return Status.SUCCESS
            return Status.RUNNING
        bb.settle_since = None
        late_s = now - trajectory.start_time_s - trajectory.end_time_s
        if late_s > cfg.goal_timeout_s:
            self._finish(trajectory)
            bb.status = f"{trajectory.name}: goal not reached within {cfg.goal_timeout_s:g} s"
            return Status.FAILURE
        return Status.RUNNING

    def _finish(self, trajectory: Trajectory) -> None:
        self.bb.trajectory = None
        self.bb.settle_since = None
        self.bb.hold = PoseSetpoint(
            trajectory.final_position_ned,
            trajectory.final_yaw_rad,
            end_effector=bool(self.bb.end_effector),
        )


class _Idle(_Node):
    """Hold the last pose (station keeping), or command nothing before any order."""

    def __init__(self, bb: py_trees.blackboard.Client) -> None:
        super().__init__("Idle / hold station", bb)

    def initialise(self) -> None:
        bb = self.bb
        if bb.hold is None:
            bb.status = "idle: waiting for a mission start or a goal"
        elif bb.goal_reached:
            bb.status = "holding station at the goal"
        # else keep the line that explains the hold (cancelled, goal not reached in time)

    def update(self) -> Status:
        self.bb.setpoint = self.bb.hold
        return Status.RUNNING


def _build_tree(
    bb: py_trees.blackboard.Client, mission: Mission | None, config: MissionConfig
) -> tuple[py_trees.behaviour.Behaviour, _GatherData]:
    """The root of the tree in the module docstring, and its data gatherer."""
    gather = _GatherData(bb)

    def setup_done(value: bool) -> Callable[[Any], None]:
        def effect(board: Any) -> None:
            board.setup_done = value

        return effect

    disarm = Sequence(
        "Disarm fallback",
        memory=False,
        children=[
            _Check("Disarm requested?", bb, lambda board: bool(board.disarm_requested)),
            _Do("Stop setpoints", bb, _stop_setpoints),
            _Do("Disarm vehicle", bb, _disarm_vehicle),
            _Do("Mark setup undone", bb, setup_done(False)),
        ],
    )
    setup = Selector(
        "Setup",
        memory=False,
        children=[
            _Check("Setup done?", bb, lambda board: bool(board.setup_done)),
            Sequence(
                "Setup once",
                memory=True,
                children=[
                    _ArmUntilArmed(
                        bb,
                        "vehicle",
                        config.setup_timeout_s,
                        "request_arm",
                        lambda board: bool(board.armed),
                    ),
                    _ArmUntilArmed(
                        bb,
                        "manipulator",
                        config.setup_timeout_s,
                        "request_manipulator",
                        lambda board: bool(board.manipulator_armed),
                        lambda board: board.ee_position is not None,
                    ),
                    _Do("Mark setup done", bb, setup_done(True)),
                ],
            ),
        ],
    )
    run = Sequence(
        "Mission",
        memory=False,
        children=[
            setup,
            _PlanOnRequest(bb, mission, config),
            Selector(
                "Execute or idle",
                memory=False,
                children=[_ExecuteTrajectory(bb, config), _Idle(bb)],
            ),
        ],
    )
    tasks = Selector("Tasks", memory=False, children=[disarm, run])
    root = Parallel(
        "Mission tree",
        policy=ParallelPolicy.SuccessOnAll(synchronise=False),
        children=[gather, tasks],
    )
    return root, gather


class MissionRunner:
    """Builds the mission tree for one vehicle and ticks it against a :class:`MissionContext`.

    Each runner keeps its keys under its own blackboard namespace (``/mission<n>/``), so
    several runners in one process do not share state. Call :meth:`close` to drop the keys.

    Args:
        mission: the mission a start request runs, or None (GoTo orders only).
        config: timing and tolerances.
    """

    def __init__(self, mission: Mission | None, config: MissionConfig | None = None) -> None:
        self.mission = mission
        self.config = config if config is not None else MissionConfig()
        self.namespace = f"/mission{next(_RUNNERS)}"
        self._bb = py_trees.blackboard.Client(name=self.namespace, namespace=self.namespace)
        for key, value in _KEYS.items():
            self._bb.register_key(key, access=Access.WRITE)
            self._bb.set(key, value)
        root, self._gather = _build_tree(self._bb, mission, self.config)
        self.tree = py_trees.trees.BehaviourTree(root)
        self._ticks = 0

    @property
    def root(self) -> py_trees.behaviour.Behaviour:
        """The tree's root behaviour."""
        return self.tree.root

    def tick(self, context: MissionContext) -> None:
        """Tick the tree once on ``context``'s inputs and write its outputs into ``context``.

        The per-tick outputs (``request_arm``, ``pose_setpoint``) start each tick as None.
        """
        bb = self._bb
        bb.request_arm = None
        bb.request_manipulator = None
        bb.setpoint = None
        self._gather.context = context
        self.tree.tick()
        self._ticks += 1
        context.request_arm = bb.request_arm
        context.request_manipulator = bb.request_manipulator
        context.pose_setpoint = bb.setpoint
        context.status = bb.status
        context.goal_reached = bb.goal_reached
        context.tick_count = self._ticks
        context.plan_count = bb.plans
        context.disarm_count = bb.disarms
        context.reached_count = bb.reached

    def tree_ascii(self, *, show_status: bool = False, unicode: bool = False) -> str:
        """The tree drawn as text (py_trees' ascii or unicode rendering), for docs and logs."""
        render = py_trees.display.unicode_tree if unicode else py_trees.display.ascii_tree
        return render(self.root, show_status=show_status)

    def close(self) -> None:
        """Remove this runner's keys from the (process-wide) blackboard."""
        self._bb.unregister(clear=True)
