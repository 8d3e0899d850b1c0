"""``testbed.vehicle.filter_history``: the model matrices its cache makes, to the bit, against the
numpy formula, and a long history (the arrays grown and compacted, many updates at one step,
late fixes rolled back through them) against a plain numpy filter fed in time order."""

from __future__ import annotations

import numpy as np

from testbed.vehicle import filter_history as history
from testbed.vehicle.estimation import KalmanNavigator
from testbed.vehicle.filter_values import FilterConfig
from testbed.vehicle.nav_sensors import Measurement


def _numpy_transition(dt: float, q: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """F, G, Q of the constant-velocity model as numpy computes them (the estimation docstring)."""
    eye = np.eye(3)
    f = np.eye(6)
    f[:3, 3:] = dt * eye
    g = np.vstack([0.5 * dt * dt * eye, dt * eye])
    qm = np.empty((6, 6))
    qm[:3, :3] = (q * dt**3 / 3.0) * eye
    qm[:3, 3:] = qm[3:, :3] = (q * dt * dt / 2.0) * eye
    qm[3:, 3:] = (q * dt) * eye
    return f, g, qm


def _cached(cache: np.ndarray, slot: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    row = cache[slot]
    return row[:36].reshape(6, 6), row[36:54].reshape(6, 3), row[54:].reshape(6, 6)


def _bits(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float64).view(np.uint64)


def test_cached_matrices_are_numpys_to_the_bit() -> None:
    rng = np.random.default_rng(5)
    dts = np.concatenate([rng.uniform(1e-6, 1.0, 300), 10.0 ** rng.uniform(-8, 1.5, 300)])
    noises = rng.choice([0.1, 1e-3, 5e-4, 2.0, 37.5], dts.size)
    for dt, q in zip(dts.tolist(), noises.tolist(), strict=True):
        cache = np.zeros((history.CACHE_SLOTS, history.CACHE_WIDTH))
        ledger = np.zeros(history.LEDGER_SIZE, dtype=np.int64)
        slot = history.transition_slot(cache, ledger, dt, q)
        for got, want in zip(_cached(cache, slot), _numpy_transition(dt, q), strict=True):
            assert np.array_equal(_bits(got), _bits(want)), (dt, q)


def test_cache_keys_whole_nanoseconds_and_empties_when_full() -> None:
    cache = np.zeros((history.CACHE_SLOTS, history.CACHE_WIDTH))
    ledger = np.zeros(history.LEDGER_SIZE, dtype=np.int64)
    dt = 1.0 / 120.0
    first = history.transition_slot(cache, ledger, dt, 0.1)
    # an ulp away: the same step, whose matrices stay the first dt's
    assert history.transition_slot(cache, ledger, np.nextafter(dt, 1.0), 0.1) == first
    assert _cached(cache, first)[0][0, 3] == dt
    slots = [history.transition_slot(cache, ledger, k * 1e-3, 0.1) for k in range(1, 16)]
    assert sorted([first, *slots]) == list(range(history.CACHE_SLOTS))
    assert history.transition_slot(cache, ledger, 0.5, 0.1) == 0  # full: emptied, then filled
    assert ledger[history.CACHED] == 1
    assert history.transition_slot(cache, ledger, dt, 0.1) == 1  # forgotten, so made again
    assert _cached(cache, 0)[0][0, 3] == 0.5


def _numpy_filter(
    config: FilterConfig,
    frames: list[tuple[float, np.ndarray]],
    events: list[tuple[float, Measurement]],
) -> tuple[np.ndarray, np.ndarray]:
    """x, P at the last frame of the module docstring's filter fed the measurements in time
    order (no gate: they are all consistent), with numpy's products and inverse; each frame's
    input (NED acceleration) is held over the interval that ends at it."""
    x = np.zeros(6)
    sigmas = [config.initial_position_sigma_m] * 3 + [config.initial_velocity_sigma_m_s] * 3
    p = np.diag(np.square(sigmas))
    t = 0.0
    frame_times = np.array([time_s for time_s, _ in frames])

    def predict(to: float) -> None:
        nonlocal x, p, t
        if to > t:
            _, u = frames[int(np.searchsorted(frame_times, to - 1e-9))]
            f, g, qm = _numpy_transition(to - t, config.accel_noise_m2_s3)
            x, p, t = f @ x + g @ u, f @ p @ f.T + qm, to

    for time_s, m in events:
        predict(time_s)
        h = np.zeros((len(m.value), 6))
        for row, column in enumerate([2] if m.kind == "depth" else range(3)):
            h[row, column] = 1.0
        r = np.diag(np.square(m.sigma))
        s = h @ p @ h.T + r
        k = p @ h.T @ np.linalg.inv(s)
        a = np.eye(6) - k @ h
        x = x + k @ (np.array(m.value) - h @ x)
        p = a @ p @ a.T + k @ r @ k.T
    predict(frames[-1][0])
    return x, p


def test_long_history_with_crowded_steps_equals_numpy_in_time_order() -> None:
    rng = np.random.default_rng(11)
    config = FilterConfig(accel_noise_m2_s3=0.05, history_s=1.5, gate_probability=1.0 - 1e-12)
    nav = KalmanNavigator(config)
    frames: list[tuple[float, np.ndarray]] = []
    events: list[tuple[float, Measurement]] = []

    def measure(kind: str, time_s: float) -> Measurement:
        dim = 1 if kind == "depth" else 3
        value = 0.2 * time_s + 0.01 * rng.standard_normal(dim)  # about where it is
        return Measurement(kind, kind, time_s, tuple(value.tolist()), (0.01,) * dim)

    for k in range(1, 701):  # 7 s at 100 Hz: several times the first rows, compacted as it goes
        t = k / 100.0
        accel = 0.05 * rng.standard_normal(3)
        nav.predict(t, accel)
        frames.append((t, accel))
        late = []
        if k > 60 and k % 7 == 0:  # a fix of 0.3 s (+ 3 ms) ago: an interval split, replayed
            late.append(measure("position_ned", t - 0.303))
        if k > 60 and k % 11 == 0:  # one at a stored step's own time, after that step's updates
            late.append(measure("position_ned", (k - 50) / 100.0))
        for m in [measure("depth", t) for _ in range(9 if k % 50 == 0 else 1)] + late:
            assert nav.update(m)
            events.append((m.time_s, m))
    assert nav.counters.rollbacks == (100 - 8) + (63 - 5)
    # the arrays grew from their first 64 rows (and were compacted in between: 1.5 s is ≈ 190)
    steps, updates = nav._arrays[:2]
    assert steps.shape[0] > 64 and updates.shape[0] > 64
    events.sort(key=lambda event: event[0])  # stable: a late fix after its step's own updates
    x, p = _numpy_filter(config, frames, events)
    np.testing.assert_allclose(nav.state, x, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(nav.covariance, p, rtol=1e-9, atol=1e-15)
