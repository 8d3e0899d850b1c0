"""Typed link events: what happened to every frame, when, where.

The medium records one :class:`LinkEvent` per happening (a tuple appended, nothing more) to an
optional :class:`Trace`, which keeps them as compact columns (21 B per event); later stages (the
recorder, the paper's Fig. 4 timeline) read it. Events
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
from array import array
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple, overload

import numpy as np

__all__ = [
    "BROADCAST",
    "RECEPTION_OUTCOMES",
    "DirectionCounts",
    "EventKind",
    "FrameOutcome",
    "LinkEvent",
    "Trace",
    "TraceColumns",
    "TraceEvents",
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


_CHUNK = 4096
"""Events held as tuples before they go to the columns (one transpose per chunk)."""

_KIND_BY_CODE: tuple[EventKind, ...] = tuple(EventKind)
_KIND_CODE: dict[EventKind, int] = {kind: code for code, kind in enumerate(_KIND_BY_CODE)}


class TraceColumns(NamedTuple):
    """Read-only NumPy views of a :class:`Trace`'s columns, one entry per event in recording
    order (:meth:`Trace.columns`). ``kind`` holds codes into :attr:`kinds`, ``src``/``dst``
    codes into :attr:`names`.

    The views share the trace's buffers (no copy); events recorded later are not in them.
    """

    t_s: np.ndarray
    kind: np.ndarray
    src: np.ndarray
    dst: np.ndarray
    frame_id: np.ndarray
    part: np.ndarray
    size_bytes: np.ndarray
    bit_errors: np.ndarray
    kinds: tuple[EventKind, ...]
    names: tuple[str, ...]

    def code_of(self, kind: EventKind) -> int:
        """The code of ``kind`` in :attr:`kind`."""
        return _KIND_CODE[kind]


_WIDER = {"B": "H", "H": "q", "h": "i", "i": "q"}
"""Integer column type → the next wider one, taken when a value does not fit."""


def _extend(column: array[Any], values: Sequence[Any]) -> array[Any]:
    """``column`` with ``values`` appended: the same array, or a copy if a NumPy view of it is
    held (:meth:`Trace.columns`; the view keeps the values it saw), or a wider copy if one of
    the values does not fit its type."""
    try:
        if column.typecode == "d":
            column.extend(values)
        elif column.typecode == "B":
            column.frombytes(bytes(values))  # faster than array("B", ...); ValueError past 255
        else:
            column.extend(array(column.typecode, values))
    except BufferError:
        return _extend(array(column.typecode, column), values)
    except (OverflowError, ValueError):
        wider = _WIDER.get(column.typecode)
        if wider is None:
            raise
        return _extend(array(wider, column), values)
    return column


def _view(column: array[int]) -> np.ndarray:
    return np.frombuffer(column, dtype=np.dtype(column.typecode))


class Trace:
    """Append-only record of :class:`LinkEvent`, optionally limited to some kinds.

    Held as compact columns (``array.array``) rather than one tuple per event (≈ 200 B): time
    8 B, kind 1 B, src and dst 1 B each (indices into the node names seen), frame id 4 B, part,
    size and bit errors 2 B each — 21 B per event; an integer column widens (to 8 B at most)
    when a value does not fit. :attr:`events` is a read-only
    sequence view that builds the :class:`LinkEvent` on demand; :meth:`columns` gives NumPy
    views for vectorised readers.

    Args:
        kinds: record only these kinds (e.g. losses only, to keep long runs cheap); all if None.
    """

    __slots__ = (
        "_bits",
        "_dst",
        "_frame",
        "_kind",
        "_kinds",
        "_name_code",
        "_names",
        "_part",
        "_pending",
        "_size",
        "_src",
        "_t",
    )

    def __init__(self, kinds: Iterable[EventKind] | None = None) -> None:
        self._kinds = frozenset(EventKind) if kinds is None else frozenset(kinds)
        self._pending: list[tuple[float, EventKind, str, str, int, int, int, int]] = []
        self._names: list[str] = []
        self._name_code: dict[str, int] = {}
        self._t = array("d")
        self._kind = array("B")
        self._src = array("B")
        self._dst = array("B")
        self._frame = array("i")
        self._part = array("h")
        self._size = array("h")
        self._bits = array("h")

    @classmethod
    def of(cls, events: Iterable[LinkEvent]) -> Trace:
        """A trace holding ``events`` (a :class:`Trace`, or its :attr:`events` view, is returned
        as it is)."""
        if isinstance(events, Trace):
            return events
        if isinstance(events, TraceEvents):
            return events.trace
        trace = cls()
        for event in events:
            trace.record(*event)
        return trace

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
            pending = self._pending
            pending.append((t_s, kind, src, dst, frame_id, part, size_bytes, bit_errors))
            if len(pending) >= _CHUNK:
                self._flush()

    def _code(self, name: str) -> int:
        code = self._name_code.get(name)
        if code is None:
            code = self._name_code[name] = len(self._names)
            self._names.append(name)
        return code

    def _flush(self) -> None:
        """Move the pending tuples to the columns."""
        pending = self._pending
        if not pending:
            return
        t_s, kind, src, dst, frame_id, part, size_bytes, bit_errors = zip(*pending)  # noqa: B905 (all of 8)
        codes = self._name_code
        try:
            src_codes = list(map(codes.__getitem__, src))
            dst_codes = list(map(codes.__getitem__, dst))
        except KeyError:  # a new name: give every name of the chunk its code, in order
            for name in dict.fromkeys((*src, *dst)):
                self._code(name)
            src_codes = list(map(codes.__getitem__, src))
            dst_codes = list(map(codes.__getitem__, dst))
        self._t = _extend(self._t, t_s)
        self._kind = _extend(self._kind, bytes(map(_KIND_CODE.__getitem__, kind)))
        self._src = _extend(self._src, src_codes)
        self._dst = _extend(self._dst, dst_codes)
        self._frame = _extend(self._frame, frame_id)
        self._part = _extend(self._part, part)
        self._size = _extend(self._size, size_bytes)
        self._bits = _extend(self._bits, bit_errors)
        pending.clear()

    @property
    def events(self) -> TraceEvents:
        """The recorded events in recording order (a read-only sequence view)."""
        return TraceEvents(self)

    def columns(self) -> TraceColumns:
        """NumPy views of the columns (see :class:`TraceColumns`)."""
        self._flush()
        return TraceColumns(
            np.frombuffer(self._t, dtype=np.float64),
            np.frombuffer(self._kind, dtype=np.uint8),
            _view(self._src),
            _view(self._dst),
            _view(self._frame),
            _view(self._part),
            _view(self._size),
            _view(self._bits),
            _KIND_BY_CODE,
            tuple(self._names),
        )

    def name_code(self, name: str) -> int | None:
        """The code of node ``name`` in :attr:`TraceColumns.names`; None if never recorded."""
        self._flush()
        return self._name_code.get(name)

    @property
    def nbytes(self) -> int:
        """Bytes held by the columns (the pending tuples not counted)."""
        columns = (self._t, self._kind, self._src, self._dst, self._frame, self._part)
        return sum(c.itemsize * len(c) for c in (*columns, self._size, self._bits))

    def _slice(self, start: int, stop: int) -> list[LinkEvent]:
        """Events ``start:stop`` (``0 ≤ start ≤ stop ≤ len``) built as :class:`LinkEvent`."""
        self._flush()
        names = self._names
        return [
            LinkEvent(t, _KIND_BY_CODE[k], names[s], names[d], f, p, n, b)
            for t, k, s, d, f, p, n, b in zip(
                self._t[start:stop],
                self._kind[start:stop],
                self._src[start:stop],
                self._dst[start:stop],
                self._frame[start:stop],
                self._part[start:stop],
                self._size[start:stop],
                self._bits[start:stop],
                strict=True,
            )
        ]

    def of_kind(self, *kinds: EventKind) -> list[LinkEvent]:
        """The recorded events of the given kinds, in recording order."""
        wanted = frozenset(kinds)
        return [e for e in self if e.kind in wanted]

    def in_time_order(self) -> list[LinkEvent]:
        """All recorded events sorted by time (stable: equal times keep recording order)."""
        order = np.argsort(self.columns().t_s, kind="stable")
        events = self._slice(0, len(self))
        return [events[i] for i in order.tolist()]

    def __len__(self) -> int:
        return len(self._t) + len(self._pending)

    def __iter__(self) -> Iterator[LinkEvent]:
        self._flush()
        start = 0
        while start < len(self):
            stop = min(start + _CHUNK, len(self))
            yield from self._slice(start, stop)
            start = stop


class TraceEvents(Sequence[LinkEvent]):
    """Read-only sequence view of a :class:`Trace`'s events (:attr:`Trace.events`); equal to
    any sequence of the same events."""

    __slots__ = ("_trace",)

    def __init__(self, trace: Trace) -> None:
        self._trace = trace

    @property
    def trace(self) -> Trace:
        """The trace viewed."""
        return self._trace

    def __len__(self) -> int:
        return len(self._trace)

    @overload
    def __getitem__(self, index: int) -> LinkEvent: ...

    @overload
    def __getitem__(self, index: slice) -> list[LinkEvent]: ...

    def __getitem__(self, index: int | slice) -> LinkEvent | list[LinkEvent]:
        n = len(self._trace)
        if isinstance(index, slice):
            start, stop, step = index.indices(n)
            if step == 1:
                return self._trace._slice(start, max(start, stop))
            return [self[i] for i in range(start, stop, step)]
        i = index + n if index < 0 else index
        if not 0 <= i < n:
            raise IndexError("trace event index out of range")
        return self._trace._slice(i, i + 1)[0]

    def __iter__(self) -> Iterator[LinkEvent]:
        return iter(self._trace)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Sequence) or isinstance(other, str | bytes):
            return NotImplemented
        return len(self) == len(other) and all(a == b for a, b in zip(self, other, strict=True))

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        return f"<{len(self)} link events>"


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
_RECEPTION_RANK = np.array(
    [
        _RANK[RECEPTION_OUTCOMES[kind]] if kind in RECEPTION_OUTCOMES else len(_SEVERITY)
        for kind in _KIND_BY_CODE
    ],
    dtype=np.int64,
)
"""Kind code → rank of its reception outcome (``len(_SEVERITY)`` for the other kinds)."""
_IS_RECEPTION = np.array([kind in RECEPTION_OUTCOMES for kind in _KIND_BY_CODE])
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
    on_air = (kind != _KIND_CODE[EventKind.ENQUEUE]) & (kind != _KIND_CODE[EventKind.DROP])
    seen = np.unique(_keys(columns.frame_id[on_air], columns.part[on_air]))
    at, found = _lookup(parts, seen)
    seen_rank = np.full(len(seen), _RANK[FrameOutcome.PENDING], dtype=np.int64)
    seen_rank[found] = part_rank[at[found]]
    frames, first = np.unique(columns.frame_id, return_index=True)
    rank = np.full(len(frames), _NO_RANK, dtype=np.int64)
    np.minimum.at(rank, np.searchsorted(frames, seen["k0"]), seen_rank)
    rank[rank == _NO_RANK] = _RANK[FrameOutcome.PENDING]  # no packet on the air
    dropped = np.unique(columns.frame_id[kind == _KIND_CODE[EventKind.DROP]])
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
    starts = kind == _KIND_CODE[EventKind.TX_START]
    ends = kind == _KIND_CODE[EventKind.TX_END]
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
    trace = Trace.of(events)
    columns = trace.columns()
    src_code, dst_code = trace.name_code(src), trace.name_code(dst)
    if src_code is None:
        return DirectionCounts(0, 0, 0, 0, 0, 0, 0, math.nan)
    # masks of one byte per event and copies of the few events concerned: no array of
    # 8 B per event, so that counting a long run takes little memory on top of its trace
    mine = columns.src == src_code
    kind = columns.kind
    enqueued = mine & (kind == _KIND_CODE[EventKind.ENQUEUE])
    sent = int(np.count_nonzero(enqueued))
    sizes = columns.size_bytes[enqueued].astype(np.int64)
    mean_frame_bytes = float(np.mean(sizes)) if sent else math.nan
    del sizes
    del enqueued
    dropped = int(np.count_nonzero(mine & (kind == _KIND_CODE[EventKind.DROP])))
    started = columns.frame_id[mine & (kind == _KIND_CODE[EventKind.TX_START])]
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
        mean_frame_bytes=mean_frame_bytes,
    )
