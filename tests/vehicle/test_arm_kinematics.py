"""The arm's kinematics (testbed.vehicle.arm) against independent truth.

* Forward kinematics against pybullet's URDF parser and its own forward kinematics, on an oracle
  URDF written here from the *published table* (Reach Alpha 5: the alpha URDF's joint origins,
  rpy and axes; the BlueROV2 Heavy mount), not from the package's TOML. pybullet's world is
  the vehicle's ROS base_link (FLU); its frames map to ours by p_frd = S p, R_frd = S R S with
  S = diag(1, −1, −1).
* The arm Jacobian against pybullet's ``calculateJacobian`` on that body and against central
  finite differences of our own FK; the UVMS Jacobian against central differences of
  ``end_effector_ned`` along a vehicle body twist.
* The package data: masses and volumes sum to the published figures; a bad value is a
  ConfigError naming the file and the key.
"""

from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pybullet
import pytest
from numpy.typing import NDArray

from testbed.common.geometry import quat_from_axis_angle, quat_from_euler, quat_multiply
from testbed.config import ConfigError
from testbed.vehicle.arm import ArmModel, load_arm_model
from testbed.vehicle.arm_kinematics import (
    arm_jacobian,
    base_transform,
    end_effector_ned,
    end_effector_pose,
    joint_transforms,
    link_centres_body,
    link_centres_ned,
    uvms_jacobian,
    uvms_kinematics,
)

S = np.diag([1.0, -1.0, -1.0])
PACKAGED = (
    Path(__file__).resolve().parents[2] / "testbed" / "vehicle" / "data" / "arms" / "alpha5.toml"
)

# The published table: (name, origin in the parent link [m], rpy [rad], axis, limits [rad]).
TABLE = [
    ("axis_e", (0.0, 0.0, 0.014), (0.0, 0.0, 0.0), (0, 0, 1), (0.0, 6.10)),
    ("axis_d", (-0.02, 0.0, 0.033), (0.0, 0.0, 0.0), (0, 1, 0), (0.0, 3.49)),
    ("axis_c", (-0.04, 0.0, -0.1453), (0.0, 0.0, math.pi), (0, 1, 0), (0.0, 3.22)),
    ("axis_b", (0.02, 0.0, 0.033), (0.0, 0.0, 2.09439), (0, 0, -1), (0.0, 3.22)),
]
EE = (0.0, 0.0, 0.09975)
MOUNT = (0.24, -0.099, 0.029)
LOWER = np.array([row[4][0] for row in TABLE])
UPPER = np.array([row[4][1] for row in TABLE])


def _v(x: tuple[float, ...]) -> str:
    return " ".join(f"{c:.17g}" for c in x)


def _oracle_urdf() -> str:
    """A URDF of the published table; every link's inertial frame at its link frame."""
    inertial = (
        '<inertial><origin xyz="0 0 0" rpy="0 0 0"/><mass value="0.1"/>'
        '<inertia ixx="1e-4" iyy="1e-4" izz="1e-4" ixy="0" ixz="0" iyz="0"/></inertial>'
    )
    links = ["base", "link_e", "link_d", "link_c", "link_b", "ee"]
    parts = ['<?xml version="1.0"?>', '<robot name="oracle">']
    parts += [f'<link name="{name}">{inertial}</link>' for name in links]
    for i, (name, origin, rpy, axis, (lo, hi)) in enumerate(TABLE):
        parts.append(
            f'<joint name="{name}" type="revolute"><parent link="{links[i]}"/>'
            f'<child link="{links[i + 1]}"/><origin xyz="{_v(origin)}" rpy="{_v(rpy)}"/>'
            f'<axis xyz="{_v(axis)}"/><limit lower="{lo}" upper="{hi}" effort="10" velocity="1"/>'
            "</joint>"
        )
    parts.append(
        '<joint name="ee" type="fixed"><parent link="link_b"/><child link="ee"/>'
        f'<origin xyz="{_v(EE)}" rpy="0 0 0"/></joint>'
    )
    parts.append("</robot>")
    return "\n".join(parts)


@pytest.fixture(scope="module")
def model() -> ArmModel:
    return load_arm_model()


@pytest.fixture(scope="module")
def oracle(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[int, int]]:
    path = tmp_path_factory.mktemp("oracle") / "oracle.urdf"
    path.write_text(_oracle_urdf(), encoding="utf-8")
    client = pybullet.connect(pybullet.DIRECT)
    body = pybullet.loadURDF(
        str(path), basePosition=MOUNT, useFixedBase=True, physicsClientId=client
    )
    assert pybullet.getNumJoints(body, physicsClientId=client) == 5
    yield client, body
    pybullet.disconnect(client)


def _random_q(rng: np.random.Generator) -> NDArray[np.float64]:
    return rng.uniform(LOWER, UPPER)


def _set(oracle: tuple[int, int], q: NDArray[np.float64]) -> None:
    client, body = oracle
    for j, angle in enumerate(q):
        pybullet.resetJointState(body, j, float(angle), physicsClientId=client)


def _rotation_log(r: NDArray[np.float64]) -> NDArray[np.float64]:
    """The rotation vector of a (near-identity) rotation matrix."""
    angle = math.acos(max(-1.0, min(1.0, 0.5 * (np.trace(r) - 1.0))))
    w = 0.5 * np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    return w if angle < 1e-12 else w * angle / math.sin(angle)


# --- forward kinematics ------------------------------------------------------------------------


def test_forward_kinematics_matches_pybullet(model: ArmModel, oracle: tuple[int, int]) -> None:
    client, body = oracle
    base_pos, base_quat = pybullet.getBasePositionAndOrientation(body, physicsClientId=client)
    base_rot = np.array(pybullet.getMatrixFromQuaternion(base_quat)).reshape(3, 3)
    np.testing.assert_allclose(base_transform(model)[:3, 3], S @ np.array(base_pos), atol=1e-6)
    np.testing.assert_allclose(base_transform(model)[:3, :3], S @ base_rot @ S, atol=1e-6)
    rng = np.random.default_rng(20261202)
    for _ in range(60):
        q = _random_q(rng)
        _set(oracle, q)
        frames = joint_transforms(model, q)
        assert len(frames) == 5
        for j, frame in enumerate(frames):
            state = pybullet.getLinkState(
                body, j, computeForwardKinematics=True, physicsClientId=client
            )
            pos = np.array(state[4])
            rot = np.array(pybullet.getMatrixFromQuaternion(state[5])).reshape(3, 3)
            np.testing.assert_allclose(frame[:3, 3], S @ pos, atol=1e-6)
            np.testing.assert_allclose(frame[:3, :3], S @ rot @ S, atol=1e-6)
            np.testing.assert_allclose(frame[3], [0, 0, 0, 1])
        p, r = end_effector_pose(model, q)
        np.testing.assert_allclose(p, frames[-1][:3, 3])
        np.testing.assert_allclose(r, frames[-1][:3, :3])


def test_documented_poses(model: ArmModel) -> None:
    """e = π, d = π/2: link d reaches forward horizontally (body x); d = 0: it hangs down."""
    forward = joint_transforms(model, [math.pi, math.pi / 2, 1.0, 1.0])
    link_d = forward[2][:3, 3] - forward[1][:3, 3]  # joint d → joint c
    assert link_d[0] > 0.14
    hanging = joint_transforms(model, [math.pi, 0.0, 1.0, 1.0])
    link_d = hanging[2][:3, 3] - hanging[1][:3, 3]
    assert link_d[2] > 0.14  # FRD z is down
    # the packaged initial pose reaches forward, ahead of the mount, jaws pointing forward
    p, r = end_effector_pose(model, model.initial_q_rad)
    assert p[0] > MOUNT[0] + 0.25
    assert (r @ S @ [0, 0, 1])[0] > 0.99  # the URDF ee z axis (jaws) along body x


def test_rejects_a_wrong_number_of_joints(model: ArmModel) -> None:
    with pytest.raises(ValueError, match=r"q: expected shape \(4,\)"):
        joint_transforms(model, [0.0, 1.0, 1.0])


# --- Jacobians ---------------------------------------------------------------------------------


def test_arm_jacobian_matches_pybullet(model: ArmModel, oracle: tuple[int, int]) -> None:
    client, body = oracle
    rng = np.random.default_rng(7)
    for _ in range(50):
        q = _random_q(rng)
        _set(oracle, q)
        zeros = [0.0] * 4
        lin, ang = pybullet.calculateJacobian(
            body, 4, [0.0, 0.0, 0.0], q.tolist(), zeros, zeros, physicsClientId=client
        )
        expected = np.vstack([S @ np.array(lin), S @ np.array(ang)])
        np.testing.assert_allclose(arm_jacobian(model, q), expected, atol=1e-6)


def test_arm_jacobian_matches_finite_differences(model: ArmModel) -> None:
    rng = np.random.default_rng(11)
    h = 1e-6
    for _ in range(50):
        q = _random_q(rng)
        jac = arm_jacobian(model, q)
        for i in range(model.n_joints):
            dq = np.zeros(model.n_joints)
            dq[i] = h
            p_plus, r_plus = end_effector_pose(model, q + dq)
            p_minus, r_minus = end_effector_pose(model, q - dq)
            np.testing.assert_allclose(jac[:3, i], (p_plus - p_minus) / (2 * h), atol=1e-6)
            omega = _rotation_log(r_plus @ r_minus.T) / (2 * h)
            np.testing.assert_allclose(jac[3:, i], omega, atol=1e-6)


def _moved_vehicle(
    position: NDArray[np.float64],
    quat: tuple[float, float, float, float],
    nu: NDArray[np.float64],
    dt: float,
) -> tuple[NDArray[np.float64], tuple[float, float, float, float]]:
    """The vehicle pose after a body twist ν for dt: position += R ν_lin dt, q ← q·exp(ω dt)."""
    w, x, y, z = quat  # R written out here, not taken from the package
    rot = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )
    omega = nu[3:6]
    rate = float(np.linalg.norm(omega))
    turn = quat_from_axis_angle(tuple(omega / rate), rate * dt) if rate > 0 else (1.0, 0, 0, 0)
    return position + rot @ nu[:3] * dt, quat_multiply(quat, turn)


def test_uvms_jacobian_matches_finite_differences(model: ArmModel) -> None:
    rng = np.random.default_rng(13)
    h = 1e-6
    for _ in range(40):
        q = _random_q(rng)
        quat = quat_from_euler(*rng.uniform(-math.pi, math.pi, 3))
        position = rng.uniform(-5.0, 5.0, 3)
        zeta = rng.uniform(-1.0, 1.0, 6 + model.n_joints)
        nu, q_dot = zeta[:6], zeta[6:]
        p_plus, q_plus = _moved_vehicle(position, quat, nu, h)
        p_minus, q_minus = _moved_vehicle(position, quat, nu, -h)
        ee_p_plus, ee_r_plus = end_effector_ned(model, q + q_dot * h, p_plus, q_plus)
        ee_p_minus, ee_r_minus = end_effector_ned(model, q - q_dot * h, p_minus, q_minus)
        expected = np.concatenate(
            [
                (ee_p_plus - ee_p_minus) / (2 * h),
                _rotation_log(ee_r_plus @ ee_r_minus.T) / (2 * h),
            ]
        )
        np.testing.assert_allclose(uvms_jacobian(model, q, quat) @ zeta, expected, atol=1e-6)


def test_uvms_jacobian_arm_part_is_the_rotated_arm_jacobian(model: ArmModel) -> None:
    quat = quat_from_euler(0.1, -0.2, 2.0)
    q = np.array(model.initial_q_rad)
    jac = uvms_jacobian(model, q, quat)
    rot = end_effector_ned(model, q, (0, 0, 0), quat)[1] @ end_effector_pose(model, q)[1].T
    arm = arm_jacobian(model, q)
    np.testing.assert_allclose(jac[:3, 6:], rot @ arm[:3], atol=1e-12)
    np.testing.assert_allclose(jac[3:, 6:], rot @ arm[3:], atol=1e-12)
    np.testing.assert_allclose(jac[3:, :3], 0.0)


def test_uvms_kinematics_is_the_two_separate_functions(model: ArmModel) -> None:
    rng = np.random.default_rng(17)
    for _ in range(30):
        q = _random_q(rng)
        quat = quat_from_euler(*rng.uniform(-math.pi, math.pi, 3))
        position = rng.uniform(-5.0, 5.0, 3)
        p, r, jac = uvms_kinematics(model, q, position, quat)
        p_alone, r_alone = end_effector_ned(model, q, position, quat)
        np.testing.assert_allclose(p, p_alone, atol=1e-12)
        np.testing.assert_allclose(r, r_alone, atol=1e-12)
        np.testing.assert_allclose(jac, uvms_jacobian(model, q, quat), atol=1e-12)
        # and the body-frame pieces, rotated and moved by the vehicle's pose
        p_b, r_b = end_effector_pose(model, q)
        rot = r_alone @ r_b.T
        np.testing.assert_allclose(p, position + rot @ p_b, atol=1e-12)
        np.testing.assert_allclose(jac[:3, 3:6], -rot @ _skew(p_b), atol=1e-12)


def _skew(a: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


def test_a_changed_model_gets_its_own_fixed_chain(model: ArmModel) -> None:
    """The per-model precomputation follows the model: a moved mount moves the end effector."""
    q = np.array(model.initial_q_rad)
    moved = dataclasses.replace(model, mount_m=(model.mount_m[0] + 0.1, *model.mount_m[1:]))
    p, _ = end_effector_pose(model, q)
    p_moved, _ = end_effector_pose(moved, q)
    np.testing.assert_allclose(p_moved - p, [0.1, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(end_effector_pose(model, q)[0], p)  # the original unchanged
    twin = dataclasses.replace(model)  # equal, not the same object: the same figures
    assert twin == model and twin is not model
    np.testing.assert_allclose(end_effector_pose(twin, q)[0], p, atol=0.0)
    frame = joint_transforms(model, q)[0]
    frame[:] = 0.0  # a caller's copy: writing it changes nothing cached
    np.testing.assert_allclose(end_effector_pose(model, q)[0], p, atol=0.0)
    base = base_transform(model)
    base[:] = 0.0
    np.testing.assert_allclose(end_effector_pose(model, q)[0], p, atol=0.0)


def test_link_centres_in_the_world(model: ArmModel) -> None:
    q = np.array(model.initial_q_rad)
    com, cov = link_centres_body(model, q)
    assert com.shape == cov.shape == (5, 3)
    # link_b's centre of volume is midway along joint b → ee
    frames = joint_transforms(model, q)
    np.testing.assert_allclose(cov[4], 0.5 * (frames[3][:3, 3] + frames[4][:3, 3]), atol=1e-12)
    quat = quat_from_euler(0.3, 0.2, -1.0)
    com_n, _ = link_centres_ned(model, q, (1.0, 2.0, 3.0), quat)
    ee_n, _ = end_effector_ned(model, q, (1.0, 2.0, 3.0), quat)
    p_b, _ = end_effector_pose(model, q)
    # the same rigid map takes body points to the world
    offset = com_n[4] - ee_n
    rot = end_effector_ned(model, q, (0, 0, 0), quat)[1] @ end_effector_pose(model, q)[1].T
    np.testing.assert_allclose(offset, rot @ (com[4] - p_b), atol=1e-12)


# --- package data ------------------------------------------------------------------------------


def test_packaged_model_sums_to_the_published_figures(model: ArmModel) -> None:
    assert model.n_joints == 4
    assert [j.name for j in model.joints] == [row[0] for row in TABLE]
    assert model.mass_kg == pytest.approx(1.41, abs=0.005)
    assert model.volume_m3 == pytest.approx(0.573e-3, rel=1e-9)
    assert model.acceleration_rad_s2 == 2.0
    assert model.initial_q_rad[0] == 3.14
    for joint, q in zip(model.joints, model.initial_q_rad, strict=True):
        assert joint.lower_rad <= q <= joint.upper_rad
    for link in (model.base, *model.links):
        assert link.drag_normal == 1.1
        assert link.diameter_m == 0.040
        assert math.isclose(float(np.linalg.norm(link.axis)), 1.0)
    # link d: a 0.429 kg solid cylinder 0.151 m long, 0.02 m radius, axis tilted in x-z
    link_d = model.links[1]
    length = math.hypot(0.04, 0.1453)
    assert link_d.length_m == pytest.approx(length)
    np.testing.assert_allclose(link_d.com_m, (-0.02, 0.0, -0.07265))
    across = 0.429 * (3 * 0.02**2 + length**2) / 12
    assert link_d.inertia_kg_m2[1] == pytest.approx(across)  # y is across the x-z axis
    # the jaws' 0.133 kg point mass pulls link b's CoM beyond its cylinder's centre
    link_b = model.links[3]
    assert link_b.mass_kg == pytest.approx(0.333)
    expected_z = (0.2 * 0.09975 / 2 + 0.133 * 0.10875) / 0.333
    assert link_b.com_m[2] == pytest.approx(expected_z)


def _bad_copy(tmp_path: Path, old: str, new: str) -> Path:
    text = PACKAGED.read_text(encoding="utf-8")
    assert text.count(old) >= 1
    path = tmp_path / "alpha5.toml"
    path.write_text(text.replace(old, new, 1), encoding="utf-8")
    return path


def test_a_copy_of_the_packaged_file_loads_the_same(model: ArmModel, tmp_path: Path) -> None:
    assert load_arm_model(path=_bad_copy(tmp_path, "name", "name")) == model


@pytest.mark.parametrize(
    ("old", "new", "key"),
    [
        ("axis = [0.0, 1.0, 0.0]", "axis = [0.0, 2.0, 0.0]", "joints[1].axis"),
        ("velocity_rad_s = 0.5", "velocity_rad_s = -0.5", "joints[0].velocity_rad_s"),
        ("mass_kg = 0.194", "mass_kg = 0.0", "links[0].mass_kg"),
        ("initial_q_rad = [3.14,", "initial_q_rad = [7.0,", "initial_q_rad[0]"),
        ("volume_l = 0.157", "volume_l = -1.0", "base.volume_l"),
        ("drag_axial = 0.8", "drag_axil = 0.8", "base.drag_axil"),
        ("acceleration_rad_s2 = 2.0", "acceleration_rad_s2 = 0.0", "acceleration_rad_s2"),
    ],
)
def test_a_bad_value_names_the_file_and_key(tmp_path: Path, old: str, new: str, key: str) -> None:
    path = _bad_copy(tmp_path, old, new)
    with pytest.raises(ConfigError, match=rf"alpha5\.toml: {re.escape(key)}: "):
        load_arm_model(path=path)


def test_a_missing_file_is_a_config_error(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"nope\.toml: file not found"):
        load_arm_model(path=tmp_path / "nope.toml")
