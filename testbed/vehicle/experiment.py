"""The ECS paper's attitude experiment (McIvor et al., §V), re-run on the simulated vehicle.

The paper commanded an oscillating orientation setpoint on a BlueROV2 in a pool, about 0.3 m
below the surface, and reported the distribution of the attitude error: yaw with 4, 3 and 2
horizontal thrusters (error below 2°, standard deviation ≈ 0.5°), and roll and pitch with one
horizontal thruster remounted as a side vertical (standard deviations 1.283° and 1.228°).

The paper gives neither the setpoint's amplitude nor its period; :data:`PAPER_EXPERIMENTS` uses
sinusoids of realistic size for a pilot's manoeuvre: yaw ±20° over 25 s; roll ±15° over 20 s
together with pitch ±10° over 30 s (different periods, so the two are not locked together),
yaw held. Depth is held at 0.3 m in a 0.1 m/s current, with the default sensor noise.

The error is the commanded attitude (the last setpoint sent, every ``setpoint_period_s``)
against the physics truth (not the vehicle's own estimate, which the paper likely logged):
Z-Y-X Euler angles of the true attitude minus the setpoint's, wrapped, sampled every
``sample_period_s`` from ``settle_s`` to the end of the run.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from testbed.vehicle.components import ControlMode
from testbed.vehicle.control import quat_from_euler, wrap_angle
from testbed.vehicle.hydrodynamics import WaterCurrent
from testbed.vehicle.vehicle import ControlGains, SensorsConfig, Vehicle, VehicleConfig

__all__ = [
    "PAPER_EXPERIMENTS",
    "AttitudeExperiment",
    "AxisProfile",
    "ErrorStats",
    "ExperimentResult",
    "run_attitude_experiment",
]


@dataclass(frozen=True, slots=True)
class AxisProfile:
    """A sinusoidal setpoint ``amplitude·sin(2π t / period)`` [rad] (amplitude 0 = hold 0)."""

    amplitude_rad: float = 0.0
    period_s: float = 25.0

    def at(self, time_s: float) -> float:
        """The setpoint [rad] at ``time_s``."""
        if self.amplitude_rad == 0.0:
            return 0.0
        return self.amplitude_rad * math.sin(2.0 * math.pi * time_s / self.period_s)


@dataclass(frozen=True, slots=True)
class AttitudeExperiment:
    """One run of the experiment.

    Attributes:
        thrusters: thruster layout name.
        roll, pitch, yaw: setpoint profiles.
        depth_m: depth held [m].
        duration_s: simulated time [s].
        settle_s: samples before this are discarded [s].
        sample_period_s: error sampling period [s].
        setpoint_period_s: how often the operator sends the setpoint (and keeps the link
            alive) [s]. Sampling and setpoint periods that are multiples of the physics step
            (1/240 s: 0.05 and 0.025 s) keep the samples exactly periodic.
        current_ned_mps: (3,) water current [m/s], NED.
        gains: closed-loop gains.
        sensors: sensor models.
    """

    thrusters: str
    roll: AxisProfile = field(default_factory=AxisProfile)
    pitch: AxisProfile = field(default_factory=AxisProfile)
    yaw: AxisProfile = field(default_factory=AxisProfile)
    depth_m: float = 0.3
    duration_s: float = 60.0
    settle_s: float = 10.0
    sample_period_s: float = 0.05
    setpoint_period_s: float = 0.025
    current_ned_mps: tuple[float, float, float] = (0.1, 0.0, 0.0)
    gains: ControlGains = field(default_factory=ControlGains)
    sensors: SensorsConfig = field(default_factory=SensorsConfig)

    def vehicle_config(self) -> VehicleConfig:
        """The vehicle this experiment runs."""
        return VehicleConfig(
            thrusters=self.thrusters,
            gains=self.gains,
            sensors=self.sensors,
            current=WaterCurrent(velocity_ned_mps=self.current_ned_mps),
            start_position_ned_m=(0.0, 0.0, self.depth_m),
        )


@dataclass(frozen=True, slots=True)
class ErrorStats:
    """Distribution of one axis's error [deg]: median and 95th percentile of |e|, std, mean."""

    p50_abs_deg: float
    p95_abs_deg: float
    std_deg: float
    mean_deg: float
    max_abs_deg: float
    samples: int

    @classmethod
    def of(cls, errors_deg: np.ndarray) -> ErrorStats:
        """Statistics of a 1-D array of errors [deg]."""
        magnitude = np.abs(errors_deg)
        return cls(
            p50_abs_deg=float(np.percentile(magnitude, 50)),
            p95_abs_deg=float(np.percentile(magnitude, 95)),
            std_deg=float(np.std(errors_deg)),
            mean_deg=float(np.mean(errors_deg)),
            max_abs_deg=float(np.max(magnitude)),
            samples=int(errors_deg.size),
        )


@dataclass(frozen=True, slots=True, eq=False)
class ExperimentResult:
    """Errors of one run (true − setpoint, deg, after settling) and their statistics."""

    time_s: np.ndarray
    errors_deg: np.ndarray  # (N, 3) roll, pitch, yaw
    roll: ErrorStats
    pitch: ErrorStats
    yaw: ErrorStats
    depth_error_m: ErrorStats  # (in metres, despite the field names)


def run_attitude_experiment(experiment: AttitudeExperiment, seed: int) -> ExperimentResult:
    """Run the experiment on a fresh vehicle seeded with ``seed``."""
    config = experiment.vehicle_config()
    times: list[float] = []
    errors: list[tuple[float, float, float]] = []
    depth_errors: list[float] = []
    with Vehicle(config, np.random.default_rng(seed)) as vehicle:
        vehicle.arm()
        vehicle.set_mode(ControlMode.DEPTH_HOLD)
        vehicle.set_depth(experiment.depth_m)
        next_sample = experiment.settle_s
        t = 0.0
        step = experiment.setpoint_period_s
        while t < experiment.duration_s - 1e-9:
            commanded = (experiment.roll.at(t), experiment.pitch.at(t), experiment.yaw.at(t))
            vehicle.set_attitude(quat_from_euler(*commanded))
            vehicle.command((0.0, 0.0, 0.0, 0.0, 0.0, 0.0))
            t = min(experiment.duration_s, t + step)
            vehicle.advance(t)
            now = vehicle.time_s
            if next_sample - 1e-9 <= now < experiment.duration_s - 1e-9:
                state = vehicle.state()
                actual = state.euler_rad.tolist()
                errors.append(
                    (
                        math.degrees(wrap_angle(actual[0] - commanded[0])),
                        math.degrees(wrap_angle(actual[1] - commanded[1])),
                        math.degrees(wrap_angle(actual[2] - commanded[2])),
                    )
                )
                depth_errors.append(float(state.position_ned[2]) - experiment.depth_m)
                times.append(now)
                next_sample += experiment.sample_period_s
    table = np.array(errors)
    return ExperimentResult(
        time_s=np.array(times),
        errors_deg=table,
        roll=ErrorStats.of(table[:, 0]),
        pitch=ErrorStats.of(table[:, 1]),
        yaw=ErrorStats.of(table[:, 2]),
        depth_error_m=ErrorStats.of(np.array(depth_errors)),
    )


_YAW = AxisProfile(math.radians(20.0), 25.0)

PAPER_EXPERIMENTS: dict[str, AttitudeExperiment] = {
    "ecs-4h": AttitudeExperiment("ecs-4h", yaw=_YAW),
    "ecs-3h": AttitudeExperiment("ecs-3h", yaw=_YAW),
    "ecs-2h": AttitudeExperiment("ecs-2h", yaw=_YAW),
    "ecs-6dof": AttitudeExperiment(
        "ecs-6dof",
        roll=AxisProfile(math.radians(15.0), 20.0),
        pitch=AxisProfile(math.radians(10.0), 30.0),
    ),
}
"""The four configurations of the paper's §V with this module's setpoint choices."""
