"""Benchmark: sweep throughput of the shipped ber-vs-lag-v1 at 60 s per run, 1 and 2 workers.

The issue's aim: 1,000 runs of 60 s in under 10 minutes on two cores (100 runs/min), and
near-linear scaling with workers. The subset is every grid point of ber-vs-lag-v1 (6 BER × 4
gaps) with seed 0 only: 24 runs of ``duration_s = 60``, ``metrics.settle_s = 10``, through
:func:`testbed.sweep.run_sweep` on the local process pool (spawned workers, journal and tables
written as in ``testbed sweep``). Reported: runs per minute for each worker count, their ratio
(2.0 would be linear), and the projected wall time of 1,000 such runs.

Run: .venv/bin/python -m pytest benchmarks/test_sweep_bench.py -m benchmark --benchmark-enable -s
"""

from __future__ import annotations

import dataclasses
import io
from pathlib import Path

import pytest

from testbed.sweep import load_sweep, run_sweep

OVERRIDES = ("duration_s=60", "metrics.settle_s=10")
SEEDS = (0,)
WORKERS = (1, 2)
TARGET_RUNS = 1000


@pytest.mark.benchmark
def test_ber_vs_lag_runs_per_minute(benchmark: pytest.FixtureRequest, tmp_path: Path) -> None:
    sweep = dataclasses.replace(load_sweep("ber-vs-lag-v1", OVERRIDES), seeds=SEEDS)
    runs = len(sweep.points) * len(SEEDS)
    rates: dict[int, float] = {}

    def both() -> None:
        for workers in WORKERS:
            out = tmp_path / f"w{workers}-{len(rates)}"
            summary = run_sweep(sweep, out, workers=workers, stream=io.StringIO())
            assert summary.ran == runs and not summary.failed
            rates[workers] = 60.0 * runs / summary.wall_s

    benchmark.pedantic(both, rounds=1, iterations=1)  # type: ignore[attr-defined]
    ratio = rates[2] / rates[1]
    projected_min = TARGET_RUNS / rates[2]
    benchmark.extra_info.update(  # type: ignore[attr-defined]
        runs_per_min_1=rates[1], runs_per_min_2=rates[2], scaling=ratio
    )
    print(
        f"\nber-vs-lag-v1, {runs} runs of 60 s: 1 worker {rates[1]:.1f} runs/min, "
        f"2 workers {rates[2]:.1f} runs/min, scaling {ratio:.2f}x; "
        f"{TARGET_RUNS} runs on 2 workers ≈ {projected_min:.1f} min"
    )
    assert ratio > 1.0  # two workers must beat one
