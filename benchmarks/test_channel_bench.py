"""Real-time factor of ``testbed link`` on the s100 preset (the paper's link).

1000 frames of 60 B, one per second, BER 7e-6 (seed 0): ≈ 1000 s of simulated link per run.
Reported as real-time factor (simulated seconds per wall second) of the whole probe call
(``run_probe``: building the link, simulating, decoding, statistics) and of the simulation alone
(the probe's own ``rtf``), plus frames per second. Reference point: ns-3's UAN two-node ALOHA
link runs at ≈ 10⁵× real time in C++ (REFERENCE §5); the aim here is the same order. Run:

    .venv/bin/python -m pytest benchmarks/test_channel_bench.py -m benchmark --benchmark-enable
"""

from __future__ import annotations

import pytest
from pytest_benchmark.fixture import BenchmarkFixture

from testbed.channel.config import load_link_config
from testbed.channel.probe import ProbeResult, run_probe

FRAMES = 1000


@pytest.mark.benchmark
def test_link_probe_real_time_factor_s100(benchmark: BenchmarkFixture) -> None:
    config = load_link_config("s100")
    results: list[ProbeResult] = []

    def probe() -> None:
        results.append(run_probe(config, frames=FRAMES, frame_bytes=60, seed=0))

    benchmark.pedantic(probe, rounds=30, warmup_rounds=2)
    sim_s = results[-1].sim_s
    assert benchmark.stats is not None
    stats = benchmark.stats.stats
    for label, seconds in (("min", stats.min), ("median", stats.median)):
        rtf = sim_s / seconds
        benchmark.extra_info[f"rtf_probe_{label}"] = rtf
        benchmark.extra_info[f"frames_per_s_{label}"] = FRAMES / seconds
        print(
            f"\nlink probe s100 ({label}): {rtf:,.0f}× real time, {FRAMES / seconds:,.0f} frames/s"
        )
    sim_only = sorted(r.rtf for r in results)
    benchmark.extra_info["rtf_simulation_median"] = sim_only[len(sim_only) // 2]
    benchmark.extra_info["rtf_simulation_max"] = sim_only[-1]
    print(
        f"simulation alone: median {sim_only[len(sim_only) // 2]:,.0f}×, best {sim_only[-1]:,.0f}×"
    )
    # Same seed, same link: every run is identical apart from its timing.
    assert len({(r.frames_delivered, r.frames_corrupted, r.latency_s) for r in results}) == 1
    assert results[-1].frames_sent == FRAMES
