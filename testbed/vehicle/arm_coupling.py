"""The arm's reaction on the hull: measured from the hull's motion, at rest, and its trim float.

:class:`~testbed.vehicle.physics.Physics` couples the arm (:mod:`.arm_body`) into the hull's
Fossen equation with these: :func:`measured_reaction`, the arm's reaction over the last step
from what the hull's own Newton–Euler equations leave unexplained; :func:`arm_static_reaction`,
the resting arm's weight and buoyancy (the first step's reaction, before any motion);
:func:`trim_float` and :func:`trim_wrench`, the float that cancels the arm's weight in water in
its start pose.

The arm's links are the hull's children in one pybullet multibody, so pybullet's articulated
dynamics carry the joint reactions. Each step measures the arm's reaction on the hull over the
last step from the hull's own motion, R = m·Δv/Δt − F_applied (and I·Δω/Δt + ω×Iω − τ_applied),
then solves Fossen's equation with τ + R (one step late: the arm is ~10 % of the hull's mass and
added mass, so the lag's recurrence factor is ~0.1) and applies the force that gives that
acceleration less R, which pybullet adds back (the step itself is :class:`Physics`'s; with
``arm_coupling=False`` R is cancelled instead, as if the arm were massless to the hull).

Wrenches [N, N·m] are body FRD about the hull's CoG; pybullet's quantities (velocities, rotation
matrices, applied force and torque) are its z-up world and body FLU (:mod:`.pybullet_frames`).
This module never imports pybullet: :class:`Physics` (the one module that does) hands it the
module and its client.
"""

from __future__ import annotations

from collections.abc import Sequence
from types import ModuleType

from testbed.vehicle.arm_body import G_M_S2, RHO_KG_M3, ArmBody

__all__ = [
    "Coupling",
    "arm_static_reaction",
    "measured_reaction",
    "rotated",
    "trim_float",
    "trim_wrench",
]

Vec3 = tuple[float, float, float]
Vec6 = tuple[float, float, float, float, float, float]
Coupling = tuple[Sequence[float], Sequence[float], Sequence[float], Vec3, Vec3]
"""The last step's hull velocity, angular velocity, rotation, force and torque (world)."""


def measured_reaction(
    last: Coupling,
    linear: Sequence[float],
    angular: Sequence[float],
    rotation: Sequence[float],
    mass: float,
    inertia: Sequence[float],
    dt: float,
) -> Vec6:
    """The arm's reaction on the hull over the last step [N, N·m], body FRD about the CoG.

    From the hull's velocities before (``last``: linear, angular, rotation, and the force and
    torque applied, all pybullet's world) and now: R = m·Δv/Δt − F and, in the body at the
    step's start, I·Δω/Δt + ω×I·ω − τ (what the hull's own Newton–Euler equations leave
    unexplained).
    """
    lin0, ang0, rot0, f0, t0 = last
    fx = mass * (linear[0] - lin0[0]) / dt - f0[0]
    fy = mass * (linear[1] - lin0[1]) / dt - f0[1]
    fz = mass * (linear[2] - lin0[2]) / dt - f0[2]
    r0 = rot0
    w = _body_point(r0, (0.0, 0.0, 0.0), ang0)
    dw = _body_point(r0, ang0, angular)
    ix, iy, iz = inertia
    hx, hy, hz = ix * w[0], iy * w[1], iz * w[2]
    tau_body = (
        ix * dw[0] / dt + w[1] * hz - w[2] * hy,
        iy * dw[1] / dt + w[2] * hx - w[0] * hz,
        iz * dw[2] / dt + w[0] * hy - w[1] * hx,
    )
    tx, ty, tz = (a - b for a, b in zip(rotated(r0, tau_body), t0, strict=True))
    bf = _body_point(rotation, (0.0, 0.0, 0.0), (fx, fy, fz))
    bt = _body_point(rotation, (0.0, 0.0, 0.0), (tx, ty, tz))
    return (bf[0], -bf[1], -bf[2], bt[0], -bt[1], -bt[2])


def arm_static_reaction(pb: ModuleType, client_id: int, body_id: int, arm: ArmBody) -> Vec6:
    """The resting arm's wrench on the hull in its present pose [N, N·m], body FRD about
    the CoG: each link's weight at its centre of mass and buoyancy at its centre of
    volume, along the world vertical (what the measured reaction is before any motion).

    Args:
        pb: the pybullet module.
        client_id: the physics client.
        body_id: the multibody (hull + the arm's links, :func:`~.arm_body.arm_links`).
        arm: the arm's links in that body.
    """
    base, orientation = pb.getBasePositionAndOrientation(body_id, client_id)
    rot = pb.getMatrixFromQuaternion(orientation)
    ux, uy, uz = rot[6], rot[7], rot[8]  # world up in the body (FLU)
    states = pb.getLinkStates(
        body_id, arm.link_indices, computeForwardKinematics=1, physicsClientId=client_id
    )
    force = [0.0, 0.0, 0.0]
    moment = [0.0, 0.0, 0.0]
    for link, state in zip(arm.links, states, strict=True):
        com = _body_point(rot, base, state[0])
        offset = rotated(pb.getMatrixFromQuaternion(state[5]), link.cov_m)
        cov = _body_point(rot, base, [p + o for p, o in zip(state[4], offset, strict=True)])
        weight, lift = link.mass_kg * G_M_S2, RHO_KG_M3 * G_M_S2 * link.volume_m3
        for point, size in ((com, -weight), (cov, lift)):
            fx, fy, fz = size * ux, size * uy, size * uz
            force[0], force[1], force[2] = force[0] + fx, force[1] + fy, force[2] + fz
            moment[0] += point[1] * fz - point[2] * fy
            moment[1] += point[2] * fx - point[0] * fz
            moment[2] += point[0] * fy - point[1] * fx
    return (force[0], -force[1], -force[2], moment[0], -moment[1], -moment[2])


def trim_float(static_reaction: Vec6) -> tuple[float, Vec3]:
    """The trim float for the arm's present (start) pose: its lift [N] (the arm's weight
    less its buoyancy) and its point [m], body FLU from the CoG, under which the arm's
    net weight acts, so that it cancels the force and the horizontal moment (the start
    attitude taken as level: every packaged scenario starts level).

    Args:
        static_reaction: the resting arm's wrench in its start pose (:func:`arm_static_reaction`).
    """
    _, _, down, mx, my, _ = static_reaction  # FRD: down = the net pull
    if abs(down) < 1e-9:
        return (0.0, (0.0, 0.0, 0.0))
    # FLU: the arm's moment is (mx, −my); a lift `down` at (px, py) gives (py, −px)·down,
    # which cancels it at py = −mx/down, px = −my/down
    return (down, (-my / down, -mx / down, 0.0))


def trim_wrench(trim: tuple[float, Vec3] | None, rotation: Sequence[float]) -> Vec6:
    """The trim float's wrench [N, N·m], body FRD about the CoG: its buoyancy (world up)
    at its body-fixed point.

    Args:
        trim: the float's lift [N] and point [m], body FLU from the CoG (:func:`trim_float`);
            None: no float.
        rotation: pybullet's row-major 3×3 rotation, body FLU → world.
    """
    if trim is None:
        return (0.0,) * 6
    lift, (px, py, pz) = trim
    # world up in the body FLU: the last row of R (body FLU → world)
    fx, fy, fz = lift * rotation[6], lift * rotation[7], lift * rotation[8]
    mx, my, mz = py * fz - pz * fy, pz * fx - px * fz, px * fy - py * fx
    return (fx, -fy, -fz, mx, -my, -mz)


def rotated(rotation: Sequence[float], v: Sequence[float]) -> Vec3:
    """R·v for pybullet's row-major 3×3 ``rotation``."""
    r = rotation
    return (
        r[0] * v[0] + r[1] * v[1] + r[2] * v[2],
        r[3] * v[0] + r[4] * v[1] + r[5] * v[2],
        r[6] * v[0] + r[7] * v[1] + r[8] * v[2],
    )


def _body_point(rotation: Sequence[float], base: Sequence[float], point: Sequence[float]) -> Vec3:
    """A world point in the base's frame (FLU, from the CoG): Rᵀ(point − base)."""
    d = [p - b for p, b in zip(point, base, strict=True)]
    r = rotation
    return (
        r[0] * d[0] + r[3] * d[1] + r[6] * d[2],
        r[1] * d[0] + r[4] * d[1] + r[7] * d[2],
        r[2] * d[0] + r[5] * d[1] + r[8] * d[2],
    )
