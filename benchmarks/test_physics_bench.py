"""Physics step cost: our Fossen plant against the bare pybullet floor it stands on.

Two workloads, each one simulated second at 240 Hz (240 steps) per round:

* ``bare floor``: pybullet DIRECT, one body, read pose and velocity, apply a force and a torque,
  step (REFERENCE §5 measured 6.5 µs/step, ≈ 640× real time on this kind of machine);
* ``physics``: :meth:`Physics.step` with the full Fossen forces (added mass solved exactly,
  Coriolis, damping, restoring, free surface), default BlueROV2; also with a water current.

Reported as real-time factors (simulated seconds per wall second) and as the ratio of the two,
measured interleaved in the same run so machine noise hits both alike. The vehicle as a whole
must reach ≥ 300× real time within 2× of the bare floor, so the plant may cost only a few µs
above it. Run:

    .venv/bin/python -m pytest benchmarks/test_physics_bench.py -m benchmark --benchmark-enable -s
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable, Iterator

import numpy as np
import pybullet
import pytest
from pytest_benchmark.fixture import BenchmarkFixture

from testbed.vehicle.hydrodynamics import load_model
from testbed.vehicle.physics import Physics
from testbed.vehicle.water_current import WaterCurrent

pytestmark = pytest.mark.benchmark

STEPS_PER_ROUND = 240
DT_S = 1.0 / 240.0
WRENCH = (5.0, 1.0, 2.0, 0.05, -0.02, 0.3)


class BareFloor:
    """One 11.5 kg box in its own DIRECT client, gravity off, pushed and read each step."""

    def __init__(self) -> None:
        self.client = pybullet.connect(pybullet.DIRECT)
        pybullet.setGravity(0.0, 0.0, 0.0, physicsClientId=self.client)
        pybullet.setPhysicsEngineParameter(fixedTimeStep=DT_S, physicsClientId=self.client)
        shape = pybullet.createCollisionShape(
            pybullet.GEOM_BOX, halfExtents=[0.23, 0.17, 0.127], physicsClientId=self.client
        )
        self.body = pybullet.createMultiBody(
            11.5, shape, -1, [0.0, 0.0, -10.0], physicsClientId=self.client
        )
        pybullet.changeDynamics(
            self.body,
            -1,
            linearDamping=0.0,
            angularDamping=0.0,
            activationState=pybullet.ACTIVATION_STATE_DISABLE_SLEEPING,
            physicsClientId=self.client,
        )

    def second(self) -> None:
        client, body = self.client, self.body
        get_pose = pybullet.getBasePositionAndOrientation
        get_velocity = pybullet.getBaseVelocity
        apply_force = pybullet.applyExternalForce
        apply_torque = pybullet.applyExternalTorque
        step = pybullet.stepSimulation
        link_frame = pybullet.LINK_FRAME
        for _ in range(STEPS_PER_ROUND):
            get_pose(body, client)
            get_velocity(body, client)
            apply_force(body, -1, (1.0, 0.0, 0.0), (0.0, 0.0, 0.0), link_frame, client)
            apply_torque(body, -1, (0.0, 0.0, 0.01), link_frame, client)
            step(client)

    def close(self) -> None:
        pybullet.disconnect(self.client)


def physics_second(sim: Physics) -> Callable[[], None]:
    def second() -> None:
        step = sim.step
        for _ in range(STEPS_PER_ROUND):
            step(WRENCH)

    return second


@pytest.fixture
def floor() -> Iterator[BareFloor]:
    bare = BareFloor()
    yield bare
    bare.close()


@pytest.fixture
def plant() -> Iterator[Physics]:
    with Physics(load_model("bluerov2")) as sim:
        yield sim


def rtf(seconds_per_round: float) -> float:
    """Simulated seconds per wall second of one round."""
    return STEPS_PER_ROUND * DT_S / seconds_per_round


def median_rtf(benchmark: BenchmarkFixture) -> float:
    assert benchmark.stats is not None
    return rtf(benchmark.stats.stats.median)


def test_bare_pybullet_floor(benchmark: BenchmarkFixture, floor: BareFloor) -> None:
    benchmark.pedantic(floor.second, rounds=60, warmup_rounds=3)
    benchmark.extra_info["rtf"] = median_rtf(benchmark)


def test_physics_step(benchmark: BenchmarkFixture, plant: Physics) -> None:
    benchmark.pedantic(physics_second(plant), rounds=60, warmup_rounds=3)
    benchmark.extra_info["rtf"] = median_rtf(benchmark)


def test_physics_step_with_varying_current(benchmark: BenchmarkFixture) -> None:
    current = WaterCurrent((0.3, 0.1, 0.0), variation_std_mps=(0.05, 0.05, 0.0))
    with Physics(load_model("bluerov2"), current=current, rng=np.random.default_rng(0)) as sim:
        benchmark.pedantic(physics_second(sim), rounds=60, warmup_rounds=3)
    benchmark.extra_info["rtf"] = median_rtf(benchmark)


def test_physics_against_bare_floor(
    benchmark: BenchmarkFixture, floor: BareFloor, plant: Physics
) -> None:
    """Interleaved rounds of both; the ratio of medians is what survives a noisy machine."""
    floor_s: list[float] = []
    plant_s: list[float] = []
    plant_round = physics_second(plant)

    def pair() -> None:
        start = time.perf_counter()
        floor.second()
        middle = time.perf_counter()
        plant_round()
        floor_s.append(middle - start)
        plant_s.append(time.perf_counter() - middle)

    benchmark.pedantic(pair, rounds=100, warmup_rounds=5)
    floor_rtf = rtf(statistics.median(floor_s))
    plant_rtf = rtf(statistics.median(plant_s))
    ratio = floor_rtf / plant_rtf
    overhead_us = (statistics.median(plant_s) - statistics.median(floor_s)) / STEPS_PER_ROUND * 1e6
    benchmark.extra_info.update(
        floor_rtf=floor_rtf, physics_rtf=plant_rtf, ratio=ratio, overhead_us_per_step=overhead_us
    )
    print(
        f"\nbare floor {floor_rtf:.0f}x real time, physics {plant_rtf:.0f}x, "
        f"ratio {ratio:.2f}, Fossen overhead {overhead_us:.1f} us/step"
    )
    # A NumPy tiny-array path would be ~6x the floor (REFERENCE §5); guard against that.
    assert ratio < 2.5
