"""Fossen's 6-DOF vehicle model: its parameters and the force law (the numpy reference).

The equation of motion (Fossen 2011, body frame, relative velocity ν_r = ν − ν_c)::

    M_RB ν̇ + C_RB(ν) ν + M_A ν̇_r + C_A(ν_r) ν_r + D(ν_r) ν_r + g(η) = τ

World NED, body FRD, body origin CO (the point the hydrodynamic coefficients refer to: the
centre of buoyancy in Wu 2018). ``cog_m`` is r_g and ``cob_m`` r_b, both from CO in the body
frame; ``inertia_kg_m2`` are the principal moments about the CoG (body-aligned axes), so
M_RB about CO carries the m·S(r_g) coupling and the parallel-axis term. The applied wrench is
given about the CoG (thruster allocation works about the centre of mass) and moved to CO here.

Two paths compute the same accelerations: the numpy reference functions here (clear matrices,
used by tests) and :func:`testbed.vehicle.scalar_dynamics.make_scalar_dynamics`, straight-line
Python over floats generated once per model, which the pybullet stepping loop calls 240 times per
simulated second. Tests hold the two to 1e-10. The water current (ν_c) is
:mod:`testbed.vehicle.water_current`; :class:`WaterCurrent` is re-exported here for the callers
that import it with the model. Rotations are :mod:`testbed.common.geometry`.

Pure numpy and math: this module must never import pybullet.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from importlib import resources
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from testbed.config import ConfigError, build, check, load_toml
from testbed.vehicle.water_current import WaterCurrent

__all__ = [
    "HydroModel",
    "WaterCurrent",
    "body_acceleration",
    "coriolis_added_mass",
    "coriolis_rigid_body",
    "damping_matrix",
    "known_models",
    "load_model",
    "restoring_forces",
    "skew",
    "submerged_fraction",
    "wrench_about_origin",
]

FloatArray = NDArray[np.float64]
Vec3 = tuple[float, float, float]
Vec6 = tuple[float, float, float, float, float, float]


@dataclass(frozen=True, slots=True)
class HydroModel:
    """One vehicle's rigid-body and hydrodynamic parameters (Fossen notation, SI units).

    Attributes:
        name: model name (the TOML file's stem).
        source: where the figures come from.
        mass_kg: rigid-body mass m.
        weight_n: weight W = m·g [N].
        buoyancy_n: buoyancy B = ρ·g·∇ [N] when fully submerged.
        cog_m: (3,) centre of gravity r_g from the body origin CO, FRD [m].
        cob_m: (3,) centre of buoyancy r_b from CO, FRD [m].
        inertia_kg_m2: (Ixx, Iyy, Izz) principal moments about the CoG, body axes [kg·m²].
        added_mass: (X_u̇, Y_v̇, Z_ẇ, K_ṗ, M_q̇, N_ṙ), ≤ 0 as in Fossen [kg, kg·m²].
        linear_damping: (X_u, Y_v, Z_w, K_p, M_q, N_r), ≤ 0 [N·s/m, N·m·s].
        quadratic_damping: (X_u|u|, Y_v|v|, Z_w|w|, K_p|p|, M_q|q|, N_r|r|), ≤ 0 [N·s²/m², N·m·s²].
        hull_size_m: (length, width, height) of the collision box centred on CO [m]; the height
            also sets how buoyancy fades as the hull crosses the free surface.
        added_mass_coriolis: which added-mass Coriolis-centripetal matrix C_A(ν_r) the model
            uses (docs/vehicle.md): ``"full"``, Fossen's C_A from the anisotropic M_A, Munk
            moments included (e.g. −(Z_ẇ − X_u̇)·u·w in pitch); ``"isotropic"``, C_A built from
            the mean of X_u̇, Y_v̇, Z_ẇ (and the rotational terms as given), so the Munk moments
            vanish, as with Stonefish's isotropic added mass; ``"off"``, C_A = 0, as bluerov2_gz,
            Blue and Gazebo's ``disable_coriolis``. M_A stays in the mass matrix in all three,
            and each C_A is skew-symmetric (it does no work).
    """

    name: str
    source: str
    mass_kg: float
    weight_n: float
    buoyancy_n: float
    cog_m: Vec3
    cob_m: Vec3
    inertia_kg_m2: Vec3
    added_mass: Vec6
    linear_damping: Vec6
    quadratic_damping: Vec6
    hull_size_m: Vec3
    added_mass_coriolis: Literal["full", "isotropic", "off"] = "full"

    def __post_init__(self) -> None:
        check(self.mass_kg > 0.0, "mass_kg", f"must be > 0, got {self.mass_kg}")
        check(self.weight_n > 0.0, "weight_n", f"must be > 0, got {self.weight_n}")
        check(self.buoyancy_n >= 0.0, "buoyancy_n", f"must be ≥ 0, got {self.buoyancy_n}")
        for i, value in enumerate(self.inertia_kg_m2):
            check(value > 0.0, f"inertia_kg_m2[{i}]", f"must be > 0, got {value}")
        for i, value in enumerate(self.hull_size_m):
            check(value > 0.0, f"hull_size_m[{i}]", f"must be > 0, got {value}")
        for key in ("added_mass", "linear_damping", "quadratic_damping"):
            for i, value in enumerate(getattr(self, key)):
                check(value <= 0.0, f"{key}[{i}]", f"must be ≤ 0 (Fossen's sign), got {value}")
        eigenvalues = np.linalg.eigvalsh(self.mass_matrix)
        check(bool(eigenvalues.min() > 0.0), "inertia_kg_m2", "mass matrix is not positive")

    @property
    def net_buoyancy_n(self) -> float:
        """B − W [N]: positive means the vehicle floats up."""
        return self.buoyancy_n - self.weight_n

    @property
    def inertia_origin(self) -> FloatArray:
        """(3, 3) inertia about CO: I_o = I_g − m·S(r_g)² [kg·m²] (parallel-axis theorem)."""
        s = skew(self.cog_m)
        return np.diag(self.inertia_kg_m2) - self.mass_kg * (s @ s)

    @property
    def rigid_body_mass_matrix(self) -> FloatArray:
        """(6, 6) M_RB about CO: [[m·I, −m·S(r_g)], [m·S(r_g), I_o]] (Fossen 2011, eq. 3.44)."""
        ms = self.mass_kg * skew(self.cog_m)
        return np.block([[self.mass_kg * np.eye(3), -ms], [ms, self.inertia_origin]])

    @property
    def added_mass_matrix(self) -> FloatArray:
        """(6, 6) M_A = −diag(X_u̇, …, N_ṙ)."""
        return -np.diag(self.added_mass)

    @property
    def mass_matrix(self) -> FloatArray:
        """(6, 6) M = M_RB + M_A."""
        return self.rigid_body_mass_matrix + self.added_mass_matrix


def _models_dir() -> resources.abc.Traversable:
    return resources.files("testbed.vehicle").joinpath("data", "models")


def known_models() -> list[str]:
    """Names of the packaged vehicle models (``testbed/vehicle/data/models/*.toml``)."""
    return sorted(
        entry.name.removesuffix(".toml")
        for entry in _models_dir().iterdir()
        if entry.name.endswith(".toml")
    )


def load_model(
    name: str = "bluerov2",
    *,
    added_mass_coriolis: Literal["full", "isotropic", "off"] | None = None,
) -> HydroModel:
    """Load a packaged vehicle model by name.

    Args:
        name: the model (``testbed/vehicle/data/models/NAME.toml``).
        added_mass_coriolis: overrides the file's :attr:`HydroModel.added_mass_coriolis`.

    Raises:
        ConfigError: unknown name (the message lists the known ones) or a bad file.
    """
    known = known_models()
    if name not in known:
        raise ConfigError(f"unknown vehicle model {name!r} (known: {', '.join(known)})")
    entry = _models_dir().joinpath(f"{name}.toml")
    with resources.as_file(entry) as path:
        model = build(HydroModel, load_toml(path), source=str(path))
    if added_mass_coriolis is not None:
        model = dataclasses.replace(model, added_mass_coriolis=added_mass_coriolis)
    return model


# --- kinematics ------------------------------------------------------------------------------


def skew(a: ArrayLike) -> FloatArray:
    """(3, 3) skew-symmetric S(a) with S(a)·b = a × b."""
    x, y, z = np.asarray(a, dtype=float)
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


# --- forces -------------------------------------------------------------


def coriolis_rigid_body(model: HydroModel, nu: ArrayLike) -> FloatArray:
    """(6, 6) C_RB(ν) about CO, linear-velocity-independent form (Fossen 2011, eq. 3.60).

    Args:
        model: the vehicle.
        nu: (6,) body velocity [u v w p q r] at CO [m/s, rad/s], FRD.
    """
    omega = np.asarray(nu, dtype=float)[3:]
    m = model.mass_kg
    s_w = skew(omega)
    s_g = skew(model.cog_m)
    return np.block(
        [
            [m * s_w, -m * s_w @ s_g],
            [m * s_g @ s_w, -skew(model.inertia_origin @ omega)],
        ]
    )


def coriolis_added_mass(model: HydroModel, nu_r: ArrayLike) -> FloatArray:
    """(6, 6) C_A(ν_r) for a diagonal M_A (Fossen 2011, eq. 6.43), includes the Munk moment.

    Args:
        model: the vehicle.
        nu_r: (6,) body velocity relative to the water [m/s, rad/s], FRD.
    """
    a = model.added_mass_matrix @ np.asarray(nu_r, dtype=float)
    s_lin = skew(a[:3])
    return np.block([[np.zeros((3, 3)), -s_lin], [-s_lin, -skew(a[3:])]])


def damping_matrix(model: HydroModel, nu_r: ArrayLike) -> FloatArray:
    """(6, 6) D(ν_r) = −diag(X_u … N_r) − diag(X_u|u| … N_r|r|)·diag(|ν_r|), positive.

    Args:
        model: the vehicle.
        nu_r: (6,) body velocity relative to the water [m/s, rad/s], FRD.
    """
    linear = -np.asarray(model.linear_damping)
    quadratic = -np.asarray(model.quadratic_damping) * np.abs(np.asarray(nu_r, dtype=float))
    return np.diag(linear + quadratic)


def restoring_forces(
    model: HydroModel, rotation: ArrayLike, buoyancy_scale: float = 1.0
) -> FloatArray:
    """(6,) g(η): weight W at r_g, buoyancy B at r_b, both world-vertical (Fossen 2011, eq. 4.6).

    g(η) is on the left of the equation of motion: the wrench on the body is −g(η).

    Args:
        model: the vehicle.
        rotation: (3, 3) R, body FRD → NED.
        buoyancy_scale: submerged fraction of the hull (1 fully under water).
    """
    down_body = np.asarray(rotation, dtype=float).T @ np.array([0.0, 0.0, 1.0])
    f_g = model.weight_n * down_body
    f_b = -model.buoyancy_n * buoyancy_scale * down_body
    moment = np.cross(model.cog_m, f_g) + np.cross(model.cob_m, f_b)
    return -np.concatenate([f_g + f_b, moment])


def wrench_about_origin(model: HydroModel, wrench_cog: ArrayLike) -> FloatArray:
    """(6,) the body wrench about CO equivalent to ``wrench_cog`` about the CoG: M_o = M_g + r_g×F.

    Args:
        model: the vehicle.
        wrench_cog: (6,) body wrench [N, N·m], FRD, moments about the CoG.
    """
    tau = np.asarray(wrench_cog, dtype=float)
    return np.concatenate([tau[:3], tau[3:] + np.cross(model.cog_m, tau[:3])])


def submerged_fraction(depth_cob_m: float, hull_height_m: float) -> float:
    """Fraction of the hull under water, linear while the hull crosses the surface (z = 0).

    Args:
        depth_cob_m: NED z of the centre of buoyancy [m] (positive under water).
        hull_height_m: hull height [m].
    """
    return min(1.0, max(0.0, 0.5 + depth_cob_m / hull_height_m))


def body_acceleration(
    model: HydroModel,
    nu: ArrayLike,
    rotation: ArrayLike,
    wrench_cog: ArrayLike,
    current_ned: ArrayLike = (0.0, 0.0, 0.0),
    buoyancy_scale: float = 1.0,
) -> FloatArray:
    """(6,) ν̇ at CO from (M_RB + M_A)ν̇ = τ − C_RB(ν)ν − C_A(ν_r)ν_r − D(ν_r)ν_r − g(η) + M_A·ν̇_c.

    The current is constant in NED (irrotational); its body-frame derivative as the vehicle
    turns is ν̇_c = [−ω × v_c; 0].

    Args:
        model: the vehicle.
        nu: (6,) body velocity [u v w p q r] at CO [m/s, rad/s], FRD.
        rotation: (3, 3) R, body FRD → NED.
        wrench_cog: (6,) applied body wrench [N, N·m], FRD, moments about the CoG.
        current_ned: (3,) water velocity [m/s], NED.
        buoyancy_scale: submerged fraction of the hull.

    Returns:
        (6,) [u̇ v̇ ẇ ṗ q̇ ṙ], body-frame derivatives of the body velocity [m/s², rad/s²].
    """
    nu = np.asarray(nu, dtype=float)
    rot = np.asarray(rotation, dtype=float)
    current_body = rot.T @ np.asarray(current_ned, dtype=float)
    nu_c = np.concatenate([current_body, np.zeros(3)])
    nu_r = nu - nu_c
    nu_c_dot = np.concatenate([-np.cross(nu[3:], current_body), np.zeros(3)])
    rhs = (
        wrench_about_origin(model, wrench_cog)
        - coriolis_rigid_body(model, nu) @ nu
        - coriolis_added_mass(model, nu_r) @ nu_r
        - damping_matrix(model, nu_r) @ nu_r
        - restoring_forces(model, rot, buoyancy_scale)
        + model.added_mass_matrix @ nu_c_dot
    )
    result: FloatArray = np.linalg.solve(model.mass_matrix, rhs)
    return result
