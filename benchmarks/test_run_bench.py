"""Benchmark: real-time factor of whole runs (operator, link, vehicle, recording).

Run: .venv/bin/python -m pytest benchmarks/test_run_bench.py -m benchmark --benchmark-enable -s
"""

from __future__ import annotations

import cProfile
import io
import pstats

import pytest

from benchmarks.test_vehicle_bench import SIM_S, bare_pybullet, best_of
from testbed.run.runner import run_scenario
from testbed.run.scenario import load_scenario


@pytest.mark.benchmark
@pytest.mark.parametrize("name", ["s100-teleop-v1", "tether-teleop-v1", "ecs-yaw-4h-v1"])
def test_run_real_time_factor(benchmark: pytest.FixtureRequest, name: str) -> None:
    scenario = load_scenario(name)
    rtfs: list[float] = []

    def once() -> None:
        rtfs.append(run_scenario(scenario, seed=0).metrics["rtf"])

    run_scenario(load_scenario(name, ["duration_s=12", "metrics.settle_s=1"]), seed=0)  # warm
    floor_rtf = SIM_S / best_of(lambda: bare_pybullet(SIM_S), rounds=3)
    benchmark.pedantic(once, rounds=3, iterations=1)  # type: ignore[attr-defined]
    best = max(rtfs)
    benchmark.extra_info["rtf_best"] = best  # type: ignore[attr-defined]
    benchmark.extra_info["bare_floor_rtf"] = floor_rtf  # type: ignore[attr-defined]
    print(
        f"\n{name}: {scenario.duration_s:.0f} s simulated, real-time factor best {best:.0f}x, "
        f"median {sorted(rtfs)[len(rtfs) // 2]:.0f}x (the bare pybullet floor measured in the "
        f"same process just before: {floor_rtf:.0f}x)"
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
