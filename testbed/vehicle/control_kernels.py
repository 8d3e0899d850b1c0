"""The closed loops' per-frame arithmetic, compiled by numba: PID, attitude hold, depth hold.

One implementation of each law, called by the controller classes of :mod:`.control` (which keep
the gains' validation, the state arrays and the telemetry properties) and, in time, by a
compiled frame. The quaternion formulas are :mod:`testbed.common.geometry`'s own, compiled into
these kernels (``register_jitable`` there); :func:`~testbed.common.jit.refresh_stale_caches`
empties these kernels' disk caches when that file is newer than them.

Layouts (float64 arrays, written in place):

* PID state (:data:`PID_STATE_SIZE`): :data:`INTEGRAL` (error·s), the last update's terms
  :data:`P_TERM`, :data:`I_TERM`, :data:`D_TERM`, :data:`LAST_ERROR`, :data:`HAS_LAST` (1.0
  after the first update) and :data:`D_FILTERED` (the low-passed derivative).
* PID gains (:data:`PID_GAINS_SIZE`): kp, ki, kd, max_integral, max_output, i_zone,
  derivative_tau_s, the anti-windup code (:data:`CLAMP`, :data:`CONDITIONAL`,
  :data:`BACK_CALCULATION`) and tracking_time_s, in :class:`~.control.PidGains`' order.
* Attitude state (:data:`ATTITUDE_STATE_SIZE`): the roll, pitch and yaw PID states one after the
  other, then the last target (4), whether there is one, the time since it last changed [s], the
  mean time between its steps [s], the feed-forward hold left [s] and the fed-forward target
  rate (3) [rad/s], NED.

Units as in :mod:`.control`: attitude errors in degrees, torques [N·m], depth [m, + down],
forces [N]; body FRD, world NED; quaternions ``(w, x, y, z)`` body → NED.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from testbed.common import geometry, jit
from testbed.common.geometry import (
    Quaternion,
    Vec3,
    attitude_error,
    quat_conjugate,
    quat_multiply,
    quat_rotate_inverse,
)
from testbed.vehicle import pilot, row_kernels, thrust_kernels
from testbed.vehicle.pilot import level_to_body, level_wrench, stick_trims, trim_targets
from testbed.vehicle.row_kernels import put_row
from testbed.vehicle.thrust_kernels import put_wrench

__all__ = [
    "ATTITUDE_STATE_SIZE",
    "BACK_CALCULATION",
    "CLAMP",
    "CONDITIONAL",
    "D_FILTERED",
    "D_TERM",
    "HAS_LAST",
    "INTEGRAL",
    "I_TERM",
    "LAST_ERROR",
    "MAX_TARGET_RATE_HOLD_S",
    "PID_GAINS_SIZE",
    "PID_STATE_SIZE",
    "P_TERM",
    "attitude_rows",
    "attitude_update",
    "depth_rows",
    "depth_update",
    "pid_update",
    "pilot_rows",
    "pilot_shape",
    "put_attitude_target",
    "put_depth_target",
    "put_targets",
]

INTEGRAL, P_TERM, I_TERM, D_TERM, LAST_ERROR, HAS_LAST, D_FILTERED = range(7)
PID_STATE_SIZE = 7
KP, KI, KD, MAX_INTEGRAL, MAX_OUTPUT, I_ZONE, DERIVATIVE_TAU, ANTI_WINDUP, TRACKING = range(9)
PID_GAINS_SIZE = 9
CLAMP, CONDITIONAL, BACK_CALCULATION = 0.0, 1.0, 2.0
"""Anti-windup codes in the gains array."""

_TARGET = 3 * PID_STATE_SIZE  # last target (4)
_HAS_TARGET = _TARGET + 4
_SINCE_CHANGE = _HAS_TARGET + 1
_INTERVAL = _SINCE_CHANGE + 1
_HOLD_LEFT = _INTERVAL + 1
_RATE = _HOLD_LEFT + 1  # fed-forward target rate (3)
ATTITUDE_STATE_SIZE = _RATE + 3

MAX_TARGET_RATE_HOLD_S = 0.25
"""Longest time [s] over which one step of an attitude target is fed forward as a rate."""
_DEG_PER_RAD = 180.0 / math.pi


@numba.njit(cache=True)
def pid_update(
    state: np.ndarray,
    gains: np.ndarray,
    error: float,
    dt_s: float,
    error_rate: float,
    has_rate: bool,
) -> float:  # pragma: no cover - compiled
    """One step of :class:`~.control.PID` (see there): the clamped output; ``state`` advanced.

    Args:
        state: (7,) the PID state (module docstring), in place.
        gains: (9,) the PID gains (module docstring).
        error: setpoint minus measurement, in the loop's unit.
        dt_s: time since the previous update [s], > 0 (the caller checks).
        error_rate: d(error)/dt, used when ``has_rate``; otherwise the error is differenced.
        has_rate: whether ``error_rate`` is given.
    """
    has_last = state[HAS_LAST] != 0.0
    differenced = (error - state[LAST_ERROR]) / dt_s if has_last else 0.0
    raw = error_rate if has_rate else differenced
    tau = gains[DERIVATIVE_TAU]
    if tau > 0.0 and has_last:
        d_filtered = state[D_FILTERED]
        d_filtered += (raw - d_filtered) * (dt_s / (tau + dt_s))
    else:
        d_filtered = raw
    state[D_FILTERED] = d_filtered
    state[LAST_ERROR] = error
    state[HAS_LAST] = 1.0
    # clamps are written out as comparisons (the same result as Python's min/max, NaN included)
    ki = gains[KI]
    p = gains[KP] * error
    d = gains[KD] * d_filtered
    limit = gains[MAX_OUTPUT]
    if abs(error) >= gains[I_ZONE]:
        state[INTEGRAL] = 0.0
    else:
        cap = gains[MAX_INTEGRAL]
        candidate = state[INTEGRAL] + error * dt_s
        candidate = candidate if candidate < cap else cap
        candidate = candidate if candidate > -cap else -cap
        anti_windup = gains[ANTI_WINDUP]
        if anti_windup == CONDITIONAL:
            unsat = p + ki * candidate + d
            if abs(unsat) <= limit or (unsat > 0.0) != (error > 0.0):
                state[INTEGRAL] = candidate
        elif anti_windup == BACK_CALCULATION and ki != 0.0:
            # İ = e + (sat(u) − u)/(ki·Tt), u from the integral before this step
            unsat = p + ki * state[INTEGRAL] + d
            low = unsat if unsat < limit else limit
            saturated = low if low > -limit else -limit
            candidate += (saturated - unsat) * dt_s / (gains[TRACKING] * ki)
            low = candidate if candidate < cap else cap
            state[INTEGRAL] = low if low > -cap else -cap
        else:
            state[INTEGRAL] = candidate
    i = ki * state[INTEGRAL]
    state[P_TERM] = p
    state[I_TERM] = i
    state[D_TERM] = d
    out = p + i + d
    out = out if out < limit else limit
    return float(out if out > -limit else -limit)


@numba.njit(cache=True)
def attitude_update(
    state: np.ndarray,
    gains: np.ndarray,
    target: Quaternion,
    current: Quaternion,
    rates_rad_s: Vec3,
    dt_s: float,
    axes: tuple[bool, bool, bool],
) -> Vec3:  # pragma: no cover - compiled
    """One step of :class:`~.control.AttitudeController` (the law is described there).

    Args:
        state: (32,) the attitude state (module docstring), in place.
        gains: (3, 9) the roll, pitch and yaw PID gains.
        target, current: (4,) target and measured attitude, body → NED.
        rates_rad_s: (3,) measured body rates (p, q, r) [rad/s], FRD.
        dt_s: time since the previous step [s], > 0 (the caller checks).
        axes: which of roll, pitch, yaw to control; a disabled axis outputs 0 and is reset.

    Returns:
        (3,) body torque (K, M, N) [N·m], FRD.
    """
    errors = attitude_error(target, current)
    state[_SINCE_CHANGE] += dt_s
    rx, ry, rz = state[_RATE], state[_RATE + 1], state[_RATE + 2]
    left = state[_HOLD_LEFT]
    last = (state[_TARGET], state[_TARGET + 1], state[_TARGET + 2], state[_TARGET + 3])
    if state[_HAS_TARGET] == 0.0:
        state[_SINCE_CHANGE] = 0.0
    elif last != target:
        # the target's step since it last changed (a small world-frame rotation, whose
        # rotation vector is 2·vec(target·last⁻¹)) over the mean time between its steps
        sw, sx, sy, sz = quat_multiply(target, quat_conjugate(last))
        if sw < 0.0:
            sx, sy, sz = -sx, -sy, -sz
        since = state[_SINCE_CHANGE]
        mean = state[_INTERVAL]
        mean = since if mean == 0.0 else 0.5 * (mean + since)
        state[_INTERVAL] = mean
        spread = MAX_TARGET_RATE_HOLD_S if mean > MAX_TARGET_RATE_HOLD_S else mean
        k = 2.0 / spread
        rx, ry, rz = k * sx, k * sy, k * sz
        state[_RATE], state[_RATE + 1], state[_RATE + 2] = rx, ry, rz
        # held until the next step, or until it is late by half the mean interval (the
        # target stopped); a lone step is thus fed over MAX_TARGET_RATE_HOLD_S in full
        left = spread if spread >= MAX_TARGET_RATE_HOLD_S else 1.5 * spread
        state[_SINCE_CHANGE] = 0.0
    for j in range(4):
        state[_TARGET + j] = target[j]
    state[_HAS_TARGET] = 1.0
    if left > 1e-9:  # still feeding the last step: this frame's share of it
        state[_HOLD_LEFT] = left - dt_s
        if left < dt_s:
            f = left / dt_s
            rx, ry, rz = rx * f, ry * f, rz * f
        target_rates = quat_rotate_inverse(current, (rx, ry, rz))
    else:
        state[_HOLD_LEFT] = 0.0
        target_rates = (0.0, 0.0, 0.0)
    out = [0.0, 0.0, 0.0]
    for j in range(3):
        pid = state[j * PID_STATE_SIZE : (j + 1) * PID_STATE_SIZE]
        if not axes[j]:
            pid[:] = 0.0
            continue
        rate_deg_s = (target_rates[j] - rates_rad_s[j]) * _DEG_PER_RAD
        out[j] = pid_update(pid, gains[j], errors[j] * _DEG_PER_RAD, dt_s, rate_deg_s, True)
    return (out[0], out[1], out[2])


@numba.njit(cache=True)
def depth_update(
    state: np.ndarray,
    gains: np.ndarray,
    target_depth_m: float,
    depth_m: float,
    attitude: Quaternion,
    dt_s: float,
    feedforward_n: float,
) -> Vec3:  # pragma: no cover - compiled
    """One step of :class:`~.control.DepthController`: the PID's world-down force plus the
    feed-forward [N], rotated into the body with the measured attitude → (X, Y, Z) [N], FRD."""
    down_n = pid_update(state, gains, target_depth_m - depth_m, dt_s, 0.0, False) + feedforward_n
    return quat_rotate_inverse(attitude, (0.0, 0.0, down_n))


# ------------------------------------------------------------------ component rows
#
# The loops on the frame store's rows (:mod:`testbed.ecs.store`; field order of the components):
# ControlTargets (depth_m, quaternion_wxyz), DepthReading (time_s, pressure_pa, depth_m),
# ImuReading (time_s, quaternion_wxyz, rates_rad_s); the output is the loop's ForceIntent row
# (marked only when the wrench changed, :func:`~.thrust_kernels.put_wrench`).


@numba.njit(cache=True)
def depth_rows(
    state: np.ndarray,
    gains: np.ndarray,
    feedforward_n: float,
    targets: np.ndarray,
    reading: np.ndarray,
    imu: np.ndarray,
    dt_s: float,
    intent: np.ndarray,
    intent_mark: np.ndarray,
    tick: int,
) -> None:  # pragma: no cover - compiled
    """:func:`depth_update` of the rows' target depth, measured depth and attitude, written as
    the depth loop's force intent (X, Y, Z, 0, 0, 0) [N]."""
    attitude = (imu[1], imu[2], imu[3], imu[4])
    fx, fy, fz = depth_update(state, gains, targets[0], reading[2], attitude, dt_s, feedforward_n)
    put_wrench(intent, intent_mark, tick, fx, fy, fz, 0.0, 0.0, 0.0)


@numba.njit(cache=True)
def attitude_rows(
    state: np.ndarray,
    gains: np.ndarray,
    targets: np.ndarray,
    imu: np.ndarray,
    dt_s: float,
    axes: tuple[bool, bool, bool],
    intent: np.ndarray,
    intent_mark: np.ndarray,
    tick: int,
) -> None:  # pragma: no cover - compiled
    """:func:`attitude_update` of the rows' target attitude, measured attitude and rates,
    written as the attitude loop's torque intent (0, 0, 0, K, M, N) [N·m]."""
    target = (targets[1], targets[2], targets[3], targets[4])
    current = (imu[1], imu[2], imu[3], imu[4])
    rates = (imu[5], imu[6], imu[7])
    tx, ty, tz = attitude_update(state, gains, target, current, rates, dt_s, axes)
    put_wrench(intent, intent_mark, tick, 0.0, 0.0, 0.0, tx, ty, tz)


@numba.njit(cache=True)
def pilot_shape(
    sticks: tuple[float, ...],
    axis_maxima: tuple[float, ...],
    gains: np.ndarray,
    precision: bool,
    depth_hold: bool,
    attitude_hold: bool,
) -> tuple[
    tuple[float, float, float, float, float, float], tuple[float, float, float, float]
]:  # pragma: no cover - compiled
    """The sticks' level wrench and trims in a mode (:func:`~.pilot.level_wrench`,
    :func:`~.pilot.stick_trims`; ``gains`` laid out by :func:`~.pilot.pilot_gains_array`)."""
    wrench = level_wrench(sticks, axis_maxima, gains, precision, depth_hold, attitude_hold)
    return wrench, stick_trims(sticks, gains, precision)


@numba.njit(cache=True)
def pilot_rows(
    sticks: tuple[float, ...],
    axis_maxima: tuple[float, ...],
    gains: np.ndarray,
    precision: bool,
    depth_hold: bool,
    attitude_hold: bool,
    imu: np.ndarray,
    targets: np.ndarray,
    dt_s: float,
    intent: np.ndarray,
    intent_mark: np.ndarray,
    targets_mark: np.ndarray,
    tick: int,
) -> None:  # pragma: no cover - compiled
    """The pilot interface's frame on the rows: its force intent from the sticks' level wrench
    (:func:`pilot_shape`; in depth hold the force rotated into the body with the ImuReading
    row's attitude, :func:`~.pilot.level_to_body`), and in a hold mode the ControlTargets row
    moved by the trims (:func:`~.pilot.trim_targets`)."""
    wrench, trims = pilot_shape(sticks, axis_maxima, gains, precision, depth_hold, attitude_hold)
    if depth_hold:
        attitude = (imu[1], imu[2], imu[3], imu[4])
        fx, fy, fz = level_to_body((wrench[0], wrench[1], wrench[2]), attitude)
        put_wrench(intent, intent_mark, tick, fx, fy, fz, wrench[3], wrench[4], wrench[5])
    else:
        x, y, z, k, m, n = wrench
        put_wrench(intent, intent_mark, tick, x, y, z, k, m, n)
    if not (depth_hold or attitude_hold):
        return
    target = (targets[1], targets[2], targets[3], targets[4])
    measured = (imu[1], imu[2], imu[3], imu[4])
    depth, q = trim_targets(targets[0], target, trims, dt_s, depth_hold, attitude_hold, measured)
    put_row(targets, targets_mark, tick, (depth, q[0], q[1], q[2], q[3]))


@numba.njit(cache=True)
def put_targets(
    row: np.ndarray, mark: np.ndarray, tick: int, depth_m: float, quaternion_wxyz: Quaternion
) -> None:  # pragma: no cover - compiled
    """A ControlTargets row: the depth target [m, + down] and the attitude target, body → NED
    (:func:`~.row_kernels.put_row`)."""
    w, x, y, z = quaternion_wxyz
    put_row(row, mark, tick, (float(depth_m), float(w), float(x), float(y), float(z)))


@numba.njit(cache=True)
def put_depth_target(
    row: np.ndarray, mark: np.ndarray, tick: int, depth_m: float
) -> None:  # pragma: no cover - compiled
    """:func:`put_targets` of a new depth target [m, + down], the attitude target kept."""
    put_row(row, mark, tick, (float(depth_m), row[1], row[2], row[3], row[4]))


@numba.njit(cache=True)
def put_attitude_target(
    row: np.ndarray, mark: np.ndarray, tick: int, quaternion_wxyz: Quaternion
) -> None:  # pragma: no cover - compiled
    """:func:`put_targets` of a new attitude target (body → NED), the depth target kept."""
    w, x, y, z = quaternion_wxyz
    put_row(row, mark, tick, (row[0], float(w), float(x), float(y), float(z)))


jit.refresh_stale_caches(
    (
        attitude_update,
        depth_update,
        attitude_rows,
        depth_rows,
        pilot_rows,
        pilot_shape,
        put_targets,
        put_depth_target,
        put_attitude_target,
    ),
    (geometry, jit, pilot, row_kernels, thrust_kernels),
)
