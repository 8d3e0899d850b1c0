"""Navigation sensor models for localization: motion capture, a DVL, an acoustic (USBL) fix.

Each model turns the physics truth (:class:`~testbed.vehicle.resources.PlantTruth`, read only
here and in :mod:`testbed.vehicle.sensors`) into the :class:`Measurement` a localizer consumes:
sampled at its own rate, with noise from the ``numpy.random.Generator`` it was given (give each
model its own, e.g. from ``Generator.spawn``), and, where the real device is late, delivered
after a delay with the time it is valid for. Frames: world NED, body FRD.

Every model satisfies :class:`NavSource`, the localization interface (Angler's "mux"): a new
sensor is one class with ``name``, ``due(t)`` and ``sample(t, truth)``. Nothing here estimates;
the filter is :mod:`testbed.vehicle.estimation`.

Models (all noise 1σ, white, per component):

- Motion capture: NED position, 100 Hz, σ 1 mm (a Qualisys/OptiTrack pool set-up, as Angler's
  BlueROV2 Heavy tests), optional latency.
- DVL: body velocity (u, v, w) FRD, 5 Hz, σ 0.01 m/s — about 1 % of 1 m/s, the order of the
  Water Linked DVL A50's stated long-term accuracy (±1.01 %, unverified vendor figure) at ROV
  speeds; bottom lock only at an altitude in [0.05, 50] m (the A50's stated range, unverified),
  random dropouts with a probability per sample; no measurement without lock.
- Acoustic fix (USBL-like): NED position every 2 s, σ 0.5 m, valid at the ping time but
  delivered ``delay_s`` later (held in a small queue until then).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal, Protocol

import numpy as np

from testbed.config import check_range
from testbed.vehicle.sensors import NormalDraws, SampleClock

if TYPE_CHECKING:
    from testbed.vehicle.resources import PlantTruth

__all__ = [
    "Accelerometer",
    "AccelerometerConfig",
    "AcousticFix",
    "AcousticFixConfig",
    "Dvl",
    "DvlConfig",
    "Measurement",
    "MeasurementKind",
    "MotionCapture",
    "MotionCaptureConfig",
    "NavSource",
]

MeasurementKind = Literal["position_ned", "velocity_body", "depth", "acceleration_ned"]
"""What a :class:`Measurement` holds: (3,) NED position [m], (3,) body FRD velocity [m/s],
(1,) depth [m, positive down] or (3,) NED acceleration [m/s²] (an input to the filter's
prediction, not an update)."""

NAV_RATE_RANGE_HZ = (0.001, 10000.0)
"""Accepted navigation sensor rates [Hz]; polled once per frame, so a rate above the frame rate
gives one measurement per frame."""
DELAY_RANGE_S = (0.0, 10.0)
"""Accepted delivery delays [s]; the filter's history must cover the delay (default 5 s)."""


@dataclass(frozen=True, slots=True)
class Measurement:
    """One navigation measurement.

    Attributes:
        source: the name of the source that produced it.
        kind: what ``value`` is (:data:`MeasurementKind`).
        time_s: the instant the value is valid for [s] (earlier than delivery when delayed).
        value: the measured components (3 for positions and velocities, 1 for depth).
        sigma: 1σ noise of each component, same units as ``value`` (all > 0).
    """

    source: str
    kind: MeasurementKind
    time_s: float
    value: tuple[float, ...]
    sigma: tuple[float, ...]


class NavSource(Protocol):
    """The localization interface: anything that yields :class:`Measurement`\\ s from truth.

    Attributes:
        name: the source's name, copied into its measurements.
    """

    name: str

    def due(self, time_s: float) -> bool:
        """Whether :meth:`sample` may return a measurement at ``time_s`` [s]."""
        ...

    def sample(self, time_s: float, truth: PlantTruth) -> Measurement | None:
        """Measure ``truth`` at ``time_s`` [s]; the measurement delivered now, or ``None``."""
        ...


class _DelayLine:
    """Measurements held until their delivery time (FIFO: delays are constant)."""

    __slots__ = ("_queue", "delay_s")

    def __init__(self, delay_s: float) -> None:
        self.delay_s = delay_s
        self._queue: deque[Measurement] = deque()

    def push(self, measurement: Measurement) -> None:
        self._queue.append(measurement)

    def ready(self, time_s: float) -> bool:
        return bool(self._queue) and time_s >= self._queue[0].time_s + self.delay_s - 1e-9

    def pop(self, time_s: float) -> Measurement | None:
        return self._queue.popleft() if self.ready(time_s) else None

    def __len__(self) -> int:
        return len(self._queue)


def _check_rate(rate_hz: float) -> None:
    check_range(rate_hz, "rate_hz", *NAV_RATE_RANGE_HZ, "Hz")


class _DelayedPositionSource:
    """Shared body of the position sources: sample on the clock, deliver through a delay."""

    __slots__ = ("_clock", "_line", "_normals", "_sigma", "name")

    def __init__(
        self, name: str, rate_hz: float, noise_m: float, delay_s: float, rng: np.random.Generator
    ) -> None:
        self.name = name
        self._clock = SampleClock(rate_hz)
        self._line = _DelayLine(delay_s)
        self._normals = NormalDraws(rng)
        self._sigma = noise_m

    @property
    def pending(self) -> int:
        """Measurements taken and not yet delivered."""
        return len(self._line)

    def due(self, time_s: float) -> bool:
        """Whether a sample is due or a held one is ready at ``time_s`` [s]."""
        return self._clock.due(time_s) or self._line.ready(time_s)

    def sample(self, time_s: float, truth: PlantTruth) -> Measurement | None:
        """Take a fix of the true NED position if one is due; deliver the oldest ready one.

        Returns:
            the measurement whose delivery time has come (valid at its own ``time_s``), or
            ``None``.
        """
        if self._clock.due(time_s):
            self._clock.advance(time_s)
            value = self._normals.perturbed(truth.position_ned_m, self._sigma)
            sigma = max(self._sigma, 1e-9)
            self._line.push(
                Measurement(self.name, "position_ned", time_s, value, (sigma, sigma, sigma))
            )
        return self._line.pop(time_s)


# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class MotionCaptureConfig:
    """Motion-capture position (pool tracking system; attitude not modelled).

    Domains: ``rate_hz`` in [0.001, 10000] Hz; ``noise_m`` in [0, 1] m; ``latency_s`` in
    [0, 10] s.

    Attributes:
        rate_hz: output rate [Hz].
        noise_m: position noise per NED axis [m], 1σ.
        latency_s: delivery delay after the instant measured [s].
    """

    rate_hz: float = 100.0
    noise_m: float = 0.001
    latency_s: float = 0.0

    def __post_init__(self) -> None:
        _check_rate(self.rate_hz)
        check_range(self.noise_m, "noise_m", 0.0, 1.0, "m")
        check_range(self.latency_s, "latency_s", *DELAY_RANGE_S, "s")


class MotionCapture(_DelayedPositionSource):
    """Motion capture: NED position with mm-level white noise, optionally late."""

    __slots__ = ("config",)

    def __init__(
        self, config: MotionCaptureConfig, rng: np.random.Generator, name: str = "mocap"
    ) -> None:
        super().__init__(name, config.rate_hz, config.noise_m, config.latency_s, rng)
        self.config = config


@dataclass(frozen=True, slots=True)
class AcousticFixConfig:
    """USBL-like acoustic position fix, delivered late.

    Domains: ``rate_hz`` in [0.001, 10000] Hz; ``noise_m`` in [0, 100] m; ``delay_s`` in
    [0, 10] s.

    Attributes:
        rate_hz: ping rate [Hz] (0.5 = every 2 s).
        noise_m: position noise per NED axis [m], 1σ.
        delay_s: delivery delay after the ping [s] (travel time and processing).
    """

    rate_hz: float = 0.5
    noise_m: float = 0.5
    delay_s: float = 0.75

    def __post_init__(self) -> None:
        _check_rate(self.rate_hz)
        check_range(self.noise_m, "noise_m", 0.0, 100.0, "m")
        check_range(self.delay_s, "delay_s", *DELAY_RANGE_S, "s")


class AcousticFix(_DelayedPositionSource):
    """Acoustic position fix: metre-level noise, valid at the ping, delivered ``delay_s`` later."""

    __slots__ = ("config",)

    def __init__(
        self, config: AcousticFixConfig, rng: np.random.Generator, name: str = "usbl"
    ) -> None:
        super().__init__(name, config.rate_hz, config.noise_m, config.delay_s, rng)
        self.config = config


# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class DvlConfig:
    """Doppler velocity log: body velocity while locked on the bottom.

    Domains: ``rate_hz`` in [0.001, 10000] Hz; ``noise_m_s`` in [0, 10] m/s;
    ``bottom_depth_m`` in [0, 11000] m; ``min_altitude_m`` in [0, 1000] m and
    ``max_altitude_m`` in [min_altitude_m, 1000] m; ``dropout_probability`` in [0, 1].

    Attributes:
        rate_hz: output rate [Hz].
        noise_m_s: velocity noise per body axis [m/s], 1σ.
        bottom_depth_m: depth of a flat bottom [m, positive down]; altitude = this − depth.
        min_altitude_m, max_altitude_m: the altitude range of bottom lock [m].
        dropout_probability: chance that a locked sample is lost anyway (per sample).
    """

    rate_hz: float = 5.0
    noise_m_s: float = 0.01
    bottom_depth_m: float = 10.0
    min_altitude_m: float = 0.05
    max_altitude_m: float = 50.0
    dropout_probability: float = 0.0

    def __post_init__(self) -> None:
        _check_rate(self.rate_hz)
        check_range(self.noise_m_s, "noise_m_s", 0.0, 10.0, "m/s")
        check_range(self.bottom_depth_m, "bottom_depth_m", 0.0, 11000.0, "m")
        check_range(self.min_altitude_m, "min_altitude_m", 0.0, 1000.0, "m")
        check_range(self.max_altitude_m, "max_altitude_m", self.min_altitude_m, 1000.0, "m")
        check_range(self.dropout_probability, "dropout_probability", 0.0, 1.0)


class Dvl:
    """DVL: body FRD velocity with white noise, only with bottom lock; see the module docstring."""

    __slots__ = ("_clock", "_rng", "config", "dropouts", "name", "unlocked")

    def __init__(self, config: DvlConfig, rng: np.random.Generator, name: str = "dvl") -> None:
        self.config = config
        self.name = name
        self._rng = rng
        self._clock = SampleClock(config.rate_hz)
        self.dropouts = 0
        """Locked samples lost to random dropout."""
        self.unlocked = 0
        """Samples without bottom lock (altitude out of range)."""

    def altitude_m(self, depth_m: float) -> float:
        """Height above the configured flat bottom [m] at ``depth_m`` [m, positive down]."""
        return self.config.bottom_depth_m - depth_m

    def due(self, time_s: float) -> bool:
        """Whether a sample is due at ``time_s`` [s]."""
        return self._clock.due(time_s)

    def sample(self, time_s: float, truth: PlantTruth) -> Measurement | None:
        """Measure the true body velocity (u, v, w) [m/s], FRD, if locked and not dropped.

        The same draws are taken whatever the outcome, so lock does not shift later noise.
        """
        self._clock.advance(time_s)
        cfg = self.config
        draws = self._rng.standard_normal(3)
        lost = float(self._rng.random()) < cfg.dropout_probability
        altitude = self.altitude_m(truth.position_ned_m[2])
        if not cfg.min_altitude_m <= altitude <= cfg.max_altitude_m:
            self.unlocked += 1
            return None
        if lost:
            self.dropouts += 1
            return None
        s = cfg.noise_m_s
        u, v, w = truth.velocity_m_s
        value = (u + s * float(draws[0]), v + s * float(draws[1]), w + s * float(draws[2]))
        sigma = max(s, 1e-9)
        return Measurement(self.name, "velocity_body", time_s, value, (sigma, sigma, sigma))


@dataclass(frozen=True, slots=True)
class AccelerometerConfig:
    """The IMU's accelerometer, as its AHRS outputs it: NED linear acceleration, gravity removed
    with the AHRS attitude.

    Domains: ``rate_hz`` in [0.001, 10000] Hz; ``noise_m_s2`` in [0, 10] m/s²; each bias
    component in [−10, 10] m/s².

    Attributes:
        rate_hz: output rate [Hz] (one sample per frame at most).
        noise_m_s2: white noise per NED axis [m/s²], 1σ (0.02: a MEMS IMU's ≈ 150 µg/√Hz at
            100 Hz plus the gravity-removal error of a 0.1° attitude error, ≈ 0.017 m/s²).
        bias_m_s2: (3,) constant NED bias [m/s²] (not estimated by the filter).
    """

    rate_hz: float = 100.0
    noise_m_s2: float = 0.02
    bias_m_s2: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        _check_rate(self.rate_hz)
        check_range(self.noise_m_s2, "noise_m_s2", 0.0, 10.0, "m/s²")
        for value in self.bias_m_s2:
            check_range(value, "bias_m_s2", -10.0, 10.0, "m/s²")


class Accelerometer:
    """The accelerometer: the true mean NED acceleration over the last frame
    (:attr:`~testbed.vehicle.resources.PlantTruth.acceleration_ned_m_s2`) plus bias and white
    noise, as an ``acceleration_ned`` measurement (the filter's prediction input)."""

    __slots__ = ("_clock", "_normals", "config", "name")

    def __init__(
        self, config: AccelerometerConfig, rng: np.random.Generator, name: str = "accel"
    ) -> None:
        self.config = config
        self.name = name
        self._normals = NormalDraws(rng)
        self._clock = SampleClock(config.rate_hz)

    def due(self, time_s: float) -> bool:
        """Whether a sample is due at ``time_s`` [s]."""
        return self._clock.due(time_s)

    def sample(self, time_s: float, truth: PlantTruth) -> Measurement | None:
        """Measure the true NED acceleration now [m/s²]."""
        self._clock.advance(time_s)
        cfg = self.config
        (a0, a1, a2), (b0, b1, b2) = truth.acceleration_ned_m_s2, cfg.bias_m_s2
        value = self._normals.perturbed((a0 + b0, a1 + b1, a2 + b2), cfg.noise_m_s2)
        sigma = max(cfg.noise_m_s2, 1e-9)
        return Measurement(self.name, "acceleration_ned", time_s, value, (sigma, sigma, sigma))
