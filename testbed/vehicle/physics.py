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

Frames: pybullet's world is NED rotated by π about north, its body frame FLU
(:mod:`.pybullet_frames`). This is the one module that imports pybullet; it hands the module and
its client to those that build and draw the scene: :mod:`.hull_body`, :mod:`.arm_body` with
:mod:`.arm_coupling` (the arm's reaction on the hull), :mod:`.pool_scene` and
:mod:`.scenery_render` (:meth:`Physics.add_scenery`, :meth:`Physics.render`).
:mod:`.open_loop` runs the plant with a constant wrench.
"""

from __future__ import annotations

import ctypes
import math
import os
import sys
import weakref
from collections.abc import Callable, Sequence
from types import ModuleType

import numpy as np
from numpy.typing import NDArray

from testbed.common import jit
from testbed.common.geometry import euler_from_quat
from testbed.vehicle.arm import ArmModel
from testbed.vehicle.arm_body import ArmBody
from testbed.vehicle.arm_coupling import (
    Coupling,
    arm_static_reaction,
    measured_reaction,
    rotated,
    trim_float,
    trim_wrench,
)
from testbed.vehicle.body_state import BodyState, frozen
from testbed.vehicle.camera import CameraConfig, CameraPose
from testbed.vehicle.hull_body import hull_body, place_hull
from testbed.vehicle.hydrodynamics import HydroModel, coefficients
from testbed.vehicle.plant_kernels import (
    LOAD_CURRENT,
    LOAD_NU_DOT,
    LOAD_WRENCH,
    N_LOADS,
    pybullet_state,
    pybullet_wrench,
)
from testbed.vehicle.pool_scene import PoolScene, build_pool
from testbed.vehicle.scenery import Scenery
from testbed.vehicle.scenery_render import add_scenery_bodies, render_scenery
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

__all__ = ["Physics"]

FloatArray = NDArray[np.float64]
Vec3 = tuple[float, float, float]
Vec6 = tuple[float, float, float, float, float, float]
Quat = tuple[float, float, float, float]
_Raw = tuple[Vec3, tuple[float, float, float, float], tuple[Vec3, Vec3]]
"""pybullet's (position, orientation xyzw, (linear velocity, angular velocity)), world z-up."""
_ZERO3 = (0.0, 0.0, 0.0)
_VEC3 = jit.floats(3)


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

    Coupling: the arm's reaction on the hull, measured from the hull's motion, enters Fossen's
    equation one step late (:mod:`.arm_coupling`).

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
        self._coupling: list[Coupling | None] = [None]  # the last step's (v, ω, R, F, τ), world
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
            self._trim = trim_float(self._arm_static_reaction())

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
        body = hull_body(pybullet, cid, self.model, self._cog, self.arm_model)
        if self.pool is not None:
            build_pool(pybullet, cid, self.pool)
        return body

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
        position = position_ned if position_ned is not None else self._start_position
        euler = euler_rad if euler_rad is not None else self._start_euler
        velocity = nu if nu is not None else (0.0,) * 6
        place_hull(pybullet, self.client_id, self.body_id, self._cog, position, euler, velocity)
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
                position_ned=frozen(position),
                quaternion_wxyz=frozen(quat),
                euler_rad=frozen(euler_from_quat(quat)),
                nu=frozen(nu),
                nu_dot=frozen(self._loads[LOAD_NU_DOT : LOAD_NU_DOT + 6]),
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
        is unchanged); bodies already here (the hull, a pool's boxes) turn transparent
        (:func:`~.scenery_render.add_scenery_bodies`)."""
        self._check_open()
        add_scenery_bodies(pybullet, self.client_id, scenery)

    def render(
        self, pose: CameraPose, camera: CameraConfig
    ) -> tuple[NDArray[np.uint8], NDArray[np.float32]]:
        """Draw the scenery from a camera pose (NED) with pybullet's CPU renderer, TinyRenderer.

        Returns:
            ``(rgb, zbuffer)`` at ``camera.render_size_px``: (h, w, 3) uint8 colour, row 0 at the
            top; (h, w) OpenGL depth buffer in [0, 1], 1 where nothing was hit
            (:func:`~.scenery_render.render_scenery`).
        """
        self._check_open()
        return render_scenery(pybullet, self.client_id, pose, camera)

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
        (:mod:`.arm_coupling`)."""
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
        # Fossen equation, the trim float's wrench, and the links' loads (:mod:`.arm_coupling`).
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
                reaction = measured_reaction(last, linear, angular, rotation, m, inertia, dt)
            self.arm_reaction_frd = reaction
            held = loads[w : w + 6].tolist()
            load = [a + t for a, t in zip(held, trim_wrench(self._trim, rotation), strict=True)]
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
                rotated(rotation, force),
                rotated(rotation, torque),
            )

        return advance_arm

    def _arm_static_reaction(self) -> Vec6:
        """The resting arm's wrench on the hull in its present pose [N, N·m], body FRD about
        the CoG (:func:`~.arm_coupling.arm_static_reaction`)."""
        arm = self.arm
        assert arm is not None
        return arm_static_reaction(pybullet, self.client_id, self.body_id, arm)

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


def _disconnect(client_id: int) -> None:
    if pybullet.isConnected(client_id):
        pybullet.disconnect(client_id)
