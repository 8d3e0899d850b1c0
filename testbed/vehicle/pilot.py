"""The pilot interface's laws: stick shaping, the pilot's wrench and trims, and their gains.

Pure and framework-free like :mod:`testbed.vehicle.control` (whose conventions hold here: world
NED, body FRD, quaternions ``(w, x, y, z)`` body → world, wrenches ``(X, Y, Z, K, M, N)`` [N,
N·m] in the body frame). Sticks in [−1, 1] are shaped cubically (mate-rov-2025, REFERENCE §3.6)
and scaled by the allocator's axis maxima; in depth hold the translation is flown level (yaw
only) and rotated into the body. The ECS system that applies them is
:func:`testbed.vehicle.systems.run_pilot_interface`. Nothing here draws random numbers.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numba.extending import register_jitable

from testbed.common.geometry import (
    Quaternion,
    Vec3,
    Wrench,
    heading_difference,
    quat_conjugate,
    quat_from_axis_angle,
    quat_multiply,
    quat_normalize,
    quat_rotate,
    yaw_only,
)
from testbed.config import check_range, check_ranges

__all__ = [
    "MAX_PILOT_GAIN",
    "PilotGains",
    "level_to_body",
    "level_wrench",
    "pilot_gains_array",
    "pilot_level_wrench",
    "pilot_trims",
    "pilot_wrench",
    "shape_stick",
    "stick_trims",
    "trim_targets",
]


MAX_PILOT_GAIN = 10.0
"""Largest accepted stick scale and per-axis pilot gain (dimensionless: a fraction of the
allocator's axis maximum; above 1 the stick saturates the axis early)."""
_PILOT_AXIS_GAINS = (
    "translation",
    "depth_hold_translation",
    "depth_hold_translation_precision",
    "torque",
    "attitude_hold_torque",
)


@dataclass(frozen=True, slots=True)
class PilotGains:
    """Stick shaping and per-axis gains (mate-rov pilot interface, REFERENCE §3.6).

    Axis order everywhere: surge, sway, heave, roll, pitch, yaw.

    Domains: scales and per-axis gains in [0, 10]; ``dead_zone`` in [0, 1);
    ``depth_trim_m_s`` in [0, 5] m/s; attitude trim rates in [0, 10] rad/s.

    Attributes:
        normal_scale, precision_scale: ``s`` in ``u = sign(x)|x|³·s``.
        dead_zone: sticks with ``|x| < dead_zone`` read as 0.
        translation: force gains in manual/stabilise modes.
        depth_hold_translation: force gains in depth hold (heave trims the target instead).
        depth_hold_translation_precision: the same in precision mode.
        torque: torque gains without attitude hold.
        attitude_hold_torque: torque gains with attitude hold (the sticks trim the target).
        depth_trim_m_s: depth-target rate at full heave stick (normal, precision).
        attitude_trim_rad_s: attitude-target rates at full stick (roll, pitch, yaw), normal.
        attitude_trim_precision_rad_s: the same in precision mode.
    """

    normal_scale: float = 0.8
    precision_scale: float = 0.3
    dead_zone: float = 0.05
    translation: tuple[float, float, float] = (1.0, 1.0, 1.0)
    depth_hold_translation: tuple[float, float, float] = (1.0, 1.0, 0.1)
    depth_hold_translation_precision: tuple[float, float, float] = (1.0, 1.0, 0.0)
    torque: tuple[float, float, float] = (1.0, 1.0, 0.5)
    attitude_hold_torque: tuple[float, float, float] = (0.0, 0.0, 0.0)
    depth_trim_m_s: tuple[float, float] = (0.3, 0.2)
    attitude_trim_rad_s: tuple[float, float, float] = (
        math.radians(35.0),
        math.radians(35.0),
        math.radians(100.0),
    )
    attitude_trim_precision_rad_s: tuple[float, float, float] = (
        math.radians(25.0),
        math.radians(25.0),
        math.radians(60.0),
    )

    def __post_init__(self) -> None:
        check_range(self.dead_zone, "dead_zone", 0.0, 1.0, high_open=True)
        check_range(self.normal_scale, "normal_scale", 0.0, MAX_PILOT_GAIN)
        check_range(self.precision_scale, "precision_scale", 0.0, MAX_PILOT_GAIN)
        for name in _PILOT_AXIS_GAINS:
            check_ranges(getattr(self, name), name, 0.0, MAX_PILOT_GAIN)
        check_ranges(self.depth_trim_m_s, "depth_trim_m_s", 0.0, 5.0, "m/s")
        for name in ("attitude_trim_rad_s", "attitude_trim_precision_rad_s"):
            check_ranges(getattr(self, name), name, 0.0, 10.0, "rad/s")


# PilotGains as the kernels read it (pilot_gains_array): offsets into one float64 array
_SCALE, _PRECISION_SCALE, _DEAD_ZONE = 0, 1, 2
_TRANSLATION, _DEPTH_HOLD_TRANSLATION, _DEPTH_HOLD_TRANSLATION_PRECISION = 3, 6, 9
_TORQUE, _ATTITUDE_HOLD_TORQUE = 12, 15
_DEPTH_TRIM = 18  # normal, precision
_ATTITUDE_TRIM, _ATTITUDE_TRIM_PRECISION = 20, 23  # 26 in all


def pilot_gains_array(gains: PilotGains) -> np.ndarray:
    """``gains`` as :func:`level_wrench` and :func:`stick_trims` read them: (26,) float64, the
    fields in declaration order, each tuple spread."""
    values = [gains.normal_scale, gains.precision_scale, gains.dead_zone]
    values += [*gains.translation, *gains.depth_hold_translation]
    values += [*gains.depth_hold_translation_precision, *gains.torque]
    values += [*gains.attitude_hold_torque, *gains.depth_trim_m_s]
    values += [*gains.attitude_trim_rad_s, *gains.attitude_trim_precision_rad_s]
    return np.array(values, dtype=np.float64)


@register_jitable
def shape_stick(x: float, scale: float, dead_zone: float = 0.0) -> float:
    """Cubic stick shaping ``sign(x)·|x|³·scale`` with ``x`` clipped to [−1, 1].

    Inside the dead zone the output is 0; outside it the stick is used as is (mate-rov 2024
    zeroes small inputs rather than rescaling the rest). A non-finite stick (NaN, ±inf) reads
    as centred: it is no deflection, and clipping would turn it into a full stick (``max``
    and ``min`` pass a NaN through to their other argument).
    """
    if not math.isfinite(x):
        return 0.0
    x = max(-1.0, min(1.0, x))
    if abs(x) < dead_zone:
        return 0.0
    return x * x * x * scale  # the cube keeps the sign


def pilot_level_wrench(
    sticks: Sequence[float],
    axis_maxima: Sequence[float],
    *,
    gains: PilotGains,
    precision: bool = False,
    depth_hold: bool = False,
    attitude_hold: bool = False,
) -> Wrench:
    """The pilot's force/torque intent before attitude enters: :func:`pilot_wrench` at level.

    It depends on the sticks and the mode only. In depth hold its force is in the yaw-only
    (level) frame, to be rotated into the body by :func:`level_to_body`; otherwise it is the
    body wrench itself. The law is :func:`level_wrench` (compiled into the pilot interface's
    kernel).

    Args:
        sticks: (6,) stick positions in [−1, 1]: surge, sway, heave, roll, pitch, yaw.
        axis_maxima: (6,) the allocator's per-axis maxima [N, N·m] (0 for an axis the thruster
            layout cannot produce).
        gains: shaping and gains.
        precision: precision mode (smaller scale; no heave force in depth hold).
        depth_hold: depth hold is active.
        attitude_hold: attitude hold is active.

    Returns:
        (6,) wrench (X, Y, Z, K, M, N) [N, N·m]: force in the level frame (depth hold) or the
        body frame, torque in the body frame, FRD.
    """
    g = pilot_gains_array(gains).tolist()  # Python floats in, Python floats out
    return level_wrench(sticks, axis_maxima, g, precision, depth_hold, attitude_hold)


@register_jitable
def level_wrench(
    sticks: Sequence[float],
    axis_maxima: Sequence[float],
    gains: Sequence[float] | np.ndarray,
    precision: bool,
    depth_hold: bool,
    attitude_hold: bool,
) -> Wrench:
    """:func:`pilot_level_wrench` with the gains as :func:`pilot_gains_array` lays them out
    (the law, for Python and compiled callers): each shaped stick times its axis maximum [N,
    N·m] and the mode's per-axis gain."""
    g = gains
    scale = g[_PRECISION_SCALE] if precision else g[_SCALE]
    dz = g[_DEAD_ZONE]
    u0 = shape_stick(sticks[0], scale, dz) * axis_maxima[0]
    u1 = shape_stick(sticks[1], scale, dz) * axis_maxima[1]
    u2 = shape_stick(sticks[2], scale, dz) * axis_maxima[2]
    u3 = shape_stick(sticks[3], scale, dz) * axis_maxima[3]
    u4 = shape_stick(sticks[4], scale, dz) * axis_maxima[4]
    u5 = shape_stick(sticks[5], scale, dz) * axis_maxima[5]
    if depth_hold:
        t = _DEPTH_HOLD_TRANSLATION_PRECISION if precision else _DEPTH_HOLD_TRANSLATION
    else:
        t = _TRANSLATION
    r = _ATTITUDE_HOLD_TORQUE if attitude_hold else _TORQUE
    return (u0 * g[t], u1 * g[t + 1], u2 * g[t + 2], u3 * g[r], u4 * g[r + 1], u5 * g[r + 2])


@register_jitable
def level_to_body(force: Vec3, attitude: Quaternion) -> Vec3:
    """A force in the yaw-only (level) frame of ``attitude`` (body → NED), in the body frame."""
    return quat_rotate(quat_multiply(quat_conjugate(attitude), yaw_only(attitude)), force)


def pilot_wrench(
    sticks: Sequence[float],
    axis_maxima: Sequence[float],
    attitude: Quaternion,
    *,
    gains: PilotGains,
    precision: bool = False,
    depth_hold: bool = False,
    attitude_hold: bool = False,
) -> Wrench:
    """The pilot's force/torque intent from stick positions, in the body frame.

    :func:`pilot_level_wrench`, its force rotated into the body in depth hold, where
    translation is commanded in the yaw-only (level) frame (:func:`level_to_body`).

    Args:
        sticks: (6,) stick positions in [−1, 1]: surge, sway, heave, roll, pitch, yaw.
        axis_maxima: (6,) the allocator's per-axis maxima [N, N·m].
        attitude: (4,) measured attitude, body → NED; used in depth hold only.
        gains: shaping and gains.
        precision: precision mode (smaller scale; no heave force in depth hold).
        depth_hold: depth hold is active.
        attitude_hold: attitude hold is active.

    Returns:
        (6,) body wrench (X, Y, Z, K, M, N) [N, N·m], FRD.
    """
    wrench = pilot_level_wrench(
        sticks,
        axis_maxima,
        gains=gains,
        precision=precision,
        depth_hold=depth_hold,
        attitude_hold=attitude_hold,
    )
    if not depth_hold:
        return wrench
    fx, fy, fz = level_to_body((wrench[0], wrench[1], wrench[2]), attitude)
    return (fx, fy, fz, wrench[3], wrench[4], wrench[5])


def pilot_trims(
    sticks: Sequence[float], *, gains: PilotGains, precision: bool = False
) -> tuple[float, float, float, float]:
    """How fast the sticks move the hold targets: ``shape(x) · rate`` at full-stick rates.

    Args:
        sticks: (6,) stick positions in [−1, 1].
        gains: the trim rates (``depth_trim_m_s``, ``attitude_trim[_precision]_rad_s``).
        precision: precision mode (the smaller rates).

    Returns:
        (depth [m/s, + down] from heave, roll, pitch, yaw [rad/s] about the target's body axes
        (roll, pitch) and world down (yaw)).
    """
    return stick_trims(sticks, pilot_gains_array(gains).tolist(), precision)


@register_jitable
def stick_trims(
    sticks: Sequence[float], gains: Sequence[float] | np.ndarray, precision: bool
) -> tuple[float, float, float, float]:
    """:func:`pilot_trims` with the gains as :func:`pilot_gains_array` lays them out (the law,
    for Python and compiled callers)."""
    g = gains
    dz = g[_DEAD_ZONE]
    r = _ATTITUDE_TRIM_PRECISION if precision else _ATTITUDE_TRIM
    return (
        shape_stick(sticks[2], 1.0, dz) * g[_DEPTH_TRIM + (1 if precision else 0)],
        shape_stick(sticks[3], 1.0, dz) * g[r],
        shape_stick(sticks[4], 1.0, dz) * g[r + 1],
        shape_stick(sticks[5], 1.0, dz) * g[r + 2],
    )


MAX_HEADING_LEAD_RAD = math.radians(60.0)
"""How far the yaw stick may turn the heading target ahead of the measured heading [rad]. A
vehicle that turns slower than the stick's 100°/s (a hull with more rotational drag: −4 N·m·s²
caps it near 64°/s) let the target run away from it; near 180° of error the attitude error's
roll and pitch parts grew and the vehicle rolled ≈ 50°. At 60° the yaw loop (kp 0.3 N·m/deg)
is saturated many times over, so a vehicle that can follow never meets the limit (the
packaged models lead by at most 18° (BlueROV2) and 22° (Heavy) at full stick)."""

SURFACE_HOLD_DEPTH_M = 0.15
"""The shallowest depth target a hold keeps [m, + down]: ArduSub's at the surface (5 cm below
its SURFACE_DEPTH of −10 cm). A target above it would ask a floating hull to climb out of the
water: the BlueROV2 floats with its centre of buoyancy 0.12 m deep, so a 0-m target only winds
the depth loop's integral up (thrust and pitch creeping) while the vehicle cannot move."""


@register_jitable
def trim_targets(
    depth_m: float,
    quaternion_wxyz: Quaternion,
    trims: tuple[float, float, float, float],
    dt_s: float,
    depth_hold: bool,
    attitude_hold: bool,
    measured_wxyz: Quaternion,
) -> tuple[float, Quaternion]:
    """The hold targets after the sticks' trims (:func:`pilot_trims`) acted for ``dt_s`` [s].

    In depth hold the depth target [m, + down] moves at the heave trim (never shallower than
    :data:`SURFACE_HOLD_DEPTH_M`); in attitude hold the attitude target (body → NED) turns
    about its own body axes by the roll and pitch trims and about world down by the yaw trim
    (unless that would take the target's heading more than :data:`MAX_HEADING_LEAD_RAD` ahead
    of the measured one, ``measured_wxyz``: a vehicle that turns slower than the stick asks
    is waited for), and is normalised.

    Returns:
        (depth [m], attitude (4,)).
    """
    depth_rate, roll_rate, pitch_rate, yaw_rate = trims
    q = quaternion_wxyz
    if depth_hold:
        depth_m = max(SURFACE_HOLD_DEPTH_M, depth_m + depth_rate * dt_s)
    if attitude_hold:
        roll = roll_rate * dt_s
        pitch = pitch_rate * dt_s
        yaw = yaw_rate * dt_s
        if roll != 0.0 or pitch != 0.0:  # about the target's own body axes
            angle = math.hypot(roll, pitch)
            q = quat_multiply(q, quat_from_axis_angle((roll / angle, pitch / angle, 0.0), angle))
        if yaw != 0.0:  # about world down
            turned = quat_multiply(quat_from_axis_angle((0.0, 0.0, 1.0), yaw), q)
            lead = heading_difference(turned, measured_wxyz)
            if abs(lead) <= MAX_HEADING_LEAD_RAD or lead * yaw < 0.0:
                q = turned
        q = quat_normalize(q)
    return depth_m, q
