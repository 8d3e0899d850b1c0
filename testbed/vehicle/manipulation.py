"""The vehicle's manipulator as ECS systems: joint state, TPIK, joint commands (Angler's UVMS).

A vehicle with a ``[vehicle.arm]`` table carries an arm on its hull (the physics:
:mod:`testbed.vehicle.arm_body`; the kinematics: :mod:`testbed.vehicle.arm`). Per frame:

- the vehicle writes the joints' measured angles and rates into the :class:`Manipulator`
  resource before the schedule runs (the arm's encoders: the joint motors' own state, as the
  Reach arm reports it over its serial link);
- UPDATE, :func:`plan_arm` (after the mission tree, before the velocity controller): with the
  manipulator armed and an :class:`EndEffectorTarget`, at the TPIK's rate (Angler: 30 Hz), it
  solves set-based TPIK (:func:`~testbed.vehicle.tpik.solve_uvms`) from the navigation estimate
  (never the physics truth) and the joints, giving a vehicle body twist — which
  :func:`~testbed.vehicle.autonomy.control_velocity` hands to the ISMC in place of the
  kinematic pose law's — and joint rates; every frame the joint-rate command moves towards the
  TPIK's within the joints' acceleration limit (2 rad/s²);
- after the frame, the vehicle drives the joint motors at :attr:`Manipulator.command_rad_s`.

Without a target, or disarmed, the joints are commanded to rest (they hold where they are)
and the vehicle flies its :class:`~testbed.vehicle.components.PoseTarget` as before.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from testbed.config import ConfigError, FieldError, check, check_ranges
from testbed.ecs import World
from testbed.vehicle.arm import ArmModel, load_arm_model
from testbed.vehicle.arm_kinematics import end_effector_ned, uvms_kinematics
from testbed.vehicle.filter_values import NavigationEstimate
from testbed.vehicle.resources import Controllers, SimClock
from testbed.vehicle.tpik import TpikConfig, TpikInput, TpikOutput, load_tpik_config, solve_uvms

__all__ = [
    "ArmConfig",
    "EndEffectorTarget",
    "Manipulator",
    "build_manipulator",
    "plan_arm",
]

Vec3 = tuple[float, float, float]
Vec6 = tuple[float, float, float, float, float, float]


@dataclass(frozen=True, slots=True)
class ArmConfig:
    """The scenario's ``[vehicle.arm]`` table: a manipulator on the hull.

    Attributes:
        model: the arm model: a packaged one (``testbed/vehicle/data/arms/NAME.toml``;
            ``alpha5``) or the path of the user's own ``.toml`` file in that layout.
        coupling: the arm's reaction forces act on the hull (True); False cancels them, as if
            the arm were massless to the vehicle (what the coupling costs the controller).
        trim: a float on the hull cancels the arm's weight in water and its moment in the
            initial pose (the vehicle is ballasted for its arm, as Angler's was).
        initial_q_rad: the joints at start [rad]; None = the model's.
        tpik: the TPIK configuration: a table of ``data/tpik.toml`` (``alpha5-heavy``) or the
            path of the user's own ``.toml`` file holding one such table's keys at its top level.
    """

    model: str = "alpha5"
    coupling: bool = True
    trim: bool = True
    initial_q_rad: tuple[float, ...] | None = None
    tpik: str = "alpha5-heavy"

    def __post_init__(self) -> None:
        if self.initial_q_rad is not None:
            check_ranges(self.initial_q_rad, "initial_q_rad", -2 * math.pi, 2 * math.pi, "rad")
        # a bad name or file fails here, naming the key (a start outside the limits is a
        # FieldError of initial_q_rad already)
        try:
            arm = self.arm_model()
        except ConfigError as err:
            raise FieldError("model", str(err)) from None
        try:
            tpik = load_tpik_config(self.tpik)
        except ConfigError as err:
            raise FieldError("tpik", str(err)) from None
        _check_tpik_fits_arm(tpik, arm, self.tpik)

    def arm_model(self) -> ArmModel:
        """The arm model, with ``initial_q_rad`` applied.

        Raises:
            ConfigError: a bad arm file; FieldError: a start of the wrong length or outside
                the joints' limits (naming the key).
        """
        model = load_arm_model(self.model)
        q = self.initial_q_rad
        if q is None:
            return model
        n = model.n_joints
        check(len(q) == n, "initial_q_rad", f"{n} joints, got {len(q)} values")
        for joint, angle in zip(model.joints, q, strict=True):
            inside = joint.lower_rad <= angle <= joint.upper_rad
            limits = f"[{joint.lower_rad:g}, {joint.upper_rad:g}]"
            check(inside, "initial_q_rad", f"{joint.name} = {angle:g} rad is outside {limits}")
        return dataclasses.replace(model, initial_q_rad=tuple(float(a) for a in q))


def _check_tpik_fits_arm(tpik: TpikConfig, arm: ArmModel, name: str) -> None:
    """Refuse, at load, a TPIK table for another arm: a joint count of its own (it crashed
    the run at its first solve), a joint-limit task whose physical range is not inside the
    arm's joint limits (degrees for radians flew the mission 1.4 m off, saying nothing), or
    whose safety range does not hold the arm's start angle."""
    n = arm.n_joints
    check(
        len(tpik.joint_velocity_limits) == n,
        "tpik",
        f"{name}: joint_velocity_limits: {len(tpik.joint_velocity_limits)} values for the "
        f"arm's {n} joints ({arm.name})",
    )
    for i, task in enumerate(tpik.limit_tasks):
        check(
            task.joint < n,
            "tpik",
            f"{name}: limit_tasks[{i}].joint: {task.joint}, the arm ({arm.name}) has joints "
            f"0…{n - 1}",
        )
        joint = arm.joints[task.joint]
        low, high = task.physical
        check(
            joint.lower_rad - 1e-9 <= low and high <= joint.upper_rad + 1e-9,
            "tpik",
            f"{name}: limit_tasks[{i}].physical: [{low:g}, {high:g}] rad is not inside "
            f"{joint.name}'s limits [{joint.lower_rad:g}, {joint.upper_rad:g}] rad ({arm.name}; "
            "degrees for radians?)",
        )
        start = arm.initial_q_rad[task.joint]
        low, high = task.safety
        check(
            low <= start <= high,
            "tpik",
            f"{name}: limit_tasks[{i}].safety: [{low:g}, {high:g}] rad does not hold "
            f"{joint.name}'s start angle {start:g} rad (the arm's initial_q_rad): the task "
            "would be broken from the first instant",
        )


@dataclass(frozen=True, slots=True)
class EndEffectorTarget:
    """Where the autonomy wants the end effector this instant (local to the vehicle).

    Attributes:
        time_s: vehicle time it was set [s].
        position_ned_m: (3,) the tool point's target [m], world NED.
        yaw_rad: the vehicle's heading meanwhile [rad, clockwise from north], or None.
        velocity_ned_m_s: (3,) the trajectory's velocity [m/s], world NED (feed-forward).
    """

    time_s: float
    position_ned_m: Vec3
    yaw_rad: float | None = None
    velocity_ned_m_s: Vec3 = (0.0, 0.0, 0.0)


@dataclass(slots=True)
class Manipulator:
    """The manipulator resource.

    Attributes:
        model: the arm.
        tpik: the TPIK's rates, gains and tasks.
        q_rad: measured joint angles [rad] (written by the vehicle each frame).
        rates_rad_s: measured joint rates [rad/s].
        armed: the manipulator is armed (its motors follow commands; set by the mission tree).
        command_rad_s: the joint-rate command this frame [rad/s] (acceleration-limited).
        vehicle_twist: the TPIK's vehicle body twist (u v w p q r) [m/s, rad/s], FRD, while it
            flies an end-effector target; None otherwise.
        last: the last TPIK solution, or None.
        next_solve_s: vehicle time of the next TPIK solve [s].
        solves: TPIK solves so far.
        limit_activations: solves with a joint-limit task active.
    """

    model: ArmModel
    tpik: TpikConfig
    q_rad: tuple[float, ...] = ()
    rates_rad_s: tuple[float, ...] = ()
    armed: bool = False
    command_rad_s: tuple[float, ...] = ()
    vehicle_twist: Vec6 | None = None
    last: TpikOutput | None = None
    next_solve_s: float = 0.0
    solves: int = 0
    limit_activations: int = 0
    _target_rates: tuple[float, ...] = field(default=())

    def __post_init__(self) -> None:
        n = self.model.n_joints
        self.q_rad = self.q_rad or tuple(self.model.initial_q_rad)
        self.rates_rad_s = self.rates_rad_s or (0.0,) * n
        self.command_rad_s = self.command_rad_s or (0.0,) * n
        self._target_rates = (0.0,) * n

    def end_effector_ned(
        self, position_ned: Vec3, quaternion_wxyz: tuple[float, float, float, float]
    ) -> Vec3:
        """The tool point [m], world NED, for the vehicle at this pose and the joints now."""
        p, _ = end_effector_ned(self.model, self.q_rad, position_ned, quaternion_wxyz)
        return (float(p[0]), float(p[1]), float(p[2]))


def build_manipulator(config: ArmConfig, model: ArmModel | None = None) -> Manipulator:
    """The :class:`Manipulator` resource of ``config`` (``model``: its arm, if loaded already)."""
    arm = model if model is not None else config.arm_model()
    return Manipulator(arm, load_tpik_config(config.tpik))


def plan_arm(world: World) -> None:
    """UPDATE: TPIK at its rate while armed with an end-effector target; the joint command
    moves towards its rates within the acceleration limit every frame (module docstring)."""
    arm = world.resource(Manipulator)
    ctl = world.resource(Controllers)
    clock = world.resource(SimClock)
    now = clock.time_s
    target = world.get(ctl.vehicle, EndEffectorTarget)
    estimate = world.get(ctl.vehicle, NavigationEstimate)
    active = arm.armed and ctl.flags.armed and target is not None and estimate is not None
    if not active:
        arm.vehicle_twist = None
        arm._target_rates = (0.0,) * arm.model.n_joints
        arm.next_solve_s = now
    elif now >= arm.next_solve_s - 1e-9:
        assert target is not None and estimate is not None
        arm.next_solve_s = max(arm.next_solve_s + arm.tpik.period_s, now)
        solution = solve_uvms(arm.tpik, _tpik_input(arm, target, estimate, now))
        arm.last = solution
        arm.solves += 1
        arm.limit_activations += bool(solution.active)
        if all(math.isfinite(v) for v in (*solution.vehicle_twist, *solution.joint_rates)):
            arm.vehicle_twist = solution.vehicle_twist
            arm._target_rates = solution.joint_rates
    step = arm.model.acceleration_rad_s2 * clock.dt_s
    arm.command_rad_s = tuple(
        c + min(step, max(-step, t - c))
        for c, t in zip(arm.command_rad_s, arm._target_rates, strict=True)
    )


def _tpik_input(
    arm: Manipulator, target: EndEffectorTarget, estimate: NavigationEstimate, now: float
) -> TpikInput:
    """The solver's input from the estimate, the joints and the target (moved on at its
    feed-forward velocity since it was set)."""
    q = np.asarray(arm.q_rad, dtype=float)
    position = np.asarray(estimate.position_ned_m, dtype=float)
    quaternion = np.asarray(estimate.quaternion_wxyz, dtype=float)
    ee_position, ee_rotation, jacobian = uvms_kinematics(arm.model, q, position, quaternion)
    ahead = now - target.time_s
    velocity = np.asarray(target.velocity_ned_m_s, dtype=float)
    posture = np.asarray(arm.model.initial_q_rad, dtype=float)  # the start pose
    return TpikInput(
        q=q,
        position_ned_m=position,
        quaternion_wxyz=quaternion,
        ee_position_ned_m=ee_position,
        ee_rotation_ned=ee_rotation,
        uvms_jacobian=jacobian,
        target_position_ned_m=np.asarray(target.position_ned_m, dtype=float) + velocity * ahead,
        target_rotation_ned=None,
        target_yaw_rad=target.yaw_rad,
        target_velocity_ned_m_s=velocity,
        posture_q_rad=posture,
    )
