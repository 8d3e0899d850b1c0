"""The vehicle's autonomy (Angler): its mission tree and velocity controller as ECS systems.

A vehicle with a ``[vehicle.autonomy]`` table flies itself; the operator supervises. Per frame:

- PRE_UPDATE, :func:`~testbed.vehicle.localization.estimate_navigation` (after the sensors):
  the :class:`~testbed.vehicle.estimation.NavigationEstimate` — the only state the systems
  below read (never the physics truth);
- UPDATE, :func:`run_mission` (after the failsafe supervisor): at the tree's tick rate (Angler:
  20 Hz) it fills a :class:`~testbed.vehicle.mission_context.MissionContext` from the world,
  ticks the :class:`~testbed.vehicle.behaviours.MissionRunner` and applies what the tree
  asked: arming (``Armed``, GUIDED), the :class:`PoseTarget` to fly, and the replicated
  :class:`MissionStatus` the operator is told (the protocol's ready and cancelled flags);
- UPDATE, :func:`control_velocity` (controller ``"ismc"``): the pose target → the kinematic
  law's body twist (:func:`~testbed.vehicle.kinematic.pose_twist`) → Angler's ISMC
  (:class:`~testbed.vehicle.ismc.IsmcController`, on the controller's own, possibly mismatched,
  model) → a six-axis :class:`ForceIntent` the generalized allocator turns into thrust. With
  controller ``"pid"`` the same target is flown by the PD position loop and the depth and
  attitude PIDs instead (:func:`~testbed.vehicle.systems.control_position`).

Supervision (the operator's intents, over either codec): a new :class:`PositionSetpoint` (a
GoTo order) is a goal that starts or replaces the mission's plan; a new
:class:`AttitudeSetpoint` (KeepHeading) re-aims the current goal, or holds here at that
heading; a new :class:`GoalCancel` (the order header's cancel bit) drops the plan and holds
the present pose; armed before any order, the vehicle holds station where it is. A goal
(either frame) above the surface (a negative depth) is a remote value the tree never gets: it
is counted (:attr:`Autonomy.refused`, ``mission.goals_refused``) and the vehicle flies on. The
tree's disarm fallback (``disarm_requested``) is a level: the operator's last arm request was a
disarm, or the link failsafe disarmed the vehicle (latched until the operator asks to arm
again). A vehicle under autonomy owns its mode: the operator's mode requests and sticks are
not applied (:func:`~testbed.vehicle.command_systems.ingest_commands`), and a link HOLD keeps
the mission flying. The link's SURFACE level takes the vehicle from the mission as it does
without autonomy: the depth and attitude loops climb at the failsafe's ascent rate from where
the vehicle is, level at its heading, and the failsafe disarms it at the surface (a vehicle
disarmed at depth would sink if it is heavy in water, as the von Benzon Heavy is by 1 N).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Literal

from testbed.common.geometry import euler_from_quat, quat_rotate_inverse
from testbed.config import ConfigError, FieldError, check_range, user_file
from testbed.ecs import World
from testbed.vehicle.behaviours import MissionRunner
from testbed.vehicle.components import (
    ActiveMode,
    Armed,
    ArmRequest,
    AttitudeSetpoint,
    ControlMode,
    EndEffectorSetpoint,
    FailsafeLevel,
    FailsafeStatus,
    GoalCancel,
    MissionStatus,
    PoseTarget,
    PositionSetpoint,
)
from testbed.vehicle.filter_values import NavigationEstimate
from testbed.vehicle.hydrodynamics import HydroModel
from testbed.vehicle.ismc import (
    IsmcController,
    IsmcGains,
    known_ismc_models,
    load_ismc_gains,
    mismatched_model,
)
from testbed.vehicle.kinematic import PoseGains, pose_twist
from testbed.vehicle.manipulation import EndEffectorTarget, Manipulator
from testbed.vehicle.mission import Mission, load_mission, load_packaged_mission, mission_names
from testbed.vehicle.mission_context import GoalRequest, MissionConfig, MissionContext
from testbed.vehicle.resources import ZERO6, Controllers, SimClock, set_intent

__all__ = [
    "Autonomy",
    "AutonomyConfig",
    "ModelMismatch",
    "build_autonomy",
    "control_velocity",
    "resolve_mission",
    "run_mission",
]


@dataclass(frozen=True, slots=True)
class ModelMismatch:
    """How the controller's model of the vehicle differs from the plant's (a scenario knob):
    :func:`~testbed.vehicle.ismc.mismatched_model`'s factors.

    Attributes:
        mass_scale: factor on mass, weight and inertia, in (0, 10].
        damping_scale: factor on every damping derivative, in [0, 10].
        added_mass_scale: factor on every added mass, in [0, 10].
        buoyancy_offset_n: added to the buoyancy [N], in [−1000, 1000].
    """

    mass_scale: float = 1.0
    damping_scale: float = 1.0
    added_mass_scale: float = 1.0
    buoyancy_offset_n: float = 0.0

    def __post_init__(self) -> None:
        check_range(self.mass_scale, "mass_scale", 0.0, 10.0, low_open=True)
        check_range(self.damping_scale, "damping_scale", 0.0, 10.0)
        check_range(self.added_mass_scale, "added_mass_scale", 0.0, 10.0)
        check_range(self.buoyancy_offset_n, "buoyancy_offset_n", -1000.0, 1000.0, "N")


@dataclass(frozen=True, slots=True)
class IsmcSettings:
    """Overrides of the vehicle model's packaged ISMC gains (``data/ismc.toml``, the table of
    the model's ``name``); each None keeps the packaged value. A model with no packaged table
    (a model file of the user's own) flies with all three set here. Domains:
    :class:`~testbed.vehicle.ismc.IsmcGains`. (The controller runs every vehicle frame, at the
    control rate; a table's ``rate_hz`` records its source's.)

    Attributes:
        kp: (6,) Kp per body axis (u v w p q r) [1/s].
        rho: switching gain ρ [N, N·m].
        lambda_: boundary-layer width λ [m/s, rad/s].
    """

    kp: tuple[float, float, float, float, float, float] | None = None
    rho: float | None = None
    lambda_: float | None = None

    def __post_init__(self) -> None:
        self.applied_to(IsmcGains((1.0,) * 6, 1.0, 1.0, 100.0))  # checks each value set

    @property
    def complete(self) -> bool:
        """Whether every gain is set (no packaged table needed)."""
        return None not in (self.kp, self.rho, self.lambda_)

    def applied_to(self, gains: IsmcGains) -> IsmcGains:
        """``gains`` with the values set here (checked by :class:`IsmcGains`)."""
        return dataclasses.replace(
            gains,
            kp=gains.kp if self.kp is None else self.kp,
            rho=gains.rho if self.rho is None else self.rho,
            lambda_=gains.lambda_ if self.lambda_ is None else self.lambda_,
        )

    def gains_for(self, model_name: str) -> IsmcGains:
        """The gains the ISMC of the model named ``model_name`` flies with: all three set here,
        or the model's packaged table with the ones set here.

        Raises:
            FieldError: not all set, and no packaged table of that name (naming ``ismc`` and
                what to set).
        """
        if self.complete:
            return self.applied_to(
                IsmcGains((1.0,) * 6, 1.0, 1.0, 100.0, "[vehicle.autonomy.ismc]")
            )
        known = known_ismc_models()
        if model_name not in known:
            missing = [k for k in ("kp", "rho", "lambda_") if getattr(self, k) is None]
            raise FieldError(
                "ismc",
                f"the vehicle model {model_name!r} has no packaged ISMC gains (known: "
                f"{', '.join(known)}): set {', '.join(missing)} too",
            )
        return self.applied_to(load_ismc_gains(model_name))


@dataclass(frozen=True, slots=True)
class AutonomyConfig:
    """The scenario's ``[vehicle.autonomy]`` table (needs ``[vehicle.navigation]``).

    Attributes:
        mission: a packaged mission (``testbed/scenarios/missions/NAME.json``: ``square``,
            ``lawn_mower``, ``station_keeping``, ``waypoint``) or a path to a mission JSON file;
            None = no mission: the vehicle arms, holds where it is and flies the operator's
            GoTo orders.
        start_s: when the mission starts [s] (the tree's start event), in [0, 1e6].
        controller: ``"ismc"`` (Angler's velocity controller over the kinematic pose law) or
            ``"pid"`` (the PD position loop with the depth and attitude PIDs).
        ismc: overrides of the ISMC gains packaged for the vehicle's model
            (``data/ismc.toml``).
        mismatch: the controller's model error (the ISMC's model terms).
        pose: the kinematic pose law's gains and limits.
        tree: the mission tree's timing and tolerances (tick rate, goal tolerance, GoTo speed).
        ready_sigma_m: the tree first ticks once the estimate's largest position 1σ is at most
            this [m], in (0, 100] (the filter starts at the origin, 10 m uncertain: a hold or a
            plan from that would fly the vehicle towards the origin); then it always ticks.
    """

    mission: str | None = None
    start_s: float = 0.0
    controller: Literal["ismc", "pid"] = "ismc"
    ismc: IsmcSettings = field(default_factory=IsmcSettings)
    mismatch: ModelMismatch = field(default_factory=ModelMismatch)
    pose: PoseGains = field(default_factory=PoseGains)
    tree: MissionConfig = field(default_factory=MissionConfig)
    ready_sigma_m: float = 0.5

    def __post_init__(self) -> None:
        check_range(self.start_s, "start_s", 0.0, 1e6, "s")
        check_range(self.ready_sigma_m, "ready_sigma_m", 0.0, 100.0, "m", low_open=True)
        if self.mission is not None:  # a bad name or file fails here, naming it and the key
            try:
                resolve_mission(self.mission)
            except ConfigError as err:
                raise FieldError("mission", str(err)) from None


def resolve_mission(name: str) -> Mission:
    """The mission ``name``: a packaged one, or a ``.json`` file at that path
    (:func:`~testbed.config.user_file`).

    Raises:
        ConfigError: neither a packaged mission (the message lists them) nor an existing
            ``.json`` file (the message names the path), or a bad file (the message names the
            file and the field).
    """
    own = user_file(name, mission_names(), "mission", suffix=".json")
    return load_packaged_mission(name) if own is None else load_mission(own)


@dataclass(slots=True)
class Autonomy:
    """The autonomy resource: the tree, its context, the ISMC and what supervision sent.

    Attributes:
        config: the autonomy's configuration.
        runner: the mission tree.
        context: the tree's inputs and outputs (kept between ticks).
        ismc: the velocity controller (None with controller ``"pid"``).
        next_tick_s: vehicle time of the next tree tick [s].
        navigating: the estimate has been good enough to start from (``ready_sigma_m``).
        ready_s: vehicle time the estimate first was (the tree's first tick) [s]; None while
            it never was (no arming, no mission: the run reports it).
        started: the mission's start event was given.
        seen: the operator's last goal, heading, cancel and end-effector goal already handed
            to the tree.
        last_arm: the operator's last arm request seen.
        link_disarmed: the link failsafe surfaced and disarmed the vehicle; latched until a new
            arm request.
        goals: goals given to the tree (mission start, GoTo, KeepHeading).
        refused: the operator's goals not given to the tree (above the surface).
        cancels: cancels given to the tree.
        cancelled: the last supervision was a cancel (cleared by the next goal).
    """

    config: AutonomyConfig
    runner: MissionRunner
    context: MissionContext
    ismc: IsmcController | None
    next_tick_s: float = 0.0
    navigating: bool = False
    ready_s: float | None = None
    started: bool = False
    seen: tuple[object, object, object, object] = (None, None, None, None)
    last_arm: ArmRequest | None = None
    link_disarmed: bool = False
    goals: int = 0
    refused: int = 0
    cancels: int = 0
    cancelled: bool = False

    @property
    def status(self) -> str:
        """One line on what the mission tree is doing, as of its last tick ("executing
        square", "square: goal reached", "…: goal not reached within 10 s", "cancelled:
        holding the current pose", "setup failed: …"); "" before its first tick."""
        return self.context.status


def build_autonomy(config: AutonomyConfig, model: HydroModel) -> Autonomy:
    """The :class:`Autonomy` resource of ``config`` for a vehicle whose plant is ``model``."""
    mission = None if config.mission is None else resolve_mission(config.mission)
    ismc = None
    if config.controller == "ismc":
        gains = config.ismc.gains_for(model.name)
        m = config.mismatch
        belief = mismatched_model(
            model,
            mass_scale=m.mass_scale,
            damping_scale=m.damping_scale,
            added_mass_scale=m.added_mass_scale,
            buoyancy_offset_n=m.buoyancy_offset_n,
        )
        ismc = IsmcController(belief, gains)
    runner = MissionRunner(mission, config.tree)
    return Autonomy(config, runner, MissionContext(), ismc)


# ------------------------------------------------------------------------------- systems


def run_mission(world: World) -> None:
    """UPDATE: tick the mission tree when due and apply its outputs (module docstring).

    Waits for a navigation estimate within ``ready_sigma_m`` (the tree plans from it).
    """
    auto = world.resource(Autonomy)
    ctl = world.resource(Controllers)
    vehicle = ctl.vehicle
    now = world.resource(SimClock).time_s
    _watch_link(world, auto, ctl)
    if now < auto.next_tick_s - 1e-9:
        return
    estimate = world.get(vehicle, NavigationEstimate)
    if estimate is None:
        return
    if not auto.navigating:
        if max(estimate.position_sigma_m) > auto.config.ready_sigma_m:
            return
        auto.navigating = True
        auto.ready_s = auto.next_tick_s = now
    auto.next_tick_s += auto.config.tree.tick_period_s
    context = auto.context
    context.time_s = now
    context.armed = ctl.flags.armed
    context.disarm_requested = auto.link_disarmed or (
        auto.last_arm is not None and not auto.last_arm.armed
    )
    context.estimate_position_ned = estimate.position_ned_m
    context.estimate_yaw_rad = euler_from_quat(estimate.quaternion_wxyz)[2]
    if world.has_resource(Manipulator):
        arm = world.resource(Manipulator)
        context.manipulator_armed = arm.armed
        context.end_effector_position_ned = arm.end_effector_ned(
            estimate.position_ned_m, estimate.quaternion_wxyz
        )
    _supervise_goals(world, auto, context)
    auto.runner.tick(context)
    _apply_outputs(world, auto, ctl, now)


def _watch_link(world: World, auto: Autonomy, ctl: Controllers) -> None:
    """Follow the operator's arm requests and the link failsafe (every frame, so a disarm
    trigger is seen at the first tick after it)."""
    requests = [r for _, r in world.query1(ArmRequest)]
    request = requests[-1] if requests else None
    if request is not None and request != auto.last_arm:
        auto.last_arm = request
        if request.armed:
            auto.link_disarmed = False
    status = world.get(ctl.vehicle, FailsafeStatus)
    if status is not None and status.level is FailsafeLevel.SURFACE and not ctl.flags.armed:
        auto.link_disarmed = True  # the failsafe surfaced the vehicle and disarmed it


def _supervise_goals(world: World, auto: Autonomy, context: MissionContext) -> None:
    """Hand the operator's new goal, heading or cancel to the tree (one-shot requests)."""
    goal, heading, cancel, reach = (_latest(world, kind) for kind in _SUPERVISION)
    seen_goal, seen_heading, seen_cancel, seen_reach = auto.seen
    mission = auto.config.mission
    if mission is not None and not auto.started and context.time_s >= auto.config.start_s:
        auto.started = context.start_requested = True
        auto.goals += 1
    new_goal = isinstance(goal, PositionSetpoint) and goal != seen_goal and _in_water(auto, goal)
    new_reach = (
        isinstance(reach, EndEffectorSetpoint) and reach != seen_reach and _in_water(auto, reach)
    )
    if isinstance(goal, PositionSetpoint) and new_goal:
        yaw = goal.yaw_rad if goal.use_yaw else None
        context.goal = GoalRequest(goal.position_ned_m, yaw)
        auto.goals += 1
        auto.cancelled = False
    elif isinstance(reach, EndEffectorSetpoint) and new_reach:
        yaw = reach.yaw_rad if reach.use_yaw else None
        context.goal = GoalRequest(reach.position_ned_m, yaw, end_effector=True)
        auto.goals += 1
        auto.cancelled = False
    elif isinstance(heading, AttitudeSetpoint) and heading != seen_heading:
        yaw = euler_from_quat(heading.quaternion_wxyz)[2]
        target = world.get(world.resource(Controllers).vehicle, PoseTarget)
        position = context.estimate_position_ned if target is None else target.position_ned_m
        context.goal = GoalRequest(position, yaw)
        auto.goals += 1
        auto.cancelled = False
    if isinstance(cancel, GoalCancel) and cancel != seen_cancel:
        context.cancel_requested = True
        auto.cancels += 1
        auto.cancelled = True
    auto.seen = (goal, heading, cancel, reach)


_SUPERVISION = (PositionSetpoint, AttitudeSetpoint, GoalCancel, EndEffectorSetpoint)


def _in_water(auto: Autonomy, goal: PositionSetpoint | EndEffectorSetpoint) -> bool:
    """The new goal's depth (NED down, the third coordinate [m]) is at or below the surface
    (≥ 0); else it is counted refused (a remote value: never raised, never given to the
    tree)."""
    if goal.position_ned_m[2] >= 0.0:
        return True
    auto.refused += 1
    return False


def _latest(world: World, kind: type[object]) -> object | None:
    found = [c for _, c in world.query1(kind)]
    return found[-1] if found else None


def _apply_outputs(world: World, auto: Autonomy, ctl: Controllers, now: float) -> None:
    context = auto.context
    vehicle = ctl.vehicle
    if context.request_arm is True and not ctl.flags.armed:
        world.set(vehicle, Armed(True))
        world.set(vehicle, FailsafeStatus(FailsafeLevel.NOMINAL, now))
        world.set(vehicle, ActiveMode(ControlMode.GUIDED))
    elif context.request_arm is False and ctl.flags.armed:
        world.set(vehicle, Armed(False))
    if context.request_manipulator is not None and world.has_resource(Manipulator):
        world.resource(Manipulator).armed = context.request_manipulator
    setpoint = context.pose_setpoint
    armed = world.get(vehicle, Armed)
    if armed is None or not armed.armed:
        world.remove(vehicle, PoseTarget)
        world.remove(vehicle, EndEffectorTarget)
    elif setpoint is not None and setpoint.end_effector:
        reach = EndEffectorTarget(
            now, setpoint.position_ned, setpoint.yaw_rad, setpoint.velocity_ned
        )
        world.set(vehicle, reach)
        world.remove(vehicle, PoseTarget)
    elif setpoint is not None:
        world.remove(vehicle, EndEffectorTarget)
        target = PoseTarget(
            now,
            setpoint.position_ned,
            setpoint.yaw_rad,
            setpoint.velocity_ned,
            setpoint.yaw_rate_rad_s,
        )
        world.set(vehicle, target)
    elif not world.has(vehicle, PoseTarget):  # armed with no order yet: hold station here
        here = PoseTarget(now, context.estimate_position_ned, context.estimate_yaw_rad)
        world.set(vehicle, here)
    ready = not context.status.startswith(("executing", "setup"))
    status = MissionStatus(ready, auto.cancelled, auto.goals, context.reached_count)
    world.set(vehicle, status)


def control_velocity(world: World) -> None:
    """UPDATE (controller ``"ismc"``): the pose target → body twist → ISMC → force intent.

    Acts only armed and in GUIDED under autonomy (``ControlFlags.velocity``) with a
    :class:`PoseTarget` and a navigation estimate; otherwise its intent is zero and the ISMC is
    reset (so the sliding variable starts at 0 at the next arming). The target moves on at its
    feed-forward velocity between the tree's ticks.
    """
    auto = world.resource(Autonomy)
    ctl = world.resource(Controllers)
    ismc = auto.ismc
    assert ismc is not None
    vehicle = ctl.vehicle
    target = world.get(vehicle, PoseTarget)
    estimate = world.get(vehicle, NavigationEstimate)
    reach = world.resource(Manipulator).vehicle_twist if world.has_resource(Manipulator) else None
    flying = target is not None or reach is not None
    if not (ctl.flags.velocity and ctl.flags.armed) or not flying or estimate is None:
        ismc.reset()
        set_intent(world, ctl, "velocity", ZERO6)
        return
    clock = world.resource(SimClock)
    q = estimate.quaternion_wxyz
    nu = (*estimate.velocity_body_m_s, *estimate.rates_rad_s)
    down = quat_rotate_inverse(q, (0.0, 0.0, 1.0))
    if reach is not None:  # the TPIK's vehicle twist (an end-effector target)
        _fly_twist(world, ctl, ismc, reach, nu, down, clock.dt_s)
        return
    assert target is not None
    ahead = clock.time_s - target.time_s
    vn, ve, vd = target.velocity_ned_m_s
    pn, pe, pd = target.position_ned_m
    position = (pn + vn * ahead, pe + ve * ahead, pd + vd * ahead)
    yaw_rate = target.yaw_rate_rad_s
    twist = pose_twist(
        position,
        target.yaw_rad + yaw_rate * ahead,
        estimate.position_ned_m,
        q,
        auto.config.pose,
        (vn, ve, vd),
        yaw_rate,
    )
    _fly_twist(world, ctl, ismc, twist, nu, down, clock.dt_s)


def _fly_twist(
    world: World,
    ctl: Controllers,
    ismc: IsmcController,
    twist: tuple[float, ...],
    nu: tuple[float, ...],
    down: tuple[float, float, float],
    dt_s: float,
) -> None:
    """The ISMC's wrench for a body twist [m/s, rad/s] as the velocity intent (zero if not
    finite)."""
    wrench = ismc.update(twist, nu, down, dt_s)
    if not all(math.isfinite(w) for w in wrench):
        wrench = ZERO6
    set_intent(world, ctl, "velocity", wrench)
