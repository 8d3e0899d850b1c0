"""Singularity-robust multiple task-priority inverse kinematics: the recursion, task-agnostic.

After Moe, Antonelli, Teel, Pettersen & Schrimpf (2016). Equality tasks i = 1, 2, … (highest
first) with Jacobian J_i (m_i × n) and gain-scaled desired task velocity σ̇_i = ẋ_d,i + K_i e_i
are solved recursively (:func:`prioritized_solution`)::

    ζ_i = ζ_{i−1} + (J_i N_{i−1})⁺ (σ̇_i − J_i ζ_{i−1}),   N_i = I − J_aug,i⁺ J_aug,i

with J_aug,i the stacked Jacobians of tasks 1..i (:func:`null_space`), so a lower task never
changes what a higher one gets. Pseudo-inverses are singularity-robust (:func:`pinv`): singular
values σ ≥ t are inverted, smaller ones get σ/t² (continuous at t, → 0 at σ → 0, gain ≤ 1/t);
the null-space projectors truncate at the same t (directions with σ < t are left to the lower
tasks), so N is an exact orthogonal projector. :class:`Level` is the recursion after some
tasks, so a caller enumerating task sets that share a prefix (:func:`~testbed.vehicle.tpik.
solve_uvms`'s set-based modes) solves the prefix once (:func:`start_level`, :func:`descend`,
:func:`finish`). Pure numpy; no frames, no ECS, no randomness.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "EqualityTask",
    "Level",
    "descend",
    "finish",
    "null_space",
    "pinv",
    "prioritized_solution",
    "start_level",
]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class EqualityTask:
    """One priority level: J ζ should equal ``error``.

    Attributes:
        name: for reports.
        jacobian: (m, N) task Jacobian (N = len ζ).
        error: (m,) desired task velocity, already gain-scaled: ẋ_d + K e.
    """

    name: str
    jacobian: FloatArray
    error: FloatArray


def _identity(n: int) -> FloatArray:
    """The read-only (n, n) identity, built once per n."""
    eye = _IDENTITIES.get(n)
    if eye is None:
        eye = np.eye(n)
        eye.flags.writeable = False
        _IDENTITIES[n] = eye
    return eye


_IDENTITIES: dict[int, FloatArray] = {}


def _symmetric_eig(g: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Eigenvalues and (column) eigenvectors of a small symmetric matrix; 2 × 2 in closed form
    (a rotation by ½·atan2(2b, a − c)), larger ones by ``np.linalg.eigh``."""
    if g.shape[0] != 2:
        lam, u = np.linalg.eigh(g)
        return lam, u
    a, b, c = float(g[0, 0]), float(g[0, 1]), float(g[1, 1])
    mean, radius = 0.5 * (a + c), math.hypot(0.5 * (a - c), b)
    angle = 0.5 * math.atan2(2.0 * b, a - c)
    cos, sin = math.cos(angle), math.sin(angle)
    return np.array([mean + radius, mean - radius]), np.array([[cos, -sin], [sin, cos]])


def _robust_inverse(a: FloatArray, lam: FloatArray, u: FloatArray, t2: float) -> FloatArray:
    """:func:`pinv` of ``a`` (m ≤ n) from the eigen-pairs (λ, U) of a·aᵀ: Aᵀ U g(Λ) Uᵀ."""
    out: FloatArray = a.T @ ((u / np.maximum(lam, t2)) @ u.T)
    return out


def _kept_projector(a: FloatArray, lam: FloatArray, u: FloatArray, t2: float) -> FloatArray:
    """:func:`_row_space` of ``a`` (m < n) from the eigen-pairs (λ, U) of a·aᵀ: each kept
    v = Aᵀu/σ, so Σ v vᵀ = Aᵀ U_k Λ_k⁻¹ U_kᵀ A."""
    keep = lam >= t2
    w = a.T @ u[:, keep]
    out: FloatArray = (w / lam[keep]) @ w.T
    return out


def pinv(matrix: FloatArray, threshold: float) -> FloatArray:
    """Singularity-robust pseudo-inverse: σ ≥ t → 1/σ, σ < t → σ/t² (module docstring (d)).

    Computed from the smaller Gram matrix, not an SVD of ``matrix``: with A = U Σ Vᵀ and
    A Aᵀ = U Σ² Uᵀ, the robust inverse V f(Σ) Uᵀ is Aᵀ U g(Σ²) Uᵀ with g(λ) = 1 / max(λ, t²)
    (σ·g(σ²) = 1/σ for σ ≥ t and σ/t² below: the same law, λ = σ² against t²), or its mirror
    V g(Σ²) Vᵀ Aᵀ from AᵀA when A has more rows than columns. One row: aᵀ / max(a·a, t²).
    """
    a = np.atleast_2d(np.asarray(matrix, dtype=float))
    t2 = threshold * threshold
    m, n = a.shape
    if m == 1:
        row = a[0]
        out: FloatArray = (row / max(float(row @ row), t2))[:, None]
        return out
    if m <= n:
        lam, u = _symmetric_eig(a @ a.T)
        return _robust_inverse(a, lam, u, t2)
    lam, v = _symmetric_eig(a.T @ a)
    out = ((v / np.maximum(lam, t2)) @ v.T) @ a.T
    return out


def _row_space(stacked: FloatArray, threshold: float) -> FloatArray:
    """(n, n) the projector onto the span of the right singular vectors of ``stacked`` whose
    singular value is ≥ ``threshold`` (eigenvalue λ = σ² ≥ t² of the smaller Gram matrix)."""
    t2 = threshold * threshold
    m, n = stacked.shape
    if m == 1:
        row = stacked[0]
        norm2 = float(row @ row)
        return np.outer(row, row / norm2) if norm2 >= t2 else np.zeros((n, n))
    if m < n:
        lam, u = _symmetric_eig(stacked @ stacked.T)
        return _kept_projector(stacked, lam, u, t2)
    lam, v = _symmetric_eig(stacked.T @ stacked)
    rows = v[:, lam >= t2]
    out: FloatArray = rows @ rows.T
    return out


def null_space(jacobians: Sequence[FloatArray], n: int, threshold: float) -> FloatArray:
    """N = I − J_aug⁺ J_aug of the stacked ``jacobians`` (n columns), truncated at ``threshold``.

    Directions with singular value < ``threshold`` count as not taken, so N is an orthogonal
    projector (symmetric, idempotent). No Jacobians: the identity.
    """
    if not jacobians:
        return np.eye(n)
    stacked = np.vstack([np.atleast_2d(np.asarray(j, dtype=float)) for j in jacobians])
    out: FloatArray = _identity(n) - _row_space(stacked, threshold)
    return out


class Level(NamedTuple):
    """The recursion after some tasks: ζ, the projector N and the stacked Jacobians so far."""

    zeta: FloatArray
    projector: FloatArray
    stacked: FloatArray


def start_level(n: int) -> Level:
    return Level(np.zeros(n), _identity(n), np.zeros((0, n)))


def _task_jacobian(task: EqualityTask, n: int) -> FloatArray:
    jac = np.atleast_2d(np.asarray(task.jacobian, dtype=float))
    if jac.shape[1] != n:
        raise ValueError(f"task {task.name}: jacobian has {jac.shape[1]} columns, not {n}")
    return jac


def _robust_step(b: FloatArray, residual: FloatArray, t2: float) -> FloatArray:
    """:func:`pinv` (b) @ residual, without forming the inverse: Bᵀ U g(Λ) Uᵀ r."""
    m, n = b.shape
    if m == 1:
        row = b[0]
        out: FloatArray = row * (float(residual[0]) / max(float(row @ row), t2))
        return out
    if m > n:
        return pinv(b, math.sqrt(t2)) @ residual
    lam, u = _symmetric_eig(b @ b.T)
    out = b.T @ (u @ ((residual @ u) / np.maximum(lam, t2)))
    return out


def descend(level: Level, task: EqualityTask, threshold: float, project: bool) -> Level:
    """One priority level of the recursion (module docstring); N_i only if ``project``."""
    n = level.zeta.shape[0]
    jac = _task_jacobian(task, n)
    residual = np.asarray(task.error, dtype=float).reshape(-1) - jac @ level.zeta
    m = jac.shape[0]
    t2 = threshold * threshold
    if level.stacked.shape[0] == 0 and 1 < m < n:  # N = I: J N and the stack are J, one Gram
        lam, u = _symmetric_eig(jac @ jac.T)
        zeta = level.zeta + jac.T @ (u @ ((residual @ u) / np.maximum(lam, t2)))
        if not project:
            return Level(zeta, level.projector, level.stacked)
        return Level(zeta, _identity(n) - _kept_projector(jac, lam, u, t2), jac)
    zeta = level.zeta + _robust_step(jac @ level.projector, residual, t2)
    if not project:
        return Level(zeta, level.projector, level.stacked)
    stacked = np.concatenate([level.stacked, jac])
    return Level(zeta, _identity(n) - _row_space(stacked, threshold), stacked)


def finish(level: Level, tasks: Sequence[EqualityTask], threshold: float) -> FloatArray:
    """ζ after ``tasks`` below ``level`` (no projector after the last: nothing uses it)."""
    for k, task in enumerate(tasks):
        level = descend(level, task, threshold, k + 1 < len(tasks))
    return level.zeta


def prioritized_solution(tasks: Sequence[EqualityTask], n: int, threshold: float) -> FloatArray:
    """ζ (n,) of the recursive null-space projection (module docstring), tasks highest first."""
    return finish(start_level(n), tasks, threshold)
