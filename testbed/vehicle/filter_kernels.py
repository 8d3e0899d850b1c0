"""The navigation filter's arithmetic, compiled: prediction and the gated Joseph update.

The equations are :mod:`testbed.vehicle.estimation`'s (its module docstring); this module only
does them on small float64 arrays without numpy's per-call overhead, which at 100 Hz motion
capture (with a one-step replay of every late fix) was most of a frame. The products are plain
loops over the (≤ 6)-sized matrices (numba's ``@`` and ``np.linalg.inv`` go through BLAS and
LAPACK, which for a 6 × 6 matrix cost more in the call than in the arithmetic), and each call
returns as few new arrays as it can: numba hands every one back to Python with a call into
Python (``_numba_unpickle``). Compiled by numba and cached to disk beside this file; the
kernels call nothing outside it (numba's cache does not follow calls into other files). numpy
and numba only.
"""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import NDArray

__all__ = ["APPLIED", "GATED", "SINGULAR", "gated_update", "propagate"]

FloatArray = NDArray[np.float64]

APPLIED = 0
""":func:`gated_update`'s status: the measurement was applied."""
GATED = 1
"""The normalised innovation exceeded the gate: nothing applied."""
SINGULAR = 2
"""The innovation covariance could not be inverted (or was not finite): nothing applied."""


@numba.njit(cache=True)
def _product(a: FloatArray, b: FloatArray) -> FloatArray:  # pragma: no cover - compiled
    """``a @ b`` for (n, k) ``a`` and (k, m) ``b``."""
    n, k = a.shape
    m = b.shape[1]
    out = np.empty((n, m))
    for i in range(n):
        for j in range(m):
            total = 0.0
            for inner in range(k):
                total += a[i, inner] * b[inner, j]
            out[i, j] = total
    return out


@numba.njit(cache=True)
def _inverse(s: FloatArray) -> tuple[FloatArray, bool]:  # pragma: no cover - compiled
    """``s⁻¹`` of a small square matrix by Gauss-Jordan elimination with partial pivoting,
    and whether it exists (a zero or non-finite pivot: ``False``, the matrix is garbage)."""
    m = s.shape[0]
    a = s.copy()
    inv = np.eye(m)
    for col in range(m):
        pivot = col
        for row in range(col + 1, m):
            if abs(a[row, col]) > abs(a[pivot, col]):
                pivot = row
        value = a[pivot, col]
        if not (value != 0.0 and np.isfinite(value)):
            return inv, False
        if pivot != col:
            for j in range(m):
                a[col, j], a[pivot, j] = a[pivot, j], a[col, j]
                inv[col, j], inv[pivot, j] = inv[pivot, j], inv[col, j]
        scale = 1.0 / value
        for j in range(m):
            a[col, j] *= scale
            inv[col, j] *= scale
        for row in range(m):
            if row != col:
                factor = a[row, col]
                if factor != 0.0:
                    for j in range(m):
                        a[row, j] -= factor * a[col, j]
                        inv[row, j] -= factor * inv[col, j]
    return inv, True


@numba.njit(cache=True)
def propagate(
    x: FloatArray, p: FloatArray, f: FloatArray, g: FloatArray, qm: FloatArray, accel: FloatArray
) -> tuple[FloatArray, FloatArray]:  # pragma: no cover - compiled
    """x⁻ = F x + G u, P⁻ = F P Fᵀ + Q for (6,) x, (6, 6) P, F, Q, (6, 3) G and an input u of
    (3,) or (0,) (none: constant velocity)."""
    n = x.shape[0]
    x_next = np.empty(n)
    for i in range(n):
        total = 0.0
        for j in range(n):
            total += f[i, j] * x[j]
        for j in range(accel.shape[0]):
            total += g[i, j] * accel[j]
        x_next[i] = total
    p_next = _product(_product(f, p), f.T)
    for i in range(n):
        for j in range(n):
            p_next[i, j] += qm[i, j]
    return x_next, p_next


@numba.njit(cache=True)
def gated_update(
    x: FloatArray, p: FloatArray, h: FloatArray, z: FloatArray, sigma: FloatArray, gate: float
) -> tuple[FloatArray, FloatArray, float, int]:  # pragma: no cover - compiled
    """One measurement, gated: y = z − H x, S = H P Hᵀ + diag(σ²), the normalised innovation
    yᵀ S⁻¹ y; when it is ≤ ``gate`` (``inf``: no gate) the Joseph update x = x⁻ + K y,
    P = (I − K H) P⁻ (I − K H)ᵀ + K R Kᵀ with K = P Hᵀ S⁻¹, R = diag(σ²).

    Returns:
        ``(x, P, nis, status)``: the posterior (the prior, unchanged, unless applied), the
        normalised innovation (NaN when S is singular) and :data:`APPLIED`, :data:`GATED` or
        :data:`SINGULAR`.
    """
    m, n = h.shape
    y = np.empty(m)
    for i in range(m):
        total = z[i]
        for j in range(n):
            total -= h[i, j] * x[j]
        y[i] = total
    pht = _product(p, h.T)  # P Hᵀ, (n, m)
    s = _product(h, pht)
    for i in range(m):
        s[i, i] += sigma[i] * sigma[i]
    s_inv, ok = _inverse(s)
    if not ok:
        return x, p, np.nan, SINGULAR
    nis = 0.0
    for i in range(m):
        row = 0.0
        for j in range(m):
            row += s_inv[i, j] * y[j]
        nis += y[i] * row
    if not np.isfinite(nis):
        return x, p, np.nan, SINGULAR
    if nis > gate:
        return x, p, nis, GATED
    k = _product(pht, s_inv)  # (n, m)
    x_post = x.copy()
    for i in range(n):
        for j in range(m):
            x_post[i] += k[i, j] * y[j]
    a = -_product(k, h)  # I − K H
    for i in range(n):
        a[i, i] += 1.0
    p_post = _product(_product(a, p), a.T)
    for i in range(n):
        for j in range(n):
            total = 0.0
            for inner in range(m):
                total += k[i, inner] * sigma[inner] * sigma[inner] * k[j, inner]
            p_post[i, j] += total
    return x_post, p_post, nis, APPLIED
