"""Change-set codec cost: a typical vehicle change set (9 state components), encoded and applied.

Every frame the vehicle changes all nine of its replicated state components (IMU, depth, position
fix, armed, mode, control targets, failsafe, command status, 8-thruster outputs), polls its
:class:`ChangeSetSender` and the operator's :class:`ChangeSetReceiver` applies the payloads. The
component values are built beforehand, so only ``world.set`` + poll + apply are timed. Reported as
change sets per second and as the real-time factor of a 100 Hz replication loop; a second test
times the bytes part alone (codec encode + decode of the same nine changes, no worlds). Run:

    .venv/bin/python -m pytest benchmarks/test_changeset_bench.py -m benchmark --benchmark-enable
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from testbed.common import ChangeSetCodec, ChangeSetReceiver, ChangeSetSender
from testbed.common.changeset import ChangeSet
from testbed.ecs import ComponentRegistry, Replicate, Side, World, replicated_changes
from testbed.vehicle.components import (
    ActiveMode,
    Armed,
    CommandStatus,
    ControlMode,
    ControlTargets,
    DepthReading,
    FailsafeLevel,
    FailsafeStatus,
    ImuReading,
    PositionReading,
    ThrusterOutput,
    register_components,
)

RATE_HZ = 100.0
THRUSTERS = 8
VARIANTS = 64
FRAMES_PER_ROUND = 100


def vec3(rng: np.random.Generator) -> tuple[float, float, float]:
    x, y, z = rng.normal(size=3).tolist()
    return (x, y, z)


def vehicle_states(rng: np.random.Generator) -> list[tuple[object, ...]]:
    """``VARIANTS`` full sets of the vehicle's replicated state, all values differing."""
    states = []
    for k in range(VARIANTS):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        quaternion = (float(q[0]), float(q[1]), float(q[2]), float(q[3]))
        t = 0.01 * k
        forces = rng.normal(0.0, 10.0, THRUSTERS)
        states.append(
            (
                ImuReading(t, quaternion, vec3(rng)),
                DepthReading(t, 101325.0 + 9806.65 * k, float(k)),
                PositionReading(t, vec3(rng)),
                Armed(k % 2 == 0),
                ActiveMode((ControlMode.MANUAL, ControlMode.DEPTH_HOLD)[k % 2], k % 4 == 0),
                ControlTargets(float(k), quaternion),
                FailsafeStatus((FailsafeLevel.NOMINAL, FailsafeLevel.HOLD)[k % 2], t),
                CommandStatus(k, t, 0.05 + 0.001 * k),
                ThrusterOutput(
                    tuple(forces.tolist()),
                    tuple((1500.0 + 10.0 * forces).tolist()),
                    tuple(np.abs(forces).tolist()),
                    1.0,
                ),
            )
        )
    return states


def build(seed: int) -> tuple[Callable[[], tuple[int, int]], ChangeSetReceiver, World]:
    """A vehicle world and an operator world joined by a sender/receiver pair."""
    registry = ComponentRegistry()
    register_components(registry)
    vehicle, operator = World(), World()
    states = vehicle_states(np.random.default_rng(seed))
    rov = vehicle.spawn(Replicate(), *states[0])
    sender = ChangeSetSender(vehicle, registry, Side.VEHICLE)
    receiver = ChangeSetReceiver(operator, registry, Side.OPERATOR)
    for payload in sender.poll():
        receiver.apply(payload)
    frame = [0]

    def replicate_frame() -> tuple[int, int]:
        """One frame: set all nine, poll, apply; returns (payloads, bytes)."""
        frame[0] += 1
        for component in states[frame[0] % VARIANTS]:
            vehicle.set(rov, component)
        payloads = sender.poll()
        size = 0
        for payload in payloads:
            receiver.apply(payload)
            size += len(payload)
        return len(payloads), size

    return replicate_frame, receiver, operator


@pytest.mark.benchmark
def test_vehicle_change_set_encode_and_apply(benchmark: pytest.FixtureDef) -> None:  # type: ignore[type-arg]
    replicate_frame, receiver, operator = build(seed=20240612)
    sent: list[tuple[int, int]] = []

    def hundred_frames() -> None:
        for _ in range(FRAMES_PER_ROUND):
            sent.append(replicate_frame())

    benchmark.pedantic(hundred_frames, rounds=30, warmup_rounds=2)
    assert receiver.malformed == receiver.rejected_ownership == receiver.lost_payloads == 0
    assert receiver.entries_applied == 9 * (1 + len(sent))
    (mirror,) = operator.entities()
    assert len(operator.components(mirror)) == 1 + 9
    payloads_per_set = sum(n for n, _ in sent) / len(sent)
    bytes_per_set = sum(b for _, b in sent) / len(sent)
    stats = benchmark.stats.stats
    benchmark.extra_info["payloads_per_change_set"] = payloads_per_set
    benchmark.extra_info["bytes_per_change_set"] = bytes_per_set
    for label, seconds in (("min", stats.min), ("median", stats.median)):
        set_s = seconds / FRAMES_PER_ROUND
        per_s = 1.0 / set_s
        benchmark.extra_info[f"change_set_us_{label}"] = set_s * 1e6
        benchmark.extra_info[f"change_sets_per_s_{label}"] = per_s
        benchmark.extra_info[f"real_time_factor_100hz_{label}"] = per_s / RATE_HZ
        print(
            f"\nvehicle change set ({label}): {set_s * 1e6:.1f} µs encode+apply, "
            f"{per_s:,.0f} change sets/s, {per_s / RATE_HZ:,.0f}× real time at {RATE_HZ:.0f} Hz, "
            f"{payloads_per_set:.0f} payloads ({bytes_per_set:.0f} B) per set"
        )


@pytest.mark.benchmark
def test_vehicle_change_set_codec_alone(benchmark: pytest.FixtureDef) -> None:  # type: ignore[type-arg]
    """The bytes part alone: encode the nine changes and decode the payloads, no worlds."""
    registry = ComponentRegistry()
    register_components(registry)
    world = World()
    world.spawn(Replicate(), *vehicle_states(np.random.default_rng(20240612))[0])
    changes = replicated_changes(world, 0, registry, side=Side.VEHICLE)
    codec = ChangeSetCodec(registry)

    def hundred_round_trips() -> None:
        for _ in range(FRAMES_PER_ROUND):
            for payload in codec.encode(changes, Side.VEHICLE, 0):
                codec.decode(payload)

    benchmark.pedantic(hundred_round_trips, rounds=30, warmup_rounds=2)
    decoded = [codec.decode(p) for p in codec.encode(changes, Side.VEHICLE, 0)]
    values = [e.value for d in decoded if isinstance(d, ChangeSet) for e in d.entries]
    assert values == [c.value for c in changes]
    set_s = benchmark.stats.stats.min / FRAMES_PER_ROUND
    benchmark.extra_info["codec_round_trip_us_min"] = set_s * 1e6
    print(f"\nvehicle change set, codec alone (min): {set_s * 1e6:.1f} µs encode+decode")
