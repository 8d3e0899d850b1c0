"""Building a vehicle from its configuration: the plant, the ECS world and their wiring.

:func:`assemble_vehicle` turns a :class:`~testbed.vehicle.vehicle_config.VehicleConfig` (the
scenario's ``[vehicle]`` table) and a generator into the :class:`VehicleParts` a
:class:`~testbed.vehicle.vehicle.Vehicle` runs: the plant (thruster configuration, T200 curves,
:class:`~testbed.vehicle.allocation.Allocator`,
:class:`~testbed.vehicle.thrusters.ThrusterDynamics`, the hydrodynamic model, the pybullet
:class:`~testbed.vehicle.physics.Physics`, the sensors) and the ECS
:class:`~testbed.ecs.World` with its frame store, entities, resources and the frame
:class:`~testbed.ecs.Schedule` of :mod:`testbed.vehicle.systems`.

The order of construction is part of the result: child generators are spawned, and entities
(whose ids fix the order in which the force intents are summed) are spawned, in the order
below, and what a later version adds (GUIDED's intent, localization, autonomy, the arm) comes
after what the runs before it had, so those runs keep their random streams and results byte
for byte. Advancing time, operator intents and thruster faults are the vehicle's
(:mod:`testbed.vehicle.vehicle`); nothing here steps the physics or runs a frame.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from testbed.ecs import Entity, Origin, Replicate, Schedule, System, World
from testbed.ecs.store import FrameStore
from testbed.vehicle.allocation import Allocator
from testbed.vehicle.autonomy import (
    build_autonomy,
    control_velocity,
    run_mission,
)
from testbed.vehicle.components import (
    ActiveMode,
    AppliedWrench,
    Armed,
    ControlMode,
    ControlTargets,
    DepthReading,
    FailsafeLevel,
    FailsafeStatus,
    ForceIntent,
    ImuReading,
    Odometry,
    PositionReading,
    ThrusterOutput,
    VehicleTag,
)
from testbed.vehicle.control import (
    AttitudeController,
    AttitudeGains,
    DepthController,
)
from testbed.vehicle.hydrodynamics import HydroModel
from testbed.vehicle.localization import (
    FixSource,
    build_navigation,
    estimate_navigation,
)
from testbed.vehicle.manipulation import Manipulator, build_manipulator, plan_arm
from testbed.vehicle.physics import Physics
from testbed.vehicle.resources import (
    ZERO6,
    Actuation,
    Controllers,
    PlantTruth,
    PowerMeter,
    SensorSuite,
    SimClock,
)
from testbed.vehicle.scenery import pool_scenery
from testbed.vehicle.sensors import (
    DepthSensor,
    Imu,
    PositionFix,
)
from testbed.vehicle.systems import build_schedule
from testbed.vehicle.thrusters import (
    T200,
    ThrusterConfig,
    ThrusterDynamics,
    load_thruster_config,
)
from testbed.vehicle.vehicle_config import VehicleConfig

__all__ = ["VehicleParts", "assemble_vehicle"]


@dataclass(frozen=True, slots=True, eq=False)  # parts compare by identity
class VehicleParts:
    """Everything a vehicle is made of, built and wired by :func:`assemble_vehicle`.

    Attributes:
        thruster_config: the thruster layout (``vehicle.thrusters``).
        thruster_names: the thrusters' names, in the layout's (and ``T``'s column) order.
        t200: the T200's force and current curves at the supply voltage.
        allocator: wrench → thruster forces, with the configuration's limits.
        matrix: (6, n) the physical configuration ``T`` [N, N·m per N], body FRD.
        dynamics: the thrusters' lag and faults (the plant side).
        model: the hydrodynamic model the physics integrates.
        physics: the pybullet plant (pool, current, arm, scenery for the camera).
        camera_rng: the camera noise's generator; None when the camera is off or noiseless.
        sensors: IMU, depth sensor and (without a navigation filter) the position fix.
        world: the vehicle's ECS world, holding the resources below.
        store: the frame store of the components the compiled kernels write.
        schedule: the frame's systems, link systems first and last.
        entity: the vehicle's own entity (armed, mode, failsafe, thruster output, wrench).
        controllers: the controllers and the pilot interface (an ECS resource).
        actuation: allocation and thruster plant stepping (an ECS resource).
        clock: the frame's time and interval (an ECS resource).
        truth: the plant's true state as the sensors sample it (an ECS resource).
        power: the thrusters' energy meter (an ECS resource).
        operator_entity: the entity of operator intents written locally (scripted runs).
        manipulator: the arm's kinematics and planner, or None without an arm.
        accelerometer: whether the navigation filter takes the NED acceleration.
    """

    thruster_config: ThrusterConfig
    thruster_names: tuple[str, ...]
    t200: T200
    allocator: Allocator
    matrix: np.ndarray
    dynamics: ThrusterDynamics
    model: HydroModel
    physics: Physics
    camera_rng: np.random.Generator | None
    sensors: SensorSuite
    world: World
    store: FrameStore
    schedule: Schedule
    entity: Entity
    controllers: Controllers
    actuation: Actuation
    clock: SimClock
    truth: PlantTruth
    power: PowerMeter
    operator_entity: Entity
    manipulator: Manipulator | None
    accelerometer: bool


def assemble_vehicle(
    config: VehicleConfig,
    rng: np.random.Generator,
    *,
    inbound: Sequence[System] = (),
    outbound: Sequence[System] = (),
) -> VehicleParts:
    """Build a vehicle's plant and ECS world from its configuration.

    Args:
        config: the vehicle's configuration.
        rng: the generator all the vehicle's randomness comes from (sensors, current, camera,
            navigation); child generators are spawned from it in a fixed order.
        inbound: link systems to run first in each frame's PRE_UPDATE.
        outbound: link or recording systems to run last in each frame's POST_UPDATE.

    Returns:
        The parts, wired: the world holds the resources, the actuation drives the physics'
        held wrench. The physics client is open (:meth:`Physics.close` releases it).
    """
    imu_rng, depth_rng, position_rng, current_rng = rng.spawn(4)
    thruster_config = load_thruster_config(config.thrusters)
    t200 = T200.from_table(config.supply_voltage_v)
    allocator = Allocator(
        thruster_config,
        t200,
        method=config.allocation,
        current_limit_a=config.current_limit_a,
        slew_limit_n_per_s=config.slew_limit_n_per_s,
    )
    matrix = np.array(thruster_config.matrix, dtype=float)
    n = matrix.shape[1]
    dynamics = ThrusterDynamics(n, time_constant_s=config.thruster_time_constant_s)
    model = config.hydro_model()
    arm_model = None if config.arm is None else config.arm.arm_model()
    pool = config.pool_in_use
    physics = Physics(
        model,
        dt_s=config.physics_dt_s,
        pool=pool,
        start_position_ned=config.start_position_ned_m,
        start_euler_rad=config.start_euler_rad,
        current=config.current,
        rng=current_rng,
        arm=arm_model,
        arm_coupling=config.arm is None or config.arm.coupling,
        arm_trim=config.arm is None or config.arm.trim,
    )
    camera = config.camera
    if camera.enabled and pool is not None:  # the camera's pool is the solid one
        physics.add_scenery(pool_scenery(pool.length_m, pool.width_m, pool.depth_m))
    # spawned only when drawn from, so runs without camera noise keep their streams
    camera_rng = rng.spawn(1)[0] if camera.enabled and camera.noise_std_grey else None
    sensor_config = config.sensors
    position = sensor_config.position
    fix = None if position is None else PositionFix(position, position_rng)
    navigation = config.navigation_in_use
    autonomy = config.autonomy
    sensors = SensorSuite(
        Imu(sensor_config.imu, imu_rng),
        DepthSensor(sensor_config.depth, depth_rng),
        fix if navigation is None else None,  # else a navigation source (below)
    )

    world = World()
    # the frame's components that compiled kernels write: kept in a frame store
    rest = ThrusterOutput((0.0,) * n, (1500.0,) * n, (0.0,) * n, 1.0)  # disarmed
    store = FrameStore()
    store.add(ForceIntent("", ZERO6), capacity=16)  # five sources here, room for more
    store.add(rest, capacity=1)
    store.add(AppliedWrench(ZERO6, ZERO6), capacity=1)
    for reading in (
        ImuReading(0.0, (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0)),
        DepthReading(0.0, 0.0, 0.0),
        PositionReading(0.0, (0.0, 0.0, 0.0)),
        ControlTargets(0.0, (1.0, 0.0, 0.0, 0.0)),
        Odometry(0.0, (0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0)),
    ):
        store.add(reading, capacity=1)
    world.use_store(store)
    schedule = build_schedule(
        inbound,
        outbound,
        estimators=() if navigation is None else (estimate_navigation,),
        planners=(
            *(() if autonomy is None else (run_mission,)),
            *(() if config.arm is None else (plan_arm,)),
        ),
        controllers=(control_velocity,) if autonomy and autonomy.controller == "ismc" else (),
    )
    start_mode = ControlMode.MANUAL if autonomy is None else ControlMode.GUIDED
    entity = world.spawn(
        VehicleTag(),
        Replicate(),
        Armed(False),
        ActiveMode(start_mode),
        FailsafeStatus(FailsafeLevel.NOMINAL, 0.0),
        rest,
        AppliedWrench(ZERO6, ZERO6),
    )
    gains = config.gains
    controllers = Controllers(
        vehicle=entity,
        attitude=AttitudeController(AttitudeGains(gains.roll, gains.pitch, gains.yaw)),
        depth=DepthController(gains.depth, gains.depth_feedforward_n),
        pilot=config.pilot,
        failsafe=config.failsafe,
        axis_maxima=tuple(float(v) for v in allocator.axis_maxima()),
        autonomous=autonomy is not None,
        velocity_control=autonomy is not None and autonomy.controller == "ismc",
    )
    for source in ("pilot", "depth", "attitude"):
        _spawn_intent(world, controllers, source)
    actuation = Actuation(
        allocator,
        dynamics,
        matrix,
        store.table(ForceIntent),
        world.row_view(entity, ThrusterOutput),
        world.row_view(entity, AppliedWrench),
        plant_wrench=physics.held_wrench,
    )
    clock = SimClock(0.0, 1.0 / config.control_rate_hz)
    truth = PlantTruth()
    power = PowerMeter(config.supply_voltage_v, t200.total_current_a)
    for resource in (clock, truth, sensors, controllers, actuation, power):
        world.insert_resource(resource)
    # operator intents written locally (scripted runs) live on their own entity
    operator_entity = world.spawn(Replicate(), origin=Origin.REMOTE)
    # GUIDED's intent entity, spawned after the others so the entity ids (and the summing
    # order) of the runs before GUIDED existed stay the same
    _spawn_intent(world, controllers, "position")
    # localization and autonomy, last: runs without them keep their entities and streams
    if navigation is not None:
        extra = () if fix is None else (FixSource(fix),)
        world.insert_resource(build_navigation(navigation, rng.spawn(1)[0], extra))
    if autonomy is not None:
        world.insert_resource(build_autonomy(autonomy, model))
        _spawn_intent(world, controllers, "velocity")
    manipulator: Manipulator | None = None
    if config.arm is not None:
        manipulator = build_manipulator(config.arm, arm_model)
        world.insert_resource(manipulator)
    return VehicleParts(
        thruster_config=thruster_config,
        thruster_names=tuple(t.name for t in thruster_config.thrusters),
        t200=t200,
        allocator=allocator,
        matrix=matrix,
        dynamics=dynamics,
        model=model,
        physics=physics,
        camera_rng=camera_rng,
        sensors=sensors,
        world=world,
        store=store,
        schedule=schedule,
        entity=entity,
        controllers=controllers,
        actuation=actuation,
        clock=clock,
        truth=truth,
        power=power,
        operator_entity=operator_entity,
        manipulator=manipulator,
        accelerometer=navigation is not None and navigation.accelerometer is not None,
    )


def _spawn_intent(world: World, controllers: Controllers, source: str) -> None:
    """An entity with ``source``'s zero :class:`ForceIntent` (its row sums in spawn order)."""
    entity = world.spawn(ForceIntent(source, ZERO6))
    controllers.intents[source] = entity
    controllers.intent_rows[source] = world.row_view(entity, ForceIntent)
