"""Vehicle benchmarks: real-time factor against a bare pybullet floor; experiment error tables.

Run with ``.venv/bin/python -m pytest benchmarks/test_vehicle_bench.py -m benchmark
--benchmark-enable -s`` (``-s`` shows the summary lines).

1. The bare floor: one 11.5 kg box in pybullet DIRECT, stepped at 240 Hz with pose and
   velocity read and a force and torque applied every step (REFERENCE §5: 6.5 µs/step, ≈640×
   real time on the reference machine). It is the least any pybullet vehicle can cost.
2. The vehicle alone: physics 240 Hz with Fossen forces, ECS frame at 100 Hz (sensors,
   commands, failsafe, pilot, depth and attitude loops, allocation, thruster plant), ecs-4h
   holding depth while tracking the yaw experiment's setpoint in a 0.1 m/s current. Reported
   as simulated seconds per wall second, and as a ratio to the floor measured in the same run.
3. Where a frame's time goes: the same run with a timer around each system, the physics step
   and the truth read, in µs per frame (timers add ≈0.1 µs each; the parts are what to compare).
4. The least frames: as many Python systems as the vehicle's doing the least a system does, and
   one compiled call doing a frame's least work on typed arrays — each against the floor.
5. The four ECS-paper experiment scenarios through the runner: mean, std and p95 of |error|.

Wall times are noisy on a shared machine; the ratios are what to compare between runs.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, TypeVar, cast

import numpy as np
import pybullet
import pytest
from numba import njit

from testbed.common.geometry import quat_from_euler
from testbed.ecs import Entity, Phase, Schedule, World
from testbed.run.runner import run_scenario
from testbed.run.scenario import load_scenario
from testbed.vehicle import systems
from testbed.vehicle.components import ControlMode
from testbed.vehicle.vehicle import Vehicle
from testbed.vehicle.vehicle_config import VehicleConfig
from testbed.vehicle.water_current import WaterCurrent

pytestmark = pytest.mark.benchmark

SIM_S = 20.0
DT_S = 1.0 / 240.0
SEED = 20250101
F = TypeVar("F", bound=Callable[..., Any])
VEHICLE_SYSTEMS = len(systems.build_schedule().names())
"""How many systems the vehicle's own schedule runs (the least frames run as many)."""


def bare_pybullet(sim_s: float) -> None:
    """The floor: step a box with pose/velocity reads and force/torque application."""
    cid = pybullet.connect(pybullet.DIRECT)
    try:
        pybullet.setGravity(0.0, 0.0, 0.0, physicsClientId=cid)
        pybullet.setTimeStep(DT_S, physicsClientId=cid)
        shape = pybullet.createCollisionShape(
            pybullet.GEOM_BOX, halfExtents=(0.23, 0.17, 0.13), physicsClientId=cid
        )
        body = pybullet.createMultiBody(11.5, shape, physicsClientId=cid)
        get_pose = pybullet.getBasePositionAndOrientation
        get_velocity = pybullet.getBaseVelocity
        apply_force = pybullet.applyExternalForce
        apply_torque = pybullet.applyExternalTorque
        step = pybullet.stepSimulation
        frame = pybullet.LINK_FRAME
        origin = (0.0, 0.0, 0.0)
        for _ in range(round(sim_s / DT_S)):
            (_, _, z), _ = get_pose(body, cid)
            (_, _, vz), _ = get_velocity(body, cid)
            apply_force(body, -1, (0.0, 0.0, -z - vz), origin, frame, cid)
            apply_torque(body, -1, (0.0, 0.0, 0.01), frame, cid)
            step(cid)
    finally:
        pybullet.disconnect(cid)


def make_vehicle(sim_s: float) -> Vehicle:
    """An armed ecs-4h vehicle in depth hold, in a 0.1 m/s current."""
    config = VehicleConfig(
        thrusters="ecs-4h",
        current=WaterCurrent(velocity_ned_mps=(0.1, 0.0, 0.0)),
        start_position_ned_m=(0.0, 0.0, 0.3),
    )
    vehicle = Vehicle(config, np.random.default_rng(SEED))
    vehicle.arm()
    vehicle.set_mode(ControlMode.DEPTH_HOLD)
    vehicle.set_depth(0.3)
    return vehicle


def drive(vehicle: Vehicle, sim_s: float) -> None:
    """The operator side: the yaw experiment's setpoint and a stick command at 40 Hz."""
    t = 0.0
    while t < sim_s - 1e-9:
        yaw = math.radians(20.0) * math.sin(2.0 * math.pi * t / 25.0)
        vehicle.set_attitude(quat_from_euler(0.0, 0.0, yaw))
        vehicle.command((0.0, 0.0, 0.0, 0.0, 0.0, 0.0))
        t += 0.025
        vehicle.advance(t)


def best_of(fn: Callable[[], None], rounds: int) -> float:
    best = math.inf
    for _ in range(rounds):
        start = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - start)
    return best


def interleaved_best(fns: dict[str, Callable[[], float]], rounds: int) -> dict[str, float]:
    """The least of ``rounds`` timings of each function, their rounds interleaved.

    Each function returns the seconds it measured (so it may leave its set-up untimed). On a
    shared virtual machine the speed of the whole machine drifts by 2-3x within seconds; timing
    the floor's rounds first and the vehicle's after turns that drift into the ratio, while
    interleaved rounds see the same machine and the least of each is its undisturbed cost.
    """
    best = dict.fromkeys(fns, math.inf)
    for _ in range(rounds):
        for name, fn in fns.items():
            best[name] = min(best[name], fn())
    return best


def timed_floor(sim_s: float) -> float:
    """Seconds :func:`bare_pybullet` takes for ``sim_s``."""
    start = time.perf_counter()
    bare_pybullet(sim_s)
    return time.perf_counter() - start


def test_vehicle_real_time_factor() -> None:
    """The vehicle alone against the floor, seven interleaved rounds of each (least of each)."""

    def vehicle_round() -> float:
        vehicle = make_vehicle(SIM_S)  # construction (≈ 25 ms) is not timed
        try:
            start = time.perf_counter()
            drive(vehicle, SIM_S)
            elapsed = time.perf_counter() - start
            assert vehicle.frames == 100 * SIM_S
            return elapsed
        finally:
            vehicle.close()

    best = interleaved_best({"floor": lambda: timed_floor(SIM_S), "vehicle": vehicle_round}, 7)
    floor_s, vehicle_s = best["floor"], best["vehicle"]
    floor_rtf = SIM_S / floor_s
    vehicle_rtf = SIM_S / vehicle_s
    ratio = vehicle_s / floor_s
    print(
        f"\nbare pybullet floor {floor_rtf:.0f}x real time "
        f"({floor_s / (SIM_S / DT_S) * 1e6:.2f} µs a step); vehicle {vehicle_rtf:.0f}x "
        f"({vehicle_s / (100 * SIM_S) * 1e6:.1f} µs a frame); vehicle costs {ratio:.2f}x the floor"
    )
    assert vehicle_rtf > 30.0  # a gross regression guard, not the target (see the report)


def test_vehicle_frame_breakdown(benchmark: pytest.FixtureRequest) -> None:
    clock = time.perf_counter
    totals: dict[str, float] = {}

    def timed(name: str, fn: F) -> F:
        totals[name] = 0.0

        def run(*args: object) -> object:
            start = clock()
            result = fn(*args)
            totals[name] += clock() - start
            return result

        return cast(F, run)

    def setup() -> tuple[tuple[Vehicle, float], dict[str, object]]:
        totals.clear()
        vehicle = make_vehicle(SIM_S)
        vehicles.append(vehicle)
        schedule = Schedule()
        plain = systems.build_schedule()
        for phase in Phase:
            for name in plain.names(phase):
                system: Callable[[World], None] = getattr(systems, name)
                schedule.add(phase, timed(name, system), name=name)
        vehicle.schedule = schedule
        physics = vehicle.physics
        physics.step_until = timed("Physics.step_until", physics.step_until)  # type: ignore[method-assign]
        physics.state_floats = timed("Physics.state_floats", physics.state_floats)  # type: ignore[method-assign]
        return (vehicle, SIM_S), {}

    vehicles: list[Vehicle] = []
    try:
        start = clock()
        benchmark.pedantic(drive, setup=setup, rounds=1, iterations=1)  # type: ignore[attr-defined]
        wall_s = clock() - start
    finally:
        for vehicle in vehicles:
            vehicle.close()
    frames = vehicles[-1].frames
    per_frame = {name: round(total / frames * 1e6, 2) for name, total in totals.items()}
    per_frame["everything (incl. timers)"] = round(wall_s / frames * 1e6, 2)
    benchmark.extra_info["us_per_frame"] = per_frame  # type: ignore[attr-defined]
    print("\nµs per frame (100 frames and 240 physics steps per simulated second):")
    for name, us in per_frame.items():
        print(f"  {name:28s} {us:7.2f}")
    assert frames == 100 * SIM_S


@dataclass(frozen=True, slots=True)
class _Reading:
    a: float
    b: float
    c: float


class _Gain:
    k = 1.0


def _least_system(index: int) -> Callable[[World], None]:
    """A system doing the least a vehicle system does: one resource, one get, one set."""

    def system(world: World) -> None:
        gain = world.resource(_Gain)
        reading = world.get(Entity(1), _Reading)
        assert reading is not None
        world.set(Entity(1), _Reading(reading.a + gain.k, reading.b, reading.c))

    system.__name__ = f"least_{index}"
    return system


def _frames_against_floor(frames: Callable[[], None]) -> tuple[float, float]:
    """Time ``frames`` (SIM_S of 100-Hz frames) and the floor, five interleaved rounds each:
    the µs a frame and the ratio of the least of its times to the floor's."""

    def frames_round() -> float:
        start = time.perf_counter()
        frames()
        return time.perf_counter() - start

    best = interleaved_best({"floor": lambda: timed_floor(SIM_S), "frames": frames_round}, 5)
    floor_s, least_s = best["floor"], best["frames"]
    return least_s / (100 * SIM_S) * 1e6, least_s / floor_s


def _systems_against_floor(
    world: World, system_of: Callable[[int], Callable[[World], None]]
) -> tuple[int, float, float, int]:
    """A schedule of as many systems as the vehicle's (``system_of(index)`` each) run on
    ``world`` at 100 Hz against the floor: the count, µs a frame, the ratio to the floor and
    the frames run in all."""
    count = VEHICLE_SYSTEMS
    schedule = Schedule()
    for index in range(count):
        schedule.add(Phase.UPDATE, system_of(index))
    rounds: list[None] = []

    def frames() -> None:
        for _ in range(round(100 * SIM_S)):
            schedule.run(world)
        rounds.append(None)

    frame_us, ratio = _frames_against_floor(frames)
    return count, frame_us, ratio, len(rounds) * round(100 * SIM_S)


def test_least_python_frame_against_floor() -> None:
    """The cheapest frame a schedule of Python systems can run, against the floor in one run.

    As many systems as the vehicle's schedule (``systems.build_schedule``), each only reading a
    resource, getting one 3-float component and setting a new one, at 100 Hz. Its cost over the
    floor's is what Python systems take before any law runs: the vehicle-alone aim (within 2×
    of the floor, while the Fossen plant alone is 1.5–1.7× it) leaves 0.3–0.5× for them.
    """
    world = World()
    world.insert_resource(_Gain())
    world.spawn(_Reading(0.0, 0.0, 0.0))
    count, frame_us, ratio, frames_run = _systems_against_floor(world, _least_system)
    print(
        f"\n{count} least Python systems at 100 Hz: {frame_us:.1f} µs a frame, "
        f"{ratio:.2f}x the bare floor's time"
    )
    assert world.get(Entity(1), _Reading) == _Reading(float(count * frames_run), 0.0, 0.0)


@njit(cache=True)
def _least_compiled_frame(
    store: np.ndarray,
    params: np.ndarray,
    matrix: np.ndarray,
    noise: np.ndarray,
    position: tuple[float, float, float],
    orientation: tuple[float, float, float, float],
    angular: tuple[float, float, float],
) -> tuple[float, float, float, float, float, float]:
    """A frame's least work as one compiled call on typed arrays (no law of the vehicle's).

    Sensors (attitude, rates and depth plus noise taken from a block of draws), a depth PI and
    a yaw-rate damper, ``f = T·m`` clipped to ±40 N and the wrench ``T·f``: the components live
    in ``store`` (the IMU at 0–6, depth at 7, the integrator at 8, forces at 16–23, the wrench
    at 24–29, the noise cursor at 63), the gains in ``params``. Returns the (6,) body wrench
    for the physics.
    """
    cursor = int(store[63])
    draws = noise[cursor : cursor + 7]
    store[63] = (cursor + 7) % (noise.size - 7)
    for i in range(4):
        store[i] = orientation[i] + (params[0] * draws[i] if i < 3 else 0.0)
    for i in range(3):
        store[4 + i] = angular[i] + params[1] * draws[3 + i]
    store[7] = -position[2] + params[2] * draws[6]
    error = params[3] - store[7]
    store[8] += error * 0.01
    fz = params[4] * error + params[5] * store[8]
    tz = -params[6] * store[6]
    count = matrix.shape[1]
    forces = store[16 : 16 + count]
    for j in range(count):
        forces[j] = min(max(matrix[2, j] * fz + matrix[5, j] * tz, -40.0), 40.0)
    wrench = store[24:30]
    for i in range(6):
        total = 0.0
        for j in range(count):
            total += matrix[i, j] * forces[j]
        wrench[i] = total
    return (wrench[0], wrench[1], wrench[2], wrench[3], wrench[4], wrench[5])


def test_least_compiled_frame_against_floor() -> None:
    """The cheapest frame a compiled design can run, against the floor in one run.

    One call per 100-Hz frame into :func:`_least_compiled_frame`, with the arguments such a
    frame needs: a component store, gains, the allocation matrix (6 × 8), a block of normal
    draws (not a ``numpy.random.Generator``: passing one into a compiled call costs ≈ 7 µs
    a call, unboxing it) and the truth as pybullet returns it. Its cost over the floor's is what
    a whole compiled frame takes before the laws' own arithmetic: set beside the least Python
    frame, it says whether "within 2× of the floor" is in reach of each design.
    """
    store = np.zeros(64)
    params = np.full(64, 0.5)
    matrix = np.ones((6, 8))
    noise = np.random.default_rng(SEED).standard_normal(4096)
    position, orientation, angular = (0.0, 0.0, -0.3), (0.0, 0.0, 0.0, 1.0), (0.0, 0.0, 0.0)
    _least_compiled_frame(store, params, matrix, noise, position, orientation, angular)
    wrenches: list[tuple[float, ...]] = []

    def frames() -> None:
        store[:] = 0.0
        for _ in range(round(100 * SIM_S)):
            wrench = _least_compiled_frame(
                store, params, matrix, noise, position, orientation, angular
            )
        wrenches.append(wrench)

    frame_us, ratio = _frames_against_floor(frames)
    print(
        f"\none compiled frame call at 100 Hz: {frame_us:.2f} µs a frame, "
        f"{ratio:.2f}x the bare floor's time"
    )
    # Every round runs the same frames from a zeroed store; the last wrench is checked against
    # the same frames replayed in plain Python.
    assert len(set(wrenches)) == 1
    integral, cursor, force = 0.0, 0, 0.0
    for _ in range(round(100 * SIM_S)):
        draws = noise[cursor : cursor + 7]
        cursor = (cursor + 7) % (noise.size - 7)
        error = 0.5 - (0.3 + 0.5 * draws[6])
        integral += error * 0.01
        force = min(max(0.5 * error + 0.5 * integral - 0.5 * (0.5 * draws[5]), -40.0), 40.0)
    assert wrenches[0] == pytest.approx((8 * force,) * 6, rel=1e-12)  # T is all ones, 8 columns


@njit(cache=True)
def _least_kernel(store: np.ndarray, params: np.ndarray, index: int) -> None:
    """A system's least compiled work on a component store: read its input slot, write its
    output slot (slot ``index`` plus the gain ``params[index]``)."""
    store[index + 1] = store[index] + params[index]


@dataclass
class _Store:
    values: np.ndarray
    params: np.ndarray


def _kernel_system(index: int) -> Callable[[World], None]:
    """A system that is a compiled kernel over a component store: one resource, one call."""

    def system(world: World) -> None:
        store = world.resource(_Store)
        _least_kernel(store.values, store.params, index)

    system.__name__ = f"kernel_{index}"
    return system


def test_kernel_systems_frame_against_floor() -> None:
    """The cheapest frame of *separate* compiled systems, against the floor in one run.

    The design between the two above: the schedule keeps as many Python systems as the
    vehicle's, each a shell that fetches the component store (a resource) and calls one
    compiled kernel on it, with no ``World.get``/``set`` and no component objects in the frame.
    Its cost says what keeping the paper's systems as separate schedule entries costs once
    their laws and components are compiled: whether such a frame fits 300× and "within 2× of
    the floor" beside the plant's own cost.
    """
    world = World()
    world.insert_resource(_Store(np.zeros(VEHICLE_SYSTEMS + 1), np.ones(VEHICLE_SYSTEMS)))
    _least_kernel(np.zeros(2), np.zeros(1), 0)
    count, frame_us, ratio, _ = _systems_against_floor(world, _kernel_system)
    print(
        f"\n{count} compiled-kernel systems at 100 Hz: {frame_us:.2f} µs a frame, "
        f"{ratio:.2f}x the bare floor's time"
    )
    # each frame sets slot i + 1 to slot i plus its gain (1), in order from slot 0, which
    # nothing writes: after any frame slot i holds i
    assert world.resource(_Store).values.tolist() == [float(i) for i in range(count + 1)]


ECS_SCENARIOS = ["ecs-yaw-4h-v1", "ecs-yaw-3h-v1", "ecs-yaw-2h-v1", "ecs-rollpitch-6dof-v1"]


@pytest.mark.parametrize("name", ECS_SCENARIOS)
def test_experiment_error_distributions(benchmark: pytest.FixtureRequest, name: str) -> None:
    scenario = load_scenario(name)
    result = benchmark.pedantic(  # type: ignore[attr-defined]
        run_scenario, args=(scenario,), kwargs={"seed": SEED}, rounds=1, iterations=1
    )
    attitude = result.metrics["attitude_error_deg"]
    table = {
        axis: {key: round(attitude[axis][key], 3) for key in ("mean", "std", "p95")}
        for axis in ("roll", "pitch", "yaw")
    }
    benchmark.extra_info.update(table)  # type: ignore[attr-defined]
    benchmark.extra_info["simulated_s"] = scenario.duration_s  # type: ignore[attr-defined]
    print(
        f"\n{name}: "
        + "; ".join(
            f"{axis} mean {v['mean']:.2f} p95 {v['p95']:.2f} std {v['std']:.2f}"
            for axis, v in table.items()
        )
    )
    if name == "ecs-rollpitch-6dof-v1":
        assert attitude["roll"]["std"] <= 1.3 and attitude["pitch"]["std"] <= 1.3
    else:
        assert attitude["yaw"]["p95"] < 2.0
