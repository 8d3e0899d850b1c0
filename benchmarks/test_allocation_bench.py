"""Allocation cost: calls per second, BlueROV2 (6 thrusters) and Heavy (8).

Two entry points: ``Allocator.step``, the frame's path (the compiled allocation, its commands
left in ``Allocator.output``), and ``Allocator.allocate``, the same allocation packaged as a
``ThrusterCommand`` (copies and the achieved wrench). The vehicle allocates once per 100 Hz
tick and its whole frame has a few µs per system. Two request mixes (2000 wrenches each, fixed
seed, slew limit on with dt = 10 ms):

* ``pilot``: mate-rov's pilot mapping (REFERENCE §3.6), u = x³ · 0.8 × the axis maximum with
  every stick x uniform in ±1 at once: mostly within limits, the current limit sometimes binds;
* ``saturating``: ±5 × the axis maxima on every axis: every call is scaled (saturation and the
  current limit).

Reported as calls per second and as the allocation-only real-time factor of a 100 Hz loop
(calls/s ÷ 100). Run:

    .venv/bin/python -m pytest benchmarks/test_allocation_bench.py -m benchmark --benchmark-enable
"""

from __future__ import annotations

import numpy as np
import pytest
from pytest_benchmark.fixture import BenchmarkFixture

from testbed.vehicle.allocation import Allocator
from testbed.vehicle.thrusters import T200, load_thruster_config

VEHICLE_RATE_HZ = 100.0
WRENCHES = 2000
DT_S = 1.0 / VEHICLE_RATE_HZ
MIXES = ("pilot", "saturating")


@pytest.mark.benchmark
@pytest.mark.parametrize("api", ["step", "allocate"])
@pytest.mark.parametrize("mix", MIXES)
@pytest.mark.parametrize("name", ["bluerov2", "bluerov2-heavy"])
def test_allocate_calls_per_second(
    benchmark: BenchmarkFixture, name: str, mix: str, api: str
) -> None:
    allocator = Allocator(load_thruster_config(name), T200.from_table())
    reach = allocator.axis_maxima_signed().max(axis=0)
    rng = np.random.default_rng(20250601)
    sticks = rng.uniform(-1.0, 1.0, (WRENCHES, 6))
    wrenches = (sticks**3 * 0.8 if mix == "pilot" else sticks * 5.0) * reach
    rows = list(wrenches)
    scales: list[float] = []

    def run() -> None:
        allocator.reset()
        scales.clear()
        if api == "step":
            step = allocator.step
            for wrench in rows:
                scales.append(step(wrench, DT_S))
        else:
            allocate = allocator.allocate
            for wrench in rows:
                scales.append(allocate(wrench, DT_S).scale)

    benchmark.pedantic(run, rounds=20, warmup_rounds=2)
    assert benchmark.stats is not None
    stats = benchmark.stats.stats
    for label, seconds in (("min", stats.min), ("median", stats.median)):
        rate = WRENCHES / seconds
        benchmark.extra_info[f"calls_per_s_{label}"] = rate
        benchmark.extra_info[f"realtime_factor_100hz_{label}"] = rate / VEHICLE_RATE_HZ
        print(
            f"\n{api} {name} {mix} ({label}): {rate:,.0f} calls/s = "
            f"{1e6 / rate:.1f} µs/call, {rate / VEHICLE_RATE_HZ:,.0f}× real time at 100 Hz"
        )
    limited = sum(scale < 1.0 for scale in scales) / WRENCHES
    benchmark.extra_info["fraction_scaled"] = limited
    print(f"fraction of calls scaled by saturation or current limit: {limited:.2f}")
    if mix == "saturating":
        assert limited == 1.0
    # A few microseconds (≈ 2 for step, 7 for allocate here): ≥ 50k calls/s even on a loaded
    # 2-core machine.
    assert WRENCHES / stats.median > 50_000
