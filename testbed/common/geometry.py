"""The rotation module: quaternions ``(w, x, y, z)``, Z-Y-X Euler angles and rotation matrices.

Every rotation formula of the testbed is written here once (the vehicle's physics, its control
laws and both nodes' teleoperation call these). Conventions: world NED, body FRD; an attitude
quaternion rotates body vectors into the world, and so does its :func:`rotation_matrix`.
Plain floats and tuples (no NumPy): these run in every control frame, where six-element arrays
cost more in call overhead than the arithmetic they hold (``np.array(rotation_matrix(q))`` is the
(3, 3) matrix where one is wanted).

The formulas compiled control laws need (the products, rotations, ``wrap_angle`` and
``attitude_error``) are also registered with numba (``register_jitable``): a Python caller calls
the plain function, unchanged, and a compiled kernel that calls it compiles this same source into
itself (:mod:`testbed.common.jit` keeps such kernels' disk caches in step with this file).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from numba.extending import register_jitable

from testbed.common import jit as _jit  # noqa: F401  (math.fmod for compiled callers)

__all__ = [
    "Quaternion",
    "Rotation",
    "Vec3",
    "Wrench",
    "attitude_error",
    "euler_from_quat",
    "quat_conjugate",
    "quat_from_axis_angle",
    "quat_from_euler",
    "quat_multiply",
    "quat_normalize",
    "quat_rotate",
    "quat_rotate_inverse",
    "rotate",
    "rotation_matrix",
    "twist_angle",
    "wrap_angle",
    "yaw_only",
]

Quaternion = tuple[float, float, float, float]
Vec3 = tuple[float, float, float]
Wrench = tuple[float, float, float, float, float, float]
Rotation = tuple[Vec3, Vec3, Vec3]
"""A (3, 3) rotation matrix as three row tuples."""

_TWO_PI = 2.0 * math.pi


@register_jitable
def quat_multiply(a: Quaternion, b: Quaternion) -> Quaternion:
    """Hamilton product ``a·b`` (apply ``b`` first, then ``a``)."""
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    )


@register_jitable
def quat_conjugate(q: Quaternion) -> Quaternion:
    """The conjugate, which is the inverse of a unit quaternion."""
    return (q[0], -q[1], -q[2], -q[3])


@register_jitable
def quat_normalize(q: Sequence[float]) -> Quaternion:
    """``q`` scaled to unit norm.

    Raises:
        ValueError: ``q`` is (numerically) zero.
    """
    w, x, y, z = q
    w, x, y, z = float(w), float(x), float(y), float(z)
    norm = math.sqrt(w * w + x * x + y * y + z * z)
    if norm < 1e-12:
        raise ValueError("cannot normalise a zero quaternion")
    return (w / norm, x / norm, y / norm, z / norm)


@register_jitable
def quat_rotate(q: Quaternion, v: Sequence[float]) -> Vec3:
    """Rotate ``v`` by ``q`` (body → world for an attitude quaternion)."""
    w, x, y, z = q
    vx, vy, vz = v
    # t = 2 (q_vec × v); v' = v + w t + q_vec × t
    tx = 2.0 * (y * vz - z * vy)
    ty = 2.0 * (z * vx - x * vz)
    tz = 2.0 * (x * vy - y * vx)
    return (
        vx + w * tx + (y * tz - z * ty),
        vy + w * ty + (z * tx - x * tz),
        vz + w * tz + (x * ty - y * tx),
    )


@register_jitable
def quat_rotate_inverse(q: Quaternion, v: Sequence[float]) -> Vec3:
    """Rotate ``v`` by ``q⁻¹`` (world → body for an attitude quaternion)."""
    return quat_rotate((q[0], -q[1], -q[2], -q[3]), v)


def rotation_matrix(q: Sequence[float]) -> Rotation:
    """R of the unit quaternion ``q`` (body → world for an attitude quaternion), rows as tuples.

    ``q`` is not normalised here: pass :func:`quat_normalize` of it if it may not be unit.
    """
    w, x, y, z = q
    return (
        (1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)),
        (2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)),
        (2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)),
    )


def rotate(rows: Sequence[Sequence[float]], v: Sequence[float]) -> Vec3:
    """``R·v`` for a (3, 3) matrix given by rows (e.g. a :func:`rotation_matrix`)."""
    x, y, z = v
    (a, b, c), (d, e, f), (g, h, i) = rows
    return (a * x + b * y + c * z, d * x + e * y + f * z, g * x + h * y + i * z)


@register_jitable
def quat_from_axis_angle(axis: Sequence[float], angle_rad: float) -> Quaternion:
    """Rotation by ``angle_rad`` about the unit vector ``axis`` (right-handed)."""
    half = 0.5 * angle_rad
    s = math.sin(half)
    return (math.cos(half), axis[0] * s, axis[1] * s, axis[2] * s)


def quat_from_euler(roll_rad: float, pitch_rad: float, yaw_rad: float) -> Quaternion:
    """Attitude from Z-Y-X (yaw, then pitch, then roll) Euler angles, body → NED."""
    cr, sr = math.cos(0.5 * roll_rad), math.sin(0.5 * roll_rad)
    cp, sp = math.cos(0.5 * pitch_rad), math.sin(0.5 * pitch_rad)
    cy, sy = math.cos(0.5 * yaw_rad), math.sin(0.5 * yaw_rad)
    return (
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    )


def euler_from_quat(q: Sequence[float]) -> Vec3:
    """Z-Y-X Euler angles ``(roll, pitch, yaw)`` [rad] of an attitude quaternion.

    Pitch is clamped to ±π/2 at the singularity.
    """
    w, x, y, z = q
    roll = math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    sin_pitch = max(-1.0, min(1.0, 2.0 * (w * y - z * x)))
    pitch = math.asin(sin_pitch)
    yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return (roll, pitch, yaw)


@register_jitable
def heading_difference(a: Quaternion, b: Quaternion) -> float:
    """How far attitude ``a`` is turned from ``b`` about world down [rad], in (−π, π]: the
    twist about z of the world-frame rotation a·b⁻¹ (defined at any pitch, where the Euler
    yaw is not; for level attitudes the difference of their yaws)."""
    aw, ax, ay, az = a
    bw, bx, by, bz = b  # a · conj(b): only its w and z parts are needed
    w = aw * bw + ax * bx + ay * by + az * bz
    z = -aw * bz - ax * by + ay * bx + az * bw
    return wrap_angle(2.0 * math.atan2(z, w))


@register_jitable
def yaw_only(q: Quaternion) -> Quaternion:
    """The heading part of an attitude: rotation about world down by the Z-Y-X yaw."""
    w, x, y, z = q
    yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return (math.cos(0.5 * yaw), 0.0, 0.0, math.sin(0.5 * yaw))


@register_jitable
def wrap_angle(angle_rad: float) -> float:
    """``angle_rad`` wrapped into (−π, π]."""
    wrapped = math.fmod(angle_rad + math.pi, _TWO_PI)
    if wrapped <= 0.0:
        wrapped += _TWO_PI
    return wrapped - math.pi


def twist_angle(q: Quaternion, axis: Sequence[float]) -> float:
    """Signed angle [rad] of the twist of ``q`` about the unit vector ``axis``, in (−π, π].

    Swing–twist decomposition: the twist is ``(w, (v·a)a)`` renormalised, whose angle is
    ``2·atan2(v·a, w)``; a rotation the long way round (``w < 0``) wraps to the short way.
    A half turn about an axis perpendicular to ``axis`` (``w = v·a = 0``, where the twist is
    undefined) gives 0.
    """
    along = q[1] * axis[0] + q[2] * axis[1] + q[3] * axis[2]
    return wrap_angle(2.0 * math.atan2(along, q[0]))


@register_jitable
def attitude_error(target: Quaternion, current: Quaternion) -> Vec3:
    """Per-body-axis attitude error [rad] of ``current`` against ``target`` (roll, pitch, yaw).

    ``q_err = target·current⁻¹`` (a world-frame rotation) is split by swing–twist about each
    body axis expressed in the world, ``current·e_i`` (mate-rov's ``instant_twist``). Since
    ``(current·e_i)·v_err = e_i·(current⁻¹ v_err)``, this equals the twist of
    ``current⁻¹·target`` about the body axes, which is what is computed (one product).

    Returns:
        (3,) errors [rad], each in (−π, π]; positive means a positive body torque about that
        axis (FRD) turns the vehicle towards the target.
    """
    cw, cx, cy, cz = current
    tw, tx, ty, tz = target
    # current⁻¹ · target
    w = cw * tw + cx * tx + cy * ty + cz * tz
    x = cw * tx - cx * tw - cy * tz + cz * ty
    y = cw * ty + cx * tz - cy * tw - cz * tx
    z = cw * tz - cx * ty + cy * tx - cz * tw
    return (
        wrap_angle(2.0 * math.atan2(x, w)),
        wrap_angle(2.0 * math.atan2(y, w)),
        wrap_angle(2.0 * math.atan2(z, w)),
    )
