"""testbed.vehicle.nav_sensors: rates, noise, delays, bottom lock, and the NavSource seam."""

from __future__ import annotations

import math

import numpy as np
import pytest

from testbed.common.components import ImuReading
from testbed.common.geometry import quat_from_euler
from testbed.config import ConfigError, build
from testbed.ecs import World
from testbed.vehicle.control import (
    AttitudeController,
    AttitudeGains,
    DepthController,
    FailsafeConfig,
    PidGains,
)
from testbed.vehicle.filter_values import FilterConfig, NavigationEstimate
from testbed.vehicle.localization import KalmanLocalizer, Navigation, estimate_navigation
from testbed.vehicle.nav_sensors import (
    AcousticFix,
    AcousticFixConfig,
    Dvl,
    DvlConfig,
    Measurement,
    MotionCapture,
    MotionCaptureConfig,
    NavSource,
)
from testbed.vehicle.pilot import PilotGains
from testbed.vehicle.resources import Controllers, PlantTruth, SimClock

TRUTH = PlantTruth(
    quat_from_euler(0.1, -0.2, 1.0), (0.0, 0.0, 0.0), (3.0, -4.0, 5.0), (0.5, -0.1, 0.05)
)


def poll(source: NavSource, rate_hz: float, duration_s: float) -> list[tuple[float, Measurement]]:
    """(delivery time, measurement) of every delivery when polled at ``rate_hz``."""
    out = []
    for k in range(round(duration_s * rate_hz)):
        t = k / rate_hz
        if source.due(t):
            m = source.sample(t, TRUTH)
            if m is not None:
                out.append((t, m))
    return out


def test_motion_capture_rate_and_noise() -> None:
    mocap = MotionCapture(MotionCaptureConfig(), np.random.default_rng(0))
    got = poll(mocap, 200.0, 50.0)
    assert len(got) == 5000  # 100 Hz polled at 200 Hz
    values = np.array([m.value for _, m in got])
    errors = values - TRUTH.position_ned_m
    n = len(errors)
    np.testing.assert_allclose(errors.std(axis=0), 0.001, rtol=4 / math.sqrt(2 * n))
    assert np.all(np.abs(errors.mean(axis=0)) < 4 * 0.001 / math.sqrt(n))
    m = got[0][1]
    assert (m.source, m.kind, m.sigma) == ("mocap", "position_ned", (0.001, 0.001, 0.001))
    assert all(t == m.time_s for t, m in got)  # no latency: delivered when valid


def test_acoustic_fix_is_delivered_late_with_its_ping_time() -> None:
    usbl = AcousticFix(AcousticFixConfig(delay_s=0.75), np.random.default_rng(1))
    got = poll(usbl, 20.0, 10.0)
    assert [m.time_s for _, m in got] == pytest.approx([0.0, 2.0, 4.0, 6.0, 8.0])
    assert [t for t, _ in got] == pytest.approx([0.75, 2.75, 4.75, 6.75, 8.75])
    assert usbl.pending == 0  # the ping at 10 s is not taken in [0, 10)
    fresh = AcousticFix(AcousticFixConfig(delay_s=0.75), np.random.default_rng(1))
    assert fresh.due(0.0) and fresh.sample(0.0, TRUTH) is None and fresh.pending == 1
    assert not fresh.due(0.05) and not fresh.due(0.7) and fresh.due(0.75)


def test_delay_longer_than_the_period_queues_several_fixes() -> None:
    usbl = AcousticFix(AcousticFixConfig(rate_hz=2.0, delay_s=1.2), np.random.default_rng(1))
    got = poll(usbl, 10.0, 3.0)
    assert [m.time_s for _, m in got] == pytest.approx([0.0, 0.5, 1.0, 1.5])
    assert [t for t, _ in got] == pytest.approx([1.2, 1.7, 2.2, 2.7])
    assert usbl.pending == 2  # taken at 2.0 and 2.5 s, still in flight


def test_motion_capture_latency() -> None:
    mocap = MotionCapture(
        MotionCaptureConfig(rate_hz=10.0, latency_s=0.05), np.random.default_rng(2)
    )
    got = poll(mocap, 100.0, 1.0)
    assert all(t - m.time_s == pytest.approx(0.05) for t, m in got)


def test_dvl_measures_body_velocity_at_its_rate() -> None:
    dvl = Dvl(DvlConfig(), np.random.default_rng(3))
    got = poll(dvl, 50.0, 400.0)
    assert len(got) == 2000  # 5 Hz; altitude 5 m is inside [0.05, 50]
    errors = np.array([m.value for _, m in got]) - TRUTH.velocity_m_s
    np.testing.assert_allclose(errors.std(axis=0), 0.01, rtol=4 / math.sqrt(2 * len(errors)))
    assert got[0][1].kind == "velocity_body"
    assert dvl.altitude_m(TRUTH.position_ned_m[2]) == pytest.approx(5.0)


def test_dvl_lock_does_not_shift_later_noise() -> None:
    locked = Dvl(DvlConfig(), np.random.default_rng(4))
    sometimes = Dvl(DvlConfig(), np.random.default_rng(4))
    deep = PlantTruth(TRUTH.quaternion_wxyz, (0.0, 0.0, 0.0), (0.0, 0.0, 9.99), TRUTH.velocity_m_s)
    a = [locked.sample(k * 0.2, TRUTH) for k in range(10)]
    b = [sometimes.sample(k * 0.2, deep if k % 3 == 0 else TRUTH) for k in range(10)]
    for k in range(10):
        assert b[k] is None if k % 3 == 0 else b[k] == a[k]
    assert sometimes.unlocked == 4


@pytest.mark.parametrize(
    ("cls", "data", "key"),
    [
        (MotionCaptureConfig, {"rate_hz": 0.0}, "rate_hz"),
        (MotionCaptureConfig, {"latency_s": -0.1}, "latency_s"),
        (DvlConfig, {"dropout_probability": 1.5}, "dropout_probability"),
        (DvlConfig, {"noise_m_s": math.inf}, "noise_m_s"),
        (AcousticFixConfig, {"delay_s": 11.0}, "delay_s"),
        (FilterConfig, {"accel_noise_m2_s3": 0.0}, "accel_noise_m2_s3"),
        (FilterConfig, {"gate_probability": 1.0}, "gate_probability"),
    ],
)
def test_configs_reject_out_of_range_values(cls: type, data: dict[str, float], key: str) -> None:
    with pytest.raises(ConfigError, match=key):
        build(cls, data)


# ----------------------------------------------------------------- the NavSource seam


class SurfaceGps:
    """A user's source: a GPS fix while at the surface (one class satisfying NavSource)."""

    name = "gps"

    def __init__(self) -> None:
        self.next_s = 0.0

    def due(self, time_s: float) -> bool:
        return time_s >= self.next_s

    def sample(self, time_s: float, truth: PlantTruth) -> Measurement | None:
        self.next_s = time_s + 1.0
        if truth.position_ned_m[2] > 0.5:
            return None
        return Measurement("gps", "position_ned", time_s, truth.position_ned_m, (2.0, 2.0, 2.0))


def test_a_user_source_plugs_into_navigation() -> None:
    world = World()
    vehicle = world.spawn(ImuReading(0.0, (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0)))
    world.insert_resource(SimClock())
    world.insert_resource(PlantTruth(position_ned_m=(10.0, 20.0, 0.0)))
    world.insert_resource(
        Controllers(
            vehicle,
            AttitudeController(AttitudeGains()),
            DepthController(PidGains()),
            PilotGains(),
            FailsafeConfig(),
            (0.0,) * 6,
        )
    )
    sources: list[NavSource] = [SurfaceGps()]
    nav = Navigation(sources, KalmanLocalizer(FilterConfig(initial_position_sigma_m=100.0)))
    world.insert_resource(nav)
    for k in range(30):
        world.resource(SimClock).time_s = k * 0.1
        estimate_navigation(world)
    estimate = world.get(vehicle, NavigationEstimate)
    assert estimate is not None
    assert nav.delivered == {"gps": 3}
    np.testing.assert_allclose(estimate.position_ned_m, (10.0, 20.0, 0.0), atol=2.0)
    assert max(estimate.position_sigma_m) < 3.0  # three 2 m fixes, velocity unobserved
