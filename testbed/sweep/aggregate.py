"""Reducing runs: a run's ``metrics.json`` to a flat row, and rows to per-point statistics.

:func:`flatten_metrics` turns nested metrics into dotted columns (``link.uplink.per``);
:func:`aggregate_rows` gives, per grid point and aggregated metric, the count, median, 95th
percentile, mean and 95 % Student-t confidence interval of the mean over its seeds
(``aggregate.csv``), clipped to the values the metric can take
(:func:`~testbed.run.metric_bounds.metric_bounds`: [0, 1] for probabilities such as ``*.per``, ≥ 0
for counts, rates, sizes, durations and magnitudes; :func:`~testbed.run.metrics.mean_ci95`
says why).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from testbed.config import ConfigError
from testbed.run.metric_bounds import metric_bounds
from testbed.run.metrics import mean_ci95
from testbed.sweep.journal import sorted_unique
from testbed.sweep.spec import RESERVED_COLUMNS, Sweep

__all__ = ["aggregate_rows", "flatten_metrics"]


def flatten_metrics(metrics: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """``metrics.json`` content → ``{"link.uplink.per": 0.0, ...}``: Python scalars only (numpy
    scalars converted), NaN and ±inf → None."""
    flat: dict[str, Any] = {}
    for key, value in metrics.items():
        dotted = f"{prefix}{key}"
        if isinstance(value, np.generic):  # numpy scalars → Python (and their plain repr)
            value = value.item()
        if isinstance(value, Mapping):
            flat.update(flatten_metrics(value, f"{dotted}."))
        elif isinstance(value, float) and not math.isfinite(value):
            flat[dotted] = None
        else:
            flat[dotted] = value
    return flat


def aggregate_rows(sweep: Sweep, rows: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """Per point: ``n_ok``, ``n_failed`` and, for each aggregated metric, ``n``, ``median``,
    ``p95``, ``mean``, ``ci_low``, ``ci_high`` (95 % Student-t interval of the mean, within
    the metric's bounds, :func:`~testbed.run.metric_bounds.metric_bounds`; None with fewer than two
    values). Missing values (None) are left
    out per metric.

    Raises:
        ConfigError: a metric no successful row has (listing the known ones).
    """
    rows = sorted_unique(rows)
    ok = [r for r in rows if r["status"] == "ok"]
    known = sorted({k for r in ok for k in r} - set(RESERVED_COLUMNS))
    for name in sweep.metrics:
        if ok and name not in known:
            raise ConfigError(
                f"{sweep.source}: metrics: unknown metric {name!r} (known: {', '.join(known)})"
            )
    table = []
    for index, point in enumerate(sweep.points):
        mine = [r for r in rows if r["point"] == index]
        good = [r for r in mine if r["status"] == "ok"]
        out: dict[str, Any] = {"point": index, **point}
        out["n_ok"], out["n_failed"] = len(good), len(mine) - len(good)
        for name in sweep.metrics:
            values = np.array([r[name] for r in good if r.get(name) is not None], dtype=float)
            n = values.size
            stat: dict[str, Any] = dict.fromkeys(("median", "p95", "mean", "ci_low", "ci_high"))
            if n:
                mean = float(values.mean())
                stat.update(median=float(np.median(values)), mean=mean)
                stat["p95"] = float(np.percentile(values, 95))
            if n >= 2:
                low, high = mean_ci95(values, metric_bounds(name))
                stat.update(ci_low=low, ci_high=high)
            out[f"{name}.n"] = n
            out.update({f"{name}.{k}": v for k, v in stat.items()})
        table.append(out)
    return table
