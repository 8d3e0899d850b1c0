"""The navigation filter's stored steps, compiled: prediction, delayed updates, replay.

:class:`~testbed.vehicle.estimation.KalmanNavigator` keeps the steps its predictions store (its
module docstring: time, input, accepted updates, x, P) in float64 arrays it owns, and these
kernels do a prediction, a measurement's update at its own time (rolling back and replaying when
it is older than the newest step) and the replay, each in one call from Python, writing into
those arrays. The arithmetic is :mod:`.filter_kernels`' ``propagate`` and ``gated_update``,
called as the Python filter called them; this module adds the bookkeeping around them and the
model's F, G, Q, cached by time step (:func:`transition_slot`).

One thing stays in Python: a re-acquisition's covariance reset (the innovation's numpy
product, whose rounding a compiled loop need not repeat). A kernel that meets one stops and says
so (:data:`NEEDS_RESET`), and Python resets and resumes it (:func:`commit_reset`,
:func:`resume_replay`).

Layouts (float64 unless said; the constants below name the columns):

* ``steps`` (rows, :data:`STEP_WIDTH`): a stored step per row, oldest first; the live rows are
  ``ledger[FIRST]`` to ``ledger[END]`` (exclusive). Time [s], whether the step has an input
  (1.0 or 0.0), how many updates it holds and the row of ``updates`` holding the first, the
  input (3,) NED acceleration [m/s²], x (6,) NED position [m] and velocity [m/s], P (36,)
  row-major.
* ``updates`` (records, :data:`UPDATE_WIDTH`): the accepted updates of the live steps, a
  record per row, in the steps' order and each step's in the order applied (so a step's are
  consecutive rows, and an update added to an older step moves the later ones on): the
  measurement's kind (the caller's code), whether it re-acquired (1.0 or 0.0), ``dim z`` (1 or
  3), H (dim × 6, row-major), z (dim,), σ (dim,).
* ``cache`` (:data:`CACHE_SLOTS`, :data:`CACHE_WIDTH`): F (6 × 6), G (6 × 3) and Q (6 × 6),
  row-major, of each cached time step.
* ``ledger`` (:data:`LEDGER_SIZE`,) int64: the live steps' rows, where a staged measurement
  goes, where a replay stopped, the filter's six counters (``FilterCounters``' order, from
  :data:`ACCEPTED`) and the cache's fill and keys.
* ``newest`` (:data:`NEWEST_WIDTH`,): the newest step's x, the 1σ of its components and P
  (row-major).

A kernel that needs a free row after the last live one (of ``steps`` or ``updates``) when there
is none moves the live rows to the front if at least half the rows are free; otherwise it
returns :data:`NEEDS_ROWS` (or :data:`NEEDS_RECORDS`) having changed nothing but the cache, and
the caller grows the arrays (:func:`grown`) and calls again. numpy and numba only.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

from testbed.common import jit
from testbed.vehicle import filter_kernels
from testbed.vehicle.filter_kernels import APPLIED, GATED, SINGULAR, gated_update, propagate

__all__ = [
    "ACCEPTED",
    "APPLIED",
    "CACHE_SLOTS",
    "CACHE_WIDTH",
    "END",
    "FIRST",
    "GATED",
    "INVALID",
    "INVALID_STATUS",
    "LEDGER_SIZE",
    "NEEDS_RECORDS",
    "NEEDS_RESET",
    "NEEDS_ROWS",
    "NEWEST_P",
    "NEWEST_WIDTH",
    "REACQUIRED",
    "REJECTED",
    "RESUME_STEP",
    "RESUME_UPDATE",
    "SINGULAR",
    "STALE",
    "STALE_STATUS",
    "STEP_FIRST_UPDATE",
    "STEP_P",
    "STEP_TIME",
    "STEP_UPDATES",
    "STEP_WIDTH",
    "STEP_X",
    "TIME_EPS_S",
    "UPDATE_DIM",
    "UPDATE_H",
    "UPDATE_KIND",
    "UPDATE_RESET",
    "UPDATE_WIDTH",
    "UPDATE_Z",
    "apply_measurement",
    "commit_reset",
    "grown",
    "predict_step",
    "publish",
    "resume_replay",
    "stage_measurement",
    "transition_slot",
]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
Floats3 = tuple[float, ...]
"""Three floats (numba: a UniTuple of three float64)."""

TIME_EPS_S = 1e-9
"""Times closer than this [s] are the same instant."""

# steps: columns
STEP_TIME = 0
STEP_HAS_INPUT = 1
STEP_UPDATES = 2
STEP_FIRST_UPDATE = 3
STEP_INPUT = 4
STEP_X = 7
STEP_P = 13
STEP_WIDTH = 49

# updates: columns of a record
UPDATE_KIND = 0
UPDATE_RESET = 1
UPDATE_DIM = 2
UPDATE_H = 3
UPDATE_Z = 21
UPDATE_SIGMA = 24
UPDATE_WIDTH = 27

# cache: columns of a slot
CACHE_F = 0
CACHE_G = 36
CACHE_Q = 54
CACHE_WIDTH = 90
CACHE_SLOTS = 16
"""Time steps whose F, G, Q are kept: frames land a few physics steps apart, so a handful."""

# ledger: entries
FIRST = 0
"""Row of the oldest live step."""
END = 1
"""One past the row of the newest step."""
TARGET = 2
"""Row of the step a staged measurement updates (inserted there when :data:`SPLIT`)."""
SPLIT = 3
"""1: the staged measurement splits an interval, its step is inserted at :data:`TARGET`."""
RESUME_STEP = 4
"""Row of the step whose stored re-acquisition a replay stopped at (:data:`NEEDS_RESET`)."""
RESUME_UPDATE = 5
"""Its index among that step's updates."""
ACCEPTED = 6
"""First of the six counters, in ``FilterCounters``' order."""
REJECTED = 7
INVALID = 8
STALE = 9
ROLLBACKS = 10
REACQUIRED = 11
CACHED = 12
"""How many cache slots are filled."""
CACHE_KEYS = 13
"""First of the cached time steps' keys (the step in whole nanoseconds)."""
LEDGER_SIZE = CACHE_KEYS + CACHE_SLOTS

# newest: entries
NEWEST_X = 0
NEWEST_SIGMA = 6
"""The 1σ of each component of x: √max(Pᵢᵢ, 0)."""
NEWEST_P = 12
NEWEST_WIDTH = 48

# statuses (APPLIED, GATED and SINGULAR are gated_update's)
STALE_STATUS = 3
"""The measurement is older than the history: dropped."""
INVALID_STATUS = 4
"""The measurement's time, a value or a σ is not finite, or a σ ≤ 0: dropped."""
NEEDS_RESET = 5
"""The measurement was applied, but a replay met a stored re-acquisition: reset and resume."""
NEEDS_ROWS = 6
"""No free row in ``steps``: grow it and call again (the largest statuses ask for room)."""
NEEDS_RECORDS = 7
"""No free row in ``updates``: grow it and call again."""


@numba.njit(cache=True)
def transition_slot(
    cache: FloatArray, ledger: IntArray, dt: float, q: float
) -> int:  # pragma: no cover - compiled
    """The cache slot of F, G, Q over ``dt`` [s] for white acceleration of density ``q``
    [m²/s³], filled if missing (the cache emptied first when full).

    Keyed by ``dt`` rounded to whole nanoseconds (frames' steps jitter by an ulp), so a slot
    keeps the matrices of the first ``dt`` that filled it. The entries are the estimation module
    docstring's, rounded as Python rounds ``q * dt**3 / 3.0`` and the like: ``math.pow`` here is
    the C library's ``pow``, which Python's ``**`` calls (numba's ``**`` with an integer
    exponent would multiply instead).
    """
    key = int(np.rint(dt * 1e9))  # as round(): half to even
    cached = ledger[CACHED]
    for slot in range(cached):
        if ledger[CACHE_KEYS + slot] == key:
            return slot
    slot = cached if cached < CACHE_SLOTS else 0
    row = cache[slot]
    row[:] = 0.0
    position_input = 0.5 * dt * dt
    position_noise = q * math.pow(dt, 3.0) / 3.0
    cross_noise = q * dt * dt / 2.0
    velocity_noise = q * dt
    for i in range(6):
        row[CACHE_F + 7 * i] = 1.0
    for i in range(3):
        row[CACHE_F + 6 * i + i + 3] = dt
        row[CACHE_G + 3 * i + i] = position_input
        row[CACHE_G + 3 * (i + 3) + i] = dt
        row[CACHE_Q + 7 * i] = position_noise
        row[CACHE_Q + 6 * i + i + 3] = cross_noise
        row[CACHE_Q + 6 * (i + 3) + i] = cross_noise
        row[CACHE_Q + 7 * (i + 3)] = velocity_noise
    ledger[CACHE_KEYS + slot] = key
    ledger[CACHED] = slot + 1
    return slot


@numba.njit(cache=True)
def _propagate_row(
    before: FloatArray, after: FloatArray, cache: FloatArray, ledger: IntArray, q: float
) -> None:  # pragma: no cover - compiled
    """``after``'s x, P: ``before``'s propagated to ``after``'s time with ``after``'s input."""
    matrices = cache[transition_slot(cache, ledger, after[STEP_TIME] - before[STEP_TIME], q)]
    inputs = 3 if after[STEP_HAS_INPUT] != 0.0 else 0
    x, p = propagate(
        before[STEP_X : STEP_X + 6],
        before[STEP_P : STEP_P + 36].reshape((6, 6)),
        matrices[CACHE_F : CACHE_F + 36].reshape((6, 6)),
        matrices[CACHE_G : CACHE_G + 18].reshape((6, 3)),
        matrices[CACHE_Q : CACHE_Q + 36].reshape((6, 6)),
        after[STEP_INPUT : STEP_INPUT + inputs],
    )
    _put_state(after, x, p)


@numba.njit(cache=True)
def _put_state(row: FloatArray, x: FloatArray, p: FloatArray) -> None:  # pragma: no cover
    """Write x (6,) and P (6, 6) into a step's row."""
    for i in range(6):
        row[STEP_X + i] = x[i]
        for j in range(6):
            row[STEP_P + 6 * i + j] = p[i, j]


@numba.njit(cache=True)
def publish(row: FloatArray, newest: FloatArray) -> None:  # pragma: no cover - compiled
    """Copy a step's x and P, and the 1σ of x, into ``newest``."""
    for i in range(6):
        newest[NEWEST_X + i] = row[STEP_X + i]
        variance = row[STEP_P + 7 * i]
        newest[NEWEST_SIGMA + i] = math.sqrt(0.0 if variance < 0.0 else variance)  # as max()
    for i in range(36):
        newest[NEWEST_P + i] = row[STEP_P + i]


@numba.njit(cache=True)
def _records_end(steps: FloatArray, ledger: IntArray) -> int:  # pragma: no cover - compiled
    """One past the row of ``updates`` holding the newest step's last update."""
    newest = steps[ledger[END] - 1]
    return int(newest[STEP_FIRST_UPDATE] + newest[STEP_UPDATES])


@numba.njit(cache=True)
def _room(
    steps: FloatArray, updates: FloatArray, ledger: IntArray, step: bool
) -> int:  # pragma: no cover
    """Make sure ``updates`` (and, with ``step``, ``steps``) has a free row after its last live
    one, moving the live rows to the front when at least half are free; :data:`APPLIED`, or
    :data:`NEEDS_ROWS` / :data:`NEEDS_RECORDS` when there is no room."""
    first, end = ledger[FIRST], ledger[END]
    rows = steps.shape[0]
    if step and end == rows:
        if end - first > rows // 2:
            return NEEDS_ROWS
        for k in range(end - first):
            steps[k, :] = steps[first + k, :]
        first, end = 0, end - first
        ledger[FIRST], ledger[END] = first, end
    start, stop = int(steps[first, STEP_FIRST_UPDATE]), _records_end(steps, ledger)
    records = updates.shape[0]
    if stop == records:
        if stop - start > records // 2:
            return NEEDS_RECORDS
        for k in range(stop - start):
            updates[k, :] = updates[start + k, :]
        for k in range(first, end):
            steps[k, STEP_FIRST_UPDATE] -= start
    return APPLIED


@numba.njit(cache=True)
def _locate(
    steps: FloatArray, ledger: IntArray, time_s: float
) -> tuple[int, bool]:  # pragma: no cover
    """The row of the step a measurement at ``time_s`` [s] updates and whether that step is to
    be inserted there (splitting the interval before it); row -1: older than the history."""
    first, end = ledger[FIRST], ledger[END]
    if time_s >= steps[end - 1, STEP_TIME] - TIME_EPS_S:
        return end - 1, False
    if time_s < steps[first, STEP_TIME] - TIME_EPS_S:
        return -1, False
    i = end - 1  # the last step at or before time_s
    while steps[i, STEP_TIME] > time_s + TIME_EPS_S:
        i -= 1
    if abs(steps[i, STEP_TIME] - time_s) <= TIME_EPS_S:
        return i, False
    return i + 1, True


@numba.njit(cache=True)
def _stage(
    steps: FloatArray,
    updates: FloatArray,
    cache: FloatArray,
    ledger: IntArray,
    time_s: float,
    scratch: FloatArray,
    q: float,
) -> int:  # pragma: no cover - compiled
    """Find the step a measurement at ``time_s`` updates (ledger TARGET, SPLIT) and copy its
    prior into ``scratch``: the stored step, or the interval split at ``time_s`` (the next
    step's input held over both parts). Returns :data:`APPLIED` when staged, else
    :data:`STALE_STATUS` (counted), :data:`NEEDS_ROWS` or :data:`NEEDS_RECORDS`."""
    target, split = _locate(steps, ledger, time_s)
    if target < 0:
        ledger[STALE] += 1
        return STALE_STATUS
    status = _room(steps, updates, ledger, split)
    if status != APPLIED:
        return status
    target, split = _locate(steps, ledger, time_s)  # the rows may have moved
    if split:
        after = steps[target]
        scratch[STEP_TIME] = time_s
        scratch[STEP_HAS_INPUT] = after[STEP_HAS_INPUT]
        scratch[STEP_UPDATES] = 0.0
        scratch[STEP_FIRST_UPDATE] = after[STEP_FIRST_UPDATE]
        for i in range(3):
            scratch[STEP_INPUT + i] = after[STEP_INPUT + i]
        _propagate_row(steps[target - 1], scratch, cache, ledger, q)
    else:
        scratch[:] = steps[target, :]
    ledger[TARGET] = target
    ledger[SPLIT] = 1 if split else 0
    return APPLIED


@numba.njit(cache=True)
def _add_update(
    steps: FloatArray, updates: FloatArray, ledger: IntArray, j: int, record: FloatArray
) -> None:  # pragma: no cover - compiled
    """Append ``record`` to step ``j``'s updates (a free row of ``updates`` after the last live
    one, which the later steps' move into)."""
    row = steps[j]
    at = int(row[STEP_FIRST_UPDATE] + row[STEP_UPDATES])
    for k in range(_records_end(steps, ledger), at, -1):
        updates[k, :] = updates[k - 1, :]
    updates[at, :] = record
    row[STEP_UPDATES] += 1.0
    for k in range(j + 1, ledger[END]):
        steps[k, STEP_FIRST_UPDATE] += 1.0


@numba.njit(cache=True)
def _drop_update(
    steps: FloatArray, updates: FloatArray, ledger: IntArray, j: int, u: int
) -> None:  # pragma: no cover - compiled
    """Remove step ``j``'s update ``u`` (the later ones move back)."""
    stop = _records_end(steps, ledger)
    for k in range(int(steps[j, STEP_FIRST_UPDATE]) + u, stop - 1):
        updates[k, :] = updates[k + 1, :]
    steps[j, STEP_UPDATES] -= 1.0
    for k in range(j + 1, ledger[END]):
        steps[k, STEP_FIRST_UPDATE] -= 1.0


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
    _put_state(row, x, p)
    _add_update(steps, updates, ledger, target, record)
    if target == ledger[END] - 1:
        publish(row, newest)
        return APPLIED
    ledger[ROLLBACKS] += 1
    _propagate_row(row, steps[target + 1], cache, ledger, q)
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
        _put_state(row, x, p)
        return True
    ledger[INVALID] += 1
    _drop_update(steps, updates, ledger, j, u)
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
        _propagate_row(row, steps[j], cache, ledger, q)
        u = 0
    publish(steps[end - 1], newest)
    return APPLIED


@numba.njit(cache=True)
def _record(
    kind: int, reset: bool, h: FloatArray, value: Floats3, sigma: Floats3
) -> tuple[FloatArray, FloatArray, FloatArray]:  # pragma: no cover - compiled
    """An update's record, and its z and σ (views of the record: the first ``dim`` of
    ``value`` and ``sigma``)."""
    dim = h.shape[0]
    record = np.zeros(UPDATE_WIDTH)
    record[UPDATE_KIND] = kind
    record[UPDATE_RESET] = 1.0 if reset else 0.0
    record[UPDATE_DIM] = dim
    for i in range(dim):
        for j in range(6):
            record[UPDATE_H + 6 * i + j] = h[i, j]
        record[UPDATE_Z + i] = value[i]
        record[UPDATE_SIGMA + i] = sigma[i]
    z = record[UPDATE_Z : UPDATE_Z + dim]
    return record, z, record[UPDATE_SIGMA : UPDATE_SIGMA + dim]


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
    status = _room(steps, updates, ledger, True)
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
    _propagate_row(before, after, cache, ledger, q)
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
    status = _stage(steps, updates, cache, ledger, time_s, scratch, q)
    if status != APPLIED:
        return status
    record, z, s = _record(kind, False, h, value, sigma)
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
def stage_measurement(
    steps: FloatArray,
    updates: FloatArray,
    cache: FloatArray,
    ledger: IntArray,
    time_s: float,
    scratch: FloatArray,
    q: float,
) -> int:  # pragma: no cover - compiled
    """The prior a measurement at ``time_s`` [s] updates, into the step row ``scratch`` (x at
    :data:`STEP_X`, P at :data:`STEP_P`), for :func:`commit_reset`. Returns :data:`APPLIED`
    when staged, else :data:`STALE_STATUS` (counted), :data:`NEEDS_ROWS` or
    :data:`NEEDS_RECORDS`."""
    return _stage(steps, updates, cache, ledger, time_s, scratch, q)


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
    record, z, s = _record(kind, True, h, value, sigma)
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


def grown(
    steps: FloatArray, updates: FloatArray, ledger: IntArray, status: int
) -> tuple[FloatArray, FloatArray]:
    """New ``steps`` (:data:`NEEDS_ROWS`) or ``updates`` (:data:`NEEDS_RECORDS`) with twice the
    rows, the live rows of both moved to the front (``ledger`` too)."""
    first, end = int(ledger[FIRST]), int(ledger[END])
    start = int(steps[first, STEP_FIRST_UPDATE])
    stop = int(steps[end - 1, STEP_FIRST_UPDATE] + steps[end - 1, STEP_UPDATES])
    new_steps = np.zeros((steps.shape[0] * (2 if status == NEEDS_ROWS else 1), STEP_WIDTH))
    new_updates = np.zeros((updates.shape[0] * (2 if status == NEEDS_RECORDS else 1), UPDATE_WIDTH))
    new_steps[: end - first] = steps[first:end]
    new_steps[: end - first, STEP_FIRST_UPDATE] -= start
    new_updates[: stop - start] = updates[start:stop]
    ledger[FIRST], ledger[END] = 0, end - first
    return new_steps, new_updates


jit.refresh_stale_caches(
    (predict_step, apply_measurement, stage_measurement, commit_reset, resume_replay),
    (filter_kernels,),
)
