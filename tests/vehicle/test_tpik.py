"""The set-based TPIK (testbed.vehicle.tpik) against independent truth.

Truth: closed forms of the pseudo-inverse (J⁻¹ for a square J, J⁺ for orthogonal row spaces),
the defining property of a task priority (a lower task never moves a higher task's output),
and, for the set-based tasks, long closed-loop runs of a vehicle-manipulator model written
here: a rigid body (NED position, body → NED quaternion) carrying a 4-joint arm whose
Jacobians are taken by central finite differences of its forward kinematics (no formula is
shared with the solver). The arm is not the Alpha 5 (testbed.vehicle.arm is not used): joint 0
turns the arm about body down, joints 1 and 2 pitch two links, joint 3 rolls the wrist.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import re
from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray

from testbed.common.geometry import (
    euler_from_quat,
    quat_from_axis_angle,
    quat_from_euler,
    quat_multiply,
    quat_normalize,
    rotation_matrix,
)
from testbed.config import ConfigError, FieldError
from testbed.vehicle.task_priority import EqualityTask, null_space, pinv, prioritized_solution
from testbed.vehicle.tpik import (
    JointLimitTask,
    TpikConfig,
    TpikInput,
    load_tpik_config,
    rotation_error,
    saturate,
    solve_uvms,
)

FloatArray = NDArray[np.float64]
N = 10  # 6 vehicle + 4 joints
T = 0.01


def _random_task(rng: np.random.Generator, m: int, name: str) -> EqualityTask:
    return EqualityTask(name, rng.normal(size=(m, N)), rng.normal(size=m))


# --- 1. priorities -------------------------------------------------------------------------


@pytest.mark.parametrize("seed", range(20))
def test_lower_task_never_changes_higher_task(seed: int) -> None:
    rng = np.random.default_rng(seed)
    high = [_random_task(rng, 2, "a"), _random_task(rng, 3, "b")]
    alone = prioritized_solution(high, N, T)
    with_low = prioritized_solution([*high, _random_task(rng, 4, "c")], N, T)
    changed = prioritized_solution([*high, _random_task(rng, 4, "c2")], N, T)
    for task in high:
        np.testing.assert_allclose(task.jacobian @ alone, task.error, atol=1e-9)
        np.testing.assert_allclose(task.jacobian @ with_low, task.error, atol=1e-9)
        np.testing.assert_allclose(task.jacobian @ changed, task.error, atol=1e-9)
    projector = null_space([t.jacobian for t in high], N, T)
    for task in high:
        np.testing.assert_allclose(task.jacobian @ projector, 0.0, atol=1e-9)
    np.testing.assert_allclose(projector @ projector, projector, atol=1e-9)
    np.testing.assert_allclose(projector, projector.T, atol=1e-12)


def test_more_tasks_than_dofs_keeps_the_higher_exact() -> None:
    rng = np.random.default_rng(7)
    tasks = [_random_task(rng, 4, "a"), _random_task(rng, 4, "b"), _random_task(rng, 5, "c")]
    zeta = prioritized_solution(tasks, N, T)
    for task in tasks[:2]:  # 8 ≤ 10 DOF: both met exactly; c gets what is left
        np.testing.assert_allclose(task.jacobian @ zeta, task.error, atol=1e-9)
    np.testing.assert_allclose(null_space([t.jacobian for t in tasks], N, T), 0.0, atol=1e-9)


def test_orthogonal_row_spaces_closed_form() -> None:
    rng = np.random.default_rng(3)
    basis, _ = np.linalg.qr(rng.normal(size=(N, N)))
    j1 = rng.normal(size=(2, 2)) @ basis[:, :2].T
    j2 = rng.normal(size=(3, 3)) @ basis[:, 2:5].T
    e1, e2 = rng.normal(size=2), rng.normal(size=3)
    zeta = prioritized_solution([EqualityTask("1", j1, e1), EqualityTask("2", j2, e2)], N, T)
    expected = np.linalg.pinv(j1) @ e1 + np.linalg.pinv(j2) @ e2
    np.testing.assert_allclose(zeta, expected, atol=1e-10)
    np.testing.assert_allclose(j1 @ zeta, e1, atol=1e-10)
    np.testing.assert_allclose(j2 @ zeta, e2, atol=1e-10)


# --- 2. closed form, singularity robustness ------------------------------------------------


@pytest.mark.parametrize("seed", range(10))
def test_square_invertible_task_is_the_inverse(seed: int) -> None:
    rng = np.random.default_rng(100 + seed)
    jac = rng.normal(size=(6, 6)) + 3.0 * np.eye(6)
    assert np.linalg.svd(jac, compute_uv=False).min() > 0.05
    xdot = rng.normal(size=6)
    zeta = prioritized_solution([EqualityTask("x", jac, xdot)], 6, T)
    np.testing.assert_allclose(zeta, np.linalg.solve(jac, xdot), atol=1e-10)


def test_rank_deficient_stack_stays_finite() -> None:
    rng = np.random.default_rng(5)
    row = rng.normal(size=N)
    conflicting = EqualityTask("dup", np.vstack([row, row]), np.array([1.0, -1.0]))
    nearly = EqualityTask("near", np.vstack([row, row + 1e-9]), np.array([1.0, 0.0]))
    same_again = EqualityTask("again", row[None, :] * 2.0, np.array([5.0]))
    zero = EqualityTask("zero", np.zeros((3, N)), np.ones(3))
    zeta = prioritized_solution([conflicting, nearly, same_again, zero], N, T)
    assert np.all(np.isfinite(zeta))
    assert np.linalg.norm(zeta) < 1.0 / T * 10.0  # the damped gain is at most 1/t
    assert np.allclose(prioritized_solution([zero], N, T), 0.0)


def _svd_law(matrix: FloatArray, t: float) -> tuple[FloatArray, FloatArray]:
    """The docstring's (d) written with an SVD: the robust inverse and the truncated N."""
    u, s, vt = np.linalg.svd(matrix, full_matrices=False)
    gain = np.where(s >= t, 1.0 / np.maximum(s, t), s / t**2)
    rows = vt[s >= t]
    return (vt.T * gain) @ u.T, np.eye(matrix.shape[1]) - rows.T @ rows


@pytest.mark.parametrize("seed", range(12))
@pytest.mark.parametrize("m", [1, 2, 3, 5, 12])
def test_pinv_and_null_space_are_the_svd_law(seed: int, m: int) -> None:
    """Singular values on both sides of t (and exact zeros): the stated law, however computed."""
    rng = np.random.default_rng(300 + seed)
    k = min(m, N)
    left, _ = np.linalg.qr(rng.normal(size=(m, k)))
    right, _ = np.linalg.qr(rng.normal(size=(N, k)))
    sigma = rng.choice([0.0, 0.3 * T, 0.9 * T, 1.1 * T, 3 * T, 0.5, 2.0], size=k)
    matrix = (left * sigma) @ right.T
    expected_inv, expected_null = _svd_law(matrix, T)
    np.testing.assert_allclose(pinv(matrix, T), expected_inv, atol=1e-8)
    np.testing.assert_allclose(null_space([matrix], N, T), expected_null, atol=1e-8)
    if m > 1:  # the same rows as several tasks stack to the same projector
        parts = [matrix[: m // 2], matrix[m // 2 :]]
        np.testing.assert_allclose(null_space(parts, N, T), expected_null, atol=1e-8)


# --- 3. set-based joint limits on a vehicle-manipulator model --------------------------------

LINKS = (0.15, 0.25, 0.2)  # upper arm, forearm, wrist to tip [m]
BASE = np.array([0.2, 0.0, 0.15])  # arm base in body FRD [m]


def _rot(axis: int, angle: float) -> FloatArray:
    c, s = math.cos(angle), math.sin(angle)
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    r = np.eye(3)
    r[i, i], r[i, j], r[j, i], r[j, j] = c, -s, s, c
    return r


def _arm(q: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Tip position in body FRD [m] and tip → body rotation of the test arm."""
    turn = _rot(2, q[0] - math.pi)  # joint 0 about body down; q0 = π points forward
    shoulder, elbow = _rot(1, q[1]), _rot(1, q[1] + q[2])
    reach = shoulder @ np.array([LINKS[0], 0.0, 0.0]) + elbow @ np.array([LINKS[1], 0.0, 0.0])
    tip_rot = turn @ elbow @ _rot(0, q[3])
    tip = BASE + turn @ reach + tip_rot @ np.array([LINKS[2], 0.0, 0.0])
    return tip, tip_rot


@functools.lru_cache(maxsize=64)
def _arm_at(q: tuple[float, ...]) -> tuple[FloatArray, FloatArray]:
    """:func:`_arm` of the joint angles ``q``, remembered: the model's central differences ask
    for the same angles many times over (the vehicle's columns leave them unchanged), and the
    same floats give the same arrays (read-only, as they are shared)."""
    tip, tip_rot = _arm(np.array(q))
    tip.setflags(write=False)
    tip_rot.setflags(write=False)
    return tip, tip_rot


@dataclasses.dataclass
class Uvms:
    position: FloatArray
    quat: tuple[float, float, float, float]
    q: FloatArray

    def step(self, zeta: FloatArray, dt: float) -> Uvms:
        r = np.array(rotation_matrix(self.quat))
        omega = zeta[3:6]
        angle = float(np.linalg.norm(omega)) * dt
        quat = self.quat
        if angle != 0.0:
            turn = quat_from_axis_angle(tuple(omega / np.linalg.norm(omega)), angle)
            quat = quat_normalize(quat_multiply(self.quat, turn))  # body-frame rates
        return Uvms(self.position + r @ zeta[:3] * dt, quat, self.q + zeta[6:] * dt)

    def ee(self) -> tuple[FloatArray, FloatArray]:
        r = np.array(rotation_matrix(self.quat))
        tip, tip_rot = _arm_at(tuple(self.q))
        return self.position + r @ tip, r @ tip_rot

    def jacobian(self, h: float = 1e-6) -> FloatArray:
        """ζ → (v_ned; ω_ned) of the tip by central differences of :meth:`step`."""
        jac = np.zeros((6, N))
        ee_rot = self.ee()[1]
        for k in range(N):
            d = np.zeros(N)
            d[k] = 1.0
            (p1, r1), (p0, r0) = self.step(d, h).ee(), self.step(d, -h).ee()
            skew = (r1 - r0) / (2.0 * h) @ ee_rot.T
            jac[:3, k] = (p1 - p0) / (2.0 * h)
            jac[3:, k] = (skew[2, 1], skew[0, 2], skew[1, 0])
        return jac

    def tpik_input(
        self, target: FloatArray, yaw: float, rotation: FloatArray | None = None
    ) -> TpikInput:
        ee_pos, ee_rot = self.ee()
        return TpikInput(
            q=self.q.copy(),
            position_ned_m=self.position.copy(),
            quaternion_wxyz=np.array(self.quat),
            ee_position_ned_m=ee_pos,
            ee_rotation_ned=ee_rot,
            uvms_jacobian=self.jacobian(),
            target_position_ned_m=target,
            target_rotation_ned=rotation,
            target_yaw_rad=yaw,
            target_velocity_ned_m_s=np.zeros(3),
        )


def _run(
    config: TpikConfig,
    start: Uvms,
    target: FloatArray,
    seconds: float = 60.0,
    rotation: FloatArray | None = None,
) -> tuple[FloatArray, list[set[str]], Uvms]:
    """Closed loop at config.rate_hz: (q history, active-name sets, final state)."""
    state, qs, actives = start, [start.q.copy()], []
    for _ in range(round(seconds * config.rate_hz)):
        out = solve_uvms(config, state.tpik_input(target, 0.0, rotation))
        zeta = np.array([*out.vehicle_twist, *out.joint_rates])
        state = state.step(zeta, config.period_s)
        qs.append(state.q.copy())
        actives.append(set(out.active))
    return np.array(qs), actives, state


def _start(q1: float) -> Uvms:
    return Uvms(
        np.array([0.0, 0.0, 2.0]), quat_from_euler(0, 0, 0), np.array([math.pi, q1, 1.0, 0])
    )


def test_model_jacobian_vehicle_columns() -> None:
    """The test model's finite differences against the rigid-body closed form."""
    state = Uvms(
        np.array([1.0, 2.0, 3.0]), quat_from_euler(0.2, -0.1, 0.7), np.array([3, 1, 1, 0.5])
    )
    jac = state.jacobian()
    r = np.array(rotation_matrix(state.quat))
    tip = _arm(state.q)[0]
    skew = np.array([[0, -tip[2], tip[1]], [tip[2], 0, -tip[0]], [-tip[1], tip[0], 0]])
    np.testing.assert_allclose(jac[:3, :3], r, atol=1e-8)
    np.testing.assert_allclose(jac[:3, 3:6], -r @ skew, atol=1e-8)
    np.testing.assert_allclose(jac[3:, :3], 0.0, atol=1e-8)
    np.testing.assert_allclose(jac[3:, 3:6], r, atol=1e-8)


def test_pose_task_converges() -> None:
    config = dataclasses.replace(load_tpik_config(), ee_orientation=True)
    start = _start(0.8)
    ee_pos, ee_rot = start.ee()
    turn = np.array(rotation_matrix(quat_from_axis_angle((0.0, 0.6, 0.8), 0.4)))
    target_rot = turn @ ee_rot
    target = ee_pos + np.array([0.2, 0.1, -0.1])
    _, _, final = _run(config, start, target, rotation=target_rot)
    pos, rot = final.ee()
    assert np.linalg.norm(pos - target) < 1e-3
    np.testing.assert_allclose(rot, target_rot, atol=1e-3)
    roll, pitch, _ = euler_from_quat(final.quat)
    assert abs(roll) < 1e-6 and abs(pitch) < 1e-6  # the arm turned the tip, not the vehicle


@pytest.mark.parametrize("angle", [0.0, 1e-7, 0.3, 2.0, math.pi - 1e-3, math.pi])
def test_rotation_error_is_the_rotation_vector(angle: float) -> None:
    rng = np.random.default_rng(11)
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    current = np.array(rotation_matrix(quat_normalize(tuple(rng.normal(size=4)))))
    target = np.array(rotation_matrix(quat_from_axis_angle(tuple(axis), angle))) @ current
    err = rotation_error(target, current)
    if angle == math.pi:  # ±axis are the same rotation
        err = err * np.sign(err @ axis)
    np.testing.assert_allclose(err, axis * angle, atol=1e-6)


TARGET_OFFSET = np.array([1.2, 0.0, 0.5])  # forward and down [m]: the shoulder (joint 1) drops


def test_free_solution_would_cross_the_limit() -> None:
    """The scenario below without limit tasks drives joint 1 (d) past its safety limit."""
    config = dataclasses.replace(load_tpik_config(), limit_tasks=())
    start = _start(0.3)
    target = start.ee()[0] + TARGET_OFFSET
    qs, _, final = _run(config, start, target)
    assert qs[:, 1].min() < 0.087 - 0.05
    assert np.linalg.norm(final.ee()[0] - target) < 1e-3


def test_limit_task_activates_and_safety_holds() -> None:
    config = load_tpik_config()
    d_task = next(t for t in config.limit_tasks if t.joint == 1)
    start = _start(0.3)
    target = start.ee()[0] + TARGET_OFFSET
    qs, actives, final = _run(config, start, target)
    assert qs[:, 1].min() >= d_task.safety[0]  # never crossed, whole run
    in_band = np.flatnonzero(qs[:-1, 1] <= d_task.low_threshold)
    assert in_band.size > 0  # entered the band ...
    assert any(d_task.name in actives[i] for i in in_band)  # ... and the task held it there
    for task in config.limit_tasks:
        assert np.all(qs[:, task.joint] >= task.safety[0])
        assert np.all(qs[:, task.joint] <= task.safety[1])
    # the vehicle takes over what the arm cannot do: the end effector still converges
    assert np.linalg.norm(final.ee()[0] - target) < 1e-3
    roll, pitch, _ = euler_from_quat(final.quat)
    assert abs(roll) < 1e-6 and abs(pitch) < 1e-6  # the level task kept it level


def test_reachable_target_leaves_set_tasks_inactive() -> None:
    config = load_tpik_config()
    start = _start(0.8)
    target = start.ee()[0] + np.array([0.1, -0.05, 0.05])
    qs, actives, final = _run(config, start, target)
    assert all(not a for a in actives)
    assert solve_uvms(config, start.tpik_input(target, 0.0)).mode_count == 1  # none in a band
    for task in config.limit_tasks:
        q = qs[:, task.joint]
        assert np.all((q > task.low_threshold) & (q < task.high_threshold))
    assert np.linalg.norm(final.ee()[0] - target) < 1e-3


def test_slow_creep_never_crosses() -> None:
    """A moving target asks joint 1 for −0.015 rad/s for ever (below Moe's 0.02 tolerance)."""
    config = load_tpik_config()
    d_task = next(t for t in config.limit_tasks if t.joint == 1)
    jac = np.zeros((6, N))
    jac[0, 7] = 1.0  # only joint 1 moves the end effector (along north)
    q = np.array([math.pi, 0.4, 1.0, 0.0])
    seen: set[str] = set()
    lowest = q[1]
    for k in range(round(120 * config.rate_hz)):
        inp = TpikInput(
            q=q.copy(),
            position_ned_m=np.zeros(3),
            quaternion_wxyz=np.array([1.0, 0.0, 0.0, 0.0]),
            ee_position_ned_m=np.array([q[1], 0.0, 0.0]),
            ee_rotation_ned=np.eye(3),
            uvms_jacobian=jac,
            target_position_ned_m=np.array([0.4 - 0.015 * k * config.period_s, 0.0, 0.0]),
            target_rotation_ned=None,
            target_yaw_rad=0.0,
            target_velocity_ned_m_s=np.array([-0.015, 0.0, 0.0]),
        )
        out = solve_uvms(config, inp)
        seen.update(out.active)
        q = q + np.array(out.joint_rates) * config.period_s
        lowest = min(lowest, q[1])
    assert d_task.name in seen
    assert d_task.safety[0] <= lowest <= d_task.low_threshold


def test_high_side_and_modes() -> None:
    """Joint 0 (e) at its high band edge: a mode per subset of band joints is solved."""
    config = load_tpik_config()
    e_task = next(t for t in config.limit_tasks if t.joint == 0)
    d_task = next(t for t in config.limit_tasks if t.joint == 1)
    state = Uvms(np.zeros(3), quat_from_euler(0, 0, 0), np.array([3.2, 0.1, 1.0, 0.0]))
    assert state.q[0] >= e_task.high_threshold and state.q[1] <= d_task.low_threshold
    target = state.ee()[0] + np.array([0.3, 0.3, -0.3])
    out = solve_uvms(config, state.tpik_input(target, 0.0))
    assert out.mode_count == 4
    for task, rate in ((e_task, out.joint_rates[0]), (d_task, out.joint_rates[1])):
        if task.name in out.active:
            threshold = task.high_threshold if task is e_task else task.low_threshold
            expected = task.gain * (threshold - state.q[task.joint])
            assert rate == pytest.approx(expected, abs=1e-9)
        else:  # admissible: inwards or slow
            inward = -rate if task is e_task else rate
            assert inward >= 0.0 or abs(rate) < 0.02


def test_yaw_and_level_tasks_turn_the_right_way() -> None:
    config = dataclasses.replace(load_tpik_config(), limit_tasks=())
    state = Uvms(np.zeros(3), quat_from_euler(0.1, -0.05, 0.0), np.array([math.pi, 0.8, 1.0, 0]))
    inp = dataclasses.replace(state.tpik_input(state.ee()[0], 0.0), target_yaw_rad=0.3)
    out = solve_uvms(config, inp)
    zeta = np.array([*out.vehicle_twist, *out.joint_rates])
    h = 1e-6  # Euler rates of the commanded body rates, by differences of the attitude
    after = np.array(euler_from_quat(state.step(zeta, h).quat))
    before = np.array(euler_from_quat(state.step(zeta, -h).quat))
    rates = (after - before) / (2.0 * h)
    np.testing.assert_allclose(rates, [-0.5 * 0.1, 0.5 * 0.05, 0.5 * 0.3], atol=1e-6)


# --- 4. configuration ------------------------------------------------------------------------


def test_packaged_config() -> None:
    config = load_tpik_config()
    assert config.rate_hz == 30.0 and config.period_s == pytest.approx(1 / 30)
    by_joint = {t.joint: t for t in config.limit_tasks}
    assert by_joint[1].safety == (0.087, 1.475) and by_joint[1].gain == 0.3
    assert by_joint[0].physical == (1.571, 3.316) and by_joint[0].activation == 0.087
    assert config.joint_velocity_limits == (0.5, 1.0, 1.0, 1.0)
    assert config.level_gain == 0.5 and config.yaw_gain == 0.5 and not config.ee_orientation
    hardware = load_tpik_config("alpha5-heavy-hardware")
    assert hardware.yaw_gain == 0.65 and all(t.gain == 0.2 for t in hardware.limit_tasks)
    with pytest.raises(ConfigError, match="unknown TPIK configuration 'nope'"):
        load_tpik_config("nope")


_GOOD = """
[x]
rate_hz = 30.0
ee_gain = 0.3
ee_orientation = true
orientation_gain = 0.3
max_linear_m_s = 0.5
max_angular_rad_s = 0.5
joint_velocity_limits = [0.5, 1.0]
singular_threshold = 0.01
[[x.limit_tasks]]
joint = 1
physical = [0.0, 1.571]
safety = [0.087, 1.475]
activation = 0.087
gain = GAIN
"""


def test_config_file_and_bad_values(tmp_path: Path) -> None:
    good = tmp_path / "good.toml"
    good.write_text(_GOOD.replace("GAIN", "0.3"))
    config = load_tpik_config("x", good)
    assert config.level_gain is None and config.yaw_gain is None and config.n_joints == 2
    cases = {
        "-0.3": "x.limit_tasks[0].gain",
        '"a"': "x.limit_tasks[0].gain",
    }
    for value, key in cases.items():
        bad = tmp_path / "bad.toml"
        bad.write_text(_GOOD.replace("GAIN", value))
        with pytest.raises(ConfigError, match=r"bad\.toml: " + re.escape(key)):
            load_tpik_config("x", bad)
    bad = tmp_path / "bad2.toml"
    bad.write_text(_GOOD.replace("GAIN", "0.3").replace("joint = 1", "joint = 2"))
    with pytest.raises(ConfigError, match=r"limit_tasks\[0\]\.joint"):
        load_tpik_config("x", bad)
    bad.write_text(_GOOD.replace("GAIN", "0.3").replace("[0.087, 1.475]", "[0.087, 1.6]"))
    with pytest.raises(ConfigError, match=r"limit_tasks\[0\]\.safety"):
        load_tpik_config("x", bad)
    with pytest.raises(FieldError, match="rate_hz"):
        dataclasses.replace(config, rate_hz=-1.0)  # the same checks on a caller's override


# --- 5. saturation ---------------------------------------------------------------------------


@pytest.mark.parametrize("seed", range(20))
def test_saturation_keeps_direction_and_limits(seed: int) -> None:
    config = load_tpik_config()
    rng = np.random.default_rng(200 + seed)
    zeta = rng.normal(size=N) * rng.uniform(0.1, 5.0)
    out = saturate(zeta, config)
    limits = np.array([0.5] * 6 + list(config.joint_velocity_limits))
    assert np.all(np.abs(out) <= limits + 1e-12)
    scale = float(out @ zeta / (zeta @ zeta))
    np.testing.assert_allclose(out, scale * zeta, atol=1e-12)  # parallel
    assert 0.0 < scale <= 1.0
    if np.all(np.abs(zeta) <= limits):
        np.testing.assert_array_equal(out, zeta)
    else:
        assert np.isclose(np.max(np.abs(out) / limits), 1.0)  # no more scaling than needed


def test_solver_output_within_limits() -> None:
    config = load_tpik_config()
    state = _start(0.8)
    far = state.ee()[0] + np.array([10.0, -5.0, 3.0])
    out = solve_uvms(config, state.tpik_input(far, 2.0))
    zeta = np.array([*out.vehicle_twist, *out.joint_rates])
    limits = np.array([0.5] * 6 + list(config.joint_velocity_limits))
    assert np.all(np.abs(zeta) <= limits + 1e-12)


def test_limit_task_checks() -> None:
    with pytest.raises(ValueError, match="overlap"):
        JointLimitTask(0, (0.0, 1.0), (0.1, 0.9), 0.5, 0.3)


def test_posture_task_brings_the_joints_home_and_leaves_the_higher_tasks_alone() -> None:
    """The optional lowest task (``posture_gain``): on the test UVMS flying its end effector
    round a 2-m square once (20 s a leg), the joints end near their start angles with it, and far
    from them without it (the minimum-norm solution lets the arm take part of every move, and
    nothing brings it back); and at any instant it does not change what the higher tasks get
    (J_ee ζ and J_yaw ζ the same with and without it, before saturation)."""
    plain = load_tpik_config()
    home = dataclasses.replace(plain, posture_gain=0.3)
    corners = [np.array(c) for c in ([2.5, 0, 2], [2.5, 2, 2], [0.5, 2, 2], [0.5, 0, 2])]
    ends = {}
    for name, config in (("plain", plain), ("home", home)):
        state = _start(1.0)
        for corner in corners:
            for _ in range(round(20.0 * config.rate_hz)):
                inp = dataclasses.replace(
                    state.tpik_input(corner, 0.0), posture_q_rad=_start(1.0).q
                )
                out = solve_uvms(config, inp)
                state = state.step(
                    np.array([*out.vehicle_twist, *out.joint_rates]), config.period_s
                )
        ends[name] = float(np.abs(state.q - _start(1.0).q).max())
        assert np.linalg.norm(state.ee()[0] - corners[-1]) < 0.01  # the mission flown either way
    assert ends["home"] < 0.01 and ends["plain"] > 0.1
    # priority: the posture rows only use what the higher tasks leave free
    state = _start(1.0)
    state = dataclasses.replace(state, q=state.q + np.array([0.3, -0.2, 0.2, 0.1]))
    inp = dataclasses.replace(state.tpik_input(corners[0], 0.2), posture_q_rad=_start(1.0).q)
    unsaturated = dataclasses.replace(home, max_linear_m_s=10.0, max_angular_rad_s=10.0)
    unsaturated = dataclasses.replace(unsaturated, joint_velocity_limits=(100.0,) * 4)
    with_it = solve_uvms(unsaturated, inp)
    without = solve_uvms(dataclasses.replace(unsaturated, posture_gain=None), inp)
    zeta_with = np.array([*with_it.vehicle_twist, *with_it.joint_rates])
    zeta_without = np.array([*without.vehicle_twist, *without.joint_rates])
    jac = inp.uvms_jacobian
    np.testing.assert_allclose(jac[:3] @ zeta_with, jac[:3] @ zeta_without, atol=1e-9)
    assert not np.allclose(zeta_with[6:], zeta_without[6:])  # it does move the joints
