"""Set-based task-priority inverse kinematics (TPIK) of the vehicle-manipulator system (UVMS).

After Moe, Antonelli, Teel, Pettersen & Schrimpf (2016), "Set-based tasks within the
singularity-robust multiple task-priority inverse kinematics framework", as Angler's
``tpik_joint_trajectory_controller`` uses it. The unknown ζ = (u v w p q r, q̇_1 … q̇_n) is the
body twist (FRD, at the body origin) [m/s, rad/s] and the arm joint rates (Alpha 5: e d c b)
[rad/s]. Equality tasks (highest first) are solved by the recursive null-space projection of
:mod:`testbed.vehicle.task_priority`, so a lower task never changes what a higher one gets.
Set-based tasks (joint limits) are handled by Moe's mode
enumeration (:func:`solve_uvms`): with k joints inside their activation band, all 2^k modes
(each such limit task inactive, or active as an equality task at top priority) are solved; a
mode is admissible if every band-joint *not* active in it moves inwards (q̇_j ≥ 0 at the low
side, ≤ 0 at the high side) or slowly (|q̇_j| < 0.02 rad/s); the admissible ζ of largest norm
is taken (ties: the mode with fewer active tasks). The mode with every candidate active is
always admissible (nothing left to check).

Joint-limit task of joint j (:class:`JointLimitTask`): a candidate when q_j ≤ safety_low +
activation or q_j ≥ safety_high − activation (that band edge is its threshold); active, it is
q̇_j = gain·(threshold − q_j). The physical limits only bound the safety limits (checked).

Task order (highest first), as built by :func:`solve_uvms`:

1. joint-limit set tasks (Angler main, priority 1);
2. vehicle "level": roll, pitch → 0 (``level_gain``; ours, see below);
3. end effector: position (3-D, NED) or, with ``ee_orientation`` and a target rotation, the
   6-D pose (Angler main priority 2, 6-D pose; Angler hardware adds a 3-D position task);
4. vehicle yaw → target (``yaw_gain``; Angler priority 3), skipped if no target yaw;
5. arm posture: every joint → its start angle (``posture_gain``; off unless set, as in Angler's
   configurations; Angler's task library has it as ``ManipulatorJointConfigurationTask``): the
   lowest task, it only uses what the others leave free, so it does not change their outputs;
   without it the minimum-norm solution lets the joints drift on long missions
   (docs/manipulator.md).

Our additions to Angler (also stated in ``data/tpik.toml``):

(a) the *level* task: the vehicle is passively stable in roll and pitch; without the task a
    6-D end-effector task could ask it to tilt. On by default; ``level_gain = None`` (omit
    the key in TOML) turns it off.
(b) the end-effector task defaults to position only; orientation is an option.
(c) a final saturation (:func:`saturate`): if any body velocity component or joint rate
    exceeds its limit, the whole ζ is scaled down uniformly; its direction, and so the
    priorities, are kept (every task velocity J_i ζ is scaled by the same factor).
(d) singularity-robust pseudo-inverses (:func:`~testbed.vehicle.task_priority.pinv`, t =
    ``singular_threshold``), and null-space projectors truncated at the same t.
(e) a safety guard on Moe's slow-motion tolerance: an inactive band-joint moving outwards
    slower than 0.02 rad/s is admissible only if one period at that rate keeps it inside its
    safety limit, so a slow creep can never cross it.

Frames: body FRD, world NED. Euler angles are Z-Y-X (:func:`~testbed.common.geometry.
euler_from_quat`). Orientation error: the rotation vector (axis·angle) of R_target·R_eeᵀ, in
NED. Pure numpy; no ECS, no randomness.
"""

from __future__ import annotations

import functools
import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from testbed.common.geometry import Vec3, euler_from_quat, wrap_angle
from testbed.config import (
    build,
    check,
    check_range,
    check_ranges,
    load_toml,
    named_table,
    user_file,
)
from testbed.vehicle.task_priority import (
    EqualityTask,
    Level,
    descend,
    finish,
    start_level,
)

__all__ = [
    "SLOW_RATE_RAD_S",
    "JointLimitTask",
    "TpikConfig",
    "TpikInput",
    "TpikOutput",
    "load_tpik_config",
    "rotation_error",
    "saturate",
    "solve_uvms",
    "tpik_config_names",
]

FloatArray = NDArray[np.float64]
VEHICLE_DOF = 6
SLOW_RATE_RAD_S = 0.02
"""Moe/Angler: an inactive set task whose task velocity is below this [rad/s] is admissible."""
_MAX_GAIN_1_S = 100.0
_MIN_COS_PITCH = 1e-6


@dataclass(frozen=True, slots=True)
class JointLimitTask:
    """A joint-limit set-based task (module docstring) of one arm joint.

    Attributes:
        joint: index into the arm's joints (0 = first arm joint, i.e. ζ index 6 + joint).
        physical: (low, high) the joint's mechanical range [rad].
        safety: (low, high) the range the joint must stay in [rad], inside ``physical``.
        activation: band width inside the safety limits where the task may activate [rad],
            > 0; the bands of the two sides must not overlap.
        gain: K of the active task q̇ = K·(threshold − q) [1/s], in (0, 100].
    """

    joint: int
    physical: tuple[float, float]
    safety: tuple[float, float]
    activation: float
    gain: float

    def __post_init__(self) -> None:
        check(self.joint >= 0, "joint", f"must be ≥ 0, got {self.joint}")
        check_ranges(self.physical, "physical", -100.0, 100.0, "rad")
        check_ranges(self.safety, "safety", -100.0, 100.0, "rad")
        check(self.physical[0] < self.physical[1], "physical", "low must be < high")
        check(
            self.physical[0] <= self.safety[0] < self.safety[1] <= self.physical[1],
            "safety",
            f"must be an increasing pair inside physical {self.physical}, got {self.safety}",
        )
        check_range(self.activation, "activation", 0.0, 10.0, "rad", low_open=True)
        check(
            self.low_threshold < self.high_threshold,
            "activation",
            f"the two activation bands overlap (safety {self.safety}, band {self.activation})",
        )
        check_range(self.gain, "gain", 0.0, _MAX_GAIN_1_S, "1/s", low_open=True)

    @property
    def name(self) -> str:
        """The task's name in :attr:`TpikOutput.active`: ``joint_limit_<joint>``."""
        return f"joint_limit_{self.joint}"

    @property
    def low_threshold(self) -> float:
        """safety_low + activation [rad]: at or below it the low side is a candidate."""
        return self.safety[0] + self.activation

    @property
    def high_threshold(self) -> float:
        """safety_high − activation [rad]: at or above it the high side is a candidate."""
        return self.safety[1] - self.activation


@dataclass(frozen=True, slots=True)
class TpikConfig:
    """TPIK rates, gains and task set (``data/tpik.toml``; module docstring for the tasks).

    Attributes:
        rate_hz: the rate the solver runs at [Hz], in (0, 1000].
        limit_tasks: the joint-limit set tasks (one per joint at most), top priority.
        level_gain: gain of the roll/pitch → 0 task [1/s], or None for no level task.
        ee_gain: gain of the end-effector position task [1/s].
        ee_orientation: also control the end-effector orientation (6-D pose task) when the
            input has a target rotation.
        orientation_gain: gain of the orientation rows of the pose task [1/s].
        yaw_gain: gain of the vehicle yaw task [1/s], or None for no yaw task.
        posture_gain: gain of the arm posture task (joints → their start angles) [1/s], or
            None for none (the default, as Angler's configurations).
        max_linear_m_s: limit on each of u, v, w [m/s].
        max_angular_rad_s: limit on each of p, q, r [rad/s].
        joint_velocity_limits: limit per arm joint [rad/s]; its length is the joint count.
        singular_threshold: t of the singularity-robust pseudo-inverse (:func:`pinv`), in
            (0, 1).
    """

    rate_hz: float
    limit_tasks: tuple[JointLimitTask, ...]
    level_gain: float | None
    ee_gain: float
    ee_orientation: bool
    orientation_gain: float
    yaw_gain: float | None
    max_linear_m_s: float
    max_angular_rad_s: float
    joint_velocity_limits: tuple[float, ...]
    singular_threshold: float
    posture_gain: float | None = None

    def __post_init__(self) -> None:
        check_range(self.rate_hz, "rate_hz", 0.0, 1000.0, "Hz", low_open=True)
        for key in ("level_gain", "yaw_gain", "posture_gain"):
            value = getattr(self, key)
            if value is not None:
                check_range(value, key, 0.0, _MAX_GAIN_1_S, "1/s", low_open=True)
        check_range(self.ee_gain, "ee_gain", 0.0, _MAX_GAIN_1_S, "1/s", low_open=True)
        check_range(self.orientation_gain, "orientation_gain", 0.0, _MAX_GAIN_1_S, "1/s")
        check_range(self.max_linear_m_s, "max_linear_m_s", 0.0, 10.0, "m/s", low_open=True)
        check_range(self.max_angular_rad_s, "max_angular_rad_s", 0.0, 10.0, low_open=True)
        check(len(self.joint_velocity_limits) > 0, "joint_velocity_limits", "must not be empty")
        check_ranges(
            self.joint_velocity_limits, "joint_velocity_limits", 0.0, 100.0, "rad/s", low_open=True
        )
        check_range(
            self.singular_threshold, "singular_threshold", 0.0, 1.0, low_open=True, high_open=True
        )
        joints = [task.joint for task in self.limit_tasks]
        for i, joint in enumerate(joints):
            key = f"limit_tasks[{i}].joint"
            n = len(self.joint_velocity_limits)
            check(joint < n, key, f"must be < {n} (the joint count), got {joint}")
            check(joint not in joints[:i], key, f"joint {joint} has two limit tasks")

    @property
    def period_s(self) -> float:
        """1 / rate_hz [s]."""
        return 1.0 / self.rate_hz

    @property
    def n_joints(self) -> int:
        """The arm's joint count (length of ``joint_velocity_limits``)."""
        return len(self.joint_velocity_limits)


@functools.cache
def _packaged_tables() -> tuple[str, dict[str, Any]]:
    """The packaged ``data/tpik.toml``: its path (for messages) and its tables, read once per
    process."""
    entry = resources.files("testbed.vehicle").joinpath("data", "tpik.toml")
    with resources.as_file(entry) as packaged:
        return str(packaged), load_toml(packaged)


def tpik_config_names() -> list[str]:
    """Names of the packaged TPIK configurations (the tables of ``data/tpik.toml``), sorted."""
    return sorted(_packaged_tables()[1])


def load_tpik_config(name: str = "alpha5-heavy", path: str | Path | None = None) -> TpikConfig:
    """A TPIK configuration: the packaged table ``name`` of ``data/tpik.toml``, or the user's
    own TOML file at the path ``name`` (:func:`~testbed.config.user_file`), which holds one
    configuration: one table's keys at its top level (``rate_hz = 30.0``, ``[[limit_tasks]]``).

    With ``path``, the table ``name`` of that file (``data/tpik.toml``'s layout) instead.

    TOML has no null: a table without ``level_gain`` / ``yaw_gain`` has that task off. Change
    single values with ``dataclasses.replace`` (which runs the same checks).

    Raises:
        ConfigError: neither a packaged name nor an existing ``.toml`` file (the message lists
            the packaged ones, or names the path), a missing file or table, or a bad table
            (file and dotted key named).
    """
    if path is not None:
        source = str(path)
        table = named_table(load_toml(path), name, source, "TPIK table")
        return _tpik_config(table, source, f"{name}.")
    own = user_file(name, tpik_config_names(), "TPIK configuration")
    if own is None:
        return _packaged_tpik_config(name)
    return _tpik_config(load_toml(own), str(own), "")


@functools.cache
def _packaged_tpik_config(name: str) -> TpikConfig:
    """Table ``name`` of the packaged ``data/tpik.toml``, built once per process."""
    source, tables = _packaged_tables()
    return _tpik_config(named_table(tables, name, source, "TPIK table"), source, f"{name}.")


def _tpik_config(table: dict[str, Any], source: str, prefix: str) -> TpikConfig:
    """Build one configuration's table; messages name ``source`` and ``prefix`` + the key."""
    data: dict[str, Any] = {"level_gain": None, "yaw_gain": None, "posture_gain": None, **table}
    data.pop("source", None)  # free-text provenance
    return build(TpikConfig, data, source=source, prefix=prefix)


def rotation_error(target: FloatArray, current: FloatArray) -> FloatArray:
    """Rotation vector (axis·angle, [rad], in the frame of both) of ``target @ current.T``.

    The angle is in [0, π]; at exactly π the axis is taken from R + I.
    """
    r = np.asarray(target, dtype=float) @ np.asarray(current, dtype=float).T
    axis_sin = 0.5 * np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    sin_angle = float(np.linalg.norm(axis_sin))
    cos_angle = 0.5 * (float(np.trace(r)) - 1.0)
    angle = math.atan2(sin_angle, cos_angle)
    if sin_angle > 1e-9:
        return axis_sin * (angle / sin_angle)
    if cos_angle > 0.0:
        return axis_sin  # small angle: sin θ ≈ θ
    sym = r + np.eye(3)  # half turn: columns of R + I = 2·a·aᵀ are along the axis
    column = sym[:, int(np.argmax(np.linalg.norm(sym, axis=0)))]
    return column / np.linalg.norm(column) * math.pi  # type: ignore[no-any-return]


@dataclass(frozen=True, slots=True)
class TpikInput:
    """One solver step's state and targets (world NED, body FRD).

    Attributes:
        q: (n,) arm joint angles [rad].
        position_ned_m: (3,) vehicle body origin in NED [m] (for reports; no task uses it).
        quaternion_wxyz: (4,) vehicle attitude, body FRD → NED.
        ee_position_ned_m: (3,) end-effector position in NED [m].
        ee_rotation_ned: (3, 3) end-effector orientation (ee frame → NED).
        uvms_jacobian: (6, 6 + n) ζ → end-effector (v_ned [m/s]; ω_ned [rad/s]).
        target_position_ned_m: (3,) end-effector target [m].
        target_rotation_ned: (3, 3) end-effector target orientation, or None.
        target_yaw_rad: vehicle heading target [rad], or None (no yaw task).
        target_velocity_ned_m_s: (3,) end-effector feed-forward velocity [m/s] (zeros if none).
        posture_q_rad: (n,) the joints' posture (their start angles) [rad], or None (no
            posture task).
    """

    q: FloatArray
    position_ned_m: FloatArray
    quaternion_wxyz: FloatArray
    ee_position_ned_m: FloatArray
    ee_rotation_ned: FloatArray
    uvms_jacobian: FloatArray
    target_position_ned_m: FloatArray
    target_rotation_ned: FloatArray | None
    target_yaw_rad: float | None
    target_velocity_ned_m_s: FloatArray
    posture_q_rad: FloatArray | None = None


@dataclass(frozen=True, slots=True)
class TpikOutput:
    """The solver's command.

    Attributes:
        vehicle_twist: (u v w p q r) body FRD [m/s, rad/s].
        joint_rates: arm joint rates [rad/s].
        active: names (:attr:`JointLimitTask.name`) of the set tasks active in the chosen mode.
        mode_count: modes solved this step, 2^k for k joints inside their activation band.
    """

    vehicle_twist: tuple[float, float, float, float, float, float]
    joint_rates: tuple[float, ...]
    active: tuple[str, ...]
    mode_count: int


def saturate(zeta: FloatArray, config: TpikConfig) -> FloatArray:
    """ζ scaled by one factor s ∈ (0, 1] so every component is within its limit.

    Limits: ``max_linear_m_s`` on u v w, ``max_angular_rad_s`` on p q r, and
    ``joint_velocity_limits`` on the joints. ζ within all limits is returned unchanged.
    """
    zeta = np.asarray(zeta, dtype=float)
    limits = (
        (config.max_linear_m_s,) * 3
        + (config.max_angular_rad_s,) * 3
        + tuple(config.joint_velocity_limits)
    )
    if zeta.shape != (len(limits),):
        raise ValueError(f"ζ has shape {zeta.shape}, the limits {(len(limits),)}")
    ratio = max(abs(z) / limit for z, limit in zip(zeta.tolist(), limits, strict=True))
    return zeta / ratio if ratio > 1.0 else zeta.copy()


def _euler_rows(state: TpikInput, n: int) -> tuple[Vec3, FloatArray]:
    """(roll, pitch, yaw) [rad] and the (3, n) rows of (φ̇, θ̇, ψ̇) in ζ (Z-Y-X kinematics)."""
    roll, pitch, yaw = euler_from_quat(tuple(float(x) for x in state.quaternion_wxyz))
    sr, cr = math.sin(roll), math.cos(roll)
    cp = math.cos(pitch)
    cp = math.copysign(max(abs(cp), _MIN_COS_PITCH), cp)
    tp = math.sin(pitch) / cp
    rows = np.zeros((3, n))
    rows[0, 3:6] = (1.0, sr * tp, cr * tp)  # φ̇ = p + sinφ tanθ q + cosφ tanθ r
    rows[1, 4:6] = (cr, -sr)  # θ̇ = cosφ q − sinφ r
    rows[2, 4:6] = (sr / cp, cr / cp)  # ψ̇ = (q sinφ + r cosφ) / cosθ
    return (roll, pitch, yaw), rows


def _ee_task(config: TpikConfig, state: TpikInput) -> EqualityTask:
    jac = np.asarray(state.uvms_jacobian, dtype=float)
    position = config.ee_gain * (
        np.asarray(state.target_position_ned_m, dtype=float)
        - np.asarray(state.ee_position_ned_m, dtype=float)
    ) + np.asarray(state.target_velocity_ned_m_s, dtype=float)
    if config.ee_orientation and state.target_rotation_ned is not None:
        turn = rotation_error(state.target_rotation_ned, state.ee_rotation_ned)
        error = np.concatenate([position, config.orientation_gain * turn])
        return EqualityTask("end_effector_pose", jac, error)
    return EqualityTask("end_effector_position", jac[:3], position)


def _admissible(
    zeta: FloatArray, q: FloatArray, inactive: Sequence[JointLimitTask], dt: float
) -> bool:
    """Moe's rule for the band-joints not active in a mode, with the guard (e) of the docstring."""
    for task in inactive:
        qj = float(q[task.joint])
        rate = float(zeta[VEHICLE_DOF + task.joint])
        low = qj <= task.low_threshold
        outward = -rate if low else rate  # > 0: towards the limit
        if outward <= 0.0:
            continue
        if outward >= SLOW_RATE_RAD_S:
            return False
        after = qj + rate * dt
        if (low and after < task.safety[0]) or (not low and after > task.safety[1]):
            return False
    return True


def _limit_task(task: JointLimitTask, q: FloatArray, n: int) -> EqualityTask:
    qj = float(q[task.joint])
    target = task.low_threshold if qj <= task.low_threshold else task.high_threshold
    jac = np.zeros((1, n))
    jac[0, VEHICLE_DOF + task.joint] = 1.0
    return EqualityTask(task.name, jac, np.array([task.gain * (target - qj)]))


def solve_uvms(config: TpikConfig, state: TpikInput) -> TpikOutput:
    """One TPIK step: the saturated ζ of the task set of the module docstring.

    Raises:
        ValueError: the input's shapes do not match each other or the config's joint count.
    """
    q = np.asarray(state.q, dtype=float).reshape(-1)
    n_joints = config.n_joints
    n = VEHICLE_DOF + n_joints
    if q.shape != (n_joints,):
        raise ValueError(f"q has {q.size} joints, the config {n_joints}")
    if np.shape(state.uvms_jacobian) != (6, n):
        raise ValueError(f"uvms_jacobian has shape {np.shape(state.uvms_jacobian)}, not (6, {n})")
    (roll, pitch, yaw), euler_rows = _euler_rows(state, n)
    fixed: list[EqualityTask] = []  # the equality tasks below the set tasks, highest first
    if config.level_gain is not None:
        level_error = config.level_gain * np.array([-roll, -pitch])
        fixed.append(EqualityTask("level", euler_rows[:2], level_error))
    fixed.append(_ee_task(config, state))
    if config.yaw_gain is not None and state.target_yaw_rad is not None:
        yaw_error = np.array([config.yaw_gain * wrap_angle(state.target_yaw_rad - yaw)])
        fixed.append(EqualityTask("yaw", euler_rows[2:], yaw_error))
    if config.posture_gain is not None and state.posture_q_rad is not None:
        rows = np.zeros((n_joints, n))
        rows[:, VEHICLE_DOF:] = np.eye(n_joints)
        posture = np.asarray(state.posture_q_rad, dtype=float) - q
        fixed.append(EqualityTask("posture", rows, config.posture_gain * posture))
    candidates = [
        t
        for t in config.limit_tasks
        if q[t.joint] <= t.low_threshold or q[t.joint] >= t.high_threshold
    ]
    best: FloatArray | None = None
    best_active: tuple[JointLimitTask, ...] = ()
    best_norm = -1.0
    modes = 0
    threshold = config.singular_threshold
    # the recursion after each mode's set tasks, which come first: a mode's prefix is the
    # mode of its first active tasks (combinations come in order), solved before it
    prefixes: dict[tuple[JointLimitTask, ...], Level] = {(): start_level(n)}
    for count in range(len(candidates) + 1):
        for active in itertools.combinations(candidates, count):
            modes += 1
            level = prefixes.get(active)
            if level is None:
                parent = prefixes[active[:-1]]
                level = descend(parent, _limit_task(active[-1], q, n), threshold, True)
                if count < len(candidates):
                    prefixes[active] = level
            zeta = finish(level, fixed, threshold)
            if not candidates:  # one mode, nothing to check
                best, best_active = zeta, active
                break
            inactive = [t for t in candidates if t not in active]
            if not _admissible(zeta, q, inactive, config.period_s):
                continue
            norm = float(np.linalg.norm(zeta))
            if norm > best_norm:
                best, best_active, best_norm = zeta, active, norm
    assert best is not None  # the all-active mode has nothing to check
    zeta = saturate(best, config)
    values = zeta.tolist()
    u, v, w, p, q_rate, r = values[:VEHICLE_DOF]
    return TpikOutput(
        vehicle_twist=(u, v, w, p, q_rate, r),
        joint_rates=tuple(values[VEHICLE_DOF:]),
        active=tuple(t.name for t in best_active),
        mode_count=modes,
    )
