"""Scenario sweeps: a grid of scenario overrides × seeds, run as independent runs, resumable.

A sweep file (TOML, ``testbed/scenarios/sweeps/*.toml`` or any path) names a base scenario,
fixed overrides (``[set]``), a grid over any scenario keys (``[grid]``: lists of values, or
``{scale = "log" | "linear", start, stop, num, include = [...]}`` ranges), the seeds of every
point and the metrics to aggregate. :func:`expand` turns it into a deterministic run list:
points are the Cartesian product of the axes in file order (last axis fastest), and every
(point, seed) is one :class:`RunSpec`.

:func:`run_sweep` runs the specs through a backend — a local process pool or a
``dask.distributed`` cluster (an address, or ``"local"`` for a ``LocalCluster``) — and records
each finished run in ``OUT/runs.jsonl``: one JSON line per run, appended in batches with one
``write`` and an ``fsync``. A torn last line (a kill in the middle of a write) is cut off on
``--resume``, which skips every (point, seed) already recorded. ``OUT/results.csv`` (one row per
run: point, seed, grid values, status, error, flattened metrics; sorted by point and seed) and
``OUT/aggregate.csv`` (per point and metric: n, median, p95, mean and a 95 % Student-t
confidence interval of the mean) are regenerated from the journal by write-and-rename, so they
never hold a partial row. A run that raises is recorded with ``status = "failed"`` and its
error; the sweep goes on. ``wall_s`` and ``rtf`` are left out of the rows so that the same sweep
gives the same rows on any backend, interrupted or not. Runs with images also carry their
``images.chunk_bytes`` and ``images.selective_repeat`` (after the metrics), which the sweep
plots' closed forms need.

One module per concept:

- :mod:`~testbed.sweep.spec` — the sweep file, :class:`Sweep`, :class:`RunSpec`, :func:`expand`.
- :mod:`~testbed.sweep.keys` — the file's tables as scenario keys, :func:`toml_literal`.
- :mod:`~testbed.sweep.backends` — one run (:func:`execute_run`), process pool and Dask.
- :mod:`~testbed.sweep.journal` — ``runs.jsonl``, atomic writes, ``results.csv``.
- :mod:`~testbed.sweep.aggregate` — flattened metrics and ``aggregate.csv``'s statistics.
- :mod:`~testbed.sweep.progress` — the progress bar or line.
- :mod:`~testbed.sweep.runner` — :func:`run_sweep` and its :class:`SweepSummary`.

A top-level package (tests/test_layering.py): it may import every layer; only the CLI imports
it.
"""

from __future__ import annotations

from testbed.sweep.aggregate import aggregate_rows, flatten_metrics
from testbed.sweep.backends import (
    EXCLUDED_METRICS,
    SCENARIO_KEYS,
    RunOutcome,
    WorkerLostError,
    execute_run,
)
from testbed.sweep.journal import read_journal, results_csv
from testbed.sweep.keys import toml_literal
from testbed.sweep.runner import SweepSummary, format_summary, run_sweep
from testbed.sweep.spec import RangeSpec, RunSpec, Sweep, expand, load_sweep, sweep_names

__all__ = [
    "EXCLUDED_METRICS",
    "SCENARIO_KEYS",
    "RangeSpec",
    "RunOutcome",
    "RunSpec",
    "Sweep",
    "SweepSummary",
    "WorkerLostError",
    "aggregate_rows",
    "execute_run",
    "expand",
    "flatten_metrics",
    "format_summary",
    "load_sweep",
    "read_journal",
    "results_csv",
    "run_sweep",
    "sweep_names",
    "toml_literal",
]
