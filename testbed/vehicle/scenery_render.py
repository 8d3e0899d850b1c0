"""The camera's scenery in a pybullet client, and pybullet's pictures of it.

:func:`add_scenery_bodies` turns a :class:`~testbed.vehicle.scenery.Scenery` (NED, metres) into
static visual-only bodies of pybullet's z-up world (:mod:`.pybullet_frames`);
:func:`render_scenery` draws them from a camera pose (NED) with pybullet's CPU renderer,
TinyRenderer. :class:`~testbed.vehicle.physics.Physics` calls both on its own client
(:meth:`~testbed.vehicle.physics.Physics.add_scenery`,
:meth:`~testbed.vehicle.physics.Physics.render`). This module never imports pybullet:
:class:`~testbed.vehicle.physics.Physics` (the one module that does) hands it the module and
its client.
"""

from __future__ import annotations

import tempfile
from types import ModuleType

import numpy as np
from numpy.typing import NDArray

from testbed.vehicle.camera import CameraConfig, CameraPose
from testbed.vehicle.pybullet_frames import ned_to_pybullet, quaternion_ned_to_pybullet
from testbed.vehicle.scenery import LIGHT_TOWARDS_NED, Scenery

__all__ = ["add_scenery_bodies", "render_scenery"]

_ZERO3 = (0.0, 0.0, 0.0)


def add_scenery_bodies(pb: ModuleType, client_id: int, scenery: Scenery) -> None:
    """Add the camera's scenery as static visual-only bodies (no collision, no mass: stepping
    is unchanged); bodies already here (the hull, a pool's boxes) turn transparent.

    Args:
        pb: the pybullet module.
        client_id: the physics client.
        scenery: what to add (NED, metres).
    """
    client = {"physicsClientId": client_id}
    for index in range(pb.getNumBodies(**client)):
        body = pb.getBodyUniqueId(index, **client)
        pb.changeVisualShape(body, -1, rgbaColor=(0, 0, 0, 0), **client)
    with tempfile.TemporaryDirectory(prefix="testbed-") as folder:  # loadTexture needs a file
        paths = scenery.write_textures(folder).items()
        textures = {name: pb.loadTexture(path, **client) for name, path in paths}
    placed = []  # (visual shape, position NED, attitude wxyz, texture or None)
    # quads: counter-clockwise seen from the normal's side; the texture's row 0 is v = 1
    mesh = {"indices": [0, 2, 1, 0, 3, 2], "uvs": [(0, 1), (1, 1), (1, 0), (0, 0)], **client}
    for quad in scenery.quads:
        vertices = [ned_to_pybullet(c) for c in quad.corners_ned_m]
        normals = [ned_to_pybullet(quad.normal_ned)] * 4
        shape = pb.createVisualShape(pb.GEOM_MESH, vertices=vertices, normals=normals, **mesh)
        placed.append((shape, _ZERO3, (1.0, 0.0, 0.0, 0.0), textures[quad.texture]))
    for solid in scenery.solids:
        kind, size = getattr(pb, f"GEOM_{solid.kind.upper()}"), solid.size_m
        half = [0.5 * s for s in size] if solid.kind == "box" else None
        rgba = (*solid.rgb, 1.0)
        shape = pb.createVisualShape(
            kind, radius=size[0], length=size[-1], halfExtents=half, rgbaColor=rgba, **client
        )
        placed.append((shape, solid.position_ned_m, solid.quaternion_wxyz, None))
    sleep = pb.ACTIVATION_STATE_SLEEP  # a sleeping static rigid body costs no step time
    for shape, position, attitude, texture in placed:
        at = ned_to_pybullet(position), quaternion_ned_to_pybullet(attitude)
        body = pb.createMultiBody(0.0, -1, shape, *at, useMaximalCoordinates=True, **client)
        pb.changeDynamics(body, -1, activationState=sleep, **client)
        if texture is not None:
            pb.changeVisualShape(body, -1, textureUniqueId=texture, **client)


def render_scenery(
    pb: ModuleType, client_id: int, pose: CameraPose, camera: CameraConfig
) -> tuple[NDArray[np.uint8], NDArray[np.float32]]:
    """Draw the scenery from a camera pose (NED) with pybullet's CPU renderer, TinyRenderer.

    Args:
        pb: the pybullet module.
        client_id: the physics client.
        pose: the camera's pose, NED.
        camera: the camera (its render size and projection).

    Returns:
        ``(rgb, zbuffer)`` at ``camera.render_size_px``: (h, w, 3) uint8 colour, row 0 at the
        top; (h, w) OpenGL depth buffer in [0, 1], 1 where nothing was hit.
    """
    eye, (w, h) = pose.position_ned_m, camera.render_size_px
    target = [e + f for e, f in zip(eye, pose.forward_ned, strict=True)]
    view = pb.computeViewMatrix(*map(ned_to_pybullet, (eye, target, pose.up_ned)))
    projection = camera.projection_matrix
    light = ned_to_pybullet(LIGHT_TOWARDS_NED)
    tiny = {"renderer": pb.ER_TINY_RENDERER, "flags": pb.ER_NO_SEGMENTATION_MASK}
    options = {"lightDirection": light, "shadow": 0, "physicsClientId": client_id, **tiny}
    _, _, rgba, zbuffer, _ = pb.getCameraImage(w, h, view, projection, **options)
    rgb = np.asarray(rgba, dtype=np.uint8).reshape(h, w, 4)[:, :, :3]
    return rgb, np.asarray(zbuffer, dtype=np.float32).reshape(h, w)
