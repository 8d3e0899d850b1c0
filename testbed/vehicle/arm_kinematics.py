"""Kinematics of the arm (:class:`~testbed.vehicle.arm.ArmModel`) on the vehicle: FK, the arm
and UVMS Jacobians, the links' centres in the body and the world.

Frames. The vehicle body frame is **FRD** and the world **NED**; the model's figures are FLU.
With S = diag(1, −1, −1) (a half turn about x), every FLU point maps as p_frd = S·p_flu and every
frame's orientation as R_frd = S·R_flu·S: each link keeps its own x axis and flips y and z, so
a link frame here is the FRD twin of the URDF's. The chain is evaluated directly in FRD with
each local quantity converted once (S·R(a, q)·S = R(S·a, q)). A link-frame FLU point ``p``
(e.g. :attr:`~testbed.vehicle.arm.ArmLink.com_m`) sits at ``T[:3, :3] @ (S @ p) + T[:3, 3]`` in
the body (:func:`link_centres_body` does this).

Pure numpy; rotations from :mod:`testbed.common.geometry`. No pybullet.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from testbed.common.geometry import Vec3, quat_from_euler, quat_normalize, rotation_matrix
from testbed.vehicle.arm import S_FLU_FRD, ArmModel
from testbed.vehicle.hydrodynamics import skew

__all__ = [
    "arm_jacobian",
    "base_transform",
    "end_effector_ned",
    "end_effector_pose",
    "joint_transforms",
    "link_centres_body",
    "link_centres_ned",
    "uvms_jacobian",
    "uvms_kinematics",
]

FloatArray = NDArray[np.float64]


def _rpy_frd(rpy: Sequence[float]) -> FloatArray:
    """S·R_rpy·S: a URDF fixed-axis rpy (= Z-Y-X Euler, :func:`quat_from_euler`) in FRD."""
    r = np.array(rotation_matrix(quat_from_euler(rpy[0], rpy[1], rpy[2])))
    out: FloatArray = S_FLU_FRD @ r @ S_FLU_FRD
    return out


def _homogeneous(rot: FloatArray, pos: ArrayLike) -> FloatArray:
    t = np.eye(4)
    t[:3, :3] = rot
    t[:3, 3] = pos
    return t


@dataclass(frozen=True, slots=True)
class _Chain:
    """What of the chain's kinematics does not depend on q, in FRD (built once per model).

    Joint i's local transform (parent link → its link) is [R_i(q_i), o_i; 0, 1] with
    R_i(q) = F_i·Rot(a_i, q) = F_i + sin q·F_i·K_i + (1 − cos q)·F_i·K_i² (Rodrigues; F_i the
    fixed rpy rotation, a_i the FRD axis, K_i its cross-product matrix).

    Attributes:
        base: (4, 4) the base link's frame → body.
        local: (n, 4, 4) each joint's local transform with the rotation block zero (a template).
        fixed, turn_sin, turn_cos: (n, 3, 3) F_i, F_i·K_i, F_i·K_i².
        axes: (n, 3) F_i·a_i: joint i's axis in its parent link's frame.
        ee: (4, 4) the end-effector frame in the last link's frame.
    """

    base: FloatArray
    local: FloatArray
    fixed: FloatArray
    turn_sin: FloatArray
    turn_cos: FloatArray
    axes: FloatArray
    ee: FloatArray


def _build_chain(model: ArmModel) -> _Chain:
    n = model.n_joints
    local = np.zeros((n, 4, 4))
    local[:, 3, 3] = 1.0
    fixed = np.empty((n, 3, 3))
    turn_sin = np.empty((n, 3, 3))
    turn_cos = np.empty((n, 3, 3))
    axes = np.empty((n, 3))
    for i, joint in enumerate(model.joints):
        axis = S_FLU_FRD @ np.asarray(joint.axis, dtype=float)
        axis /= np.linalg.norm(axis)  # unit to 1e-6 by the loader's check; exactly here
        k = skew(axis)
        fixed[i] = _rpy_frd(joint.rpy_rad)
        turn_sin[i] = fixed[i] @ k
        turn_cos[i] = fixed[i] @ k @ k
        axes[i] = fixed[i] @ axis
        local[i, :3, 3] = S_FLU_FRD @ np.asarray(joint.origin_m, dtype=float)
    base = _homogeneous(_rpy_frd(model.mount_rpy_rad), S_FLU_FRD @ np.asarray(model.mount_m))
    ee = _homogeneous(np.eye(3), S_FLU_FRD @ np.asarray(model.ee_origin_m, dtype=float))
    for a in (base, local, fixed, turn_sin, turn_cos, axes, ee):
        a.flags.writeable = False
    return _Chain(base, local, fixed, turn_sin, turn_cos, axes, ee)


_CHAINS: dict[int, tuple[ArmModel, _Chain]] = {}
_MAX_CHAINS = 32


def _chain(model: ArmModel) -> _Chain:
    """The model's :class:`_Chain`, built on first use.

    Keyed by identity, not by hash: an :class:`ArmModel` is hashable (frozen, tuples only) but
    its hash walks every field of every joint and link each time (≈5 µs, a fifth of a whole
    FK), while an ``id`` look-up is ≈0.1 µs. The entry holds the model itself, so its id
    cannot be reused while the entry lives; the table is bounded (oldest evicted first), and
    slotted dataclasses take no weak references.
    """
    entry = _CHAINS.get(id(model))
    if entry is not None and entry[0] is model:
        return entry[1]
    chain = _build_chain(model)
    if len(_CHAINS) >= _MAX_CHAINS:
        del _CHAINS[next(iter(_CHAINS))]
    _CHAINS[id(model)] = (model, chain)
    return chain


def _frames(model: ArmModel, q: ArrayLike, world: FloatArray | None = None) -> FloatArray:
    """(n + 2, 4, 4): the base, each joint's frame after its rotation, the end effector.

    The frames of the chain (:func:`joint_transforms`) in the body, or in the frame ``world``
    maps the body to ((4, 4) body → that frame) if given. The one place the chain is walked.
    """
    qs = np.asarray(q, dtype=float)
    n = model.n_joints
    if qs.shape != (n,):
        raise ValueError(f"q: expected shape ({n},), got {qs.shape}")
    chain = _chain(model)
    local = chain.local.copy()
    local[:, :3, :3] = (
        chain.fixed
        + np.sin(qs)[:, None, None] * chain.turn_sin
        + (1.0 - np.cos(qs))[:, None, None] * chain.turn_cos
    )
    frames = np.empty((n + 2, 4, 4))
    if world is None:
        frames[0] = chain.base
    else:
        np.matmul(world, chain.base, out=frames[0])
    for i in range(n):
        np.matmul(frames[i], local[i], out=frames[i + 1])
    np.matmul(frames[n], chain.ee, out=frames[n + 1])
    return frames


_CROSS_A = [1, 2, 0]
_CROSS_B = [2, 0, 1]


def _cross(a: FloatArray, b: FloatArray) -> FloatArray:
    """Row-wise a × b of (k, 3) arrays (broadcast), cheaper than ``np.cross`` at this size."""
    out: FloatArray = a[..., _CROSS_A] * b[..., _CROSS_B] - a[..., _CROSS_B] * b[..., _CROSS_A]
    return out


def _jacobian_of(model: ArmModel, frames: FloatArray) -> FloatArray:
    """(6, n) the arm's geometric Jacobian (:func:`arm_jacobian`) in the frame of ``frames``."""
    n = model.n_joints
    z = (frames[:n, :3, :3] @ _chain(model).axes[:, :, None])[:, :, 0]  # each axis, moved
    lever = frames[n + 1, :3, 3] - frames[1 : n + 1, :3, 3]  # joint origin → ee
    jac = np.empty((6, n))
    jac[:3] = _cross(z, lever).T
    jac[3:] = z.T
    return jac


def base_transform(model: ArmModel) -> FloatArray:
    """(4, 4) the arm base link's frame → body FRD (its FRD twin, as :func:`joint_transforms`)."""
    return _chain(model).base.copy()


def joint_transforms(model: ArmModel, q: ArrayLike) -> list[FloatArray]:
    """The frames of the chain in the vehicle body (FRD, origin CO).

    Args:
        model: the arm.
        q: (n,) joint positions [rad].

    Returns:
        n + 1 (4, 4) homogeneous transforms, link frame → body: each joint's frame after its
        rotation q_i (= the frame of the link it moves), then the end-effector frame. Each is
        the FRD twin of the URDF frame (module docstring: R = S·R_flu·S, p = S·p_flu).
    """
    return list(_frames(model, q)[1:])


def end_effector_pose(model: ArmModel, q: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """The end effector's (3,) position [m] and (3, 3) rotation (ee → body) in body FRD."""
    ee = _frames(model, q)[-1]
    return ee[:3, 3].copy(), ee[:3, :3].copy()


def arm_jacobian(model: ArmModel, q: ArrayLike) -> FloatArray:
    """(6, n) geometric Jacobian of the end effector in body FRD, the vehicle held still.

    Rows: the ee origin's linear velocity [m/s] (3), then the ee's angular velocity [rad/s]
    (3), both in body FRD, per unit joint rate: column i = [z_i × (p_ee − p_i); z_i] with
    z_i joint i's axis in the body.
    """
    return _jacobian_of(model, _frames(model, q))


def _attitude(quaternion_wxyz: ArrayLike) -> FloatArray:
    """R_nb (body FRD → NED) of a (w, x, y, z) attitude, normalised first."""
    quat = np.asarray(quaternion_wxyz, dtype=float).reshape(4)
    return np.array(rotation_matrix(quat_normalize(quat.tolist())))


def _uvms(
    model: ArmModel,
    q: ArrayLike,
    position_ned: ArrayLike,
    quaternion_wxyz: ArrayLike,
    jacobian: bool,
) -> tuple[FloatArray, FloatArray, FloatArray | None]:
    """:func:`uvms_kinematics` (the Jacobian only if ``jacobian``): the chain walked once, in NED.

    The body → NED map [R_nb, p_CO] is prepended to the chain, so every frame, axis and lever
    is in NED directly; the vehicle's part of the Jacobian uses −R·S(r_ee) = S(R r_ee)·R
    (column j: R e_j × (p_ee − p_CO), both in NED).
    """
    r_nb = _attitude(quaternion_wxyz)
    origin = np.asarray(position_ned, dtype=float).reshape(3)
    world = np.zeros((4, 4))
    world[:3, :3] = r_nb
    world[:3, 3] = origin
    world[3, 3] = 1.0
    frames = _frames(model, q, world)
    ee = frames[-1]
    ee_position, ee_rotation = ee[:3, 3].copy(), ee[:3, :3].copy()
    if not jacobian:
        return ee_position, ee_rotation, None
    jac = np.zeros((6, 6 + model.n_joints))
    jac[:3, :3] = r_nb
    jac[:3, 3:6] = _cross(r_nb.T, ee_position - origin).T
    jac[3:, 3:6] = r_nb
    jac[:, 6:] = _jacobian_of(model, frames)
    return ee_position, ee_rotation, jac


def uvms_kinematics(
    model: ArmModel,
    q: ArrayLike,
    position_ned: ArrayLike,
    quaternion_wxyz: ArrayLike,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """:func:`end_effector_ned` and :func:`uvms_jacobian` at once, the chain walked once.

    Args:
        model, q: the arm and its (n,) joint positions [rad].
        position_ned: the vehicle's body origin CO in NED [m].
        quaternion_wxyz: the vehicle's attitude (body FRD → NED), normalised here.

    Returns:
        The end effector's (3,) position [m] and (3, 3) rotation (ee → NED) in the world, and
        the (6, 6 + n) UVMS Jacobian.
    """
    position, rotation, jac = _uvms(model, q, position_ned, quaternion_wxyz, True)
    assert jac is not None
    return position, rotation, jac


def end_effector_ned(
    model: ArmModel,
    q: ArrayLike,
    position_ned: ArrayLike,
    quaternion_wxyz: ArrayLike,
) -> tuple[FloatArray, FloatArray]:
    """The end effector's (3,) position [m] and (3, 3) rotation (ee → NED) in the world.

    Args:
        model, q: the arm and its (n,) joint positions [rad].
        position_ned: the vehicle's body origin CO in NED [m].
        quaternion_wxyz: the vehicle's attitude (body FRD → NED), normalised here.
    """
    position, rotation, _ = _uvms(model, q, position_ned, quaternion_wxyz, False)
    return position, rotation


def uvms_jacobian(model: ArmModel, q: ArrayLike, quaternion_wxyz: ArrayLike) -> FloatArray:
    """(6, 6 + n) Jacobian of the vehicle-manipulator system (Angler, eqs. 2–4).

    ζ = [u v w p q r (the vehicle's body twist at CO, FRD), q̇ (n)] maps to the end effector's
    [linear velocity in NED (3); angular velocity in NED (3)]:
    J = [[R, −R·S(r_ee)], [0, R]] for the vehicle's part (r_ee the ee position in the body,
    S(·) the cross-product matrix) and [[R, 0], [0, R]]·J_arm for the arm's, R = R_nb.
    :func:`uvms_kinematics` gives it with the end effector's pose for one chain walk.
    """
    return uvms_kinematics(model, q, _ZERO3, quaternion_wxyz)[2]


_ZERO3: FloatArray = np.zeros(3)
_ZERO3.flags.writeable = False


def link_centres_body(model: ArmModel, q: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Centres of mass and of volume of the base and each link in body FRD [m].

    Returns:
        (com, cov), each (n + 1, 3): row 0 the base, row i + 1 ``links[i]``.
    """
    frames = _frames(model, q)[:-1]
    links = (model.base, *model.links)

    def place(point: Vec3, t: FloatArray) -> FloatArray:
        out: FloatArray = t[:3, :3] @ (S_FLU_FRD @ np.asarray(point)) + t[:3, 3]
        return out

    com = np.array([place(link.com_m, t) for t, link in zip(frames, links, strict=True)])
    cov = np.array([place(link.cov_m, t) for t, link in zip(frames, links, strict=True)])
    return com, cov


def link_centres_ned(
    model: ArmModel,
    q: ArrayLike,
    position_ned: ArrayLike,
    quaternion_wxyz: ArrayLike,
) -> tuple[FloatArray, FloatArray]:
    """:func:`link_centres_body` in the world NED for a vehicle at ``position_ned`` (CO) with
    attitude ``quaternion_wxyz`` (body FRD → NED): (com, cov), each (n + 1, 3) [m]."""
    r_nb = _attitude(quaternion_wxyz)
    p0 = np.asarray(position_ned, dtype=float)
    com, cov = link_centres_body(model, q)
    return p0 + com @ r_nb.T, p0 + cov @ r_nb.T
