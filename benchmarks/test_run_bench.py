"""Benchmark: real-time factor of whole runs (operator, link, vehicle, recording).

Run: .venv/bin/python -m pytest benchmarks/test_run_bench.py -m benchmark --benchmark-enable -s
"""

from __future__ import annotations

import cProfile
import io
import pstats

import pytest

from benchmarks.test_vehicle_bench import SIM_S, interleaved_best, timed_floor
from testbed.run.runner import run_scenario
from testbed.run.scenario import load_scenario


@pytest.mark.benchmark
@pytest.mark.parametrize("name", ["s100-teleop-v1", "tether-teleop-v1", "ecs-yaw-4h-v1"])
def test_run_real_time_factor(name: str) -> None:
    """Whole runs and the floor, five interleaved rounds each (the machine's speed drifts)."""
    scenario = load_scenario(name)
    rtfs: list[float] = []

    def once() -> float:
        result = run_scenario(scenario, seed=0)
        rtfs.append(result.metrics["rtf"])
        return scenario.duration_s / result.metrics["rtf"]

    run_scenario(load_scenario(name, ["duration_s=12", "metrics.settle_s=1"]), seed=0)  # warm
    best = interleaved_best({"floor": lambda: timed_floor(SIM_S), "run": once}, 5)
    floor_rtf = SIM_S / best["floor"]
    print(
        f"\n{name}: {scenario.duration_s:.0f} s simulated, real-time factor best {max(rtfs):.0f}x, "
        f"median {sorted(rtfs)[len(rtfs) // 2]:.0f}x (the bare pybullet floor, interleaved with "
        f"the runs: {floor_rtf:.0f}x)"
    )


@pytest.mark.benchmark
def test_profile_top_costs_s100() -> None:
    """Print the top cumulative costs of one s100-teleop-v1 run (for the README's notes)."""
    scenario = load_scenario("s100-teleop-v1", ["duration_s=60"])
    profiler = cProfile.Profile()
    profiler.enable()
    run_scenario(scenario, seed=0)
    profiler.disable()
    text = io.StringIO()
    pstats.Stats(profiler, stream=text).sort_stats("tottime").print_stats(12)
    print(text.getvalue())
