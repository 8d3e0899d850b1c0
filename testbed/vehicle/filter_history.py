"""The navigation filter's stored steps: their arrays' layout and the compiled moves on them.

:class:`~testbed.vehicle.estimation.KalmanNavigator` keeps the steps its predictions store (its
module docstring: time, input, accepted updates, x, P) in float64 arrays it owns; the kernels of
:mod:`.filter_replay` predict, roll back and replay on them with the helpers here: the model's
F, G, Q cached by time step (:func:`transition_slot`), a step predicted from another
(:func:`propagate_row`: :mod:`.filter_kernels`' ``propagate`` on the rows' x and P),
finding the step a measurement's time falls on or in (:func:`locate`), adding and removing
stored updates, and making room. numpy and numba only.

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
from testbed.vehicle.filter_kernels import APPLIED, GATED, SINGULAR, propagate

__all__ = [
    "ACCEPTED",
    "APPLIED",
    "CACHED",
    "CACHE_F",
    "CACHE_G",
    "CACHE_KEYS",
    "CACHE_Q",
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
    "NEWEST_SIGMA",
    "NEWEST_WIDTH",
    "NEWEST_X",
    "REACQUIRED",
    "REJECTED",
    "RESUME_STEP",
    "RESUME_UPDATE",
    "ROLLBACKS",
    "SINGULAR",
    "SPLIT",
    "STALE",
    "STALE_STATUS",
    "STEP_FIRST_UPDATE",
    "STEP_HAS_INPUT",
    "STEP_INPUT",
    "STEP_P",
    "STEP_TIME",
    "STEP_UPDATES",
    "STEP_WIDTH",
    "STEP_X",
    "TARGET",
    "TIME_EPS_S",
    "UPDATE_DIM",
    "UPDATE_H",
    "UPDATE_KIND",
    "UPDATE_RESET",
    "UPDATE_SIGMA",
    "UPDATE_WIDTH",
    "UPDATE_Z",
    "add_update",
    "drop_update",
    "grown",
    "locate",
    "make_record",
    "make_room",
    "propagate_row",
    "publish",
    "put_state",
    "records_end",
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
def propagate_row(
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
    put_state(after, x, p)


@numba.njit(cache=True)
def put_state(row: FloatArray, x: FloatArray, p: FloatArray) -> None:  # pragma: no cover
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
def records_end(steps: FloatArray, ledger: IntArray) -> int:  # pragma: no cover - compiled
    """One past the row of ``updates`` holding the newest step's last update."""
    newest = steps[ledger[END] - 1]
    return int(newest[STEP_FIRST_UPDATE] + newest[STEP_UPDATES])


@numba.njit(cache=True)
def make_room(
    steps: FloatArray, updates: FloatArray, ledger: IntArray, new_step: bool
) -> int:  # pragma: no cover - compiled
    """Make sure ``updates`` (and, for a ``new_step``, ``steps``) has a free row after its last
    live one, moving the live rows to the front when at least half are free; :data:`APPLIED`,
    or :data:`NEEDS_ROWS` / :data:`NEEDS_RECORDS` when there is no room."""
    first, end = ledger[FIRST], ledger[END]
    rows = steps.shape[0]
    if new_step and end == rows:
        if end - first > rows // 2:
            return NEEDS_ROWS
        for k in range(end - first):
            steps[k, :] = steps[first + k, :]
        first, end = 0, end - first
        ledger[FIRST], ledger[END] = first, end
    start, stop = int(steps[first, STEP_FIRST_UPDATE]), records_end(steps, ledger)
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
def locate(
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
def add_update(
    steps: FloatArray, updates: FloatArray, ledger: IntArray, j: int, record: FloatArray
) -> None:  # pragma: no cover - compiled
    """Append ``record`` to step ``j``'s updates (a free row of ``updates`` after the last live
    one, which the later steps' move into)."""
    row = steps[j]
    at = int(row[STEP_FIRST_UPDATE] + row[STEP_UPDATES])
    for k in range(records_end(steps, ledger), at, -1):
        updates[k, :] = updates[k - 1, :]
    updates[at, :] = record
    row[STEP_UPDATES] += 1.0
    for k in range(j + 1, ledger[END]):
        steps[k, STEP_FIRST_UPDATE] += 1.0


@numba.njit(cache=True)
def drop_update(
    steps: FloatArray, updates: FloatArray, ledger: IntArray, j: int, u: int
) -> None:  # pragma: no cover - compiled
    """Remove step ``j``'s update ``u`` (the later ones move back)."""
    stop = records_end(steps, ledger)
    for k in range(int(steps[j, STEP_FIRST_UPDATE]) + u, stop - 1):
        updates[k, :] = updates[k + 1, :]
    steps[j, STEP_UPDATES] -= 1.0
    for k in range(j + 1, ledger[END]):
        steps[k, STEP_FIRST_UPDATE] -= 1.0


@numba.njit(cache=True)
def make_record(
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


jit.refresh_stale_caches((propagate_row,), (filter_kernels,))
