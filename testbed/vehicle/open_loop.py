"""An open-loop run of the plant: a constant body wrench, no thrusters, no controller.

:func:`simulate_open_loop` steps a :class:`~testbed.vehicle.physics.Physics` in open water with
one body wrench [N, N·m] (FRD, moments about the CoG) held throughout and returns every step's
state as an :class:`OpenLoopResult`: time [s], position of CO [m] NED, roll, pitch, yaw [rad]
and the body velocity [m/s, rad/s] FRD (the tests hold the plant to closed forms with it).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from testbed.common.geometry import euler_from_quat
from testbed.vehicle.hydrodynamics import load_model
from testbed.vehicle.physics import Physics

__all__ = ["OpenLoopResult", "simulate_open_loop"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, slots=True, eq=False)
class OpenLoopResult:
    """Samples of an open-loop run, one row per step including t = 0.

    Attributes:
        t: (N,) time [s].
        position_ned: (N, 3) position of CO [m], NED.
        euler_rad: (N, 3) roll, pitch, yaw [rad].
        nu: (N, 6) body velocity [u v w p q r] [m/s, rad/s], FRD.
    """

    t: FloatArray
    position_ned: FloatArray
    euler_rad: FloatArray
    nu: FloatArray


def simulate_open_loop(
    model: str,
    wrench_body: Sequence[float],
    duration_s: float,
    dt_s: float = 1.0 / 240.0,
    start_depth_m: float = 10.0,
) -> OpenLoopResult:
    """Apply a constant body wrench in open water (no thrusters, no controller) and record.

    Args:
        model: a packaged model name (see :func:`testbed.vehicle.hydrodynamics.known_models`).
        wrench_body: (6,) body wrench [N, N·m], FRD, moments about the CoG.
        duration_s: simulated time [s].
        dt_s: physics step [s].
        start_depth_m: initial depth of CO [m]; the vehicle starts level, at rest, heading north.

    Returns:
        One sample per step, t = 0 included.
    """
    wrench = tuple(float(c) for c in wrench_body)
    if len(wrench) != 6:
        raise ValueError(f"wrench_body must have 6 values, got {len(wrench)}")
    n_steps = round(duration_s / dt_s)
    samples = []
    with Physics(load_model(model), dt_s=dt_s, start_position_ned=(0.0, 0.0, start_depth_m)) as sim:
        samples.append(sim.state_floats())
        for _ in range(n_steps):
            sim.step(wrench)
            samples.append(sim.state_floats())
    return OpenLoopResult(
        t=np.array([s[0] for s in samples]),
        position_ned=np.array([s[1] for s in samples]),
        euler_rad=np.array([euler_from_quat(s[2]) for s in samples]),
        nu=np.array([s[3] for s in samples]),
    )
