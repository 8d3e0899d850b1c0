"""The water current: a constant NED velocity plus an optional slow Gauss–Markov variation.

:class:`WaterCurrent` holds the parameters (part of a vehicle's configuration);
:class:`CurrentProcess` is its running state, which :mod:`testbed.vehicle.physics` advances and
feeds to the force law as the relative velocity ν_r = ν − ν_c. Velocities in world NED [m/s].
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from testbed.config import check, check_range, check_ranges

__all__ = ["CurrentProcess", "WaterCurrent"]

Vec3 = tuple[float, float, float]

MAX_CURRENT_SPEED_MPS = 5.0
"""Largest accepted mean current speed [m/s]: the fastest tidal races; a BlueROV2 manages ≈ 1."""


@dataclass(frozen=True, slots=True)
class WaterCurrent:
    """A water current: a constant NED velocity plus an optional slow Gauss–Markov variation.

    Each NED component of the variation is a first-order Gauss–Markov process
    ẋ = −x/T + w (Fossen 2011, §8.3), sampled exactly every ``update_period_s`` and held in
    between, so the current is irrotational and piecewise constant in NED.

    Domains: ``velocity_ned_mps`` finite with speed ≤ 5 m/s (the fastest tidal races);
    ``variation_std_mps`` in [0, 1] m/s per component; ``time_constant_s`` in (0, 86400] s;
    ``update_period_s`` in [1e-3, 3600] s.

    Attributes:
        velocity_ned_mps: (3,) mean water velocity [m/s], NED.
        variation_std_mps: (3,) stationary standard deviation of each component's variation [m/s].
        time_constant_s: correlation time T of the variation [s].
        update_period_s: how often the variation is sampled [s].
    """

    velocity_ned_mps: Vec3 = (0.0, 0.0, 0.0)
    variation_std_mps: Vec3 = (0.0, 0.0, 0.0)
    time_constant_s: float = 120.0
    update_period_s: float = 0.5

    def __post_init__(self) -> None:
        limit = MAX_CURRENT_SPEED_MPS
        check_ranges(self.velocity_ned_mps, "velocity_ned_mps", -limit, limit, "m/s")
        speed = math.hypot(*self.velocity_ned_mps)
        check(
            speed <= limit,
            "velocity_ned_mps",
            f"speed must be ≤ {limit:g} m/s, got {speed:g} m/s",
        )
        check_ranges(self.variation_std_mps, "variation_std_mps", 0.0, 1.0, "m/s")
        check_range(self.time_constant_s, "time_constant_s", 0.0, 86400.0, "s", low_open=True)
        check_range(self.update_period_s, "update_period_s", 1e-3, 3600.0, "s")

    @property
    def varies(self) -> bool:
        """Whether the current has a random variation."""
        return any(value > 0.0 for value in self.variation_std_mps)


class CurrentProcess:
    """The running state of a :class:`WaterCurrent`: its NED velocity now.

    Args:
        current: the current's parameters.
        rng: the generator driving the variation (required when the current varies).

    Raises:
        ValueError: the current varies and no generator was given.
    """

    def __init__(self, current: WaterCurrent, rng: np.random.Generator | None = None) -> None:
        if current.varies and rng is None:
            raise ValueError("a varying WaterCurrent needs a numpy Generator (rng=...)")
        self._current = current
        self._rng = rng
        self._std = np.asarray(current.variation_std_mps, dtype=float)
        # Start in the stationary distribution, as if the process had always been running.
        self._deviation = (
            self._std * rng.standard_normal(3) if current.varies and rng is not None else None
        )
        self.velocity_ned: Vec3 = self._velocity()

    def _velocity(self) -> Vec3:
        mean = self._current.velocity_ned_mps
        if self._deviation is None:
            return (float(mean[0]), float(mean[1]), float(mean[2]))
        vx, vy, vz = (np.asarray(mean) + self._deviation).tolist()
        return (vx, vy, vz)

    def advance(self, dt_s: float) -> Vec3:
        """Advance the variation by ``dt_s`` (exact discretisation); the velocity [m/s], NED."""
        if self._deviation is not None and self._rng is not None:
            phi = math.exp(-dt_s / self._current.time_constant_s)
            noise = self._std * math.sqrt(1.0 - phi * phi) * self._rng.standard_normal(3)
            self._deviation = phi * self._deviation + noise
            self.velocity_ned = self._velocity()
        return self.velocity_ned
