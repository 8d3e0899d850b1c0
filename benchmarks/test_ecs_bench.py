"""ECS frame cost: a vehicle-sized world (36 entities) doing ~20 sets and ~20 queries per frame.

Reported as frames per second and as the real-time factor of a 100 Hz vehicle loop
(frames/s ÷ 100). Target: ≥ 300× real time leaves ~33 µs per frame for everything, so the ECS
share must be tens of microseconds. Run:

    .venv/bin/python -m pytest benchmarks/test_ecs_bench.py -m benchmark --benchmark-enable
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pytest

from testbed.ecs import Phase, Replicate, Schedule, World

VEHICLE_RATE_HZ = 100.0
ENTITY_COUNT = 36
THRUSTERS = 8


@dataclass(frozen=True, slots=True)
class Depth:
    depth_m: float


@dataclass(frozen=True, slots=True)
class Attitude:
    roll_rad: float
    pitch_rad: float
    yaw_rad: float


@dataclass(frozen=True, slots=True)
class Intent:
    surge_n: float
    heave_n: float


@dataclass(frozen=True, slots=True)
class ThrusterCommand:
    force_n: float


@dataclass(frozen=True, slots=True)
class Armed:
    armed: bool


def build(seed: int) -> tuple[World, Callable[[], None]]:
    """A world like the vehicle's: one ROV entity, 8 thrusters, 27 misc entities; 7 systems."""
    rng = np.random.default_rng(seed)
    world = World()
    rov = world.spawn(Replicate(), Depth(0.0), Attitude(0.0, 0.0, 0.0), Intent(0, 0), Armed(True))
    thrusters = [world.spawn(ThrusterCommand(0.0)) for _ in range(THRUSTERS)]
    for i in range(ENTITY_COUNT - 1 - THRUSTERS):
        world.spawn(Depth(float(i)), Armed(bool(i % 2)))
    noise = rng.normal(0.0, 0.01, size=4096).tolist()
    frame = [0]

    def read_sensors(world: World) -> None:  # 2 sets (changing)
        k = frame[0]
        world.set(rov, Depth(1.0 + noise[k % 4096]))
        world.set(rov, Attitude(0.0, 0.0, noise[(k + 7) % 4096]))

    def ingest_commands(world: World) -> None:  # 1 set (usually equal), 1 query
        for _ in world.query1(Intent, changed=True):
            pass
        world.set(rov, Intent(10.0, 0.0))

    def control_depth(world: World) -> None:  # 2 queries, 1 set
        for _, (depth, _intent) in world.query(Depth, Intent, changed=True):
            world.set(rov, Intent(10.0, -depth.depth_m))
        world.get(rov, Armed)

    def allocate_thrust(world: World) -> None:  # 8 sets, 9 queries
        _, intent = next(world.query1(Intent))
        for i, entity in enumerate(thrusters):
            world.set(entity, ThrusterCommand(intent.heave_n / THRUSTERS + i))
            world.has(entity, ThrusterCommand)
        for _ in range(8):
            for _ in world.query(Armed, Depth):
                break

    def check_failsafe(world: World) -> None:  # 1 query over 28 entities, 1 set (equal)
        armed = sum(1 for _, a in world.query1(Armed) if a.armed)
        world.set(rov, Armed(armed > 0))

    def actuate_thrusters(world: World) -> None:  # 1 query over 8 thrusters
        for _ in world.query1(ThrusterCommand, changed=True):
            pass

    def replicate_out(world: World) -> None:  # 6 queries (changed, replicated), 4 equal sets
        for cls in (Depth, Attitude, Intent, Armed, ThrusterCommand, Replicate):
            for _ in world.query(cls, Replicate, changed=True):
                pass
        for entity in thrusters[:4]:
            world.set(entity, world.get_or(entity, ThrusterCommand, ThrusterCommand(0.0)))

    schedule = Schedule()
    schedule.add(Phase.PRE_UPDATE, read_sensors)
    schedule.add(Phase.PRE_UPDATE, ingest_commands)
    schedule.add(Phase.UPDATE, control_depth)
    schedule.add(Phase.UPDATE, allocate_thrust)
    schedule.add(Phase.UPDATE, check_failsafe)
    schedule.add(Phase.POST_UPDATE, actuate_thrusters)
    schedule.add(Phase.POST_UPDATE, replicate_out)

    def run_frame() -> None:
        frame[0] += 1
        schedule.run(world)

    return world, run_frame


@pytest.mark.benchmark
def test_vehicle_sized_frame(benchmark: pytest.FixtureDef) -> None:  # type: ignore[type-arg]
    world, run_frame = build(seed=20240501)
    frames_per_round = 100

    def hundred_frames() -> None:
        for _ in range(frames_per_round):
            run_frame()

    benchmark.pedantic(hundred_frames, rounds=30, warmup_rounds=2)
    stats = benchmark.stats.stats
    for label, seconds in (("min", stats.min), ("median", stats.median)):
        frame_s = seconds / frames_per_round
        frames_per_s = 1.0 / frame_s
        benchmark.extra_info[f"frame_us_{label}"] = frame_s * 1e6
        benchmark.extra_info[f"real_time_factor_100hz_{label}"] = frames_per_s / VEHICLE_RATE_HZ
        print(
            f"\nECS frame ({label}): {frame_s * 1e6:.1f} µs, {frames_per_s:,.0f} frames/s, "
            f"{frames_per_s / VEHICLE_RATE_HZ:,.0f}× real time at {VEHICLE_RATE_HZ:.0f} Hz"
        )
    assert world.tick == 1 + 7 * frames_per_round * 32  # 7 systems, 32 rounds of 100 frames


@pytest.mark.benchmark
def test_twenty_sets_twenty_queries(benchmark: pytest.FixtureDef) -> None:  # type: ignore[type-arg]
    """ECS operations alone: values are built beforehand, so only set/query cost is timed.

    Per frame: 20 sets (10 changing, 10 equal) and 20 queries (8 single-type, 8 two-type,
    4 change-filtered) on 36 entities, through a one-system schedule.
    """
    rng = np.random.default_rng(7)
    world = World()
    entities = [world.spawn(Depth(float(i)), Armed(True)) for i in range(ENTITY_COUNT)]
    world.set(entities[0], Replicate())
    depths = [Depth(float(x)) for x in rng.normal(size=2)]
    same = Armed(True)
    frame = [0]

    def do_frame(world: World) -> None:
        new = depths[frame[0] % 2]
        for entity in entities[:10]:
            world.set(entity, new)
            world.set(entity, same)
        for _ in range(8):
            for _ in world.query1(Depth):
                break
            for _ in world.query(Depth, Replicate):
                pass
        for _ in range(4):
            for _ in world.query(Depth, changed=True):
                pass

    schedule = Schedule()
    schedule.add(Phase.UPDATE, do_frame)
    frames_per_round = 100

    def hundred_frames() -> None:
        for _ in range(frames_per_round):
            frame[0] += 1
            schedule.run(world)

    benchmark.pedantic(hundred_frames, rounds=30, warmup_rounds=2)
    frame_s = benchmark.stats.stats.min / frames_per_round
    benchmark.extra_info["frame_us_min"] = frame_s * 1e6
    print(f"\n20 sets + 20 queries: {frame_s * 1e6:.1f} µs per frame (min)")
    assert world.get(entities[0], Depth) == depths[frame[0] % 2]
