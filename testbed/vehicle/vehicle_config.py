"""The vehicle's configuration: the scenario's ``[vehicle]`` table as a frozen
:class:`VehicleConfig` (model, thruster layout, rates, gains, sensors, current, failsafe, start
pose, camera, pool, navigation, autonomy, arm), checked when built (each bad value one line
naming its key), and the default gains. :class:`~testbed.vehicle.vehicle.Vehicle` assembles a
vehicle from one.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from testbed.config import (
    ConfigError,
    FieldError,
    build,
    check,
    check_range,
    check_ranges,
    load_toml,
)
from testbed.vehicle.arm_body import G_M_S2, RHO_KG_M3
from testbed.vehicle.autonomy import AutonomyConfig, resolve_mission
from testbed.vehicle.camera import CameraConfig
from testbed.vehicle.control import (
    FailsafeConfig,
    PidGains,
)
from testbed.vehicle.hydrodynamics import HydroModel, load_model
from testbed.vehicle.localization import (
    NavigationConfig,
)
from testbed.vehicle.manipulation import ArmConfig
from testbed.vehicle.mission import BODY_FRAMES, MAX_POSITION_M
from testbed.vehicle.nav_sensors import MotionCaptureConfig
from testbed.vehicle.pilot import PilotGains
from testbed.vehicle.pool_scene import PoolScene
from testbed.vehicle.sensors import (
    DepthSensorConfig,
    ImuConfig,
    PositionFixConfig,
)
from testbed.vehicle.t200 import SUPPLY_VOLTAGE_RANGE_V
from testbed.vehicle.thrusters import (
    SPIN_UP_TIME_CONSTANT_S,
    load_thruster_config,
)
from testbed.vehicle.water_current import WaterCurrent

__all__ = [
    "CONTROL_RATE_RANGE_HZ",
    "DEPTH_GAINS",
    "MAX_DEPTH_FEEDFORWARD_N",
    "PHYSICS_DT_RANGE_S",
    "PITCH_GAINS",
    "ROLL_GAINS",
    "YAW_GAINS",
    "ControlGains",
    "SensorsConfig",
    "VehicleConfig",
    "load_vehicle_config",
]


ROLL_GAINS = PidGains(kp=0.5, ki=0.25, kd=0.1, max_integral=10.0, max_output=5.0, i_zone=5.0)
"""Roll loop (deg → N·m), tuned for the simulated plant from mate-rov-2025's 0.15/0.01/0.05.

With mate-rov's gains the Wu model's weak righting moment (W·z_g = 2.26 N·m/rad) needs a
≈4° proportional error to hold 15° of roll; kp 0.5 N·m/deg puts the roll mode near
10 rad/s with kd 0.1 (ζ ≈ 1 on 0.28 kg·m² incl. added inertia) and ki 0.25 removes the
remaining offset within ~2 s. Doubling kp (1.0/0.5/0.15) oscillates: a gain margin of ≈2.
The integral clamp is 10 deg·s (mate-rov: 40 for roll, 60 for pitch, with ki 0.01 / 0.015:
integral torques of at most 0.4 / 0.9 N·m): with ki 0.25 it bounds the integral's torque at
2.5 N·m, near the hull's largest righting moment (W·z_g = 2.26 N·m, at 90°); mate-rov's clamps
with this ki would allow 10 / 15 N·m, past the 5-N·m output limit.
"""
PITCH_GAINS = PidGains(kp=0.5, ki=0.25, kd=0.1, max_integral=10.0, max_output=5.0, i_zone=5.0)
"""Pitch loop (deg → N·m), tuned as the roll loop (mate-rov-2025: 0.25/0.015/0.07; its
integral clamp 60, ours 10 as for roll)."""
YAW_GAINS = PidGains(kp=0.3, ki=0.01, kd=0.05, max_integral=10.0, max_output=5.0, i_zone=5.0)
"""mate-rov-2025 yaw loop (deg → N·m)."""
DEPTH_GAINS = PidGains(
    kp=100.0, ki=5.0, kd=40.0, max_integral=10.0, max_output=25.0, i_zone=0.25, derivative_tau_s=0.1
)
"""mate-rov-2025 depth loop (m → N) with kd raised from 1.5 to 40 N·s/m and filtered (0.1 s)."""


MAX_DEPTH_FEEDFORWARD_N = 1000.0
"""Largest accepted ``|depth_feedforward_n|`` [N]: beyond the heave force of any layout."""
CONTROL_RATE_RANGE_HZ = (1.0, 1000.0)
"""Accepted ECS frame rates [Hz] (mate-rov: 100); the physics step must not exceed the period."""
PHYSICS_DT_RANGE_S = (1e-4, 0.1)
"""Accepted physics steps [s] (default 1/240): below 0.1 ms a day-long run would take ≈ 10⁹
steps; above 0.1 s the explicit integration of a 0.02 s thruster lag is meaningless."""


def _default_gains() -> ControlGains:
    return ControlGains()


@dataclass(frozen=True, slots=True)
class ControlGains:
    """Closed-loop gains. Attitude loops take the error in degrees and output N·m; depth takes
    metres and outputs N (mate-rov's units, REFERENCE §3.6).

    Defaults: mate-rov-2025's table (REFERENCE §3.6) for yaw; roll and pitch retuned for the
    simulated plant's weak righting moment, and the depth derivative raised and filtered (the
    published kd 1.5 N·s/m leaves the ≈26 kg heave mode almost undamped). Each constant's
    docstring gives the reason. ``depth_feedforward_n`` [N, + down] is a constant heave force
    added to the depth loop's output, in [−1000, 1000] N.
    """

    roll: PidGains = ROLL_GAINS
    pitch: PidGains = PITCH_GAINS
    yaw: PidGains = YAW_GAINS
    depth: PidGains = DEPTH_GAINS
    depth_feedforward_n: float = 0.0

    def __post_init__(self) -> None:
        limit = MAX_DEPTH_FEEDFORWARD_N
        check_range(self.depth_feedforward_n, "depth_feedforward_n", -limit, limit, "N")


@dataclass(frozen=True, slots=True)
class SensorsConfig:
    """Sensor models; ``position`` None = no position fix."""

    imu: ImuConfig = field(default_factory=ImuConfig)
    depth: DepthSensorConfig = field(default_factory=DepthSensorConfig)
    position: PositionFixConfig | None = None


@dataclass(frozen=True, slots=True)
class VehicleConfig:
    """One simulated vehicle.

    Every number is checked at construction against its domain (below, and in the nested
    configs' docstrings); docs/vehicle.md lists them all.

    Attributes:
        model: hydrodynamic model name (``testbed/vehicle/data/models``).
        thrusters: thruster layout name (``testbed/vehicle/data/thrusters``).
        control_rate_hz: ECS frame rate [Hz] (mate-rov: 100), in [1, 1000].
        physics_dt_s: physics step [s], in [1e-4, 0.1] and ≤ the control period.
        allocation: ``"pinv"`` (the ECS paper's T⁺) or ``"lsq"`` (bounded least squares).
        current_limit_a: total current budget [A], in (0, 1e4]; None = the layout's budget.
        slew_limit_n_per_s: per-thruster force slew limit [N/s], in (0, 1e6]; None = the
            layout's.
        added_mass_coriolis: the model's added-mass Coriolis option, overriding its file's
            (``"full"``, ``"isotropic"`` or ``"off"``: see
            :attr:`~testbed.vehicle.hydrodynamics.HydroModel.added_mass_coriolis`); None keeps
            the model's own.
        supply_voltage_v: thruster supply voltage [V] for the T200 table, in [12, 20] (the
            published range the table is scaled over, :data:`SUPPLY_VOLTAGE_RANGE_V`);
            default 14.8 V, the nominal voltage of the BlueROV2's 4S lithium battery.
        thruster_time_constant_s: plant spin-up lag [s], in [0, 10].
        gains: closed-loop gains.
        pilot: stick shaping and gains.
        failsafe: stale-command failsafe.
        sensors: sensor models.
        current: water current.
        start_position_ned_m: (3,) initial body-origin position [m], NED, each in
            [−1e4, 1e4], the depth (down) ≥ 0: in the water.
        start_euler_rad: (3,) initial roll, pitch, yaw [rad], each in [−2π, 2π].
        camera: the forward camera (disabled by default); when enabled, the physics client
            also holds the pool's scenery (visual only) for it to see, and the pool is solid
            (:attr:`pool_in_use`).
        pool: a rectangular pool whose floor and walls the hull collides with (the origin at
            the centre of its surface); None = open water, or the default pool when the camera
            is on (the camera sees the pool, so the vehicle cannot pass through it).
        navigation: the localization (navigation sources and the filter,
            :mod:`testbed.vehicle.localization`); None = none. Its estimate is the vehicle's
            position reading; a ``sensors.position`` fix becomes one of its sources.
        autonomy: the mission tree and velocity controller (:mod:`testbed.vehicle.autonomy`);
            None = none (the operator flies it). Without ``navigation`` it gets the default
            one (:attr:`navigation_in_use`: the position fix if fitted, else motion capture).
        arm: a manipulator on the hull (:mod:`testbed.vehicle.manipulation`); None = none.
            Under autonomy its mission tree arms it and flies end-effector goals with TPIK,
            whose vehicle twist only the ISMC flies: an arm needs ``autonomy.controller =
            "ismc"`` (the PID path takes a position, not a body twist).
    """

    model: str = "bluerov2"
    thrusters: str = "bluerov2"
    control_rate_hz: float = 100.0
    physics_dt_s: float = 1.0 / 240.0
    allocation: Literal["pinv", "lsq"] = "pinv"
    current_limit_a: float | None = None
    slew_limit_n_per_s: float | None = None
    added_mass_coriolis: Literal["full", "isotropic", "off"] | None = None
    supply_voltage_v: float = 14.8
    thruster_time_constant_s: float = SPIN_UP_TIME_CONSTANT_S
    gains: ControlGains = field(default_factory=_default_gains)
    pilot: PilotGains = field(default_factory=PilotGains)
    failsafe: FailsafeConfig = field(default_factory=FailsafeConfig)
    sensors: SensorsConfig = field(default_factory=SensorsConfig)
    current: WaterCurrent = field(default_factory=WaterCurrent)
    start_position_ned_m: tuple[float, float, float] = (0.0, 0.0, 0.5)
    start_euler_rad: tuple[float, float, float] = (0.0, 0.0, 0.0)
    camera: CameraConfig = field(default_factory=CameraConfig)
    pool: PoolScene | None = None
    navigation: NavigationConfig | None = None
    autonomy: AutonomyConfig | None = None
    arm: ArmConfig | None = None

    def __post_init__(self) -> None:
        check_range(self.control_rate_hz, "control_rate_hz", *CONTROL_RATE_RANGE_HZ, "Hz")
        check_range(self.physics_dt_s, "physics_dt_s", *PHYSICS_DT_RANGE_S, "s")
        check(
            self.physics_dt_s <= 1.0 / self.control_rate_hz,
            "physics_dt_s",
            f"must not exceed the control period (1/control_rate_hz = "
            f"{1.0 / self.control_rate_hz:g} s), got {self.physics_dt_s:g}",
        )
        if self.current_limit_a is not None:
            check_range(self.current_limit_a, "current_limit_a", 0.0, 1.0e4, "A", low_open=True)
        if self.slew_limit_n_per_s is not None:
            check_range(
                self.slew_limit_n_per_s, "slew_limit_n_per_s", 0.0, 1.0e6, "N/s", low_open=True
            )
        check_range(self.supply_voltage_v, "supply_voltage_v", *SUPPLY_VOLTAGE_RANGE_V, "V")
        check_range(self.thruster_time_constant_s, "thruster_time_constant_s", 0.0, 10.0, "s")
        limit = MAX_POSITION_M
        check_ranges(self.start_position_ned_m, "start_position_ned_m", -limit, limit, "m")
        depth = self.start_position_ned_m[2]
        check(
            depth >= 0.0,
            "start_position_ned_m",
            f"the depth (down, the third) must be ≥ 0 m (in the water), got {depth}",
        )
        check_ranges(self.start_euler_rad, "start_euler_rad", -2 * math.pi, 2 * math.pi, "rad")
        self._check_arm_controller()
        self._check_arm_mission()
        self._check_dvl_bottom()
        self._check_arm_load()
        self._check_ismc_gains()
        self._check_layout_fits_hull()
        pool = self.pool_in_use
        if pool is not None:
            x, y, z = self.start_position_ned_m
            inside = abs(x) <= 0.5 * pool.length_m and abs(y) <= 0.5 * pool.width_m
            check(
                inside and z <= pool.depth_m,
                "start_position_ned_m",
                f"must be inside the pool (|north| ≤ {0.5 * pool.length_m:g} m, |east| ≤ "
                f"{0.5 * pool.width_m:g} m, depth ≤ {pool.depth_m:g} m), got "
                f"{list(self.start_position_ned_m)}",
            )

    def _check_arm_mission(self) -> None:
        """Refuse an end-effector mission (``child`` a tool frame) without an arm: its points
        are the tool's, and flying the hull to them is another experiment (it was flown so,
        without a word, as an operator's end-effector goal never was)."""
        autonomy = self.autonomy
        if self.arm is not None or autonomy is None or autonomy.mission is None:
            return
        mission = resolve_mission(autonomy.mission)
        check(
            not mission.end_effector,
            "autonomy.mission",
            f"{mission.source}: child {mission.child!r} is the arm's end effector, and the "
            "vehicle has no arm (vehicle.arm); for the hull's own waypoints use child "
            f"{BODY_FRAMES[0]!r}",
        )

    def _check_dvl_bottom(self) -> None:
        """Refuse a DVL's flat bottom at or above the vehicle's start: the vehicle would start
        in the seabed (the DVL then never locks, and the run said nothing)."""
        navigation = self.navigation
        if navigation is None or navigation.dvl is None:
            return
        bottom, depth = navigation.dvl.bottom_depth_m, self.start_position_ned_m[2]
        check(
            bottom > depth,
            "navigation.dvl.bottom_depth_m",
            f"the bottom ({bottom:g} m) must lie below the vehicle's start depth "
            f"(start_position_ned_m: {depth:g} m)",
        )

    def _check_arm_load(self) -> None:
        """Refuse an arm that weighs more in water than the whole vehicle weighs in air: no
        hull carries that (its trim float would outsize the vehicle; without one the thrusters
        hold nothing). A 400-kg link made a 3.9-kN float, silently, and the run "worked"."""
        if self.arm is None:
            return
        arm = self.arm.arm_model()
        links = (arm.base, *arm.links)
        wet_n = sum((link.mass_kg - RHO_KG_M3 * link.volume_m3) * G_M_S2 for link in links)
        weight_n = self.hydro_model().weight_n
        check(
            abs(wet_n) <= weight_n,
            "arm",
            f"the arm ({self.arm.model}) weighs {wet_n:.0f} N in water, more than the "
            f"vehicle ({self.model}, {weight_n:.1f} N) weighs in air: the hull cannot carry it",
        )

    def _check_layout_fits_hull(self) -> None:
        """Refuse a layout's centre of mass outside the hull box, and a thruster farther from
        the body origin than the hull's size along an axis (twice the hull box's half-extent:
        room for ducts outside it); a layout's thruster at 1e9 m ran quietly, its energy 0 Wh."""
        try:
            hull = self.hydro_model().hull_size_m
            layout = load_thruster_config(self.thrusters)
        except ConfigError:  # a file that does not load: the scenario loader names its key
            return
        com = layout.center_of_mass_m
        check(  # moments are taken about it: 2 m off, every thruster pushed from afar
            all(abs(c) <= size / 2.0 for c, size in zip(com, hull, strict=True)),
            "thrusters",
            f"the centre of mass of {self.thrusters}, {[round(c, 6) for c in com]} m in body FRD, "
            f"lies outside the hull of {self.model} (half-sizes "
            f"{[round(size / 2.0, 6) for size in hull]} m)",
        )
        for thruster in layout.thrusters:
            for i, (value, size) in enumerate(zip(thruster.position_m, hull, strict=True)):
                check(
                    abs(value) <= size,
                    "thrusters",
                    f"thruster {thruster.name!r} of {self.thrusters} is outside the hull of "
                    f"{self.model}: |position_m[{i}]| = {abs(value):g} m, at most hull_size_m"
                    f"[{i}] = {size:g} m",
                )

    def _check_ismc_gains(self) -> None:
        """Refuse, at load, an ISMC with no gains: a model with no packaged table (a model
        file of the user's own) needs all three in ``autonomy.ismc``."""
        if self.autonomy is not None and self.autonomy.controller == "ismc":
            try:
                self.autonomy.ismc.gains_for(self.hydro_model().name)
            except FieldError as err:
                raise FieldError(f"autonomy.{err.key}", err.message) from None

    def _check_arm_controller(self) -> None:
        """Refuse an arm under the PID controller: TPIK's output is a body twist [m/s, rad/s]
        that only the ISMC flies; the PID path's position loop would leave the hull with no
        horizontal control while the arm waits on it."""
        if self.arm is None or self.autonomy is None:
            return
        check(
            self.autonomy.controller == "ismc",
            "autonomy.controller",
            f"{self.autonomy.controller!r} cannot fly vehicle.arm's end-effector missions "
            '(TPIK\'s body twist needs "ismc"); use controller = "ismc" or drop vehicle.arm',
        )

    def hydro_model(self) -> HydroModel:
        """The vehicle's model file, loaded with :attr:`added_mass_coriolis` when set."""
        return load_model(self.model, added_mass_coriolis=self.added_mass_coriolis)

    @property
    def pool_in_use(self) -> PoolScene | None:
        """The solid pool the vehicle flies in: ``pool``; with the camera on and no ``pool``,
        the default one (the scenery the camera renders); else None (open water)."""
        if self.pool is None and self.camera.enabled:
            return PoolScene()
        return self.pool

    @property
    def navigation_in_use(self) -> NavigationConfig | None:
        """The navigation the vehicle runs: ``navigation``; under autonomy without one, the
        default (the position fix alone when fitted, else default motion capture)."""
        if self.navigation is not None or self.autonomy is None:
            return self.navigation
        if self.sensors.position is not None:
            return NavigationConfig()
        return NavigationConfig(motion_capture=MotionCaptureConfig())


def load_vehicle_config(
    source: str | Path | Mapping[str, Any], *, name: str = "<vehicle>"
) -> VehicleConfig:
    """Build a :class:`VehicleConfig` from a TOML file or an already-loaded mapping.

    Raises:
        ConfigError: missing file, unknown key or bad value (message names file and key).
    """
    if isinstance(source, str | Path):
        return build(VehicleConfig, load_toml(source), source=str(source))
    return build(VehicleConfig, source, source=name)
