"""The pool the vehicle swims in: its dimensions and its floor and walls in the physics.

:class:`PoolScene` is plain configuration (a vehicle file's ``[pool]`` table);
:func:`build_pool` adds its floor and four walls to a pybullet client as static boxes with
contact on. Dimensions in metres; positions NED from the centre of the water surface, turned
into pybullet's z-up world by :mod:`.pybullet_frames`. This module never imports pybullet:
:class:`~testbed.vehicle.physics.Physics` (the one module that does) hands it the module and
its client. What the camera sees of a pool is :mod:`.scenery`.
"""

from __future__ import annotations

from dataclasses import dataclass
from types import ModuleType

from testbed.config import check
from testbed.vehicle.pybullet_frames import ned_to_pybullet

__all__ = ["POOL_LIMITS_M", "PoolScene", "build_pool"]


POOL_LIMITS_M = {"length_m": 50.0, "width_m": 50.0, "depth_m": 20.0, "wall_thickness_m": 5.0}
"""Largest pool dimensions [m]: an Olympic pool or a large test tank (the camera's textures grow
with the area, at 2 cm a texel)."""


@dataclass(frozen=True, slots=True)
class PoolScene:
    """A rectangular pool: floor and four walls as static bodies, contact on.

    The origin is the centre of the water surface; the floor's top is at NED z = ``depth_m``,
    the walls' inner faces at x = ±length/2 and y = ±width/2.

    Attributes:
        length_m: extent along north [m].
        width_m: extent along east [m].
        depth_m: water depth [m].
        wall_thickness_m: thickness of the floor and walls [m].
    """

    length_m: float = 10.0
    width_m: float = 6.0
    depth_m: float = 3.0
    wall_thickness_m: float = 0.5

    def __post_init__(self) -> None:
        for key, high in POOL_LIMITS_M.items():
            value = getattr(self, key)
            check(0.0 < value <= high, key, f"must be in (0, {high:g}] m, got {value}")


def build_pool(pb: ModuleType, client_id: int, pool: PoolScene) -> None:
    """Add the pool's floor and four walls to the client as static boxes (contact on).

    Args:
        pb: the pybullet module.
        client_id: the physics client.
        pool: the pool.
    """
    t = pool.wall_thickness_m
    half_l, half_w, depth = 0.5 * pool.length_m, 0.5 * pool.width_m, pool.depth_m
    # (centre NED, half extents) of the floor and the four walls.
    boxes = [
        ((0.0, 0.0, depth + t / 2), (half_l + t, half_w + t, t / 2)),
        ((half_l + t / 2, 0.0, depth / 2), (t / 2, half_w + t, depth / 2)),
        ((-half_l - t / 2, 0.0, depth / 2), (t / 2, half_w + t, depth / 2)),
        ((0.0, half_w + t / 2, depth / 2), (half_l + t, t / 2, depth / 2)),
        ((0.0, -half_w - t / 2, depth / 2), (half_l + t, t / 2, depth / 2)),
    ]
    for centre, half in boxes:
        shape = pb.createCollisionShape(pb.GEOM_BOX, halfExtents=half, physicsClientId=client_id)
        pb.createMultiBody(
            baseMass=0.0,
            baseCollisionShapeIndex=shape,
            basePosition=ned_to_pybullet(centre),
            physicsClientId=client_id,
        )
