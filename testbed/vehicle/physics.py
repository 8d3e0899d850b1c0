"""The vehicle's plant: Fossen's 6-DOF model stepped by a pybullet rigid body.

pybullet integrates one rigid body (mass m, inertia about the CoG) and resolves contacts; it
knows nothing of added mass, damping, buoyancy or currents, and its gravity is off. Each step
reads pybullet's pose and velocity, solves (M_RB + M_A) ν̇ = τ − C(ν)ν − D(ν_r)ν_r − g(η) for
the acceleration exactly (never a lagged estimate: heave added mass exceeds the vehicle's mass),
then applies the body force and torque that give pybullet's rigid body exactly that
acceleration. pybullet integrates linear velocity in the world frame (v += dt·F/m) and angular
velocity with its own explicit gyroscopic term (ω̇ = I⁻¹(τ − ω×Iω)), so the force carries the
transport term ω×v_g and the torque puts back ω×I_gω.

pybullet's body frame is placed at the CoG: its base position *is* the centre of mass, so there
is no inertial-frame offset to get wrong, and the hydrodynamic origin CO sits at −r_g from it.
M = M_RB + M_A about CO is then general (r_g ≠ 0 couples surge–pitch and sway–roll); its inverse
is computed once (:func:`testbed.vehicle.hydrodynamics.coefficients`); each step's arithmetic
is one compiled function, :func:`~.plant_kernels.pybullet_wrench`.

Frames: this module (with its compiled arithmetic, :mod:`.plant_kernels`) is the only place that
knows pybullet is z-up. pybullet's world is NED
rotated by π about north, (x, y, z)_pb = (N, −E, −D), and its body frame is FLU, the same
rotation of FRD: vectors map by (x, −y, −z) both ways and a quaternion (w, x, y, z) maps to
(w, x, −y, −z). Nothing outside this module imports pybullet.

Rendering: :meth:`Physics.add_scenery` (visual-only static bodies, :mod:`.scenery`) and
:meth:`Physics.render` (pybullet's CPU renderer from a camera pose in NED, :mod:`.camera`).

Size: this module stays whole, over the 500-line guideline, because it is the one module allowed
to import pybullet and the one that knows pybullet's z-up frames; the scene, the stepper and the
frame conversions cannot move out without spreading that knowledge.
"""

from __future__ import annotations

import ctypes
import math
import os
import sys
import tempfile
import weakref
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from types import ModuleType

import numpy as np
from numpy.typing import NDArray

from testbed.common import jit
from testbed.common.geometry import euler_from_quat, quat_from_euler, rotate, rotation_matrix
from testbed.config import check
from testbed.vehicle.arm import ArmModel
from testbed.vehicle.arm_body import G_M_S2, RHO_KG_M3, ArmBody, arm_links
from testbed.vehicle.camera import CameraConfig, CameraPose
from testbed.vehicle.hydrodynamics import HydroModel, coefficients, load_model
from testbed.vehicle.plant_kernels import (
    LOAD_CURRENT,
    LOAD_NU_DOT,
    LOAD_WRENCH,
    N_LOADS,
    pybullet_state,
    pybullet_wrench,
)
from testbed.vehicle.scenery import LIGHT_TOWARDS_NED, Scenery
from testbed.vehicle.water_current import CurrentProcess, WaterCurrent


def _import_pybullet_quietly() -> ModuleType:
    """Import pybullet without its C-level "pybullet build time" banner.

    pybullet prints the banner from C at import, straight to file descriptor 2, where it would
    precede a command's one-line error message; descriptor 2 points at /dev/null for the
    duration of the import only.
    """
    sys.stderr.flush()
    libc = ctypes.CDLL(None)
    saved = os.dup(2)
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 2)
        import pybullet as module  # imported here to silence its banner

        libc.fflush(None)  # anything still in C's buffers goes to /dev/null too
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        os.close(devnull)
    return module  # type: ignore[no-any-return]


pybullet = _import_pybullet_quietly()

__all__ = [
    "POOL_LIMITS_M",
    "BodyState",
    "OpenLoopResult",
    "Physics",
    "PoolScene",
    "ned_to_pybullet",
    "pybullet_to_ned",
    "quaternion_ned_to_pybullet",
    "quaternion_pybullet_to_ned",
    "simulate_open_loop",
]

FloatArray = NDArray[np.float64]
Vec3 = tuple[float, float, float]
Vec6 = tuple[float, float, float, float, float, float]
Quat = tuple[float, float, float, float]
_Raw = tuple[Vec3, tuple[float, float, float, float], tuple[Vec3, Vec3]]
"""pybullet's (position, orientation xyzw, (linear velocity, angular velocity)), world z-up."""
_ZERO3 = (0.0, 0.0, 0.0)
_VEC3 = jit.floats(3)
_Coupling = tuple[Sequence[float], Sequence[float], Sequence[float], Vec3, Vec3]
"""The last step's hull velocity, angular velocity, rotation, force and torque (world)."""


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


@dataclass(frozen=True, slots=True, eq=False)
class BodyState:
    """The vehicle's state at one instant (arrays are read-only).

    Attributes:
        time_s: simulated time [s].
        position_ned: (3,) position of the body origin CO [m], NED.
        quaternion_wxyz: (4,) attitude, body FRD → NED.
        euler_rad: (3,) roll, pitch, yaw [rad], ZYX.
        nu: (6,) body velocity [u v w p q r] at CO [m/s, rad/s], FRD.
        nu_dot: (6,) body acceleration of the last step's model (contacts not included)
            [m/s², rad/s²], FRD.
    """

    time_s: float
    position_ned: FloatArray
    quaternion_wxyz: FloatArray
    euler_rad: FloatArray
    nu: FloatArray
    nu_dot: FloatArray


@dataclass(frozen=True, slots=True, eq=False)
class OpenLoopResult:
    """Samples of an open-loop run, one row per step including t = 0.

    Attributes:
        t: (N,) time [s].
        position_ned: (N, 3) position of CO [m], NED.
        euler_rad: (N, 3) roll, pitch, yaw [rad].
        nu: (N, 6) body velocity [u v w p q r] [m/s, rad/s], FRD.
    """

    t: FloatArray
    position_ned: FloatArray
    euler_rad: FloatArray
    nu: FloatArray


def _frozen(values: Sequence[float] | FloatArray) -> FloatArray:
    array = np.array(values, dtype=float)
    array.setflags(write=False)
    return array


class Physics:
    """One vehicle in its own pybullet DIRECT client, stepped with Fossen's forces.

    Args:
        model: the vehicle's parameters.
        dt_s: physics step [s].
        start_position_ned: (3,) initial position of CO [m], NED.
        start_euler_rad: (3,) initial roll, pitch, yaw [rad].
        current: water current (none by default).
        pool: pool scene (open water by default).
        rng: generator for the current's variation (needed only if it varies).
        arm: a manipulator on the hull (:mod:`.arm_body`), or None.
        arm_coupling: the arm's reaction on the hull enters Fossen's equation (True), or is
            cancelled, as if the arm were massless to the hull (False: what coupling costs).
        arm_trim: a float fixed to the hull cancels the arm's weight in water and its moment
            in the arm's initial pose (as Angler's vehicle is ballasted for its arm); only with
            ``arm_coupling`` (uncoupled, the hull feels none of the arm's weight either).

    Coupling. The arm's links are the hull's children in one pybullet multibody, so pybullet's
    articulated dynamics carry the joint reactions. Each step measures the arm's reaction on the
    hull over the last step from the hull's own motion, R = m·Δv/Δt − F_applied (and
    I·Δω/Δt + ω×Iω − τ_applied), then solves Fossen's equation with τ + R (one step late:
    the arm is ~10 % of the hull's mass and added mass, so the lag's recurrence factor is
    ~0.1) and applies the force that gives that acceleration less R, which pybullet adds back.

    Use as a context manager or call :meth:`close`; the pybullet client is disconnected then.
    """

    def __init__(
        self,
        model: HydroModel,
        *,
        dt_s: float = 1.0 / 240.0,
        start_position_ned: Sequence[float] = (0.0, 0.0, 10.0),
        start_euler_rad: Sequence[float] = (0.0, 0.0, 0.0),
        current: WaterCurrent | None = None,
        pool: PoolScene | None = None,
        rng: np.random.Generator | None = None,
        arm: ArmModel | None = None,
        arm_coupling: bool = True,
        arm_trim: bool = True,
    ) -> None:
        if not dt_s > 0.0:
            raise ValueError(f"dt_s must be > 0, got {dt_s}")
        self.model = model
        self.dt_s = float(dt_s)
        self.current = current if current is not None else WaterCurrent()
        self.pool = pool
        self._current_process = CurrentProcess(self.current, rng)
        self._current_ned = self._current_process.velocity_ned
        # the applied wrench (held), the current and the last step's ν̇ (plant_kernels' offsets)
        self._loads = np.zeros(N_LOADS)
        self._current_varies = self.current.varies
        self._next_current_update_s = self.current.update_period_s
        self._start_position = tuple(float(c) for c in start_position_ned)
        self._start_euler = tuple(float(c) for c in start_euler_rad)
        self._steps = 0
        self._cached: BodyState | None = None
        # pybullet's pose and velocity as read since the last step (reused by the next step)
        self._raw: _Raw | None = None
        self._floats: tuple[float, Vec3, Quat, Vec6] | None = None

        xg, yg, zg = model.cog_m
        self._cog = (float(xg), float(yg), float(zg))
        # the CoG, then pybullet's reads: position, (x, y, z, w), linear and angular velocity
        self._state_of = jit.entry(pybullet_state, _VEC3, _VEC3, jit.floats(4), _VEC3, _VEC3)
        self.arm_model = arm
        self.arm_coupling = arm_coupling
        self.arm: ArmBody | None = None
        self._trim: tuple[float, Vec3] | None = None
        self._coupling: list[_Coupling | None] = [None]  # the last step's (v, ω, R, F, τ), world
        self.arm_reaction_frd: Vec6 = (0.0,) * 6
        self._seed_reaction: Vec6 = (0.0,) * 6  # the resting arm's, for the first step
        """The arm's reaction on the hull measured at the last step [N, N·m], FRD, CoG."""

        self.client_id: int = pybullet.connect(pybullet.DIRECT)
        self._finalizer = weakref.finalize(self, _disconnect, self.client_id)
        self.body_id: int = self._build_scene()
        if arm is not None:
            self.arm = ArmBody(pybullet, self.client_id, self.body_id, arm)
        self._advance = self._make_stepper()
        self.reset()
        if arm is not None and arm_trim and arm_coupling:
            self._trim = self._arm_trim()

    # --- setup -----------------------------------------------------------------------------

    def _build_scene(self) -> int:
        cid = self.client_id
        pybullet.setGravity(0.0, 0.0, 0.0, physicsClientId=cid)
        pybullet.setPhysicsEngineParameter(
            fixedTimeStep=self.dt_s,
            numSubSteps=0,
            deterministicOverlappingPairs=1,
            physicsClientId=cid,
        )
        half = [0.5 * s for s in self.model.hull_size_m]
        # The hull box is centred on CO, which is at −r_g from the CoG (pybullet's body frame).
        centre_flu = ned_to_pybullet([-c for c in self._cog])
        shape = pybullet.createCollisionShape(
            pybullet.GEOM_BOX,
            halfExtents=half,
            collisionFramePosition=centre_flu,
            physicsClientId=cid,
        )
        links = (
            {} if self.arm_model is None else arm_links(pybullet, cid, self.arm_model, self._cog)
        )
        body: int = pybullet.createMultiBody(
            baseMass=self.model.mass_kg,
            baseCollisionShapeIndex=shape,
            basePosition=[0.0, 0.0, 0.0],
            physicsClientId=cid,
            **links,
        )
        pybullet.changeDynamics(
            body,
            -1,
            linearDamping=0.0,
            angularDamping=0.0,
            localInertiaDiagonal=list(self.model.inertia_kg_m2),  # FRD and FLU share a diagonal
            activationState=pybullet.ACTIVATION_STATE_DISABLE_SLEEPING,
            physicsClientId=cid,
        )
        if self.pool is not None:
            self._build_pool(self.pool)
        return body

    def _build_pool(self, pool: PoolScene) -> None:
        cid = self.client_id
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
            shape = pybullet.createCollisionShape(
                pybullet.GEOM_BOX, halfExtents=half, physicsClientId=cid
            )
            pybullet.createMultiBody(
                baseMass=0.0,
                baseCollisionShapeIndex=shape,
                basePosition=ned_to_pybullet(centre),
                physicsClientId=cid,
            )

    # --- public API ------------------------------------------------------------------------

    @property
    def time_s(self) -> float:
        """Simulated time since the last reset [s]."""
        return self._steps * self.dt_s

    @property
    def current_ned(self) -> Vec3:
        """The water velocity now [m/s], NED."""
        return self._current_ned

    def reset(
        self,
        *,
        position_ned: Sequence[float] | None = None,
        euler_rad: Sequence[float] | None = None,
        nu: Sequence[float] | None = None,
    ) -> None:
        """Put the vehicle at a pose and body velocity and restart time at 0.

        Args:
            position_ned: (3,) position of CO [m], NED (default: the start position).
            euler_rad: (3,) roll, pitch, yaw [rad] (default: the start attitude).
            nu: (6,) body velocity [u v w p q r] at CO [m/s, rad/s], FRD (default: rest).

        The water current keeps its state; the held wrench is cleared (:attr:`held_wrench`).
        """
        self._check_open()
        px, py, pz = position_ned if position_ned is not None else self._start_position
        roll, pitch, yaw = euler_rad if euler_rad is not None else self._start_euler
        u, v, w, p, q, r = nu if nu is not None else (0.0,) * 6
        quat = quat_from_euler(roll, pitch, yaw)
        rot = rotation_matrix(quat)
        xg, yg, zg = self._cog
        cog_offset = rotate(rot, (xg, yg, zg))
        cog_ned = (px + cog_offset[0], py + cog_offset[1], pz + cog_offset[2])
        # CoG velocity in the body: v_g = v_o + ω × r_g; then to NED.
        vg_body = (u + q * zg - r * yg, v + r * xg - p * zg, w + p * yg - q * xg)
        cid = self.client_id
        pybullet.resetBasePositionAndOrientation(
            self.body_id,
            ned_to_pybullet(cog_ned),
            quaternion_ned_to_pybullet(quat),
            physicsClientId=cid,
        )
        pybullet.resetBaseVelocity(
            self.body_id,
            ned_to_pybullet(rotate(rot, vg_body)),
            ned_to_pybullet(rotate(rot, (p, q, r))),
            physicsClientId=cid,
        )
        if self.arm is not None:
            self.arm.reset(self.arm_model.initial_q_rad if self.arm_model else ())
            self._coupling[0] = None
            self._seed_reaction = self._arm_static_reaction()
        self._steps = 0
        self._next_current_update_s = self.current.update_period_s
        self._loads[:] = 0.0
        self._loads[LOAD_CURRENT : LOAD_CURRENT + 3] = self._current_ned
        self._cached = None
        self._raw = None
        self._floats = None

    @property
    def held_wrench(self) -> FloatArray:
        """(6,) the body wrench every step applies until it is written again [N, N·m], FRD,
        moments about the CoG: the plant's own array (a vehicle's actuation writes it in
        place once a frame; :meth:`step` with a wrench writes it too)."""
        return self._loads[LOAD_WRENCH : LOAD_WRENCH + 6]

    def step(self, wrench_body: Sequence[float] | FloatArray | None = None) -> None:
        """Advance one ``dt_s`` with the applied wrench held constant.

        Args:
            wrench_body: (6,) body wrench [N, N·m], FRD, moments about the CoG, held from now
                on; None (the vehicle's frame path) applies :attr:`held_wrench` as it is.
        """
        if wrench_body is not None:
            self._loads[LOAD_WRENCH : LOAD_WRENCH + 6] = wrench_body
        self.step_until(-math.inf)

    def step_until(self, until_s: float) -> float:
        """Step once with :attr:`held_wrench`, then again while the time is before ``until_s``.

        Args:
            until_s: the time to reach [s] (a vehicle's next frame, or the end of its advance).

        Returns:
            The time now [s]: the first step's time at or after ``until_s``, or one step later
            than before when that was already reached.
        """
        raw = self._raw  # read since the last step (by state_floats): still current
        self._raw = None
        self._floats = None
        self._cached = None
        advance, dt, varies = self._advance, self.dt_s, self._current_varies
        steps = self._steps
        while True:
            advance(raw)
            raw = None
            steps += 1
            self._steps = steps
            now = steps * dt
            if varies and now >= self._next_current_update_s:
                self._next_current_update_s += self.current.update_period_s
                self._current_ned = self._current_process.advance(self.current.update_period_s)
                self._loads[LOAD_CURRENT : LOAD_CURRENT + 3] = self._current_ned
            if now >= until_s:
                return now

    def state(self) -> BodyState:
        """The state now as a :class:`BodyState` (arrays, Euler angles): :meth:`state_floats`
        with the Euler angles of its attitude and the last step's ν̇, cached until the next step."""
        if self._cached is None:
            t, position, quat, nu = self.state_floats()
            self._cached = BodyState(
                time_s=t,
                position_ned=_frozen(position),
                quaternion_wxyz=_frozen(quat),
                euler_rad=_frozen(euler_from_quat(quat)),
                nu=_frozen(nu),
                nu_dot=_frozen(self._loads[LOAD_NU_DOT : LOAD_NU_DOT + 6]),
            )
        return self._cached

    def state_floats(self) -> tuple[float, Vec3, Quat, Vec6]:
        """The state now as plain floats, for per-frame use; the pybullet reads it makes are
        reused by the next :meth:`step`.

        Returns:
            ``(time_s, position_ned, quaternion_wxyz, nu)``: time [s]; (3,) position of CO [m],
            NED; (4,) attitude, body FRD → NED; (6,) body velocity [u v w p q r] at CO
            [m/s, rad/s], FRD.
        """
        floats = self._floats
        if floats is None:
            raw = self._raw
            if raw is None:
                raw = self._raw = self._read()
            position, orientation, (linear, angular) = raw
            state = self._state_of(self._cog, position, orientation, linear, angular)
            floats = self._floats = (self._steps * self.dt_s, *state)
        return floats

    def add_scenery(self, scenery: Scenery) -> None:
        """Add the camera's scenery as static visual-only bodies (no collision, no mass: stepping
        is unchanged); bodies already here (the hull, a pool's boxes) turn transparent."""
        self._check_open()
        pb = {"physicsClientId": self.client_id}
        for index in range(pybullet.getNumBodies(**pb)):
            body = pybullet.getBodyUniqueId(index, **pb)
            pybullet.changeVisualShape(body, -1, rgbaColor=(0, 0, 0, 0), **pb)
        with tempfile.TemporaryDirectory(prefix="testbed-") as folder:  # loadTexture needs a file
            paths = scenery.write_textures(folder).items()
            textures = {name: pybullet.loadTexture(path, **pb) for name, path in paths}
        placed = []  # (visual shape, position NED, attitude wxyz, texture or None)
        # quads: counter-clockwise seen from the normal's side; the texture's row 0 is v = 1
        mesh = {"indices": [0, 2, 1, 0, 3, 2], "uvs": [(0, 1), (1, 1), (1, 0), (0, 0)], **pb}
        for quad in scenery.quads:
            vertices = [ned_to_pybullet(c) for c in quad.corners_ned_m]
            normals = [ned_to_pybullet(quad.normal_ned)] * 4
            shape = pybullet.createVisualShape(
                pybullet.GEOM_MESH, vertices=vertices, normals=normals, **mesh
            )
            placed.append((shape, _ZERO3, (1.0, 0.0, 0.0, 0.0), textures[quad.texture]))
        for solid in scenery.solids:
            kind, size = getattr(pybullet, f"GEOM_{solid.kind.upper()}"), solid.size_m
            half = [0.5 * s for s in size] if solid.kind == "box" else None
            rgba = (*solid.rgb, 1.0)
            shape = pybullet.createVisualShape(
                kind, radius=size[0], length=size[-1], halfExtents=half, rgbaColor=rgba, **pb
            )
            placed.append((shape, solid.position_ned_m, solid.quaternion_wxyz, None))
        sleep = pybullet.ACTIVATION_STATE_SLEEP  # a sleeping static rigid body costs no step time
        for shape, position, attitude, texture in placed:
            at = ned_to_pybullet(position), quaternion_ned_to_pybullet(attitude)
            body = pybullet.createMultiBody(0.0, -1, shape, *at, useMaximalCoordinates=True, **pb)
            pybullet.changeDynamics(body, -1, activationState=sleep, **pb)
            if texture is not None:
                pybullet.changeVisualShape(body, -1, textureUniqueId=texture, **pb)

    def render(
        self, pose: CameraPose, camera: CameraConfig
    ) -> tuple[NDArray[np.uint8], NDArray[np.float32]]:
        """Draw the scenery from a camera pose (NED) with pybullet's CPU renderer, TinyRenderer.

        Returns:
            ``(rgb, zbuffer)`` at ``camera.render_size_px``: (h, w, 3) uint8 colour, row 0 at the
            top; (h, w) OpenGL depth buffer in [0, 1], 1 where nothing was hit.
        """
        self._check_open()
        eye, (w, h) = pose.position_ned_m, camera.render_size_px
        target = [e + f for e, f in zip(eye, pose.forward_ned, strict=True)]
        view = pybullet.computeViewMatrix(*map(ned_to_pybullet, (eye, target, pose.up_ned)))
        projection = camera.projection_matrix
        light = ned_to_pybullet(LIGHT_TOWARDS_NED)
        tiny = {"renderer": pybullet.ER_TINY_RENDERER, "flags": pybullet.ER_NO_SEGMENTATION_MASK}
        options = {"lightDirection": light, "shadow": 0, "physicsClientId": self.client_id, **tiny}
        _, _, rgba, zbuffer, _ = pybullet.getCameraImage(w, h, view, projection, **options)
        rgb = np.asarray(rgba, dtype=np.uint8).reshape(h, w, 4)[:, :, :3]
        return rgb, np.asarray(zbuffer, dtype=np.float32).reshape(h, w)

    def close(self) -> None:
        """Disconnect the pybullet client (idempotent)."""
        self._finalizer()

    def __enter__(self) -> Physics:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    # --- internals ---------------------------------------------------------------------------

    def _make_stepper(self) -> Callable[[_Raw | None], None]:
        """One step: pybullet's reads, the compiled :func:`~.plant_kernels.pybullet_wrench`,
        force, torque and pybullet's step, the floor's five pybullet calls (attribute lookups
        bound once: this runs 240 times a simulated second); with an arm, the coupled step
        (class docstring)."""
        get_pose = pybullet.getBasePositionAndOrientation
        get_velocity = pybullet.getBaseVelocity
        apply_force = pybullet.applyExternalForce
        apply_torque = pybullet.applyExternalTorque
        step_simulation = pybullet.stepSimulation
        rotation_of = pybullet.getMatrixFromQuaternion  # the arm step needs R here too
        link_frame = pybullet.LINK_FRAME
        cid, body = self.client_id, self.body_id
        model = self.model
        fossen = coefficients(model)
        rigid = np.array(
            (
                model.mass_kg,
                *model.inertia_kg_m2,
                *model.cog_m,
                *(b - g for b, g in zip(model.cob_m, model.cog_m, strict=True)),
                1.0 / model.hull_size_m[2],
            ),
            dtype=np.float64,
        )

        loads = self._loads
        # what pybullet gives: floats, (x, y, z, w), (linear, angular)
        wrench_of = jit.entry(
            pybullet_wrench,
            jit.CONST_VECTOR,
            jit.VECTOR,
            jit.VECTOR,
            jit.F64,
            jit.floats(4),
            jit.tuple_of(_VEC3, 2),
        )

        def advance(raw: _Raw | None) -> None:
            if raw is None:
                (_, _, height), orientation = get_pose(body, cid)
                velocity = get_velocity(body, cid)
            else:  # read since the last step (by state_floats): still current
                (_, _, height), orientation, velocity = raw
            force, torque = wrench_of(fossen, rigid, loads, height, orientation, velocity)
            apply_force(body, -1, force, _ZERO3, link_frame, cid)
            apply_torque(body, -1, torque, link_frame, cid)
            step_simulation(cid)

        if self.arm is None:
            return advance
        # With the arm: its measured reaction coupled into (or cancelled from) the hull's
        # Fossen equation, the trim float's wrench, and the links' loads (class docstring).
        arm = self.arm
        assert arm is not None
        m, dt, coupled = model.mass_kg, self.dt_s, self.arm_coupling
        inertia = model.inertia_kg_m2  # FRD and FLU share the diagonal
        memory = self._coupling

        scratch = np.zeros(N_LOADS)  # the hull's loads with the trim and the arm's reaction
        w, c = LOAD_WRENCH, LOAD_CURRENT

        def advance_arm(raw: _Raw | None) -> None:
            if raw is None:
                (_, _, height), orientation = get_pose(body, cid)
                velocity = get_velocity(body, cid)
            else:
                (_, _, height), orientation, velocity = raw
            linear, angular = velocity
            rotation = rotation_of(orientation)
            last = memory[0]
            if last is None:  # nothing measured yet: the resting arm's weight and buoyancy
                reaction = self._seed_reaction
            else:
                reaction = _measured_reaction(last, linear, angular, rotation, m, inertia, dt)
            self.arm_reaction_frd = reaction
            held = loads[w : w + 6].tolist()
            load = [a + t for a, t in zip(held, self._trim_wrench(rotation), strict=True)]
            if coupled:
                load = [a + r for a, r in zip(load, reaction, strict=True)]
            scratch[w : w + 6] = load
            scratch[c : c + 3] = loads[c : c + 3]
            force, torque = wrench_of(fossen, rigid, scratch, height, orientation, velocity)
            loads[LOAD_NU_DOT : LOAD_NU_DOT + 6] = scratch[LOAD_NU_DOT : LOAD_NU_DOT + 6]
            rx, ry, rz, rk, rm, rn = reaction  # FRD → FLU: (x, −y, −z)
            force = (force[0] - rx, force[1] + ry, force[2] + rz)
            torque = (torque[0] - rk, torque[1] + rm, torque[2] + rn)
            apply_force(body, -1, force, _ZERO3, link_frame, cid)
            apply_torque(body, -1, torque, link_frame, cid)
            arm.apply_loads(self._current_ned)
            arm.hold_limits(dt)
            step_simulation(cid)
            memory[0] = (
                linear,
                angular,
                rotation,
                _rotated(rotation, force),
                _rotated(rotation, torque),
            )

        return advance_arm

    def _trim_wrench(self, rotation: Sequence[float]) -> Vec6:
        """The trim float's wrench [N, N·m], body FRD about the CoG: its buoyancy (world up)
        at its body-fixed point."""
        if self._trim is None:
            return (0.0,) * 6
        lift, (px, py, pz) = self._trim
        # world up in the body FLU: the last row of R (body FLU → world)
        fx, fy, fz = lift * rotation[6], lift * rotation[7], lift * rotation[8]
        mx, my, mz = py * fz - pz * fy, pz * fx - px * fz, px * fy - py * fx
        return (fx, -fy, -fz, mx, -my, -mz)

    def _arm_static_reaction(self) -> Vec6:
        """The resting arm's wrench on the hull in its present pose [N, N·m], body FRD about
        the CoG: each link's weight at its centre of mass and buoyancy at its centre of
        volume, along the world vertical (what the measured reaction is before any motion)."""
        arm = self.arm
        assert arm is not None
        cid = self.client_id
        base, orientation = pybullet.getBasePositionAndOrientation(self.body_id, cid)
        rot = pybullet.getMatrixFromQuaternion(orientation)
        ux, uy, uz = rot[6], rot[7], rot[8]  # world up in the body (FLU)
        states = pybullet.getLinkStates(
            self.body_id, arm.link_indices, computeForwardKinematics=1, physicsClientId=cid
        )
        force = [0.0, 0.0, 0.0]
        moment = [0.0, 0.0, 0.0]
        for link, state in zip(arm.links, states, strict=True):
            com = _body_point(rot, base, state[0])
            offset = _rotated(pybullet.getMatrixFromQuaternion(state[5]), link.cov_m)
            cov = _body_point(rot, base, [p + o for p, o in zip(state[4], offset, strict=True)])
            weight, lift = link.mass_kg * G_M_S2, RHO_KG_M3 * G_M_S2 * link.volume_m3
            for point, size in ((com, -weight), (cov, lift)):
                fx, fy, fz = size * ux, size * uy, size * uz
                force[0], force[1], force[2] = force[0] + fx, force[1] + fy, force[2] + fz
                moment[0] += point[1] * fz - point[2] * fy
                moment[1] += point[2] * fx - point[0] * fz
                moment[2] += point[0] * fy - point[1] * fx
        return (force[0], -force[1], -force[2], moment[0], -moment[1], -moment[2])

    def _arm_trim(self) -> tuple[float, Vec3]:
        """The trim float for the arm's present (start) pose: its lift [N] (the arm's weight
        less its buoyancy) and its point [m], body FLU from the CoG, under which the arm's
        net weight acts, so that it cancels the force and the horizontal moment (the start
        attitude taken as level: every packaged scenario starts level)."""
        _, _, down, mx, my, _ = self._arm_static_reaction()  # FRD: down = the net pull
        if abs(down) < 1e-9:
            return (0.0, (0.0, 0.0, 0.0))
        # FLU: the arm's moment is (mx, −my); a lift `down` at (px, py) gives (py, −px)·down,
        # which cancels it at py = −mx/down, px = −my/down
        return (down, (-my / down, -mx / down, 0.0))

    def arm_state(self) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """The arm's joint angles [rad] and rates [rad/s] (model order); empty without an arm."""
        self._check_open()
        return ((), ()) if self.arm is None else self.arm.joint_state()

    @property
    def arm_commanded_rates(self) -> tuple[float, ...]:
        """The joint motors' present target rates [rad/s]; empty without an arm."""
        return () if self.arm is None else self.arm.commanded_rates

    def command_arm(self, rates_rad_s: Sequence[float]) -> None:
        """Drive the arm's joints at these rates [rad/s] (held until changed)."""
        if self.arm is None:
            raise RuntimeError("this vehicle has no arm")
        self.arm.command(rates_rad_s)

    def _check_open(self) -> None:
        if not self._finalizer.alive:
            raise RuntimeError("Physics is closed")

    def _read(self) -> _Raw:
        """pybullet's base position, orientation, linear and angular velocity (world, z-up)."""
        self._check_open()
        cid = self.client_id
        pos, orn = pybullet.getBasePositionAndOrientation(self.body_id, cid)
        return (pos, orn, pybullet.getBaseVelocity(self.body_id, cid))


def _rotated(rotation: Sequence[float], v: Sequence[float]) -> Vec3:
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


def _measured_reaction(
    last: _Coupling,
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
    tx, ty, tz = (a - b for a, b in zip(_rotated(r0, tau_body), t0, strict=True))
    bf = _body_point(rotation, (0.0, 0.0, 0.0), (fx, fy, fz))
    bt = _body_point(rotation, (0.0, 0.0, 0.0), (tx, ty, tz))
    return (bf[0], -bf[1], -bf[2], bt[0], -bt[1], -bt[2])


def _disconnect(client_id: int) -> None:
    if pybullet.isConnected(client_id):
        pybullet.disconnect(client_id)


def simulate_open_loop(
    model: str,
    wrench_body: Sequence[float],
    duration_s: float,
    dt_s: float = 1.0 / 240.0,
    start_depth_m: float = 10.0,
) -> OpenLoopResult:
    """Apply a constant body wrench in open water (no thrusters, no controller) and record.

    Args:
        model: a packaged model name (see :func:`testbed.vehicle.hydrodynamics.known_models`).
        wrench_body: (6,) body wrench [N, N·m], FRD, moments about the CoG.
        duration_s: simulated time [s].
        dt_s: physics step [s].
        start_depth_m: initial depth of CO [m]; the vehicle starts level, at rest, heading north.

    Returns:
        One sample per step, t = 0 included.
    """
    wrench = tuple(float(c) for c in wrench_body)
    if len(wrench) != 6:
        raise ValueError(f"wrench_body must have 6 values, got {len(wrench)}")
    n_steps = round(duration_s / dt_s)
    samples = []
    with Physics(load_model(model), dt_s=dt_s, start_position_ned=(0.0, 0.0, start_depth_m)) as sim:
        samples.append(sim.state_floats())
        for _ in range(n_steps):
            sim.step(wrench)
            samples.append(sim.state_floats())
    return OpenLoopResult(
        t=np.array([s[0] for s in samples]),
        position_ned=np.array([s[1] for s in samples]),
        euler_rad=np.array([euler_from_quat(s[2]) for s in samples]),
        nu=np.array([s[3] for s in samples]),
    )
