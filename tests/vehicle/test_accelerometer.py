"""The accelerometer as the navigation filter's prediction input.

Truth: a closed-form sinusoidal trajectory (its exact mean acceleration over each step is the
change of its analytic velocity), and the plant at rest released from neutral: its first
acceleration is the net buoyancy over the heave mass, (B − W)/(m − Z_ẇ), upwards.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from testbed.config import build
from testbed.vehicle.estimation import KalmanNavigator
from testbed.vehicle.filter_values import FilterConfig
from testbed.vehicle.vehicle import Vehicle
from testbed.vehicle.vehicle_config import VehicleConfig

AMP_M = np.array([1.0, 0.8, 0.3])
OMEGA_RAD_S = 2.0 * np.pi / np.array([20.0, 15.0, 25.0])


def position(t: float) -> np.ndarray:
    return AMP_M * np.sin(OMEGA_RAD_S * t)


def velocity(t: float) -> np.ndarray:
    return AMP_M * OMEGA_RAD_S * np.cos(OMEGA_RAD_S * t)


@pytest.mark.parametrize("with_input", [True, False])
def test_dead_reckoning_with_the_mean_acceleration_follows_the_trajectory(
    with_input: bool,
) -> None:
    """No measurement for 10 s: held over each step, the exact mean acceleration keeps the
    velocity exact and the position within O(Δt²) of the truth; without it the constant-velocity
    model drifts by the trajectory's own excursion."""
    nav = KalmanNavigator(
        FilterConfig(initial_position_sigma_m=1e-3, initial_velocity_sigma_m_s=1e-3),
        position_ned_m=tuple(position(0.0)),
        velocity_ned_m_s=tuple(velocity(0.0)),
    )
    t = 0.0
    for k in range(1000):
        dt = 1 / 120 if k % 2 else 1 / 80  # frames land 2 or 3 physics steps apart
        mean_accel = (velocity(t + dt) - velocity(t)) / dt
        t += dt
        nav.predict(t, mean_accel if with_input else None)
    error = float(np.linalg.norm(nav.state[:3] - position(t)))
    if with_input:
        assert error < 2e-3
    else:
        assert error > 0.1


def test_the_plants_first_acceleration_is_the_net_buoyancy_over_the_heave_mass() -> None:
    data = {
        "start_position_ned_m": [0.0, 0.0, 2.0],
        "navigation": {"accelerometer": {"noise_m_s2": 0.0}, "motion_capture": {}},
    }
    vehicle = Vehicle(build(VehicleConfig, data, source="test"), np.random.default_rng(0))
    vehicle.advance(0.03)
    model = vehicle.model
    expected = -(model.buoyancy_n - model.weight_n) / (model.mass_kg - model.added_mass[2])
    a = vehicle.truth.acceleration_ned_m_s2
    assert a[2] == pytest.approx(expected, rel=0.05)
    assert math.hypot(a[0], a[1]) < 1e-3 * abs(expected)
