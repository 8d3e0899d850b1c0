"""The navigation filter's prediction, delayed updates and replay, compiled (one call each).

:class:`~testbed.vehicle.estimation.KalmanNavigator` calls these kernels on its stored steps
(the arrays :mod:`.filter_history` lays out): a prediction stores a step
(:func:`predict_step`); a measurement's update (:func:`apply_measurement`) goes to the newest
step, or to the stored step at its time (or the interval its time splits, the next step's input
held over both parts), after which the following steps are predicted again and their stored
updates re-applied, without a second gate, in their order (:func:`filter_history.locate`'s
rules; the estimation module docstring). The arithmetic is :mod:`.filter_kernels`'
``propagate`` and ``gated_update``, called on the same operands in the same order as when this
bookkeeping was Python (the results are the same to the bit).

One thing stays in Python: a re-acquisition's covariance reset (the innovation's numpy product,
whose rounding a compiled loop need not repeat). A kernel that meets one stops and says so
(:data:`~.filter_history.NEEDS_RESET`); Python resets and resumes (:func:`stage_measurement`
and :func:`commit_reset` for a new measurement, :func:`resume_replay` for a stored one).
numpy and numba only.
"""

from __future__ import annotations

import numba
import numpy as np

from testbed.common import jit
from testbed.vehicle import filter_history, filter_kernels
from testbed.vehicle.filter_history import (
    ACCEPTED,
    APPLIED,
    END,
    FIRST,
    GATED,
    INVALID,
    INVALID_STATUS,
    NEEDS_RESET,
    RESUME_STEP,
    RESUME_UPDATE,
    ROLLBACKS,
    SINGULAR,
    SPLIT,
    STALE,
    STALE_STATUS,
    STEP_FIRST_UPDATE,
    STEP_HAS_INPUT,
    STEP_INPUT,
    STEP_P,
    STEP_TIME,
    STEP_UPDATES,
    STEP_WIDTH,
    STEP_X,
    TARGET,
    UPDATE_DIM,
    UPDATE_H,
    UPDATE_RESET,
    UPDATE_SIGMA,
    UPDATE_Z,
    FloatArray,
    Floats3,
    IntArray,
    add_update,
    drop_update,
    locate,
    make_record,
    make_room,
    propagate_row,
    publish,
    put_state,
)
from testbed.vehicle.filter_kernels import gated_update

__all__ = [
    "apply_measurement",
    "commit_reset",
    "predict_step",
    "resume_replay",
    "stage_measurement",
]


@numba.njit(cache=True)
def stage_measurement(
    steps: FloatArray,
    updates: FloatArray,
    cache: FloatArray,
    ledger: IntArray,
    time_s: float,
    scratch: FloatArray,
    q: float,
) -> int:  # pragma: no cover - compiled
    """Find the step a measurement at ``time_s`` [s] updates (ledger TARGET, SPLIT) and copy its
    prior into the step row ``scratch`` (x at :data:`STEP_X`, P at :data:`STEP_P`): the stored
    step, or the interval split at ``time_s`` (the next step's input held over both parts); for
    :func:`apply_measurement` and :func:`commit_reset`. Returns :data:`APPLIED` when staged, else
    :data:`STALE_STATUS` (counted), :data:`NEEDS_ROWS` or :data:`NEEDS_RECORDS`."""
    target, split = locate(steps, ledger, time_s)
    if target < 0:
        ledger[STALE] += 1
        return STALE_STATUS
    status = make_room(steps, updates, ledger, split)
    if status != APPLIED:
        return status
    target, split = locate(steps, ledger, time_s)  # the rows may have moved
    if split:
        after = steps[target]
        scratch[STEP_TIME] = time_s
        scratch[STEP_HAS_INPUT] = after[STEP_HAS_INPUT]
        scratch[STEP_UPDATES] = 0.0
        scratch[STEP_FIRST_UPDATE] = after[STEP_FIRST_UPDATE]
        for i in range(3):
            scratch[STEP_INPUT + i] = after[STEP_INPUT + i]
        propagate_row(steps[target - 1], scratch, cache, ledger, q)
    else:
        scratch[:] = steps[target, :]
    ledger[TARGET] = target
    ledger[SPLIT] = 1 if split else 0
    return APPLIED


@numba.njit(cache=True)
def _commit(
    steps: FloatArray,
    updates: FloatArray,
    cache: FloatArray,
    ledger: IntArray,
    newest: FloatArray,
    scratch: FloatArray,
    x: FloatArray,
    p: FloatArray,
    record: FloatArray,
    q: float,
) -> int:  # pragma: no cover - compiled
    """Store the staged step with posterior ``x``, ``p`` and its new update ``record``, then
    replay the steps after it (counted as a roll-back) to the newest."""
    target = ledger[TARGET]
    if ledger[SPLIT]:
        end = ledger[END]
        for k in range(end, target, -1):  # the later steps one row on
            steps[k, :] = steps[k - 1, :]
        ledger[END] = end + 1
        steps[target, :] = scratch
    row = steps[target]
    put_state(row, x, p)
    add_update(steps, updates, ledger, target, record)
    if target == ledger[END] - 1:
        publish(row, newest)
        return APPLIED
    ledger[ROLLBACKS] += 1
    propagate_row(row, steps[target + 1], cache, ledger, q)
    return _replay(steps, updates, cache, ledger, newest, target + 1, 0, q)


@numba.njit(cache=True)
def _reapply(
    steps: FloatArray,
    updates: FloatArray,
    ledger: IntArray,
    j: int,
    u: int,
    prior_p: FloatArray,
) -> bool:  # pragma: no cover - compiled
    """Re-apply step ``j``'s stored update ``u`` to its x and ``prior_p`` without the gate;
    one that cannot be applied now (a singular S) is counted invalid and removed."""
    row = steps[j]
    record = updates[int(row[STEP_FIRST_UPDATE]) + u]
    dim = int(record[UPDATE_DIM])
    h = record[UPDATE_H : UPDATE_H + 6 * dim].reshape((dim, 6))
    z = record[UPDATE_Z : UPDATE_Z + dim]
    sigma = record[UPDATE_SIGMA : UPDATE_SIGMA + dim]
    x, p, _, status = gated_update(row[STEP_X : STEP_X + 6], prior_p, h, z, sigma, np.inf)
    if status == APPLIED:
        put_state(row, x, p)
        return True
    ledger[INVALID] += 1
    drop_update(steps, updates, ledger, j, u)
    return False


@numba.njit(cache=True)
def _replay(
    steps: FloatArray,
    updates: FloatArray,
    cache: FloatArray,
    ledger: IntArray,
    newest: FloatArray,
    j: int,
    u: int,
    q: float,
) -> int:  # pragma: no cover - compiled
    """Re-apply step ``j``'s stored updates from ``u`` on (its prediction done), then predict
    each later step and re-apply its updates; publish the newest. Stops at a stored
    re-acquisition (ledger RESUME_STEP, RESUME_UPDATE; :data:`NEEDS_RESET`), else returns
    :data:`APPLIED`."""
    end = ledger[END]
    while True:
        row = steps[j]
        while u < row[STEP_UPDATES]:
            if updates[int(row[STEP_FIRST_UPDATE]) + u, UPDATE_RESET] != 0.0:
                ledger[RESUME_STEP] = j
                ledger[RESUME_UPDATE] = u
                return NEEDS_RESET
            if _reapply(steps, updates, ledger, j, u, row[STEP_P : STEP_P + 36].reshape((6, 6))):
                u += 1
        j += 1
        if j >= end:
            break
        propagate_row(row, steps[j], cache, ledger, q)
        u = 0
    publish(steps[end - 1], newest)
    return APPLIED


@numba.njit(cache=True)
def predict_step(
    steps: FloatArray,
    updates: FloatArray,
    cache: FloatArray,
    ledger: IntArray,
    newest: FloatArray,
    time_s: float,
    hold_input: bool,
    has_input: bool,
    accel: Floats3,
    q: float,
    history_s: float,
) -> int:  # pragma: no cover - compiled
    """Store a step at ``time_s`` [s] (after the newest) predicted with the NED acceleration
    ``accel`` [m/s²] when ``has_input`` (``hold_input``: with the newest step's input instead),
    drop the steps that ended more than ``history_s`` [s] before it, publish it. Returns
    :data:`APPLIED`, :data:`NEEDS_ROWS` or :data:`NEEDS_RECORDS`."""
    status = make_room(steps, updates, ledger, True)
    if status != APPLIED:
        return status
    end = ledger[END]
    before, after = steps[end - 1], steps[end]
    after[STEP_TIME] = time_s
    after[STEP_UPDATES] = 0.0
    after[STEP_FIRST_UPDATE] = before[STEP_FIRST_UPDATE] + before[STEP_UPDATES]
    if hold_input:
        after[STEP_HAS_INPUT] = before[STEP_HAS_INPUT]
        for i in range(3):
            after[STEP_INPUT + i] = before[STEP_INPUT + i]
    else:
        after[STEP_HAS_INPUT] = 1.0 if has_input else 0.0
        for i in range(3):
            after[STEP_INPUT + i] = accel[i]
    propagate_row(before, after, cache, ledger, q)
    ledger[END] = end + 1
    horizon = time_s - history_s  # keep the last step at or before it
    first = ledger[FIRST]
    while first < end and steps[first + 1, STEP_TIME] <= horizon:
        first += 1
    ledger[FIRST] = first
    publish(after, newest)
    return APPLIED


@numba.njit(cache=True)
def apply_measurement(
    steps: FloatArray,
    updates: FloatArray,
    cache: FloatArray,
    ledger: IntArray,
    newest: FloatArray,
    time_s: float,
    kind: int,
    h: FloatArray,
    value: Floats3,
    sigma: Floats3,
    gate: float,
    q: float,
) -> int:  # pragma: no cover - compiled
    """Apply a measurement valid at ``time_s`` [s] (not after the newest step) with the gate
    ``gate`` on its normalised innovation: to the newest step, or to the stored step at its time
    (or the interval it splits) and then replayed to the newest.

    Args:
        kind: the measurement's kind, a code kept with the update.
        h: (dim, 6) H; dim is the measurement's.
        value, sigma: z and its 1σ, the first ``dim`` components used.

    Returns:
        :data:`APPLIED` (counted accepted, and a roll-back when not at the newest step),
        :data:`GATED` (nothing counted: the caller decides), :data:`SINGULAR`,
        :data:`INVALID_STATUS` (both counted invalid), :data:`STALE_STATUS` (counted),
        :data:`NEEDS_RESET` (applied and counted; a replay stopped) or :data:`NEEDS_ROWS` /
        :data:`NEEDS_RECORDS` (nothing done).
    """
    dim = h.shape[0]
    finite = np.isfinite(time_s)
    for i in range(dim):
        finite = finite and np.isfinite(value[i]) and np.isfinite(sigma[i]) and sigma[i] > 0.0
    if not finite:
        ledger[INVALID] += 1
        return INVALID_STATUS
    scratch = np.empty(STEP_WIDTH)
    status = stage_measurement(steps, updates, cache, ledger, time_s, scratch, q)
    if status != APPLIED:
        return status
    record, z, s = make_record(kind, False, h, value, sigma)
    p = scratch[STEP_P : STEP_P + 36].reshape((6, 6))
    x, p, _, status = gated_update(scratch[STEP_X : STEP_X + 6], p, h, z, s, gate)
    if status == GATED:
        return GATED
    if status == SINGULAR:
        ledger[INVALID] += 1
        return SINGULAR
    ledger[ACCEPTED] += 1
    return _commit(steps, updates, cache, ledger, newest, scratch, x, p, record, q)


@numba.njit(cache=True)
def commit_reset(
    steps: FloatArray,
    updates: FloatArray,
    cache: FloatArray,
    ledger: IntArray,
    newest: FloatArray,
    scratch: FloatArray,
    kind: int,
    h: FloatArray,
    value: Floats3,
    sigma: Floats3,
    reset_p: FloatArray,
    q: float,
) -> int:  # pragma: no cover - compiled
    """Apply a re-acquiring measurement (no gate) to the prior :func:`stage_measurement` left
    in ``scratch``, with ``reset_p`` for its P; store it (marked a re-acquisition) and replay.
    Returns :data:`APPLIED` (a roll-back counted when not at the newest step),
    :data:`SINGULAR` (counted invalid, nothing stored) or :data:`NEEDS_RESET`."""
    record, z, s = make_record(kind, True, h, value, sigma)
    x, p, _, status = gated_update(scratch[STEP_X : STEP_X + 6], reset_p, h, z, s, np.inf)
    if status != APPLIED:
        ledger[INVALID] += 1
        return SINGULAR
    return _commit(steps, updates, cache, ledger, newest, scratch, x, p, record, q)


@numba.njit(cache=True)
def resume_replay(
    steps: FloatArray,
    updates: FloatArray,
    cache: FloatArray,
    ledger: IntArray,
    newest: FloatArray,
    reset_p: FloatArray,
    q: float,
) -> int:  # pragma: no cover - compiled
    """Re-apply the stored re-acquisition a replay stopped at (ledger RESUME_STEP,
    RESUME_UPDATE) with ``reset_p`` for its prior P, and go on replaying. Returns
    :data:`APPLIED` or :data:`NEEDS_RESET` (stopped at the next one)."""
    j, u = ledger[RESUME_STEP], ledger[RESUME_UPDATE]
    if _reapply(steps, updates, ledger, j, u, reset_p):
        u += 1
    return _replay(steps, updates, cache, ledger, newest, j, u, q)


jit.refresh_stale_caches(
    (predict_step, apply_measurement, stage_measurement, commit_reset, resume_replay),
    (filter_history, filter_kernels),
)
