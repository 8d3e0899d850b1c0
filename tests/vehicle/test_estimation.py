"""testbed.vehicle.estimation and .localization: NEES consistency, delayed fixes by rollback,
dropouts, outlier gating, determinism, and the ECS system in a small World.

Truth is independent of the code under test: a closed-form 3-D sinusoidal trajectory in plain
numpy (velocity its analytic derivative) with a known yaw sweep.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest
from scipy.stats import chi2

from testbed.common.geometry import quat_from_euler, quat_rotate_inverse
from testbed.config import ConfigError, build
from testbed.ecs import World
from testbed.vehicle.components import DepthReading, ImuReading
from testbed.vehicle.control import (
    AttitudeController,
    AttitudeGains,
    DepthController,
    FailsafeConfig,
    PidGains,
)
from testbed.vehicle.estimation import KalmanNavigator
from testbed.vehicle.filter_values import FilterConfig, NavigationEstimate
from testbed.vehicle.localization import (
    KalmanLocalizer,
    Navigation,
    NavigationConfig,
    build_navigation,
    depth_measurement,
    estimate_navigation,
)
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
from testbed.vehicle.sensors import DepthSensor, DepthSensorConfig

# --- truth: p(t) = d0 + A sin(ωt + φ) per NED axis; yaw sweeps at a constant rate ----------
AMP_M = np.array([1.0, 0.8, 0.3])
OMEGA_RAD_S = 2.0 * np.pi / np.array([20.0, 15.0, 25.0])
PHASE_RAD = np.array([0.0, 1.0, 2.0])
OFFSET_M = np.array([0.0, 0.0, 2.0])
YAW_RATE_RAD_S = 0.2
A_RMS_M_S2 = float(np.sqrt(np.mean((AMP_M * OMEGA_RAD_S**2) ** 2 / 2.0)))  # ≈ 0.07 m/s²

# ρ·g = 9800 Pa/m, ArduSub's conversion, so the depth sensor is unbiased; σ = 20 Pa / 9800
DEPTH_CONFIG = DepthSensorConfig(rate_hz=10.0, water_density_kg_m3=9800.0 / 9.80665)
DEPTH_SIGMA_M = DEPTH_CONFIG.noise_pa / 9800.0

# q: the trajectory's acceleration is deterministic, so q must make the model's claimed velocity
# spread match the lag that acceleration causes within the filter's response time τ:
# q ≈ a_rms²·τ. For 1 mm fixes at 100 Hz (r = σ²Δt = 1e-8 m²·s) τ = (r/q)^¼ ≈ 0.07 s, giving
# q ≈ a_rms^1.6·r^0.2 ≈ 3.6e-4; for the 5 Hz, 0.01 m/s DVL (r = 2e-5) τ = (r/q)^½ ≈ 0.15 s,
# q ≈ a_rms^(4/3)·r^(1/3) ≈ 8e-4. Rounded up to 5e-4 and 1e-3 m²/s³ (the rule is only an
# order of magnitude; a 10× larger q makes the filter conservative, ANEES ≈ 3.5).
Q_MOCAP = 5e-4
Q_DVL = 1e-3
N_SEEDS = 20


def truth_at(time_s: float) -> tuple[np.ndarray, PlantTruth]:
    """(6,) true NED position and velocity, and the PlantTruth the sensors read."""
    arg = OMEGA_RAD_S * time_s + PHASE_RAD
    position = OFFSET_M + AMP_M * np.sin(arg)
    velocity = AMP_M * OMEGA_RAD_S * np.cos(arg)
    q = quat_from_euler(0.0, 0.0, YAW_RATE_RAD_S * time_s)
    body = quat_rotate_inverse(q, (float(velocity[0]), float(velocity[1]), float(velocity[2])))
    p = (float(position[0]), float(position[1]), float(position[2]))
    truth = PlantTruth(q, (0.0, 0.0, YAW_RATE_RAD_S), p, body)
    return np.concatenate([position, velocity]), truth


@dataclass
class Run:
    times_s: np.ndarray
    truth: np.ndarray  # (K, 6)
    states: np.ndarray  # (K, 6)
    covariances: np.ndarray  # (K, 6, 6)
    navigator: KalmanNavigator

    @property
    def errors(self) -> np.ndarray:
        errors: np.ndarray = self.states - self.truth
        return errors

    def nees(self) -> np.ndarray:
        e = self.errors
        nees: np.ndarray = np.einsum(
            "ki,ki->k", e, np.linalg.solve(self.covariances, e[..., None])[..., 0]
        )
        return nees


def simulate(
    seed: int,
    *,
    mocap: bool,
    duration_s: float,
    rate_hz: float,
    q: float,
    dvl: DvlConfig | None = None,
    gap_s: tuple[float, float] | None = None,
) -> Run:
    """Run the filter over the trajectory; mocap only, or DVL + depth + delayed acoustic fix.

    The initial state is drawn from the filter's own prior around the truth. Within ``gap_s``
    the DVL and acoustic fixes are withheld (depth stays).
    """
    rng = np.random.default_rng(seed)
    init_rng, mocap_rng, dvl_rng, usbl_rng, depth_rng = rng.spawn(5)
    config = FilterConfig(
        accel_noise_m2_s3=q, initial_position_sigma_m=1.0, initial_velocity_sigma_m_s=0.2
    )
    x0 = truth_at(0.0)[0] + np.repeat([1.0, 0.2], 3) * init_rng.standard_normal(6)
    nav = KalmanNavigator(config, position_ned_m=x0[:3], velocity_ned_m_s=x0[3:])
    sources: list[NavSource]
    depth: DepthSensor | None = None
    if mocap:
        sources = [MotionCapture(MotionCaptureConfig(), mocap_rng)]
    else:
        sources = [Dvl(dvl or DvlConfig(), dvl_rng), AcousticFix(AcousticFixConfig(), usbl_rng)]
        depth = DepthSensor(DEPTH_CONFIG, depth_rng)
    count = round(duration_s * rate_hz)
    times = np.arange(1, count + 1) / rate_hz
    truth, states, covs = np.empty((count, 6)), np.empty((count, 6)), np.empty((count, 6, 6))
    for k, t in enumerate(times.tolist()):
        x_true, plant = truth_at(t)
        nav.predict(t)
        withheld = gap_s is not None and gap_s[0] <= t < gap_s[1]
        for source in sources:
            if source.due(t):
                m = source.sample(t, plant)
                if m is not None and not withheld:
                    nav.update(m, plant.quaternion_wxyz)
        if depth is not None and depth.due(t):
            reading = depth.sample(t, plant.position_ned_m[2])
            nav.update(depth_measurement(reading, DEPTH_SIGMA_M))
        truth[k], states[k], covs[k] = x_true, nav.state, nav.covariance
    return Run(times, truth, states, covs, nav)


def average_nees(**kwargs: object) -> tuple[float, float, float]:
    """Time mean of the seed-averaged NEES, and its two-sided 95 % bounds for N·6 dof."""
    runs = [simulate(seed, **kwargs) for seed in range(N_SEEDS)]  # type: ignore[arg-type]
    avg = np.mean([run.nees() for run in runs], axis=0)
    low, high = chi2.ppf([0.025, 0.975], N_SEEDS * 6) / N_SEEDS
    return float(avg.mean()), float(low), float(high)


# ------------------------------------------------------------------------------- consistency


def test_nees_is_consistent_with_motion_capture() -> None:
    anees, low, high = average_nees(mocap=True, duration_s=6.0, rate_hz=100.0, q=Q_MOCAP)
    assert low < anees < high, (anees, low, high)  # measured 5.97 in [4.58, 7.61]


def test_nees_is_consistent_with_dvl_depth_and_delayed_acoustic_fixes() -> None:
    anees, low, high = average_nees(mocap=False, duration_s=40.0, rate_hz=20.0, q=Q_DVL)
    assert low < anees < high, (anees, low, high)  # measured 6.14 in [4.58, 7.61]


def test_q_rule_of_the_comment_matches_the_chosen_values() -> None:
    r_mocap = MotionCaptureConfig().noise_m ** 2 / 100.0
    r_dvl = DvlConfig().noise_m_s ** 2 / DvlConfig().rate_hz
    assert A_RMS_M_S2**1.6 * r_mocap**0.2 == pytest.approx(3.6e-4, rel=0.1)
    assert A_RMS_M_S2 ** (4 / 3) * r_dvl ** (1 / 3) == pytest.approx(8e-4, rel=0.1)


# --------------------------------------------------------------------------- delayed fixes


def _fix(time_s: float, rng: np.random.Generator) -> Measurement:
    p = truth_at(time_s)[0][:3] + 0.5 * rng.standard_normal(3)
    return Measurement("usbl", "position_ned", time_s, tuple(p.tolist()), (0.5, 0.5, 0.5))


def _dvl(time_s: float, rng: np.random.Generator) -> Measurement:
    _, plant = truth_at(time_s)
    v = np.array(plant.velocity_m_s) + 0.01 * rng.standard_normal(3)
    return Measurement("dvl", "velocity_body", time_s, tuple(v.tolist()), (0.01, 0.01, 0.01))


@pytest.mark.parametrize("offset_s", [0.0, 0.013])  # on a frame, and between two frames
def test_delayed_fix_by_rollback_equals_in_order_processing(offset_s: float) -> None:
    rng = np.random.default_rng(7)
    config = FilterConfig(accel_noise_m2_s3=Q_DVL)
    late, in_order = KalmanNavigator(config), KalmanNavigator(config)
    rate_hz, delay_frames = 20.0, 15  # fixes arrive 0.75 s (+ offset) late
    fix_frames = {20, 60, 100}
    fixes = {k: _fix(k / rate_hz + offset_s, rng) for k in fix_frames}
    for k in range(1, 161):
        t = k / rate_hz
        q = truth_at(t)[1].quaternion_wxyz
        dvl = _dvl(t, rng) if k % 4 == 0 else None
        for nav in (late, in_order):
            nav.predict(t)
            if dvl is not None:
                nav.update(dvl, q)
        if k in fixes:  # the reference gets the fix at its own time, after that frame's DVL
            fix = fixes[k]
            if fix.time_s > t:
                in_order.predict(fix.time_s)
            assert in_order.update(fix)
        if k - delay_frames in fixes:
            assert late.update(fixes[k - delay_frames])
    assert late.counters.rollbacks == 3
    assert in_order.counters.rollbacks == 0
    np.testing.assert_allclose(late.state, in_order.state, rtol=0, atol=1e-12)
    np.testing.assert_allclose(late.covariance, in_order.covariance, rtol=0, atol=1e-12)


def test_fix_older_than_the_history_is_dropped_and_counted() -> None:
    nav = KalmanNavigator(FilterConfig(history_s=1.0))
    for k in range(1, 41):
        nav.predict(k * 0.05)
    before = nav.state
    assert not nav.update(Measurement("usbl", "position_ned", 0.5, (1.0, 1.0, 1.0), (0.5,) * 3))
    assert nav.counters.stale == 1
    np.testing.assert_array_equal(nav.state, before)
    assert nav.update(Measurement("usbl", "position_ned", 1.5, (1.0, 1.0, 1.0), (0.5,) * 3))


# ------------------------------------------------------------------------------- dropouts


def test_sigma_grows_through_a_dropout_and_recovers_after() -> None:
    gap = (15.0, 25.0)
    inside_3_sigma = []
    for seed in range(8):
        run = simulate(seed, mocap=False, duration_s=45.0, rate_hz=20.0, q=Q_DVL, gap_s=gap)
        sigma = np.sqrt(np.diagonal(run.covariances, axis1=1, axis2=2))
        inside = (run.times_s >= gap[0]) & (run.times_s < gap[1])
        horizontal = sigma[inside, :2]
        assert np.all(np.diff(horizontal, axis=0) > 0.0)  # strictly growing, every frame
        assert horizontal[-1].min() > 3.0 * horizontal[0].max()
        # 10 s of dead reckoning through the sinusoid leaves metres of error where σ claims
        # less (white-noise q, deterministic acceleration), so the first fixes after the gap
        # fail the gate; after three the filter re-acquires (FilterConfig.reacquire_after)
        counters = run.navigator.counters
        assert (counters.rejected, counters.reacquired) == (3, 1)
        settled = run.times_s >= gap[1] + 12.0
        ratio = np.abs(run.errors[settled, :3]) / sigma[settled, :3]
        assert np.all(ratio[-1] < 3.0)
        inside_3_sigma.append(ratio < 3.0)
        assert sigma[settled, :2].max() < 0.5 * horizontal[-1].min()
    assert np.mean(inside_3_sigma) > 0.98  # measured 0.995


def test_dvl_dropouts_and_lost_bottom_give_no_measurement() -> None:
    _, plant = truth_at(1.0)  # 2.1 m deep
    lossy = Dvl(DvlConfig(dropout_probability=0.3), np.random.default_rng(0))
    got = [lossy.sample(k * 0.2, plant) for k in range(2000)]
    lost = sum(m is None for m in got)
    assert lost == lossy.dropouts
    assert lost / 2000 == pytest.approx(0.3, abs=0.04)
    high = Dvl(DvlConfig(bottom_depth_m=60.0), np.random.default_rng(0))  # altitude 58 m
    low = Dvl(DvlConfig(bottom_depth_m=2.11), np.random.default_rng(0))  # altitude < 5 cm
    assert high.sample(0.0, plant) is None and high.unlocked == 1
    assert low.sample(0.0, plant) is None and low.unlocked == 1


# ------------------------------------------------------------------------- outlier gating


def test_a_100_sigma_fix_is_gated_out_and_counted() -> None:
    run = simulate(1, mocap=True, duration_s=1.0, rate_hz=100.0, q=Q_MOCAP)
    nav = run.navigator
    before, accepted = nav.state, nav.counters.accepted
    outlier = tuple((before[:3] + 100 * 0.001 * np.array([1.0, -1.0, 1.0])).tolist())
    assert not nav.update(Measurement("mocap", "position_ned", 1.0, outlier, (0.001,) * 3))
    assert not nav.update(Measurement("mocap", "position_ned", 1.0, (math.nan, 0, 0), (1,) * 3))
    assert not nav.update(Measurement("mocap", "position_ned", 1.0, (0.0, 0.0), (1.0, 1.0)))
    assert not nav.update(Measurement("dvl", "velocity_body", 1.0, (0, 0, 0), (0.0, 1, 1)))
    counters = nav.counters
    assert (counters.rejected, counters.invalid, counters.accepted) == (1, 3, accepted)
    np.testing.assert_array_equal(nav.state, before)


def test_predict_backwards_is_misuse() -> None:
    nav = KalmanNavigator(FilterConfig(), time_s=1.0)
    nav.predict(1.0)  # same time: nothing
    with pytest.raises(ValueError, match="before"):
        nav.predict(0.5)


# -------------------------------------------------------------------------- ECS and config


def _world(config: NavigationConfig, seed: int) -> tuple[World, Navigation]:
    world = World()
    vehicle = world.spawn()
    world.insert_resource(SimClock(0.0, 0.05))
    world.insert_resource(PlantTruth())
    world.insert_resource(
        Controllers(
            vehicle=vehicle,
            attitude=AttitudeController(AttitudeGains()),
            depth=DepthController(PidGains()),
            pilot=PilotGains(),
            failsafe=FailsafeConfig(),
            axis_maxima=(0.0,) * 6,
        )
    )
    nav = build_navigation(config, np.random.default_rng(seed))
    world.insert_resource(nav)
    return world, nav


def _run_world(config: NavigationConfig, seed: int, frames: int) -> list[NavigationEstimate]:
    world, _ = _world(config, seed)
    vehicle = world.resource(Controllers).vehicle
    clock, truth = world.resource(SimClock), world.resource(PlantTruth)
    estimates = []
    for k in range(frames):
        t = k * clock.dt_s
        _, plant = truth_at(t)
        clock.time_s = t
        truth.quaternion_wxyz, truth.position_ned_m = plant.quaternion_wxyz, plant.position_ned_m
        truth.velocity_m_s, truth.rates_rad_s = plant.velocity_m_s, plant.rates_rad_s
        world.set(vehicle, ImuReading(t, plant.quaternion_wxyz, plant.rates_rad_s))
        if k % 2 == 0:
            world.set(vehicle, DepthReading(t, 0.0, plant.position_ned_m[2]))
        estimate_navigation(world)
        world.advance()
        est = world.get(vehicle, NavigationEstimate)
        assert est is not None
        estimates.append(est)
    return estimates


FULL = NavigationConfig(
    motion_capture=MotionCaptureConfig(rate_hz=10.0, noise_m=0.01),
    dvl=DvlConfig(dropout_probability=0.2),
    acoustic=AcousticFixConfig(),
    filter=FilterConfig(accel_noise_m2_s3=Q_DVL),
)


def test_estimate_navigation_runs_in_a_world() -> None:
    estimates = _run_world(FULL, seed=5, frames=200)  # 10 s
    _, nav = _world(FULL, 5)
    assert [type(s) for s in nav.sources] == [MotionCapture, Dvl, AcousticFix]
    last = estimates[-1]
    x_true, plant = truth_at(last.time_s)
    assert last.time_s == pytest.approx(199 * 0.05)
    assert np.all(np.abs(np.array(last.position_ned_m) - x_true[:3]) < 0.05)
    assert np.all(np.abs(np.array(last.velocity_ned_m_s) - x_true[3:]) < 0.05)
    np.testing.assert_allclose(last.velocity_body_m_s, plant.velocity_m_s, atol=0.05)
    assert last.quaternion_wxyz == plant.quaternion_wxyz
    assert max(last.position_sigma_m) < 0.01


def test_estimate_navigation_waits_for_the_imu_and_counts_deliveries() -> None:
    world, nav = _world(NavigationConfig(acoustic=AcousticFixConfig()), 0)
    vehicle = world.resource(Controllers).vehicle
    estimate_navigation(world)
    assert world.get(vehicle, NavigationEstimate) is None and nav.frames == 0
    clock = world.resource(SimClock)
    for k in range(60):  # 3 s: pings at 0 and 2 s, delivered at 0.75 and 2.75 s
        clock.time_s = k * 0.05
        world.set(vehicle, ImuReading(clock.time_s, (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0)))
        world.set(vehicle, DepthReading(0.0, 0.0, 0.0))  # not new after the first frame
        estimate_navigation(world)
    assert nav.delivered == {"usbl": 2, "depth": 1}
    assert nav.frames == 60
    assert isinstance(nav.localizer, KalmanLocalizer)
    assert nav.localizer.navigator.counters.rollbacks == 2


def test_same_seed_gives_identical_estimates() -> None:
    a = _run_world(FULL, seed=11, frames=80)
    b = _run_world(FULL, seed=11, frames=80)
    c = _run_world(FULL, seed=12, frames=80)
    assert a == b
    assert a != c


def test_navigation_config_loads_from_toml_tables() -> None:
    data = {
        "dvl": {"rate_hz": 8, "bottom_depth_m": 30.0},
        "acoustic": {"delay_s": 1.0},
        "filter": {"accel_noise_m2_s3": 0.05},
    }
    config = build(NavigationConfig, data, source="s.toml", prefix="vehicle.navigation.")
    assert config.dvl == DvlConfig(rate_hz=8.0, bottom_depth_m=30.0)
    assert config.acoustic == AcousticFixConfig(delay_s=1.0)
    assert config.motion_capture is None
    assert config.filter.accel_noise_m2_s3 == 0.05
    with pytest.raises(ConfigError, match=r"s\.toml: vehicle\.navigation\.dvl\.nope"):
        build(NavigationConfig, {"dvl": {"nope": 1}}, source="s.toml", prefix="vehicle.navigation.")
    with pytest.raises(ConfigError, match="max_altitude_m"):
        build(NavigationConfig, {"dvl": {"min_altitude_m": 5.0, "max_altitude_m": 1.0}})
    with pytest.raises(ConfigError, match="noise_m"):
        build(NavigationConfig, {"acoustic": {"noise_m": -1.0}})


def test_rollback_through_a_reacquisition_replays_it_exactly() -> None:
    config = FilterConfig(initial_position_sigma_m=0.01, initial_velocity_sigma_m_s=0.01)
    late, in_order = KalmanNavigator(config), KalmanNavigator(config)
    still = Measurement("dvl", "velocity_body", 1.0, (0.0, 0.0, 0.0), (0.01, 0.01, 0.01))
    for k in range(1, 81):  # the vehicle is really 5 m north: fixes fail the gate, then one
        t = k * 0.05  # re-acquires (at 2 s); the DVL reading valid at 1 s arrives at 3 s
        for nav in (late, in_order):
            nav.predict(t)
            if k % 10 == 0:
                nav.update(Measurement("usbl", "position_ned", t, (5.0, 0.0, 0.0), (0.5,) * 3))
        if k == 20:
            assert in_order.update(still)
        if k == 60:
            assert late.update(still)
    for nav in (late, in_order):
        assert (nav.counters.rejected, nav.counters.reacquired) == (3, 1)
    assert late.counters.rollbacks == 1
    np.testing.assert_allclose(late.state, in_order.state, rtol=0, atol=1e-12)
    np.testing.assert_allclose(late.covariance, in_order.covariance, rtol=0, atol=1e-12)
    assert abs(late.state[0] - 5.0) < 1.0


def test_known_acceleration_input_propagates_in_closed_form() -> None:
    nav = KalmanNavigator(FilterConfig(accel_noise_m2_s3=1e-3))
    accel = (0.2, -0.1, 0.05)
    for k in range(1, 101):
        nav.predict(k * 0.01, accel)
    a = np.array(accel)
    np.testing.assert_allclose(nav.state, np.concatenate([0.5 * a, a]), rtol=1e-12, atol=1e-15)
    p = nav.covariance
    np.testing.assert_allclose(p, p.T, rtol=0, atol=1e-15)
    # P(1 s) = P0 propagated plus q·[[1/3, 1/2], [1/2, 1]] per axis (exact discretisation)
    s_p, s_v, q = 10.0**2, 1.0**2, 1e-3
    assert p[0, 0] == pytest.approx(s_p + s_v + q / 3.0, rel=1e-12)
    assert p[0, 3] == pytest.approx(s_v + q / 2.0, rel=1e-12)
    assert p[3, 3] == pytest.approx(s_v + q, rel=1e-12)
