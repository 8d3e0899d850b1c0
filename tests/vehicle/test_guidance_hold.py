"""GUIDED's hold point without a goal (vehicle/guidance.py ``PositionController.latch_hold``):
ArduPilot's stopping point for a linear speed demand (AP_Math ``stopping_distance`` with
``accel_max → ∞``: ``min(|v|, max_speed) / kp`` ahead along the velocity), from the loop's own
fix-differenced velocity estimate, chosen once that estimate is formed.

Independent truth: noise-free fixes of a vehicle moving at a constant velocity, whose
low-passed estimate after ``k`` differences is ``v (1 − (1 − α)^k)`` (a first-order filter
from zero), with the stopping distance worked out here by hand.
"""

from __future__ import annotations

import math

import pytest

from testbed.vehicle.guidance import PositionController, PositionGains

RATE_HZ = 20.0
TAU_S = 0.15
ALPHA = (1.0 / RATE_HZ) / (TAU_S + 1.0 / RATE_HZ)  # 0.25


def _fly(loop: PositionController, velocity: tuple[float, float], fixes: int) -> int | None:
    """Feed ``fixes`` fixes of a vehicle at ``velocity`` from the origin; the index of the fix
    at which the hold point was chosen (None: never)."""
    for i in range(fixes):
        t = 1.0 + i / RATE_HZ
        if loop.latch_hold(t, (velocity[0] * (t - 1.0), velocity[1] * (t - 1.0))):
            return i
    return None


def test_the_point_is_the_stopping_point_of_the_formed_estimate() -> None:
    loop = PositionController(PositionGains(velocity_tau_s=TAU_S))
    velocity = (0.24, 0.18)  # 0.3 m/s, under the 0.5 m/s cap
    chosen = _fly(loop, velocity, 40)
    k = math.ceil(math.log(0.05) / math.log(1.0 - ALPHA))  # (1 − α)^k ≤ 5 %: 11
    assert chosen == k  # fix k is the k-th difference
    assert loop.hold_ne_m is not None
    t = chosen / RATE_HZ
    formed = 1.0 - (1.0 - ALPHA) ** k  # the estimate's share of the true velocity
    speed = 0.3 * formed
    ahead = speed / 0.8  # the loop's gain 0.8 /s
    expected = (0.24 * t + 0.8 * ahead, 0.18 * t + 0.6 * ahead)
    assert loop.hold_ne_m == pytest.approx(expected, abs=1e-12)
    _fly(loop, (0.0, 0.0), 5)  # later fixes do not move a chosen point
    assert loop.hold_ne_m == pytest.approx(expected, abs=1e-12)
    loop.reset()  # a lost fix or GUIDED left: forgotten
    assert loop.hold_ne_m is None


def test_a_faster_vehicle_stops_at_the_speed_caps_distance() -> None:
    loop = PositionController(PositionGains(velocity_tau_s=0.0))  # the estimate formed at once
    assert _fly(loop, (2.0, 0.0), 3) == 1
    assert loop.hold_ne_m == pytest.approx((0.1 + 0.5 / 0.8, 0.0), abs=1e-12)
