"""The allocator's linear algebra: T and T⁺ under failures, bounded least squares, axis maxima.

:func:`effective_layout` turns a thruster configuration's T, (6, n) [N, N·m per N], body FRD,
rows X Y Z K M N, and the known failures into what
:class:`~testbed.vehicle.allocation.Allocator` solves with (an :class:`EffectiveLayout`): the
effective T (a dead thruster's column zero, a degraded one's scaled by its factor), T⁺ of the
commandable columns (:func:`pseudoinverse`, SVD), the stuck thrusters' held forces and wrench,
and the matrix of the bounded least-squares solve (:func:`solve_bounded`, the allocator's
``method="lsq"`` when T⁺m saturates). :func:`probe_axis_maxima` measures how far such a layout
can push along each axis, for pilot scaling (mate-rov's algorithm).

The layout and the maxima are computed once per configuration or failure set, never per frame.
The per-frame step and the current and slew limits are the allocator's (:mod:`.allocation`);
the arithmetic they share is compiled in :mod:`.thrust_kernels`. scipy is imported only by
:func:`solve_bounded`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from testbed.vehicle.thrust_kernels import current_scale, pinv_forces
from testbed.vehicle.thrusters import ThrusterFault

__all__ = [
    "AXIS_DIRECTION_TOLERANCE",
    "AXIS_PROBE",
    "PINV_RTOL",
    "EffectiveLayout",
    "effective_layout",
    "probe_axis_maxima",
    "pseudoinverse",
    "solve_bounded",
]

PINV_RTOL = 1e-5
"""Singular values below this × the largest are treated as zero in T⁺ (mate-rov motor_math)."""

AXIS_PROBE = 15.0
"""Probe magnitude [N or N·m] for the axis maxima (mate-rov 2025)."""

AXIS_DIRECTION_TOLERANCE = 0.05
"""mate-rov's ε for the axis probe: the axis counts if |√(15 · (T T⁺ m)_k) - 15| ≤ ε."""

_LSQ_REGULARISATION = 1e-4
"""Weight of ‖f‖ in the lsq objective, to pick the least-effort solution among equals."""


def pseudoinverse(matrix: np.ndarray, rtol: float = PINV_RTOL) -> tuple[np.ndarray, int]:
    """Moore-Penrose pseudoinverse by SVD, and the numerical rank.

    Args:
        matrix: (r, c) matrix.
        rtol: singular values ≤ rtol × the largest count as zero.

    Returns:
        ((c, r) pseudoinverse, rank).
    """
    u, s, vt = np.linalg.svd(matrix, full_matrices=False)
    if s.size == 0 or s[0] == 0.0:
        return np.zeros(matrix.T.shape), 0
    keep = s > rtol * s[0]
    inverse = (vt[keep].T / s[keep]) @ u[:, keep].T
    return inverse, int(keep.sum())


@dataclass(frozen=True, slots=True, eq=False)
class EffectiveLayout:
    """A thruster layout as the allocator sees it under the known failures. ``==`` is identity
    (it holds arrays).

    Attributes:
        matrix: (6, n) effective T [N, N·m per N], FRD: dead columns zero, degraded ones scaled.
        pinv: (n, 6) T⁺ of the commandable columns, C-contiguous; rows of the thrusters that
            cannot be commanded (dead, stuck, degraded to 0) are exactly zero.
        rank: numerical rank of the commandable part of T (6 = every axis independent).
        commandable: (n,) bool, whether the allocator may command each thruster.
        columns: indices of the commandable thrusters, ascending.
        lsq_matrix: (6 + c, c) the commandable columns of T over 1e-4 × the identity, for the
            bounded least squares min ‖T f - m‖ with a least-effort tie-break (c commandable).
        stuck_forces: (n,) each stuck thruster's held force [N], 0 elsewhere.
        stuck_wrench: (6,) the body wrench [N, N·m], FRD, the stuck thrusters give.
    """

    matrix: np.ndarray
    pinv: np.ndarray
    rank: int
    commandable: np.ndarray
    columns: np.ndarray
    lsq_matrix: np.ndarray
    stuck_forces: np.ndarray
    stuck_wrench: np.ndarray


def effective_layout(matrix: np.ndarray, failures: Mapping[int, ThrusterFault]) -> EffectiveLayout:
    """T, T⁺ and the stuck offsets of a layout with some thrusters failed.

    Args:
        matrix: (6, n) T of the healthy layout [N, N·m per N], FRD.
        failures: known faults by thruster index: a dead thruster leaves T; a stuck one leaves
            T⁺ and holds its force; a degraded one's column is scaled by its factor (and leaves
            T⁺ at factor 0).

    Returns:
        The layout the allocator solves with.
    """
    n = matrix.shape[1]
    gain = np.ones(n)
    commandable = np.ones(n, dtype=bool)
    stuck_forces = np.zeros(n)
    for index, fault in failures.items():
        if fault.mode == "degraded":
            gain[index] = fault.value
            commandable[index] = fault.value > 0.0
        else:
            commandable[index] = False
            if fault.mode == "dead":
                gain[index] = 0.0
            else:
                stuck_forces[index] = fault.value
    matrix_eff = matrix * gain
    solve = matrix_eff * commandable
    pinv, rank = pseudoinverse(solve)
    pinv[~commandable] = 0.0  # exact zeros, not SVD round-off
    columns = np.flatnonzero(commandable)
    lsq_matrix = np.vstack([solve[:, columns], _LSQ_REGULARISATION * np.eye(columns.size)])
    return EffectiveLayout(
        matrix=matrix_eff,
        pinv=np.ascontiguousarray(pinv),
        rank=rank,
        commandable=commandable,
        columns=columns,
        lsq_matrix=lsq_matrix,
        stuck_forces=stuck_forces,
        stuck_wrench=matrix_eff @ stuck_forces,
    )


def probe_axis_maxima(
    layout: EffectiveLayout,
    force_limits_n: tuple[float, float],
    current_table: np.ndarray,
    current_cap_a: float,
    current_tolerance_a: float,
) -> np.ndarray:
    """(2, 6) largest pure wrench along +e_k (row 0) and -e_k (row 1) [N, N·m], FRD.

    Probe m = ±15 e_k (mate-rov's algorithm, REFERENCE §3.5): f = T⁺m; the axis counts only
    if √(F·F_req) + √(τ·τ_req) = 15 within :data:`AXIS_DIRECTION_TOLERANCE` (for a one-axis
    probe: √(15 · (T f)_k) within 0.05 of 15, i.e. its own component delivered to within
    ≈ 0.1), else it reports 0; then f is scaled up until the first thruster limit or the
    current budget binds, and the maximum is 15 α.

    Like mate-rov, the test ignores cross-coupling into other axes: on the standard
    BlueROV2 the laterals sit 7 cm below the CoM and the verticals 1 cm forward of it, and
    pitch is not in T's range, so T⁺ delivers 14.93 N of a 15 N surge request with a
    1.05 N·m parasitic pitch moment (heave: 15.00 N with -0.15 N·m), which the vehicle's
    righting moment absorbs; both axes count. Where T has full rank, T T⁺ m = m exactly.
    The stuck thrusters' wrench is not counted (their current is off ``current_cap_a``).

    With the 12 V table this reproduces REFERENCE §3.5's derived maxima (standard and 6-DOF
    BlueROV2, 25 and 50 A) to within 0.06 N or N·m; tests/vehicle/test_allocation.py
    lists the two figures that round differently and why.

    Args:
        layout: the layout to probe.
        force_limits_n: each thruster's (reverse, forward) force limits [N], reverse < 0.
        current_table: (2, k) the thrusters' current [A] against force [N].
        current_cap_a: the current budget left for the commandable thrusters [A].
        current_tolerance_a: a binding current budget is met to within this [A], from below.

    Returns:
        The maxima, read-only.
    """
    f_lo, f_hi = force_limits_n
    maxima = np.zeros((2, 6))
    no_offset = np.zeros(6)
    f = np.zeros(layout.matrix.shape[1])
    for row, sign in enumerate((1.0, -1.0)):
        for k in range(6):
            probe = np.zeros(6)
            probe[k] = sign * AXIS_PROBE
            worst = pinv_forces(probe, no_offset, layout.pinv, f_lo, f_hi, f)
            along = probe[k] * float(layout.matrix[k] @ f)  # F·F_req or τ·τ_req
            if along <= 0.0 or worst <= 0.0:
                continue
            if abs(math.sqrt(along) - AXIS_PROBE) > AXIS_DIRECTION_TOLERANCE:
                continue
            alpha = current_scale(
                f, current_table, current_cap_a, 1.0 / worst, -1.0, current_tolerance_a
            )
            maxima[row, k] = AXIS_PROBE * alpha
    maxima.setflags(write=False)
    return maxima


def solve_bounded(
    layout: EffectiveLayout, wrench: np.ndarray, force_limits_n: tuple[float, float]
) -> np.ndarray:
    """Bounded least squares: min ‖T f - m‖ (+ a 1e-4 ‖f‖ tie-break) on the force limits.

    Solved over the commandable thrusters by scipy's ``lsq_linear`` (BVLS).

    Args:
        layout: the layout to solve with.
        wrench: (6,) the body wrench m to deliver [N, N·m], FRD (stuck thrusters' wrench off).
        force_limits_n: each thruster's (reverse, forward) force limits [N], reverse < 0.

    Returns:
        (n,) forces [N], within the limits; 0 for the thrusters that cannot be commanded.
    """
    from scipy.optimize import lsq_linear  # scipy only on this slow, opt-in path

    f_lo, f_hi = force_limits_n
    target = np.concatenate([wrench, np.zeros(layout.columns.size)])
    result = lsq_linear(layout.lsq_matrix, target, bounds=force_limits_n, method="bvls")
    f = np.zeros(layout.matrix.shape[1])
    f[layout.columns] = np.clip(result.x, f_lo, f_hi)
    return f
