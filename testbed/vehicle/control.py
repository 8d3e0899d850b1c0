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

The loops' arithmetic is compiled (:mod:`.control_kernels`); the classes here validate, hold the
state arrays and expose the terms. Nothing in this module draws random numbers.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Literal

import numpy as np

from testbed.common import jit
from testbed.common.geometry import Quaternion, Vec3
from testbed.common.jit import BOOL, F64, I64, MARK, TABLE, VECTOR, floats
from testbed.config import check, check_range

if TYPE_CHECKING:
    from testbed.ecs.store import RowView
from testbed.vehicle.control_kernels import (
    ATTITUDE_STATE_SIZE,
    BACK_CALCULATION,
    CLAMP,
    CONDITIONAL,
    D_TERM,
    I_TERM,
    INTEGRAL,
    MAX_TARGET_RATE_HOLD_S,
    P_TERM,
    PID_STATE_SIZE,
    attitude_rows,
    attitude_update,
    depth_rows,
    depth_update,
    pid_update,
)

__all__ = [
    "MAX_TARGET_RATE_HOLD_S",
    "PID",
    "AttitudeController",
    "AttitudeGains",
    "DepthController",
    "FailsafeConfig",
    "PidGains",
    "failsafe_level",
    "pid_gains_array",
]

# The loops' kernels, called without numba's dispatcher (testbed.common.jit.entry): states,
# gains and rows are the controllers' and the store's contiguous float64 arrays.
_GAINS3 = TABLE  # the attitude loop's three axes' gains, stacked
_AXES = jit.tuple_of(BOOL, 3)  # which of roll, pitch, yaw are controlled
_PID_UPDATE = jit.entry(pid_update, VECTOR, VECTOR, F64, F64, F64, BOOL)
_ATTITUDE_UPDATE = jit.entry(
    attitude_update, VECTOR, _GAINS3, floats(4), floats(4), floats(3), F64, _AXES
)
_DEPTH_UPDATE = jit.entry(depth_update, VECTOR, VECTOR, F64, F64, floats(4), F64, F64)
_ATTITUDE_ROWS = jit.entry(
    attitude_rows, VECTOR, _GAINS3, VECTOR, VECTOR, F64, _AXES, VECTOR, MARK, I64
)
_DEPTH_ROWS = jit.entry(
    depth_rows, VECTOR, VECTOR, F64, VECTOR, VECTOR, VECTOR, F64, VECTOR, MARK, I64
)


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
    ``d`` for telemetry. The arithmetic is :func:`~.control_kernels.pid_update`; this class
    holds the gains and the state it advances (a view into a larger state when ``state`` is
    given, as :class:`AttitudeController` does for its three axes).
    """

    __slots__ = ("_config", "_gains", "_state")

    def __init__(self, gains: PidGains, state: np.ndarray | None = None) -> None:
        self._config = gains
        self._gains = pid_gains_array(gains)
        if state is None:
            state = np.zeros(PID_STATE_SIZE)
        elif not (state.shape == (PID_STATE_SIZE,) and state.dtype == np.float64):
            raise ValueError(f"a PID's state must be ({PID_STATE_SIZE},) float64")
        elif not state.flags.c_contiguous:  # the kernels are called on it without checks
            raise ValueError("a PID's state must be one contiguous block")
        self._state = state
        self._state[:] = 0.0

    @property
    def gains(self) -> PidGains:
        """The loop's gains (fixed at construction: the kernel reads their array form)."""
        return self._config

    @property
    def integral(self) -> float:
        """The integral state [error unit · s]."""
        return float(self._state[INTEGRAL])

    @property
    def p(self) -> float:
        """The last update's proportional term."""
        return float(self._state[P_TERM])

    @property
    def i(self) -> float:
        """The last update's integral term."""
        return float(self._state[I_TERM])

    @property
    def d(self) -> float:
        """The last update's derivative term."""
        return float(self._state[D_TERM])

    @property
    def state_array(self) -> np.ndarray:
        """The state :func:`~.control_kernels.pid_update` advances (a view, not a copy)."""
        return self._state

    @property
    def gains_array(self) -> np.ndarray:
        """The gains in the kernels' layout (:func:`pid_gains_array`)."""
        return self._gains

    def reset(self) -> None:
        """Forget the integral, the previous error and the derivative filter state."""
        self._state[:] = 0.0

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
        has_rate = error_rate is not None
        rate = float(error_rate) if error_rate is not None else 0.0
        return _PID_UPDATE(self._state, self._gains, float(error), float(dt_s), rate, has_rate)


def pid_gains_array(gains: PidGains) -> np.ndarray:
    """``gains`` in :mod:`.control_kernels`' PID gains layout (9 float64)."""
    return np.array(
        [
            gains.kp,
            gains.ki,
            gains.kd,
            gains.max_integral,
            gains.max_output,
            gains.i_zone,
            gains.derivative_tau_s,
            _ANTI_WINDUP_CODES[gains.anti_windup],
            gains.tracking_time_s,
        ],
        dtype=np.float64,
    )


_ANTI_WINDUP_CODES = {
    "clamp": CLAMP,
    "conditional": CONDITIONAL,
    "back_calculation": BACK_CALCULATION,
}


# --------------------------------------------------------------------------------------------
# Attitude and depth hold


@dataclass(frozen=True, slots=True)
class AttitudeGains:
    """Per-axis attitude PIDs; error in degrees, output in N·m (mate-rov's units)."""

    roll: PidGains = field(default_factory=PidGains)
    pitch: PidGains = field(default_factory=PidGains)
    yaw: PidGains = field(default_factory=PidGains)


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

    The arithmetic is :func:`~.control_kernels.attitude_update`; ``pids`` are the three axes'
    :class:`PID` over their part of the state, for telemetry.
    """

    __slots__ = ("_gains", "_state", "pids")

    def __init__(self, gains: AttitudeGains) -> None:
        self._state = np.zeros(ATTITUDE_STATE_SIZE)
        axes = (gains.roll, gains.pitch, gains.yaw)
        n = PID_STATE_SIZE
        self.pids = tuple(PID(g, self._state[k * n : (k + 1) * n]) for k, g in enumerate(axes))
        self._gains = np.stack([pid.gains_array for pid in self.pids])

    def reset(self) -> None:
        """Reset every axis and forget the previous target and its rate."""
        self._state[:] = 0.0

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
        if not dt_s > 0.0:
            raise ValueError(f"dt_s must be > 0, got {dt_s}")
        return _ATTITUDE_UPDATE(
            self._state,
            self._gains,
            _floats4(target),
            _floats4(current),
            _floats3(rates_rad_s),
            float(dt_s),
            axes if type(axes) is tuple else (bool(axes[0]), bool(axes[1]), bool(axes[2])),
        )

    def update_rows(
        self,
        targets: RowView,
        imu: RowView,
        dt_s: float,
        axes: tuple[bool, bool, bool],
        intent: RowView,
        tick: int,
    ) -> None:
        """:meth:`update` on the frame store's rows (a frame's path): the ControlTargets and
        ImuReading rows in, the torque written into a ForceIntent row at ``tick``
        (:func:`~.control_kernels.attitude_rows`).

        Raises:
            ValueError: ``dt_s`` is not positive.
        """
        if not dt_s > 0.0:
            raise ValueError(f"dt_s must be > 0, got {dt_s}")
        _ATTITUDE_ROWS(
            self._state,
            self._gains,
            targets.values,
            imu.values,
            dt_s + 0.0,
            axes,
            intent.values,
            intent.mark,
            tick,
        )


class DepthController:
    """Depth hold: PID on ``e = target − depth`` (m, positive down) → world-down force [N].

    The force acts along world +Z (down) and is rotated into the body frame with the measured
    attitude, so holding depth does not push the vehicle sideways when it is tilted. A constant
    ``feedforward_n`` (e.g. minus the net buoyancy) may be added to the world-down force. The
    arithmetic is :func:`~.control_kernels.depth_update`.
    """

    __slots__ = ("_pid_gains", "_pid_state", "feedforward_n", "pid")

    def __init__(self, gains: PidGains, feedforward_n: float = 0.0) -> None:
        self.pid = PID(gains)
        self._pid_state, self._pid_gains = self.pid.state_array, self.pid.gains_array
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
            dt_s: time since the previous step [s], > 0.

        Returns:
            (3,) body force (X, Y, Z) [N], FRD.

        Raises:
            ValueError: ``dt_s`` is not positive.
        """
        if not dt_s > 0.0:
            raise ValueError(f"dt_s must be > 0, got {dt_s}")
        return _DEPTH_UPDATE(
            self._pid_state,
            self._pid_gains,
            float(target_depth_m),
            float(depth_m),
            _floats4(attitude),
            float(dt_s),
            float(self.feedforward_n),
        )

    def update_rows(
        self,
        targets: RowView,
        reading: RowView,
        imu: RowView,
        dt_s: float,
        intent: RowView,
        tick: int,
    ) -> None:
        """:meth:`update` on the frame store's rows (a frame's path): the ControlTargets,
        DepthReading and ImuReading rows in, the force written into a ForceIntent row at
        ``tick`` (:func:`~.control_kernels.depth_rows`).

        Raises:
            ValueError: ``dt_s`` is not positive.
        """
        if not dt_s > 0.0:
            raise ValueError(f"dt_s must be > 0, got {dt_s}")
        _DEPTH_ROWS(
            self._pid_state,
            self._pid_gains,
            float(self.feedforward_n),
            targets.values,
            reading.values,
            imu.values,
            dt_s + 0.0,
            intent.values,
            intent.mark,
            tick,
        )


def _floats4(q: Sequence[float]) -> Quaternion:
    """``q`` as a tuple of four floats (one compiled signature), without copying one."""
    if type(q) is tuple and type(q[0]) is float:
        return q  # four floats by the callers' contract
    w, x, y, z = q
    return (float(w), float(x), float(y), float(z))


def _floats3(v: Sequence[float]) -> Vec3:
    if type(v) is tuple and type(v[0]) is float:
        return v
    x, y, z = v
    return (float(x), float(y), float(z))


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
