"""The assembled vehicle: an ECS world and schedule driving allocation, thrusters and physics.

:class:`Vehicle` owns a :class:`~testbed.ecs.World` and the frame :class:`~testbed.ecs.Schedule`
of :mod:`testbed.vehicle.systems`, the pybullet :class:`~testbed.vehicle.physics.Physics`, the
:class:`~testbed.vehicle.allocation.Allocator`, the plant-side
:class:`~testbed.vehicle.thrusters.ThrusterDynamics`, the sensors and the RNGs they draw from.
It is configured by a frozen :class:`~testbed.vehicle.vehicle_config.VehicleConfig` (the
scenario's ``[vehicle]`` table, :mod:`testbed.vehicle.vehicle_config`); building and wiring
those parts from it, in the order that fixes the random streams and entity ids, is
:func:`~testbed.vehicle.assembly.assemble_vehicle`'s. This module runs them: time, the
camera, operator intents written locally, thruster faults.

Timing. :meth:`Vehicle.advance` steps the physics at ``physics_dt_s`` (1/240 s) and runs one
ECS frame at ``control_rate_hz`` (100 Hz). 240 and 100 do not divide, so a frame runs at the
first physics instant at or after each control instant ``k/100`` s: frames land 2 or 3
physics steps apart (8.3 or 12.5 ms), 100 per simulated second on average, and every frame
is given the true time since the previous one (``SimClock.dt_s``). The thruster commands are
held between frames, so the thruster plant's lag is stepped once per frame, exactly, over the
interval to the next frame, and the physics applies ``T @`` the interval's mean actual forces
(the exact impulse of the lagged, failed or saturated thrusters; not the allocator's request)
at each of its steps in that interval (see :func:`~testbed.vehicle.systems.actuate_thrusters`).

Thruster faults at run time (:meth:`Vehicle.fail_thruster`) go to both the plant (which
produces the faulty force) and, unless ``inform_allocator=False``, the allocator (which drops
the thruster from ``T`` and re-probes the axis maxima), as a vehicle whose health monitoring
detected the fault would.

The operator's intents normally arrive by replication; :meth:`Vehicle.command`,
:meth:`Vehicle.arm` and friends write them directly (as a peer would) for scripted runs.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from testbed.common.geometry import Quaternion, quat_rotate
from testbed.ecs import Origin, System
from testbed.vehicle.assembly import assemble_vehicle
from testbed.vehicle.body_state import BodyState
from testbed.vehicle.camera import CapturedImage, camera_pose, underwater_grey
from testbed.vehicle.components import (
    ArmRequest,
    AttitudeSetpoint,
    ControlMode,
    DepthSetpoint,
    ModeRequest,
    MovementCommand,
)
from testbed.vehicle.systems import shaped_sticks, wrench_of
from testbed.vehicle.thrusters import FaultMode
from testbed.vehicle.vehicle_config import VehicleConfig

__all__ = ["Vehicle"]


class Vehicle:
    """A simulated ROV: ECS control stack, thruster plant and pybullet physics.

    Args:
        config: the vehicle's configuration.
        rng: the generator this vehicle draws all its randomness from (sensors, current);
            child generators are spawned from it, so a seed gives identical runs.
        inbound: link systems to run first in each frame's PRE_UPDATE.
        outbound: link or recording systems to run last in each frame's POST_UPDATE.

    Use as a context manager or call :meth:`close` (pybullet client).
    """

    def __init__(
        self,
        config: VehicleConfig,
        rng: np.random.Generator,
        *,
        inbound: Sequence[System] = (),
        outbound: Sequence[System] = (),
    ) -> None:
        self.config = config
        parts = assemble_vehicle(config, rng, inbound=inbound, outbound=outbound)
        self.thruster_config = parts.thruster_config
        self.thruster_names = parts.thruster_names
        self.t200 = parts.t200
        self.allocator = parts.allocator
        self.dynamics = parts.dynamics
        self.model = parts.model
        self.physics = parts.physics
        self.sensors = parts.sensors
        self.world = parts.world
        self.store = parts.store
        self.schedule = parts.schedule
        self.entity = parts.entity
        self.controllers = parts.controllers
        self.actuation = parts.actuation
        self.clock = parts.clock
        self.truth = parts.truth
        self.power = parts.power
        self.operator_entity = parts.operator_entity
        self.manipulator = parts.manipulator
        self._camera_rng = parts.camera_rng
        self._last_capture_s: float | None = None
        self._seq = 0
        self._arm_seq = 0
        self._control_period_s = 1.0 / config.control_rate_hz
        self._next_control_s = 0.0
        self._last_frame_s: float | None = None
        self._accelerometer = parts.accelerometer
        self._last_velocity_ned: tuple[float, float, float] | None = None
        self.frames = 0

    # ------------------------------------------------------------------------- running

    @property
    def time_s(self) -> float:
        """Simulated time [s]."""
        return self.physics.time_s

    def advance(self, until_s: float) -> None:
        """Step physics (and frames, at the control rate) until time ``until_s`` is reached.

        Stops at the first physics instant ≥ ``until_s`` (within 1 ns), so successive calls
        compose. See the module docstring for the frame timing.
        """
        physics = self.physics
        limit = until_s - 1e-9
        now = physics.time_s
        while now < limit:
            if now >= self._next_control_s - 1e-9:
                self._frame()
            # to the next frame (or the limit) with the actuation's wrench, Physics.held_wrench
            now = physics.step_until(min(limit, self._next_control_s - 1e-9))

    def _frame(self) -> None:
        physics = self.physics
        now, position, quaternion, nu = physics.state_floats()
        truth = self.truth
        truth.quaternion_wxyz = quaternion
        truth.rates_rad_s = (nu[3], nu[4], nu[5])
        truth.position_ned_m = position
        truth.velocity_m_s = (nu[0], nu[1], nu[2])
        if self._accelerometer:  # the NED velocity's change since the last frame
            v_ned = quat_rotate(quaternion, truth.velocity_m_s)
            last = self._last_velocity_ned
            if last is not None and self._last_frame_s is not None and now > self._last_frame_s:
                h = now - self._last_frame_s
                truth.acceleration_ned_m_s2 = (
                    (v_ned[0] - last[0]) / h,
                    (v_ned[1] - last[1]) / h,
                    (v_ned[2] - last[2]) / h,
                )
            self._last_velocity_ned = v_ned
        period = self._control_period_s
        clock = self.clock
        clock.time_s = now
        clock.dt_s = period if self._last_frame_s is None else now - self._last_frame_s
        self._last_frame_s = now
        # the next frame runs at the first physics instant at or after the next control time
        self._next_control_s += period
        if self._next_control_s <= now:  # never owe a burst of frames
            self._next_control_s = now + period
        dt = physics.dt_s
        steps = max(1, math.ceil((self._next_control_s - now) / dt - 1e-6))
        self.actuation.interval_s = steps * dt
        arm = self.manipulator
        if arm is not None:  # the joints' encoders
            arm.q_rad, arm.rates_rad_s = physics.arm_state()
        self.schedule.run(self.world)
        if arm is not None and arm.command_rad_s != physics.arm_commanded_rates:
            physics.command_arm(arm.command_rad_s)
        self.frames += 1

    @property
    def next_frame_s(self) -> float:
        """Time of the next ECS frame [s]: the first physics instant at or after the next
        control instant (a node that waits until then and calls :meth:`advance` just past it
        runs that frame with everything that arrived by then)."""
        physics = self.physics
        now = physics.time_s
        steps = max(0, math.ceil((self._next_control_s - 1e-9 - now) / physics.dt_s - 1e-6))
        return now + steps * physics.dt_s

    def reference_velocity(self, sticks: Sequence[float]) -> tuple[float, float, float, float]:
        """The velocity the pilot interface asks for with these sticks, in the active mode.

        Surge and sway (and heave, yaw outside the hold modes) are force commands: the
        reference is the steady speed at which the model's linear + quadratic damping balances
        that force, ``|d_q|·v² + |d_l|·v = F``. In depth hold the heave stick moves the depth
        target at ``shape(z)·depth_trim`` m/s; with attitude hold the yaw stick turns the
        heading target at ``shape(yaw)·yaw_trim`` rad/s — those rates are the references.

        Args:
            sticks: (6,) stick positions in [−1, 1] (surge, sway, heave, roll, pitch, yaw).

        Returns:
            (u [m/s], v [m/s], w [m/s], r [rad/s]) references, body FRD.
        """
        ctl = self.controllers
        flags = ctl.flags
        held = sticks if type(sticks) is tuple else tuple(sticks)
        wrench, (depth_rate, _, _, yaw_rate) = shaped_sticks(ctl, held)
        model = self.model

        def steady(axis: int, force: float) -> float:
            linear = abs(model.linear_damping[axis])
            quadratic = abs(model.quadratic_damping[axis])
            magnitude = abs(force)
            if quadratic > 0.0:
                speed = (math.sqrt(linear * linear + 4.0 * quadratic * magnitude) - linear) / (
                    2.0 * quadratic
                )
            else:
                speed = magnitude / linear if linear > 0.0 else 0.0
            return math.copysign(speed, force)

        u = steady(0, wrench[0])
        v = steady(1, wrench[1])
        w = depth_rate if flags.depth_hold else steady(2, wrench[2])
        r = yaw_rate if flags.attitude_hold else steady(5, wrench[5])
        return (u, v, w, r)

    def capture_image(self) -> CapturedImage | None:
        """Render the forward camera at the plant's true pose now.

        Refused (None, nothing rendered) when called less than ``1/camera.max_rate_hz`` after
        the last capture: the caller asks again later (:attr:`next_capture_s`); a stale image is
        never handed out as a new one.

        Raises:
            RuntimeError: the camera is disabled.
        """
        camera = self.config.camera
        if not camera.enabled:
            raise RuntimeError("the camera is disabled (vehicle.camera.enabled = false)")
        now, position, quaternion, _ = self.physics.state_floats()
        if now < self.next_capture_s - 1e-9:
            return None
        self._last_capture_s = now
        pose = camera_pose(position, quaternion, camera)
        rgb, zbuffer = self.physics.render(pose, camera)
        pixels = underwater_grey(rgb, zbuffer, camera, self._camera_rng)
        pixels.setflags(write=False)
        return CapturedImage(now, pixels, pose, position, quaternion)

    @property
    def next_capture_s(self) -> float:
        """Earliest time of the next capture [s] (the camera's ``max_rate_hz``)."""
        last = self._last_capture_s
        return 0.0 if last is None else last + self.config.camera.min_interval_s

    def state(self) -> BodyState:
        """The physics truth now (for metrics and tests; the controllers never see it)."""
        return self.physics.state()

    def close(self) -> None:
        """Release the physics client."""
        self.physics.close()

    def __enter__(self) -> Vehicle:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    # ------------------------------------------------------------------ operator intents

    def command(self, sticks: Sequence[float], *, sampled_s: float | None = None) -> int:
        """Send stick positions (6,) in [−1, 1] as the operator would; returns the seq used."""
        if len(sticks) != 6:
            raise ValueError(f"sticks must have 6 values, got {len(sticks)}")
        self._seq += 1
        s0, s1, s2, s3, s4, s5 = sticks
        values = (float(s0), float(s1), float(s2), float(s3), float(s4), float(s5))
        sampled = self.time_s if sampled_s is None else sampled_s
        self._write(MovementCommand(self._seq, sampled, values))
        return self._seq

    def arm(self, armed: bool = True) -> None:
        """Request arming (or disarming)."""
        self._arm_seq += 1
        self._write(ArmRequest(armed, self._arm_seq))

    def disarm(self) -> None:
        """Request disarming."""
        self.arm(False)

    def set_mode(self, mode: ControlMode, *, precision: bool = False) -> None:
        """Request a control mode."""
        self._write(ModeRequest(mode, precision))

    def set_depth(self, depth_m: float) -> None:
        """Set the depth target [m, positive down]."""
        self._write(DepthSetpoint(float(depth_m)))

    def set_attitude(self, quaternion_wxyz: Quaternion) -> None:
        """Set the attitude target (body → NED, w x y z)."""
        w, x, y, z = quaternion_wxyz
        self._write(AttitudeSetpoint((float(w), float(x), float(y), float(z))))

    def _write(self, component: object) -> None:
        self.world.set(self.operator_entity, component, origin=Origin.REMOTE)

    # ------------------------------------------------------------------------ faults

    def thruster_index(self, thruster: int | str) -> int:
        """Index of a thruster given by index or name.

        Raises:
            KeyError: unknown name. IndexError: index out of range.
        """
        if isinstance(thruster, str):
            try:
                return self.thruster_names.index(thruster)
            except ValueError:
                known = ", ".join(self.thruster_names)
                raise KeyError(f"unknown thruster {thruster!r} (known: {known})") from None
        if not 0 <= thruster < len(self.thruster_names):
            raise IndexError(f"thruster index {thruster} out of range")
        return thruster

    def fail_thruster(
        self,
        thruster: int | str,
        mode: FaultMode,
        value: float | None = None,
        *,
        inform_allocator: bool = True,
    ) -> None:
        """Fail a thruster in the plant and (by default) tell the allocator.

        Args:
            thruster: index or name.
            mode: ``"dead"``, ``"stuck"`` (held force [N], default its force now) or
                ``"degraded"`` (factor in [0, 1]).
            value: the stuck force or degraded factor.
            inform_allocator: also update the allocator (removes dead/stuck thrusters from
                ``T``, scales degraded ones) and the axis maxima the pilot scales by.
        """
        index = self.thruster_index(thruster)
        self.dynamics.set_fault(index, mode, value)
        self._refresh_plant()
        if inform_allocator:
            fault = self.dynamics.faults[index]
            self.allocator.set_failure(index, mode, fault.value)
            self._refresh_maxima()

    def clear_thruster_fault(self, thruster: int | str | None = None) -> None:
        """Repair one thruster (or all) in the plant and the allocator."""
        indices = (
            range(len(self.thruster_names)) if thruster is None else [self.thruster_index(thruster)]
        )
        for index in indices:
            self.dynamics.clear_fault(index)
            self.allocator.clear_failure(index)
        self._refresh_plant()
        self._refresh_maxima()

    def _refresh_plant(self) -> None:
        # a fault between frames takes effect at once: the rest of the interval applies the
        # plant's forces as they now are (a dead or stuck thruster changes instantly)
        act = self.actuation
        act.plant_wrench[:] = wrench_of(act.actual_forces_n, act.matrix)

    def _refresh_maxima(self) -> None:
        self.controllers.axis_maxima = tuple(float(v) for v in self.allocator.axis_maxima())
