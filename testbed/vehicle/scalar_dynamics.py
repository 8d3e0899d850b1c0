"""Fossen's 6-DOF equation of motion as generated straight-line Python over floats.

The same accelerations as :func:`testbed.vehicle.hydrodynamics.body_acceleration` (the numpy
reference), as one function per model: the equation is expanded once into polynomials in the
scalar inputs, with every constant folded in and every zero term dropped, M⁻¹ inverted once, and
compiled. The pybullet stepping loop (:mod:`testbed.vehicle.physics`) calls it 240 times per
simulated second; tests hold it to the reference within 1e-10. Frames: body FRD, world NED.

Pure numpy and math: this module must never import pybullet.
"""

from __future__ import annotations

import typing
from collections.abc import Callable, Sequence

import numpy as np

from testbed.vehicle.hydrodynamics import HydroModel

__all__ = ["ScalarDynamics", "make_scalar_dynamics", "scalar_dynamics_source"]

Vec6 = tuple[float, float, float, float, float, float]

# The stepping loop runs 240 times per simulated second, where tiny numpy arrays cost ~40 µs a
# step (REFERENCE §5). Instead, the equation is expanded once per model into polynomials in the
# scalar inputs, with every constant folded in and every zero term dropped (r_g along z alone
# leaves M⁻¹ with 10 non-zeros of 36), and compiled to one straight-line function of floats. The
# numpy functions of testbed.vehicle.hydrodynamics stay the reference; tests compare the two.

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
    """ν̇ as one function of plain floats (the same as :func:`~.hydrodynamics.body_acceleration`).

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
