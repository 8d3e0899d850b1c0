"""Fossen's 6-DOF vehicle model: its parameters and its equation of motion, written once.

The equation of motion (Fossen 2011, body frame, relative velocity ν_r = ν − ν_c)::

    M_RB ν̇ + C_RB(ν) ν + M_A ν̇_r + C_A(ν_r) ν_r + D(ν_r) ν_r + g(η) = τ

World NED, body FRD, body origin CO (the point the hydrodynamic coefficients refer to: the
centre of buoyancy in Wu 2018). ``cog_m`` is r_g and ``cob_m`` r_b, both from CO in the body
frame; ``inertia_kg_m2`` are the principal moments about the CoG (body-aligned axes), so
M_RB about CO carries the m·S(r_g) coupling and the parallel-axis term. The applied wrench is
given about the CoG (thruster allocation works about the centre of mass) and moved to CO here.

:func:`~testbed.vehicle.plant_kernels.fossen_acceleration` is the one implementation of the
right-hand side, compiled by numba (:mod:`testbed.vehicle.plant_kernels`, beside the pybullet
step that calls it); :func:`coefficients` lays the model out for it and
:func:`body_acceleration` is its array interface. Tests check it against Fossen's matrices
written out independently in the tests (tests/vehicle/fossen_matrices.py), an integration by
scipy, and closed forms. The water current (ν_c) is :mod:`testbed.vehicle.water_current`;
:class:`WaterCurrent` is re-exported here for the callers that import it with the model.

numpy and math: this module must never import pybullet.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from testbed.config import (
    ConfigError,
    FieldError,
    build,
    built_from_text,
    check,
    load_toml,
    user_file,
)
from testbed.vehicle.plant_kernels import N_COEFFICIENTS, fossen_acceleration
from testbed.vehicle.water_current import WaterCurrent

__all__ = [
    "GRAVITY_RANGE_M_S2",
    "WEIGHT_TOLERANCE",
    "HydroModel",
    "WaterCurrent",
    "body_acceleration",
    "coefficients",
    "known_models",
    "load_model",
    "skew",
    "submerged_fraction",
]

FloatArray = NDArray[np.float64]
Vec3 = tuple[float, float, float]
Vec6 = tuple[float, float, float, float, float, float]


MAX_WATER_DENSITY_KG_M3 = 1030.0
"""The densest sea water a vehicle is modelled in [kg/m³] (a bound on buoyancy, not the plant's
density)."""

MAX_SOLID_DENSITY_KG_M3 = 22590.0
"""Osmium, the densest element [kg/m³]: a vehicle's mass over its hull box's volume is below it
(a mass given in grams, 11 500 "kg", sank the vehicle 450 m in 12 s, quietly)."""

GRAVITY_RANGE_M_S2 = (9.78, 9.83)
"""Standard gravity at sea level from the equator to the poles [m/s²]: a model's ``weight_n``
must be ``mass_kg`` times some g in this range (the packaged models use 9.81 and 9.82)."""
WEIGHT_TOLERANCE = 0.01
"""Relative slack on ``weight_n`` beyond :data:`GRAVITY_RANGE_M_S2` (rounded figures)."""


@dataclass(frozen=True, slots=True)
class HydroModel:
    """One vehicle's rigid-body and hydrodynamic parameters (Fossen notation, SI units).

    Attributes:
        name: model name (the TOML file's stem).
        source: where the figures come from.
        mass_kg: rigid-body mass m.
        weight_n: weight W = m·g [N], g in [9.78, 9.83] m/s² (:data:`GRAVITY_RANGE_M_S2`),
            within 1 % (:data:`WEIGHT_TOLERANCE`).
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
            and each C_A is skew-symmetric (it does no work). The default is the packaged
            models' ``"isotropic"``; a model file must name it (:func:`load_model`).
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
    added_mass_coriolis: Literal["full", "isotropic", "off"] = "isotropic"

    def __post_init__(self) -> None:
        for key in _NUMBER_KEYS:  # inf passed the sign checks (a traceback, or NaN results)
            value = getattr(self, key)
            for i, number in enumerate(value if isinstance(value, tuple) else (value,)):
                where = f"{key}[{i}]" if isinstance(value, tuple) else key
                check(math.isfinite(number), where, f"must be finite, got {number}")
        check(self.mass_kg > 0.0, "mass_kg", f"must be > 0, got {self.mass_kg}")
        check(self.weight_n > 0.0, "weight_n", f"must be > 0, got {self.weight_n}")
        g_low, g_high = GRAVITY_RANGE_M_S2
        low = self.mass_kg * g_low * (1.0 - WEIGHT_TOLERANCE)
        high = self.mass_kg * g_high * (1.0 + WEIGHT_TOLERANCE)
        check(
            low <= self.weight_n <= high,
            "weight_n",
            f"must be mass_kg·g (W = m·g, g in [{g_low:g}, {g_high:g}] m/s², within 1 %): "
            f"[{low:.4g}, {high:.4g}] N for {self.mass_kg:g} kg, got {self.weight_n:g}",
        )
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

    def check_body(self) -> None:
        """Refuse figures no rigid body has (they ran quietly: 1e9 N of buoyancy on 14 kg
        flew the vehicle 33 m above the surface): a body's principal moments obey the triangle
        inequality; its centres of gravity and buoyancy lie within its hull box; it displaces
        at most its hull box's volume of the densest water, at the strongest gravity.
        :func:`load_model` checks every model file so; a controller's deliberately wrong belief
        (:func:`~testbed.vehicle.ismc.mismatched_model`) is not a body and is not checked.

        Raises:
            FieldError: naming the key.
        """
        inertia, size = self.inertia_kg_m2, self.hull_size_m
        volume_m3 = float(np.prod(size))
        density = self.mass_kg / volume_m3
        check(
            density <= MAX_SOLID_DENSITY_KG_M3,
            "mass_kg",
            f"{self.mass_kg:g} kg in a hull box of {volume_m3:.4g} m³ is {density:.4g} kg/m³, "
            f"denser than any solid ({MAX_SOLID_DENSITY_KG_M3:g} kg/m³, osmium): grams for kg?",
        )
        for i, axis in enumerate("xyz"):
            b, c = size[(i + 1) % 3], size[(i + 2) % 3]
            most = self.mass_kg * (b * b + c * c) / 4.0  # all the mass at the box's corners
            check(
                inertia[i] <= most * (1.0 + 1e-9),
                f"inertia_kg_m2[{i}]",
                f"I{axis}{axis} = {inertia[i]:g} kg·m² exceeds {most:.4g}, the most "
                f"{self.mass_kg:g} kg inside the {b:g} × {c:g} m hull section can have",
            )
            others = inertia[(i + 1) % 3] + inertia[(i + 2) % 3]
            check(
                inertia[i] <= others * (1.0 + 1e-9),
                f"inertia_kg_m2[{i}]",
                f"I{axis}{axis} = {inertia[i]:g} exceeds the other two together ({others:g}): "
                "no rigid body has such principal moments",
            )
        for key in ("cog_m", "cob_m"):
            point = getattr(self, key)
            for i, (value, extent) in enumerate(zip(point, size, strict=True)):
                check(
                    abs(value) <= extent / 2.0,
                    f"{key}[{i}]",
                    f"must lie within the hull box (|{value:g}| ≤ hull_size_m[{i}]/2 = "
                    f"{extent / 2.0:g} m)",
                )
        most_n = MAX_WATER_DENSITY_KG_M3 * GRAVITY_RANGE_M_S2[1] * volume_m3
        check(
            self.buoyancy_n <= most_n,
            "buoyancy_n",
            f"must be ≤ {most_n:.4g} N, the weight of the water the hull box holds "
            f"({volume_m3:.4g} m³ of {MAX_WATER_DENSITY_KG_M3:g} kg/m³), got {self.buoyancy_n:g}",
        )

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


_NUMBER_KEYS = tuple(
    f.name for f in dataclasses.fields(HydroModel) if f.type in ("float", "Vec3", "Vec6")
)
"""The fields that hold numbers (from the class: a new one is checked too), each checked
finite first in :meth:`HydroModel.__post_init__`."""


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
    """Load a vehicle model: a packaged one by name, or the user's own TOML file (the packaged
    files' layout) at the path ``name``.

    Args:
        name: a packaged model (``testbed/vehicle/data/models/NAME.toml``) or a ``.toml`` path.
        added_mass_coriolis: overrides the file's :attr:`HydroModel.added_mass_coriolis`.

    Raises:
        ConfigError: neither a packaged name nor a file (the message lists the packaged ones),
            or a bad file (the message names the file and the key).
    """
    own = user_file(name, known_models(), "vehicle model")
    option = added_mass_coriolis
    if own is not None:
        return built_from_text("model", own, lambda: _read_model(own, option), option)
    with resources.as_file(_models_dir().joinpath(f"{name}.toml")) as path:
        return built_from_text("model", path, lambda: _read_model(path, option), option)


def _read_model(
    path: Path, added_mass_coriolis: Literal["full", "isotropic", "off"] | None
) -> HydroModel:
    """The model in the file at ``path``, checked (:meth:`HydroModel.check_body`)."""
    source = str(path)
    data = load_toml(path)
    if added_mass_coriolis is None and "added_mass_coriolis" not in data:
        raise ConfigError(  # left out, it silently meant Wu's full C_A once, which tumbles
            f"{source}: added_mass_coriolis: required key missing ('isotropic' as the packaged "
            "models, 'full' or 'off': docs/vehicle.md), or set vehicle.added_mass_coriolis"
        )
    model = build(HydroModel, data, source=source)
    try:
        model.check_body()
    except FieldError as err:
        raise ConfigError(f"{source}: {err.key}: {err.message}") from None
    if added_mass_coriolis is not None:
        model = dataclasses.replace(model, added_mass_coriolis=added_mass_coriolis)
    return model


# --- kinematics ------------------------------------------------------------------------------


def skew(a: ArrayLike) -> FloatArray:
    """(3, 3) skew-symmetric S(a) with S(a)·b = a × b."""
    x, y, z = np.asarray(a, dtype=float)
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def coefficients(model: HydroModel) -> FloatArray:
    """The model's coefficients as :func:`~.plant_kernels.fossen_acceleration` reads them, in
    the order of :mod:`~testbed.vehicle.plant_kernels`' offsets (read-only float64 array): m, W,
    B, r_g, r_b, I_o (row-major), −diag(M_A), the diagonal C_A is built from (per
    :attr:`HydroModel.added_mass_coriolis`), linear and quadratic damping, M⁻¹ (row-major)."""
    added = [-a for a in model.added_mass]
    if model.added_mass_coriolis == "full":
        coriolis = added
    elif model.added_mass_coriolis == "isotropic":
        mean = sum(added[:3]) / 3.0
        coriolis = [mean, mean, mean, *added[3:]]
    else:
        coriolis = [0.0] * 6
    values = [
        model.mass_kg,
        model.weight_n,
        model.buoyancy_n,
        *model.cog_m,
        *model.cob_m,
        *model.inertia_origin.ravel().tolist(),
        *added,
        *coriolis,
        *model.linear_damping,
        *model.quadratic_damping,
        *np.linalg.inv(model.mass_matrix).ravel().tolist(),
    ]
    array = np.array(values, dtype=np.float64)
    assert array.shape == (N_COEFFICIENTS,)  # plant_kernels' layout, in its order
    array.setflags(write=False)
    return array


def body_acceleration(
    model: HydroModel,
    nu: ArrayLike,
    rotation: ArrayLike,
    wrench_cog: ArrayLike,
    current_ned: ArrayLike = (0.0, 0.0, 0.0),
    buoyancy_scale: float = 1.0,
) -> FloatArray:
    """(6,) ν̇ at CO: :func:`~.plant_kernels.fossen_acceleration` for arrays (tests, analysis).

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
    rot = np.asarray(rotation, dtype=np.float64)
    u, v, w, p, q, r = _floats(nu)
    gx, gy, gz = _floats(rot[2])
    uc, vc, wc = _floats(rot.T @ np.asarray(current_ned, dtype=np.float64))
    fx, fy, fz, mx, my, mz = _floats(wrench_cog)
    result = fossen_acceleration(
        coefficients(model),
        (u, v, w, p, q, r),
        (gx, gy, gz),
        (uc, vc, wc),
        float(buoyancy_scale),
        (fx, fy, fz, mx, my, mz),
    )
    return np.array(result)


def _floats(values: ArrayLike) -> list[float]:
    """``values`` as Python floats (one compiled signature for every caller)."""
    return [float(x) for x in np.asarray(values, dtype=np.float64).ravel()]


def submerged_fraction(depth_cob_m: float, hull_height_m: float) -> float:
    """Fraction of the hull under water, linear while the hull crosses the surface (z = 0).

    Args:
        depth_cob_m: NED z of the centre of buoyancy [m] (positive under water).
        hull_height_m: hull height [m].
    """
    return min(1.0, max(0.0, 0.5 + depth_cob_m / hull_height_m))
