"""The navigation filter's arithmetic, compiled: prediction, innovation and Joseph update.

The equations are :mod:`testbed.vehicle.estimation`'s (its module docstring); this module only
does them on small float64 arrays without numpy's per-call overhead, which at 100 Hz motion
capture (with a one-step replay of every late fix) was most of a frame. Compiled by numba and
cached to disk beside this file; the kernels call nothing outside it (numba's cache does not
follow calls into other files). numpy and numba only.
"""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import NDArray

__all__ = ["innovation", "joseph_update", "propagate"]

FloatArray = NDArray[np.float64]


@numba.njit(cache=True)
def propagate(
    x: FloatArray, p: FloatArray, f: FloatArray, qm: FloatArray
) -> tuple[FloatArray, FloatArray]:  # pragma: no cover - compiled
    """x⁻ = F x, P⁻ = F P Fᵀ + Q for (6,) x and (6, 6) P, F, Q."""
    return f @ x, f @ p @ f.T + qm


@numba.njit(cache=True)
def innovation(
    x: FloatArray, p: FloatArray, h: FloatArray, z: FloatArray, sigma: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray, float]:  # pragma: no cover - compiled
    """y = z − H x, P Hᵀ, S⁻¹ with S = H P Hᵀ + diag(σ²), and the normalised innovation
    yᵀ S⁻¹ y, for (m, 6) H and (m,) z and σ. Raises on a singular S (numba: ValueError-like
    ``np.linalg.LinAlgError``)."""
    y = z - h @ x
    pht = p @ h.T
    s = h @ pht
    for i in range(z.shape[0]):
        s[i, i] += sigma[i] * sigma[i]
    s_inv: FloatArray = np.linalg.inv(s)  # type: ignore[assignment]  # float64 in, float64 out
    nis = float(y @ (s_inv @ y))
    return y, pht, s_inv, nis


@numba.njit(cache=True)
def joseph_update(
    x: FloatArray,
    p: FloatArray,
    h: FloatArray,
    pht: FloatArray,
    s_inv: FloatArray,
    y: FloatArray,
    sigma: FloatArray,
) -> tuple[FloatArray, FloatArray]:  # pragma: no cover - compiled
    """x = x⁻ + K y, P = (I − K H) P⁻ (I − K H)ᵀ + K R Kᵀ with K = P Hᵀ S⁻¹, R = diag(σ²)."""
    k = pht @ s_inv
    a = np.eye(x.shape[0]) - k @ h
    kr = k.copy()
    for j in range(sigma.shape[0]):
        kr[:, j] *= sigma[j] * sigma[j]
    return x + k @ y, a @ p @ a.T + kr @ k.T
