"""Fossen's 6-DOF vehicle model: parameters, forces, and the water current.

The equation of motion (Fossen 2011, body frame, relative velocity ν_r = ν − ν_c)::

    M_RB ν̇ + C_RB(ν) ν + M_A ν̇_r + C_A(ν_r) ν_r + D(ν_r) ν_r + g(η) = τ

World NED, body FRD, body origin CO (the point the hydrodynamic coefficients refer to: the
centre of buoyancy in Wu 2018). ``cog_m`` is r_g and ``cob_m`` r_b, both from CO in the body
frame; ``inertia_kg_m2`` are the principal moments about the CoG (body-aligned axes), so
M_RB about CO carries the m·S(r_g) coupling and the parallel-axis term. The applied wrench is
given about the CoG (thruster allocation works about the centre of mass) and moved to CO here.

Two paths compute the same accelerations: the numpy reference functions (clear matrices, used by
tests) and :func:`make_scalar_dynamics`, straight-line Python over floats generated once per
model (constants folded in, zero terms dropped, M⁻¹ inverted once), which the pybullet stepping
loop calls 240 times per simulated second. Tests hold the two to 1e-10.

Pure numpy and math: this module must never import pybullet.
"""

from __future__ import annotations

import math
import typing
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from importlib import resources

import numpy as np
from numpy.typing import ArrayLike, NDArray

from testbed.config import ConfigError, build, check, load_toml

__all__ = [
    "CurrentProcess",
    "HydroModel",
    "ScalarDynamics",
    "WaterCurrent",
    "body_acceleration",
    "coriolis_added_mass",
    "coriolis_rigid_body",
    "damping_matrix",
    "euler_from_quaternion",
    "known_models",
    "load_model",
    "make_scalar_dynamics",
    "quaternion_from_euler",
    "restoring_forces",
    "rotation_from_euler",
    "rotation_from_quaternion",
    "scalar_dynamics_source",
    "skew",
    "submerged_fraction",
    "wrench_about_origin",
]

FloatArray = NDArray[np.float64]
Vec3 = tuple[float, float, float]
Vec4 = tuple[float, float, float, float]
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


def load_model(name: str = "bluerov2") -> HydroModel:
    """Load a packaged vehicle model by name.

    Raises:
        ConfigError: unknown name (the message lists the known ones) or a bad file.
    """
    known = known_models()
    if name not in known:
        raise ConfigError(f"unknown vehicle model {name!r} (known: {', '.join(known)})")
    entry = _models_dir().joinpath(f"{name}.toml")
    with resources.as_file(entry) as path:
        return build(HydroModel, load_toml(path), source=str(path))


# --- kinematics ------------------------------------------------------------------------------


def skew(a: ArrayLike) -> FloatArray:
    """(3, 3) skew-symmetric S(a) with S(a)·b = a × b."""
    x, y, z = np.asarray(a, dtype=float)
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def rotation_from_quaternion(q_wxyz: ArrayLike) -> FloatArray:
    """(3, 3) rotation R (body → world) of the unit quaternion (w, x, y, z)."""
    w, x, y, z = np.asarray(q_wxyz, dtype=float) / np.linalg.norm(q_wxyz)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def rotation_from_euler(roll_rad: float, pitch_rad: float, yaw_rad: float) -> FloatArray:
    """(3, 3) R = Rz(yaw)·Ry(pitch)·Rx(roll), body FRD → NED (ZYX convention)."""
    cr, sr = math.cos(roll_rad), math.sin(roll_rad)
    cp, sp = math.cos(pitch_rad), math.sin(pitch_rad)
    cy, sy = math.cos(yaw_rad), math.sin(yaw_rad)
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def quaternion_from_euler(roll_rad: float, pitch_rad: float, yaw_rad: float) -> Vec4:
    """Unit quaternion (w, x, y, z) of the ZYX Euler angles (body FRD → NED)."""
    cr, sr = math.cos(roll_rad / 2), math.sin(roll_rad / 2)
    cp, sp = math.cos(pitch_rad / 2), math.sin(pitch_rad / 2)
    cy, sy = math.cos(yaw_rad / 2), math.sin(yaw_rad / 2)
    return (
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    )


def euler_from_quaternion(w: float, x: float, y: float, z: float) -> Vec3:
    """ZYX Euler angles (roll, pitch, yaw) [rad] of the unit quaternion (w, x, y, z).

    Pitch is clamped to ±π/2 at the singularity.
    """
    roll = math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2.0 * (w * y - z * x))))
    yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return (roll, pitch, yaw)


# --- forces (numpy reference path) -------------------------------------------------------------


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


# --- fast scalar path ---------------------------------------------------------------------------
#
# The stepping loop runs 240 times per simulated second, where tiny numpy arrays cost ~40 µs a
# step (REFERENCE §5). Instead, the equation above is expanded once per model into polynomials
# in the scalar inputs, with every constant folded in and every zero term dropped (r_g along z
# alone leaves M⁻¹ with 10 non-zeros of 36), and compiled to one straight-line function of
# floats. The numpy functions above stay the reference; tests compare the two.

ScalarDynamics = Callable[..., Vec6]
"""``f(u, v, w, p, q, r, gx, gy, gz, uc, vc, wc, scale, X, Y, Z, K, M, N) -> ν̇``."""

_Poly = dict[tuple[str, ...], float]
_ARGS = "u, v, w, p, q, r, gx, gy, gz, uc, vc, wc, scale, fx, fy, fz, mx, my, mz"


def _var(name: str) -> _Poly:
    return {(name,): 1.0}


def _const(value: float) -> _Poly:
    return {(): value} if value != 0.0 else {}


def _add(*polys: _Poly) -> _Poly:
    total: _Poly = {}
    for poly in polys:
        for mono, coef in poly.items():
            total[mono] = total.get(mono, 0.0) + coef
    return {mono: coef for mono, coef in total.items() if coef != 0.0}


def _mul(a: _Poly, b: _Poly) -> _Poly:
    terms = [{tuple(sorted(ma + mb)): ca * cb} for ma, ca in a.items() for mb, cb in b.items()]
    return _add(*terms)


def _scale(k: float, a: _Poly) -> _Poly:
    return _add({mono: k * coef for mono, coef in a.items()})


def _cross(a: Sequence[_Poly], b: Sequence[_Poly]) -> list[_Poly]:
    return [
        _add(_mul(a[1], b[2]), _scale(-1.0, _mul(a[2], b[1]))),
        _add(_mul(a[2], b[0]), _scale(-1.0, _mul(a[0], b[2]))),
        _add(_mul(a[0], b[1]), _scale(-1.0, _mul(a[1], b[0]))),
    ]


def _code(poly: _Poly) -> str:
    if not poly:
        return "0.0"
    parts = []
    for mono, coef in sorted(poly.items()):
        factors = " * ".join(mono)
        if not mono:
            parts.append(repr(coef))
        elif coef == 1.0:
            parts.append(factors)
        elif coef == -1.0:
            parts.append(f"-{factors}")
        else:
            parts.append(f"{coef!r} * {factors}")
    return " + ".join(parts).replace("+ -", "- ")


def scalar_dynamics_source(model: HydroModel, *, with_current: bool = True) -> str:
    """Python source of the model's ν̇ function (see :func:`make_scalar_dynamics`)."""
    m = model.mass_kg
    rg = [_const(c) for c in model.cog_m]
    omega = [_var("p"), _var("q"), _var("r")]
    vel = [_var("u"), _var("v"), _var("w")]
    # Without a current, ν_r = ν: the added-mass terms share the rigid body's monomials.
    rel = [_var(n) for n in (("ur", "vr", "wr") if with_current else ("u", "v", "w"))]
    down = [_var("gx"), _var("gy"), _var("gz")]
    force = [_var("fx"), _var("fy"), _var("fz")]
    moment = [_var("mx"), _var("my"), _var("mz")]
    added = [-a for a in model.added_mass]
    inertia = model.inertia_origin.tolist()
    # −C_RB(ν)ν − C_A(ν_r)ν_r, Kirchhoff's form: momenta P = m·v_g + A₁₁ν_r, L = I_o·ω + A₂₂ω.
    v_cog = [_add(vi, ci) for vi, ci in zip(vel, _cross(omega, rg), strict=True)]
    a_lin = [_scale(added[i], rel[i]) for i in range(3)]
    momentum = [_add(_scale(m, v_cog[i]), a_lin[i]) for i in range(3)]
    spin = [
        _add(
            *(_scale(inertia[i][j] + (added[3 + i] if i == j else 0.0), omega[j]) for j in range(3))
        )
        for i in range(3)
    ]
    lin = [_scale(-1.0, c) for c in _cross(omega, momentum)]
    ang = [
        _scale(-1.0, _add(a, b, c))
        for a, b, c in zip(
            _cross([_scale(m, g) for g in rg], _cross(omega, vel)),
            _cross(omega, spin),
            _cross(rel, a_lin),
            strict=True,
        )
    ]
    # −D(ν_r)ν_r, quadratic terms through |x| helper variables.
    names = ["ur", "vr", "wr", "p", "q", "r"] if with_current else ["u", "v", "w", "p", "q", "r"]
    damping = [
        _add(
            _scale(model.linear_damping[i], _var(n)),
            _scale(model.quadratic_damping[i], _mul(_var(f"abs_{n}"), _var(n))),
        )
        for i, n in enumerate(names)
    ]
    # −g(η): net·down and (W·r_g − B·s·r_b) × down, with net = W − B·s computed first.
    weight, buoyancy = model.weight_n, model.buoyancy_n
    preamble = [f"net = {weight!r} - {buoyancy!r} * scale"]
    lever = []
    for axis, g, b in zip("xyz", model.cog_m, model.cob_m, strict=True):
        if b == 0.0:
            lever.append(_const(weight * g))
        else:
            h = _add(_const(weight * g), _scale(-buoyancy * b, _var("scale")))
            preamble.append(f"h{axis} = {_code(h)}")
            lever.append(_var(f"h{axis}"))
    restoring = [_mul(_var("net"), d) for d in down] + _cross(lever, down)
    # τ about CO from the wrench about the CoG; + M_A·ν̇_c with ν̇_c = [v_c × ω; 0].
    applied = force + [_add(mi, ci) for mi, ci in zip(moment, _cross(rg, force), strict=True)]
    current = [_var("uc"), _var("vc"), _var("wc")]
    transport = [_scale(added[i], c) for i, c in enumerate(_cross(current, omega))]
    tau = [
        _add(applied[i], restoring[i], damping[i], (lin + ang)[i], transport[i] if i < 3 else {})
        if with_current
        else _add(applied[i], restoring[i], damping[i], (lin + ang)[i])
        for i in range(6)
    ]
    minv = np.linalg.inv(model.mass_matrix)
    tiny = 1e-12 * float(np.abs(minv).max())
    lines = [f"def accelerate({_ARGS}):"] + [f"    {line}" for line in preamble]
    if with_current:
        lines.append("    ur = u - uc; vr = v - vc; wr = w - wc")
    used = {f for poly in tau for mono in poly for f in mono}
    for n in names:
        if f"abs_{n}" in used:
            lines.append(f"    abs_{n} = {n} if {n} >= 0.0 else -{n}")
    for i, poly in enumerate(tau):
        lines.append(f"    t{i} = {_code(poly)}")
    rows = [
        _code({(f"t{j}",): float(minv[i, j]) for j in range(6) if abs(minv[i, j]) > tiny})
        for i in range(6)
    ]
    lines.append("    return (" + ", ".join(rows) + ")")
    return "\n".join(lines) + "\n"


def make_scalar_dynamics(model: HydroModel, *, with_current: bool = True) -> ScalarDynamics:
    """The same ν̇ as :func:`body_acceleration`, as one function of plain floats.

    The function takes the body velocity at CO (u, v, w, p, q, r), the world "down" direction in
    the body (gx, gy, gz) = Rᵀ·[0, 0, 1] (the last row of R), the current in the body
    (uc, vc, wc), the submerged fraction, and the applied wrench about the CoG
    (X, Y, Z, K, M, N), FRD; it returns ν̇ at CO as a 6-tuple [m/s², rad/s²]. M⁻¹ is inverted
    once, here, for the general M (r_g ≠ 0 couples surge–pitch and sway–roll).

    Args:
        model: the vehicle.
        with_current: False drops the current terms (uc, vc, wc are then ignored).
    """
    source = scalar_dynamics_source(model, with_current=with_current)
    namespace: dict[str, object] = {}
    # The source is generated from the model's numbers only, never from user text.
    exec(compile(source, f"<scalar dynamics: {model.name}>", "exec"), namespace)
    return typing.cast(ScalarDynamics, namespace["accelerate"])


# --- water current -----------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class WaterCurrent:
    """A water current: a constant NED velocity plus an optional slow Gauss–Markov variation.

    Each NED component of the variation is a first-order Gauss–Markov process
    ẋ = −x/T + w (Fossen 2011, §8.3), sampled exactly every ``update_period_s`` and held in
    between, so the current is irrotational and piecewise constant in NED.

    Attributes:
        velocity_ned_mps: (3,) mean water velocity [m/s], NED.
        variation_std_mps: (3,) stationary standard deviation of each component's variation [m/s].
        time_constant_s: correlation time T of the variation [s].
        update_period_s: how often the variation is sampled [s].
    """

    velocity_ned_mps: Vec3 = (0.0, 0.0, 0.0)
    variation_std_mps: Vec3 = (0.0, 0.0, 0.0)
    time_constant_s: float = 120.0
    update_period_s: float = 0.5

    def __post_init__(self) -> None:
        for i, value in enumerate(self.variation_std_mps):
            check(value >= 0.0, f"variation_std_mps[{i}]", f"must be ≥ 0, got {value}")
        check(
            self.time_constant_s > 0.0,
            "time_constant_s",
            f"must be > 0, got {self.time_constant_s}",
        )
        check(
            self.update_period_s > 0.0,
            "update_period_s",
            f"must be > 0, got {self.update_period_s}",
        )

    @property
    def varies(self) -> bool:
        """Whether the current has a random variation."""
        return any(value > 0.0 for value in self.variation_std_mps)


class CurrentProcess:
    """The running state of a :class:`WaterCurrent`: its NED velocity now.

    Args:
        current: the current's parameters.
        rng: the generator driving the variation (required when the current varies).

    Raises:
        ValueError: the current varies and no generator was given.
    """

    def __init__(self, current: WaterCurrent, rng: np.random.Generator | None = None) -> None:
        if current.varies and rng is None:
            raise ValueError("a varying WaterCurrent needs a numpy Generator (rng=...)")
        self._current = current
        self._rng = rng
        self._std = np.asarray(current.variation_std_mps, dtype=float)
        # Start in the stationary distribution, as if the process had always been running.
        self._deviation = (
            self._std * rng.standard_normal(3) if current.varies and rng is not None else None
        )
        self.velocity_ned: Vec3 = self._velocity()

    def _velocity(self) -> Vec3:
        mean = self._current.velocity_ned_mps
        if self._deviation is None:
            return (float(mean[0]), float(mean[1]), float(mean[2]))
        vx, vy, vz = (np.asarray(mean) + self._deviation).tolist()
        return (vx, vy, vz)

    def advance(self, dt_s: float) -> Vec3:
        """Advance the variation by ``dt_s`` (exact discretisation); the velocity [m/s], NED."""
        if self._deviation is not None and self._rng is not None:
            phi = math.exp(-dt_s / self._current.time_constant_s)
            noise = self._std * math.sqrt(1.0 - phi * phi) * self._rng.standard_normal(3)
            self._deviation = phi * self._deviation + noise
            self.velocity_ned = self._velocity()
        return self.velocity_ned
