"""Change-set wire format and codec: bytes by hand, splitting at entry boundaries, entry size
limits, malformed payloads."""

from __future__ import annotations

import struct

import numpy as np
import pytest

from testbed.common.changeset import HEADER_SIZE, MIN_PAYLOAD, ChangeSetCodec
from testbed.common.changeset_receiver import ApplyStatus, ChangeSetReceiver
from testbed.common.changeset_sender import ChangeSetSender
from testbed.ecs import Change, ChangeKind, ComponentRegistry, Entity, Replicate, World
from tests.common.changeset_helpers import (
    OPERATOR,
    VEHICLE,
    Forces,
    Inner,
    Level,
    Mode,
    Note,
    Pose,
    Status,
    assert_mirrored,
    deliver,
    make_registry,
)

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
