"""What became of each frame of a link trace: the one classification of outcomes.

:func:`frame_outcomes` classifies every frame (:class:`FrameOutcome`), :func:`transmissions`
pairs each packet's start and end with its outcome (the timeline's bars), and
:func:`direction_counts` gives the per-direction frame counts of ``metrics.json``
(:class:`DirectionCounts`). All three rank a frame's packets the same way
(:func:`worst_outcome`): a frame sent as several packets takes its worst one. They work on the
trace's columns (:class:`~testbed.channel.trace.Trace`) with numpy.

This module imports nothing from simpy.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from testbed.channel.trace import KIND_BY_CODE, KIND_CODE, EventKind, LinkEvent, Trace, TraceColumns

__all__ = [
    "RECEPTION_OUTCOMES",
    "DirectionCounts",
    "FrameOutcome",
    "Transmission",
    "TransmissionColumns",
    "direction_counts",
    "frame_outcome_columns",
    "frame_outcomes",
    "outcome_of_rank",
    "transmission_columns",
    "transmissions",
    "worst_outcome",
]


# --- what became of each frame --------------------------------------------------------------


class FrameOutcome(enum.StrEnum):
    """What became of a frame (or of one transmitted packet of it)."""

    DELIVERED = "delivered"
    """Every packet reached every receiver clean."""
    CORRUPTED = "corrupted"
    """A packet arrived with flipped bits (the receiver's CRC rejects the frame)."""
    COLLIDED = "collided"
    """A packet was destroyed by an overlapping transmission: another copy at the receiver
    (trace kind ``collide``) or, half duplex, the receiver's own (``deaf``)."""
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
    EventKind.DEAF: FrameOutcome.COLLIDED,
    EventKind.OUTAGE: FrameOutcome.OUTAGE,
    EventKind.OUT_OF_RANGE: FrameOutcome.OUT_OF_RANGE,
}
"""The reception event kinds (one per copy that reaches a receiver) and the outcome each means."""
_RECEPTION_RANK = np.array(
    [
        _RANK[RECEPTION_OUTCOMES[kind]] if kind in RECEPTION_OUTCOMES else len(_SEVERITY)
        for kind in KIND_BY_CODE
    ],
    dtype=np.int64,
)
"""Kind code → rank of its reception outcome (``len(_SEVERITY)`` for the other kinds)."""
_IS_RECEPTION = np.array([kind in RECEPTION_OUTCOMES for kind in KIND_BY_CODE])
"""Kind code → whether it is a reception kind."""


def worst_outcome(outcomes: Iterable[FrameOutcome]) -> FrameOutcome:
    """The worst of ``outcomes`` (``dropped`` > ``collided`` > ``outage`` > ``out_of_range`` >
    ``corrupted`` > ``pending`` > ``delivered``); ``pending`` when there are none."""
    return min(outcomes, key=_RANK.__getitem__, default=FrameOutcome.PENDING)


def _keys(*columns: np.ndarray) -> np.ndarray:
    """Rows of ``columns`` as one structured array (sortable, for :func:`np.unique`)."""
    keys = np.empty(len(columns[0]), dtype=[(f"k{i}", np.int64) for i in range(len(columns))])
    for i, column in enumerate(columns):
        keys[f"k{i}"] = column
    return keys


def _lookup(table: np.ndarray, keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Positions of ``keys`` in the sorted unique ``table`` and whether each is there."""
    at = np.searchsorted(table, keys)
    found = at < len(table)
    found[found] = table[at[found]] == keys[found]
    return at, found


_NO_RANK = len(_SEVERITY)


def _part_ranks(columns: TraceColumns) -> tuple[np.ndarray, np.ndarray]:
    """Sorted unique (frame_id, part) keys of the reception events and the rank of the worst
    reception outcome of each, over its receivers."""
    received = _IS_RECEPTION[columns.kind]
    ranks = _RECEPTION_RANK[columns.kind[received]]
    parts, where = np.unique(
        _keys(columns.frame_id[received], columns.part[received]), return_inverse=True
    )
    worst = np.full(len(parts), _NO_RANK, dtype=np.int64)
    np.minimum.at(worst, where.reshape(-1), ranks)
    return parts, worst


def frame_outcome_columns(events: Iterable[LinkEvent]) -> tuple[np.ndarray, np.ndarray]:
    """:func:`frame_outcomes` as arrays: the frame ids in order of first appearance and the
    rank of each one's outcome in ``_SEVERITY`` (see :func:`outcome_of_rank`)."""
    columns = Trace.of(events).columns()
    kind = columns.kind
    parts, part_rank = _part_ranks(columns)
    on_air = (kind != KIND_CODE[EventKind.ENQUEUE]) & (kind != KIND_CODE[EventKind.DROP])
    seen = np.unique(_keys(columns.frame_id[on_air], columns.part[on_air]))
    at, found = _lookup(parts, seen)
    seen_rank = np.full(len(seen), _RANK[FrameOutcome.PENDING], dtype=np.int64)
    seen_rank[found] = part_rank[at[found]]
    frames, first = np.unique(columns.frame_id, return_index=True)
    rank = np.full(len(frames), _NO_RANK, dtype=np.int64)
    np.minimum.at(rank, np.searchsorted(frames, seen["k0"]), seen_rank)
    rank[rank == _NO_RANK] = _RANK[FrameOutcome.PENDING]  # no packet on the air
    dropped = np.unique(columns.frame_id[kind == KIND_CODE[EventKind.DROP]])
    rank[np.searchsorted(frames, dropped)] = _RANK[FrameOutcome.DROPPED]
    order = np.argsort(first, kind="stable")
    return frames[order], rank[order]


def outcome_of_rank(rank: int) -> FrameOutcome:
    """The outcome of a rank of :func:`frame_outcome_columns` or :class:`TransmissionColumns`."""
    return _SEVERITY[rank]


def frame_outcomes(events: Iterable[LinkEvent]) -> dict[int, FrameOutcome]:
    """Classify every frame that appears in a link trace.

    A dropped frame is :attr:`~FrameOutcome.DROPPED`. Otherwise the frame takes the worst
    outcome of its packets (``collided`` > ``outage`` > ``out_of_range`` > ``corrupted`` >
    ``pending`` > ``delivered``): one lost packet loses the frame. A transmitted packet with no
    reception outcome, or a frame only enqueued, is ``pending`` (the run ended first).

    Args:
        events: link events (a :class:`Trace` or any iterable of them).

    Returns:
        Frame id → outcome, for every frame id seen in ``events`` (in order of first
        appearance).
    """
    frames, rank = frame_outcome_columns(events)
    return {f: _SEVERITY[r] for f, r in zip(frames.tolist(), rank.tolist(), strict=True)}


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


@dataclass(frozen=True, slots=True)
class TransmissionColumns:
    """:func:`transmissions` as arrays, one entry per packet in order of start time
    (:func:`transmission_columns`); ``src`` holds codes into ``names``, ``outcome`` ranks
    (:func:`outcome_of_rank`)."""

    src: np.ndarray
    frame_id: np.ndarray
    part: np.ndarray
    start_s: np.ndarray
    end_s: np.ndarray
    size_bytes: np.ndarray
    outcome: np.ndarray
    names: tuple[str, ...]

    def __len__(self) -> int:
        return len(self.start_s)

    def take(self, at: slice | np.ndarray) -> list[Transmission]:
        """The transmissions at ``at`` (a slice or an index array) as :class:`Transmission`."""
        names = self.names
        return [
            Transmission(names[s], f, p, t0, t1, n, _SEVERITY[o])
            for s, f, p, t0, t1, n, o in zip(
                self.src[at].tolist(),
                self.frame_id[at].tolist(),
                self.part[at].tolist(),
                self.start_s[at].tolist(),
                self.end_s[at].tolist(),
                self.size_bytes[at].tolist(),
                self.outcome[at].tolist(),
                strict=True,
            )
        ]


def transmission_columns(events: Iterable[LinkEvent]) -> TransmissionColumns:
    """:func:`transmissions` as arrays (no object per packet)."""
    columns = Trace.of(events).columns()
    kind = columns.kind
    starts = kind == KIND_CODE[EventKind.TX_START]
    ends = kind == KIND_CODE[EventKind.TX_END]
    end_keys = _keys(columns.src[ends], columns.frame_id[ends], columns.part[ends])[::-1]
    end_table, last = np.unique(end_keys, return_index=True)  # the last tx_end of each packet
    end_t = columns.t_s[ends][::-1][last]
    src, frame_id, part = columns.src[starts], columns.frame_id[starts], columns.part[starts]
    start_s = columns.t_s[starts]
    at, found = _lookup(end_table, _keys(src, frame_id, part))
    end_s = start_s.copy()
    end_s[found] = end_t[at[found]]
    parts, part_rank = _part_ranks(columns)
    at, found = _lookup(parts, _keys(frame_id, part))
    outcome = np.full(len(start_s), _RANK[FrameOutcome.PENDING], dtype=np.int64)
    outcome[found] = part_rank[at[found]]
    order = np.argsort(start_s, kind="stable")
    size_bytes = columns.size_bytes[starts]
    return TransmissionColumns(
        src[order],
        frame_id[order],
        part[order],
        start_s[order],
        end_s[order],
        size_bytes[order],
        outcome[order],
        columns.names,
    )


def transmissions(events: Iterable[LinkEvent]) -> list[Transmission]:
    """Pair every ``tx_start`` with its ``tx_end`` and the packet's reception outcome.

    A packet whose ``tx_end`` is missing (a trace limited to some kinds) ends where it starts.

    Args:
        events: link events (a :class:`Trace` or any iterable of them).

    Returns:
        The transmissions in order of start time.
    """
    return transmission_columns(events).take(slice(None))


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
        mean_on_air_bytes: mean size on the air of the frames handed to the modem, packet
            padding included (the trace's ``enqueue`` sizes) [B]; NaN if none. Bit errors
            follow the frame's own bytes, not the padding: a PER closed form takes the frame's
            length, which the trace does not hold.
    """

    frames_sent: int
    frames_dropped: int
    frames_collided: int
    frames_outage: int
    frames_out_of_range: int
    frames_corrupted: int
    frames_settled: int
    mean_on_air_bytes: float


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
    trace = Trace.of(events)
    columns = trace.columns()
    src_code, dst_code = trace.name_code(src), trace.name_code(dst)
    if src_code is None:
        return DirectionCounts(0, 0, 0, 0, 0, 0, 0, math.nan)
    # masks of one byte per event and copies of the few events concerned: no array of
    # 8 B per event, so that counting a long run takes little memory on top of its trace
    mine = columns.src == src_code
    kind = columns.kind
    enqueued = mine & (kind == KIND_CODE[EventKind.ENQUEUE])
    sent = int(np.count_nonzero(enqueued))
    sizes = columns.size_bytes[enqueued].astype(np.int64)
    mean_on_air_bytes = float(np.mean(sizes)) if sent else math.nan
    del sizes
    del enqueued
    dropped = int(np.count_nonzero(mine & (kind == KIND_CODE[EventKind.DROP])))
    started = columns.frame_id[mine & (kind == KIND_CODE[EventKind.TX_START])]
    frames_sent, packets_sent = np.unique(started, return_counts=True)
    del started
    if dst_code is None:
        mine[:] = False
    else:
        mine &= columns.dst == dst_code
        mine &= _IS_RECEPTION[kind]
    # the receptions sorted by (frame, rank): each frame's first is its worst outcome
    heard = columns.frame_id[mine].astype(np.int64)
    heard <<= 3
    heard |= _RECEPTION_RANK[kind[mine]]
    del mine
    heard.sort()
    worst_all = (heard & 7).astype(np.int8)
    heard >>= 3  # frame ids
    first = np.flatnonzero(np.diff(heard, prepend=np.int64(-(2**62))))
    frames_heard = heard[first]
    worst = worst_all[first]
    packets_settled = np.diff(first, append=len(heard))
    del heard, worst_all
    at = np.searchsorted(frames_heard, frames_sent)
    found = at < len(frames_heard)
    found[found] = frames_heard[at[found]] == frames_sent[found]
    settled_packets = np.zeros(len(frames_sent), dtype=np.int64)
    settled_packets[found] = packets_settled[at[found]]

    def lost(outcome: FrameOutcome) -> int:
        return int(np.count_nonzero(worst == _RANK[outcome]))

    return DirectionCounts(
        frames_sent=sent,
        frames_dropped=dropped,
        frames_collided=lost(FrameOutcome.COLLIDED),
        frames_outage=lost(FrameOutcome.OUTAGE),
        frames_out_of_range=lost(FrameOutcome.OUT_OF_RANGE),
        frames_corrupted=lost(FrameOutcome.CORRUPTED),
        frames_settled=int(np.count_nonzero(settled_packets >= packets_sent)),
        mean_on_air_bytes=mean_on_air_bytes,
    )
