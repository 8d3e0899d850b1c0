"""testbed.vehicle.vehicle / systems / components: the assembled ECS vehicle in closed loop."""

from __future__ import annotations

import math

import numpy as np
import pytest

from testbed.common.geometry import quat_from_euler, quat_rotate
from testbed.config import ConfigError
from testbed.ecs import ComponentRegistry, Side, World, replicated_changes
from testbed.vehicle.components import (
    REPLICATED,
    ActiveMode,
    AppliedWrench,
    Armed,
    AttitudeSetpoint,
    CommandStatus,
    ControlMode,
    ControlTargets,
    FailsafeLevel,
    FailsafeStatus,
    MovementCommand,
    ThrusterOutput,
    register_components,
)
from testbed.vehicle.control import FailsafeConfig
from testbed.vehicle.hydrodynamics import load_model
from testbed.vehicle.pilot import SURFACE_HOLD_DEPTH_M
from testbed.vehicle.resources import SimClock
from testbed.vehicle.sensors import DepthSensorConfig, ImuConfig
from testbed.vehicle.vehicle import Vehicle
from testbed.vehicle.vehicle_config import SensorsConfig, VehicleConfig, load_vehicle_config

QUIET = SensorsConfig(
    imu=ImuConfig(attitude_noise_rad=0.0, heading_noise_rad=0.0, gyro_noise_rad_s=0.0),
    depth=DepthSensorConfig(noise_pa=0.0),
)


def make(seed: int = 1, **overrides: object) -> Vehicle:
    config = VehicleConfig(**overrides)  # type: ignore[arg-type]
    return Vehicle(config, np.random.default_rng(seed))


def hold(vehicle: Vehicle, depth_m: float, yaw_rad: float = 0.0) -> None:
    vehicle.arm()
    vehicle.set_mode(ControlMode.DEPTH_HOLD)
    vehicle.set_depth(depth_m)
    vehicle.set_attitude(quat_from_euler(0.0, 0.0, yaw_rad))


def run_with_sticks(vehicle: Vehicle, until_s: float, sticks: tuple[float, ...]) -> None:
    """Keep the operator link alive (a command every 0.1 s) until ``until_s``."""
    while vehicle.time_s < until_s - 1e-9:
        vehicle.command(sticks)
        vehicle.advance(min(until_s, vehicle.time_s + 0.1))


def get(vehicle: Vehicle, cls: type) -> object:
    return vehicle.world.get(vehicle.entity, cls)


# ------------------------------------------------------------------------------- timing


def test_frames_run_at_the_control_rate_across_physics_steps() -> None:
    with make() as v:
        frame_steps = []
        last = None
        for step in range(240):
            v.advance(v.time_s + v.physics.dt_s)
            clock = v.world.resource(SimClock)
            if clock.time_s != last:
                frame_steps.append(step)  # the frame ran at the start of this step
                last = clock.time_s
                assert clock.time_s == pytest.approx(step / 240.0)
        assert v.time_s == pytest.approx(1.0)
        assert v.frames == 100
        # a frame at the first physics instant at or after each k/100 s
        assert frame_steps == [math.ceil(k * 2.4 - 1e-9) for k in range(100)]
        assert set(np.diff(frame_steps)) == {2, 3}


def test_same_seed_same_run_and_different_seed_differs() -> None:
    finals = []
    for seed in (5, 5, 6):
        with make(seed) as v:
            hold(v, 0.8, 0.3)
            run_with_sticks(v, 3.0, (0.2, 0.0, 0.0, 0.0, 0.0, 0.1))
            finals.append(v.state().position_ned.tolist() + v.state().quaternion_wxyz.tolist())
    assert finals[0] == finals[1]
    assert finals[0] != finals[2]


# ------------------------------------------------------------------------- arming


def test_disarmed_outputs_neutral_and_vehicle_floats_up() -> None:
    with make(start_position_ned_m=(0.0, 0.0, 2.0)) as v:
        v.set_mode(ControlMode.DEPTH_HOLD)
        v.set_depth(2.0)
        run_with_sticks(v, 3.0, (1.0, 0.0, 0.0, 0.0, 0.0, 1.0))
        out = get(v, ThrusterOutput)
        assert isinstance(out, ThrusterOutput)
        assert set(out.forces_n) == {0.0} and set(out.pwm_us) == {1500.0}
        assert get(v, AppliedWrench) == AppliedWrench((0.0,) * 6, (0.0,) * 6)
        # +2 N net buoyancy (Wu 2018): the unpowered vehicle rises
        assert v.state().position_ned[2] < 2.0 - 0.05
        assert abs(v.state().position_ned[0]) < 1e-3


def test_disarm_zeroes_outputs_and_resets_controllers() -> None:
    with make() as v:
        hold(v, 1.0)
        run_with_sticks(v, 2.0, (0.0,) * 6)
        assert any(abs(f) > 0.5 for f in get(v, ThrusterOutput).forces_n)  # type: ignore[union-attr]
        assert v.controllers.depth.pid.integral != 0.0
        v.disarm()
        run_with_sticks(v, 2.1, (0.0,) * 6)
        assert set(get(v, ThrusterOutput).forces_n) == {0.0}  # type: ignore[union-attr]
        assert v.controllers.depth.pid.integral == 0.0
        assert all(pid.integral == 0.0 for pid in v.controllers.attitude.pids)


# --------------------------------------------------------------------------- closed loop


def test_depth_hold_reaches_and_holds_the_target() -> None:
    with make(start_position_ned_m=(0.0, 0.0, 0.5), sensors=QUIET) as v:
        hold(v, 1.2)
        run_with_sticks(v, 20.0, (0.0,) * 6)
        depths = []
        while v.time_s < 25.0:
            run_with_sticks(v, v.time_s + 0.1, (0.0,) * 6)
            depths.append(v.state().position_ned[2])
        # the sensor converts with ArduSub's 9800 Pa/m; the water has ρg = 9806.65 Pa/m
        expected = 1.2 * 9800.0 / 9806.65
        assert np.mean(depths) == pytest.approx(expected, abs=0.01)
        assert np.ptp(depths) < 0.02


def test_controllers_see_the_sensor_not_the_truth() -> None:
    # sea water read with the fresh-water setting: the vehicle holds its *measured* depth,
    # so it sits 2.5 % shallower than the target, as a real one would
    sensors = SensorsConfig(
        imu=QUIET.imu, depth=DepthSensorConfig(noise_pa=0.0, water_density_kg_m3=1025.0)
    )
    with make(start_position_ned_m=(0.0, 0.0, 2.0), sensors=sensors) as v:
        hold(v, 2.0)
        run_with_sticks(v, 25.0, (0.0,) * 6)
        expected = 2.0 * 9800.0 / (1025.0 * 9.80665)
        assert v.state().position_ned[2] == pytest.approx(expected, abs=0.01)
        assert abs(expected - 2.0) > 0.04


def test_heading_step_settles() -> None:
    with make(thrusters="bluerov2", sensors=QUIET) as v:
        hold(v, 0.5, math.radians(45.0))
        run_with_sticks(v, 8.0, (0.0,) * 6)
        yaw = math.degrees(v.state().euler_rad[2])
        assert yaw == pytest.approx(45.0, abs=0.5)


def test_surge_stick_reaches_the_drag_limited_speed() -> None:
    # half surge stick in depth hold: a level-frame force 0.5³·0.8·X_max; at steady state the
    # body-x balance is the model's damping d_l u + d_q u|u| = τ_x − (W − B) sin θ (Fossen's
    # restoring term); the horizontal thrust line passes through CO, where the drag acts
    # (data/thrusters/bluerov2.toml), so thrust and drag form no couple: the vehicle stays
    # level
    model = load_model("bluerov2")
    with make(sensors=QUIET, start_position_ned_m=(0.0, 0.0, 1.0)) as v:
        hold(v, 1.0)
        run_with_sticks(v, 15.0, (0.5, 0.0, 0.0, 0.0, 0.0, 0.0))
        state = v.state()
        achieved = get(v, AppliedWrench).achieved  # type: ignore[union-attr]
        world_force = quat_rotate(tuple(state.quaternion_wxyz), achieved[:3])
        assert math.hypot(world_force[0], world_force[1]) == pytest.approx(
            0.125 * 0.8 * v.controllers.axis_maxima[0], rel=0.03
        )
        pitch = state.euler_rad[1]
        assert abs(math.degrees(pitch)) < 1.0
        drive = achieved[0] - (model.weight_n - model.buoyancy_n) * math.sin(pitch)
        a, b = -model.quadratic_damping[0], -model.linear_damping[0]
        expected = (-b + math.sqrt(b * b + 4 * a * drive)) / (2 * a)
        assert state.nu[0] == pytest.approx(expected, rel=0.03)
        assert state.nu[0] > 0.3


def test_stabilize_yaw_stick_trims_the_heading_target() -> None:
    with make(sensors=QUIET) as v:
        v.arm()
        v.set_mode(ControlMode.STABILIZE)
        run_with_sticks(v, 1.0, (0.0,) * 6)
        start = math.degrees(v.state().euler_rad[2])
        run_with_sticks(v, 3.0, (0.0, 0.0, 0.0, 0.0, 0.0, 0.5))  # 0.5³ · 100°/s for 2 s = 25°
        target = get(v, ControlTargets).quaternion_wxyz  # type: ignore[union-attr]
        w, x, y, z = target
        target_yaw = math.degrees(math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z)))
        assert target_yaw - start == pytest.approx(25.0, abs=1.0)
        run_with_sticks(v, 6.0, (0.0,) * 6)
        assert math.degrees(v.state().euler_rad[2]) == pytest.approx(target_yaw, abs=1.0)


def test_depth_hold_heave_stick_trims_the_depth_target() -> None:
    with make(sensors=QUIET, start_position_ned_m=(0.0, 0.0, 1.0)) as v:
        hold(v, 1.0)
        run_with_sticks(v, 1.0, (0.0,) * 6)
        run_with_sticks(v, 3.0, (0.0, 0.0, 1.0, 0.0, 0.0, 0.0))  # 0.3 m/s down for 2 s
        targets = get(v, ControlTargets)
        assert targets.depth_m == pytest.approx(1.6, abs=0.01)  # type: ignore[union-attr]
        v.set_mode(ControlMode.DEPTH_HOLD, precision=True)  # same mode: target kept
        run_with_sticks(v, 4.0, (0.0, 0.0, -1.0, 0.0, 0.0, 0.0))  # 0.2 m/s up for 1 s
        assert get(v, ControlTargets).depth_m == pytest.approx(1.4, abs=0.01)  # type: ignore[union-attr]


# ---------------------------------------------------------------------------- commands


def test_stale_or_reordered_commands_are_ignored() -> None:
    with make() as v:
        v.arm()
        v.command((0.5, 0, 0, 0, 0, 0))
        v.advance(0.05)
        status = get(v, CommandStatus)
        assert isinstance(status, CommandStatus) and status.seq == 1
        v.world.set(
            v.operator_entity,
            MovementCommand(0, 0.0, (-1.0, 0, 0, 0, 0, 0)),  # older seq
        )
        v.advance(0.1)
        assert get(v, CommandStatus) == status
        assert v.controllers.sticks == (0.5, 0, 0, 0, 0, 0)
        seq = v.command((0.1, 0, 0, 0, 0, 0), sampled_s=v.time_s - 0.25)
        v.advance(0.15)
        status = get(v, CommandStatus)
        assert status.seq == seq  # type: ignore[union-attr]
        assert status.latency_s == pytest.approx(0.25, abs=0.011)  # type: ignore[union-attr]


def test_a_zero_attitude_setpoint_from_the_link_is_counted_and_ignored() -> None:
    """A peer's attitude setpoint of zero norm (well-formed bytes, no attitude) leaves the
    targets as they were and the vehicle flying; it is counted, and the next valid one holds."""
    with make() as v:
        hold(v, 0.5, yaw_rad=0.3)
        v.advance(0.5)
        before = get(v, ControlTargets)
        v.world.set(v.operator_entity, AttitudeSetpoint((0.0, 0.0, 0.0, 0.0)))
        v.advance(1.0)
        assert v.controllers.ignored_setpoints == 1
        assert get(v, ControlTargets) == before
        assert get(v, Armed) == Armed(True)
        v.set_attitude(quat_from_euler(0.0, 0.0, -0.2))
        v.advance(1.5)
        targets = get(v, ControlTargets)
        assert isinstance(targets, ControlTargets)
        assert targets.quaternion_wxyz == pytest.approx(quat_from_euler(0.0, 0.0, -0.2))
        assert v.controllers.ignored_setpoints == 1


def test_failsafe_holds_then_surfaces_and_disarms() -> None:
    failsafe = FailsafeConfig(hold_after_s=1.0, surface_after_s=4.0, ascent_rate_m_s=0.3)
    with make(sensors=QUIET, failsafe=failsafe, start_position_ned_m=(0.0, 0.0, 1.5)) as v:
        hold(v, 1.5)
        run_with_sticks(v, 10.0, (0.5, 0.0, 0.0, 0.0, 0.0, 0.0))  # cruising forward
        last_command_s = v.time_s - 0.1
        v.advance(last_command_s + 0.9)
        assert get(v, FailsafeStatus).level is FailsafeLevel.NOMINAL  # type: ignore[union-attr]
        v.advance(last_command_s + 1.1)
        assert get(v, FailsafeStatus).level is FailsafeLevel.HOLD  # type: ignore[union-attr]
        v.advance(last_command_s + 3.9)
        assert abs(v.state().nu[0]) < 0.15  # sticks ignored: stopped
        depth_held = v.state().position_ned[2]
        assert depth_held == pytest.approx(1.5 * 9800 / 9806.65, abs=0.05)
        v.advance(last_command_s + 4.1)
        assert get(v, FailsafeStatus).level is FailsafeLevel.SURFACE  # type: ignore[union-attr]
        while get(v, Armed) == Armed(True) and v.time_s < last_command_s + 12.0:
            v.advance(v.time_s + 0.05)
            assert v.state().position_ned[2] < depth_held + 0.05  # rising, never sinking
        # disarmed once the sensor read the surfacing depth (its reading lags ≤ one frame)
        assert get(v, Armed) == Armed(False)
        assert v.state().position_ned[2] < failsafe.surfaced_depth_m + 0.03
        v.advance(v.time_s + 0.01)  # the failsafe ends at the frame after the disarm
        assert get(v, FailsafeStatus).level is FailsafeLevel.NOMINAL  # type: ignore[union-attr]
        ascent_s = v.time_s - (last_command_s + 4.0)
        assert ascent_s == pytest.approx((depth_held - failsafe.surfaced_depth_m) / 0.3, abs=1.0)


def test_failsafe_hold_clears_when_commands_resume() -> None:
    with make(failsafe=FailsafeConfig(hold_after_s=0.5, surface_after_s=5.0)) as v:
        hold(v, 0.5)
        v.advance(1.0)
        assert get(v, FailsafeStatus).level is FailsafeLevel.HOLD  # type: ignore[union-attr]
        run_with_sticks(v, 1.5, (0.0,) * 6)
        assert get(v, FailsafeStatus).level is FailsafeLevel.NOMINAL  # type: ignore[union-attr]
        assert get(v, ActiveMode) == ActiveMode(ControlMode.DEPTH_HOLD)


# ------------------------------------------------------------------------------ faults


def test_stuck_thruster_pushes_even_when_disarmed() -> None:
    with make(sensors=QUIET) as v:
        v.fail_thruster("VerticalLeft", "stuck", 10.0)
        v.advance(0.5)
        column = v.thruster_config.matrix[:, v.thruster_index("VerticalLeft")]
        np.testing.assert_allclose(get(v, AppliedWrench).achieved, 10.0 * column, atol=1e-9)  # type: ignore[union-attr]
        assert set(get(v, ThrusterOutput).forces_n) == {0.0}  # type: ignore[union-attr]
        assert v.state().nu[5] != 0.0 or v.state().nu[3] != 0.0  # it rolls


def test_achieved_wrench_comes_from_the_actual_forces() -> None:
    # a dead thruster the allocator does not know about: the request is not what is achieved
    with make(sensors=QUIET, thrusters="ecs-4h") as v:
        hold(v, 0.5, math.radians(30))
        v.fail_thruster("LateralFrontLeft", "dead", inform_allocator=False)
        run_with_sticks(v, 0.5, (0.0,) * 6)
        applied = get(v, AppliedWrench)
        assert isinstance(applied, AppliedWrench)
        forces = v.actuation.actual_forces_n
        assert forces[v.thruster_index("LateralFrontLeft")] == 0.0
        assert abs(applied.achieved[5] - applied.requested[5]) > 0.05


def test_known_dead_thruster_keeps_yaw_control() -> None:
    with make(sensors=QUIET, thrusters="ecs-4h") as v:
        full = v.controllers.axis_maxima
        v.fail_thruster("LateralBackLeft", "dead")
        assert v.controllers.axis_maxima != full
        assert v.controllers.axis_maxima[5] > 0.0
        hold(v, 0.5, math.radians(-40))
        run_with_sticks(v, 10.0, (0.0,) * 6)
        assert math.degrees(v.state().euler_rad[2]) == pytest.approx(-40.0, abs=1.0)
        v.clear_thruster_fault()
        assert v.controllers.axis_maxima == full


def test_unknown_thruster_name_raises() -> None:
    with make() as v, pytest.raises(KeyError, match="known"):
        v.fail_thruster("Nope", "dead")


# -------------------------------------------------------------------- config, registry


def test_vehicle_config_from_mapping_checks_keys() -> None:
    cfg = load_vehicle_config(
        {
            "thrusters": "ecs-6dof",
            "gains": {"yaw": {"kp": 0.5}},
            "current": {"velocity_ned_mps": [0.1, 0, 0]},
        }
    )
    assert cfg.gains.yaw.kp == 0.5 and cfg.thrusters == "ecs-6dof"
    assert cfg.current.velocity_ned_mps == (0.1, 0.0, 0.0)
    with pytest.raises(ConfigError, match=r"gains\.yaw\.kq"):
        load_vehicle_config({"gains": {"yaw": {"kq": 1.0}}})
    with pytest.raises(ConfigError, match="physics_dt_s"):
        load_vehicle_config({"physics_dt_s": 0.1})


def test_replicated_components_register_with_owners() -> None:
    registry = ComponentRegistry()
    register_components(registry)
    assert len(registry) == len(REPLICATED)
    assert registry.owner_of(MovementCommand) is Side.OPERATOR
    assert registry.owner_of(ThrusterOutput) is Side.VEHICLE
    assert len({type_id for _, type_id, _ in REPLICATED}) == len(REPLICATED)


def test_vehicle_world_replicates_state_not_intents() -> None:
    registry = ComponentRegistry()
    register_components(registry)
    with make() as v:
        hold(v, 0.5)
        v.advance(0.2)
        world: World = v.world
        changes = replicated_changes(world, 0, registry, side=Side.VEHICLE)
        sent = {c.component for c in changes}
        assert {Armed, ActiveMode, ControlTargets, ThrusterOutput} <= sent
        assert MovementCommand not in sent
        # the operator's intents were written as REMOTE: never echoed
        assert not [
            c for c in replicated_changes(world, 0, registry) if c.component in {MovementCommand}
        ]


# ------------------------------------------------------------------------------- the pool


def _fly(vehicle: Vehicle, sticks: tuple[float, ...], until_s: float) -> None:
    vehicle.arm()
    vehicle.set_mode(ControlMode.MANUAL)
    run_with_sticks(vehicle, until_s, sticks)


def test_the_pool_the_camera_sees_is_solid() -> None:
    """Full down stick with the camera on: the hull comes to rest on the floor the camera
    renders (its box's bottom face on the floor's top: depth − hull height / 2), never below."""
    camera = load_vehicle_config({"camera": {"enabled": True}})
    pool = camera.pool_in_use
    assert pool is not None  # the camera's default pool
    with Vehicle(camera, np.random.default_rng(3)) as v:
        _fly(v, (0.0, 0.0, 1.0, 0.0, 0.0, 0.0), 25.0)
        resting = pool.depth_m - v.model.hull_size_m[2] / 2
        assert v.state().position_ned[2] == pytest.approx(resting, abs=0.01)
        assert abs(v.state().nu[2]) < 0.01


def test_a_pool_without_a_camera_stops_the_vehicle_at_its_wall() -> None:
    """Full forward stick in a 4-m pool: the bow's face stops at the north wall's inner face
    (length / 2 − hull length / 2 from the centre)."""
    config = load_vehicle_config(
        {
            "pool": {"length_m": 4.0, "width_m": 4.0, "depth_m": 2.0},
            "start_position_ned_m": [0, 0, 1],
        }
    )
    with Vehicle(config, np.random.default_rng(3)) as v:
        _fly(v, (1.0, 0.0, 0.0, 0.0, 0.0, 0.0), 12.0)
        north = v.state().position_ned[0]
        assert north == pytest.approx(2.0 - v.model.hull_size_m[0] / 2, abs=0.03)
    with Vehicle(
        load_vehicle_config({"start_position_ned_m": [0, 0, 1]}), np.random.default_rng(3)
    ) as v:
        _fly(v, (1.0, 0.0, 0.0, 0.0, 0.0, 0.0), 12.0)
        assert v.state().position_ned[0] > 5.0  # open water: nothing in the way


def test_pool_keys_are_checked_in_one_line() -> None:
    with pytest.raises(ConfigError, match=r"length_m: must be in \(0, 50\] m"):
        load_vehicle_config({"pool": {"length_m": 1e3}})
    with pytest.raises(ConfigError, match="start_position_ned_m: must be inside the pool"):
        load_vehicle_config({"pool": {"depth_m": 2.0}, "start_position_ned_m": [0, 0, 2.5]})
    with pytest.raises(ConfigError, match="start_position_ned_m: must be inside the pool"):
        load_vehicle_config({"camera": {"enabled": True}, "start_position_ned_m": [6, 0, 1]})


def test_holding_up_at_the_surface_keeps_the_hull_in_the_water_without_winding_up() -> None:
    """Full up stick in depth hold from 0.3 m, then let go at the surface: the target stops at
    ArduSub's surface depth (0.15 m, where the BlueROV2's hull is still under: it floats at
    0.12 m) and the vehicle goes back under and holds with a steady effort. A 0-m target
    had the hull floating while the depth loop's integral wound the thrust up without end
    (a review: 2.7 → 5.1 A over 20 s)."""
    up = (0.0, 0.0, -1.0, 0.0, 0.0, 0.0)
    with make(start_position_ned_m=(0.0, 0.0, 0.3), sensors=QUIET) as v:
        hold(v, 0.3)
        run_with_sticks(v, 15.0, up)
        targets = get(v, ControlTargets)
        assert isinstance(targets, ControlTargets) and targets.depth_m == SURFACE_HOLD_DEPTH_M
        run_with_sticks(v, 30.0, (0.0,) * 6)  # let go
        current_30 = v.power.current_a
        run_with_sticks(v, 60.0, (0.0,) * 6)
        depth = v.state().position_ned[2]
        floating = (v.model.weight_n / v.model.buoyancy_n - 0.5) * v.model.hull_size_m[2]
        assert depth > floating + 0.015  # under water, the loop holding it there
        assert depth == pytest.approx(SURFACE_HOLD_DEPTH_M, abs=0.03)
        assert v.power.current_a <= 1.1 * current_30  # a steady effort, nothing winding up


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_a_non_finite_stick_from_the_link_is_no_deflection(bad: float) -> None:
    # the vehicle's stick clip, max(−1, min(1, x)), made a NaN a full stick: a NaN over the
    # change-set codec flew at full surge; any non-finite stick reads centred
    with make(sensors=QUIET, start_position_ned_m=(0.0, 0.0, 1.0)) as v:
        hold(v, 1.0)
        sticks = (bad, bad, bad, bad, bad, bad)
        assert v.reference_velocity(sticks) == (0.0, 0.0, 0.0, 0.0)
        run_with_sticks(v, 3.0, sticks)
        assert abs(v.state().nu[0]) < 0.02
        assert get(v, AppliedWrench).requested[0] == pytest.approx(0.0, abs=1.0)  # type: ignore[union-attr]
