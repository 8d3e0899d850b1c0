"""Vehicle control laws: PID, attitude and depth hold, failsafe (the pilot's in :mod:`.pilot`).

Everything here is pure and framework-free: controllers are small stateful objects fed with
*sensor* values (never the physics truth) and returning body-frame force/torque intents; the ECS
systems in :mod:`testbed.vehicle.systems` own them and sum their intents for the allocator.

Frames and conventions: world NED, body FRD; quaternions are ``(w, x, y, z)`` tuples rotating
body vectors into the world frame; wrenches are ``(X, Y, Z, K, M, N)`` = (surge, sway, heave
force [N], roll, pitch, yaw torque [N·m]) in the body frame. The laws follow mate-rov-2025
(REFERENCE §3.6): orientation error ``q_err = q_target·q_current⁻¹`` split per body axis by
swing–twist, in **degrees** so that mate-rov's published gains apply unchanged; depth error
``e = target − depth`` (positive down) drives a world-vertical force rotated into the body.

The hot path uses Python floats and tuples, not NumPy: six-element arrays cost more in call
overhead than the arithmetic they hold. Nothing in this module draws random numbers.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Literal

from testbed.common.geometry import (
    Quaternion,
    Vec3,
    attitude_error,
    quat_conjugate,
    quat_multiply,
    quat_rotate_inverse,
)
from testbed.config import check, check_range

__all__ = [
    "PID",
    "AttitudeController",
    "AttitudeGains",
    "DepthController",
    "FailsafeConfig",
    "PidGains",
    "failsafe_level",
]

_DEG_PER_RAD = 180.0 / math.pi


# --------------------------------------------------------------------------------------------
# PID


MAX_PID_GAIN = 1e6
"""Largest accepted kp, ki, kd (loop units): ≥ 10⁴× the packaged gains, far past any stable
loop, small enough that gain × error stays finite."""
MAX_PID_LIMIT = 1e9
"""Largest finite accepted ``max_integral``, ``max_output``, ``i_zone``; beyond it use ``inf``."""


@dataclass(frozen=True, slots=True)
class PidGains:
    """Gains and limits of one PID loop (units follow the loop: error unit → output unit).

    Domains (checked at construction): the gains are finite, in [0, 1e6]; ``max_integral``,
    ``max_output`` and ``i_zone`` in (0, 1e9] or ``inf``; ``derivative_tau_s`` in [0, 10] s;
    ``tracking_time_s`` in [1e-3, 100] s.

    Attributes:
        kp, ki, kd: proportional, integral [1/s] and derivative [s] gains, ≥ 0.
        max_integral: clamp on the integral state (error·s), as mate-rov's ``maxI``
            (``inf`` = none).
        max_output: clamp on the output (``inf`` = none).
        i_zone: the integral is cleared while ``|error| >= i_zone`` (``inf`` = never).
        derivative_tau_s: time constant of the first-order low-pass on the derivative (0 = none).
        anti_windup: ``"clamp"`` (integral clamp only), ``"conditional"`` (stop integrating
            while the output saturates in the direction of the error) or
            ``"back_calculation"`` (bleed the integral by the saturation excess).
        tracking_time_s: back-calculation tracking time constant [s].
    """

    kp: float = 0.0
    ki: float = 0.0
    kd: float = 0.0
    max_integral: float = math.inf
    max_output: float = math.inf
    i_zone: float = math.inf
    derivative_tau_s: float = 0.0
    anti_windup: Literal["clamp", "conditional", "back_calculation"] = "conditional"
    tracking_time_s: float = 0.1

    def __post_init__(self) -> None:
        for name in ("kp", "ki", "kd"):
            check_range(getattr(self, name), name, 0.0, MAX_PID_GAIN)
        for name in ("max_integral", "max_output", "i_zone"):
            check_range(
                getattr(self, name), name, 0.0, MAX_PID_LIMIT, low_open=True, allow_inf=True
            )
        check_range(self.derivative_tau_s, "derivative_tau_s", 0.0, 10.0, "s")
        check_range(self.tracking_time_s, "tracking_time_s", 1e-3, 100.0, "s")


class PID:
    """A discrete PID loop with derivative filter, i-zone, output clamp and anti-windup.

    ``update`` takes the error and, optionally, its rate (e.g. from a gyro, which is far less
    noisy than differencing a measured angle); without it the derivative is the filtered
    backward difference of the error. The terms of the last update are kept in ``p``, ``i``,
    ``d`` for telemetry.
    """

    __slots__ = ("_d_state", "_has_last", "_last_error", "d", "gains", "i", "integral", "p")

    def __init__(self, gains: PidGains) -> None:
        self.gains = gains
        self.integral = 0.0
        self.p = self.i = self.d = 0.0
        self._last_error = 0.0
        self._has_last = False
        self._d_state = 0.0

    def reset(self) -> None:
        """Forget the integral, the previous error and the derivative filter state."""
        self.integral = 0.0
        self.p = self.i = self.d = 0.0
        self._last_error = 0.0
        self._has_last = False
        self._d_state = 0.0

    def update(self, error: float, dt_s: float, error_rate: float | None = None) -> float:
        """Advance one step and return the (clamped) output.

        Args:
            error: setpoint minus measurement, in the loop's error unit.
            dt_s: time since the previous update [s], > 0.
            error_rate: d(error)/dt if known; otherwise the error is differenced.

        Raises:
            ValueError: ``dt_s`` is not positive.
        """
        if not dt_s > 0.0:
            raise ValueError(f"dt_s must be > 0, got {dt_s}")
        g = self.gains
        has_last = self._has_last
        if error_rate is None:
            raw = (error - self._last_error) / dt_s if has_last else 0.0
        else:
            raw = error_rate
        tau = g.derivative_tau_s
        if tau > 0.0 and has_last:
            d_state = self._d_state
            d_state += (raw - d_state) * (dt_s / (tau + dt_s))
        else:
            d_state = raw
        self._d_state = d_state
        self._last_error = error
        self._has_last = True

        # clamps below are max(-c, min(c, x)) written out (same result, NaN included)
        p = g.kp * error
        d = g.kd * d_state
        limit = g.max_output
        if abs(error) >= g.i_zone:
            self.integral = 0.0
        else:
            cap = g.max_integral
            candidate = self.integral + error * dt_s
            candidate = candidate if candidate < cap else cap
            candidate = candidate if candidate > -cap else -cap
            anti_windup = g.anti_windup
            if anti_windup == "conditional":
                unsat = p + g.ki * candidate + d
                if abs(unsat) <= limit or (unsat > 0.0) != (error > 0.0):
                    self.integral = candidate
            elif anti_windup == "back_calculation" and g.ki != 0.0:
                # İ = e + (sat(u) − u)/(ki·Tt), u from the integral before this step
                unsat = p + g.ki * self.integral + d
                excess = max(-limit, min(limit, unsat)) - unsat
                candidate += excess * dt_s / (g.tracking_time_s * g.ki)
                self.integral = max(-cap, min(cap, candidate))
            else:
                self.integral = candidate
        i = g.ki * self.integral
        self.p, self.i, self.d = p, i, d
        out = p + i + d
        out = out if out < limit else limit
        return out if out > -limit else -limit


# --------------------------------------------------------------------------------------------
# Attitude and depth hold


@dataclass(frozen=True, slots=True)
class AttitudeGains:
    """Per-axis attitude PIDs; error in degrees, output in N·m (mate-rov's units)."""

    roll: PidGains = field(default_factory=PidGains)
    pitch: PidGains = field(default_factory=PidGains)
    yaw: PidGains = field(default_factory=PidGains)


MAX_TARGET_RATE_HOLD_S = 0.25
"""Longest time [s] over which one step of an attitude target is fed forward as a rate."""


class AttitudeController:
    """Three per-axis PIDs on the swing–twist attitude error, returning a body torque.

    The derivative is fed the error rate ``target rate − body rate`` from the gyro and the
    target's own motion, so no measured angle is ever differenced. Targets arrive held (a
    setpoint sent at 40 Hz and received over a link steps every 2–3 frames of 100 Hz), so each
    step of the target is fed forward as its size over the mean time between its steps (the
    mean of the last interval and the mean before; at most :data:`MAX_TARGET_RATE_HOLD_S`),
    held until the next step: a steady setpoint's rate feeds forward within ≈ 10 % of
    constant, without the spike on the frames it stepped and nothing in between that one
    frame's difference gives; a lone step after a still spell (≥ 0.5 s) is fed over 0.25 s in
    full instead of kicking in one frame (after a shorter one, up to 1.5 × its size over the
    mean interval: the feedforward's only overshoot).
    """

    __slots__ = (
        "_hold_left_s",
        "_interval_s",
        "_last_target",
        "_since_change_s",
        "_target_rate_ned",
        "pids",
    )

    def __init__(self, gains: AttitudeGains) -> None:
        self.pids = (PID(gains.roll), PID(gains.pitch), PID(gains.yaw))
        self._last_target: Quaternion | None = None
        self._since_change_s = 0.0
        self._interval_s = 0.0  # the mean time between the target's steps (0: none yet)
        self._hold_left_s = 0.0
        self._target_rate_ned: Vec3 = (0.0, 0.0, 0.0)

    def reset(self) -> None:
        """Reset every axis and forget the previous target and its rate."""
        for pid in self.pids:
            pid.reset()
        self._last_target = None
        self._since_change_s = 0.0
        self._interval_s = 0.0
        self._hold_left_s = 0.0
        self._target_rate_ned = (0.0, 0.0, 0.0)

    def update(
        self,
        target: Quaternion,
        current: Quaternion,
        rates_rad_s: Sequence[float],
        dt_s: float,
        axes: tuple[bool, bool, bool] = (True, True, True),
    ) -> Vec3:
        """One control step.

        Args:
            target: (4,) target attitude, body → NED.
            current: (4,) measured attitude, body → NED.
            rates_rad_s: (3,) measured body rates (p, q, r) [rad/s], FRD.
            dt_s: time since the previous step [s], > 0.
            axes: which of roll, pitch, yaw to control (e.g. pitch off when the thruster layout
                cannot produce pitch torque); a disabled axis outputs 0 and is reset.

        Returns:
            (3,) body torque (K, M, N) [N·m], FRD.

        Raises:
            ValueError: ``dt_s`` is not positive.
        """
        if not dt_s > 0.0:  # before the target's rate divides by the time it took
            raise ValueError(f"dt_s must be > 0, got {dt_s}")
        errors = attitude_error(target, current)
        last = self._last_target
        self._since_change_s += dt_s
        rate = self._target_rate_ned
        left = self._hold_left_s
        if last is None:
            self._since_change_s = 0.0
        elif last is not target and last != target:
            # the target's step since it last changed (a small world-frame rotation, whose
            # rotation vector is 2·vec(target·last⁻¹)) over the mean time between its steps
            sw, sx, sy, sz = quat_multiply(target, quat_conjugate(last))
            if sw < 0.0:
                sx, sy, sz = -sx, -sy, -sz
            since = self._since_change_s
            mean = self._interval_s
            mean = self._interval_s = since if mean == 0.0 else 0.5 * (mean + since)
            spread = min(mean, MAX_TARGET_RATE_HOLD_S)
            k = 2.0 / spread
            rate = self._target_rate_ned = (k * sx, k * sy, k * sz)
            # held until the next step, or until it is late by half the mean interval (the
            # target stopped); a lone step is thus fed over MAX_TARGET_RATE_HOLD_S in full
            left = spread if spread >= MAX_TARGET_RATE_HOLD_S else 1.5 * spread
            self._since_change_s = 0.0
        self._last_target = target
        if left > 1e-9:  # still feeding the last step: this frame's share of it
            self._hold_left_s = left - dt_s
            if left < dt_s:
                f = left / dt_s
                rate = (rate[0] * f, rate[1] * f, rate[2] * f)
            target_rates = quat_rotate_inverse(current, rate)
        else:
            self._hold_left_s = 0.0
            target_rates = (0.0, 0.0, 0.0)
        out = [0.0, 0.0, 0.0]
        for k in range(3):
            pid = self.pids[k]
            if not axes[k]:
                pid.reset()
                continue
            rate_deg_s = (target_rates[k] - rates_rad_s[k]) * _DEG_PER_RAD
            out[k] = pid.update(errors[k] * _DEG_PER_RAD, dt_s, rate_deg_s)
        return (out[0], out[1], out[2])


class DepthController:
    """Depth hold: PID on ``e = target − depth`` (m, positive down) → world-down force [N].

    The force acts along world +Z (down) and is rotated into the body frame with the measured
    attitude, so holding depth does not push the vehicle sideways when it is tilted. A constant
    ``feedforward_n`` (e.g. minus the net buoyancy) may be added to the world-down force.
    """

    __slots__ = ("feedforward_n", "pid")

    def __init__(self, gains: PidGains, feedforward_n: float = 0.0) -> None:
        self.pid = PID(gains)
        self.feedforward_n = feedforward_n

    def reset(self) -> None:
        """Reset the PID."""
        self.pid.reset()

    def update(
        self, target_depth_m: float, depth_m: float, attitude: Quaternion, dt_s: float
    ) -> Vec3:
        """One control step.

        Args:
            target_depth_m: setpoint [m], positive down.
            depth_m: measured depth [m], positive down.
            attitude: (4,) measured attitude, body → NED.
            dt_s: time since the previous step [s].

        Returns:
            (3,) body force (X, Y, Z) [N], FRD.
        """
        down_n = self.pid.update(target_depth_m - depth_m, dt_s) + self.feedforward_n
        return quat_rotate_inverse(attitude, (0.0, 0.0, down_n))


# --------------------------------------------------------------------------------------------
# Failsafe


MAX_FAILSAFE_AGE_S = 86400.0
"""Largest accepted failsafe command age [s]: one day, the longest scenario."""


@dataclass(frozen=True, slots=True)
class FailsafeConfig:
    """Vehicle-side failsafe on stale operator commands.

    Domains: both ages in (0, 86400] s (a day: longer than any run), surface after hold;
    ``ascent_rate_m_s`` in (0, 10] m/s; ``surfaced_depth_m`` in [0, 10] m.

    Attributes:
        hold_after_s: command age at which the vehicle holds depth and heading (sticks zeroed).
        surface_after_s: command age at which it surfaces (depth target rises) and, once at
            ``surfaced_depth_m`` or shallower, disarms.
        ascent_rate_m_s: how fast the depth target rises while surfacing.
        surfaced_depth_m: depth [m] counted as surfaced.
    """

    hold_after_s: float = 1.0
    surface_after_s: float = 5.0
    ascent_rate_m_s: float = 0.25
    surfaced_depth_m: float = 0.15

    def __post_init__(self) -> None:
        check_range(self.hold_after_s, "hold_after_s", 0.0, MAX_FAILSAFE_AGE_S, "s", low_open=True)
        check_range(
            self.surface_after_s, "surface_after_s", 0.0, MAX_FAILSAFE_AGE_S, "s", low_open=True
        )
        check(
            self.surface_after_s > self.hold_after_s,
            "surface_after_s",
            f"must be > hold_after_s ({self.hold_after_s}), got {self.surface_after_s}",
        )
        check_range(self.ascent_rate_m_s, "ascent_rate_m_s", 0.0, 10.0, "m/s", low_open=True)
        check_range(self.surfaced_depth_m, "surfaced_depth_m", 0.0, 10.0, "m")


def failsafe_level(command_age_s: float, config: FailsafeConfig) -> Literal[0, 1, 2]:
    """0 nominal, 1 hold, 2 surface, from the age of the last fresh operator command [s]."""
    if command_age_s >= config.surface_after_s:
        return 2
    if command_age_s >= config.hold_after_s:
        return 1
    return 0
