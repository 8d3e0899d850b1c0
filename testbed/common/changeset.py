"""The full change-set replication codec: ECS change sets ⇄ bytes, for wideband links.

The ECS paper's automated state synchronisation (§III.B): every registered component type on an
entity carrying :class:`~testbed.ecs.Replicate` is serialised when it changes, carried to the
peer and applied to the corresponding entity there. A :class:`ChangeSetSender` turns what its
side owns and changed since its previous poll (:func:`~testbed.ecs.replicated_changes`) into
payloads of at most ``max_payload`` bytes; a :class:`ChangeSetReceiver` applies them to its own
world with ``Origin.REMOTE`` (so nothing echoes back), after checking that the peer wrote only
what the peer owns. Unlike mate-rov's bincode stream (REFERENCE §3.6) nothing here buffers
without bound and authority is checked: a payload writing a type the receiver's side owns is
dropped whole.

Wire format of one payload (big-endian; field values per :mod:`testbed.common.fieldcodec`)::

    offset  size  field
    0       1     version, u8 = 1 (WIRE_VERSION)
    1       1     sender side, u8: 1 = vehicle, 2 = operator
    2       2     sequence, u16: +1 per payload the sender emits, wrapping 65535 → 0
    4       1     entry count, u8
    5       …     entries, back to back, then nothing (trailing bytes are malformed)

    entry:  kind u8 (1 ADDED, 2 CHANGED, 3 REMOVED, 4 DESPAWNED)
            sender entity id u32 (the id in the sender's world)
            type id u16                  — not for DESPAWNED
            value length u8 + the value  — ADDED and CHANGED only

An ADDED/CHANGED entry is 8 B + its value, REMOVED 7 B, DESPAWNED 5 B; a payload is 5 B + its
entries. A change set that does not fit one payload is split between entries over several (each
with its own sequence number); an entry that cannot fit any payload (value over 255 B or over
``max_payload`` − 13 B) is a local error, raised when the sender is built for a fixed-size type
and when the value is encoded for a variable one.

Receiving is all-or-nothing per payload: it is decoded completely before anything is written.
Wrong version, unknown side, kind or type id, truncated or trailing bytes, or a value its type's
codec rejects make it *malformed*; a side byte equal to the receiver's own side or any entry
naming a type the sender does not own make it *rejected for ownership*; spawning past the
receiver's entity bound makes it *rejected for capacity*. Each case is counted and reported as
an :class:`ApplyResult`; :meth:`ChangeSetReceiver.apply` never raises on any bytes.

Entities: the receiver maps each sender entity id to a local *mirror* entity, spawned (with
``Replicate``, origin REMOTE) the first time an ADDED or CHANGED entry names it, and despawned
when the sender's DESPAWNED arrives. A peer can therefore only touch the mirrors it created,
never the receiver's own entities. Each node writes the components it owns on entities it
spawned itself.

Losses: sequence gaps are counted (``lost_payloads``); a backward step (a restarted sender or a
duplicate; every testbed link is FIFO) is counted as ``out_of_order`` and resets the
expectation. Each poll carries only the latest value of what changed since the previous poll,
so a lost payload loses those updates until the same components change again, and a split
change set may arrive in part. :meth:`ChangeSetSender.snapshot` re-sends the full owned state
(and the despawns and removals still in the world's removal log), so a node can resync a peer
periodically or after a gap; the runner decides when.

Imports: ``ecs``, ``protocol`` and the standard library. No pickle, no eval, no I/O.

Size: the codec, sender and receiver are the two ends of one wire format and share its private
header and type tables; the module stays whole, over 500 lines, so the format reads in one file.
"""

from __future__ import annotations

import enum
import struct
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from typing import Any

from testbed.common.field_layouts import FieldDecodeError
from testbed.common.fieldcodec import FieldCodec, compile_codec
from testbed.ecs import (
    Change,
    ChangeKind,
    ComponentRegistry,
    Entity,
    Origin,
    RawChange,
    Registration,
    Replicate,
    Side,
    World,
    replicated_entries,
)
from testbed.protocol import MAX_PAYLOAD, MalformedPayload

__all__ = [
    "DEFAULT_MAX_ENTITIES",
    "HEADER_SIZE",
    "MAX_VALUE_SIZE",
    "MIN_PAYLOAD",
    "WIRE_VERSION",
    "ApplyResult",
    "ApplyStatus",
    "ChangeEntry",
    "ChangeSet",
    "ChangeSetCodec",
    "ChangeSetReceiver",
    "ChangeSetSender",
]

WIRE_VERSION = 1
_HEADER = struct.Struct(">BBHB")
HEADER_SIZE = _HEADER.size
"""Payload header: version, side, sequence, entry count [B]."""
_KIND_ENTITY = struct.Struct(">BI")
_VALUED = struct.Struct(">BIHB")
_REMOVED = struct.Struct(">BIH")
MAX_VALUE_SIZE = 255
"""The largest encoded component value an entry carries (u8 length) [B]."""
MIN_PAYLOAD = HEADER_SIZE + _VALUED.size
"""The smallest usable ``max_payload``: a header and one entry with an empty value [B]."""
MAX_ENTRIES = 255
DEFAULT_MAX_ENTITIES = 4096
"""Default bound on the mirror entities one receiver creates for its peer."""
_SEQUENCE_MOD = 1 << 16
_U32_MAX = 0xFFFF_FFFF

_SIDE_CODES = {Side.VEHICLE: 1, Side.OPERATOR: 2}
_SIDES = {code: side for side, code in _SIDE_CODES.items()}
_KIND_CODES = {
    ChangeKind.ADDED: 1,
    ChangeKind.CHANGED: 2,
    ChangeKind.REMOVED: 3,
    ChangeKind.DESPAWNED: 4,
}
_KINDS = {code: kind for kind, code in _KIND_CODES.items()}
_ADDED, _CHANGED, _REMOVED_CODE, _DESPAWNED = 1, 2, 3, 4


@dataclass(frozen=True, slots=True)
class ChangeEntry:
    """One decoded entry.

    Attributes:
        kind: added, changed, removed or despawned.
        entity: the entity id in the *sender's* world.
        component: the registered type, None for a despawn.
        value: the component for ADDED/CHANGED, None otherwise.
    """

    kind: ChangeKind
    entity: int
    component: type[Any] | None
    value: object | None


@dataclass(frozen=True, slots=True)
class ChangeSet:
    """One decoded payload.

    Attributes:
        side: the side the sender claims to be.
        sequence: its sequence number (u16).
        entries: the entries, in order.
    """

    side: Side
    sequence: int
    entries: tuple[ChangeEntry, ...]


class _TypeInfo:
    """One registered type as the codec uses it: class, owner and compiled field codec."""

    __slots__ = ("cls", "codec", "decode", "encode", "owner")

    def __init__(self, entry: Registration) -> None:
        self.cls = entry.cls
        self.owner = entry.owner
        self.codec = compile_codec(entry.cls, entry.fields)
        self.encode = self.codec.encode
        self.decode = self.codec.decode


# A parsed entry: kind code, sender entity id, type (None for a despawn), value (or None).
_Entry = tuple[int, int, _TypeInfo | None, object]
_Parsed = tuple[Side, int, list[_Entry]]
# What a receiver did with a payload: the fields of an ApplyResult, in order.
_Outcome = tuple["ApplyStatus", int | None, int, int, int, str]


class ChangeSetCodec:
    """Change sets ⇄ payloads for one registry; field codecs compiled once per type.

    Args:
        registry: the replicated component types (may grow later; new types compile on use).
        max_payload: the largest payload to emit [B], ``MIN_PAYLOAD`` or more (default: the
            frame payload limit, 255).

    Raises:
        ValueError: ``max_payload`` is below ``MIN_PAYLOAD``.
        TypeError: a registered type has no field codec (see :func:`compile_codec`).
    """

    __slots__ = ("_registry", "_types", "max_payload", "max_value_size")

    def __init__(self, registry: ComponentRegistry, *, max_payload: int = MAX_PAYLOAD) -> None:
        if max_payload < MIN_PAYLOAD:
            raise ValueError(f"max_payload must be at least {MIN_PAYLOAD} B, got {max_payload}")
        self._registry = registry
        self._types: dict[int, _TypeInfo] = {}
        self.max_payload = max_payload
        self.max_value_size = min(MAX_VALUE_SIZE, max_payload - MIN_PAYLOAD)
        """The largest encoded value one entry can carry at this ``max_payload`` [B]."""
        for entry in registry:  # compile now: a type without a codec is a local error
            self._info(entry.type_id)

    def field_codec(self, type_id: int) -> FieldCodec:
        """The compiled field codec of a registered type id (KeyError if unregistered)."""
        return self._info(type_id).codec

    def _info(self, type_id: int) -> _TypeInfo:
        info = self._types.get(type_id)
        if info is None:
            info = self._types[type_id] = _TypeInfo(self._registry.entry_by_id(type_id))
        return info

    def check_fits(self, entry: Registration) -> None:
        """Raise ValueError if a fixed-size type's values can never fit one entry."""
        size = self.field_codec(entry.type_id).fixed_size
        if size is not None and size > self.max_value_size:
            raise ValueError(self._too_big(entry.cls, size))

    def _too_big(self, cls: type[Any], size: int) -> str:
        return (
            f"{cls.__qualname__} encodes to {size} B; one change-set entry carries at most "
            f"{self.max_value_size} B at max_payload={self.max_payload}"
        )

    def encode(self, changes: Iterable[Change], side: Side, first_sequence: int) -> list[bytes]:
        """Payloads carrying ``changes`` in order, split between entries to fit ``max_payload``.

        Args:
            changes: entries to send (as :func:`~testbed.ecs.replicated_changes` lists them).
            side: the sending side.
            first_sequence: sequence number of the first payload (the next ones count up, mod
                65536).

        Returns:
            The payloads; none for no changes.

        Raises:
            ValueError: an entity id beyond u32, a change without a type id, a value that does
                not fit one entry (the type is named), or one its field codec cannot encode.
            KeyError: a type id that is not registered.
        """
        return self._encode_entries(_raw_changes(changes), _SIDE_CODES[side], first_sequence)

    def _encode_entries(
        self, changes: Iterable[RawChange], side_code: int, first_sequence: int
    ) -> list[bytes]:
        """:meth:`encode` of changes in :func:`~testbed.ecs.replicated_entries`' form (the
        sender's hot path: no :class:`~testbed.ecs.Change` objects)."""
        limit = self.max_payload - HEADER_SIZE
        max_value = self.max_value_size
        types = self._types
        pack_valued, pack_removed, pack_despawned = _VALUED.pack, _REMOVED.pack, _KIND_ENTITY.pack
        added, despawned, removed = ChangeKind.ADDED, ChangeKind.DESPAWNED, ChangeKind.REMOVED
        payloads: list[bytes] = []
        body: list[bytes] = []
        used = 0
        for entity, type_id, kind, _, value, _ in changes:
            if not 0 <= entity <= _U32_MAX:
                raise ValueError(f"entity id {entity} does not fit the u32 of a change-set entry")
            if kind is despawned:
                entry = pack_despawned(_DESPAWNED, entity)
            else:
                info = types.get(type_id) or self._info(type_id)
                if kind is removed:
                    entry = pack_removed(_REMOVED_CODE, entity, type_id)
                else:
                    data = info.encode(value)
                    if len(data) > max_value:
                        raise ValueError(self._too_big(info.cls, len(data)))
                    code = _ADDED if kind is added else _CHANGED
                    entry = pack_valued(code, entity, type_id, len(data)) + data
            if body and (used + len(entry) > limit or len(body) == MAX_ENTRIES):
                payloads.append(_payload(side_code, first_sequence + len(payloads), body))
                body = []
                used = 0
            body.append(entry)
            used += len(entry)
        if body:
            payloads.append(_payload(side_code, first_sequence + len(payloads), body))
        return payloads

    def decode(self, payload: bytes) -> ChangeSet | MalformedPayload:
        """Parse one payload completely; never raises on any bytes.

        Returns:
            The change set, or :class:`~testbed.protocol.MalformedPayload` saying what was wrong.
        """
        parsed = self._parse(payload)
        if isinstance(parsed, MalformedPayload):
            return parsed
        side, sequence, entries = parsed
        return ChangeSet(
            side,
            sequence,
            tuple(
                ChangeEntry(_KINDS[code], entity, None if info is None else info.cls, value)
                for code, entity, info, value in entries
            ),
        )

    def _parse(self, payload: bytes) -> _Parsed | MalformedPayload:
        """Like :meth:`decode`, as plain tuples (the receiver's hot path)."""
        try:
            return self._parse_entries(payload)
        except (FieldDecodeError, struct.error) as err:
            return MalformedPayload(str(err))

    def _parse_entries(self, payload: bytes) -> _Parsed | MalformedPayload:
        size = len(payload)
        if size < HEADER_SIZE:
            return MalformedPayload(f"{size} B is shorter than the {HEADER_SIZE} B header")
        version, side_code, sequence, count = _HEADER.unpack_from(payload, 0)
        if version != WIRE_VERSION:
            return MalformedPayload(f"wire version {version}, expected {WIRE_VERSION}")
        side = _SIDES.get(side_code)
        if side is None:
            return MalformedPayload(f"unknown sender side {side_code}")
        types = self._types
        unpack_valued, unpack_removed = _VALUED.unpack_from, _REMOVED.unpack_from
        valued_size = _VALUED.size
        entries: list[_Entry] = []
        pos = HEADER_SIZE
        for index in range(count):
            code = payload[pos] if pos < size else 0
            if code in (_ADDED, _CHANGED):
                start = pos + valued_size
                if start > size:
                    return MalformedPayload(f"entry {index} of {count}: truncated header")
                _, entity, type_id, length = unpack_valued(payload, pos)
                pos = start + length
                if pos > size:
                    return MalformedPayload(f"entry {index}: value of {length} B truncated")
                info = types.get(type_id) or self._known(type_id)
                if info is None:
                    return MalformedPayload(f"entry {index}: unknown type id {type_id}")
                entries.append((code, entity, info, info.decode(payload[start:pos])))
            elif code == _REMOVED_CODE:
                if pos + _REMOVED.size > size:
                    return MalformedPayload(f"entry {index} of {count}: truncated header")
                _, entity, type_id = unpack_removed(payload, pos)
                pos += _REMOVED.size
                info = types.get(type_id) or self._known(type_id)
                if info is None:
                    return MalformedPayload(f"entry {index}: unknown type id {type_id}")
                entries.append((code, entity, info, None))
            elif code == _DESPAWNED:
                if pos + _KIND_ENTITY.size > size:
                    return MalformedPayload(f"entry {index} of {count}: truncated header")
                _, entity = _KIND_ENTITY.unpack_from(payload, pos)
                pos += _KIND_ENTITY.size
                entries.append((code, entity, None, None))
            elif pos >= size:
                return MalformedPayload(f"entry {index} of {count}: truncated")
            else:
                return MalformedPayload(f"entry {index}: unknown kind {code}")
        if pos != size:
            return MalformedPayload(f"{size - pos} trailing bytes after {count} entries")
        return side, sequence, entries

    def _known(self, type_id: int) -> _TypeInfo | None:
        """The type registered under ``type_id`` (compiled on first use), or None."""
        try:
            return self._info(type_id)
        except (KeyError, TypeError):  # TypeError: registered since, but has no codec
            return None


def _payload(side_code: int, sequence: int, body: list[bytes]) -> bytes:
    header = _HEADER.pack(WIRE_VERSION, side_code, sequence % _SEQUENCE_MOD, len(body))
    return header + b"".join(body)


def _raw_changes(changes: Iterable[Change]) -> Iterator[RawChange]:
    """``changes`` in :func:`~testbed.ecs.replicated_entries`' tuple form, checked one by one
    as the encoder reaches them."""
    for change in changes:
        kind = change.kind
        type_id = change.type_id
        if kind is not ChangeKind.DESPAWNED and type_id is None:
            if not 0 <= change.entity <= _U32_MAX:  # the encoder's first check, as before
                raise ValueError(
                    f"entity id {change.entity} does not fit the u32 of a change-set entry"
                )
            raise ValueError(f"{kind.name} change without a type id: {change!r}")
        yield (change.entity, type_id or 0, kind, None, change.value, change.tick)


class ChangeSetSender:
    """Outbound replication of one node: what ``side`` owns and changed, as payloads.

    Args:
        world: the node's world.
        registry: the replicated component types.
        side: this node's side; only types it owns are sent.
        max_payload: the largest payload [B] (default 255, the frame payload limit).

    Raises:
        ValueError: ``max_payload`` below ``MIN_PAYLOAD``, or a registered fixed-size type of
            ``side`` whose values cannot fit one entry (the type is named).
        TypeError: ``side`` is not a :class:`~testbed.ecs.Side`.
    """

    __slots__ = (
        "_codec",
        "_owned",
        "_owned_of",
        "_registry",
        "_sequence",
        "_side",
        "_side_code",
        "_since",
        "_snapshot_tick",
        "_world",
    )

    def __init__(
        self,
        world: World,
        registry: ComponentRegistry,
        side: Side,
        *,
        max_payload: int = MAX_PAYLOAD,
    ) -> None:
        if not isinstance(side, Side):
            raise TypeError(f"side must be a Side, got {side!r}")
        self._world = world
        self._registry = registry
        self._side = side
        self._codec = ChangeSetCodec(registry, max_payload=max_payload)
        for entry in registry:
            if entry.owner is side:
                self._codec.check_fits(entry)
        self._since = 0
        self._snapshot_tick = 0
        self._sequence = 0
        self._side_code = _SIDE_CODES[side]
        self._owned: list[Registration] = []
        self._owned_of = -1  # registry size the owned list was made at (-1: not yet)

    @property
    def last_polled_tick(self) -> int:
        """World tick of the last poll (0 before the first): the next poll sends what is newer."""
        return self._since

    @property
    def next_sequence(self) -> int:
        """Sequence number the next payload will carry."""
        return self._sequence

    def poll(self) -> list[bytes]:
        """Payloads for every owned change since the previous poll (all owned state at first).

        Advances the world tick after reading it, so writes made after the poll (even in the
        same system) are newer than the poll mark and go out with the next one.

        Raises:
            ValueError: a value that does not fit one entry; nothing is marked as sent, so the
                next poll reports the same changes again.
        """
        world = self._world
        now = world.tick
        changes = replicated_entries(world, self._since, self._owned_types())
        payloads = self._emit(changes) if changes else []
        self._since = now
        world.advance()
        return payloads

    def snapshot(self) -> list[bytes]:
        """Payloads carrying the full owned state, for a new peer or a periodic resync.

        Also repeats the despawns and removals still in the world's removal log, so a resync
        clears mirrors whose despawn was lost. Does not move the poll mark. Then forgets the
        removals made before the previous snapshot (and already polled): each has gone out in
        a poll and in at least one snapshot since, so the log stays bounded by what two
        snapshot periods remove (a peer churning mirrors grew it by two rows a cycle, forever).
        """
        world = self._world
        payloads = self._emit(replicated_entries(world, 0, self._owned_types()))
        world.trim_removals(min(self._snapshot_tick, self._since))
        self._snapshot_tick = world.tick
        return payloads

    def _owned_types(self) -> list[Registration]:
        """The registered types this side owns, in type-id order (remade if the registry grew:
        it only ever grows)."""
        registry = self._registry
        if len(registry) != self._owned_of:
            self._owned = [entry for entry in registry if entry.owner is self._side]
            self._owned_of = len(registry)
        return self._owned

    def _emit(self, changes: list[RawChange]) -> list[bytes]:
        payloads = self._codec._encode_entries(changes, self._side_code, self._sequence)
        self._sequence = (self._sequence + len(payloads)) % _SEQUENCE_MOD
        return payloads


class ApplyStatus(enum.Enum):
    """What a receiver did with one payload."""

    APPLIED = enum.auto()
    REJECTED_OWNERSHIP = enum.auto()
    """It writes a type the sender does not own (or claims the receiver's own side)."""
    REJECTED_CAPACITY = enum.auto()
    """It would spawn more mirror entities than the receiver's bound."""
    MALFORMED = enum.auto()


@dataclass(frozen=True, slots=True)
class ApplyResult:
    """What happened to one payload.

    Attributes:
        status: applied, rejected (ownership or capacity) or malformed.
        sequence: its sequence number, None if malformed.
        entries: entries applied (0 unless applied).
        spawned: mirror entities spawned.
        lost: payloads missing just before this one (the sequence gap; 0 if malformed).
        reason: why it was dropped ("" if applied).
    """

    status: ApplyStatus
    sequence: int | None
    entries: int = 0
    spawned: int = 0
    lost: int = 0
    reason: str = ""


class ChangeSetReceiver:
    """Inbound replication of one node: applies the peer's payloads to this world.

    Args:
        world: the node's world.
        registry: the replicated component types.
        side: this node's (the receiver's) side; the peer may write only the other side's types.
        max_entities: bound on the mirror entities the peer may make this node hold.

    Attributes:
        payloads_applied: payloads applied.
        rejected_ownership: payloads dropped for writing a type the sender does not own.
        rejected_capacity: payloads dropped for spawning past ``max_entities``.
        malformed: payloads dropped as malformed.
        entries_applied: entries of applied payloads.
        lost_payloads: payloads missing from the sequence (counted at the next one that arrives).
        out_of_order: payloads whose sequence number stepped back (restart or duplicate).
    """

    __slots__ = (
        "_codec",
        "_expected",
        "_max_entities",
        "_mirrors",
        "_registry",
        "_side",
        "_world",
        "entries_applied",
        "lost_payloads",
        "malformed",
        "out_of_order",
        "payloads_applied",
        "rejected_capacity",
        "rejected_ownership",
    )

    def __init__(
        self,
        world: World,
        registry: ComponentRegistry,
        side: Side,
        *,
        max_entities: int = DEFAULT_MAX_ENTITIES,
    ) -> None:
        if not isinstance(side, Side):
            raise TypeError(f"side must be a Side, got {side!r}")
        if max_entities < 1:
            raise ValueError(f"max_entities must be at least 1, got {max_entities}")
        self._world = world
        self._registry = registry
        self._side = side
        self._codec = ChangeSetCodec(registry)
        self._max_entities = max_entities
        self._mirrors: dict[int, Entity] = {}
        self._expected: int | None = None
        self.payloads_applied = 0
        self.rejected_ownership = 0
        self.rejected_capacity = 0
        self.malformed = 0
        self.entries_applied = 0
        self.lost_payloads = 0
        self.out_of_order = 0

    @property
    def payloads_received(self) -> int:
        """Every payload given to :meth:`apply`, whatever became of it."""
        return (
            self.payloads_applied
            + self.rejected_ownership
            + self.rejected_capacity
            + self.malformed
        )

    def local_entity(self, sender_entity: int) -> Entity | None:
        """The live local mirror of a sender entity id, or None."""
        entity = self._mirrors.get(sender_entity)
        return entity if entity is not None and self._world.is_alive(entity) else None

    def mirrors(self) -> dict[int, Entity]:
        """Sender entity id → live local mirror entity, for every mirror."""
        alive = self._world.is_alive
        return {remote: local for remote, local in self._mirrors.items() if alive(local)}

    def apply(self, payload: bytes) -> ApplyResult:
        """Decode one payload and, if it is well formed and allowed, apply all of it.

        Never raises on remote bytes: every outcome is counted and returned.

        Raises:
            TypeError: ``payload`` is not bytes-like (local misuse).
        """
        return ApplyResult(*self._receive(payload))

    def apply_all(self, payloads: Iterable[bytes]) -> int:
        """:meth:`apply` each payload in order (the same counts and effects) without building
        the results; returns how many were not applied (rejected or malformed).

        Raises:
            TypeError: a payload is not bytes-like (local misuse).
        """
        refused = 0
        applied = ApplyStatus.APPLIED
        for payload in payloads:
            if self._receive(payload)[0] is not applied:
                refused += 1
        return refused

    def _receive(self, payload: bytes) -> _Outcome:
        """Decode, check, count and (if allowed) apply one payload: :class:`ApplyResult`'s
        fields in order."""
        if not isinstance(payload, bytes | bytearray | memoryview):
            raise TypeError(f"payload must be bytes, got {type(payload).__qualname__}")
        parsed = self._codec._parse(bytes(payload))  # same module: the tuple fast path
        if isinstance(parsed, MalformedPayload):
            self.malformed += 1
            return (ApplyStatus.MALFORMED, None, 0, 0, 0, parsed.reason)
        side, sequence, entries = parsed
        lost = self._track(sequence)
        if side is self._side:
            reason = f"payload claims to come from this node's own side ({side.name})"
            self.rejected_ownership += 1
            return (ApplyStatus.REJECTED_OWNERSHIP, sequence, 0, 0, lost, reason)
        mirrors = self._mirrors
        new: set[int] | None = None
        for code, entity, info, _ in entries:
            if info is not None and info.owner is not side:
                reason = f"{side.name} may not write {info.cls.__qualname__}"
                self.rejected_ownership += 1
                return (ApplyStatus.REJECTED_OWNERSHIP, sequence, 0, 0, lost, reason)
            if code <= _CHANGED and entity not in mirrors:
                if new is None:
                    new = set()
                new.add(entity)
        if new is not None and len(mirrors) + len(new) > self._max_entities:
            self.rejected_capacity += 1
            reason = f"{len(new)} new entities would pass the bound of {self._max_entities}"
            return (ApplyStatus.REJECTED_CAPACITY, sequence, 0, 0, lost, reason)
        spawned = self._write(entries)
        self.payloads_applied += 1
        self.entries_applied += len(entries)
        return (ApplyStatus.APPLIED, sequence, len(entries), spawned, lost, "")

    def _track(self, sequence: int) -> int:
        """Update the sequence expectation; return the gap before ``sequence``."""
        expected = self._expected
        self._expected = (sequence + 1) % _SEQUENCE_MOD
        if expected is None:
            return 0
        gap = (sequence - expected) % _SEQUENCE_MOD
        if gap >= _SEQUENCE_MOD // 2:
            self.out_of_order += 1
            return 0
        self.lost_payloads += gap
        return gap

    def _write(self, entries: list[_Entry]) -> int:
        """Apply parsed, checked entries in order; return the mirrors spawned."""
        world = self._world
        alive, write = world.is_alive, world.set
        mirrors = self._mirrors
        remote = Origin.REMOTE
        spawned = 0
        for code, entity, info, value in entries:
            local = mirrors.get(entity)
            if local is not None and not alive(local):
                del mirrors[entity]  # despawned here by a local system
                local = None
            if code <= _CHANGED:
                if local is None:
                    local = mirrors[entity] = world.spawn(Replicate(), origin=remote)
                    spawned += 1
                write(local, value, origin=remote)
            elif local is None:
                continue  # removal or despawn of an entity never seen (or gone): nothing to do
            elif code == _DESPAWNED:
                world.despawn(local, origin=remote)
                del mirrors[entity]
            else:
                assert info is not None  # parsed REMOVED entries carry their type
                world.remove(local, info.cls, origin=remote)
        return spawned
