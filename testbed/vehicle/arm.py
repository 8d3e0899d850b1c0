"""A Reach-Alpha-5-like manipulator on the vehicle: its model (package data) and kinematics.

The model (:class:`ArmModel`, loaded from ``data/alpha5.toml`` by :func:`load_arm_model`) is a
serial chain written as a URDF is: every joint has an origin and fixed-axis roll-pitch-yaw in
its parent link's frame and one axis in its own frame; link ``i`` moves with joint ``i``. All
figures in the model are **FLU** (ROS: x forward, y left, z up), as published; the arm's base
is mounted at ``mount_m`` / ``mount_rpy_rad`` in the vehicle's ROS ``base_link``, whose origin is
taken as our body origin CO.

Frames of the kinematics. The vehicle body frame is **FRD** and the world **NED**. With
S = diag(1, −1, −1) (a half turn about x), every FLU point maps as p_frd = S·p_flu and every
frame's orientation as R_frd = S·R_flu·S: each link keeps its own x axis and flips y and z, so
a link frame here is the FRD twin of the URDF's. The chain is evaluated directly in FRD with
each local quantity converted once (S·R(a, q)·S = R(S·a, q)). A link-frame FLU point ``p``
(e.g. :attr:`ArmLink.com_m`) sits at ``T[:3, :3] @ (S @ p) + T[:3, 3]`` in the body
(:func:`link_centres_body` does this).

Link geometry for the physics (:func:`_derive_link`): each link is approximated by a solid
cylinder of the datasheet's nominal diameter between two points of its frame (by default the
link origin and the next joint's origin, or the end-effector origin for the last link); the
centre of mass and centre of volume are the cylinder's centre, shifted for a point mass where a
link carries one (the jaws); the inertia is the solid-cylinder tensor (m(3r² + L²)/12 across,
m r²/2 along) plus the point mass, about the combined CoM, of which the diagonal in link axes
is kept (a tilted link's product of inertia is dropped).

Pure numpy; rotations from :mod:`testbed.common.geometry`. No pybullet.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from testbed.common.geometry import (
    quat_from_euler,
    quat_normalize,
    rotation_matrix,
)
from testbed.config import build, check, check_range, check_ranges, load_toml
from testbed.vehicle.hydrodynamics import skew

__all__ = [
    "ArmJoint",
    "ArmLink",
    "ArmModel",
    "arm_jacobian",
    "base_transform",
    "end_effector_ned",
    "end_effector_pose",
    "joint_transforms",
    "link_centres_body",
    "link_centres_ned",
    "load_arm_model",
    "uvms_jacobian",
    "uvms_kinematics",
]

Vec3 = tuple[float, float, float]
FloatArray = NDArray[np.float64]

S_FLU_FRD: FloatArray = np.diag([1.0, -1.0, -1.0])
"""S = diag(1, −1, −1): FLU ↔ FRD (its own inverse)."""

_UNIT_TOL = 1e-6


def _check_unit(axis: Vec3, key: str) -> None:
    norm = math.sqrt(sum(a * a for a in axis))
    check(abs(norm - 1.0) <= _UNIT_TOL, key, f"must be a unit vector, got norm {norm:g}")


@dataclass(frozen=True, slots=True)
class ArmJoint:
    """One revolute joint, as a URDF writes it (FLU).

    Attributes:
        name: the joint's name (the Reach convention: ``axis_e`` … ``axis_b``).
        origin_m: the joint frame's origin in the parent link's frame [m].
        rpy_rad: the joint frame's fixed-axis roll-pitch-yaw in the parent link frame [rad]
            (R = Rz(yaw)·Ry(pitch)·Rx(roll)).
        axis: unit rotation axis in the joint frame.
        lower_rad, upper_rad: position limits [rad], lower ≤ upper.
        velocity_rad_s: speed limit [rad/s], > 0.
        effort_n_m: torque limit [N·m], > 0.
    """

    name: str
    origin_m: Vec3
    rpy_rad: Vec3
    axis: Vec3
    lower_rad: float
    upper_rad: float
    velocity_rad_s: float
    effort_n_m: float

    def __post_init__(self) -> None:
        check_ranges(self.origin_m, "origin_m", -10.0, 10.0, "m")
        check_ranges(self.rpy_rad, "rpy_rad", -2.0 * math.pi, 2.0 * math.pi, "rad")
        _check_unit(self.axis, "axis")
        check_range(self.lower_rad, "lower_rad", -2.0 * math.pi, 2.0 * math.pi, "rad")
        check_range(self.upper_rad, "upper_rad", self.lower_rad, 2.0 * math.pi, "rad")
        check_range(self.velocity_rad_s, "velocity_rad_s", 0.0, 100.0, "rad/s", low_open=True)
        check_range(self.effort_n_m, "effort_n_m", 0.0, 1e4, "N·m", low_open=True)


@dataclass(frozen=True, slots=True)
class ArmLink:
    """One rigid link's mass, buoyancy and drag data, in its own link frame (FLU).

    Attributes:
        name: the link's name.
        mass_kg: mass [kg], > 0 (point masses folded in included).
        com_m: centre of mass in the link frame [m].
        inertia_kg_m2: diagonal inertia about the CoM, link axes [kg·m²], each ≥ 0.
        volume_m3: displaced volume [m³], ≥ 0 (buoyancy ρ·g·V acts at ``cov_m``).
        cov_m: centre of volume (buoyancy) in the link frame [m].
        diameter_m: the drag cylinder's diameter [m], > 0.
        length_m: the drag cylinder's length [m], > 0.
        axis: unit axis of the drag cylinder in the link frame.
        drag_normal: crossflow drag coefficient on diameter × length [-].
        drag_axial: axial drag coefficient on the end area π d²/4 [-].
    """

    name: str
    mass_kg: float
    com_m: Vec3
    inertia_kg_m2: Vec3
    volume_m3: float
    cov_m: Vec3
    diameter_m: float
    length_m: float
    axis: Vec3
    drag_normal: float
    drag_axial: float

    def __post_init__(self) -> None:  # the loader checked the figures these derive from
        check(self.mass_kg > 0.0 and self.length_m > 0.0, "mass_kg", "mass, length must be > 0")
        check_ranges(self.inertia_kg_m2, "inertia_kg_m2", 0.0, 1e3, "kg·m²")
        _check_unit(self.axis, "axis")


@dataclass(frozen=True, slots=True)
class ArmModel:
    """The whole arm: the mount, the fixed base link, the joints and the links they move.

    Attributes:
        name: the model's name (its TOML file's stem).
        mount_m: the arm base frame's origin in the vehicle's ``base_link`` (FLU) [m].
        mount_rpy_rad: its fixed-axis roll-pitch-yaw there [rad].
        base: the base link, fixed to the vehicle (it rides with the mount).
        joints: the joints base → tip (``axis_e, axis_d, axis_c, axis_b``).
        links: ``links[i]`` moves with ``joints[i]``; same length as ``joints``.
        ee_origin_m: the end-effector frame's origin in the last joint's frame (FLU) [m]; its
            orientation is the last joint's.
        initial_q_rad: the joint positions at start [rad], within the limits.
        acceleration_rad_s2: every joint's acceleration limit [rad/s²].
        source: where the figures come from.
    """

    name: str
    mount_m: Vec3
    mount_rpy_rad: Vec3
    base: ArmLink
    joints: tuple[ArmJoint, ...]
    links: tuple[ArmLink, ...]
    ee_origin_m: Vec3
    initial_q_rad: tuple[float, ...]
    acceleration_rad_s2: float
    source: str

    def __post_init__(self) -> None:
        if not len(self.joints) == len(self.links) == len(self.initial_q_rad):
            raise ValueError("ArmModel: joints, links and initial_q_rad differ in length")

    @property
    def n_joints(self) -> int:
        """The number of joints (columns of :func:`arm_jacobian`)."""
        return len(self.joints)

    @property
    def mass_kg(self) -> float:
        """Total mass of the base and all links [kg]."""
        return self.base.mass_kg + sum(link.mass_kg for link in self.links)

    @property
    def volume_m3(self) -> float:
        """Total displaced volume of the base and all links [m³]."""
        return self.base.volume_m3 + sum(link.volume_m3 for link in self.links)


# --- the file's schema ------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class _LinkSpec:
    """A link as the TOML gives it; :func:`_derive_link` makes the :class:`ArmLink`."""

    name: str
    mass_kg: float
    volume_l: float
    diameter_m: float
    drag_normal: float
    drag_axial: float
    cylinder_from_m: Vec3 = (0.0, 0.0, 0.0)
    cylinder_to_m: Vec3 | None = None
    point_mass_kg: float = 0.0
    point_mass_at_m: Vec3 = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        check_range(self.mass_kg, "mass_kg", 0.0, 1e3, "kg", low_open=True)
        check_range(self.volume_l, "volume_l", 0.0, 1e3, "L")
        check_range(self.diameter_m, "diameter_m", 0.0, 1.0, "m", low_open=True)
        check_range(self.drag_normal, "drag_normal", 0.0, 5.0)
        check_range(self.drag_axial, "drag_axial", 0.0, 5.0)
        check_ranges(self.cylinder_from_m, "cylinder_from_m", -10.0, 10.0, "m")
        check_range(self.point_mass_kg, "point_mass_kg", 0.0, 1e3, "kg")
        check_ranges(self.point_mass_at_m, "point_mass_at_m", -10.0, 10.0, "m")


@dataclass(frozen=True, slots=True)
class _ArmSpec:
    name: str
    source: str
    mount_m: Vec3
    mount_rpy_rad: Vec3
    ee_origin_m: Vec3
    initial_q_rad: tuple[float, ...]
    acceleration_rad_s2: float
    base: _LinkSpec
    joints: tuple[ArmJoint, ...]
    links: tuple[_LinkSpec, ...]

    def __post_init__(self) -> None:
        check(len(self.joints) >= 1, "joints", "at least one joint is needed")
        n = len(self.joints)
        check(len(self.links) == n, "links", f"expected {n} links (one per joint)")
        check(len(self.initial_q_rad) == n, "initial_q_rad", f"expected {n} values")
        for i, (q, joint) in enumerate(zip(self.initial_q_rad, self.joints, strict=True)):
            check_range(q, f"initial_q_rad[{i}]", joint.lower_rad, joint.upper_rad, "rad")
        check_ranges(self.mount_m, "mount_m", -10.0, 10.0, "m")
        check_ranges(self.ee_origin_m, "ee_origin_m", -10.0, 10.0, "m")
        check_range(self.acceleration_rad_s2, "acceleration_rad_s2", 0.0, 1e3, low_open=True)
        for i, link in enumerate((self.base, *self.links)):
            end = link.cylinder_to_m or self._next_origin(i)
            gap = math.dist(link.cylinder_from_m, end)
            key = "base" if i == 0 else f"links[{i - 1}]"
            check(gap > 1e-6, f"{key}.cylinder_from_m", "the cylinder has zero length")

    def _next_origin(self, i: int) -> Vec3:
        """The default cylinder end of link ``i`` (0 = the base): the next joint's origin."""
        return self.joints[i].origin_m if i < len(self.joints) else self.ee_origin_m


def _derive_link(spec: _LinkSpec, end: Vec3) -> ArmLink:
    """The :class:`ArmLink` of a solid cylinder from ``spec.cylinder_from_m`` to ``end`` (module
    docstring), with ``spec``'s point mass folded in."""
    start = np.asarray(spec.cylinder_from_m, dtype=float)
    seg = np.asarray(spec.cylinder_to_m or end, dtype=float) - start
    length = float(np.linalg.norm(seg))
    axis = seg / length
    centre = start + 0.5 * seg
    m_cyl, m_pt = spec.mass_kg, spec.point_mass_kg
    p_pt = np.asarray(spec.point_mass_at_m, dtype=float)
    mass = m_cyl + m_pt
    com = (m_cyl * centre + m_pt * p_pt) / mass
    r = 0.5 * spec.diameter_m
    across = m_cyl * (3.0 * r * r + length * length) / 12.0
    along = 0.5 * m_cyl * r * r
    aa = np.outer(axis, axis)
    inertia = across * (np.eye(3) - aa) + along * aa
    for m, p in ((m_cyl, centre), (m_pt, p_pt)):  # parallel-axis shifts to the combined CoM
        d = p - com
        inertia += m * (float(d @ d) * np.eye(3) - np.outer(d, d))

    def vec(a: FloatArray) -> Vec3:
        return (float(a[0]), float(a[1]), float(a[2]))

    return ArmLink(
        name=spec.name,
        mass_kg=mass,
        com_m=vec(com),
        inertia_kg_m2=vec(np.diag(inertia)),
        volume_m3=spec.volume_l * 1e-3,
        cov_m=vec(centre),
        diameter_m=spec.diameter_m,
        length_m=length,
        axis=vec(axis),
        drag_normal=spec.drag_normal,
        drag_axial=spec.drag_axial,
    )


@functools.cache
def _packaged_arm_model(name: str) -> ArmModel:
    """The packaged model ``name``, read once per process (the package's files do not change
    while it runs; the model is immutable)."""
    entry = resources.files("testbed.vehicle").joinpath("data", f"{name}.toml")
    with resources.as_file(entry) as packaged:
        return load_arm_model(name, path=packaged)


def load_arm_model(name: str = "alpha5", *, path: str | Path | None = None) -> ArmModel:
    """Load an arm model from ``testbed/vehicle/data/{name}.toml`` (or from ``path``).

    Args:
        name: the packaged model's name.
        path: read this file instead of the packaged one (tests, experiments).

    Raises:
        ConfigError: the file is missing or malformed, or a key is unknown, missing or out of
            range; the message names the file and the dotted key (e.g. ``joints[1].axis``).
    """
    if path is None:
        return _packaged_arm_model(name)
    spec = build(_ArmSpec, load_toml(path), source=str(path))
    n = len(spec.joints)
    return ArmModel(
        name=spec.name,
        mount_m=spec.mount_m,
        mount_rpy_rad=spec.mount_rpy_rad,
        base=_derive_link(spec.base, spec._next_origin(0)),
        joints=spec.joints,
        links=tuple(_derive_link(spec.links[i], spec._next_origin(i + 1)) for i in range(n)),
        ee_origin_m=spec.ee_origin_m,
        initial_q_rad=spec.initial_q_rad,
        acceleration_rad_s2=spec.acceleration_rad_s2,
        source=spec.source,
    )


# --- kinematics -------------------------------------------------------------------------------


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
