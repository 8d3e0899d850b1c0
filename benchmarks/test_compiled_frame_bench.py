"""The vehicle's own laws as one compiled frame, with the real plant, against the floor.

Run with ``.venv/bin/python -m pytest -n 0 benchmarks/test_compiled_frame_bench.py -m benchmark
--benchmark-enable -s``.

``test_vehicle_bench.py`` measures the least frames (a frame's least work, no law of the
vehicle's). This one composes the vehicle's real per-frame kernels in frame order inside one
compiled function — the depth and attitude loops (:mod:`~testbed.vehicle.control_kernels`),
the sum of the intents, the ECS paper's allocation (``allocate_pinv``), the thrusters' lag, the
interval's wrench and the power meter's current (:mod:`~testbed.vehicle.thrust_kernels`) — on
the arrays a built :class:`~testbed.vehicle.vehicle.Vehicle` holds, and first checks that it
computes what the vehicle's Python systems compute: the same plant wrench, frame by frame, from
the same readings. Then it runs that frame at 100 Hz on the real Fossen plant (``Physics``, 240
Hz) beside the bare floor, as the vehicle-alone benchmark does, and beside the plant with an
empty frame: what a compiled frame of these laws would cost, measured, not estimated.

Not in it: the sensors' noise models (the readings are the true attitude, and rates and depth
plus white noise from a block of draws, the least frame's sensors), the failsafe, the pilot
interface and command ingestion (events and cached shaping in the benchmark's run: sticks at
zero), the schedule and the components. A design that keeps those in Python pays for them on
top.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest
from numba import njit

from benchmarks.test_vehicle_bench import (
    SIM_S,
    drive,
    interleaved_best,
    make_vehicle,
    timed_floor,
)
from testbed.common.geometry import quat_from_euler
from testbed.ecs import Phase, World
from testbed.vehicle.allocation import CURRENT_TOLERANCE_A
from testbed.vehicle.components import ControlTargets, DepthReading, ForceIntent, ImuReading
from testbed.vehicle.control_kernels import attitude_update, depth_update
from testbed.vehicle.resources import Actuation, Controllers, PowerMeter, SimClock
from testbed.vehicle.systems import mean_force_weight
from testbed.vehicle.thrust_kernels import (
    allocate_pinv,
    interval_wrench,
    lag_step,
    total_current,
)
from testbed.vehicle.thrusters import lag_blend
from testbed.vehicle.vehicle import Vehicle

pytestmark = pytest.mark.benchmark


# Not cached: it compiles kernels of other files into itself, whose edits numba's disk cache
# would not see.
@njit
def _laws_frame(
    loops: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float, tuple[bool, bool, bool]],
    allocation: tuple[
        np.ndarray, np.ndarray, float, float, float, float, np.ndarray, np.ndarray, np.ndarray
    ],
    tables: tuple[np.ndarray, np.ndarray],
    plant: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float, float],
    readings: tuple[tuple[float, float, float, float], tuple[float, float, float], float],
    targets: tuple[float, tuple[float, float, float, float]],
    pilot: tuple[float, float, float, float, float, float],
    dt_s: float,
    requested: np.ndarray,
) -> tuple[tuple[float, float, float, float, float, float], float]:
    """One frame of the vehicle's laws: depth and attitude loops, Σ intents, allocation,
    thruster lag over the interval, the interval's wrench and the current. Returns the plant
    wrench (6,) [N, N·m], FRD, and the thrusters' current [A]; the arrays advance in place."""
    depth_state, depth_gains, attitude_state, attitude_gains, feedforward_n, axes = loops
    offset, pinv, f_lo, f_hi, slew_n_s, cap_a, work, thrusters, start = allocation
    current_table, pwm_table = tables
    actual, gain, held, matrix, blend, weight = plant
    quaternion, rates, depth_m = readings
    depth_target, attitude_target = targets
    fx, fy, fz = depth_update(
        depth_state, depth_gains, depth_target, depth_m, quaternion, dt_s, feedforward_n
    )
    tx, ty, tz = attitude_update(
        attitude_state, attitude_gains, attitude_target, quaternion, rates, dt_s, axes
    )
    # Σ intents in the systems' order (pilot, depth, attitude, position at zero), from 0.0
    intents = (
        (pilot[0], pilot[1], pilot[2], pilot[3], pilot[4], pilot[5]),
        (fx, fy, fz, 0.0, 0.0, 0.0),
        (0.0, 0.0, 0.0, tx, ty, tz),
        (0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
    )
    for i in range(6):
        total = 0.0
        for intent in intents:
            total += intent[i]
        requested[i] = total
    allocate_pinv(
        requested,
        offset,
        pinv,
        f_lo,
        f_hi,
        slew_n_s * dt_s,
        cap_a,
        CURRENT_TOLERANCE_A,
        work,
        thrusters,
        current_table,
        pwm_table,
    )
    start[:] = actual
    lag_step(actual, work[0], gain, held, blend)
    wrench = interval_wrench(matrix, start, actual, weight)
    return wrench, total_current(actual, 1.0, current_table)


@dataclass
class _Arrays:
    """What :func:`_laws_frame` takes from a built vehicle (its own arrays, advanced in place)."""

    loops: tuple[Any, ...]
    allocation: tuple[Any, ...]
    tables: tuple[np.ndarray, np.ndarray]
    plant: tuple[Any, ...]


def _arrays_of(vehicle: Vehicle, interval_s: float) -> _Arrays:
    """The vehicle's controller, allocator, thruster and power arrays (private attributes: a
    benchmark reaching in, so the frame runs on exactly what the systems use), with the lag's
    blend and the mean force's weight for a frame interval of ``interval_s``."""
    world = vehicle.world
    ctl = world.resource(Controllers)
    act = world.resource(Actuation)
    allocator = act.allocator
    assert allocator.method == "pinv"
    dynamics = act.dynamics
    blend = lag_blend(interval_s, dynamics.time_constant_s)
    weight = mean_force_weight(interval_s, dynamics.time_constant_s)
    power = world.resource(PowerMeter)
    current_table = power.current_of.__self__._current_table  # type: ignore[attr-defined]
    assert current_table is allocator._current_table
    depth, attitude = ctl.depth, ctl.attitude
    loops = (
        depth._pid_state,
        depth._pid_gains,
        attitude._state,
        attitude._gains,
        float(depth.feedforward_n),
        ctl.attitude_axes,
    )
    allocation = (
        allocator._stuck_wrench,
        allocator._pinv,
        float(allocator._f_lo),
        float(allocator._f_hi),
        float(allocator._slew),
        float(allocator._cap_active),
        allocator._work,
        allocator._thrusters,
        np.zeros(act.matrix.shape[1]),
    )
    plant = (
        dynamics._forces,
        dynamics._gain,
        dynamics._held,
        act.matrix,
        blend,
        weight,
    )
    return _Arrays(loops, allocation, (current_table, allocator._pwm_table), plant)


@dataclass
class _Frame:
    readings: tuple[tuple[float, ...], tuple[float, ...], float]
    targets: tuple[float, tuple[float, ...]]
    pilot: tuple[float, ...]
    dt_s: float
    interval_s: float
    holds: tuple[bool, bool, bool]
    wrench: tuple[float, ...]
    current_a: float


def _recorded_frames(sim_s: float) -> list[_Frame]:
    """The vehicle-alone benchmark's vehicle, run by its Python systems for ``sim_s``: each
    frame's readings, targets, pilot intent, clock and the plant wrench and current it made."""
    vehicle = make_vehicle(sim_s)
    frames: list[_Frame] = []

    def record(world: World) -> None:
        ctl = world.resource(Controllers)
        imu = world.get(ctl.vehicle, ImuReading)
        depth = world.get(ctl.vehicle, DepthReading)
        targets = world.get(ctl.vehicle, ControlTargets)
        pilot = world.get(ctl.intents["pilot"], ForceIntent)
        assert imu is not None and depth is not None and targets is not None
        assert pilot is not None
        flags = ctl.flags
        frames.append(
            _Frame(
                (imu.quaternion_wxyz, imu.rates_rad_s, depth.depth_m),
                (targets.depth_m, targets.quaternion_wxyz),
                pilot.wrench,
                world.resource(SimClock).dt_s,
                world.resource(Actuation).interval_s,
                (flags.armed, flags.depth_hold, flags.attitude_hold),
                tuple(world.resource(Actuation).plant_wrench.tolist()),
                world.resource(PowerMeter).current_a,
            )
        )

    vehicle.schedule.add(Phase.POST_UPDATE, record, name="record_frame")
    try:
        drive(vehicle, sim_s)
    finally:
        vehicle.close()
    return frames


def test_the_compiled_frame_makes_the_systems_wrench() -> None:
    """Replayed on a fresh vehicle's arrays, the compiled frame gives the plant wrench and the
    current the Python systems gave, frame by frame, from the same readings and targets."""
    frames = _recorded_frames(5.0)
    assert all(frame.holds == (True, True, True) for frame in frames)  # no loop was reset
    intervals = {frame.interval_s for frame in frames}
    assert len(intervals) <= 2  # 2 or 3 steps of 1/240 s
    vehicle = make_vehicle(5.0)
    try:
        requested = np.zeros(6)
        arrays = {interval: _arrays_of(vehicle, interval) for interval in intervals}
        for frame in frames:
            plant = arrays[frame.interval_s]  # the same arrays; the interval's blend, weight
            wrench, current = _laws_frame(
                plant.loops,
                plant.allocation,
                plant.tables,
                plant.plant,
                frame.readings,
                frame.targets,
                frame.pilot,
                frame.dt_s,
                requested,
            )
            assert wrench == frame.wrench
            assert current == frame.current_a
        assert max(abs(w) for frame in frames for w in frame.wrench) > 1.0  # it did work
    finally:
        vehicle.close()


def _plant_with_frame(compiled: bool) -> float:
    """Seconds of SIM_S of the vehicle-alone run with the frame replaced: the truth read, the
    readings (the true attitude; rates and depth plus white noise from a block of draws), the
    yaw setpoint at 40 Hz and, when ``compiled``, :func:`_laws_frame`, then the physics steps
    to the next frame."""
    vehicle = make_vehicle(SIM_S)
    try:
        physics = vehicle.physics
        arrays = _arrays_of(vehicle, 2 * physics.dt_s)
        step = physics.step
        requested = np.zeros(6)
        noise = np.random.default_rng(0).standard_normal(4096).tolist()
        zero6 = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        wrench = zero6
        target = quat_from_euler(0.0, 0.0, 0.0)
        period = 0.01
        plants = {}
        start = time.perf_counter()
        next_frame = 0.0
        frame = 0
        while physics.time_s < SIM_S - 1e-9:
            now, position, q, nu = physics.state_floats()
            if frame % 5 in (0, 2):  # the 40-Hz setpoint: every 2.5 frames
                yaw = math.radians(20.0) * math.sin(2.0 * math.pi * now / 25.0)
                target = quat_from_euler(0.0, 0.0, yaw)
            k = (4 * frame) % 4092
            rates = (
                nu[3] + 0.002 * noise[k],
                nu[4] + 0.002 * noise[k + 1],
                nu[5] + 0.002 * noise[k + 2],
            )
            depth_m = position[2] + 0.002 * noise[k + 3]
            next_frame += period
            interval = max(1, math.ceil((next_frame - now) / physics.dt_s - 1e-6))
            plant = plants.get(interval)
            if plant is None:
                plant = plants[interval] = _arrays_of(vehicle, interval * physics.dt_s).plant
            if compiled:
                wrench, _ = _laws_frame(
                    arrays.loops,
                    arrays.allocation,
                    arrays.tables,
                    plant,
                    (q, rates, depth_m),
                    (0.3, target),
                    zero6,
                    period,
                    requested,
                )
            for _ in range(interval):
                step(wrench)
            frame += 1
        elapsed = time.perf_counter() - start
        if compiled:  # it held depth: the loops flew the real plant
            assert abs(physics.state_floats()[1][2] - 0.3) < 0.05
        return elapsed
    finally:
        vehicle.close()


def test_compiled_laws_frame_with_the_plant_against_floor() -> None:
    """The real plant with a compiled frame of the vehicle's laws, the plant with an empty
    frame, and the bare floor, seven interleaved rounds each (least of each)."""
    _plant_with_frame(compiled=True)  # compile
    best = interleaved_best(
        {
            "floor": lambda: timed_floor(SIM_S),
            "plant": lambda: _plant_with_frame(compiled=False),
            "frame": lambda: _plant_with_frame(compiled=True),
        },
        7,
    )
    frames = 100 * SIM_S
    floor_us, plant_us, frame_us = (best[k] / frames * 1e6 for k in ("floor", "plant", "frame"))
    print(
        f"\nper 100-Hz frame: bare floor {floor_us:.1f} µs; plant with an empty frame "
        f"{plant_us:.1f} µs ({plant_us / floor_us:.2f}x the floor); plant with the compiled "
        f"laws frame {frame_us:.1f} µs ({frame_us / floor_us:.2f}x the floor, "
        f"{SIM_S / best['frame']:.0f}x real time); the frame itself {frame_us - plant_us:.1f} µs"
    )
