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

The filter is the default localizer's (:class:`~testbed.vehicle.localization.KalmanLocalizer`;
the seam for a user's own algorithm is :class:`~testbed.vehicle.localization.Localizer`). No ECS
here (that is :mod:`testbed.vehicle.localization`); no global RNG.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from testbed.common import jit
from testbed.common.geometry import (
    Quaternion,
    Vec3,
    quat_normalize,
    quat_rotate_inverse,
    rotation_matrix,
)
from testbed.common.jit import F64, TABLE, VECTOR
from testbed.config import check_range
from testbed.vehicle.filter_kernels import GATED, SINGULAR, gated_update, propagate
from testbed.vehicle.nav_sensors import Measurement

__all__ = [
    "FilterConfig",
    "FilterCounters",
    "KalmanNavigator",
    "NavigationEstimate",
]

LEVEL: Quaternion = (1.0, 0.0, 0.0, 0.0)
_TIME_EPS_S = 1e-9
_CACHED_STEPS = 16  # time steps whose F, G, Q are kept
_H_POSITION = np.hstack([np.eye(3), np.zeros((3, 3))])
_H_DEPTH = np.array([[0.0, 0.0, 1.0, 0.0, 0.0, 0.0]])
_DIMS = {"position_ned": 3, "velocity_body": 3, "depth": 1}
_OBSERVED = {"position_ned": slice(0, 3), "velocity_body": slice(3, 6), "depth": slice(2, 3)}
_COUNTERS = ("accepted", "rejected", "invalid", "stale", "rollbacks", "reacquired")
_NO_INPUT = np.zeros(0)
"""The prediction's input when there is none (constant velocity)."""

# The filter's kernels, called without numba's dispatcher (testbed.common.jit.entry): x, P, the
# model's matrices and a measurement's arrays are the filter's own contiguous float64 arrays.
_PROPAGATE = jit.entry(propagate, VECTOR, TABLE, TABLE, TABLE, TABLE, VECTOR)
_GATED_UPDATE = jit.entry(gated_update, VECTOR, TABLE, TABLE, VECTOR, VECTOR, F64)


@dataclass(frozen=True, slots=True)
class NavigationEstimate:
    """The vehicle's navigation estimate at one instant (a vehicle-local component).

    Attributes:
        time_s: the instant it is valid for [s].
        position_ned_m: (3,) body-origin position [m], world NED.
        velocity_ned_m_s: (3,) velocity [m/s], world NED.
        velocity_body_m_s: (3,) the same velocity in the body frame (u, v, w) [m/s], FRD,
            rotated with the IMU attitude.
        quaternion_wxyz: attitude from the IMU, body → NED.
        rates_rad_s: (3,) body rates from the IMU [rad/s], FRD.
        position_sigma_m: (3,) 1σ of each position component [m].
        velocity_sigma_m_s: (3,) 1σ of each NED velocity component [m/s].
    """

    time_s: float
    position_ned_m: Vec3
    velocity_ned_m_s: Vec3
    velocity_body_m_s: Vec3
    quaternion_wxyz: Quaternion
    rates_rad_s: Vec3
    position_sigma_m: Vec3
    velocity_sigma_m_s: Vec3


@dataclass(frozen=True, slots=True)
class FilterConfig:
    """Noise figures and bookkeeping of :class:`KalmanNavigator`.

    Domains: ``accel_noise_m2_s3`` in (0, 100]; ``initial_position_sigma_m`` in (0, 1e4] m;
    ``initial_velocity_sigma_m_s`` in (0, 100] m/s; ``history_s`` in [0, 60] s;
    ``gate_probability`` in (0, 1); ``reacquire_after`` in [0, 1000].

    Attributes:
        accel_noise_m2_s3: ``q``, spectral density of the white acceleration per NED axis
            [m²/s³]. 0.1 suits an ROV whose accelerations of ≈ 0.3 m/s² last ≈ 1 s.
        initial_position_sigma_m: 1σ of the initial position per axis [m].
        initial_velocity_sigma_m_s: 1σ of the initial velocity per axis [m/s].
        history_s: how far back delayed measurements are re-processed [s].
        gate_probability: chi-square gate; innovations beyond this quantile are rejected.
        reacquire_after: consecutive rejections of one source after which the next rejected
            one re-acquires (module docstring); 0 never re-acquires.
    """

    accel_noise_m2_s3: float = 0.1
    initial_position_sigma_m: float = 10.0
    initial_velocity_sigma_m_s: float = 1.0
    history_s: float = 5.0
    gate_probability: float = 0.9999
    reacquire_after: int = 3

    def __post_init__(self) -> None:
        check_range(self.accel_noise_m2_s3, "accel_noise_m2_s3", 0.0, 100.0, "m²/s³", low_open=True)
        check_range(
            self.initial_position_sigma_m, "initial_position_sigma_m", 0.0, 1e4, "m", low_open=True
        )
        check_range(
            self.initial_velocity_sigma_m_s,
            "initial_velocity_sigma_m_s",
            0.0,
            100.0,
            "m/s",
            low_open=True,
        )
        check_range(self.history_s, "history_s", 0.0, 60.0, "s")
        check_range(
            self.gate_probability, "gate_probability", 0.0, 1.0, low_open=True, high_open=True
        )
        check_range(self.reacquire_after, "reacquire_after", 0, 1000)


@dataclass(frozen=True, slots=True)
class FilterCounters:
    """What happened to the measurements a filter was given (counts since construction).

    Attributes:
        accepted: applied.
        rejected: failed the chi-square gate.
        invalid: malformed (unknown kind, wrong length, non-finite value or σ ≤ 0).
        stale: older than the history, dropped.
        rollbacks: accepted measurements that were applied by rolling back.
        reacquired: rejected measurements applied after a covariance reset (module docstring).
    """

    accepted: int = 0
    rejected: int = 0
    invalid: int = 0
    stale: int = 0
    rollbacks: int = 0
    reacquired: int = 0


@dataclass(slots=True)
class _Step:
    """One stored filter instant: the input that reached it, its accepted updates, x, P."""

    time_s: float
    accel: np.ndarray | None
    x: np.ndarray
    p: np.ndarray
    updates: list[tuple[Measurement, Quaternion, bool]] = field(default_factory=list)
    """(measurement, attitude, whether it re-acquired) in the order they were applied."""


def _transition(dt: float, q: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """F (6, 6), G (6, 3) and Q (6, 6) of the constant-velocity model over ``dt`` [s]."""
    eye = np.eye(3)
    f = np.eye(6)
    f[:3, 3:] = dt * eye
    g = np.vstack([0.5 * dt * dt * eye, dt * eye])
    qm = np.empty((6, 6))
    qm[:3, :3] = (q * dt**3 / 3.0) * eye
    qm[:3, 3:] = qm[3:, :3] = (q * dt * dt / 2.0) * eye
    qm[3:, 3:] = (q * dt) * eye
    return f, g, qm


class KalmanNavigator:
    """The position/velocity Kalman filter of the module docstring.

    Args:
        config: noise figures.
        time_s: the time of the initial state [s].
        position_ned_m: (3,) initial position [m], NED (default the origin).
        velocity_ned_m_s: (3,) initial velocity [m/s], NED (default at rest).
    """

    __slots__ = (
        "_cache",
        "_counts",
        "_gates",
        "_history",
        "_p",
        "_streaks",
        "_t",
        "_x",
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
        self._x = np.array([*position_ned_m, *velocity_ned_m_s], dtype=np.float64)
        if self._x.shape != (6,):
            raise ValueError("initial position and velocity must have 3 components each")
        variances = [config.initial_position_sigma_m**2] * 3
        variances += [config.initial_velocity_sigma_m_s**2] * 3
        self._p = np.diag(np.array(variances, dtype=np.float64))
        self._history: list[_Step] = [_Step(self._t, None, self._x.copy(), self._p.copy())]
        # chdtri(k, q): the x with P(χ²_k > x) = q, i.e. chi2.ppf(1 − q, k); scipy.special here
        # rather than scipy.stats at import (≈ 1 s of every process's start-up otherwise)
        from scipy.special import chdtri

        self._gates = {dim: float(chdtri(dim, 1.0 - config.gate_probability)) for dim in (1, 3)}
        self._counts = {k: 0 for k in _COUNTERS}
        self._streaks: dict[str, int] = {}
        # F, G, Q by time step [ns]: frames land 2 or 3 physics steps apart, so a handful
        self._cache: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}

    # ------------------------------------------------------------------- accessors

    @property
    def time_s(self) -> float:
        """Time of the newest state [s]."""
        return self._t

    @property
    def state(self) -> np.ndarray:
        """(6,) copy of x: NED position [m] and velocity [m/s]."""
        return self._x.copy()

    @property
    def covariance(self) -> np.ndarray:
        """(6, 6) copy of P."""
        return self._p.copy()

    @property
    def counters(self) -> FilterCounters:
        """Measurement counts since construction."""
        return FilterCounters(**self._counts)

    def estimate(
        self, quaternion_wxyz: Quaternion = LEVEL, rates_rad_s: Vec3 = (0.0, 0.0, 0.0)
    ) -> NavigationEstimate:
        """The newest estimate, with the given IMU attitude (body → NED) and rates [rad/s]."""
        n, e, d, vn, ve, vd = self._x.tolist()
        s0, s1, s2, s3, s4, s5 = (math.sqrt(max(v, 0.0)) for v in self._p.diagonal().tolist())
        v_ned = (vn, ve, vd)
        return NavigationEstimate(
            time_s=self._t,
            position_ned_m=(n, e, d),
            velocity_ned_m_s=v_ned,
            velocity_body_m_s=quat_rotate_inverse(quaternion_wxyz, v_ned),
            quaternion_wxyz=quaternion_wxyz,
            rates_rad_s=rates_rad_s,
            position_sigma_m=(s0, s1, s2),
            velocity_sigma_m_s=(s3, s4, s5),
        )

    # --------------------------------------------------------------------- predict

    def predict(self, time_s: float, accel_ned: Sequence[float] | np.ndarray | None = None) -> None:
        """Propagate to ``time_s`` [s] with the NED acceleration input [m/s²] held over it.

        A ``time_s`` equal to the newest state's does nothing.

        Raises:
            ValueError: ``time_s`` is earlier than the newest state (local misuse).
        """
        dt = time_s - self._t
        if dt < -_TIME_EPS_S:
            raise ValueError(f"predict to {time_s} s is before the filter's time {self._t} s")
        if dt <= _TIME_EPS_S:
            return
        accel = None if accel_ned is None else np.ascontiguousarray(accel_ned, dtype=np.float64)
        self._x, self._p = self._propagate(self._x, self._p, dt, accel)
        self._t = float(time_s)
        self._history.append(_Step(self._t, accel, self._x, self._p))
        self._trim()

    def _propagate(
        self, x: np.ndarray, p: np.ndarray, dt: float, accel: np.ndarray | None
    ) -> tuple[np.ndarray, np.ndarray]:
        key = round(dt * 1e9)  # frames' dt jitter by ~1 ulp; 1 ns is far below any step
        matrices = self._cache.get(key)
        if matrices is None:
            if len(self._cache) >= _CACHED_STEPS:
                self._cache.clear()
            matrices = self._cache[key] = _transition(dt, self.config.accel_noise_m2_s3)
        f, g, qm = matrices
        return _PROPAGATE(x, p, f, g, qm, _NO_INPUT if accel is None else accel)

    def _trim(self) -> None:
        horizon = self._t - self.config.history_s
        history = self._history
        drop = 0
        while drop < len(history) - 1 and history[drop + 1].time_s <= horizon:
            drop += 1
        if drop:
            del history[:drop]

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
        if not self._valid(measurement):
            self._counts["invalid"] += 1
            return False
        if measurement.kind == "velocity_body":
            try:
                quaternion_wxyz = quat_normalize(quaternion_wxyz)
            except ValueError:  # a zero attitude from the AHRS: data, not misuse
                self._counts["invalid"] += 1
                return False
        t = measurement.time_s
        if t > self._t + _TIME_EPS_S:
            self.predict(t, self._history[-1].accel)
        if t >= self._t - _TIME_EPS_S:
            step = self._history[-1]
            ok = self._apply(step, measurement, quaternion_wxyz, gate=True)
            self._x, self._p = step.x, step.p
            return ok
        return self._rollback(measurement, quaternion_wxyz)

    def _valid(self, m: Measurement) -> bool:
        dim = _DIMS.get(m.kind)
        if dim is None or len(m.value) != dim or len(m.sigma) != dim:
            return False
        if not math.isfinite(m.time_s):
            return False
        isfinite = math.isfinite
        return all(map(isfinite, m.value)) and all(map(isfinite, m.sigma)) and min(m.sigma) > 0.0

    def _apply(
        self,
        step: _Step,
        m: Measurement,
        quaternion: Quaternion,
        *,
        gate: bool,
        reset: bool = False,
    ) -> bool:
        """Update ``step``'s posterior in place with ``m``; record it when applied.

        ``reset`` widens the observed states' spread first (a re-acquisition); ``gate=False``
        applies without the gate (re-acquisitions and replays, counted already).
        """
        x, p = step.x, step.p
        if m.kind == "velocity_body":
            h = np.zeros((3, 6))
            h[:, 3:] = np.array(rotation_matrix(quaternion)).T  # R: body → NED; H = [0 Rᵀ]
        else:
            h = _H_POSITION if m.kind == "position_ned" else _H_DEPTH
        z = np.array(m.value, dtype=np.float64)
        sigma = np.array(m.sigma, dtype=np.float64)
        if reset:  # the innovation does not depend on P
            p = self._reset_spread(p, m.kind, z - h @ x)
        limit = self._gates[len(z)] if gate else math.inf
        x, p, _, status = _GATED_UPDATE(x, p, h, z, sigma, limit)
        if status == SINGULAR:
            self._counts["invalid"] += 1
            return False
        if status == GATED:
            if self._reacquire(m):
                self._counts["reacquired"] += 1
                self._counts["accepted"] += 1
                return self._apply(step, m, quaternion, gate=False, reset=True)
            self._counts["rejected"] += 1
            return False
        step.x, step.p = x, p
        step.updates.append((m, quaternion, reset))
        if gate:
            self._streaks[m.source] = 0
            self._counts["accepted"] += 1
        return True

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

    def _rollback(self, m: Measurement, quaternion: Quaternion) -> bool:
        history = self._history
        t = m.time_s
        if t < history[0].time_s - _TIME_EPS_S:
            self._counts["stale"] += 1
            return False
        # the last stored step at or before t
        i = len(history) - 1
        while history[i].time_s > t + _TIME_EPS_S:
            i -= 1
        base = history[i]
        if abs(base.time_s - t) <= _TIME_EPS_S:
            target = _Step(base.time_s, base.accel, base.x, base.p, list(base.updates))
            replace = True
        else:  # split the interval (base, next] at t; the next step's input held over both
            accel = history[i + 1].accel
            x, p = self._propagate(base.x, base.p, t - base.time_s, accel)
            target = _Step(t, accel, x, p)
            replace = False
        if not self._apply(target, m, quaternion, gate=True):
            return False  # history untouched
        self._counts["rollbacks"] += 1
        if replace:
            history[i] = target
        else:
            i += 1
            history.insert(i, target)
        prev = target
        for j in range(i + 1, len(history)):
            step = history[j]
            x, p = self._propagate(prev.x, prev.p, step.time_s - prev.time_s, step.accel)
            replayed = _Step(step.time_s, step.accel, x, p)
            for old, q, reset in step.updates:
                self._apply(replayed, old, q, gate=False, reset=reset)
            history[j] = prev = replayed
        self._x, self._p = prev.x, prev.p
        return True
