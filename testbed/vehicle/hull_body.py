"""The vehicle's hull in the physics: one pybullet rigid body with its base frame at the CoG.

:func:`hull_body` creates the hull, :func:`place_hull` puts it at a pose and body velocity of
CO (NED, FRD). The hull is pybullet's multibody base: a box the hull's size [m] centred on the
hydrodynamic origin CO, which sits at −r_g from the base frame (pybullet's base position *is*
the centre of mass, so there is no inertial-frame offset to get wrong), with the model's mass
[kg] and diagonal inertia [kg·m²] (FRD and FLU share a diagonal), no damping
(:class:`~testbed.vehicle.physics.Physics` applies Fossen's) and never asleep. An arm's links
(:func:`~testbed.vehicle.arm_body.arm_links`) are its children in the same multibody. Frames:
r_g and the pose in NED and body FRD, turned into pybullet's z-up world and body FLU by
:mod:`.pybullet_frames`. This module never imports pybullet:
:class:`~testbed.vehicle.physics.Physics` (the one module that does) hands it the module and
its client.
"""

from __future__ import annotations

from collections.abc import Sequence
from types import ModuleType

from testbed.common.geometry import quat_from_euler, rotate, rotation_matrix
from testbed.vehicle.arm import ArmModel
from testbed.vehicle.arm_body import arm_links
from testbed.vehicle.hydrodynamics import HydroModel
from testbed.vehicle.pybullet_frames import ned_to_pybullet, quaternion_ned_to_pybullet

__all__ = ["hull_body", "place_hull"]


def hull_body(
    pb: ModuleType,
    client_id: int,
    model: HydroModel,
    cog_frd_m: Sequence[float],
    arm: ArmModel | None,
) -> int:
    """Create the hull (with ``arm``'s links, if any) at the world origin; its body id.

    Args:
        pb: the pybullet module.
        client_id: the physics client.
        model: the vehicle's parameters (hull size, mass, inertia).
        cog_frd_m: the hull's CoG from CO [m], body FRD (pybullet's base frame origin).
        arm: a manipulator on the hull, or None.

    Returns:
        The multibody's unique id.
    """
    half = [0.5 * s for s in model.hull_size_m]
    # The hull box is centred on CO, which is at −r_g from the CoG (pybullet's body frame).
    centre_flu = ned_to_pybullet([-c for c in cog_frd_m])
    shape = pb.createCollisionShape(
        pb.GEOM_BOX,
        halfExtents=half,
        collisionFramePosition=centre_flu,
        physicsClientId=client_id,
    )
    links = {} if arm is None else arm_links(pb, client_id, arm, cog_frd_m)
    body: int = pb.createMultiBody(
        baseMass=model.mass_kg,
        baseCollisionShapeIndex=shape,
        basePosition=[0.0, 0.0, 0.0],
        physicsClientId=client_id,
        **links,
    )
    pb.changeDynamics(
        body,
        -1,
        linearDamping=0.0,
        angularDamping=0.0,
        localInertiaDiagonal=list(model.inertia_kg_m2),  # FRD and FLU share a diagonal
        activationState=pb.ACTIVATION_STATE_DISABLE_SLEEPING,
        physicsClientId=client_id,
    )
    return body


def place_hull(
    pb: ModuleType,
    client_id: int,
    body_id: int,
    cog_frd_m: Sequence[float],
    position_ned: Sequence[float],
    euler_rad: Sequence[float],
    nu: Sequence[float],
) -> None:
    """Put the hull's base (its CoG) where CO is at a pose and body velocity.

    Args:
        pb: the pybullet module.
        client_id: the physics client.
        body_id: the hull (:func:`hull_body`).
        cog_frd_m: the hull's CoG from CO [m], body FRD.
        position_ned: (3,) position of CO [m], NED.
        euler_rad: (3,) roll, pitch, yaw [rad].
        nu: (6,) body velocity [u v w p q r] at CO [m/s, rad/s], FRD.
    """
    px, py, pz = position_ned
    roll, pitch, yaw = euler_rad
    u, v, w, p, q, r = nu
    quat = quat_from_euler(roll, pitch, yaw)
    rot = rotation_matrix(quat)
    xg, yg, zg = cog_frd_m
    cog_offset = rotate(rot, (xg, yg, zg))
    cog_ned = (px + cog_offset[0], py + cog_offset[1], pz + cog_offset[2])
    # CoG velocity in the body: v_g = v_o + ω × r_g; then to NED.
    vg_body = (u + q * zg - r * yg, v + r * xg - p * zg, w + p * yg - q * xg)
    pb.resetBasePositionAndOrientation(
        body_id,
        ned_to_pybullet(cog_ned),
        quaternion_ned_to_pybullet(quat),
        physicsClientId=client_id,
    )
    pb.resetBaseVelocity(
        body_id,
        ned_to_pybullet(rotate(rot, vg_body)),
        ned_to_pybullet(rotate(rot, (p, q, r))),
        physicsClientId=client_id,
    )
