"""The kinematic pose law (testbed.vehicle.kinematic) against hand-derived values and scipy's
rotations: frames, the norm limit, yaw wrapping, levelling and its closed-loop decay."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from testbed.common.geometry import euler_from_quat, quat_from_euler, quat_multiply
from testbed.config import FieldError
from testbed.vehicle.kinematic import PoseGains, pose_twist

LEVEL = (1.0, 0.0, 0.0, 0.0)
GAINS = PoseGains(k_position_1_s=0.5, k_yaw_1_s=0.8, k_level_1_s=1.0, max_speed_m_s=1.0)


def test_north_error_at_yaw_90_is_the_bodys_minus_y() -> None:
    # heading east: body x → east, body y (right, FRD) → south, so north is −y
    twist = pose_twist(
        (1.0, 0.0, 0.0), None, (0.0, 0.0, 0.0), quat_from_euler(0, 0, math.pi / 2), GAINS
    )
    assert twist == pytest.approx((0.0, -0.5, 0.0, 0.0, 0.0, 0.0), abs=1e-12)
    # down error at level is +w (FRD z down); east error at yaw 0 is +v
    assert pose_twist((0.0, 0.4, 0.6), None, (0.0, 0.0, 0.0), LEVEL, GAINS)[:3] == pytest.approx(
        (0.0, 0.2, 0.3)
    )


def test_linear_twist_is_r_transposed_times_the_world_demand_at_any_attitude() -> None:
    rng = np.random.default_rng(11)
    for _ in range(10):
        roll, pitch, yaw = rng.uniform(-0.5, 0.5), rng.uniform(-0.5, 0.5), rng.uniform(-3, 3)
        q = quat_from_euler(roll, pitch, yaw)
        target, here, ff = rng.normal(0, 0.3, 3), rng.normal(0, 0.3, 3), rng.normal(0, 0.1, 3)
        twist = pose_twist(target.tolist(), None, here.tolist(), q, GAINS, ff.tolist())
        r = Rotation.from_euler("ZYX", [yaw, pitch, roll])  # body → NED
        expected = r.inv().apply(0.5 * (target - here) + ff)
        assert np.linalg.norm(expected) < GAINS.max_speed_m_s  # unsaturated draws
        np.testing.assert_allclose(twist[:3], expected, atol=1e-12)


def test_saturation_keeps_the_direction_and_limits_the_norm() -> None:
    q = quat_from_euler(0.1, -0.2, 0.7)
    far = pose_twist((30.0, -40.0, 10.0), None, (0.0, 0.0, 0.0), q, GAINS)
    near = pose_twist((0.3, -0.4, 0.1), None, (0.0, 0.0, 0.0), q, GAINS)
    lin_far, lin_near = np.array(far[:3]), np.array(near[:3])
    assert np.linalg.norm(lin_far) == pytest.approx(GAINS.max_speed_m_s)
    np.testing.assert_allclose(
        lin_far / np.linalg.norm(lin_far), lin_near / np.linalg.norm(lin_near)
    )
    # a feed-forward alone is limited too
    fast = pose_twist((0.0, 0.0, 0.0), None, (0.0, 0.0, 0.0), LEVEL, GAINS, (3.0, 0.0, 0.0))
    assert fast[:3] == pytest.approx((1.0, 0.0, 0.0))


def test_yaw_error_wraps_the_short_way_and_clamps() -> None:
    here = quat_from_euler(0.0, 0.0, math.radians(-179.0))
    twist = pose_twist((0.0, 0.0, 0.0), math.radians(179.0), (0.0, 0.0, 0.0), here, GAINS)
    assert twist[5] == pytest.approx(0.8 * math.radians(-2.0))  # −2°, not +358°
    twist = pose_twist((0.0, 0.0, 0.0), math.radians(-170.0), (0.0, 0.0, 0.0), here, GAINS)
    assert twist[5] == pytest.approx(0.8 * math.radians(9.0))
    big = pose_twist((0.0, 0.0, 0.0), 2.0, (0.0, 0.0, 0.0), LEVEL, GAINS)
    assert big[5] == pytest.approx(GAINS.max_yaw_rate_rad_s)
    none = pose_twist((0.0, 0.0, 0.0), None, (0.0, 0.0, 0.0), here, GAINS)
    assert none == pytest.approx((0.0,) * 6, abs=1e-15)


def test_roll_and_pitch_are_commanded_back_to_level() -> None:
    twist = pose_twist((0, 0, 0), None, (0, 0, 0), quat_from_euler(0.2, 0.0, 1.0), GAINS)
    assert twist[3:] == pytest.approx((-0.2, 0.0, 0.0), abs=1e-12)
    twist = pose_twist((0, 0, 0), None, (0, 0, 0), quat_from_euler(0.0, -0.3, 0.0), GAINS)
    assert twist[3:] == pytest.approx((0.0, 0.3, 0.0), abs=1e-12)


def test_closed_loop_attitude_decays_exponentially_per_euler_angle() -> None:
    """Integrating q̇ = ½·q⊗(0, ω) under the law: each Euler angle error decays as exp(−k·t)
    (the body rates are T⁻¹ of the demanded Euler rates)."""
    gains = PoseGains(
        k_yaw_1_s=0.8, k_level_1_s=1.0, max_yaw_rate_rad_s=3.0, max_level_rate_rad_s=3.0
    )
    start = (0.3, -0.25, 0.0)
    target_yaw = 1.0
    q = quat_from_euler(*start)
    dt, steps = 1e-3, 1000
    for _ in range(steps):
        _, _, _, p, qq, r = pose_twist((0, 0, 0), target_yaw, (0, 0, 0), q, gains)
        angle = math.sqrt(p * p + qq * qq + r * r) * dt  # exact step for the held rate
        if angle > 0.0:
            axis = (p * dt / angle, qq * dt / angle, r * dt / angle)
            half = 0.5 * angle
            sh = math.sin(half)
            step = (math.cos(half), axis[0] * sh, axis[1] * sh, axis[2] * sh)
            q = quat_multiply(q, step)  # body-frame rates: right multiplication
    roll, pitch, yaw = euler_from_quat(q)
    t = steps * dt
    assert roll == pytest.approx(start[0] * math.exp(-1.0 * t), rel=2e-3)
    assert pitch == pytest.approx(start[1] * math.exp(-1.0 * t), rel=2e-3)
    assert yaw - target_yaw == pytest.approx(-target_yaw * math.exp(-0.8 * t), rel=2e-3)


def test_gains_are_validated() -> None:
    for key, value in (
        ("k_position_1_s", 0.0),
        ("k_yaw_1_s", -1.0),
        ("k_level_1_s", math.nan),
        ("max_speed_m_s", 5.0),
        ("max_yaw_rate_rad_s", 0.0),
        ("max_level_rate_rad_s", math.inf),
    ):
        with pytest.raises(FieldError, match=key):
            PoseGains(**{key: value})
    assert PoseGains(k_level_1_s=0.0).k_level_1_s == 0.0


def test_a_turning_target_is_followed_without_lag_with_its_rate_fed_forward() -> None:
    """ψ*(t) = ω·t from ψ(0) = 0, integrating ψ̇ = r (level, so r = ψ̇_d) with the law's yaw rate:
    with ψ̇_ff = ω the error stays 0; without it, it is the closed form
    e(t) = (ω/k)·(1 − exp(−k·t)), 18° behind at 9°/s and k 0.5 once settled."""
    gains = PoseGains(k_yaw_1_s=0.5)
    omega, dt = math.radians(9.0), 1e-3
    for feedforward in (True, False):
        yaw = 0.0
        for step in range(20_000):  # 20 s, explicit Euler
            target = omega * step * dt
            q = quat_from_euler(0.0, 0.0, yaw)
            rate = omega if feedforward else 0.0
            twist = pose_twist((0.0, 0.0, 0.0), target, (0.0, 0.0, 0.0), q, gains, None, rate)
            yaw += twist[5] * dt
        error = omega * 20.0 - yaw
        if feedforward:
            assert abs(error) < 1e-9
        else:
            # explicit Euler at 1 ms: within 0.1 % of the closed form
            expected = omega / 0.5 * (1.0 - math.exp(-0.5 * 20.0))
            assert error == pytest.approx(expected, rel=1e-3)
            assert math.degrees(error) == pytest.approx(18.0, abs=0.02)
