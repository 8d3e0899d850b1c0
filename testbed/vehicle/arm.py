"""A Reach-Alpha-5-like manipulator on the vehicle: its model, loaded from package data.

The model (:class:`ArmModel`, loaded from ``data/arms/alpha5.toml`` by :func:`load_arm_model`) is a
serial chain written as a URDF is: every joint has an origin and fixed-axis roll-pitch-yaw in
its parent link's frame and one axis in its own frame; link ``i`` moves with joint ``i``. All
figures in the model are **FLU** (ROS: x forward, y left, z up), as published; the arm's base
is mounted at ``mount_m`` / ``mount_rpy_rad`` in the vehicle's ROS ``base_link``, whose origin is
taken as our body origin CO. Its kinematics (FRD, NED) are :mod:`testbed.vehicle.arm_kinematics`.

Link geometry for the physics (:func:`_derive_link`): each link is approximated by a solid
cylinder of the datasheet's nominal diameter between two points of its frame (by default the
link origin and the next joint's origin, or the end-effector origin for the last link); the
centre of mass and centre of volume are the cylinder's centre, shifted for a point mass where a
link carries one (the jaws); the inertia is the solid-cylinder tensor (m(3r² + L²)/12 across,
m r²/2 along) plus the point mass, about the combined CoM, of which the diagonal in link axes
is kept (a tilted link's product of inertia is dropped).

Pure numpy. No pybullet.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from testbed.config import build, check, check_range, check_ranges, load_toml, user_file

__all__ = [
    "ArmJoint",
    "ArmLink",
    "ArmModel",
    "arm_model_names",
    "load_arm_model",
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


def _arms_dir() -> resources.abc.Traversable:
    return resources.files("testbed.vehicle").joinpath("data", "arms")


def arm_model_names() -> list[str]:
    """Names of the packaged arm models (``testbed/vehicle/data/arms/*.toml``), sorted."""
    return sorted(
        entry.name.removesuffix(".toml")
        for entry in _arms_dir().iterdir()
        if entry.name.endswith(".toml")
    )


@functools.cache
def _packaged_arm_model(name: str) -> ArmModel:
    """The packaged model ``name``, read once per process (the package's files do not change
    while it runs; the model is immutable)."""
    with resources.as_file(_arms_dir().joinpath(f"{name}.toml")) as packaged:
        return load_arm_model(path=packaged)


def load_arm_model(name: str = "alpha5", *, path: str | Path | None = None) -> ArmModel:
    """Load an arm model: a packaged one by name, or the user's own TOML file (the packaged
    files' layout) at the path ``name`` (:func:`~testbed.config.user_file`).

    Args:
        name: a packaged model (``testbed/vehicle/data/arms/NAME.toml``; see
            :func:`arm_model_names`) or a ``.toml`` path.
        path: read this file instead (``name`` is then ignored).

    Raises:
        ConfigError: neither a packaged name nor an existing ``.toml`` file (the message lists
            the packaged ones, or names the path), or the file is malformed, or a key is
            unknown, missing or out of range; the message names the file and the dotted key
            (e.g. ``joints[1].axis``).
    """
    if path is None:
        own = user_file(name, arm_model_names(), "arm model")
        if own is None:
            return _packaged_arm_model(name)
        path = own
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
