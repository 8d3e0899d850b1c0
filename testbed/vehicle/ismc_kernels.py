"""The ISMC's law, compiled: one control step on the controller's state array.

The law and its frames are :mod:`testbed.vehicle.ismc`'s (its module docstring); that module
keeps the gains, the model and the state's meaning, and calls :func:`ismc_step` once a control
period. The model terms come from :func:`~testbed.vehicle.plant_kernels.fossen_acceleration`,
compiled into this kernel (:func:`~testbed.common.jit.refresh_stale_caches` empties this
file's disk cache when that file is newer). numpy and numba only.

State (:data:`STATE_SIZE` float64, written in place): :data:`ERROR0` (6,) v_e(0) at arming,
:data:`LAST_ERROR` (6,) the previous update's v_e, :data:`INTEGRAL` (6,) ∫v_e dt [m, rad],
:data:`SLIDING` (6,) s [m/s, rad/s], :data:`ROBUST` (6,) ρ·tanh(s/λ) [N, N·m] and
:data:`ARMED` (1.0 once v_e(0) is stored, 0.0 after a reset).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from testbed.common import jit
from testbed.vehicle import plant_kernels
from testbed.vehicle.plant_kernels import fossen_acceleration

__all__ = [
    "ARMED",
    "ERROR0",
    "INTEGRAL",
    "LAST_ERROR",
    "ROBUST",
    "SLIDING",
    "STATE_SIZE",
    "ismc_step",
]

ERROR0, LAST_ERROR, INTEGRAL, SLIDING, ROBUST = 0, 6, 12, 18, 24
"""Offsets of the state's six-vectors."""
ARMED = 30
"""Offset of the armed flag (1.0: v_e(0) stored)."""
STATE_SIZE = 31


@numba.njit(cache=True)
def ismc_step(
    c: np.ndarray,
    mass: np.ndarray,
    cog: tuple[float, float, float],
    kp: tuple[float, float, float, float, float, float],
    rho: float,
    width: float,
    state: np.ndarray,
    v_cmd: tuple[float, float, float, float, float, float],
    nu: tuple[float, float, float, float, float, float],
    down: tuple[float, float, float],
    dt_s: float,
) -> tuple[float, float, float, float, float, float]:  # pragma: no cover - compiled
    """One ISMC update (:meth:`~testbed.vehicle.ismc.IsmcController.update`'s law).

    Args:
        c: the controller model's :func:`~testbed.vehicle.hydrodynamics.coefficients`.
        mass: (6, 6) its mass matrix M (rigid body plus added mass) about CO.
        cog: its centre of gravity from CO [m], FRD.
        kp: Kp per body axis [1/s].
        rho: ρ [N, N·m]; width: λ [m/s, rad/s].
        state: the controller's state (module docstring), updated in place.
        v_cmd: commanded body twist (u v w p q r) [m/s, rad/s], FRD, at CO.
        nu: measured body twist, same frame.
        down: the world's down unit vector in the body, FRD.
        dt_s: time since the previous update [s] (ignored by the arming update).

    Returns:
        (6,) body wrench (X Y Z K M N) [N, N·m], FRD, moments about the CoG.
    """
    error = np.empty(6)
    for i in range(6):
        error[i] = v_cmd[i] - nu[i]
    if state[ARMED] == 0.0:  # arming: v_e(0) now, the integral empty, so s = 0 exactly
        for i in range(6):
            state[ERROR0 + i] = error[i]
            state[INTEGRAL + i] = 0.0
        state[ARMED] = 1.0
    else:  # forward Euler with the error the held wrench was computed from
        for i in range(6):
            state[INTEGRAL + i] = state[INTEGRAL + i] + state[LAST_ERROR + i] * dt_s
    for i in range(6):
        state[LAST_ERROR + i] = error[i]
        s = error[i] - state[ERROR0 + i] + kp[i] * state[INTEGRAL + i]
        state[SLIDING + i] = s
        state[ROBUST + i] = rho * math.tanh(s / width)
    free = fossen_acceleration(c, nu, down, (0.0, 0.0, 0.0), 1.0, (0.0, 0.0, 0.0, 0.0, 0.0, 0.0))
    # τ_CO = M·(Kp·v_e − ν̇_free) + ρ·tanh(s/λ): −M·ν̇_free = C(ν)ν + D(ν)ν + g(η)
    demand = np.empty(6)
    for i in range(6):
        demand[i] = kp[i] * error[i] - free[i]
    tau = np.empty(6)
    for i in range(6):
        total = mass[i, 0] * demand[0]
        for j in range(1, 6):
            total = total + mass[i, j] * demand[j]
        tau[i] = total + state[ROBUST + i]
    fx, fy, fz = tau[0], tau[1], tau[2]
    xg, yg, zg = cog
    # moment about the CoG = moment about CO − r_g × F
    return (
        fx,
        fy,
        fz,
        tau[3] - (yg * fz - zg * fy),
        tau[4] - (zg * fx - xg * fz),
        tau[5] - (xg * fy - yg * fx),
    )


jit.refresh_stale_caches((ismc_step,), (plant_kernels,))
