"""Change-set receiver: mirroring without echo (property test), both directions, ownership and
capacity checks, sequence losses and resync, and a fuzz of the apply path."""

from __future__ import annotations

from typing import Any

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from testbed.common.changeset import ChangeSetCodec
from testbed.common.changeset_receiver import ApplyStatus, ChangeSetReceiver
from testbed.common.changeset_sender import ChangeSetSender
from testbed.ecs import Change, ChangeKind, Entity, Origin, Replicate, World, replicated_changes
from tests.common.changeset_helpers import (
    OPERATOR,
    VEHICLE,
    VEHICLE_TYPES,
    Forces,
    Inner,
    Level,
    Local,
    Mode,
    ModeRequest,
    Note,
    Pose,
    Status,
    Sticks,
    assert_mirrored,
    deliver,
    make_registry,
)

# ------------------------------------------------------------------------------ mirroring

ENTITY_REF = st.integers(0, 30)
vehicle_values = st.one_of(
    st.builds(
        Pose,
        st.tuples(*[st.floats(allow_nan=False)] * 3),
        st.floats(allow_nan=False, allow_infinity=False),
    ),
    st.builds(
        Status,
        st.booleans(),
        st.sampled_from(Level),
        st.builds(Inner, st.booleans(), st.integers(-(2**63), 2**63 - 1)),
    ),
    st.builds(
        Note,
        st.text(max_size=8),
        st.binary(max_size=8),
        st.lists(st.sampled_from(Mode), max_size=3).map(tuple),
    ),
    st.builds(Forces, st.lists(st.floats(allow_nan=False), max_size=8).map(tuple)),
)
other_values = st.one_of(
    st.builds(Sticks, st.integers(0, 9), st.tuples(st.floats(-1, 1))),
    st.builds(Local, st.floats(allow_nan=False)),
)
operations = st.lists(
    st.one_of(
        st.tuples(st.just("spawn"), st.booleans(), st.lists(vehicle_values, max_size=3)),
        st.tuples(st.just("set"), ENTITY_REF, vehicle_values),
        st.tuples(st.just("set_other"), ENTITY_REF, other_values),
        st.tuples(st.just("remove"), ENTITY_REF, st.sampled_from((*VEHICLE_TYPES, Sticks))),
        st.tuples(st.just("despawn"), ENTITY_REF),
        st.tuples(st.just("replicate"), ENTITY_REF),
        st.tuples(st.just("advance")),
        st.tuples(st.just("poll")),
    ),
    max_size=60,
)


def run_operation(world: World, entities: list[Entity], op: tuple[Any, ...]) -> None:
    alive = [e for e in entities if world.is_alive(e)]
    name = op[0]
    if name == "spawn":
        _, replicated, values = op
        unique = list({type(v): v for v in values}.values())
        entities.append(world.spawn(*([Replicate()] if replicated else []), *unique))
    elif name == "advance":
        world.advance()
    elif alive:
        entity = alive[op[1] % len(alive)]
        if name in ("set", "set_other"):
            world.set(entity, op[2])
        elif name == "remove":
            world.remove(entity, op[2])
        elif name == "despawn":
            world.despawn(entity)
        elif name == "replicate":
            world.set(entity, Replicate())


@settings(max_examples=150, deadline=None)
@given(operations)
def test_receiver_mirrors_the_sender_and_nothing_echoes(ops: list[tuple[Any, ...]]) -> None:
    registry = make_registry()
    vehicle_world, operator_world = World(), World()
    sender = ChangeSetSender(vehicle_world, registry, VEHICLE, max_payload=100)
    receiver = ChangeSetReceiver(operator_world, registry, OPERATOR)
    echo = ChangeSetSender(operator_world, registry, OPERATOR)
    echo.poll()
    entities: list[Entity] = []
    for op in [*ops, ("poll",)]:
        if op[0] != "poll":
            run_operation(vehicle_world, entities, op)
            continue
        payloads = sender.poll()
        assert all(len(p) <= 100 for p in payloads)
        deliver(payloads, receiver)
        assert_mirrored(vehicle_world, receiver, operator_world, registry, VEHICLE)
        assert echo.poll() == []  # REMOTE writes are never sent back
        assert replicated_changes(operator_world, 0, registry) == []
    assert receiver.lost_payloads == 0 and receiver.out_of_order == 0
    assert receiver.payloads_received == receiver.payloads_applied == sender.next_sequence
    for _, local in receiver.mirrors().items():  # only the sender's registered types arrive
        types = {type(c) for c in operator_world.components(local)}
        assert types <= {Replicate, *VEHICLE_TYPES}


def test_both_directions_at_once() -> None:
    registry = make_registry()
    vehicle_world, operator_world = World(), World()
    vehicle_out = ChangeSetSender(vehicle_world, registry, VEHICLE)
    operator_out = ChangeSetSender(operator_world, registry, OPERATOR)
    vehicle_in = ChangeSetReceiver(vehicle_world, registry, VEHICLE)
    operator_in = ChangeSetReceiver(operator_world, registry, OPERATOR)
    rov = vehicle_world.spawn(Replicate(), Pose((0.0, 0.0, 1.0), 0.0))
    pilot = operator_world.spawn(Replicate(), Sticks(1, (0.5, -0.5)))
    for k in range(5):
        vehicle_world.set(rov, Pose((0.0, 0.0, 1.0 + k), 0.1 * k))
        operator_world.set(pilot, Sticks(k, (0.1 * k,)))
        deliver(operator_out.poll(), vehicle_in)
        deliver(vehicle_out.poll(), operator_in)
    assert_mirrored(vehicle_world, operator_in, operator_world, registry, VEHICLE)
    assert_mirrored(operator_world, vehicle_in, vehicle_world, registry, OPERATOR)
    assert vehicle_out.poll() == [] and operator_out.poll() == []
    (mirror,) = vehicle_in.mirrors().values()
    assert vehicle_world.origin_of(mirror, Sticks) is Origin.REMOTE


def test_removed_and_despawned_for_unknown_entities_are_no_ops() -> None:
    registry = make_registry()
    world = World()
    receiver = ChangeSetReceiver(world, registry, OPERATOR)
    codec = ChangeSetCodec(registry)
    changes = [
        Change(Entity(7), ChangeKind.REMOVED, Pose, 10, None, 1),
        Change(Entity(8), ChangeKind.DESPAWNED, None, None, None, 1),
        Change(Entity(9), ChangeKind.CHANGED, Pose, 10, Pose((1.0, 1.0, 1.0), 1.0), 1),
    ]
    (payload,) = codec.encode(changes, VEHICLE, 0)
    result = receiver.apply(payload)
    assert (result.status, result.entries, result.spawned) == (ApplyStatus.APPLIED, 3, 1)
    assert world.entities() == [receiver.local_entity(9)]
    assert receiver.local_entity(7) is None and receiver.local_entity(8) is None


# ------------------------------------------------------------------------------ ownership


def test_ownership_violations_are_dropped_whole_and_counted() -> None:
    registry = make_registry()
    world = World()
    own = world.spawn(Replicate(), Sticks(1, (0.0,)))
    receiver = ChangeSetReceiver(world, registry, OPERATOR)
    codec = ChangeSetCodec(registry)
    good = Change(Entity(1), ChangeKind.ADDED, Pose, 10, Pose((1.0, 2.0, 3.0), 0.0), 1)
    bad = Change(Entity(1), ChangeKind.ADDED, Sticks, 1, Sticks(99, (1.0,)), 1)
    removal = Change(Entity(1), ChangeKind.REMOVED, ModeRequest, 2, None, 1)
    before = (world.tick, world.entities(), world.components(own), world.changed_tick(own, Sticks))
    for changes, side in (
        ([good, bad], VEHICLE),  # one good and one forbidden entry: nothing applies
        ([removal], VEHICLE),
        ([good], OPERATOR),  # claims to come from the receiver's own side
    ):
        (payload,) = codec.encode(changes, side, 0)
        result = receiver.apply(payload)
        assert result.status is ApplyStatus.REJECTED_OWNERSHIP and result.entries == 0
    assert receiver.rejected_ownership == 3 and receiver.payloads_applied == 0
    after = (world.tick, world.entities(), world.components(own), world.changed_tick(own, Sticks))
    assert after == before and receiver.mirrors() == {}
    (payload,) = codec.encode([good], VEHICLE, 1)
    assert receiver.apply(payload).status is ApplyStatus.APPLIED


def test_capacity_bound_rejects_payloads_spawning_too_many_mirrors() -> None:
    registry = make_registry()
    world = World()
    receiver = ChangeSetReceiver(world, registry, OPERATOR, max_entities=3)
    codec = ChangeSetCodec(registry)

    def added(entity: int) -> Change:
        return Change(Entity(entity), ChangeKind.ADDED, Forces, 13, Forces(()), 1)

    (two,) = codec.encode([added(1), added(2)], VEHICLE, 0)
    (two_more,) = codec.encode([added(2), added(3), added(4)], VEHICLE, 1)
    (one_more,) = codec.encode([added(3)], VEHICLE, 2)
    assert receiver.apply(two).status is ApplyStatus.APPLIED
    assert receiver.apply(two_more).status is ApplyStatus.REJECTED_CAPACITY
    assert receiver.apply(one_more).status is ApplyStatus.APPLIED
    assert len(world.entities()) == 3 and receiver.rejected_capacity == 1


# ------------------------------------------------------------------------------ losses


def test_sequence_gaps_and_snapshot_resync() -> None:
    registry = make_registry()
    world, mirror_world = World(), World()
    sender = ChangeSetSender(world, registry, VEHICLE)
    receiver = ChangeSetReceiver(mirror_world, registry, OPERATOR)
    rov = world.spawn(Replicate(), Pose((0.0, 0.0, 0.0), 0.0))
    spare = world.spawn(Replicate(), Status(False, Level.NOMINAL, Inner(False, 0)))
    deliver(sender.poll(), receiver)
    world.set(rov, Pose((1.0, 0.0, 0.0), 0.0))
    world.despawn(spare)
    lost = sender.poll()  # never delivered
    world.set(rov, Note("x", b"", ()))
    (late,) = sender.poll()
    result = receiver.apply(late)
    assert result.lost == 1 and receiver.lost_payloads == 1
    mirror = receiver.local_entity(rov)
    assert mirror is not None
    assert mirror_world.get(mirror, Pose) == Pose((0.0, 0.0, 0.0), 0.0)  # the update was lost
    assert receiver.local_entity(spare) is not None  # so was the despawn
    assert len(lost) == 1
    deliver(sender.snapshot(), receiver)
    assert_mirrored(world, receiver, mirror_world, registry, VEHICLE)
    assert receiver.local_entity(spare) is None


def test_sequence_wraps_and_backward_steps_are_out_of_order() -> None:
    registry = make_registry()
    receiver = ChangeSetReceiver(World(), registry, OPERATOR)
    codec = ChangeSetCodec(registry)
    despawn = [Change(Entity(1), ChangeKind.DESPAWNED, None, None, None, 1)]

    def at(sequence: int) -> bytes:
        return codec.encode(despawn, VEHICLE, sequence)[0]

    assert [receiver.apply(at(s)).lost for s in (65534, 65535, 0, 3)] == [0, 0, 0, 2]
    assert receiver.apply(at(3)).lost == 0  # duplicate: out of order, not a gap
    assert receiver.apply(at(0)).lost == 0  # sender restarted
    assert receiver.apply(at(1)).lost == 0
    assert (receiver.lost_payloads, receiver.out_of_order, receiver.payloads_applied) == (2, 2, 7)


# ------------------------------------------------------------------------------ fuzz


def _mutate(payload: bytes, corpus: list[bytes], rng: np.random.Generator) -> bytes:
    data = bytearray(payload)
    for _ in range(int(rng.integers(1, 4))):
        choice = int(rng.integers(0, 7))
        at = int(rng.integers(0, len(data) + 1))
        if choice == 0 and data:  # flip a bit
            at = min(at, len(data) - 1)
            data[at] ^= 1 << int(rng.integers(0, 8))
        elif choice == 1 and data:  # replace a byte
            data[min(at, len(data) - 1)] = int(rng.integers(0, 256))
        elif choice == 2:  # truncate
            del data[at:]
        elif choice == 3:  # append garbage
            data += rng.bytes(int(rng.integers(1, 8)))
        elif choice == 4:  # insert a byte
            data.insert(at, int(rng.integers(0, 256)))
        elif choice == 5 and data:  # delete a byte
            del data[min(at, len(data) - 1)]
        else:  # splice with another payload
            other = corpus[int(rng.integers(0, len(corpus)))]
            data = data[:at] + other[int(rng.integers(0, len(other) + 1)) :]
    return bytes(data)


def test_fuzz_apply_never_raises_and_counters_add_up() -> None:
    registry = make_registry()
    rng = np.random.default_rng(20240611)
    vehicle, operator = World(), World()
    vehicle_out = ChangeSetSender(vehicle, registry, VEHICLE)
    operator_out = ChangeSetSender(operator, registry, OPERATOR)
    corpus: list[bytes] = []
    for k in range(30):
        entity = vehicle.spawn(
            Replicate(),
            Pose((float(k), -float(k), 0.5), 1.0),
            Note("n" * (k % 5), bytes([k]), (Mode.HOLD,) * (k % 3)),
            Forces(tuple(float(x) for x in range(k % 9))),
        )
        vehicle.set(entity, Status(bool(k % 2), Level(k % 3), Inner(True, k)))
        if k % 4 == 0:
            vehicle.remove(entity, Note)
        if k % 7 == 0:
            vehicle.despawn(entity)
        operator.spawn(Replicate(), Sticks(k, (0.1,) * (k % 6)), ModeRequest(Mode.HOLD, True))
        corpus += vehicle_out.poll() + operator_out.poll()
    own = operator.spawn(Replicate(), Sticks(-1, (1.0,)))
    receiver = ChangeSetReceiver(operator, registry, OPERATOR, max_entities=64)
    entries = 0
    statuses = dict.fromkeys(ApplyStatus, 0)
    n = 50_000
    for i in range(n):
        if i % 4 == 0:
            payload = rng.bytes(int(rng.integers(0, 300)))
        else:
            payload = _mutate(corpus[int(rng.integers(0, len(corpus)))], corpus, rng)
        result = receiver.apply(payload)
        statuses[result.status] += 1
        entries += result.entries
    assert receiver.payloads_received == n
    assert statuses == {
        ApplyStatus.APPLIED: receiver.payloads_applied,
        ApplyStatus.REJECTED_OWNERSHIP: receiver.rejected_ownership,
        ApplyStatus.REJECTED_CAPACITY: receiver.rejected_capacity,
        ApplyStatus.MALFORMED: receiver.malformed,
    }
    assert entries == receiver.entries_applied
    assert min(statuses.values()) > 0  # every outcome was exercised
    assert operator.get(own, Sticks) == Sticks(-1, (1.0,))
    assert operator.origin_of(own, Sticks) is Origin.LOCAL
    mirrors = set(receiver.mirrors().values())
    for entity in operator.entities():
        if entity in mirrors:
            types = {type(c) for c in operator.components(entity)}
            assert types <= {Replicate, *VEHICLE_TYPES}
