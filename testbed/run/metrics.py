"""Run metrics: pure functions from recorded series to the numbers in ``metrics.json``.

Nothing here simulates; the runner records, these functions reduce. Every function takes plain
sequences or arrays and returns floats or small dicts of floats, so each can be checked against
closed forms on hand-made inputs (tests/test_metrics.py).

Age of information. A receiver that holds the latest update it applied, where update ``i`` was
*sampled* at ``s_i`` and *applied* at ``a_i`` (``a_i ≥ s_i``, increasing), holds at time ``t``
information of age ``Δ(t) = t − s_k`` with ``k`` the last update applied by ``t``. Its time
average over ``[t0, t1]`` is ``(1/(t1 − t0)) ∫ Δ(t) dt``, computed exactly: on each interval
between applications the age grows linearly, so each contributes a trapezoid.

For periodic updates every ``T`` seconds, each delivered independently with probability ``q``,
and applied a delay ``D`` after sampling (``D`` = latency + the wait for the receiver's tick),
the intervals between applications are ``K·T`` with ``K`` geometric, ``P(K = k) = q(1 − q)^(k−1)``,
``E[K] = 1/q`` and ``E[K²] = (2 − q)/q²``. The age at an application is ``D``; over the following
interval it grows linearly, so by the renewal-reward theorem

    E[Δ] = E[D] + E[(K·T)²] / (2·E[K·T]) = E[D] + T·(2 − q) / (2·q).

With no loss (``q = 1``) this is ``D + T/2``.

Mission metrics (vehicles under autonomy). The position error is the distance
``e(t) = |p(t) − p*(t)|`` between the true body-origin position and the pose target the mission
tree set (:func:`position_error`); :func:`error_statistics` reduces it to Angler's figures (mean
and spread, and the error at the end of the run, its "final error"), and
:func:`time_to_converge_s` gives the first instant after which it stays within the goal
tolerance to the end. A trajectory-following vehicle rides along with its moving target and is
within tolerance from the start, so convergence is counted from when the target arrives at its
final value (:func:`final_target_s`: the last waypoint's time, a GoTo leg's end):
:func:`settling_time_s` is the time from then until the error stays within tolerance.
"""

from __future__ import annotations

import math
from array import array
from collections.abc import Mapping, Sequence

import numpy as np

__all__ = [
    "SIGNAL_LAG_WINDOW_S",
    "age_of_information",
    "distribution",
    "error_statistics",
    "final_target_s",
    "mean_ci95",
    "mean_ci95_half_width",
    "position_error",
    "settling_time_s",
    "signal_lag_s",
    "summary",
    "time_to_converge_s",
    "tracked_positions",
    "yaw_error_deg",
]


def summary(values: Sequence[float]) -> dict[str, float]:
    """``{mean, p50, p95, max, n}`` of ``values`` (NaN statistics and n 0 when empty)."""
    if len(values) == 0:
        nan = math.nan
        return {"mean": nan, "p50": nan, "p95": nan, "max": nan, "n": 0}
    array = np.asarray(values, dtype=float)
    return {
        "mean": float(array.mean()),
        "p50": float(np.percentile(array, 50)),
        "p95": float(np.percentile(array, 95)),
        "max": float(array.max()),
        "n": int(array.size),
    }


def distribution(values: Sequence[float]) -> dict[str, float]:
    """``{mean, std, p95}`` of ``values``; p95 of the absolute value (an error bound)."""
    if len(values) == 0:
        return {"mean": math.nan, "std": math.nan, "p95": math.nan}
    array = np.asarray(values, dtype=float)
    return {
        "mean": float(array.mean()),
        "std": float(array.std()),
        "p95": float(np.percentile(np.abs(array), 95)),
    }


def mean_ci95_half_width(values: Sequence[float] | np.ndarray) -> float:
    """Half-width of the 95 % Student-t confidence interval of the mean of ``values``.

    ``t(0.975, n − 1) · s / √n`` with ``s`` the sample standard deviation (``ddof = 1``): the
    interval is ``mean ± half-width``.

    Args:
        values: the samples (in the unit of the result).

    Returns:
        The half-width, in the unit of ``values``; NaN with fewer than two values.
    """
    from scipy import stats  # scipy only when intervals are asked for

    array = np.asarray(values, dtype=float)
    n = array.size
    if n < 2:
        return math.nan
    return float(stats.t.ppf(0.975, n - 1)) * float(array.std(ddof=1)) / math.sqrt(n)


def mean_ci95(
    values: Sequence[float] | np.ndarray, bounds: tuple[float, float] | None = None
) -> tuple[float, float]:
    """The 95 % Student-t confidence interval of the mean of ``values``, within ``bounds``.

    ``mean ± t(0.975, n − 1) · s / √n`` (:func:`mean_ci95_half_width`), clipped to ``bounds``
    when given: the mean of a bounded quantity (a probability: ``(0, 1)``) lies within its
    bounds, so the part of the interval outside them holds no possible value. Clipping keeps
    the coverage (the true mean is inside the clipped interval whenever it is inside the
    unclipped one) and removes the impossible values a t interval reaches with few seeds (two
    runs with PER 0.02 and 0.12 give −0.565…0.705).

    Args:
        values: the samples.
        bounds: ``(low, high)`` the quantity cannot leave, or None.

    Returns:
        ``(low, high)``, in the unit of ``values``; NaNs with fewer than two values.
    """
    array = np.asarray(values, dtype=float)
    half = mean_ci95_half_width(array)
    if math.isnan(half):
        return math.nan, math.nan
    mean = float(array.mean())
    low, high = mean - half, mean + half
    if bounds is not None:
        low, high = max(low, bounds[0]), min(high, bounds[1])
    return low, high


def age_of_information(
    updates: Sequence[tuple[float, float]], t0_s: float, t1_s: float, grid_s: float = 0.01
) -> dict[str, float]:
    """Time-average and 95th percentile of the age of the information a receiver holds.

    Args:
        updates: ``(applied_s, sampled_s)`` of each update the receiver applied, in application
            order; an update sampled earlier than the one held is ignored (it does not make
            the held information newer).
        t0_s: start of the window [s]; the update held then is the last applied at or before it.
        t1_s: end of the window [s], > ``t0_s``.
        grid_s: step of the uniform grid the 95th percentile is read on [s].

    Returns:
        ``{"mean", "p95"}`` [s]; ``inf`` for both if nothing was held at ``t0_s`` and nothing
        arrived (the mean covers only the time something was held otherwise).
    """
    if t1_s <= t0_s:
        raise ValueError(f"empty window [{t0_s}, {t1_s}]")
    # (from_s, sampled_s) segments, newest sample wins; flat float arrays (16 B a segment)
    starts: array[float] = array("d")
    samples: array[float] = array("d")
    newest = -math.inf
    for applied_s, sampled_s in updates:
        if sampled_s <= newest:
            continue
        newest = sampled_s
        start = max(applied_s, t0_s)
        if starts and start <= starts[-1]:
            samples[-1] = sampled_s  # several updates at once: the newest counts
        elif start < t1_s or not starts or applied_s <= t0_s:
            starts.append(start)
            samples.append(sampled_s)
    keep = np.frombuffer(starts, dtype=np.float64) < t1_s
    begin = np.frombuffer(starts, dtype=np.float64)[keep]
    sample_times = np.frombuffer(samples, dtype=np.float64)[keep]
    del starts, samples
    if not begin.size:
        return {"mean": math.inf, "p95": math.inf}
    end = np.append(begin[1:], t1_s)
    area = 0.0
    for k in range(0, begin.size, 4096):  # in Python floats, a chunk at a time
        chunk = zip(
            begin[k : k + 4096].tolist(),
            end[k : k + 4096].tolist(),
            sample_times[k : k + 4096].tolist(),
            strict=True,
        )
        for start, stop, sampled_s in chunk:
            area += 0.5 * ((stop - sampled_s) ** 2 - (start - sampled_s) ** 2)
    covered = t1_s - float(begin[0])
    grid = np.arange(float(begin[0]), t1_s, grid_s)
    index = np.searchsorted(begin, grid, side="right") - 1
    ages = grid - sample_times[index]
    return {"mean": area / covered, "p95": float(np.percentile(ages, 95))}


SIGNAL_LAG_WINDOW_S = 5.0
"""Default upper end of :func:`signal_lag_s`'s search [s]."""


def signal_lag_s(
    t_s: Sequence[float] | np.ndarray,
    commanded: Sequence[float] | np.ndarray,
    received: Sequence[float] | np.ndarray,
    max_lag_s: float = SIGNAL_LAG_WINDOW_S,
    valid: Sequence[bool] | np.ndarray | None = None,
) -> float:
    """The delay that best aligns ``received`` with ``commanded`` (cross-correlation) [s].

    Both signals are sampled at the same increasing times ``t_s``, not necessarily uniform
    (vehicle frames land 2 or 3 physics steps apart); they are first resampled by linear
    interpolation onto a uniform grid with the mean spacing ``dt``. The normalised
    cross-correlation of the mean-removed signals is computed for shifts of ``−dt`` to
    ``max_lag_s`` on that grid; its peak is refined by a parabola through the peak and its two
    neighbours, at zero shift too (hence the one negative shift), so a lag below the sampling
    step is measured, not rounded to 0 or ``dt``. A peak at either end of the search (at
    ``−dt``, the received signal leading, or at ``max_lag_s``, the true lag possibly beyond it)
    is no measurement: NaN.

    ``valid`` marks the received samples that are the link's: where it is false (a failsafe
    holding the sticks centred, the vehicle disarmed) the received value says nothing of the
    delay, and those samples (and the grid points next to them) take no part in the means or
    in any shift's correlation.

    Args:
        t_s: (n,) sample times [s], increasing.
        commanded: (n,) the pilot's signal.
        received: (n,) the signal the vehicle applied, same units.
        max_lag_s: upper end of the search [s] (capped at the series' length).
        valid: (n,) which received samples count; None = all.

    Returns:
        The lag [s], within ``(−dt/2, max_lag_s)``; NaN when either signal is constant (nothing
        to align), when fewer than 3 samples, or when the peak is at an end of the search.
    """
    t = np.asarray(t_s, dtype=float)
    a = np.asarray(commanded, dtype=float)
    b = np.asarray(received, dtype=float)
    if t.size < 3:
        return math.nan
    dt = float(t[-1] - t[0]) / (t.size - 1)
    grid = t[0] + dt * np.arange(t.size)
    a = np.interp(grid, t, a)
    b = np.interp(grid, t, b)
    if valid is None:
        mask = np.ones(t.size, dtype=bool)
    else:  # a grid point counts only between two valid samples
        mask = np.interp(grid, t, np.asarray(valid, dtype=float)) >= 1.0
    if mask.sum() < 3:
        return math.nan
    a = a - a[mask].mean()
    b = np.where(mask, b - b[mask].mean(), 0.0)
    if not a.any() or not b.any():
        return math.nan
    max_shift = min(round(max_lag_s / dt), t.size - 2)
    shifts = range(-1, max_shift + 1)
    scores = np.array([_correlation(a, b, mask, shift) for shift in shifts])
    k = int(np.argmax(scores))
    if not 0 < k < scores.size - 1:
        return math.nan  # the peak is at an end of the search window
    left, mid, right = scores[k - 1], scores[k], scores[k + 1]
    curvature = left - 2.0 * mid + right
    offset = 0.5 * (left - right) / curvature if -math.inf < curvature < 0.0 else 0.0
    return (shifts[k] + offset) * dt


def _correlation(a: np.ndarray, b: np.ndarray, mask: np.ndarray, shift: int) -> float:
    """Normalised correlation of ``a`` with ``b`` delayed by ``shift`` samples (any sign), over
    the pairs whose ``b`` sample is in ``mask`` (``b`` is 0 elsewhere)."""
    if shift >= 0:
        x, y, m = a[: a.size - shift], b[shift:], mask[shift:]
    else:
        x, y, m = a[-shift:], b[: b.size + shift], mask[: mask.size + shift]
    x = np.where(m, x, 0.0)
    denom = math.sqrt(float(x @ x) * float(y @ y))
    return float(x @ y) / denom if denom > 0.0 else -math.inf


def position_error(
    truth: Sequence[Sequence[float]] | np.ndarray, target: Sequence[Sequence[float]] | np.ndarray
) -> np.ndarray:
    """The distance between two position tracks, row by row.

    Args:
        truth: (n, 3) positions [m], NED.
        target: (n, 3) positions [m], same frame.

    Returns:
        (n,) Euclidean distances [m]; NaN where either row has a NaN.
    """
    a = np.asarray(truth, dtype=float).reshape(-1, 3)
    b = np.asarray(target, dtype=float).reshape(-1, 3)
    if a.shape != b.shape:
        raise ValueError(f"position tracks of different lengths: {len(a)} and {len(b)}")
    distance: np.ndarray = np.sqrt(np.sum((a - b) ** 2, axis=1))
    return distance


def tracked_positions(
    series: Mapping[str, np.ndarray],
) -> tuple[np.ndarray, np.ndarray, bool]:
    """What a mission flies, row by row, and its target, world NED: the body origin and the
    pose target (``north_m``…, ``target_*``); or, when some row has an end-effector target
    (``ee_target_*``), the end effector (``ee_*``) and that target (NaN on the rows without
    one, e.g. the station held before the mission started).

    Returns:
        ``(truth, target, reaching)``: (n, 3) positions [m] each (NaN where there is no
        target), and whether the end effector is what is flown.
    """
    truth = np.column_stack([series["north_m"], series["east_m"], series["down_m"]])
    target = np.column_stack([series["target_n"], series["target_e"], series["target_d"]])
    if "ee_target_n" not in series:  # a series from before the arm
        return truth.astype(float), target.astype(float), False
    reach = np.column_stack([series[f"ee_target_{k}"] for k in "ned"]).astype(float)
    rows = np.isfinite(reach).all(axis=1)
    if not rows.any():
        return truth.astype(float), target.astype(float), False
    ee = np.column_stack([series[f"ee_{k}"] for k in "ned"]).astype(float)
    return ee, reach, True


def error_statistics(error: Sequence[float] | np.ndarray) -> dict[str, float]:
    """``{mean, std, p95, final}`` of an error track (NaN entries left out).

    ``std`` is the population standard deviation (``ddof = 0``, as :func:`distribution`);
    ``final`` is the last finite entry (Angler's "final error": where the run ended up).

    Args:
        error: (n,) error values in time order (e.g. :func:`position_error` [m]).

    Returns:
        The four statistics, NaN each when no entry is finite.
    """
    values = np.asarray(error, dtype=float)
    values = values[np.isfinite(values)]
    if values.size == 0:
        return {"mean": math.nan, "std": math.nan, "p95": math.nan, "final": math.nan}
    return {
        "mean": float(values.mean()),
        "std": float(values.std()),
        "p95": float(np.percentile(values, 95)),
        "final": float(values[-1]),
    }


def time_to_converge_s(
    t_s: Sequence[float] | np.ndarray, error: Sequence[float] | np.ndarray, tolerance: float
) -> float:
    """The first time after which ``error`` stays below ``tolerance`` up to the last sample.

    That is the time of the first sample of the final unbroken run of samples with
    ``error < tolerance``; a NaN sample counts as not within tolerance (it breaks the run).

    Args:
        t_s: (n,) sample times [s], increasing.
        error: (n,) the error at those times.
        tolerance: the bound (in the unit of ``error``).

    Returns:
        That time [s]; NaN if the last sample is not within tolerance (or there is none).
    """
    t = np.asarray(t_s, dtype=float)
    e = np.asarray(error, dtype=float)
    if t.shape != e.shape:
        raise ValueError(f"{t.size} times for {e.size} error samples")
    within = e < tolerance  # NaN compares False
    if within.size == 0 or not within[-1]:
        return math.nan
    outside = np.flatnonzero(~within)
    first = int(outside[-1]) + 1 if outside.size else 0
    return float(t[first])


def final_target_s(
    t_s: Sequence[float] | np.ndarray,
    target: Sequence[Sequence[float]] | np.ndarray,
    atol_m: float = 1e-6,
) -> float:
    """When a target track arrived at its final value: the time of the first sample from which
    every later sample is within ``atol_m`` of the last one (per coordinate).

    For a mission this is the last waypoint's time (the trajectory's end, after which the tree
    holds that pose); for a GoTo, the end of its leg.

    Args:
        t_s: (n,) sample times [s], increasing.
        target: (n, 3) target positions [m], NED, or (n, 4) with the target yaw [deg] last (a
            waypoint that only turns the vehicle moves the target too); a row with a NaN
            counts as different.
        atol_m: how far a coordinate may differ and still be the final value [m, or deg].

    Returns:
        That time [s]; NaN without samples, when the last one has no target, or when the
        target still moved between the last two (a run that ended mid-trajectory).
    """
    t = np.asarray(t_s, dtype=float)
    p = np.asarray(target, dtype=float)
    p = p.reshape(-1, p.shape[-1] if p.ndim > 1 else 3)
    if t.size != len(p):
        raise ValueError(f"{t.size} times for {len(p)} target samples")
    if t.size == 0 or not np.isfinite(p[-1]).all():
        return math.nan
    same = (np.abs(p - p[-1]) <= atol_m).all(axis=1)  # NaN compares False
    moved = np.flatnonzero(~same)
    if moved.size and moved[-1] == t.size - 2:  # still moving at the end: it never arrived
        return math.nan
    return float(t[int(moved[-1]) + 1 if moved.size else 0])


def settling_time_s(
    t_s: Sequence[float] | np.ndarray,
    truth: Sequence[Sequence[float]] | np.ndarray,
    target: Sequence[Sequence[float]] | np.ndarray,
    tolerance_m: float,
    target_yaw_deg: Sequence[float] | np.ndarray | None = None,
) -> tuple[float, float]:
    """How long after the target arrived at its final value the position error settled.

    ``arrival`` = :func:`final_target_s` of ``target`` (with ``target_yaw_deg`` when it is
    given and its last value is finite: a last waypoint that only turns the vehicle arrives
    when the turn ends); on the samples from then on, the
    error to that (final) target is :func:`position_error`, and the settling time is
    :func:`time_to_converge_s` of it minus ``arrival``: 0 when the vehicle arrived with its
    target and stayed within tolerance, NaN when it ended outside.

    Args:
        t_s: (n,) sample times [s], increasing.
        truth: (n, 3) positions flown [m], NED.
        target: (n, 3) their targets [m], NED.
        tolerance_m: the goal tolerance [m].
        target_yaw_deg: (n,) the target yaw [deg], or None.

    Returns:
        ``(settling [s], arrival [s])``; both NaN when there is no final target.
    """
    t = np.asarray(t_s, dtype=float)
    track = np.asarray(target, dtype=float).reshape(-1, 3)
    if target_yaw_deg is not None:
        yaw = np.asarray(target_yaw_deg, dtype=float)
        if yaw.size and math.isfinite(yaw[-1]):
            track = np.column_stack([track, yaw])
    arrival = final_target_s(t, track)
    if math.isnan(arrival):
        return math.nan, math.nan
    rows = t >= arrival
    error = position_error(
        np.asarray(truth, dtype=float)[rows], np.asarray(target, dtype=float)[rows]
    )
    return time_to_converge_s(t[rows], error, tolerance_m) - arrival, arrival


def yaw_error_deg(
    yaw_deg: Sequence[float] | np.ndarray, target_yaw_deg: Sequence[float] | np.ndarray
) -> np.ndarray:
    """The absolute heading error, wrapped: ``|wrap(ψ − ψ*)|`` row by row [deg], in [0, 180].

    Args:
        yaw_deg: (n,) true heading [deg, clockwise from north].
        target_yaw_deg: (n,) target heading [deg], same convention.

    Returns:
        (n,) the shorter way round between them [deg]; NaN where either is NaN.
    """
    difference = np.asarray(yaw_deg, dtype=float) - np.asarray(target_yaw_deg, dtype=float)
    wrapped: np.ndarray = np.abs((difference + 180.0) % 360.0 - 180.0)
    return wrapped
