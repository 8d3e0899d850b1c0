"""Typed link events: what happened to every frame, when, where.

The medium appends one :class:`LinkEvent` per happening (a list append, nothing more) to an
optional :class:`Trace`; later stages (the recorder, the paper's Fig. 4 timeline) read it. Events
are recorded when the medium decides them, so a ``TX_END`` is recorded at its transmission's start
with its future time: use :meth:`Trace.in_time_order` for a timeline.

Every copy of a transmission that reaches a receiver ends in exactly one of ``DELIVER``,
``CORRUPT``, ``COLLIDE``, ``OUTAGE`` or ``OUT_OF_RANGE``; every frame handed to a modem is
``ENQUEUE``\\ d and then either ``DROP``\\ ped or sent as one ``TX_START``/``TX_END`` pair per
packet.

This module imports nothing from simpy.
"""

from __future__ import annotations

import enum
from collections.abc import Iterable, Iterator
from typing import NamedTuple

__all__ = ["BROADCAST", "EventKind", "LinkEvent", "Trace"]

BROADCAST = "*"
"""``dst`` of events that concern the sender only (enqueue, drop, transmit start/end)."""


class EventKind(enum.StrEnum):
    """What happened to a frame (or one packet of it)."""

    ENQUEUE = "enqueue"
    """Handed to the sender's modem (``size_bytes`` = whole frame incl. packet padding)."""
    DROP = "drop"
    """Tail-dropped: the transmit FIFO had no room."""
    TX_START = "tx_start"
    """The modem starts sending (intrinsic delay first, then airtime)."""
    TX_END = "tx_end"
    """The last bit leaves the sender."""
    DELIVER = "deliver"
    """A clean copy was handed to the receiver."""
    CORRUPT = "corrupt"
    """A copy with flipped bits was handed to the receiver (``bit_errors`` > 0)."""
    COLLIDE = "collide"
    """A copy was destroyed by an overlapping reception or (half duplex) by transmitting."""
    OUT_OF_RANGE = "out_of_range"
    """The receiver was beyond ``max_range_m`` at transmit time: nothing arrives."""
    OUTAGE = "outage"
    """A copy overlapped a link outage window (:meth:`~testbed.channel.medium.Medium.add_outage`)
    and was lost."""


class LinkEvent(NamedTuple):
    """One link event (immutable).

    A ``NamedTuple`` rather than a frozen dataclass: one is built per happening on the hot path
    and a frozen dataclass costs about five times as much to construct.

    Attributes:
        t_s: simulated time of the event [s].
        kind: what happened.
        src: sending modem's name.
        dst: receiving modem's name, or :data:`BROADCAST` for sender-side events.
        frame_id: id the medium gave the frame at ``send`` (unique per medium, from 0).
        part: packet index within the frame (0 when frames go out whole).
        size_bytes: bytes concerned (the frame at enqueue/drop, the packet otherwise).
        bit_errors: bits flipped in a ``CORRUPT`` copy, else 0.
    """

    t_s: float
    kind: EventKind
    src: str
    dst: str
    frame_id: int
    part: int
    size_bytes: int
    bit_errors: int = 0


class Trace:
    """Append-only list of :class:`LinkEvent`, optionally limited to some kinds.

    Args:
        kinds: record only these kinds (e.g. losses only, to keep long runs cheap); all if None.
    """

    __slots__ = ("_kinds", "events")

    def __init__(self, kinds: Iterable[EventKind] | None = None) -> None:
        self.events: list[LinkEvent] = []
        self._kinds = frozenset(EventKind) if kinds is None else frozenset(kinds)

    def record(
        self,
        t_s: float,
        kind: EventKind,
        src: str,
        dst: str,
        frame_id: int,
        part: int,
        size_bytes: int,
        bit_errors: int = 0,
    ) -> None:
        """Append one event (if its kind is traced)."""
        if kind in self._kinds:
            self.events.append(
                LinkEvent(t_s, kind, src, dst, frame_id, part, size_bytes, bit_errors)
            )

    def of_kind(self, *kinds: EventKind) -> list[LinkEvent]:
        """The recorded events of the given kinds, in recording order."""
        wanted = frozenset(kinds)
        return [e for e in self.events if e.kind in wanted]

    def in_time_order(self) -> list[LinkEvent]:
        """All recorded events sorted by time (stable: equal times keep recording order)."""
        return sorted(self.events, key=lambda e: e.t_s)

    def __len__(self) -> int:
        return len(self.events)

    def __iter__(self) -> Iterator[LinkEvent]:
        return iter(self.events)
