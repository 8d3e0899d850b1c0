"""The full change-set replication codec: ECS change sets ⇄ bytes, for wideband links.

The ECS paper's automated state synchronisation (§III.B): every registered component type on an
entity carrying :class:`~testbed.ecs.Replicate` is serialised when it changes, carried to the
peer and applied to the corresponding entity there. Three modules share the work: this one holds
the wire format and :class:`ChangeSetCodec` (change sets ⇄ payloads, the only code that reads or
writes its bytes); :class:`~testbed.common.changeset_sender.ChangeSetSender` turns what its side
owns and changed since its previous poll (:func:`~testbed.ecs.replicated_changes`) into payloads
of at most ``max_payload`` bytes; :class:`~testbed.common.changeset_receiver.ChangeSetReceiver`
applies them to its own world with ``Origin.REMOTE`` (so nothing echoes back), after checking
that the peer wrote only what the peer owns. Unlike mate-rov's bincode stream (REFERENCE §3.6)
nothing here buffers without bound and authority is checked: a payload writing a type the
receiver's side owns is dropped whole.

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

Decoding is complete before anything is used: wrong version, unknown side, kind or type id,
truncated or trailing bytes, or a value its type's codec rejects make a payload *malformed*,
returned as a :class:`~testbed.protocol.MalformedPayload` value, never raised. Which side may
write what, the entity mirrors, sequence gaps and capacity are the receiver's (see
:mod:`testbed.common.changeset_receiver`); when to poll and resync, the sender's.

The wire tables the sender and receiver also need are public here, each documented: the entry
kind codes (``ENTRY_ADDED`` … ``ENTRY_DESPAWNED``), ``SEQUENCE_MODULUS``, and the plain-tuple
forms of :meth:`ChangeSetCodec.encode_raw` and :meth:`ChangeSetCodec.decode_raw` (their hot
paths: no :class:`ChangeSet` objects built).

Imports: ``ecs``, ``protocol`` and the standard library. No pickle, no eval, no I/O.
"""

from __future__ import annotations

import struct
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from typing import Any

from testbed.common.field_layouts import FieldDecodeError
from testbed.common.fieldcodec import FieldCodec, compile_codec
from testbed.ecs import Change, ChangeKind, ComponentRegistry, RawChange, Registration, Side
from testbed.protocol import MAX_PAYLOAD, MalformedPayload

__all__ = [
    "ENTRY_ADDED",
    "ENTRY_CHANGED",
    "ENTRY_DESPAWNED",
    "ENTRY_REMOVED",
    "HEADER_SIZE",
    "MAX_VALUE_SIZE",
    "MIN_PAYLOAD",
    "SEQUENCE_MODULUS",
    "WIRE_VERSION",
    "ChangeEntry",
    "ChangeSet",
    "ChangeSetCodec",
    "CompiledType",
    "RawChangeSet",
    "RawEntry",
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
SEQUENCE_MODULUS = 1 << 16
"""Sequence numbers count modulo this (the u16 of the header): 65535 is followed by 0."""
_U32_MAX = 0xFFFF_FFFF

_SIDE_CODES = {Side.VEHICLE: 1, Side.OPERATOR: 2}
_SIDES = {code: side for side, code in _SIDE_CODES.items()}
ENTRY_ADDED, ENTRY_CHANGED, ENTRY_REMOVED, ENTRY_DESPAWNED = 1, 2, 3, 4
"""An entry's kind byte. The two that carry a value are the two lowest: ``code <=
ENTRY_CHANGED`` means ADDED or CHANGED."""
_KIND_CODES = {
    ChangeKind.ADDED: ENTRY_ADDED,
    ChangeKind.CHANGED: ENTRY_CHANGED,
    ChangeKind.REMOVED: ENTRY_REMOVED,
    ChangeKind.DESPAWNED: ENTRY_DESPAWNED,
}
_KINDS = {code: kind for kind, code in _KIND_CODES.items()}


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


class CompiledType:
    """One registered type as the codec uses it: class, owner and compiled field codec.

    Attributes:
        cls: the component type.
        owner: the side that may write it.
        codec: its compiled field codec; ``encode``, ``encode_floats`` and ``decode`` are its
            bound methods.
    """

    __slots__ = ("cls", "codec", "decode", "encode", "encode_floats", "owner")

    def __init__(self, entry: Registration) -> None:
        self.cls = entry.cls
        self.owner = entry.owner
        self.codec = compile_codec(entry.cls, entry.fields)
        self.encode = self.codec.encode
        self.encode_floats = self.codec.encode_floats
        self.decode = self.codec.decode


RawEntry = tuple[int, int, CompiledType | None, object]
"""A decoded entry as a plain tuple: kind code (``ENTRY_*``), sender entity id, type (None for a
despawn), value (None unless ADDED/CHANGED)."""
RawChangeSet = tuple[Side, int, list[RawEntry]]
"""A decoded payload as a plain tuple: claimed side, sequence number, entries in order."""


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
        self._types: dict[int, CompiledType] = {}
        self.max_payload = max_payload
        self.max_value_size = min(MAX_VALUE_SIZE, max_payload - MIN_PAYLOAD)
        """The largest encoded value one entry can carry at this ``max_payload`` [B]."""
        for entry in registry:  # compile now: a type without a codec is a local error
            self._info(entry.type_id)

    def field_codec(self, type_id: int) -> FieldCodec:
        """The compiled field codec of a registered type id (KeyError if unregistered)."""
        return self._info(type_id).codec

    def _info(self, type_id: int) -> CompiledType:
        info = self._types.get(type_id)
        if info is None:
            info = self._types[type_id] = CompiledType(self._registry.entry_by_id(type_id))
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
        return self.encode_raw(_raw_changes(changes), side, first_sequence)

    def encode_raw(
        self, changes: Iterable[RawChange], side: Side, first_sequence: int
    ) -> list[bytes]:
        """:meth:`encode` of changes in :func:`~testbed.ecs.replicated_entries`' tuple form
        (the sender's hot path: no :class:`~testbed.ecs.Change` objects); the same payloads
        and errors. A value given as a ``list`` is the component's flat floats (a store row,
        for a type whose codec has :attr:`~testbed.common.fieldcodec.FieldCodec.float_widths`)
        and is encoded from them."""
        side_code = _SIDE_CODES[side]
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
                entry = pack_despawned(ENTRY_DESPAWNED, entity)
            else:
                info = types.get(type_id) or self._info(type_id)
                if kind is removed:
                    entry = pack_removed(ENTRY_REMOVED, entity, type_id)
                else:
                    data = info.encode_floats(value) if type(value) is list else info.encode(value)
                    if len(data) > max_value:
                        raise ValueError(self._too_big(info.cls, len(data)))
                    code = ENTRY_ADDED if kind is added else ENTRY_CHANGED
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
        parsed = self.decode_raw(payload)
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

    def decode_raw(self, payload: bytes) -> RawChangeSet | MalformedPayload:
        """:meth:`decode` as plain tuples (the receiver's hot path); never raises on any bytes.

        Returns:
            The :data:`RawChangeSet`, or :class:`~testbed.protocol.MalformedPayload`.
        """
        try:
            return self._parse_entries(payload)
        except (FieldDecodeError, struct.error) as err:
            return MalformedPayload(str(err))

    def _parse_entries(self, payload: bytes) -> RawChangeSet | MalformedPayload:
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
        entries: list[RawEntry] = []
        pos = HEADER_SIZE
        for index in range(count):
            code = payload[pos] if pos < size else 0
            if code in (ENTRY_ADDED, ENTRY_CHANGED):
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
            elif code == ENTRY_REMOVED:
                if pos + _REMOVED.size > size:
                    return MalformedPayload(f"entry {index} of {count}: truncated header")
                _, entity, type_id = unpack_removed(payload, pos)
                pos += _REMOVED.size
                info = types.get(type_id) or self._known(type_id)
                if info is None:
                    return MalformedPayload(f"entry {index}: unknown type id {type_id}")
                entries.append((code, entity, info, None))
            elif code == ENTRY_DESPAWNED:
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

    def _known(self, type_id: int) -> CompiledType | None:
        """The type registered under ``type_id`` (compiled on first use), or None."""
        try:
            return self._info(type_id)
        except (KeyError, TypeError):  # TypeError: registered since, but has no codec
            return None


def _payload(side_code: int, sequence: int, body: list[bytes]) -> bytes:
    header = _HEADER.pack(WIRE_VERSION, side_code, sequence % SEQUENCE_MODULUS, len(body))
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
