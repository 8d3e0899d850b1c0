"""The thrust chain's per-frame arithmetic, compiled by numba: allocation, T200 lookups, thrusters.

One implementation of each step, called by :mod:`.allocation` (f = T⁺m, saturation, current
budget, slew), :mod:`.t200` (every lookup of the T200's tables: :func:`lookup`) and
:mod:`.thrusters` (the spin-up lag), and by the frame's systems (:mod:`.systems`: the wrench of
the thrusters' mean forces). The kernels take and return plain floats and float64 arrays; the
classes around them keep the validation (shapes, finite values) and the configuration.

Every kernel is ``numba.njit(cache=True)``: compiled once per machine and loaded from the cache
beside this file afterwards (sweep workers and repeated runs do not recompile). They live in one
module because numba's cache does not follow calls into other files: a kernel calling one
defined elsewhere would keep a stale copy of it after that file changed. The one exception is the
frame store's write rule (:func:`~.row_kernels.put_row`), whose file
:func:`~testbed.common.jit.refresh_stale_caches` watches for the kernels that compile it in.

Units: forces [N], wrenches (X, Y, Z, K, M, N) [N, N·m] in the body FRD frame, currents [A],
PWM pulses [µs], times [s]. A lookup table is a (2, k) array: row 0 the strictly increasing
abscissae, row 1 the values, interpolated linearly with the end values held outside
(:func:`lookup`).

Layouts shared with :class:`~testbed.vehicle.allocation.Allocator`:

* ``work`` (4, n): rows :data:`FORCES` (the command, written), :data:`PWM` (written),
  :data:`CURRENTS` (written) and :data:`PREVIOUS` (the last command before stuck forces, read
  for the slew limit and written);
* ``thrusters`` (3, n): rows :data:`PWM_SIGN` and :data:`PWM_OFFSET` (pwm = sign · pulse +
  offset: 1, 0 for CW propellers; -1, 3000 µs for CCW) and :data:`STUCK` (each stuck
  thruster's held force [N], 0 elsewhere).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from testbed.common import jit
from testbed.vehicle import row_kernels
from testbed.vehicle.row_kernels import put_row

__all__ = [
    "CURRENTS",
    "FORCES",
    "PREVIOUS",
    "PWM",
    "PWM_OFFSET",
    "PWM_SIGN",
    "STUCK",
    "actuate_rows",
    "allocate_pinv",
    "allocate_rows",
    "current_scale",
    "interval_wrench",
    "lag_step",
    "limit_forces",
    "lookup",
    "lookup_many",
    "pinv_forces",
    "put_output",
    "put_wrench",
    "put_wrench_pair",
    "sum_rows",
    "total_current",
]

FORCES, PWM, CURRENTS, PREVIOUS = 0, 1, 2, 3
"""Rows of the allocator's ``work`` array."""
PWM_SIGN, PWM_OFFSET, STUCK = 0, 1, 2
"""Rows of the allocator's ``thrusters`` array."""

_MAX_ITERATIONS = 100
_STALL = 1e-9
"""A regula falsi step this close to an end of the bracket (its fraction of the bracket) is
taken as a stall and replaced by a bisection: over a stretch of Σ I(α f) that is flat a hair
above the budget (the T200 table has flat steps) the secant crept towards the root by a few ulp
an iteration and ran out of iterations 0.07 A short of a 5-A budget."""


@numba.njit(cache=True)
def lookup(x: float, table: np.ndarray) -> float:  # pragma: no cover - compiled
    """The (2, k) table at ``x``: linear between the rows around it, the end values outside.

    On [x_j, x_j+1): ``slope_j · (x − x_j) + y_j`` with slope_j = (y_j+1 − y_j) / (x_j+1 − x_j),
    so a row's own abscissa gives its value exactly. NaN gives NaN.
    """
    xs, ys = table[0], table[1]
    last = xs.size - 1
    if x <= xs[0]:
        return float(ys[0])
    if x >= xs[last]:
        return float(ys[last])
    lo, hi = 0, last
    while hi - lo > 1:  # bisection: xs[lo] <= x < xs[hi]
        mid = (lo + hi) >> 1
        if xs[mid] <= x:
            lo = mid
        else:
            hi = mid
    slope = (ys[lo + 1] - ys[lo]) / (xs[lo + 1] - xs[lo])
    return float(slope * (x - xs[lo]) + ys[lo])


@numba.njit(cache=True)
def lookup_many(
    xs: np.ndarray, table: np.ndarray, out: np.ndarray
) -> None:  # pragma: no cover - compiled
    """:func:`lookup` at each of (n,) ``xs``, into (n,) ``out``."""
    for i in range(xs.size):
        out[i] = lookup(xs[i], table)


@numba.njit(cache=True)
def total_current(
    forces: np.ndarray, scale: float, table: np.ndarray
) -> float:  # pragma: no cover - compiled
    """Σ_i I(scale · forces_i) [A] for (n,) forces [N] on the (2, k) force → current table."""
    total = 0.0
    for i in range(forces.size):
        total += lookup(scale * forces[i], table)
    return total


@numba.njit(cache=True)
def current_scale(
    forces: np.ndarray,
    table: np.ndarray,
    cap_a: float,
    alpha_max: float,
    current_at_max_a: float,
    tolerance_a: float,
) -> float:  # pragma: no cover - compiled
    """Largest α in [0, alpha_max] with Σ I(α f) ≤ cap_a, to within ``tolerance_a`` below it.

    Σ I(α f) is piecewise linear and non-decreasing in α (the current envelope rises with |F|
    on both sides of 0 N) and 0 at α = 0. The first guess assumes I ∝ |F|^1.5 (momentum
    theory: power ∝ thrust^1.5); Illinois regula falsi then refines inside the bracket, a step
    that stalls at an end of it bisecting instead (:data:`_STALL`). The returned α always
    satisfies the budget (typically 2-4 evaluations).

    Args:
        forces: (n,) forces [N] to scale.
        table: (2, k) force [N] → current [A] table.
        cap_a: the budget [A].
        alpha_max: the largest admissible α (saturation).
        current_at_max_a: Σ I(alpha_max f) [A] if known, else negative.
        tolerance_a: how far below the budget a binding result may stay [A].
    """
    if cap_a <= 0.0:
        return 0.0
    g_hi = current_at_max_a
    if g_hi < 0.0:
        g_hi = total_current(forces, alpha_max, table)
    if g_hi <= cap_a:
        return alpha_max
    a_lo, g_lo, a_hi = 0.0, 0.0, alpha_max
    a: float = alpha_max * (cap_a / g_hi) ** (2.0 / 3.0)
    side = 0
    for _ in range(_MAX_ITERATIONS):
        g = total_current(forces, a, table)
        if g <= cap_a:
            if cap_a - g <= tolerance_a:
                return a
            a_lo, g_lo = a, g
            if side < 0:  # Illinois: the same end moved twice, halve the other's residual
                g_hi = cap_a + 0.5 * (g_hi - cap_a)
            side = -1
        else:
            a_hi, g_hi = a, g
            if side > 0:
                g_lo = cap_a - 0.5 * (cap_a - g_lo)
            side = 1
        a = a_lo + (cap_a - g_lo) * (a_hi - a_lo) / (g_hi - g_lo)
        edge = _STALL * (a_hi - a_lo)
        if a - a_lo < edge or a_hi - a < edge:  # stalled at an end: bisect instead
            a = 0.5 * (a_lo + a_hi)
    return a_lo


@numba.njit(cache=True)
def pinv_forces(
    wrench: np.ndarray,
    offset: np.ndarray,
    pinv: np.ndarray,
    f_lo: float,
    f_hi: float,
    out: np.ndarray,
) -> float:  # pragma: no cover - compiled
    """f = T⁺(m − m_stuck) into ``out``; returns how far the worst thruster is past its limit.

    Args:
        wrench: (6,) requested body wrench m [N, N·m], FRD.
        offset: (6,) the stuck thrusters' wrench m_stuck, subtracted first.
        pinv: (n, 6) T⁺.
        f_lo, f_hi: the thrusters' force limits [N] (f_lo < 0 < f_hi).
        out: (n,) written with f [N].

    Returns:
        max_i f_i / limit_i (the limit on f_i's side; 0 for f = 0): above 1, f saturates and
        1 / that is the direction-keeping scale. NaN when the wrench is not finite.
    """
    for k in range(6):
        if not math.isfinite(wrench[k]):
            return math.nan
    worst = 0.0
    for i in range(pinv.shape[0]):
        f = 0.0
        for k in range(6):
            f += pinv[i, k] * (wrench[k] - offset[k])
        out[i] = f
        ratio = f / f_hi if f > 0.0 else f / f_lo
        if ratio > worst:
            worst = ratio
    return worst


@numba.njit(cache=True)
def limit_forces(
    work: np.ndarray,
    worst: float,
    slew_step_n: float,
    cap_a: float,
    tolerance_a: float,
    thrusters: np.ndarray,
    current_table: np.ndarray,
    pwm_table: np.ndarray,
) -> float:  # pragma: no cover - compiled
    """The vehicle's limits on a free allocation, then its PWM pulses and currents.

    1. Saturation: when ``worst`` > 1 the whole f is scaled by 1 / worst (direction kept).
    2. Current: when Σ I(f_i) > ``cap_a``, f is scaled by :func:`current_scale`'s α.
    3. Slew (``slew_step_n`` ≥ 0, finite): each f_i moves at most ``slew_step_n`` [N] from the
       previous command; if that lets Σ I exceed the budget, step 2 is applied again and wins.
    4. The result is the next previous command; stuck thrusters' held forces are added
       (their columns of T⁺ are zero, so they carry 0 N until here), then PWM and current.

    Args:
        work: (4, n) the allocator's work rows: FORCES holds T⁺m on entry (from
            :func:`pinv_forces`, or a bounded solution with ``worst`` = 1), PREVIOUS the last
            command; FORCES, PWM, CURRENTS and PREVIOUS are written.
        worst: :func:`pinv_forces`'s saturation ratio.
        slew_step_n: largest change per thruster this call [N]; negative or infinite = none.
        cap_a: current budget of the commandable thrusters [A] (stuck ones' draw taken off).
        tolerance_a: a binding current limit is met to within this below the budget [A].
        thrusters: (3, n) PWM_SIGN, PWM_OFFSET and STUCK rows.
        current_table: (2, k) force [N] → current [A].
        pwm_table: (2, k) force [N] → CW pulse [µs].

    Returns:
        The common factor of steps 1 and 2 (1 if neither bound).
    """
    f = work[FORCES]
    n = f.size
    scale = 1.0
    if worst > 1.0:
        scale = 1.0 / worst
        for i in range(n):
            f[i] *= scale
    total = total_current(f, 1.0, current_table)
    if total > cap_a:
        alpha = current_scale(f, current_table, cap_a, 1.0, total, tolerance_a)
        scale *= alpha
        for i in range(n):
            f[i] *= alpha
    previous = work[PREVIOUS]
    if slew_step_n >= 0.0 and math.isfinite(slew_step_n):
        for i in range(n):
            p = previous[i]
            d = f[i] - p
            f[i] = p + (slew_step_n if d > slew_step_n else -slew_step_n if d < -slew_step_n else d)
        total = total_current(f, 1.0, current_table)
        if total > cap_a:
            alpha = current_scale(f, current_table, cap_a, 1.0, total, tolerance_a)
            for i in range(n):
                f[i] *= alpha
    pwm, currents = work[PWM], work[CURRENTS]
    for i in range(n):
        previous[i] = f[i]
        f[i] += thrusters[STUCK, i]
        pwm[i] = thrusters[PWM_SIGN, i] * lookup(f[i], pwm_table) + thrusters[PWM_OFFSET, i]
        currents[i] = lookup(f[i], current_table)
    return scale


@numba.njit(cache=True)
def allocate_pinv(
    wrench: np.ndarray,
    offset: np.ndarray,
    pinv: np.ndarray,
    f_lo: float,
    f_hi: float,
    slew_step_n: float,
    cap_a: float,
    tolerance_a: float,
    work: np.ndarray,
    thrusters: np.ndarray,
    current_table: np.ndarray,
    pwm_table: np.ndarray,
) -> float:  # pragma: no cover - compiled
    """The ECS paper's allocation in one call: :func:`pinv_forces` into ``work[FORCES]``, then
    :func:`limit_forces` (the arguments are theirs). Returns the scale, NaN for a wrench that
    is not finite (``work`` then holds nothing of use)."""
    worst = pinv_forces(wrench, offset, pinv, f_lo, f_hi, work[FORCES])
    if worst != worst:
        return math.nan
    return limit_forces(
        work, worst, slew_step_n, cap_a, tolerance_a, thrusters, current_table, pwm_table
    )


@numba.njit(cache=True)
def lag_step(
    forces: np.ndarray, command: np.ndarray, gain: np.ndarray, held: np.ndarray, blend: float
) -> None:  # pragma: no cover - compiled
    """One zero-order-hold step of the thrusters' first-order lag, in place.

    F_i += (g_i · F_cmd,i − F_i) · blend with blend = 1 − exp(−dt/τ) (exact for a held
    command); a thruster whose ``held`` entry is not NaN (dead: 0 N, stuck: its force) gives
    that force whatever is commanded.

    Args:
        forces: (n,) actual forces [N], advanced in place.
        command: (n,) commanded forces [N].
        gain: (n,) command multipliers (1 healthy, the factor when degraded).
        held: (n,) the overriding force [N], NaN where none.
        blend: 1 − exp(−dt/τ), in [0, 1].
    """
    for i in range(forces.size):
        h = held[i]
        if h == h:
            forces[i] = h
        else:
            f = forces[i]
            forces[i] = f + (command[i] * gain[i] - f) * blend


@numba.njit(cache=True)
def interval_wrench(
    matrix: np.ndarray, start: np.ndarray, end: np.ndarray, weight: float
) -> tuple[float, float, float, float, float, float]:  # pragma: no cover - compiled
    """T @ (F0 + (F1 − F0)·c): the body wrench of the interval's mean forces [N, N·m], FRD.

    Args:
        matrix: (6, n) thruster configuration T [N, N·m per N].
        start, end: (n,) forces at the start and end of the interval [N].
        weight: c, the weight of the end forces in the mean (c = 0: the start forces).
    """
    x = y = z = k = m = nn = 0.0
    for i in range(start.size):
        f = start[i] + (end[i] - start[i]) * weight
        x += matrix[0, i] * f
        y += matrix[1, i] * f
        z += matrix[2, i] * f
        k += matrix[3, i] * f
        m += matrix[4, i] * f
        nn += matrix[5, i] * f
    return (x, y, z, k, m, nn)


# ------------------------------------------------------------------ component rows
#
# The frame's store-backed components (:mod:`testbed.ecs.store`): a kernel writes a row's fields
# and then, only when a field changed, the row's mark (``mark``, the row's (2,) view of its
# change tick and write count: the tick of the system that runs it, and one more write).


@numba.njit(cache=True)
def sum_rows(rows: np.ndarray, marks: np.ndarray, out: np.ndarray) -> None:  # pragma: no cover
    """Σ of the live rows (change tick ``marks[r, 0]`` > 0) of a (rows, 6) wrench table into
    ``out`` (6,), row by row from 0.0 in row order (the force intents' sum, [N, N·m], FRD)."""
    for j in range(6):
        out[j] = 0.0
    for r in range(rows.shape[0]):
        if marks[r, 0] > 0:
            for j in range(6):
                out[j] += rows[r, j]


@numba.njit(cache=True)
def put_wrench(
    row: np.ndarray,
    mark: np.ndarray,
    tick: int,
    x: float,
    y: float,
    z: float,
    k: float,
    m: float,
    n: float,
) -> None:  # pragma: no cover - compiled
    """A force intent's wrench row (X, Y, Z, K, M, N) [N, N·m], FRD; marked only when a
    value changed."""
    put_row(row, mark, tick, (x, y, z, k, m, n))


@numba.njit(cache=True)
def put_output(
    work: np.ndarray,
    scale: float,
    row: np.ndarray,
    mark: np.ndarray,
    tick: int,
    commanded: np.ndarray,
) -> None:  # pragma: no cover - compiled
    """A ThrusterOutput row (forces, PWM, currents, scale) from ``work``'s first three rows and
    ``scale`` (:func:`~.row_kernels.put_row`). ``commanded`` (n,) gets the forces."""
    n = work.shape[1]
    values = np.empty(3 * n + 1)
    for i in range(n):
        commanded[i] = work[FORCES, i]
    for k in range(3):
        for i in range(n):
            values[k * n + i] = work[k, i]
    values[3 * n] = scale
    put_row(row, mark, tick, values)


@numba.njit(cache=True)
def allocate_rows(
    intents: np.ndarray,
    intent_marks: np.ndarray,
    requested: np.ndarray,
    offset: np.ndarray,
    pinv: np.ndarray,
    limits: np.ndarray,
    work: np.ndarray,
    thrusters: np.ndarray,
    current_table: np.ndarray,
    pwm_table: np.ndarray,
    output: np.ndarray,
    output_mark: np.ndarray,
    tick: int,
    commanded: np.ndarray,
) -> float:  # pragma: no cover - compiled
    """The allocation of one frame on component rows: :func:`sum_rows` of the intents into
    ``requested``, :func:`allocate_pinv` of it with ``limits`` = (f_lo, f_hi, slew step, current
    cap, tolerance), and :func:`put_output` (with ``commanded``). Returns the scale, NaN for a
    sum that is not finite (nothing is written then)."""
    sum_rows(intents, intent_marks, requested)
    scale = allocate_pinv(
        requested,
        offset,
        pinv,
        limits[0],
        limits[1],
        limits[2],
        limits[3],
        limits[4],
        work,
        thrusters,
        current_table,
        pwm_table,
    )
    if scale == scale:
        put_output(work, scale, output, output_mark, tick, commanded)
    return scale


@numba.njit(cache=True)
def put_wrench_pair(
    matrix: np.ndarray,
    start: np.ndarray,
    end: np.ndarray,
    weight: float,
    requested: np.ndarray,
    row: np.ndarray,
    mark: np.ndarray,
    tick: int,
) -> tuple[float, float, float, float, float, float]:  # pragma: no cover - compiled
    """:func:`interval_wrench` of the interval, written with ``requested`` (6,) into an
    AppliedWrench row (requested, achieved); returns the achieved wrench [N, N·m], FRD."""
    w = interval_wrench(matrix, start, end, weight)
    r0, r1, r2, r3, r4, r5 = (
        requested[0],
        requested[1],
        requested[2],
        requested[3],
        requested[4],
        requested[5],
    )
    put_row(row, mark, tick, (r0, r1, r2, r3, r4, r5, w[0], w[1], w[2], w[3], w[4], w[5]))
    return w


@numba.njit(cache=True)
def actuate_rows(
    forces: np.ndarray,
    start: np.ndarray,
    command: np.ndarray,
    gain: np.ndarray,
    held: np.ndarray,
    blend: float,
    matrix: np.ndarray,
    weight: float,
    requested: np.ndarray,
    row: np.ndarray,
    mark: np.ndarray,
    tick: int,
    out: np.ndarray,
) -> None:  # pragma: no cover - compiled
    """One frame's interval of the thrusters: ``start`` ← ``forces``, :func:`lag_step` of
    ``forces`` in place (its arguments), then :func:`put_wrench_pair` of the interval (its
    arguments), its wrench [N, N·m], FRD, also written into ``out`` (6,)."""
    for i in range(forces.size):
        start[i] = forces[i]
    lag_step(forces, command, gain, held, blend)
    w = put_wrench_pair(matrix, start, forces, weight, requested, row, mark, tick)
    for i in range(6):
        out[i] = w[i]


jit.refresh_stale_caches((put_wrench, put_wrench_pair, allocate_rows, actuate_rows), (row_kernels,))
