"""The stick-tracking metrics (``signal_lag_s``, ``velocity_tracking_rmse``) through
:func:`compute_metrics` on a hand-made recording: a piloted vehicle's RMS error is computed by
hand; a vehicle under autonomy flies no sticks, so both are null rather than its RMS speed."""

from __future__ import annotations

import math

import numpy as np

from testbed.run.recorder import SERIES_COLUMNS, Recorder
from testbed.run.run_metrics import compute_metrics
from testbed.run.scenario import load_scenario


def _recording(n: int = 400) -> Recorder:
    """20 Hz rows from t = 0: armed, sticks centred (``rx_*`` = ``ref_*`` = 0) while the body
    moves at u = 0.05 + 0.02·sin(t), v = 0.01 m/s, r = 0.002 rad/s."""
    t = np.arange(n) / 20.0
    cols = {name: np.zeros(n) for name in SERIES_COLUMNS}
    cols["t_s"] = t
    cols["armed"] = np.ones(n)
    cols["u"] = 0.05 + 0.02 * np.sin(t)
    cols["v"] = np.full(n, 0.01)
    cols["r"] = np.full(n, 0.002)
    for name in SERIES_COLUMNS:
        if name.startswith(("target_", "est_", "ee_")):
            cols[name][:] = math.nan
    table = np.column_stack([cols[name] for name in SERIES_COLUMNS])
    return Recorder(rows=[tuple(row) for row in table.tolist()])


def _metrics(scenario_id: str, recorder: Recorder) -> dict[str, object]:
    scenario = load_scenario(scenario_id)
    return compute_metrics(
        scenario,
        0,
        recorder,
        sim_s=20.0,
        wall_s=1.0,
        energy_wh=0.0,
        payload_bytes={"uplink": 0, "downlink": 0},
    )


def test_a_piloted_vehicle_is_scored_against_the_velocity_its_sticks_ask_for() -> None:
    rec = _recording()
    metrics = _metrics("s100-teleop-v1", rec)
    series = rec.series()
    after = series["t_s"] >= load_scenario("s100-teleop-v1").metrics.settle_s
    expected_x = math.sqrt(float(np.mean(series["u"][after] ** 2)))  # demand 0: RMS(u)
    rmse = metrics["velocity_tracking_rmse"]
    assert isinstance(rmse, dict)
    assert rmse["x"] == expected_x
    assert math.isclose(rmse["y"], 0.01) and math.isclose(rmse["yaw"], 0.002)


def test_under_autonomy_the_stick_metrics_are_null() -> None:
    """The same recording under autonomy: the vehicle applied no stick, so there is no tracking
    error to report (before the fix, ``x`` was RMS(u) and ``y`` 0.01 m/s)."""
    metrics = _metrics("heavy-waypoint-v1", _recording())
    for key in ("velocity_tracking_rmse", "signal_lag_s"):
        figure = metrics[key]
        assert isinstance(figure, dict)
        assert set(figure) == {"x", "y", "z", "yaw"}
        assert all(math.isnan(value) for value in figure.values()), (key, figure)
