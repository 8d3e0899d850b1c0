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

from testbed.common.components import DepthReading, ImuReading, PositionReading
from testbed.common.geometry import Quaternion, quat_multiply
from testbed.config import check_range

__all__ = [
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

STANDARD_GRAVITY_M_S2 = 9.80665
SEA_LEVEL_PA = 101325.0
ARDUSUB_PA_PER_M = 9800.0  # ArduSub's ρg for specific gravity 1

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


def baro_pressure_pa(
    depth_m: float,
    *,
    water_density_kg_m3: float = 1000.0,
    surface_pressure_pa: float = SEA_LEVEL_PA,
    gravity_m_s2: float = STANDARD_GRAVITY_M_S2,
) -> float:
    """Absolute hydrostatic pressure [Pa] at ``depth_m`` (positive down; 0 above the surface)."""
    return surface_pressure_pa + water_density_kg_m3 * gravity_m_s2 * max(depth_m, 0.0)


def baro_depth_m(
    pressure_pa: float, *, spec_grav: float = 1.0, surface_pressure_pa: float = SEA_LEVEL_PA
) -> float:
    """Depth [m, positive down] from absolute pressure, as ArduSub: Δp / (9800·spec_grav)."""
    return (pressure_pa - surface_pressure_pa) / (ARDUSUB_PA_PER_M * spec_grav)


class NormalDraws:
    """Standard normal draws from ``rng``, fetched in blocks (a per-call draw costs ~1 µs): the
    same numbers, in the same order, as one ``rng.standard_normal`` call per draw, for a
    generator nothing else draws from."""

    __slots__ = ("_buffer", "_index", "_rng", "block")

    def __init__(self, rng: np.random.Generator, block: int = 1024) -> None:
        self._rng = rng
        self.block = block
        self._buffer: list[float] = []
        self._index = 0

    def take(self) -> float:
        if self._index >= len(self._buffer):
            self._buffer = self._rng.standard_normal(self.block).tolist()
            self._index = 0
        value = self._buffer[self._index]
        self._index += 1
        return value

    def perturbed(self, values: Sequence[float], sigma: float) -> tuple[float, float, float]:
        """(3,) ``values`` each plus ``sigma`` times the next draw (white noise, 1σ ``sigma``)."""
        n0, n1, n2 = self.take_many(3)
        x, y, z = values
        return (float(x) + sigma * n0, float(y) + sigma * n1, float(z) + sigma * n2)

    def take_many(self, count: int) -> list[float]:
        """The next ``count`` draws (the same as ``count`` calls of :meth:`take`)."""
        start = self._index
        end = start + count
        if end <= len(self._buffer):
            self._index = end
            return self._buffer[start:end]
        return [self.take() for _ in range(count)]


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
    """Attitude and rate sensor; see the module docstring for the model."""

    __slots__ = ("_clock", "_decay", "_errors", "_innovation", "_normals", "_sigmas", "config")

    def __init__(self, config: ImuConfig, rng: np.random.Generator) -> None:
        self.config = config
        self._normals = NormalDraws(rng)
        self._clock = SampleClock(config.rate_hz)
        tau = config.correlation_time_s
        self._decay = math.exp(-self._clock.period_s / tau) if tau > 0 else 0.0
        self._innovation = math.sqrt(1.0 - self._decay * self._decay)
        sigmas = (config.attitude_noise_rad, config.attitude_noise_rad, config.heading_noise_rad)
        self._sigmas = sigmas
        # stationary start: the correlated error already has its steady-state spread
        self._errors = [s * self._normals.take() for s in sigmas]

    def due(self, time_s: float) -> bool:
        """Whether a reading is due at ``time_s``."""
        return self._clock.due(time_s)

    def sample(
        self, time_s: float, quaternion_wxyz: Quaternion, rates_rad_s: Sequence[float]
    ) -> ImuReading:
        """Measure the true attitude and body rates now (and schedule the next reading).

        Args:
            time_s: simulation time [s].
            quaternion_wxyz: (4,) true attitude, body → NED.
            rates_rad_s: (3,) true body rates [rad/s], FRD.
        """
        self._clock.advance(time_s)
        n0, n1, n2, n3, n4, n5 = self._normals.take_many(6)  # in the order they were drawn
        a, b = self._decay, self._innovation
        s0, s1, s2 = self._sigmas
        e0, e1, e2 = self._errors
        ex = a * e0 + b * s0 * n0
        ey = a * e1 + b * s1 * n1
        eh = a * e2 + b * s2 * n2
        self._errors = [ex, ey, eh]
        # body roll/pitch error: rotation vector (ex, ey, 0) on the body axes
        angle = math.sqrt(ex * ex + ey * ey)
        if angle > 0.0:
            s = math.sin(0.5 * angle) / angle
            q_body: Quaternion = (math.cos(0.5 * angle), ex * s, ey * s, 0.0)
        else:
            q_body = (1.0, 0.0, 0.0, 0.0)
        q_heading: Quaternion = (math.cos(0.5 * eh), 0.0, 0.0, math.sin(0.5 * eh))
        measured = quat_multiply(q_heading, quat_multiply(quaternion_wxyz, q_body))
        g = self.config.gyro_noise_rad_s
        rates = (rates_rad_s[0] + g * n3, rates_rad_s[1] + g * n4, rates_rad_s[2] + g * n5)
        return ImuReading(time_s, measured, rates)


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
    """Pressure depth sensor; see the module docstring for the model."""

    __slots__ = ("_clock", "_normals", "config")

    def __init__(self, config: DepthSensorConfig, rng: np.random.Generator) -> None:
        self.config = config
        self._normals = NormalDraws(rng)
        self._clock = SampleClock(config.rate_hz)

    def due(self, time_s: float) -> bool:
        """Whether a reading is due at ``time_s``."""
        return self._clock.due(time_s)

    def sample(self, time_s: float, depth_m: float) -> DepthReading:
        """Measure the true depth [m, positive down] now (and schedule the next reading)."""
        self._clock.advance(time_s)
        cfg = self.config
        surface = cfg.surface_pressure_pa
        pressure = baro_pressure_pa(
            depth_m, water_density_kg_m3=cfg.water_density_kg_m3, surface_pressure_pa=surface
        )
        pressure += cfg.noise_pa * self._normals.take()
        depth = baro_depth_m(pressure, spec_grav=cfg.spec_grav, surface_pressure_pa=surface)
        return DepthReading(time_s, pressure, depth)


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
    """Position-fix sensor; see the module docstring for the model."""

    __slots__ = ("_clock", "_normals", "config")

    def __init__(self, config: PositionFixConfig, rng: np.random.Generator) -> None:
        self.config = config
        self._normals = NormalDraws(rng)
        self._clock = SampleClock(config.rate_hz)

    def due(self, time_s: float) -> bool:
        """Whether a reading is due at ``time_s``."""
        return self._clock.due(time_s)

    def sample(self, time_s: float, position_ned_m: Sequence[float]) -> PositionReading:
        """Measure the true (3,) NED position [m] now (and schedule the next reading)."""
        self._clock.advance(time_s)
        return PositionReading(time_s, self._normals.perturbed(position_ned_m, self.config.noise_m))
