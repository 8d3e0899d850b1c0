"""Camera speed: one capture (pose, TinyRenderer render, underwater grey) in the pool scene.

Reported as frames per second and milliseconds per frame (``extra_info``) at 160 x 120 and
320 x 240, with the default 2 x 2 supersampling and without it, from the vehicle's start pose
(the whole pool, the amphorae and the panel in view). Also the cost the scenery adds to a
physics step (it should add almost nothing: sleeping static bodies). Run:

    .venv/bin/python -m pytest benchmarks/test_camera_bench.py -m benchmark --benchmark-enable
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

from testbed.vehicle.camera import CameraConfig, camera_pose, underwater_grey
from testbed.vehicle.hydrodynamics import load_model
from testbed.vehicle.physics import Physics
from testbed.vehicle.scenery import pool_scenery


@pytest.fixture(scope="module")
def pool() -> Iterator[Physics]:
    with Physics(load_model("bluerov2"), start_position_ned=(0.0, 0.0, 0.5)) as sim:
        sim.add_scenery(pool_scenery())
        yield sim


@pytest.mark.benchmark
@pytest.mark.parametrize("supersampling", [2, 1])
@pytest.mark.parametrize(("width", "height"), [(160, 120), (320, 240)])
def test_capture(
    benchmark: Any, pool: Physics, width: int, height: int, supersampling: int
) -> None:
    config = CameraConfig(
        enabled=True, width_px=width, height_px=height, supersampling=supersampling
    )
    _, position, quaternion, _ = pool.state_floats()

    def capture() -> np.ndarray:
        pose = camera_pose(position, quaternion, config)
        rgb, zbuffer = pool.render(pose, config)
        return underwater_grey(rgb, zbuffer, config)

    image = benchmark(capture)
    assert image.shape == (height, width)
    mean_s = benchmark.stats.stats.mean
    benchmark.extra_info["frames_per_s"] = 1.0 / mean_s
    benchmark.extra_info["ms_per_frame"] = 1e3 * mean_s


@pytest.mark.benchmark
@pytest.mark.parametrize("scenery", [False, True])
def test_physics_step_with_scenery(benchmark: Any, scenery: bool) -> None:
    """Physics steps per second with and without the pool scenery in the client."""
    steps = 240
    wrench = [5.0, 0.0, -2.0, 0.0, 0.0, 0.1]
    with Physics(load_model("bluerov2"), start_position_ned=(0.0, 0.0, 1.5)) as sim:
        if scenery:
            sim.add_scenery(pool_scenery())

        def second() -> None:
            sim.reset()
            for _ in range(steps):
                sim.step(wrench)

        benchmark(second)
    benchmark.extra_info["steps_per_s"] = steps / benchmark.stats.stats.mean
