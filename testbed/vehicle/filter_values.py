"""The Kalman navigator's plain values: its settings, its counts and the estimate it gives.

:class:`FilterConfig` (noise figures [m²/s³, m, m/s] and bookkeeping of
:class:`~testbed.vehicle.estimation.KalmanNavigator`, checked on construction),
:class:`FilterCounters` (what happened to the measurements it was given) and
:class:`NavigationEstimate` (the vehicle-local component it publishes: NED position and
velocity, body-frame FRD velocity, IMU attitude and rates, 1σ). Frozen dataclasses of plain
values; no filter arithmetic and no ECS here (:mod:`testbed.vehicle.estimation`,
:mod:`testbed.vehicle.localization`).
"""

from __future__ import annotations

from dataclasses import dataclass

from testbed.common.geometry import Quaternion, Vec3
from testbed.config import check_range

__all__ = ["FilterConfig", "FilterCounters", "NavigationEstimate"]


@dataclass(frozen=True, slots=True)
class NavigationEstimate:
    """The vehicle's navigation estimate at one instant (a vehicle-local component).

    Attributes:
        time_s: the instant it is valid for [s].
        position_ned_m: (3,) body-origin position [m], world NED.
        velocity_ned_m_s: (3,) velocity [m/s], world NED.
        velocity_body_m_s: (3,) the same velocity in the body frame (u, v, w) [m/s], FRD,
            rotated with the IMU attitude.
        quaternion_wxyz: attitude from the IMU, body → NED.
        rates_rad_s: (3,) body rates from the IMU [rad/s], FRD.
        position_sigma_m: (3,) 1σ of each position component [m].
        velocity_sigma_m_s: (3,) 1σ of each NED velocity component [m/s].
    """

    time_s: float
    position_ned_m: Vec3
    velocity_ned_m_s: Vec3
    velocity_body_m_s: Vec3
    quaternion_wxyz: Quaternion
    rates_rad_s: Vec3
    position_sigma_m: Vec3
    velocity_sigma_m_s: Vec3


@dataclass(frozen=True, slots=True)
class FilterConfig:
    """Noise figures and bookkeeping of :class:`KalmanNavigator`.

    Domains: ``accel_noise_m2_s3`` in (0, 100]; ``initial_position_sigma_m`` in (0, 1e4] m;
    ``initial_velocity_sigma_m_s`` in (0, 100] m/s; ``history_s`` in [0, 60] s;
    ``gate_probability`` in (0, 1); ``reacquire_after`` in [0, 1000].

    Attributes:
        accel_noise_m2_s3: ``q``, spectral density of the white acceleration per NED axis
            [m²/s³]. 0.1 suits an ROV whose accelerations of ≈ 0.3 m/s² last ≈ 1 s.
        initial_position_sigma_m: 1σ of the initial position per axis [m].
        initial_velocity_sigma_m_s: 1σ of the initial velocity per axis [m/s].
        history_s: how far back delayed measurements are re-processed [s].
        gate_probability: chi-square gate; innovations beyond this quantile are rejected.
        reacquire_after: consecutive rejections of one source after which the next rejected
            one re-acquires (module docstring); 0 never re-acquires.
    """

    accel_noise_m2_s3: float = 0.1
    initial_position_sigma_m: float = 10.0
    initial_velocity_sigma_m_s: float = 1.0
    history_s: float = 5.0
    gate_probability: float = 0.9999
    reacquire_after: int = 3

    def __post_init__(self) -> None:
        check_range(self.accel_noise_m2_s3, "accel_noise_m2_s3", 0.0, 100.0, "m²/s³", low_open=True)
        check_range(
            self.initial_position_sigma_m, "initial_position_sigma_m", 0.0, 1e4, "m", low_open=True
        )
        check_range(
            self.initial_velocity_sigma_m_s,
            "initial_velocity_sigma_m_s",
            0.0,
            100.0,
            "m/s",
            low_open=True,
        )
        check_range(self.history_s, "history_s", 0.0, 60.0, "s")
        check_range(
            self.gate_probability, "gate_probability", 0.0, 1.0, low_open=True, high_open=True
        )
        check_range(self.reacquire_after, "reacquire_after", 0, 1000)


@dataclass(frozen=True, slots=True)
class FilterCounters:
    """What happened to the measurements a filter was given (counts since construction).

    Attributes:
        accepted: applied.
        rejected: failed the chi-square gate.
        invalid: malformed (unknown kind, wrong length, non-finite value or σ ≤ 0).
        stale: older than the history, dropped.
        rollbacks: accepted measurements that were applied by rolling back.
        reacquired: rejected measurements applied after a covariance reset (module docstring).
    """

    accepted: int = 0
    rejected: int = 0
    invalid: int = 0
    stale: int = 0
    rollbacks: int = 0
    reacquired: int = 0
