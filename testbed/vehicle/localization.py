"""Localization on the vehicle's ECS: the :class:`Navigation` resource and its system.

:func:`estimate_navigation` runs each frame in PRE_UPDATE right after ``read_sensors``: it
samples each due :class:`~testbed.vehicle.nav_sensors.NavSource` from the plant truth, adds the
depth sensor's reading when it is new, hands them with the vehicle's IMU reading to the
:class:`Localizer` and writes the
:class:`~testbed.vehicle.estimation.NavigationEstimate` on the vehicle entity. Like
``read_sensors``, the sources are the only readers of the truth; the localizer never sees it.
The estimate's position is also written as the vehicle's :class:`PositionReading`, so
everything that reads a position fix (GUIDED's loop, the odometry sent to the operator, the
GoTo support check) reads the estimate. A vehicle's position fix (``sensors.position``), when
it also has a navigation, is one of the navigation's sources (:class:`FixSource`).

:class:`NavigationConfig` is the scenario's ``[vehicle.navigation]`` table (loadable with
:func:`testbed.config.build`: ``[vehicle.navigation.dvl]`` etc. are the optional sub-tables),
:func:`build_navigation` turns it into the resource. Wiring into the schedule is the vehicle's.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from testbed.common import jit
from testbed.common.jit import F64, I64, MARK, VECTOR, floats
from testbed.config import check_range
from testbed.ecs import World
from testbed.vehicle.components import DepthReading, ImuReading, PositionReading
from testbed.vehicle.estimation import KalmanNavigator
from testbed.vehicle.filter_values import FilterConfig, NavigationEstimate
from testbed.vehicle.nav_sensors import (
    Accelerometer,
    AccelerometerConfig,
    AcousticFix,
    AcousticFixConfig,
    Dvl,
    DvlConfig,
    Measurement,
    MotionCapture,
    MotionCaptureConfig,
    NavSource,
)
from testbed.vehicle.resources import Controllers, PlantTruth, SimClock, vehicle_row
from testbed.vehicle.sensor_kernels import put_position
from testbed.vehicle.sensors import PositionFix

MIN_FIX_SIGMA_M = 1e-4
"""Smallest 1σ [m] a position fix is given in the filter (a noiseless fix is 0.1 mm)."""

__all__ = [
    "FixSource",
    "KalmanLocalizer",
    "Localizer",
    "Navigation",
    "NavigationConfig",
    "build_navigation",
    "depth_measurement",
    "estimate_navigation",
]

_PUT_POSITION = jit.entry(put_position, VECTOR, MARK, I64, F64, floats(3))
"""The estimate's position row writer without numba's dispatcher (a store row and its mark)."""


# --------------------------------------------------------------------------------- localizer


class Localizer(Protocol):
    """The localization seam: IMU attitude plus measurements in, an estimate out.

    A user plugs their own algorithm by writing one class with this method.
    """

    def step(
        self, time_s: float, imu: ImuReading, measurements: Sequence[Measurement]
    ) -> NavigationEstimate:
        """Advance to ``time_s`` [s] with this frame's IMU reading and new measurements."""
        ...


class KalmanLocalizer:
    """The default :class:`Localizer`: :class:`~.estimation.KalmanNavigator`, IMU as the AHRS.

    Measurements are applied in order of their validity time; the DVL is rotated with this
    frame's IMU attitude (the DVL is not delayed). An ``acceleration_ned`` measurement (the
    accelerometer: the mean acceleration since the previous frame) is not an update but the
    input the prediction to this frame holds over its interval.
    """

    __slots__ = ("navigator",)

    def __init__(self, config: FilterConfig, *, time_s: float = 0.0) -> None:
        self.navigator = KalmanNavigator(config, time_s=time_s)

    def step(
        self, time_s: float, imu: ImuReading, measurements: Sequence[Measurement]
    ) -> NavigationEstimate:
        """Predict to ``time_s`` [s], apply ``measurements``, return the estimate."""
        nav = self.navigator
        accel = None
        updates = []
        for m in measurements:
            if m.kind == "acceleration_ned":
                accel = m.value
            else:
                updates.append(m)
        nav.predict(max(time_s, nav.time_s), accel)
        q = imu.quaternion_wxyz
        for m in sorted(updates, key=lambda m: m.time_s):
            nav.update(m, q)
        return nav.estimate(q, imu.rates_rad_s)


@dataclass(frozen=True, slots=True)
class NavigationConfig:
    """The vehicle's navigation: which sources are fitted and the filter's noise figures.

    Domains: ``depth_sigma_m`` in [0, 10] m (0 = the depth reading is not used).

    Attributes:
        motion_capture: motion-capture position, or ``None`` (not fitted).
        dvl: DVL body velocity, or ``None``.
        acoustic: delayed acoustic (USBL) fix, or ``None``.
        accelerometer: the IMU's accelerometer (NED acceleration, the filter's prediction
            input), or ``None`` (the filter predicts with constant velocity alone).
        filter: the Kalman filter's process noise, initial spread, history and gate.
        depth_sigma_m: 1σ the filter gives the depth sensor [m]. 0.005 m: the MS5837 model's
            20 Pa noise is ≈ 2 mm; the rest covers a small density mismatch at shallow depth.
    """

    motion_capture: MotionCaptureConfig | None = None
    dvl: DvlConfig | None = None
    acoustic: AcousticFixConfig | None = None
    accelerometer: AccelerometerConfig | None = None
    filter: FilterConfig = field(default_factory=FilterConfig)
    depth_sigma_m: float = 0.005

    def __post_init__(self) -> None:
        check_range(self.depth_sigma_m, "depth_sigma_m", 0.0, 10.0, "m")


@dataclass(slots=True)
class Navigation:
    """The navigation resource: sources, the localizer and what they delivered.

    Attributes:
        sources: the fitted navigation sources, sampled in this order.
        localizer: the estimator (any :class:`Localizer`).
        depth_sigma_m: 1σ for depth readings [m]; 0 leaves them out.
        last_depth_time_s: time of the last depth reading handed on [s] (a newer one is new).
        delivered: measurements delivered so far, by source name (``"depth"`` for the depth
            sensor).
        frames: frames the localizer was stepped.
    """

    sources: list[NavSource]
    localizer: Localizer
    depth_sigma_m: float = 0.005
    last_depth_time_s: float = -np.inf
    delivered: dict[str, int] = field(default_factory=dict)
    frames: int = 0


class FixSource:
    """The vehicle's position fix (:class:`~testbed.vehicle.sensors.PositionFix`) as a
    navigation source: its readings become ``position_ned`` measurements with 1σ its noise
    (at least :data:`MIN_FIX_SIGMA_M`).

    Args:
        fix: the sensor (its own generator and rate).
        name: the source's name.
    """

    def __init__(self, fix: PositionFix, name: str = "fix") -> None:
        self.fix = fix
        self.name = name

    def due(self, time_s: float) -> bool:
        """Whether the fix has a reading due at ``time_s``."""
        return self.fix.due(time_s)

    def sample(self, time_s: float, truth: PlantTruth) -> Measurement | None:
        """The fix's reading of the true position now, as a measurement."""
        reading = self.fix.sample(time_s, truth.position_ned_m)
        sigma = max(self.fix.config.noise_m, MIN_FIX_SIGMA_M)
        return Measurement(
            self.name, "position_ned", reading.time_s, reading.position_ned_m, (sigma,) * 3
        )


def build_navigation(
    config: NavigationConfig, rng: np.random.Generator, extra: Sequence[NavSource] = ()
) -> Navigation:
    """The :class:`Navigation` of ``config``, each source with its own child of ``rng``.

    The children are spawned in a fixed order (motion capture, DVL, acoustic) whether or not
    each is fitted, so fitting one source does not change another's noise. ``extra`` sources
    (the vehicle's position fix) are sampled after these.
    """
    mocap_rng, dvl_rng, acoustic_rng = rng.spawn(3)
    sources: list[NavSource] = []
    if config.motion_capture is not None:
        sources.append(MotionCapture(config.motion_capture, mocap_rng))
    if config.dvl is not None:
        sources.append(Dvl(config.dvl, dvl_rng))
    if config.acoustic is not None:
        sources.append(AcousticFix(config.acoustic, acoustic_rng))
    if config.accelerometer is not None:  # its own child, spawned after the three above
        sources.append(Accelerometer(config.accelerometer, rng.spawn(1)[0]))
    sources.extend(extra)
    return Navigation(sources, KalmanLocalizer(config.filter), config.depth_sigma_m)


def depth_measurement(reading: DepthReading, sigma_m: float) -> Measurement:
    """The depth sensor's reading as a ``depth`` measurement with 1σ ``sigma_m`` [m]."""
    return Measurement("depth", "depth", reading.time_s, (reading.depth_m,), (sigma_m,))


def estimate_navigation(world: World) -> None:
    """Sample the due navigation sources, step the localizer, store the estimate.

    Does nothing until the vehicle has an IMU reading (the localizer needs its attitude).
    """
    nav = world.resource(Navigation)
    ctl = world.resource(Controllers)
    vehicle = ctl.vehicle
    imu = world.get(vehicle, ImuReading)
    if imu is None:
        return
    t = world.resource(SimClock).time_s
    truth = world.resource(PlantTruth)
    measurements: list[Measurement] = []
    for source in nav.sources:
        if source.due(t):
            m = source.sample(t, truth)
            if m is not None:
                measurements.append(m)
    depth = world.get(vehicle, DepthReading)
    if nav.depth_sigma_m > 0.0 and depth is not None and depth.time_s > nav.last_depth_time_s:
        nav.last_depth_time_s = depth.time_s
        measurements.append(depth_measurement(depth, nav.depth_sigma_m))
    for m in measurements:
        nav.delivered[m.source] = nav.delivered.get(m.source, 0) + 1
    nav.frames += 1
    estimate = nav.localizer.step(t, imu, measurements)
    world.set(vehicle, estimate)
    # the estimate is the vehicle's position reading: GUIDED's loop, the odometry the operator
    # is sent and the GoTo support check read it as they read a position fix
    row = vehicle_row(world, ctl, PositionReading)
    if row is None:
        world.set(vehicle, PositionReading(estimate.time_s, estimate.position_ned_m))
    else:
        _PUT_POSITION(row.values, row.mark, world.tick, estimate.time_s, estimate.position_ned_m)
