"""Simulated vehicle sensors: IMU attitude and rates, pressure depth, an optional position fix.

Each sensor turns the physics truth into what the vehicle's software would see: sampled at its
own rate, with noise drawn from the ``numpy.random.Generator`` it was given (draws are taken in
blocks, so give each sensor its own generator, e.g. from ``Generator.spawn``). Controllers read
only these readings; nothing here feeds the truth forward.

Models (all noise 1σ):

- IMU: the fused attitude of an AHRS (mate-rov runs Madgwick at 1 kHz and reports at the
  control rate) as the true attitude perturbed by a small roll/pitch rotation about the body
  axes and a heading rotation about world down, optionally first-order Gauss–Markov
  (correlated) rather than white; body rates with white gyro noise.
- Depth: an MS5837-style pressure sensor at the body origin. Absolute pressure
  ``p = p_surface + ρ·g·depth`` plus noise, converted back as ArduSub does,
  ``depth = (p − p_surface) / (9800·BARO_SPEC_GRAV)`` (REFERENCE §4.3; 1.0 fresh, 1.024 salt),
  so a fresh-water setting in sea water reads about 2.6 % deep, as on a real vehicle.
- Position fix: a motion-capture-like NED position with white noise (off by default).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from testbed.common import jit
from testbed.common.components import DepthReading, ImuReading, PositionReading
from testbed.common.geometry import Quaternion, Vec3
from testbed.common.jit import F64, I64, INTS, MARK, VECTOR, floats
from testbed.config import check_range
from testbed.ecs.store import Layout, RowView
from testbed.vehicle.sensor_kernels import (
    ARDUSUB_PA_PER_M,
    SEA_LEVEL_PA,
    STANDARD_GRAVITY_M_S2,
    baro_depth_m,
    baro_pressure_pa,
    depth_sample,
    imu_sample,
    position_sample,
)

__all__ = [
    "ARDUSUB_PA_PER_M",
    "SEA_LEVEL_PA",
    "STANDARD_GRAVITY_M_S2",
    "DepthReading",
    "DepthSensor",
    "DepthSensorConfig",
    "Imu",
    "ImuConfig",
    "ImuReading",
    "NormalDraws",
    "PositionFix",
    "PositionFixConfig",
    "PositionReading",
    "SampleClock",
    "baro_depth_m",
    "baro_pressure_pa",
]

SENSOR_RATE_RANGE_HZ = (0.01, 10000.0)
"""Accepted sensor output rates [Hz]; the sensors are polled once per control frame, so a rate
above the control rate gives a reading every frame."""
WATER_DENSITY_RANGE_KG_M3 = (900.0, 1100.0)
"""Accepted water densities [kg/m³]: fresh water (≈ 1000) to the densest sea water (≈ 1050)."""
SPEC_GRAV_RANGE = (0.9, 1.1)
"""Accepted firmware specific gravities (ArduSub's BARO_SPEC_GRAV: 1.0 fresh, 1.024 salt)."""
SURFACE_PRESSURE_RANGE_PA = (5.0e4, 1.5e5)
"""Accepted surface pressures [Pa]: a lake at ≈ 5 km altitude up to well above sea level."""


def _check_rate(rate_hz: float) -> None:
    check_range(rate_hz, "rate_hz", *SENSOR_RATE_RANGE_HZ, "Hz")


# The sensor kernels, called without numba's dispatcher (testbed.common.jit.entry): the draws'
# buffer and cursor, the sensor's arrays and the row are the frame's own float64/int64 vectors.
_DRAWS = (VECTOR, INTS)
_IMU_SAMPLE = jit.entry(
    imu_sample, *_DRAWS, VECTOR, VECTOR, floats(4), floats(3), F64, VECTOR, MARK, I64
)
_DEPTH_SAMPLE = jit.entry(depth_sample, *_DRAWS, VECTOR, F64, F64, VECTOR, MARK, I64)
_POSITION_SAMPLE = jit.entry(position_sample, *_DRAWS, F64, floats(3), F64, VECTOR, MARK, I64)


class NormalDraws:
    """Standard normal draws from ``rng``, fetched in blocks (a per-call draw costs ~1 µs): the
    same numbers, in the same order, as one ``rng.standard_normal`` call per draw, for a
    generator nothing else draws from.

    Compiled sensor models draw straight from :attr:`buffer` at :attr:`cursor` ``[0]`` and
    advance it, after :meth:`ready` made enough draws available.
    """

    __slots__ = ("_listed", "_rng", "block", "buffer", "cursor")

    def __init__(self, rng: np.random.Generator, block: int = 1024) -> None:
        self._rng = rng
        self.block = block
        self.buffer = np.zeros(0)
        self.cursor = np.zeros(1, dtype=np.int64)
        self._listed: list[float] = []  # the buffer as floats, for the Python readers

    def ready(self, count: int) -> None:
        """Make at least ``count`` draws available from the cursor (the rest of the block, then
        a new one: the order of the draws is kept)."""
        start = int(self.cursor[0])
        if start + count > self.buffer.size:
            fresh = self._rng.standard_normal(max(self.block, count))
            self.buffer = np.concatenate((self.buffer[start:], fresh))
            self._listed = self.buffer.tolist()
            self.cursor[0] = 0

    def take(self) -> float:
        return self.take_many(1)[0]

    def perturbed(self, values: Sequence[float], sigma: float) -> tuple[float, float, float]:
        """(3,) ``values`` each plus ``sigma`` times the next draw (white noise, 1σ ``sigma``)."""
        n0, n1, n2 = self.take_many(3)
        x, y, z = values
        return (float(x) + sigma * n0, float(y) + sigma * n1, float(z) + sigma * n2)

    def take_many(self, count: int) -> list[float]:
        """The next ``count`` draws (the same as ``count`` calls of :meth:`take`)."""
        cursor = self.cursor
        start = int(cursor[0])
        if start + count > len(self._listed):
            self.ready(count)
            start = 0
        cursor[0] = start + count
        return self._listed[start : start + count]


class SampleClock:
    """When a sensor at ``rate_hz`` is next due. Late polls do not produce bursts."""

    __slots__ = ("next_s", "period_s")

    def __init__(self, rate_hz: float) -> None:
        self.period_s = 1.0 / rate_hz
        self.next_s = 0.0

    def due(self, time_s: float) -> bool:
        return time_s >= self.next_s - 1e-9

    def advance(self, time_s: float) -> None:
        self.next_s += self.period_s
        if self.next_s <= time_s:
            self.next_s = time_s + self.period_s


# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class ImuConfig:
    """IMU/AHRS output model.

    Domains: ``rate_hz`` in [0.01, 10000] Hz; ``attitude_noise_rad`` in [0, 1] rad;
    ``heading_noise_rad`` in [0, π] rad; ``gyro_noise_rad_s`` in [0, 10] rad/s;
    ``correlation_time_s`` in [0, 3600] s.

    Attributes:
        rate_hz: output rate [Hz].
        attitude_noise_rad: roll/pitch error [rad], 1σ.
        heading_noise_rad: heading error [rad], 1σ.
        gyro_noise_rad_s: body-rate noise [rad/s], 1σ, white.
        correlation_time_s: correlation time of the attitude error [s]; 0 = white per sample.
    """

    rate_hz: float = 100.0
    attitude_noise_rad: float = math.radians(0.1)
    heading_noise_rad: float = math.radians(0.3)
    gyro_noise_rad_s: float = math.radians(0.1)
    correlation_time_s: float = 0.0

    def __post_init__(self) -> None:
        _check_rate(self.rate_hz)
        check_range(self.attitude_noise_rad, "attitude_noise_rad", 0.0, 1.0, "rad")
        check_range(self.heading_noise_rad, "heading_noise_rad", 0.0, math.pi, "rad")
        check_range(self.gyro_noise_rad_s, "gyro_noise_rad_s", 0.0, 10.0, "rad/s")
        check_range(self.correlation_time_s, "correlation_time_s", 0.0, 3600.0, "s")


class Imu:
    """Attitude and rate sensor; see the module docstring for the model (the arithmetic is
    :func:`~.sensor_kernels.imu_sample`)."""

    __slots__ = ("_clock", "_errors", "_normals", "_params", "_scratch", "config")

    def __init__(self, config: ImuConfig, rng: np.random.Generator) -> None:
        self.config = config
        self._normals = NormalDraws(rng)
        self._clock = SampleClock(config.rate_hz)
        tau = config.correlation_time_s
        decay = math.exp(-self._clock.period_s / tau) if tau > 0 else 0.0
        innovation = math.sqrt(1.0 - decay * decay)
        sigmas = (config.attitude_noise_rad, config.attitude_noise_rad, config.heading_noise_rad)
        self._params = np.array(
            [decay, innovation, *sigmas, config.gyro_noise_rad_s], dtype=np.float64
        )
        # stationary start: the correlated error already has its steady-state spread
        self._errors = np.array([s * self._normals.take() for s in sigmas], dtype=np.float64)
        self._scratch = _Scratch(_IMU)

    def due(self, time_s: float) -> bool:
        """Whether a reading is due at ``time_s``."""
        return self._clock.due(time_s)

    def sample(self, time_s: float, quaternion_wxyz: Quaternion, rates_rad_s: Vec3) -> ImuReading:
        """Measure the true attitude and body rates now (and schedule the next reading).

        Args:
            time_s: simulation time [s].
            quaternion_wxyz: (4,) true attitude, body → NED.
            rates_rad_s: (3,) true body rates [rad/s], FRD.
        """
        scratch = self._scratch
        self.sample_into(time_s, quaternion_wxyz, rates_rad_s, scratch.row, 0)
        return scratch.reading()  # type: ignore[return-value]  # the ImuReading layout's

    def sample_into(
        self,
        time_s: float,
        quaternion_wxyz: Quaternion,
        rates_rad_s: Vec3,
        row: RowView,
        tick: int,
    ) -> None:
        """:meth:`sample`, written into an ImuReading row at ``tick`` (a frame's path)."""
        self._clock.advance(time_s)
        normals = self._normals
        while not _IMU_SAMPLE(
            normals.buffer,
            normals.cursor,
            self._errors,
            self._params,
            quaternion_wxyz,
            rates_rad_s,
            time_s,
            row.values,
            row.mark,
            tick,
        ):
            normals.ready(6)


# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class DepthSensorConfig:
    """Pressure depth sensor (MS5837-30BA-like; 0.2 mbar resolution ≈ 2 mm).

    Domains: ``rate_hz`` in [0.01, 10000] Hz; ``noise_pa`` in [0, 1e5] Pa (≈ 10 m of
    water); ``water_density_kg_m3`` in [900, 1100]; ``spec_grav`` in [0.9, 1.1];
    ``surface_pressure_pa`` in [5e4, 1.5e5] Pa.

    Attributes:
        rate_hz: output rate [Hz].
        noise_pa: pressure noise [Pa], 1σ (20 Pa ≈ 2 mm of water).
        water_density_kg_m3: density of the water the vehicle is in (physical truth).
        spec_grav: the specific gravity the firmware converts with (1.0 fresh, 1.024 salt).
        surface_pressure_pa: pressure at the surface, recalibrated at start.
    """

    rate_hz: float = 100.0
    noise_pa: float = 20.0
    water_density_kg_m3: float = 1000.0
    spec_grav: float = 1.0
    surface_pressure_pa: float = SEA_LEVEL_PA

    def __post_init__(self) -> None:
        _check_rate(self.rate_hz)
        check_range(self.noise_pa, "noise_pa", 0.0, 1.0e5, "Pa")
        check_range(
            self.water_density_kg_m3, "water_density_kg_m3", *WATER_DENSITY_RANGE_KG_M3, "kg/m³"
        )
        check_range(self.spec_grav, "spec_grav", *SPEC_GRAV_RANGE)
        check_range(
            self.surface_pressure_pa, "surface_pressure_pa", *SURFACE_PRESSURE_RANGE_PA, "Pa"
        )


class DepthSensor:
    """Pressure depth sensor; see the module docstring for the model (the arithmetic is
    :func:`~.sensor_kernels.depth_sample`)."""

    __slots__ = ("_clock", "_normals", "_params", "_scratch", "config")

    def __init__(self, config: DepthSensorConfig, rng: np.random.Generator) -> None:
        self.config = config
        self._normals = NormalDraws(rng)
        self._clock = SampleClock(config.rate_hz)
        self._params = np.array(
            [
                config.water_density_kg_m3,
                config.surface_pressure_pa,
                config.noise_pa,
                config.spec_grav,
            ],
            dtype=np.float64,  # whole numbers in a config too: the kernel reads float64
        )
        self._scratch = _Scratch(_DEPTH)

    def due(self, time_s: float) -> bool:
        """Whether a reading is due at ``time_s``."""
        return self._clock.due(time_s)

    def sample(self, time_s: float, depth_m: float) -> DepthReading:
        """Measure the true depth [m, positive down] now (and schedule the next reading)."""
        scratch = self._scratch
        self.sample_into(time_s, depth_m, scratch.row, 0)
        return scratch.reading()  # type: ignore[return-value]  # the DepthReading layout's

    def sample_into(self, time_s: float, depth_m: float, row: RowView, tick: int) -> None:
        """:meth:`sample`, written into a DepthReading row at ``tick`` (a frame's path)."""
        self._clock.advance(time_s)
        normals = self._normals
        while not _DEPTH_SAMPLE(
            normals.buffer,
            normals.cursor,
            self._params,
            depth_m,
            time_s,
            row.values,
            row.mark,
            tick,
        ):
            normals.ready(1)


# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class PositionFixConfig:
    """Motion-capture-like position fix.

    Domains: ``rate_hz`` in [0.01, 10000] Hz; ``noise_m`` in [0, 100] m.

    Attributes:
        rate_hz: output rate [Hz].
        noise_m: position noise per axis [m], 1σ.
    """

    rate_hz: float = 20.0
    noise_m: float = 0.005

    def __post_init__(self) -> None:
        _check_rate(self.rate_hz)
        check_range(self.noise_m, "noise_m", 0.0, 100.0, "m")


class PositionFix:
    """Position-fix sensor; see the module docstring for the model (the arithmetic is
    :func:`~.sensor_kernels.position_sample`)."""

    __slots__ = ("_clock", "_normals", "_scratch", "config")

    def __init__(self, config: PositionFixConfig, rng: np.random.Generator) -> None:
        self.config = config
        self._normals = NormalDraws(rng)
        self._clock = SampleClock(config.rate_hz)
        self._scratch = _Scratch(_POSITION)

    def due(self, time_s: float) -> bool:
        """Whether a reading is due at ``time_s``."""
        return self._clock.due(time_s)

    def sample(self, time_s: float, position_ned_m: Vec3) -> PositionReading:
        """Measure the true (3,) NED position [m] now (and schedule the next reading)."""
        scratch = self._scratch
        self.sample_into(time_s, position_ned_m, scratch.row, 0)
        return scratch.reading()  # type: ignore[return-value]  # the PositionReading layout's

    def sample_into(self, time_s: float, position_ned_m: Vec3, row: RowView, tick: int) -> None:
        """:meth:`sample`, written into a PositionReading row at ``tick`` (a frame's path)."""
        self._clock.advance(time_s)
        normals = self._normals
        noise = self.config.noise_m
        while not _POSITION_SAMPLE(
            normals.buffer,
            normals.cursor,
            noise,
            position_ned_m,
            time_s,
            row.values,
            row.mark,
            tick,
        ):
            normals.ready(3)


# --------------------------------------------------------------------------------------------

_IMU = Layout(ImuReading(0.0, (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0)))
_DEPTH = Layout(DepthReading(0.0, 0.0, 0.0))
_POSITION = Layout(PositionReading(0.0, (0.0, 0.0, 0.0)))


class _Scratch:
    """A sensor's own row, for a sample taken outside a world."""

    __slots__ = ("layout", "row")

    def __init__(self, layout: Layout) -> None:
        self.layout = layout
        self.row = RowView.detached(layout.width)

    def reading(self) -> object:
        return self.layout.read(self.row.values)
