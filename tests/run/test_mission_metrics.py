"""Mission metrics on hand-made tracks against hand-computed answers: the position error, its
statistics (final error, NaN left out), the convergence time, and the ``"mission"`` key of
``metrics.json`` (present only under autonomy), plus the recorder's target and estimate columns."""

from __future__ import annotations

import math

import numpy as np
import pytest

from testbed.common.components import MissionStatus
from testbed.run.metrics import (
    error_statistics,
    final_target_s,
    position_error,
    settling_time_s,
    time_to_converge_s,
    yaw_error_deg,
)
from testbed.run.recorder import SERIES_COLUMNS
from testbed.run.run_metrics import mission_metrics


def test_position_error_is_the_3d_distance_nan_where_either_is_missing() -> None:
    truth = [(0.0, 0.0, 1.0), (1.0, 2.0, 3.0), (0.0, 0.0, 0.0)]
    target = [(3.0, 4.0, 1.0), (1.0, 2.0, 1.0), (math.nan, 0.0, 0.0)]
    error = position_error(truth, target)
    assert error[:2].tolist() == [5.0, 2.0]
    assert math.isnan(error[2])
    with pytest.raises(ValueError, match="different lengths"):
        position_error(truth, target[:2])


def test_error_statistics_final_is_the_last_finite_value() -> None:
    stats = error_statistics([1.0, math.nan, 3.0, 2.0, math.nan])
    assert stats["mean"] == pytest.approx(2.0)
    assert stats["std"] == pytest.approx(math.sqrt(2.0 / 3.0))  # population std of 1, 3, 2
    assert stats["p95"] == pytest.approx(2.9)  # sorted 1, 2, 3 at rank 0.95·2 = 1.9: 2 + 0.9
    assert stats["final"] == 2.0


def test_error_statistics_of_nothing_finite_are_nan() -> None:
    for values in ([], [math.nan, math.nan]):
        stats = error_statistics(values)
        assert set(stats) == {"mean", "std", "p95", "final"}
        assert all(math.isnan(v) for v in stats.values())


@pytest.mark.parametrize(
    ("error", "expected"),
    [
        ([0.5, 0.3, 0.1, 0.15, 0.05], 2.0),  # within 0.2 from t = 2 s on
        ([0.1, 0.1, 0.1, 0.1, 0.1], 0.0),  # always within: the first sample
        ([0.1, 0.3, 0.1, 0.25, 0.1], 4.0),  # left twice; the last entry counts
        ([0.1, 0.1, 0.1, 0.1, 0.3], math.nan),  # ends outside: never converged
        ([0.1, 0.1, math.nan, 0.1, 0.1], 3.0),  # a NaN breaks the run
        ([0.1, 0.2, 0.1, 0.1, 0.1], 2.0),  # exactly at the tolerance is outside
    ],
)
def test_time_to_converge(error: list[float], expected: float) -> None:
    t = [0.0, 1.0, 2.0, 3.0, 4.0]
    got = time_to_converge_s(t, error, 0.2)
    assert (math.isnan(got) and math.isnan(expected)) or got == expected


def test_time_to_converge_of_no_samples_is_nan() -> None:
    assert math.isnan(time_to_converge_s([], [], 0.2))
    with pytest.raises(ValueError):
        time_to_converge_s([0.0, 1.0], [0.1], 0.2)


def _ramp_mission(lag_m: float, dt: float = 0.01) -> dict[str, np.ndarray]:
    """A mission from t = 1 s: the target moves north at 0.2 m/s from 0 to 1 m (arriving at
    t = 6 s), the vehicle ``lag_m`` behind it; after the arrival the lag decays as
    lag·exp(−(t − 6 s)/1 s). Rows every ``dt`` [s] to t = 12 s."""
    k = np.arange(round(1.0 / dt), round(12.0 / dt) + 1)
    t = k * dt
    target = np.minimum(0.2 * (t - 1.0), 1.0)
    lag = np.where(t < 6.0, lag_m, lag_m * np.exp(-(t - 6.0)))
    s = _series(t.size)
    s["t_s"] = t
    s["target_n"], s["north_m"] = target, target - lag
    s["est_n"] = s["north_m"]
    return s


def test_convergence_is_counted_from_the_final_targets_arrival() -> None:
    """A follower 0.25 m behind its moving target (outside the 0.2-m tolerance) settles when
    0.25·exp(−τ) < 0.2, τ = ln 1.25 = 0.223 s after the target's arrival at t = 6 s: on a
    10-ms grid the first sample inside is 6.23 s (a duration of 0.23 s), not a time from the
    start of the run."""
    dt = 0.01
    m = mission_metrics(_ramp_mission(0.25, dt), 0.0, 0.2, status=None, orders_acknowledged=None)
    expected = math.ceil(math.log(1.25) / dt) * dt
    assert m["final_target_s"] == pytest.approx(6.0, abs=1e-9)
    assert m["time_to_converge_s"] == pytest.approx(expected, abs=1e-9)
    assert m["time_to_converge_s"] == pytest.approx(0.23, abs=1e-9)


def test_a_follower_that_arrives_with_its_target_converged_in_zero_time() -> None:
    """1 cm behind all along (always within 0.2 m): 0 s after the arrival at 6 s — the old
    definition said 1.0 s, the first row of the mission, before anything had moved."""
    m = mission_metrics(_ramp_mission(0.01), 0.0, 0.2, status=None, orders_acknowledged=None)
    assert m["final_target_s"] == pytest.approx(6.0, abs=1e-9)
    assert m["time_to_converge_s"] == 0.0


def test_final_target_and_settling_by_hand() -> None:
    t = [0.0, 1.0, 2.0, 3.0, 4.0]
    target = [(0, 0, 0), (1, 0, 0), (2, 0, 0), (2, 0, 0), (2, 0, 0)]
    assert final_target_s(t, target) == 2.0
    assert final_target_s(t, [(0, 0, 0)] * 4 + [(math.nan, 0, 0)]) != final_target_s(t, target)
    assert math.isnan(final_target_s(t, [(0, 0, 0)] * 4 + [(math.nan, 0, 0)]))
    truth = [(0, 0, 0), (0.5, 0, 0), (1.5, 0, 0), (1.9, 0, 0), (1.95, 0, 0)]
    assert settling_time_s(t, truth, target, 0.2) == (1.0, 2.0)  # within from t = 3 s
    ends_outside = [*truth[:4], (1.7, 0, 0)]
    settling, arrival = settling_time_s(t, ends_outside, target, 0.2)
    assert math.isnan(settling) and arrival == 2.0
    turning = [0.0, 0.0, 0.0, 45.0, 45.0]  # the last waypoint only turns: it arrives at 3 s
    assert settling_time_s(t, truth, target, 0.2, turning) == (0.0, 3.0)
    assert settling_time_s(t, truth, target, 0.2, [math.nan] * 5) == (1.0, 2.0)  # no yaw target


def test_yaw_error_is_wrapped_and_absolute() -> None:
    got = yaw_error_deg([179.0, -170.0, 10.0, 0.0, math.nan], [-179.0, 170.0, 30.0, 180.0, 0.0])
    assert got[:4].tolist() == pytest.approx([2.0, 20.0, 20.0, 180.0])
    assert math.isnan(got[4])


def test_mission_yaw_error_against_the_pose_targets_heading() -> None:
    """Truth heading against ``target_yaw_deg`` on the scored rows (armed, with a target, after
    the settle time), the short way round: rows t = 1, 3, 4, 5 s have errors 2 (across ±180°),
    0, 10 and 4 deg; t = 0 (50° off) is before the settle time, t = 2 s (90° off) disarmed."""
    s = _series()
    s["yaw_deg"] = np.array([50.0, 179.0, 90.0, 100.0, -5.0, 34.0])
    s["target_yaw_deg"] = np.array([0.0, -179.0, 0.0, 100.0, 5.0, 30.0])
    s["armed"][2] = 0.0
    m = mission_metrics(s, 1.0, 0.2, status=None, orders_acknowledged=None)
    errors = np.array([2.0, 0.0, 10.0, 4.0])  # t = 1, 3, 4, 5
    heading = m["yaw_error_deg"]
    assert heading["mean"] == pytest.approx(errors.mean())
    assert heading["std"] == pytest.approx(errors.std())
    assert heading["p95"] == pytest.approx(np.percentile(errors, 95))


def _series(n: int = 6) -> dict[str, np.ndarray]:
    cols = {name: np.zeros(n) for name in SERIES_COLUMNS}
    cols["t_s"] = np.arange(n, dtype=float)
    cols["armed"] = np.ones(n)
    for name in SERIES_COLUMNS:
        if name.startswith("ee_"):  # no arm: the recorder writes NaN
            cols[name][:] = math.nan
    return cols


def test_mission_metrics_by_hand() -> None:
    s = _series()
    # truth north 0.5, 0.4, 0.3, 0.1, 0.1, 0.05; target at the origin from t = 1 s
    s["north_m"] = np.array([0.5, 0.4, 0.3, 0.1, 0.1, 0.05])
    s["target_n"][0] = math.nan
    s["armed"][2] = 0.0  # a disarmed row is left out
    s["est_n"] = s["north_m"] + np.array([0.0, 0.0, 0.0, 0.03, 0.0, 0.04])
    s["est_e"][4] = 0.0
    s["est_n"][4] = math.nan  # no estimate at that row
    m = mission_metrics(
        s,
        settle_s=1.0,
        tolerance_m=0.2,
        status=MissionStatus(ready=True, goals=2, reached=1),
        orders_acknowledged=None,
    )
    # rows t = 1, 3, 4, 5 → errors 0.4, 0.1, 0.1, 0.05
    assert m["samples"] == 4
    assert m["position_error_m"]["mean"] == pytest.approx(0.1625)
    assert m["position_error_m"]["final"] == pytest.approx(0.05)
    # the target (the origin) is final from its first row, t = 1 s; within 0.2 m from t = 3 s
    assert m["final_target_s"] == 1.0
    assert m["time_to_converge_s"] == 2.0
    # estimate errors on rows t = 1, 3, 5 (t = 4 has none): 0, 0.03, 0.04
    assert m["estimate_error_m"]["mean"] == pytest.approx(0.07 / 3)
    assert (m["goals"], m["goals_reached"], m["orders_acknowledged"]) == (2, 1, None)
    assert m["goal_tolerance_m"] == 0.2


def test_end_effector_rows_are_scored_on_the_end_effector() -> None:
    """With an end-effector target the error is the end effector's against it (by hand), the
    estimate error stays the body's, and the frame is named."""
    s = _series()
    s["north_m"] = np.full(6, 9.0)  # the body is far away: it must not enter the error
    s["est_n"] = np.full(6, 9.1)
    s["ee_n"], s["ee_e"], s["ee_d"] = (
        np.array([1.0, 0.9, 0.8, 0.6, 0.5, 0.5]),
        np.zeros(6),
        np.zeros(6),
    )
    s["ee_target_n"], s["ee_target_e"], s["ee_target_d"] = np.full(6, 0.5), np.zeros(6), np.zeros(6)
    s["ee_target_n"][0] = math.nan  # the station held before the mission: no ee target
    m = mission_metrics(s, settle_s=1.0, tolerance_m=0.2, status=None, orders_acknowledged=None)
    assert m["frame"] == "end_effector"
    assert m["samples"] == 5
    errors = [0.4, 0.3, 0.1, 0.0, 0.0]
    assert m["position_error_m"]["mean"] == pytest.approx(np.mean(errors))
    assert m["position_error_m"]["final"] == pytest.approx(0.0)
    assert m["estimate_error_m"]["mean"] == pytest.approx(0.1)
    # the ee target is final from t = 1 s; 0.1 m at t = 3 s is within 0.2
    assert m["time_to_converge_s"] == pytest.approx(2.0)


def test_mission_metrics_without_any_target_are_nan_and_unknown_status_null() -> None:
    s = _series()
    for name in ("target_n", "target_e", "target_d", "est_n", "est_e", "est_d"):
        s[name][:] = math.nan
    m = mission_metrics(s, 0.0, 0.2, status=None, orders_acknowledged=3)
    assert m["samples"] == 0
    assert all(math.isnan(v) for v in m["position_error_m"].values())
    assert math.isnan(m["time_to_converge_s"])
    assert math.isnan(m["final_target_s"])
    assert all(math.isnan(v) for v in m["yaw_error_deg"].values())
    assert math.isnan(m["estimate_error_m"]["mean"])
    assert (m["goals"], m["goals_reached"], m["orders_acknowledged"]) == (None, None, 3)


def test_new_series_columns_are_appended_at_the_end() -> None:
    assert SERIES_COLUMNS[:3] == ("t_s", "cmd_x", "cmd_y")
    assert SERIES_COLUMNS[-14:] == (
        "target_n",
        "target_e",
        "target_d",
        "target_yaw_deg",
        "est_n",
        "est_e",
        "est_d",
        "ee_n",
        "ee_e",
        "ee_d",
        "ee_target_n",
        "ee_target_e",
        "ee_target_d",
        "mode",
    )
    assert SERIES_COLUMNS.index("failsafe") == 31  # existing indices unchanged
