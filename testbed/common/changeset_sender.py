"""The sending end of change-set replication: what one node owns and changed, as payloads.

A :class:`ChangeSetSender` polls its world for the replicated components its side owns that
changed since its previous poll (:func:`~testbed.ecs.replicated_entries`) and encodes them with
a :class:`~testbed.common.changeset.ChangeSetCodec` into payloads of at most ``max_payload``
bytes, numbering them with the wire format's u16 sequence (described once, in
:mod:`testbed.common.changeset`).

Each poll carries only the latest value of what changed since the previous poll, so a lost
payload loses those updates until the same components change again, and a split change set may
arrive in part. :meth:`ChangeSetSender.snapshot` re-sends the full owned state (and the despawns
and removals still in the world's removal log), so a node can resync a peer periodically or
after a gap; the runner decides when. Each node writes the components it owns on entities it
spawned itself.

Imports: ``ecs``, ``protocol``, the codec and the standard library. No I/O.
"""

from __future__ import annotations

from typing import Any

from testbed.common.changeset import SEQUENCE_MODULUS, ChangeSetCodec
from testbed.ecs import ComponentRegistry, RawChange, Registration, Side, World, replicated_entries
from testbed.protocol import MAX_PAYLOAD

__all__ = ["ChangeSetSender"]


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
        "_floats",
        "_owned",
        "_owned_of",
        "_registry",
        "_sequence",
        "_side",
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
        self._owned: list[Registration] = []
        # the owned types encoded from their flat floats (a store row is read as is)
        self._floats: dict[type[Any], tuple[int, ...]] = {}
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
        changes = replicated_entries(world, self._since, self._owned_types(), self._floats)
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
        payloads = self._emit(replicated_entries(world, 0, self._owned_types(), self._floats))
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
            codec = self._codec
            self._floats = {
                entry.cls: widths
                for entry in self._owned
                if (widths := codec.field_codec(entry.type_id).float_widths) is not None
            }
        return self._owned

    def _emit(self, changes: list[RawChange]) -> list[bytes]:
        payloads = self._codec.encode_raw(changes, self._side, self._sequence)
        self._sequence = (self._sequence + len(payloads)) % SEQUENCE_MODULUS
        return payloads
