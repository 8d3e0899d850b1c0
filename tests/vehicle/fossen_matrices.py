"""Fossen's equation of motion in his matrix form, the tests' independent second method.

The package computes ν̇ once, written out term by term and compiled
(:func:`testbed.vehicle.hydrodynamics.fossen_acceleration`); these are the textbook's matrices
(Fossen 2011: C_RB eq. 3.60, C_A eq. 6.43, D, g(η) eq. 4.6) built with numpy and solved with
``np.linalg.solve``, so a sign or index slip in either shows as a disagreement. Frames: body
FRD, world NED, body origin CO; wrenches about the CoG are moved to CO.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from testbed.vehicle.hydrodynamics import HydroModel, skew

FloatArray = NDArray[np.float64]


def coriolis_rigid_body(model: HydroModel, nu: ArrayLike) -> FloatArray:
    """(6, 6) C_RB(ν) about CO, linear-velocity-independent form (Fossen 2011, eq. 3.60)."""
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


def coriolis_diagonal(model: HydroModel) -> FloatArray:
    """(6,) the positive added masses C_A is built from, per ``model.added_mass_coriolis``."""
    added = -np.asarray(model.added_mass, dtype=float)
    if model.added_mass_coriolis == "off":
        return np.zeros(6)
    if model.added_mass_coriolis == "isotropic":
        added[:3] = added[:3].mean()
    return added


def coriolis_added_mass(model: HydroModel, nu_r: ArrayLike) -> FloatArray:
    """(6, 6) C_A(ν_r) for a diagonal added mass (Fossen 2011, eq. 6.43), Munk moment included
    when the model's option is ``"full"``."""
    a = coriolis_diagonal(model) * np.asarray(nu_r, dtype=float)
    s_lin = skew(a[:3])
    return np.block([[np.zeros((3, 3)), -s_lin], [-s_lin, -skew(a[3:])]])


def damping_matrix(model: HydroModel, nu_r: ArrayLike) -> FloatArray:
    """(6, 6) D(ν_r) = −diag(X_u … N_r) − diag(X_u|u| … N_r|r|)·diag(|ν_r|), positive."""
    linear = -np.asarray(model.linear_damping)
    quadratic = -np.asarray(model.quadratic_damping) * np.abs(np.asarray(nu_r, dtype=float))
    return np.diag(linear + quadratic)


def restoring_forces(
    model: HydroModel, rotation: ArrayLike, buoyancy_scale: float = 1.0
) -> FloatArray:
    """(6,) g(η): weight at r_g, buoyancy at r_b, both world-vertical (eq. 4.6); the wrench on
    the body is −g(η). ``rotation``: R, body FRD → NED."""
    down_body = np.asarray(rotation, dtype=float).T @ np.array([0.0, 0.0, 1.0])
    f_g = model.weight_n * down_body
    f_b = -model.buoyancy_n * buoyancy_scale * down_body
    moment = np.cross(model.cog_m, f_g) + np.cross(model.cob_m, f_b)
    return -np.concatenate([f_g + f_b, moment])


def wrench_about_origin(model: HydroModel, wrench_cog: ArrayLike) -> FloatArray:
    """(6,) the body wrench about CO equivalent to ``wrench_cog`` about the CoG."""
    tau = np.asarray(wrench_cog, dtype=float)
    return np.concatenate([tau[:3], tau[3:] + np.cross(model.cog_m, tau[:3])])


def body_acceleration(
    model: HydroModel,
    nu: ArrayLike,
    rotation: ArrayLike,
    wrench_cog: ArrayLike,
    current_ned: ArrayLike = (0.0, 0.0, 0.0),
    buoyancy_scale: float = 1.0,
) -> FloatArray:
    """(6,) ν̇ = M⁻¹(τ − C_RB(ν)ν − C_A(ν_r)ν_r − D(ν_r)ν_r − g(η) + M_A·ν̇_c), the current
    constant in NED: ν̇_c = [−ω × v_c; 0] in the turning body."""
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
