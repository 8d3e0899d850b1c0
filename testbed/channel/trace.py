"""Typed link events: what happened to every frame, when, where.

The medium appends one :class:`LinkEvent` per happening (a list append, nothing more) to an
optional :class:`Trace`; later stages (the recorder, the paper's Fig. 4 timeline) read it. Events
are recorded when the medium decides them, so a ``TX_END`` is recorded at its transmission's start
with its future time: use :meth:`Trace.in_time_order` for a timeline.

Every copy of a transmission that reaches a receiver ends in exactly one of ``DELIVER``,
``CORRUPT``, ``COLLIDE``, ``OUTAGE`` or ``OUT_OF_RANGE``; every frame handed to a modem is
``ENQUEUE``\\ d and then either ``DROP``\\ ped or sent as one ``TX_START``/``TX_END`` pair per
packet.

Reading a trace: :func:`frame_outcomes` classifies every frame (:class:`FrameOutcome`),
:func:`transmissions` pairs each packet's start and end with its outcome (the timeline's bars),
and :func:`direction_counts` gives the per-direction frame counts of ``metrics.json``
(:class:`DirectionCounts`). All three rank a frame's packets the same way
(:func:`worst_outcome`): a frame sent as several packets takes its worst one.

This module imports nothing from simpy.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

__all__ = [
    "BROADCAST",
    "RECEPTION_OUTCOMES",
    "DirectionCounts",
    "EventKind",
    "FrameOutcome",
    "LinkEvent",
    "Trace",
    "Transmission",
    "direction_counts",
    "frame_outcomes",
    "transmissions",
    "worst_outcome",
]

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


# --- what became of each frame --------------------------------------------------------------


class FrameOutcome(enum.StrEnum):
    """What became of a frame (or of one transmitted packet of it)."""

    DELIVERED = "delivered"
    """Every packet reached every receiver clean."""
    CORRUPTED = "corrupted"
    """A packet arrived with flipped bits (the receiver's CRC rejects the frame)."""
    COLLIDED = "collided"
    """A packet was destroyed by an overlapping transmission."""
    OUTAGE = "outage"
    """A packet overlapped a link outage window."""
    OUT_OF_RANGE = "out_of_range"
    """The receiver was beyond the link's range."""
    DROPPED = "dropped"
    """Tail-dropped by the sender's full FIFO: never transmitted."""
    PENDING = "pending"
    """Queued or on the air when the run ended: no outcome yet."""


# Worst first: a frame takes the worst outcome of its packets (a lost packet loses the frame).
_SEVERITY = (
    FrameOutcome.DROPPED,
    FrameOutcome.COLLIDED,
    FrameOutcome.OUTAGE,
    FrameOutcome.OUT_OF_RANGE,
    FrameOutcome.CORRUPTED,
    FrameOutcome.PENDING,
    FrameOutcome.DELIVERED,
)
_RANK = {outcome: rank for rank, outcome in enumerate(_SEVERITY)}
RECEPTION_OUTCOMES: dict[EventKind, FrameOutcome] = {
    EventKind.DELIVER: FrameOutcome.DELIVERED,
    EventKind.CORRUPT: FrameOutcome.CORRUPTED,
    EventKind.COLLIDE: FrameOutcome.COLLIDED,
    EventKind.OUTAGE: FrameOutcome.OUTAGE,
    EventKind.OUT_OF_RANGE: FrameOutcome.OUT_OF_RANGE,
}
"""The reception event kinds (one per copy that reaches a receiver) and the outcome each means."""


def worst_outcome(outcomes: Iterable[FrameOutcome]) -> FrameOutcome:
    """The worst of ``outcomes`` (``dropped`` > ``collided`` > ``outage`` > ``out_of_range`` >
    ``corrupted`` > ``pending`` > ``delivered``); ``pending`` when there are none."""
    return min(outcomes, key=_RANK.__getitem__, default=FrameOutcome.PENDING)


def _part_outcomes(events: Iterable[LinkEvent]) -> dict[tuple[int, int], FrameOutcome]:
    """(frame_id, part) → worst reception outcome over its receivers."""
    parts: dict[tuple[int, int], FrameOutcome] = {}
    for e in events:
        outcome = RECEPTION_OUTCOMES.get(e.kind)
        if outcome is None:
            continue
        key = (e.frame_id, e.part)
        held = parts.get(key)
        parts[key] = outcome if held is None else worst_outcome((held, outcome))
    return parts


def frame_outcomes(events: Iterable[LinkEvent]) -> dict[int, FrameOutcome]:
    """Classify every frame that appears in a link trace.

    A dropped frame is :attr:`~FrameOutcome.DROPPED`. Otherwise the frame takes the worst
    outcome of its packets (``collided`` > ``outage`` > ``out_of_range`` > ``corrupted`` >
    ``pending`` > ``delivered``): one lost packet loses the frame. A transmitted packet with no
    reception outcome, or a frame only enqueued, is ``pending`` (the run ended first).

    Args:
        events: link events (a :class:`Trace` or any iterable of them).

    Returns:
        Frame id → outcome, for every frame id seen in ``events``.
    """
    events = list(events)
    received = _part_outcomes(events)
    seen: dict[int, set[int]] = {}
    dropped: set[int] = set()
    for e in events:
        seen.setdefault(e.frame_id, set())
        if e.kind is EventKind.DROP:
            dropped.add(e.frame_id)
        elif e.kind is not EventKind.ENQUEUE:
            seen[e.frame_id].add(e.part)
    outcomes: dict[int, FrameOutcome] = {}
    for frame_id, parts in seen.items():
        if frame_id in dropped:
            outcomes[frame_id] = FrameOutcome.DROPPED
        else:
            per_part = (received.get((frame_id, p), FrameOutcome.PENDING) for p in parts)
            outcomes[frame_id] = worst_outcome(per_part)
    return outcomes


@dataclass(frozen=True, slots=True)
class Transmission:
    """One packet on the air, from the sender's ``tx_start`` to its ``tx_end``.

    Attributes:
        src: sending node.
        frame_id: the medium's frame id.
        part: packet index within the frame.
        start_s: transmission start (intrinsic delay first, then airtime) [s].
        end_s: last bit sent [s].
        size_bytes: packet length [B].
        outcome: what became of this packet at its receiver(s) (worst over receivers).
    """

    src: str
    frame_id: int
    part: int
    start_s: float
    end_s: float
    size_bytes: int
    outcome: FrameOutcome


def transmissions(events: Iterable[LinkEvent]) -> list[Transmission]:
    """Pair every ``tx_start`` with its ``tx_end`` and the packet's reception outcome.

    A packet whose ``tx_end`` is missing (a trace limited to some kinds) ends where it starts.

    Args:
        events: link events (a :class:`Trace` or any iterable of them).

    Returns:
        The transmissions in order of start time.
    """
    events = list(events)
    received = _part_outcomes(events)
    ends = {(e.src, e.frame_id, e.part): e.t_s for e in events if e.kind is EventKind.TX_END}
    out = []
    for e in events:
        if e.kind is not EventKind.TX_START:
            continue
        end_s = ends.get((e.src, e.frame_id, e.part), e.t_s)
        outcome = received.get((e.frame_id, e.part), FrameOutcome.PENDING)
        out.append(Transmission(e.src, e.frame_id, e.part, e.t_s, end_s, e.size_bytes, outcome))
    out.sort(key=lambda x: x.start_s)
    return out


# --- per-direction counts ---------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class DirectionCounts:
    """What became of the frames one node sent to another (the ``link`` counts of a run).

    A lost frame counts once, by its worst packet at the receiver (:func:`worst_outcome`), even
    when some of its other packets were still on the air when the run ended.

    Attributes:
        frames_sent: frames handed to the sender's modem (``enqueue`` events).
        frames_dropped: frames tail-dropped by the sender's full FIFO (``drop`` events).
        frames_collided: frames with a packet destroyed by a collision at the receiver.
        frames_outage: frames with a packet lost in an outage, none collided.
        frames_out_of_range: frames with a packet out of range, none collided or in an outage.
        frames_corrupted: frames with a corrupted packet and no packet lost otherwise.
        frames_settled: transmitted frames whose every packet reached an outcome at the
            receiver (delivered, corrupted or lost) by the end of the trace: the frames a
            packet error rate is taken over.
        mean_frame_bytes: mean size of the frames handed to the modem [B]; NaN if none.
    """

    frames_sent: int
    frames_dropped: int
    frames_collided: int
    frames_outage: int
    frames_out_of_range: int
    frames_corrupted: int
    frames_settled: int
    mean_frame_bytes: float


def direction_counts(events: Iterable[LinkEvent], src: str, dst: str) -> DirectionCounts:
    """Count what became of the frames ``src`` sent, as received by ``dst``.

    Sender-side events (enqueue, drop, ``tx_start``) count when ``src`` sent them; reception
    events when they are ``src``'s copies at ``dst`` (copies other nodes heard are left out).
    A frame is settled when ``dst`` has as many reception events for it as ``src`` had
    ``tx_start`` events: a frame still queued or on the air at the end is neither delivered
    nor lost.

    Args:
        events: link events (a :class:`Trace` or any iterable of them).
        src: the sending node.
        dst: the receiving node.

    Returns:
        The counts.
    """
    sent = dropped = 0
    sizes: list[int] = []
    packets_sent: dict[int, int] = {}
    packets_settled: dict[int, int] = {}
    worst: dict[int, FrameOutcome] = {}
    for event in events:
        if event.src != src:
            continue
        if event.kind is EventKind.ENQUEUE:
            sent += 1
            sizes.append(event.size_bytes)
        elif event.kind is EventKind.DROP:
            dropped += 1
        elif event.kind is EventKind.TX_START:
            packets_sent[event.frame_id] = packets_sent.get(event.frame_id, 0) + 1
        elif event.dst == dst and event.kind in RECEPTION_OUTCOMES:
            frame_id = event.frame_id
            packets_settled[frame_id] = packets_settled.get(frame_id, 0) + 1
            outcome = RECEPTION_OUTCOMES[event.kind]
            held = worst.get(frame_id)
            worst[frame_id] = outcome if held is None else worst_outcome((held, outcome))
    lost = list(worst.values())
    settled = sum(1 for f, n in packets_sent.items() if packets_settled.get(f, 0) >= n)
    return DirectionCounts(
        frames_sent=sent,
        frames_dropped=dropped,
        frames_collided=lost.count(FrameOutcome.COLLIDED),
        frames_outage=lost.count(FrameOutcome.OUTAGE),
        frames_out_of_range=lost.count(FrameOutcome.OUT_OF_RANGE),
        frames_corrupted=lost.count(FrameOutcome.CORRUPTED),
        frames_settled=settled,
        mean_frame_bytes=float(np.mean(sizes)) if sizes else math.nan,
    )
