"""Navigation state estimation: a small Kalman filter over NED position and velocity.

State ``x = [n, e, d, v_n, v_e, v_d]`` (world NED [m], [m/s]), covariance ``P`` (6, 6).

Process model, per axis, constant velocity driven by white acceleration noise of spectral
density ``q`` [m²/s³] plus an optional known NED acceleration input ``u`` [m/s²] (gravity
removed, e.g. from an accelerometer), held constant over each interval ``Δt``::

    x⁻ = F x + G u,   F = [[I, Δt·I], [0, I]],   G = [[Δt²/2·I], [Δt·I]]
    P⁻ = F P Fᵀ + Q,  Q = q·[[Δt³/3·I, Δt²/2·I], [Δt²/2·I, Δt·I]]

(the exact discretisation, so splitting an interval gives the same result). A rule for ``q``:
the velocity change the model allows over ``Δt`` is ``√(q·Δt)``, so ``q ≈ a²·T`` for
accelerations of size ``a`` that persist for ``T`` seconds.

Measurements ``z = H x + r``, ``r ~ N(0, R)``, ``R = diag(σ²)``:

- position fix (NED): ``H = [I 0]``; depth: ``H = [0 0 1 0 0 0]``;
- DVL body velocity (FRD): ``h(x) = R(q)ᵀ v_ned``. The attitude ``q`` comes from the IMU (the
  AHRS) and is treated as a *known input*, not estimated, so ``h`` is linear in ``x`` with the
  time-varying ``H = [0 R(q)ᵀ]``. It is an EKF only in that sense: with attitude as a known
  input no linearisation error remains; attitude errors are not modelled (keep the DVL σ above
  the velocity error an attitude error of a few tenths of a degree makes).

Update (Joseph form, which keeps ``P`` symmetric positive definite)::

    y = z − H x⁻,  S = H P⁻ Hᵀ + R,  K = P⁻ Hᵀ S⁻¹
    x = x⁻ + K y,  P = (I − K H) P⁻ (I − K H)ᵀ + K R Kᵀ

Outliers: the normalised innovation ``yᵀ S⁻¹ y`` is gated against the chi-square quantile of
``gate_probability`` for ``dim z`` degrees of freedom; a failing measurement is counted and
dropped, as are non-finite or malformed ones (sensor data never raises here). A gate alone can
lock a filter out for good (after a long dropout the covariance may claim less than the error
really is, and every fix is then "an outlier"), so after ``reacquire_after`` consecutive
rejections from one source its next rejected measurement *re-acquires*: the covariance of the
states it observes is reset to the initial spread (their cross terms cleared) and it is applied.

Delayed measurements (exact re-processing): each :meth:`KalmanNavigator.predict` stores a step
``(time, input, accepted updates, x, P)``, bounded to the last ``history_s`` seconds. A
measurement older than the newest step rolls back to the stored state at (or just before) its
time — splitting that interval if it falls inside one — applies the update, and re-propagates
through the stored steps (their inputs and their previously accepted measurements, which are
re-applied without a second gate) to the present. The result equals a filter that received the
measurement at its true time. Measurements older than the history are dropped and counted.
The steps are kept in float64 arrays, and the bookkeeping around the arithmetic
(:mod:`~testbed.vehicle.filter_kernels`) is compiled too (:mod:`~testbed.vehicle.filter_replay`).

The filter is the default localizer's (:class:`~testbed.vehicle.localization.KalmanLocalizer`;
the seam for a user's own algorithm is :class:`~testbed.vehicle.localization.Localizer`). No ECS
here (that is :mod:`testbed.vehicle.localization`); no global RNG.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from typing import NamedTuple

import numpy as np

from testbed.common import jit
from testbed.common.geometry import (
    Quaternion,
    Vec3,
    quat_normalize,
    quat_rotate_inverse,
    rotation_matrix,
)
from testbed.common.jit import BOOL, F64, I64, INTS, TABLE, VECTOR, floats
from testbed.vehicle import filter_history as history
from testbed.vehicle import filter_replay as replay
from testbed.vehicle.filter_history import (
    ACCEPTED,
    APPLIED,
    GATED,
    INVALID,
    NEEDS_RESET,
    NEEDS_ROWS,
    REACQUIRED,
    REJECTED,
    TIME_EPS_S,
)
from testbed.vehicle.filter_values import FilterConfig, FilterCounters, NavigationEstimate
from testbed.vehicle.nav_sensors import Measurement

__all__ = [
    "FilterConfig",
    "FilterCounters",
    "KalmanNavigator",
    "NavigationEstimate",
]

LEVEL: Quaternion = (1.0, 0.0, 0.0, 0.0)
_H_POSITION = np.hstack([np.eye(3), np.zeros((3, 3))])
_H_DEPTH = np.array([[0.0, 0.0, 1.0, 0.0, 0.0, 0.0]])
_DIMS = {"position_ned": 3, "velocity_body": 3, "depth": 1}
_KINDS = ("position_ned", "velocity_body", "depth")
"""The measurement kinds by the code the stored updates keep."""
_KIND_CODES = {kind: code for code, kind in enumerate(_KINDS)}
_OBSERVED = {"position_ned": slice(0, 3), "velocity_body": slice(3, 6), "depth": slice(2, 3)}
_NO_INPUT = (0.0, 0.0, 0.0)
"""What the prediction kernel is given for its input when there is none (it is not read)."""
_FIRST_ROWS = 64
"""Stored steps, and stored updates, the history starts with room for (doubled when full)."""

# The history's kernels, called without numba's dispatcher (testbed.common.jit.entry): the
# arrays are the filter's own contiguous float64 (int64: the ledger) arrays, z and σ tuples of
# three floats (a depth's padded), H the (dim, 6) arrays made here.
_HISTORY = (TABLE, TABLE, TABLE, INTS)
"""steps, updates, cache, ledger (:mod:`.filter_history`)."""
_MEASUREMENT = (I64, TABLE, floats(3), floats(3))
"""Its kind's code, H, z and σ."""


class _HistoryKernels(NamedTuple):
    """The entries of :mod:`.filter_replay`'s kernels, each returning its status code."""

    predict: Callable[..., int]
    apply: Callable[..., int]
    stage: Callable[..., int]
    commit_reset: Callable[..., int]
    resume: Callable[..., int]


@functools.cache
def _history_kernels() -> _HistoryKernels:
    """The filter's entries, compiled (or loaded from numba's disk cache) when the first
    filter is built, not when this module is imported: they take most of a cold cache's
    compile time (≈ 20 s), and only vehicles that navigate with a filter need them."""
    return _HistoryKernels(
        predict=jit.entry(
            replay.predict_step, *_HISTORY, VECTOR, F64, BOOL, BOOL, floats(3), F64, F64
        ),
        apply=jit.entry(replay.apply_measurement, *_HISTORY, VECTOR, F64, *_MEASUREMENT, F64, F64),
        stage=jit.entry(replay.stage_measurement, *_HISTORY, F64, VECTOR, F64),
        commit_reset=jit.entry(
            replay.commit_reset, *_HISTORY, VECTOR, VECTOR, *_MEASUREMENT, TABLE, F64
        ),
        resume=jit.entry(replay.resume_replay, *_HISTORY, VECTOR, TABLE, F64),
    )


class KalmanNavigator:
    """The position/velocity Kalman filter of the module docstring.

    The stored steps live in arrays this filter owns (:mod:`.filter_history` lays them out);
    a prediction, and a measurement's update with its roll-back and replay, are one call each
    of a compiled kernel (:mod:`.filter_replay`).

    Args:
        config: noise figures.
        time_s: the time of the initial state [s].
        position_ned_m: (3,) initial position [m], NED (default the origin).
        velocity_ned_m_s: (3,) initial velocity [m/s], NED (default at rest).
    """

    __slots__ = (
        "_arrays",
        "_by_source",
        "_gates",
        "_kernels",
        "_ledger",
        "_newest",
        "_q",
        "_scratch",
        "_streaks",
        "_summary",
        "_t",
        "config",
    )

    def __init__(
        self,
        config: FilterConfig,
        *,
        time_s: float = 0.0,
        position_ned_m: Sequence[float] | np.ndarray = (0.0, 0.0, 0.0),
        velocity_ned_m_s: Sequence[float] | np.ndarray = (0.0, 0.0, 0.0),
    ) -> None:
        self.config = config
        self._t = float(time_s)
        x = np.array([*position_ned_m, *velocity_ned_m_s], dtype=np.float64)
        if x.shape != (6,):
            raise ValueError("initial position and velocity must have 3 components each")
        variances = [config.initial_position_sigma_m**2] * 3
        variances += [config.initial_velocity_sigma_m_s**2] * 3
        p = np.diag(np.array(variances, dtype=np.float64))
        steps = np.zeros((_FIRST_ROWS, history.STEP_WIDTH))
        updates = np.zeros((_FIRST_ROWS, history.UPDATE_WIDTH))
        cache = np.zeros((history.CACHE_SLOTS, history.CACHE_WIDTH))
        self._ledger = np.zeros(history.LEDGER_SIZE, dtype=np.int64)
        self._newest = np.zeros(history.NEWEST_WIDTH)
        self._kernels = _history_kernels()
        self._arrays = (steps, updates, cache, self._ledger, self._newest)
        """The kernels' first five arguments (steps and updates are replaced as they grow)."""
        self._summary = self._newest[: history.NEWEST_P]
        """x and its 1σ, what :meth:`estimate` reads."""
        self._scratch = np.zeros(history.STEP_WIDTH)
        self._q = float(config.accel_noise_m2_s3)
        first = steps[0]  # the initial state, the first stored step (no input)
        first[history.STEP_TIME] = self._t
        first[history.STEP_X : history.STEP_X + 6] = x
        first[history.STEP_P :] = p.ravel()
        self._ledger[history.END] = 1
        history.publish(first, self._newest)
        # chdtri(k, q): the x with P(χ²_k > x) = q, i.e. chi2.ppf(1 − q, k); scipy.special here
        # rather than scipy.stats at import (≈ 1 s of every process's start-up otherwise)
        from scipy.special import chdtri

        gates = {dim: float(chdtri(dim, 1.0 - config.gate_probability)) for dim in (1, 3)}
        self._gates = (math.nan, gates[1], math.nan, gates[3])
        """The gate by dim z."""
        self._streaks: dict[str, int] = {}
        self._by_source: dict[str, list[int]] = {}
        """[accepted, rejected] by measurement source (the ledger's two, split by source)."""

    # ------------------------------------------------------------------- accessors

    @property
    def time_s(self) -> float:
        """Time of the newest state [s]."""
        return self._t

    @property
    def state(self) -> np.ndarray:
        """(6,) copy of x: NED position [m] and velocity [m/s]."""
        return self._newest[:6].copy()

    @property
    def covariance(self) -> np.ndarray:
        """(6, 6) copy of P."""
        return self._newest[history.NEWEST_P :].reshape(6, 6).copy()

    @property
    def counters(self) -> FilterCounters:
        """Measurement counts since construction."""
        return FilterCounters(*self._ledger[ACCEPTED : ACCEPTED + 6].tolist())

    @property
    def source_counters(self) -> dict[str, tuple[int, int]]:
        """``(accepted, rejected)`` by measurement source since construction: the
        :attr:`counters` ``accepted`` (re-acquisitions included) and ``rejected`` (the gate's),
        split by :attr:`Measurement.source`; a source none of whose measurements was accepted
        or gated is absent."""
        return {name: (counts[0], counts[1]) for name, counts in sorted(self._by_source.items())}

    def _count(self, source: str, slot: int) -> None:
        counts = self._by_source.get(source)
        if counts is None:
            counts = self._by_source[source] = [0, 0]
        counts[slot] += 1

    def estimate(
        self, quaternion_wxyz: Quaternion = LEVEL, rates_rad_s: Vec3 = (0.0, 0.0, 0.0)
    ) -> NavigationEstimate:
        """The newest estimate, with the given IMU attitude (body → NED) and rates [rad/s]."""
        n, e, d, vn, ve, vd, s0, s1, s2, s3, s4, s5 = self._summary.tolist()
        v_ned = (vn, ve, vd)
        return NavigationEstimate(  # by position, in the fields' order (keywords: 0.6 µs more)
            self._t,
            (n, e, d),
            v_ned,
            quat_rotate_inverse(quaternion_wxyz, v_ned),
            quaternion_wxyz,
            rates_rad_s,
            (s0, s1, s2),
            (s3, s4, s5),
        )

    # --------------------------------------------------------------------- predict

    def predict(self, time_s: float, accel_ned: Sequence[float] | np.ndarray | None = None) -> None:
        """Propagate to ``time_s`` [s] with the NED acceleration input [m/s²] held over it.

        A ``time_s`` equal to the newest state's does nothing.

        Raises:
            ValueError: ``time_s`` is earlier than the newest state, or ``accel_ned`` has
                neither 3 components nor none (local misuse).
        """
        dt = time_s - self._t
        if dt < -TIME_EPS_S:
            raise ValueError(f"predict to {time_s} s is before the filter's time {self._t} s")
        if dt <= TIME_EPS_S:
            return
        accel: tuple[float, ...] = ()
        if accel_ned is not None:
            accel = accel_ned if type(accel_ned) is tuple else tuple(accel_ned)
            if len(accel) != 3 and len(accel) != 0:
                raise ValueError(f"an acceleration input has 3 components, not {len(accel)}")
        self._predict(float(time_s), False, accel)

    def _predict(self, time_s: float, hold_input: bool, accel: tuple[float, ...]) -> None:
        """Store the step at ``time_s`` [s] (:func:`~.filter_replay.predict_step`) predicted
        with ``accel`` (3 components, or none: constant velocity) or the newest step's input."""
        has_input = len(accel) == 3
        accel = accel if has_input else _NO_INPUT
        history_s = self.config.history_s
        while True:
            steps, updates, cache, ledger, newest = self._arrays  # (a star call costs 0.08 µs)
            status = self._kernels.predict(
                steps,
                updates,
                cache,
                ledger,
                newest,
                time_s,
                hold_input,
                has_input,
                accel,
                self._q,
                history_s,
            )
            if status < NEEDS_ROWS:
                break
            self._grow(status)
        self._t = time_s

    def _grow(self, status: int) -> None:
        """Give ``steps`` or ``updates`` twice the rows (a kernel's NEEDS_ROWS, NEEDS_RECORDS)."""
        steps, updates, cache, ledger, newest = self._arrays
        steps, updates = history.grown(steps, updates, ledger, status)
        self._arrays = (steps, updates, cache, ledger, newest)

    # ---------------------------------------------------------------------- update

    def update(self, measurement: Measurement, quaternion_wxyz: Quaternion = LEVEL) -> bool:
        """Apply one measurement (rolling back if it is older than the newest state).

        Args:
            measurement: the measurement, valid at its ``time_s``.
            quaternion_wxyz: attitude body → NED at the measurement's time (used by
                ``velocity_body`` only).

        Returns:
            Whether it was applied (``False``: malformed, gated out or older than the history;
            see :attr:`counters`).
        """
        m = measurement
        kind, value, sigma = m.kind, m.value, m.sigma
        dim = _DIMS.get(kind)
        if dim is None or len(value) != dim or len(sigma) != dim:
            self._ledger[INVALID] += 1
            return False
        if kind == "velocity_body":
            if not _finite(m):  # checked before the attitude, as the kernel would
                self._ledger[INVALID] += 1
                return False
            try:
                quaternion = quat_normalize(quaternion_wxyz)
            except ValueError:  # a zero attitude from the AHRS: data, not misuse
                self._ledger[INVALID] += 1
                return False
            h = np.zeros((3, 6))
            h[:, 3:] = np.array(rotation_matrix(quaternion)).T  # R: body → NED; H = [0 Rᵀ]
        else:
            h = _H_POSITION if kind == "position_ned" else _H_DEPTH
        t = m.time_s
        if t > self._t + TIME_EPS_S:  # newer than the filter: predict to it, input held
            if not _finite(m):
                self._ledger[INVALID] += 1
                return False
            self._predict(float(t), True, ())  # the input held
        if dim == 1:
            value, sigma = (value[0], 0.0, 0.0), (sigma[0], 1.0, 1.0)
        else:
            value = value if type(value) is tuple else tuple(value)
            sigma = sigma if type(sigma) is tuple else tuple(sigma)
        code = _KIND_CODES[kind]
        while True:
            steps, updates, cache, ledger, newest = self._arrays
            status = self._kernels.apply(
                steps,
                updates,
                cache,
                ledger,
                newest,
                t,
                code,
                h,
                value,
                sigma,
                self._gates[dim],
                self._q,
            )
            if status < NEEDS_ROWS:
                break
            self._grow(status)
        if status == APPLIED:
            self._streaks[m.source] = 0
            self._count(m.source, 0)
            return True
        if status == NEEDS_RESET:
            self._streaks[m.source] = 0
            self._count(m.source, 0)
            self._replay_resets(status)
            return True
        if status == GATED:
            return self._gated(m, code, h, value, sigma)
        return False  # invalid, singular or stale: counted

    def _gated(
        self,
        m: Measurement,
        code: int,
        h: np.ndarray,
        value: tuple[float, ...],
        sigma: tuple[float, ...],
    ) -> bool:
        """A gate rejection: counted, or (module docstring) a re-acquisition applied."""
        if not self._reacquire(m):
            self._ledger[REJECTED] += 1
            self._count(m.source, 1)
            return False
        self._ledger[REACQUIRED] += 1
        self._ledger[ACCEPTED] += 1
        self._count(m.source, 0)
        q = self._q
        while True:
            status = self._kernels.stage(*self._arrays[:4], m.time_s, self._scratch, q)
            if status < NEEDS_ROWS:
                break
            self._grow(status)
        scratch = self._scratch
        x = scratch[history.STEP_X : history.STEP_X + 6].copy()
        p = scratch[history.STEP_P : history.STEP_P + 36].reshape(6, 6)
        z = np.array(m.value, dtype=np.float64)
        reset_p = self._reset_spread(p, m.kind, z - h @ x)  # the innovation does not depend on P
        commit_reset = self._kernels.commit_reset
        status = commit_reset(*self._arrays, scratch, code, h, value, sigma, reset_p, q)
        if status != APPLIED and status != NEEDS_RESET:
            return False  # singular: counted
        self._replay_resets(status)
        return True

    def _replay_resets(self, status: int) -> None:
        """Resume a replay that stopped at stored re-acquisitions, resetting P for each."""
        while status == NEEDS_RESET:
            steps, updates = self._arrays[:2]
            step = steps[self._ledger[history.RESUME_STEP]]
            u = int(step[history.STEP_FIRST_UPDATE]) + int(self._ledger[history.RESUME_UPDATE])
            record = updates[u]
            dim = int(record[history.UPDATE_DIM])
            h = record[history.UPDATE_H : history.UPDATE_H + 6 * dim].reshape(dim, 6).copy()
            z = record[history.UPDATE_Z : history.UPDATE_Z + dim].copy()
            x = step[history.STEP_X : history.STEP_X + 6].copy()
            p = step[history.STEP_P : history.STEP_P + 36].reshape(6, 6)
            kind = _KINDS[int(record[history.UPDATE_KIND])]
            reset_p = self._reset_spread(p, kind, z - h @ x)
            status = self._kernels.resume(*self._arrays, reset_p, self._q)

    def _reacquire(self, m: Measurement) -> bool:
        """Count a gate rejection of ``m``'s source; whether this one re-acquires instead."""
        limit = self.config.reacquire_after
        streak = self._streaks.get(m.source, 0)
        if limit and streak >= limit:
            self._streaks[m.source] = 0
            return True
        self._streaks[m.source] = streak + 1
        return False

    def _reset_spread(self, p: np.ndarray, kind: str, innovation: np.ndarray) -> np.ndarray:
        """``p`` with the observed block reset to the initial spread, or wider: the largest
        innovation component squared (so the fix that re-acquires is believed)."""
        cfg = self.config
        block = _OBSERVED[kind]
        p = p.copy()
        p[block, :] = 0.0
        p[:, block] = 0.0
        sigma = cfg.initial_velocity_sigma_m_s if kind == "velocity_body" else None
        sigma = cfg.initial_position_sigma_m if sigma is None else sigma
        idx = np.arange(6)[block]
        p[idx, idx] = max(sigma * sigma, float(np.max(np.square(innovation))))
        return p


def _finite(m: Measurement) -> bool:
    """Whether a measurement's time, values and σ are finite and its σ > 0."""
    if not math.isfinite(m.time_s):
        return False
    isfinite = math.isfinite
    return all(map(isfinite, m.value)) and all(map(isfinite, m.sigma)) and min(m.sigma) > 0.0
