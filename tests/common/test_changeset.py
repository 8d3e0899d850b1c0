"""Change-set codec: wire format, mirroring, no echo, ownership, splitting, losses, fuzz."""

from __future__ import annotations

import enum
import struct
from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from testbed.common.changeset import (
    HEADER_SIZE,
    MIN_PAYLOAD,
    ApplyStatus,
    ChangeSet,
    ChangeSetCodec,
    ChangeSetReceiver,
    ChangeSetSender,
)
from testbed.ecs import (
    Change,
    ChangeKind,
    ComponentRegistry,
    Entity,
    Origin,
    Replicate,
    Side,
    World,
    replicated_changes,
)

VEHICLE, OPERATOR = Side.VEHICLE, Side.OPERATOR


class Level(enum.IntEnum):
    NOMINAL = 0
    HOLD = 1
    SURFACE = 2


class Mode(enum.Enum):
    MANUAL = "manual"
    HOLD = "depth-hold"


@dataclass(frozen=True, slots=True)
class Inner:
    ok: bool
    count: int


# operator-owned
@dataclass(frozen=True, slots=True)
class Sticks:
    seq: int
    axes: tuple[float, ...]


@dataclass(frozen=True, slots=True)
class ModeRequest:
    mode: Mode
    precision: bool


# vehicle-owned
@dataclass(frozen=True, slots=True)
class Pose:
    position: tuple[float, float, float]
    heading: float


@dataclass(frozen=True, slots=True)
class Status:
    armed: bool
    level: Level
    inner: Inner


@dataclass(frozen=True, slots=True)
class Note:
    text: str
    data: bytes
    tags: tuple[Mode, ...]


@dataclass(frozen=True, slots=True)
class Forces:
    forces_n: tuple[float, ...]


# never registered
@dataclass(frozen=True, slots=True)
class Local:
    x: float


OPERATOR_TYPES = (Sticks, ModeRequest)
VEHICLE_TYPES = (Pose, Status, Note, Forces)


def make_registry() -> ComponentRegistry:
    registry = ComponentRegistry()
    for type_id, cls in enumerate(OPERATOR_TYPES, start=1):
        registry.register(cls, type_id, OPERATOR)
    for type_id, cls in enumerate(VEHICLE_TYPES, start=10):
        registry.register(cls, type_id, VEHICLE)
    return registry


def replicated_state(
    world: World, registry: ComponentRegistry, owner: Side
) -> dict[Entity, dict[type[Any], object]]:
    """Registered components of ``owner`` on each Replicate entity (entities with none left out)."""
    state: dict[Entity, dict[type[Any], object]] = {}
    for entity, _ in world.query(Replicate):
        comps = {
            type(c): c
            for c in world.components(entity)
            if registry.is_registered(type(c)) and registry.owner_of(type(c)) is owner
        }
        if comps:
            state[entity] = comps
    return state


def assert_mirrored(
    sender_world: World,
    receiver: ChangeSetReceiver,
    receiver_world: World,
    registry: ComponentRegistry,
    owner: Side,
) -> None:
    """The receiver's mirrors hold exactly the sender's replicated components of ``owner``."""
    mirrors = receiver.mirrors()
    sent = replicated_state(sender_world, registry, owner)
    mirrored = {
        remote: comps
        for remote, comps in (
            (remote, replicated_state(receiver_world, registry, owner).get(local, {}))
            for remote, local in mirrors.items()
        )
        if comps
    }
    assert mirrored == sent
    alive_replicated = {e for e, _ in sender_world.query(Replicate)}
    assert set(mirrors) <= alive_replicated  # every sender despawn reached the receiver


def deliver(payloads: list[bytes], receiver: ChangeSetReceiver) -> None:
    for payload in payloads:
        result = receiver.apply(payload)
        assert result.status is ApplyStatus.APPLIED, result.reason


# ------------------------------------------------------------------------------ wire format


def test_wire_format_byte_for_byte() -> None:
    registry = make_registry()
    world = World()
    keep = world.spawn(Replicate(), Status(True, Level.HOLD, Inner(False, 5)))
    gone = world.spawn(Replicate(), Pose((0.0, 0.0, 0.0), 0.0))
    sender = ChangeSetSender(world, registry, VEHICLE)
    first = sender.poll()
    assert first == [
        bytes.fromhex(
            "01 01 0000 02"  # version 1, vehicle, sequence 0, 2 entries
            "01 00000001 000b 12 01 0000000000000001 00 0000000000000005"  # ADDED Status
            "01 00000002 000a 20" + "00" * 32  # ADDED Pose: 4 × 0.0
        )
    ]
    world.set(keep, Status(True, Level.SURFACE, Inner(True, -1)))
    world.set(keep, Note("é", b"\x07", (Mode.HOLD,)))
    world.remove(keep, Status)
    world.despawn(gone)
    assert sender.poll() == [
        bytes.fromhex(
            "01 01 0001 03"
            "03 00000001 000b"  # REMOVED Status (entries by entity, then type id)
            "01 00000001 000c 15 0002 c3a9 0001 07 0001 000a" + b"depth-hold".hex() +  # ADDED Note
            "04 00000002"  # DESPAWNED
        )
    ]  # fmt: skip
    assert sender.poll() == []
    assert sender.next_sequence == 2


def test_first_poll_is_the_full_state_and_snapshot_repeats_it() -> None:
    registry = make_registry()
    world = World()
    world.spawn(Replicate(), Pose((1.0, 2.0, 3.0), 0.5), Sticks(1, (0.0,)), Local(1.0))
    world.spawn(Pose((9.0, 9.0, 9.0), 0.0))  # not replicated
    sender = ChangeSetSender(world, registry, VEHICLE)
    snapshot = sender.snapshot()
    first = sender.poll()
    decoded = ChangeSetCodec(registry).decode(first[0])
    assert isinstance(decoded, ChangeSet)
    assert [(e.kind, e.entity, e.value) for e in decoded.entries] == [
        (ChangeKind.ADDED, 1, Pose((1.0, 2.0, 3.0), 0.5))
    ]
    assert snapshot[0][4:] == first[0][4:] and sender.snapshot()[0][4:] == first[0][4:]


def test_poll_advances_the_tick_so_later_writes_in_the_same_tick_go_next_time() -> None:
    registry = make_registry()
    world = World()
    entity = world.spawn(Replicate(), Pose((0.0, 0.0, 0.0), 0.0))
    sender = ChangeSetSender(world, registry, VEHICLE)
    tick = world.tick
    sender.poll()
    assert sender.last_polled_tick == tick and world.tick == tick + 1
    world.set(entity, Pose((1.0, 0.0, 0.0), 0.0))  # no advance between poll and write
    receiver_world = World()
    receiver = ChangeSetReceiver(receiver_world, registry, OPERATOR)
    deliver(sender.snapshot(), receiver)
    mirror = receiver.local_entity(entity)
    assert mirror is not None
    world.set(entity, Pose((2.0, 0.0, 0.0), 0.0))
    deliver(sender.poll(), receiver)
    assert receiver_world.get(mirror, Pose) == Pose((2.0, 0.0, 0.0), 0.0)


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


def test_a_sender_sends_only_what_its_side_owns() -> None:
    registry = make_registry()
    world = World()
    world.spawn(Replicate(), Sticks(1, (0.0,)), ModeRequest(Mode.HOLD, True), Local(0.0))
    assert ChangeSetSender(world, registry, VEHICLE).poll() == []
    assert len(ChangeSetSender(world, registry, OPERATOR).poll()) == 1


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


# ------------------------------------------------------------------------------ splitting


@pytest.mark.parametrize("max_payload", [MIN_PAYLOAD + 45, 64, 100, 255])
def test_large_change_sets_split_at_entry_boundaries(max_payload: int) -> None:
    registry = make_registry()
    world, mirror_world = World(), World()
    rng = np.random.default_rng(max_payload)
    entities = [
        world.spawn(
            Replicate(),
            Pose((float(rng.normal()), float(rng.normal()), 0.0), float(rng.normal())),
            Status(bool(k % 2), Level(k % 3), Inner(True, k)),
        )
        for k in range(40)
    ]
    sender = ChangeSetSender(world, registry, VEHICLE, max_payload=max_payload)
    receiver = ChangeSetReceiver(mirror_world, registry, OPERATOR)
    payloads = sender.poll()
    sizes = [len(p) for p in payloads]
    assert max(sizes) <= max_payload
    # 40 × (Pose 8+32 B, Status 8+18 B), packed greedily in order: an independent count
    expected, room = 1, max_payload - HEADER_SIZE
    for entry_size in [40, 26] * 40:
        if entry_size > room:
            expected, room = expected + 1, max_payload - HEADER_SIZE
        room -= entry_size
    assert len(payloads) == expected
    assert sum(sizes) == len(payloads) * HEADER_SIZE + 40 * (40 + 26)
    deliver(payloads, receiver)
    assert_mirrored(world, receiver, mirror_world, registry, VEHICLE)
    for entity in entities[::3]:
        world.despawn(entity)
    deliver(sender.poll(), receiver)
    assert_mirrored(world, receiver, mirror_world, registry, VEHICLE)


def test_entry_count_caps_a_payload_at_255_entries() -> None:
    registry = make_registry()
    changes = [Change(Entity(k), ChangeKind.DESPAWNED, None, None, None, 1) for k in range(300)]
    payloads = ChangeSetCodec(registry, max_payload=4000).encode(changes, VEHICLE, 65535)
    assert [p[4] for p in payloads] == [255, 45]
    assert [struct.unpack(">H", p[2:4])[0] for p in payloads] == [65535, 0]  # wraps


def test_entries_that_cannot_fit_are_local_errors_naming_the_type() -> None:
    registry = make_registry()
    with pytest.raises(ValueError, match="Pose"):
        ChangeSetSender(World(), registry, VEHICLE, max_payload=MIN_PAYLOAD + 31)  # Pose: 32 B
    ChangeSetSender(World(), registry, OPERATOR, max_payload=MIN_PAYLOAD + 31)  # owns no Pose
    with pytest.raises(ValueError, match="at least"):
        ChangeSetCodec(registry, max_payload=MIN_PAYLOAD - 1)
    world = World()
    entity = world.spawn(Replicate(), Forces(tuple([1.0] * 31)))  # 2 + 248 B > 255 − 13
    sender = ChangeSetSender(world, registry, VEHICLE)
    for _ in range(2):  # a failed poll marks nothing as sent
        with pytest.raises(ValueError, match="Forces encodes to 250 B"):
            sender.poll()
    world.set(entity, Forces(tuple([1.0] * 30)))
    (payload,) = sender.poll()
    assert len(payload) == 255 and sender.next_sequence == 1


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


# ------------------------------------------------------------------------------ malformed


def _valid_payload(registry: ComponentRegistry) -> bytes:
    world = World()
    status = Status(True, Level.HOLD, Inner(True, 2))
    world.spawn(Replicate(), status, Note("ab", b"", (Mode.MANUAL,)))
    (payload,) = ChangeSetSender(world, registry, VEHICLE).poll()
    return payload


def test_malformed_payloads_are_dropped_and_counted() -> None:
    registry = make_registry()
    valid = _valid_payload(registry)
    # header(5) · ADDED Status: kind, entity, type 000b, length 18 B · armed, level i64, inner
    # · ADDED Note: kind, entity, type 000c, length 16 B · text 0002 'ab', data 0000, tags …
    assert valid[5:13] == bytes.fromhex("01 00000001 000b 12")
    assert valid[31:39] == bytes.fromhex("01 00000001 000c 10")
    status, note = 13, 39
    cases = {
        "short header": valid[:4],
        "wrong version": b"\x02" + valid[1:],
        "unknown side": valid[:1] + b"\x03" + valid[2:],
        "unknown kind": valid[:5] + b"\x05" + valid[6:],
        "unknown type id": valid[:10] + b"\x00\x63" + valid[12:],
        "truncated": valid[:-1],
        "count too high": valid[:4] + b"\x03" + valid[5:],
        "count too low": valid[:4] + b"\x01" + valid[5:],
        "trailing byte": valid + b"\x00",
        "bad utf-8": valid[:note + 2] + b"\xff\xfe" + valid[note + 4 :],
        "bad bool": valid[:status] + b"\x02" + valid[status + 1 :],
        "bad enum": valid[:status + 1] + b"\x00" * 7 + b"\x09" + valid[status + 9 :],
        "value length too long": valid[:12] + b"\x13" + valid[13:],
        "value length too short": valid[:12] + b"\x11" + valid[13:],
        "str enum": valid.replace(b"manual", b"manuel"),
    }  # fmt: skip
    receiver = ChangeSetReceiver(World(), registry, OPERATOR)
    assert receiver.apply(valid).status is ApplyStatus.APPLIED
    world_before = receiver.mirrors()
    for name, payload in cases.items():
        result = receiver.apply(payload)
        assert result.status is ApplyStatus.MALFORMED, name
        assert result.reason and result.sequence is None, name
    assert receiver.malformed == len(cases) and receiver.mirrors() == world_before
    assert receiver.payloads_received == len(cases) + 1


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


def test_periodic_snapshots_keep_the_removal_log_bounded() -> None:
    """A peer churning mirrors (16 spawned and despawned a cycle; a despawned mirror logs its
    two components and itself: 48 rows a cycle): with a snapshot every 50 cycles the receiving
    world's removal log holds at most two snapshot periods of removals (it grew by 48 rows a
    cycle, forever), and a despawn made since the
    previous snapshot is still repeated by the next one."""
    from testbed.common.components import MovementCommand
    from testbed.ecs import Change, ChangeKind, Side, World
    from testbed.run.links import make_registry

    registry = make_registry()
    codec = ChangeSetCodec(registry)
    type_id = {entry.cls: entry.type_id for entry in registry}
    world = World()
    receiver = ChangeSetReceiver(world, registry, Side.VEHICLE, max_entities=16)
    sender = ChangeSetSender(world, registry, Side.VEHICLE)
    command = MovementCommand(1, 0.0, (0.0,) * 6)
    sequence, longest = 0, 0
    for cycle in range(1000):
        ids = range(cycle * 16, cycle * 16 + 16)
        changes = [
            Change(e, ChangeKind.ADDED, MovementCommand, type_id[MovementCommand], command, 0)
            for e in ids
        ]
        changes += [Change(e, ChangeKind.DESPAWNED, None, None, None, 0) for e in ids]
        for payload in codec.encode(changes, Side.OPERATOR, sequence):
            receiver.apply(payload)
            sequence += 1
        world.advance()
        sender.poll()
        if cycle % 50 == 49:
            sender.snapshot()
        longest = max(longest, len(world.removals_since(0)))
    assert receiver.payloads_applied == sequence
    assert longest <= 2 * 50 * 48 + 48
    own = world.spawn(Replicate(), command)
    sender.poll()
    world.despawn(own)
    sender.poll()  # the despawn goes out, then is lost on the way (say)
    repeated = [codec.decode(p) for p in sender.snapshot()]
    despawns = [e for s in repeated if isinstance(s, ChangeSet) for e in s.entries]
    assert any(e.kind is ChangeKind.DESPAWNED and e.entity == own for e in despawns)
