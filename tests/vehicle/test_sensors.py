"""testbed.vehicle.sensors: noise statistics, rates, pressure/depth conversion, determinism."""

from __future__ import annotations

import math

import numpy as np
import pytest

from testbed.common.geometry import attitude_error, quat_from_euler
from testbed.config import ConfigError, build
from testbed.vehicle.sensors import (
    DepthSensor,
    DepthSensorConfig,
    Imu,
    ImuConfig,
    PositionFix,
    PositionFixConfig,
    baro_depth_m,
    baro_pressure_pa,
)


def run_imu(config: ImuConfig, n: int, seed: int = 1) -> tuple[np.ndarray, np.ndarray]:
    imu = Imu(config, np.random.default_rng(seed))
    # level truth: heading noise (about world down) and roll/pitch noise (body x, y) separate
    truth = quat_from_euler(0.0, 0.0, 2.0)
    errors, rates = [], []
    for k in range(n):
        t = k / config.rate_hz
        reading = imu.sample(t, truth, (0.1, -0.2, 0.3))
        assert reading.time_s == t
        errors.append(attitude_error(reading.quaternion_wxyz, truth))
        rates.append(reading.rates_rad_s)
    return np.array(errors), np.array(rates) - (0.1, -0.2, 0.3)


def test_imu_white_noise_statistics() -> None:
    cfg = ImuConfig(
        attitude_noise_rad=math.radians(0.2),
        heading_noise_rad=math.radians(0.5),
        gyro_noise_rad_s=0.01,
    )
    errors, rate_errors = run_imu(cfg, 20000)
    n = len(errors)
    tol = 4.0 / math.sqrt(2 * n)  # ~4σ of a sample std
    expected = (cfg.attitude_noise_rad, cfg.attitude_noise_rad, cfg.heading_noise_rad)
    for k in range(3):
        assert errors[:, k].std() == pytest.approx(expected[k], rel=tol)
        assert abs(errors[:, k].mean()) < 4 * expected[k] / math.sqrt(n)
        assert rate_errors[:, k].std() == pytest.approx(0.01, rel=tol)
    lag1 = np.corrcoef(errors[1:, 2], errors[:-1, 2])[0, 1]
    assert abs(lag1) < 4 / math.sqrt(n)


def test_imu_correlated_noise_is_gauss_markov() -> None:
    cfg = ImuConfig(heading_noise_rad=math.radians(0.5), correlation_time_s=0.5)
    errors, _ = run_imu(cfg, 40000)
    heading = errors[:, 2]
    lag1 = np.corrcoef(heading[1:], heading[:-1])[0, 1]
    assert lag1 == pytest.approx(math.exp(-0.01 / 0.5), abs=0.005)
    # stationary spread (effective samples ≈ n·(1−ρ)/(1+ρ) ≈ 400)
    assert heading.std() == pytest.approx(cfg.heading_noise_rad, rel=0.15)


def test_noise_draws_follow_the_generator_across_blocks() -> None:
    """The gyro noise of reading k is g times draws 3 + 6k + (3, 4, 5) of the sensor's generator
    (three draws seed the attitude errors, then six per reading): the sensors draw in blocks of
    1024, and 400 readings cross two of them."""
    cfg = ImuConfig(gyro_noise_rad_s=0.01)
    imu = Imu(cfg, np.random.default_rng(7))
    draws = np.random.default_rng(7).standard_normal(3 + 6 * 400)
    truth = (0.1, -0.2, 0.3)
    for k in range(400):
        rates = imu.sample(k * 0.01, (1.0, 0.0, 0.0, 0.0), truth).rates_rad_s
        gyro = draws[3 + 6 * k + 3 : 3 + 6 * k + 6]
        assert rates == tuple(float(t + 0.01 * n) for t, n in zip(truth, gyro, strict=True))
    depth = DepthSensor(DepthSensorConfig(noise_pa=20.0), np.random.default_rng(8))
    pressure_draws = np.random.default_rng(8).standard_normal(2500)
    for k in range(2500):
        reading = depth.sample(k * 0.01, 2.0)
        expected = baro_pressure_pa(2.0) + 20.0 * float(pressure_draws[k])
        assert reading.pressure_pa == expected


def test_zero_noise_imu_reads_truth() -> None:
    cfg = ImuConfig(attitude_noise_rad=0.0, heading_noise_rad=0.0, gyro_noise_rad_s=0.0)
    imu = Imu(cfg, np.random.default_rng(0))
    truth = quat_from_euler(0.1, 0.2, 0.3)
    reading = imu.sample(0.0, truth, (1.0, 2.0, 3.0))
    np.testing.assert_allclose(reading.quaternion_wxyz, truth, atol=1e-15)
    assert reading.rates_rad_s == (1.0, 2.0, 3.0)


def test_sensor_rates_when_polled_at_physics_rate() -> None:
    imu = Imu(ImuConfig(rate_hz=100.0), np.random.default_rng(0))
    depth = DepthSensor(DepthSensorConfig(rate_hz=50.0), np.random.default_rng(1))
    fix = PositionFix(PositionFixConfig(rate_hz=10.0), np.random.default_rng(2))
    counts = [0, 0, 0]
    for k in range(2400):  # 10 s at 240 Hz
        t = k / 240.0
        if imu.due(t):
            imu.sample(t, (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
            counts[0] += 1
        if depth.due(t):
            depth.sample(t, 1.0)
            counts[1] += 1
        if fix.due(t):
            fix.sample(t, (0.0, 0.0, 1.0))
            counts[2] += 1
    assert counts == [1000, 500, 100]


def test_late_poll_does_not_burst() -> None:
    depth = DepthSensor(DepthSensorConfig(rate_hz=100.0), np.random.default_rng(0))
    depth.sample(0.0, 1.0)
    assert depth.due(5.0)
    depth.sample(5.0, 1.0)
    assert not depth.due(5.005)
    assert depth.due(5.01)


def test_baro_conversion_matches_ardusub_formula() -> None:
    # ArduSub: press_abs [hPa] = p_surface + 98·SG·depth when ρg = 9800·SG
    p = baro_pressure_pa(3.0, water_density_kg_m3=1024.0, gravity_m_s2=9.8 / 1.0)
    assert p == pytest.approx(101325.0 + 100 * 98 * 1.024 * 3.0)
    assert baro_depth_m(p, spec_grav=1.024) == pytest.approx(3.0)
    assert baro_pressure_pa(-0.5) == 101325.0  # out of the water


@pytest.mark.parametrize(
    ("density", "spec_grav", "factor"),
    [
        (1000.0, 1.0, 9.80665 / 9.8),  # fresh, fresh setting: g vs ArduSub's 9.8
        (1025.0, 1.024, 1025 * 9.80665 / (9800 * 1.024)),  # salt, salt setting
        (1025.0, 1.0, 1025 * 9.80665 / 9800),  # sea water read with the fresh setting: 2.6 % deep
    ],
)
def test_depth_sensor_scale_by_water_and_setting(
    density: float, spec_grav: float, factor: float
) -> None:
    cfg = DepthSensorConfig(noise_pa=0.0, water_density_kg_m3=density, spec_grav=spec_grav)
    reading = DepthSensor(cfg, np.random.default_rng(0)).sample(0.0, 2.0)
    assert reading.depth_m == pytest.approx(2.0 * factor, rel=1e-12)
    assert reading.pressure_pa == pytest.approx(101325.0 + density * 9.80665 * 2.0)


def test_depth_noise_statistics() -> None:
    cfg = DepthSensorConfig(noise_pa=30.0)
    sensor = DepthSensor(cfg, np.random.default_rng(3))
    depths = np.array([sensor.sample(k * 0.01, 1.0).depth_m for k in range(10000)])
    assert depths.std() == pytest.approx(30.0 / 9800.0, rel=0.05)
    assert depths.mean() == pytest.approx(9.80665 / 9.8, abs=1e-4)


def test_position_fix_noise_and_determinism() -> None:
    cfg = PositionFixConfig(noise_m=0.01)
    a = PositionFix(cfg, np.random.default_rng(9))
    b = PositionFix(cfg, np.random.default_rng(9))
    fixes = []
    for k in range(5000):
        ra = a.sample(k * 0.05, (1.0, 2.0, 3.0))
        assert ra == b.sample(k * 0.05, (1.0, 2.0, 3.0))
        fixes.append(ra.position_ned_m)
    arr = np.array(fixes) - (1.0, 2.0, 3.0)
    np.testing.assert_allclose(arr.std(axis=0), 0.01, rtol=0.06)
    np.testing.assert_allclose(arr.mean(axis=0), 0.0, atol=4 * 0.01 / math.sqrt(5000))


def test_sensor_configs_reject_bad_values() -> None:
    with pytest.raises(ConfigError, match="rate_hz"):
        build(ImuConfig, {"rate_hz": 0})
    with pytest.raises(ConfigError, match="noise_pa"):
        build(DepthSensorConfig, {"noise_pa": -1})
    with pytest.raises(ConfigError, match="unknown key"):
        build(PositionFixConfig, {"rate": 1})
