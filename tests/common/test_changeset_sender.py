"""Change-set sender: the first poll and snapshots carry the full owned state, the poll mark,
only the owning side sends, and periodic snapshots keep the removal log bounded."""

from __future__ import annotations

import struct

from testbed.common.changeset import ChangeSet, ChangeSetCodec
from testbed.common.changeset_receiver import ChangeSetReceiver
from testbed.common.changeset_sender import ChangeSetSender
from testbed.ecs import ChangeKind, FrameStore, Replicate, World
from tests.common.changeset_helpers import (
    OPERATOR,
    VEHICLE,
    Forces,
    Local,
    Mode,
    ModeRequest,
    Pose,
    Sticks,
    deliver,
    make_registry,
)


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


def test_a_sender_sends_only_what_its_side_owns() -> None:
    registry = make_registry()
    world = World()
    world.spawn(Replicate(), Sticks(1, (0.0,)), ModeRequest(Mode.HOLD, True), Local(0.0))
    assert ChangeSetSender(world, registry, VEHICLE).poll() == []
    assert len(ChangeSetSender(world, registry, OPERATOR).poll()) == 1


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


def test_a_row_written_in_the_store_goes_out_as_the_documented_wire_bytes() -> None:
    """A store-backed all-float type is sent from its row (no component rebuilt): the payload
    is the wire format of the changeset module's docstring, built here with struct, and a
    store-backed type whose wire form is not its row (a variable tuple) arrives as written."""
    registry = make_registry()
    world = World()
    store = FrameStore()
    store.add(Pose((0.0, 0.0, 0.0), 0.0), capacity=2)
    store.add(Forces((0.0, 0.0)), capacity=2)
    world.use_store(store)
    entity = world.spawn(Replicate(), Pose((1.0, 2.0, 3.0), 0.5), Forces((1.0, 2.0)))
    sender = ChangeSetSender(world, registry, VEHICLE)
    receiver_world = World()
    receiver = ChangeSetReceiver(receiver_world, registry, OPERATOR)
    deliver(sender.poll(), receiver)  # the full state, sequence 0
    floats = (-0.0, 1e-300, 3.5, 2.0**0.5)
    row = world.row_view(entity, Pose)  # written as a compiled frame does: fields, then mark
    row.values[:] = floats
    row.mark[0] = world.tick
    row.mark[1] += 1
    world.set(entity, Forces((-1.5, 0.25)))  # a variable tuple on the wire
    payloads = sender.poll()
    pose_entry = struct.pack(">BIHB", 2, entity, 10, 32) + struct.pack(">4d", *floats)
    assert payloads[0][:5] == struct.pack(">BBHB", 1, 1, 1, 2)
    assert payloads[0][5 : 5 + len(pose_entry)] == pose_entry
    deliver(payloads, receiver)
    mirror = receiver.local_entity(entity)
    assert mirror is not None
    pose = receiver_world.get(mirror, Pose)
    assert pose is not None
    assert struct.pack(">4d", *pose.position, pose.heading) == struct.pack(">4d", *floats)
    assert receiver_world.get(mirror, Forces) == Forces((-1.5, 0.25))
