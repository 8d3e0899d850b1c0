"""The manipulator's links in the physics: one pybullet multibody with the vehicle's hull.

The arm (:class:`~testbed.vehicle.arm.ArmModel`) becomes the hull's child links in the same
pybullet multibody: a fixed link (the arm's base housing, at the mount pose) and one revolute
link per joint, driven by pybullet's joint motors (velocity control up to the joint's effort,
inside its position limits). pybullet's articulated-body dynamics then carry every reaction
between arm and hull; :class:`~testbed.vehicle.physics.Physics` measures the arm's reaction on
the hull each step and couples it into Fossen's equation (or cancels it: ``coupling = False``).

Per link, each step (pybullet's gravity is off, as for the hull):

* weight m·g at the link's centre of mass;
* buoyancy ρ·g·V at its centre of volume while that centre is below the surface (the
  datasheet's volumes, :mod:`testbed.vehicle.arm`);
* quadratic drag on the link as a cylinder at its centre of mass, relative to the water:
  −½ρ(C_n·d·L·|v_n|·v_n + C_a·(π d²/4)·|v_a|·v_a), v_a along the cylinder's axis and v_n across
  it (Hoerner's coefficients, in the arm's data file); the links' rotational drag is neglected
  (their angular rates reach 1 rad/s over 0.04-m tubes: the moment is below 1 mN·m).

Links have no collision shapes (arm contact is not modelled) and cylinder visual shapes, so the
camera sees the arm.

Frames: the arm's figures are in its URDF frames (FLU, as ROS); pybullet's body frame is FLU
at the hull's CoG, so the mount sits at mount − r_g(FLU). This module never imports pybullet:
:class:`~testbed.vehicle.physics.Physics` (the one module that does) hands it the module and its
client.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from types import ModuleType
from typing import Any

from testbed.vehicle.arm import ArmLink, ArmModel

__all__ = ["ArmBody", "arm_links"]

RHO_KG_M3 = 1000.0
"""Water density [kg/m³] (fresh water, the pools Angler's trials ran in)."""
G_M_S2 = 9.81
"""Gravity [m/s²]."""
_ARM_COLOUR = (0.85, 0.85, 0.8, 1.0)


def _flu(vector: Sequence[float]) -> tuple[float, float, float]:
    return (float(vector[0]), float(vector[1]), float(vector[2]))


def arm_links(
    pb: ModuleType, client_id: int, model: ArmModel, cog_frd_m: Sequence[float]
) -> dict[str, Any]:
    """The keyword arguments of ``createMultiBody`` that add ``model``'s links to the hull.

    Args:
        pb: the pybullet module.
        client_id: the physics client (for the visual shapes).
        model: the arm.
        cog_frd_m: the hull's CoG from CO [m], body FRD (pybullet's base frame origin).

    Returns:
        ``linkMasses``, ``linkCollisionShapeIndices``, ``linkVisualShapeIndices``,
        ``linkPositions``, ``linkOrientations``, ``linkInertialFramePositions``,
        ``linkInertialFrameOrientations``, ``linkParentIndices``, ``linkJointTypes`` and
        ``linkJointAxis``: link 0 is the base housing (fixed), links 1… the joints in order.
    """
    xg, yg, zg = (float(c) for c in cog_frd_m)
    mx, my, mz = model.mount_m
    mount = (mx - xg, my + yg, mz + zg)  # FLU, from the CoG (r_g FLU = (xg, −yg, −zg))
    links: list[ArmLink] = [model.base, *model.links]
    positions = [mount, *(_flu(j.origin_m) for j in model.joints)]
    orientations = [
        pb.getQuaternionFromEuler(model.mount_rpy_rad),
        *(pb.getQuaternionFromEuler(j.rpy_rad) for j in model.joints),
    ]
    visuals = [_visual(pb, client_id, link) for link in links]
    return {
        "linkMasses": [link.mass_kg for link in links],
        "linkCollisionShapeIndices": [-1] * len(links),
        "linkVisualShapeIndices": visuals,
        "linkPositions": positions,
        "linkOrientations": orientations,
        "linkInertialFramePositions": [_flu(link.com_m) for link in links],
        "linkInertialFrameOrientations": [(0.0, 0.0, 0.0, 1.0)] * len(links),
        "linkParentIndices": list(range(len(links))),
        "linkJointTypes": [pb.JOINT_FIXED] + [pb.JOINT_REVOLUTE] * len(model.joints),
        "linkJointAxis": [(0.0, 0.0, 1.0), *(_flu(j.axis) for j in model.joints)],
    }


def _visual(pb: ModuleType, client_id: int, link: ArmLink) -> int:
    """A cylinder the link's size along its axis, centred on its centre of volume."""
    ax, ay, az = link.axis
    # pybullet's cylinder lies along its frame's z: turn z onto the link's axis
    angle = math.acos(max(-1.0, min(1.0, az)))
    norm = math.hypot(ax, ay)
    if norm < 1e-12:
        turn = (0.0, 0.0, 0.0, 1.0) if az > 0 else (1.0, 0.0, 0.0, 0.0)
    else:
        s = math.sin(angle / 2) / norm
        turn = (-ay * s, ax * s, 0.0, math.cos(angle / 2))
    shape: int = pb.createVisualShape(
        pb.GEOM_CYLINDER,
        radius=0.5 * link.diameter_m,
        length=link.length_m,
        visualFramePosition=_flu(link.cov_m),
        visualFrameOrientation=turn,
        rgbaColor=_ARM_COLOUR,
        physicsClientId=client_id,
    )
    return shape


class ArmBody:
    """The arm's links of a built multibody: joint motors, state and hydrodynamic loads.

    Args:
        pb: the pybullet module.
        client_id: the physics client.
        body_id: the multibody (hull + :func:`arm_links`).
        model: the arm.
    """

    def __init__(self, pb: ModuleType, client_id: int, body_id: int, model: ArmModel) -> None:
        self._pb = pb
        self._cid = client_id
        self._body = body_id
        self.model = model
        self.links: tuple[ArmLink, ...] = (model.base, *model.links)
        self.link_indices = list(range(len(self.links)))
        self.joint_indices = list(range(1, len(self.links)))
        self._efforts = [j.effort_n_m for j in model.joints]
        # per link: weight, buoyancy [N], centre of volume, axis, ½ρC_n·d·L, ½ρC_a·πd²/4
        self._loads = [
            (
                link.mass_kg * G_M_S2,
                RHO_KG_M3 * G_M_S2 * link.volume_m3,
                _flu(link.cov_m),
                _flu(link.axis),
                0.5 * RHO_KG_M3 * link.drag_normal * link.diameter_m * link.length_m,
                0.5 * RHO_KG_M3 * link.drag_axial * math.pi * link.diameter_m**2 / 4.0,
            )
            for link in self.links
        ]
        self._rates: tuple[float, ...] = (0.0,) * len(model.joints)
        self._applied: tuple[float, ...] | None = None  # the motors' targets now
        for index in self.joint_indices:
            pb.changeDynamics(
                body_id,
                index,
                jointDamping=0.0,
                linearDamping=0.0,
                angularDamping=0.0,
                physicsClientId=client_id,
            )
        for index, link in zip(self.link_indices, self.links, strict=True):
            pb.changeDynamics(
                body_id,
                index,
                localInertiaDiagonal=list(link.inertia_kg_m2),
                physicsClientId=client_id,
            )

    def reset(self, q_rad: Sequence[float]) -> None:
        """Put the joints at ``q_rad`` [rad], at rest, and their motors at zero rate."""
        for index, angle in zip(self.joint_indices, q_rad, strict=True):
            self._pb.resetJointState(self._body, index, float(angle), 0.0, self._cid)
        self.command((0.0,) * len(self.joint_indices))
        self._applied = None

    def command(self, rates_rad_s: Sequence[float]) -> None:
        """Drive the joint motors at these rates [rad/s] (held until the next command), each
        up to its joint's effort and never past its position limits (:meth:`hold_limits`)."""
        rates = tuple(float(r) for r in rates_rad_s)
        if len(rates) != len(self.joint_indices):
            raise ValueError(f"{len(self.joint_indices)} joint rates expected, got {len(rates)}")
        self._rates = rates

    def hold_limits(self, dt_s: float) -> None:
        """Before a step of ``dt_s`` [s]: each motor's target is the commanded rate, cut so the
        joint ends the step at most at its limit, and turned back towards the limit (at most at
        the joint's velocity limit) when a load has pushed it past (the arm's soft limits, as
        Reach's firmware keeps its joints inside theirs; a resting motor at its effort limit
        otherwise creeps: axis c 0.014 rad past its upper limit in 30 s); the motors are set
        again only when that changes. pybullet's own limit constraints on these links are not
        relied on: on the lightest links they let a driven joint through, or past by 0.025 rad
        pulling its neighbour."""
        states = self._pb.getJointStates(self._body, self.joint_indices, self._cid)
        targets = []
        for state, rate, joint in zip(states, self._rates, self.model.joints, strict=True):
            angle, fastest = state[0], joint.velocity_rad_s
            if angle > joint.upper_rad:  # pushed past: back towards the limit
                rate = max(-fastest, min(rate, (joint.upper_rad - angle) / dt_s))
            elif angle < joint.lower_rad:
                rate = min(fastest, max(rate, (joint.lower_rad - angle) / dt_s))
            elif rate > 0.0:
                rate = min(rate, (joint.upper_rad - angle) / dt_s)
            elif rate < 0.0:
                rate = max(rate, (joint.lower_rad - angle) / dt_s)
            targets.append(rate)
        applied = tuple(targets)
        if applied != self._applied:
            self._applied = applied
            self._pb.setJointMotorControlArray(
                self._body,
                self.joint_indices,
                self._pb.VELOCITY_CONTROL,
                targetVelocities=targets,
                forces=self._efforts,
                physicsClientId=self._cid,
            )

    @property
    def commanded_rates(self) -> tuple[float, ...]:
        """The motors' present target rates [rad/s]."""
        return self._rates

    def joint_state(self) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """Joint angles [rad] and rates [rad/s], in the model's joint order."""
        states = self._pb.getJointStates(self._body, self.joint_indices, self._cid)
        return tuple(s[0] for s in states), tuple(s[1] for s in states)

    def apply_loads(self, current_ned: Sequence[float]) -> None:
        """Weight, buoyancy and drag on every link for the coming step (pybullet's world,
        z up; the current in NED)."""
        pb, body, cid = self._pb, self._body, self._cid
        cn, ce, cd = current_ned
        wx, wy, wz = cn, -ce, -cd  # the water's velocity, pybullet's world
        states = pb.getLinkStates(
            body,
            self.link_indices,
            computeLinkVelocity=1,
            computeForwardKinematics=1,
            physicsClientId=cid,
        )
        apply, world, matrix = pb.applyExternalForce, pb.WORLD_FRAME, pb.getMatrixFromQuaternion
        for index, loads, state in zip(self.link_indices, self._loads, states, strict=True):
            weight, lift, (cx, cy, cz), (ax, ay, az), k_normal, k_axial = loads
            com, _, _, _, (px, py, pz), orientation, (vx, vy, vz), _ = state
            r0, r1, r2, r3, r4, r5, r6, r7, r8 = matrix(orientation)
            cov_z = pz + r6 * cx + r7 * cy + r8 * cz
            if cov_z >= 0.0:  # out of the water: its weight only
                apply(body, index, (0.0, 0.0, -weight), com, world, cid)
                continue
            cov = (px + r0 * cx + r1 * cy + r2 * cz, py + r3 * cx + r4 * cy + r5 * cz, cov_z)
            # drag: the relative velocity split along and across the link's axis (world)
            bx, by, bz = (
                r0 * ax + r1 * ay + r2 * az,
                r3 * ax + r4 * ay + r5 * az,
                r6 * ax + r7 * ay + r8 * az,
            )
            ux, uy, uz = vx - wx, vy - wy, vz - wz
            along = ux * bx + uy * by + uz * bz
            nx, ny, nz = ux - along * bx, uy - along * by, uz - along * bz
            kn = k_normal * math.sqrt(nx * nx + ny * ny + nz * nz)
            ka = k_axial * abs(along) * along
            force = (-kn * nx - ka * bx, -kn * ny - ka * by, -kn * nz - ka * bz - weight)
            apply(body, index, force, com, world, cid)
            apply(body, index, (0.0, 0.0, lift), cov, world, cid)
