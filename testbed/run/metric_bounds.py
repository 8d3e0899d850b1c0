"""The values a metric of ``metrics.json`` can take, by its meaning: probabilities within
[0, 1], counts, rates, sizes, durations and magnitudes ≥ 0, the rest (signed errors, lags that
may lead) unbounded. Confidence intervals over runs are clipped to them
(:func:`testbed.run.metrics.mean_ci95`, :mod:`testbed.sweep.aggregate`, the sweep plots).
Standard library only.
"""

from __future__ import annotations

import math
from fnmatch import fnmatchcase

__all__ = ["NON_NEGATIVE_METRICS", "PROBABILITY_METRICS", "is_probability", "metric_bounds"]


PROBABILITY_METRICS = ("*.per", "*.drop_rate", "reply_fits_gap")
"""Flattened metrics (``fnmatch`` patterns) that are probabilities or shares, within [0, 1]: a
packet error rate, the share of frames a link dropped, a yes/no (its mean over runs is a
share)."""

NON_NEGATIVE_METRICS = (
    # counts: a number of things, never below 0
    "*.n",
    "link.*.frames_*",
    "link.*.copies_lost_transmitting",
    "arm.solves",
    "arm.limit_activations",
    "frames_rejected.*",
    "events.*",
    "images.captured",
    "images.completed",
    "images.undecodable",
    "images.bytes_delivered",
    "images.chunk_bytes",
    "mission.goals",
    "mission.goals_reached",
    "mission.goals_refused",
    "mission.orders_acknowledged",
    "mission.samples",
    "navigation.delivered.*",
    "navigation.lost.*",
    "navigation.filter.*",
    "navigation.by_source.*",
    # rates and sizes [bit/s, B, 1/min]
    "link.*.goodput_bps",
    "link.*.mean_frame_bytes",
    "link.*.mean_on_air_bytes",
    "images.per_minute",
    # durations, ages and lags of delivered things, times since the start [s]
    "sim_s",
    "ipg_s",
    "token_round_trip_s",
    "command_lag_s.*",
    "command_age_s.*",
    "odometry_age_s.*",
    "images.latency_s.*",
    "images.completion_interval_s.*",
    "mission.completion_s",
    "mission.final_target_s",
    "mission.time_to_converge_s",
    "mission.ready_s",
    # magnitudes: norms, RMS values, spreads, percentiles of absolute errors, energy used
    "velocity_tracking_rmse.*",
    "mission.position_error_m.*",
    "mission.estimate_error_m.*",
    "*.std",
    "attitude_error_deg.*.p95",
    "depth_error_m.p95",
    "mission.yaw_error_deg.p95",
    "energy_wh",
    "max_tilt_deg.*",
)
"""Flattened metrics (``fnmatch`` patterns) that cannot be negative by their meaning. Signed
ones are left out on purpose: ``signal_lag_s.*`` (the received stick may lead by up to half a
sample), the means of ``attitude_error_deg.*``, ``depth_error_m`` and ``mission.yaw_error_deg``
(signed errors), and anything not listed (no bound is assumed)."""


def is_probability(name: str) -> bool:
    """Whether a flattened metric (``link.uplink.per``) is a probability, within [0, 1]
    (:data:`PROBABILITY_METRICS`)."""
    return any(fnmatchcase(name, pattern) for pattern in PROBABILITY_METRICS)


def metric_bounds(name: str) -> tuple[float, float] | None:
    """The values a flattened metric can take: ``(0, 1)`` for a probability
    (:data:`PROBABILITY_METRICS`), ``(0, inf)`` for a quantity that cannot be negative
    (:data:`NON_NEGATIVE_METRICS`: counts, rates, sizes, durations, magnitudes), else None (a
    signed or unknown quantity). :func:`mean_ci95` clips confidence intervals to them."""
    if is_probability(name):
        return 0.0, 1.0
    if any(fnmatchcase(name, pattern) for pattern in NON_NEGATIVE_METRICS):
        return 0.0, math.inf
    return None
