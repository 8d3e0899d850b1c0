"""Confidence intervals within the values a metric can take: [0, 1] for probabilities, ≥ 0 for
counts, rates, sizes, durations and magnitudes, free for signed quantities; checked against
scipy's Student-t interval and the keys a real run produces."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from testbed.run.metric_bounds import metric_bounds
from testbed.sweep import RunSpec, Sweep, aggregate_rows, execute_run

NON_NEGATIVE = [
    "images.per_minute",
    "images.bytes_delivered",
    "images.completed",
    "images.latency_s.mean",
    "events.failsafe",
    "link.uplink.frames_corrupted",
    "link.downlink.goodput_bps",
    "command_age_s.mean",
    "command_lag_s.p95",
    "velocity_tracking_rmse.z",
    "mission.completion_s",
    "mission.position_error_m.final",
    "attitude_error_deg.roll.std",
    "depth_error_m.p95",
    "energy_wh",
]
PROBABILITIES = ["link.uplink.per", "link.downlink.drop_rate"]
SIGNED = [
    "signal_lag_s.x",
    "attitude_error_deg.roll.mean",
    "depth_error_m.mean",
    "mission.yaw_error_deg.mean",
    "m",
]


def _scipy_interval(values: list[float]) -> tuple[float, float]:
    """The 95 % Student-t interval of the mean, by scipy (a second method)."""
    sample = np.asarray(values)
    low, high = stats.t.interval(0.95, sample.size - 1, loc=sample.mean(), scale=stats.sem(sample))
    return float(low), float(high)


@pytest.mark.parametrize(
    ("name", "low_bound", "high_bound"),
    [*((n, 0.0, math.inf) for n in NON_NEGATIVE), *((n, 0.0, 1.0) for n in PROBABILITIES)]
    + [(n, -math.inf, math.inf) for n in SIGNED],
)
def test_aggregate_intervals_are_scipys_clipped_to_the_metric_bounds(
    name: str, low_bound: float, high_bound: float
) -> None:
    """Two seeds 0.02 and 0.98 (and 0 and 2): scipy's t interval reaches below 0 (and above 1);
    aggregate.csv holds it clipped to what the metric can take, and only then."""
    for values in ([0.02, 0.98], [0.0, 2.0, 0.0]):
        sweep = Sweep(
            id="b-v1",
            description="",
            scenario="s100-teleop-v1",
            overrides=(),
            axes=(("link.ber", (0.0,)),),
            seeds=tuple(range(len(values))),
            metrics=(name,),
            source="b",
        )
        rows = [
            {"point": 0, "seed": s, "status": "ok", "error": "", name: v}
            for s, v in enumerate(values)
        ]
        (point,) = aggregate_rows(sweep, rows)
        low, high = _scipy_interval(values)
        assert low < 0.0  # the free interval holds impossible values for a bounded metric
        assert point[f"{name}.ci_low"] == pytest.approx(max(low, low_bound), abs=1e-12)
        assert point[f"{name}.ci_high"] == pytest.approx(min(high, high_bound), abs=1e-12)


def test_every_metric_of_a_real_run_is_classified_by_its_meaning() -> None:
    """The keys a real run writes: counts, rates, times and magnitudes are ≥ 0, PER and drop
    rates in [0, 1]; the signed ones (signal lag, mean attitude and depth errors) have no
    bound."""
    spec = RunSpec(0, 0, "s100-teleop-v1", ("duration_s=8.0", "metrics.settle_s=1.0"))
    outcome = execute_run(spec)
    assert outcome.metrics is not None, outcome.error
    for name in outcome.metrics:
        bounds = metric_bounds(name)
        last = name.rsplit(".", 1)[-1]
        if name.startswith("signal_lag_s.") or (
            name.startswith(("attitude_error", "depth_error")) and last == "mean"
        ):
            assert bounds is None, name
        elif last in ("per", "drop_rate") or isinstance(outcome.metrics[name], bool):
            assert bounds == (0.0, 1.0), name  # a yes/no: its mean over runs is a share
        else:
            assert bounds == (0.0, math.inf), name
