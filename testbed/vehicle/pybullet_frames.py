"""NED ↔ pybullet: the vectors and attitude quaternions of the plant's pybullet world.

pybullet's world is NED rotated by π about north, (x, y, z)_pb = (N, −E, −D), and its body
frame is FLU, the same rotation of FRD: vectors map by (x, −y, −z) both ways and a quaternion
(w, x, y, z) maps to (w, x, −y, −z). With :mod:`.physics` and its compiled arithmetic
(:mod:`.plant_kernels`), these functions are the only place that knows pybullet is z-up.
Pure Python: this module never imports pybullet (only :mod:`.physics` does).
"""

from __future__ import annotations

from collections.abc import Sequence

__all__ = [
    "ned_to_pybullet",
    "pybullet_to_ned",
    "quaternion_ned_to_pybullet",
    "quaternion_pybullet_to_ned",
]

Vec3 = tuple[float, float, float]


def ned_to_pybullet(vector: Sequence[float]) -> Vec3:
    """A vector in NED (or body FRD) → pybullet's world (or body FLU): (x, −y, −z)."""
    return (float(vector[0]), -float(vector[1]), -float(vector[2]))


def pybullet_to_ned(vector: Sequence[float]) -> Vec3:
    """A vector in pybullet's world (or body FLU) → NED (or body FRD): (x, −y, −z)."""
    return (float(vector[0]), -float(vector[1]), -float(vector[2]))


def quaternion_ned_to_pybullet(q_wxyz: Sequence[float]) -> tuple[float, float, float, float]:
    """Attitude quaternion (w, x, y, z), FRD → NED, as pybullet's (x, y, z, w), FLU → world."""
    w, x, y, z = (float(c) for c in q_wxyz)
    return (x, -y, -z, w)


def quaternion_pybullet_to_ned(q_xyzw: Sequence[float]) -> tuple[float, float, float, float]:
    """pybullet's (x, y, z, w), FLU → world, as the attitude quaternion (w, x, y, z), FRD → NED."""
    x, y, z, w = (float(c) for c in q_xyzw)
    return (w, x, -y, -z)
