"""The receiving end of change-set replication: the peer's payloads applied to this world.

A :class:`ChangeSetReceiver` decodes each payload with a
:class:`~testbed.common.changeset.ChangeSetCodec` (the wire format is described there, once)
and applies it with ``Origin.REMOTE``, so nothing it writes is sent back.

Receiving is all-or-nothing per payload: it is decoded completely before anything is written.
A payload the codec finds *malformed* is dropped; a side byte equal to the receiver's own side
or any entry naming a type the sender does not own make it *rejected for ownership*; spawning
past the receiver's entity bound makes it *rejected for capacity*. Each case is counted and
reported as an :class:`ApplyResult`; :meth:`ChangeSetReceiver.apply` never raises on any bytes.

Entities: the receiver maps each sender entity id to a local *mirror* entity, spawned (with
``Replicate``, origin REMOTE) the first time an ADDED or CHANGED entry names it, and despawned
when the sender's DESPAWNED arrives. A peer can therefore only touch the mirrors it created,
never the receiver's own entities.

Losses: sequence gaps are counted (``lost_payloads``); a backward step (a restarted sender or a
duplicate; every testbed link is FIFO) is counted as ``out_of_order`` and resets the
expectation. What a lost payload costs, and how a snapshot repairs it, is the sender's
(:mod:`testbed.common.changeset_sender`).

Imports: ``ecs``, ``protocol``, the codec and the standard library. No pickle, no eval, no I/O.
"""

from __future__ import annotations

import enum
from collections.abc import Iterable
from dataclasses import dataclass

from testbed.common.changeset import (
    ENTRY_CHANGED,
    ENTRY_DESPAWNED,
    SEQUENCE_MODULUS,
    ChangeSetCodec,
    RawEntry,
)
from testbed.ecs import ComponentRegistry, Entity, Origin, Replicate, Side, World
from testbed.protocol import MalformedPayload

__all__ = ["DEFAULT_MAX_ENTITIES", "ApplyResult", "ApplyStatus", "ChangeSetReceiver"]

DEFAULT_MAX_ENTITIES = 4096
"""Default bound on the mirror entities one receiver creates for its peer."""


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


# What a receiver did with a payload: the fields of an ApplyResult, in order.
_Outcome = tuple[ApplyStatus, int | None, int, int, int, str]


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
        parsed = self._codec.decode_raw(bytes(payload))
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
            if code <= ENTRY_CHANGED and entity not in mirrors:
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
        self._expected = (sequence + 1) % SEQUENCE_MODULUS
        if expected is None:
            return 0
        gap = (sequence - expected) % SEQUENCE_MODULUS
        if gap >= SEQUENCE_MODULUS // 2:
            self.out_of_order += 1
            return 0
        self.lost_payloads += gap
        return gap

    def _write(self, entries: list[RawEntry]) -> int:
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
            if code <= ENTRY_CHANGED:
                if local is None:
                    local = mirrors[entity] = world.spawn(Replicate(), origin=remote)
                    spawned += 1
                write(local, value, origin=remote)
            elif local is None:
                continue  # removal or despawn of an entity never seen (or gone): nothing to do
            elif code == ENTRY_DESPAWNED:
                world.despawn(local, origin=remote)
                del mirrors[entity]
            else:
                assert info is not None  # parsed REMOVED entries carry their type
                world.remove(local, info.cls, origin=remote)
        return spawned
