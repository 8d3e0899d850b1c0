"""Typed link events: what happened to every frame, when, where.

The medium records one :class:`LinkEvent` per happening (a tuple appended, nothing more) to an
optional :class:`Trace`, which keeps them as compact columns (21 B per event); later stages (the
recorder, the paper's Fig. 4 timeline) read it. Events
are recorded when the medium decides them, so a ``TX_END`` is recorded at its transmission's start
with its future time: use :meth:`Trace.in_time_order` for a timeline.

Every copy of a transmission that reaches a receiver ends in exactly one of ``DELIVER``,
``CORRUPT``, ``COLLIDE``, ``DEAF``, ``OUTAGE`` or ``OUT_OF_RANGE``; every frame handed to a modem is
``ENQUEUE``\\ d and then either ``DROP``\\ ped or sent as one ``TX_START``/``TX_END`` pair per
packet.

What became of each frame is read from a trace by :mod:`testbed.channel.outcomes`.

This module imports nothing from simpy.
"""

from __future__ import annotations

import enum
from array import array
from collections.abc import Iterable, Iterator, Sequence
from typing import Any, NamedTuple, overload

import numpy as np

__all__ = [
    "BROADCAST",
    "KIND_BY_CODE",
    "KIND_CODE",
    "EventKind",
    "LinkEvent",
    "ListEquality",
    "Trace",
    "TraceColumns",
    "TraceEvents",
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
    """A copy was destroyed by another copy overlapping it at the receiver."""
    OUT_OF_RANGE = "out_of_range"
    """The receiver was beyond ``max_range_m`` at transmit time: nothing arrives."""
    OUTAGE = "outage"
    """A copy overlapped a link outage window (:meth:`~testbed.channel.medium.Medium.add_outage`)
    and was lost."""
    DEAF = "deaf"
    """A copy lost only because its half-duplex receiver was transmitting (no other copy
    overlapped it); the frame's outcome is ``collided``, the receiver's ``rx_deaf`` counts it.
    Last in the enum so the older kinds keep their codes."""


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

KIND_BY_CODE: tuple[EventKind, ...] = tuple(EventKind)
KIND_CODE: dict[EventKind, int] = {kind: code for code, kind in enumerate(KIND_BY_CODE)}


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
        return KIND_CODE[kind]


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


def _cut(column: array[Any], length: int) -> array[Any]:
    """``column`` with no more than ``length`` values: the same array, or a copy if a NumPy view
    of it is held."""
    if len(column) > length:
        try:
            del column[length:]
        except BufferError:
            return array(column.typecode, column[:length])
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
        "_columns",
        "_kinds",
        "_length",
        "_name_code",
        "_names",
        "_pending",
    )

    def __init__(self, kinds: Iterable[EventKind] | None = None) -> None:
        self._kinds = frozenset(EventKind) if kinds is None else frozenset(kinds)
        self._pending: list[tuple[float, EventKind, str, str, int, int, int, int]] = []
        self._names: list[str] = []
        self._name_code: dict[str, int] = {}
        # time, kind, src, dst, frame id, part, size, bit errors
        self._columns: tuple[array[Any], ...] = (
            *(array(code) for code in "dBBBi"),
            *(array("h") for _ in range(3)),
        )
        self._length = 0  # events in the columns (an interrupted flush may leave more: cut)

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
            # the name first, then its code: an interrupt between leaves an unused name, never
            # a code without one
            self._names.append(name)
            code = self._name_code[name] = len(self._names) - 1
        return code

    def _flush(self) -> None:
        """Move the pending tuples to the columns, in one step an interrupt cannot split.

        A ``KeyboardInterrupt`` (Ctrl-C, or the CLI's SIGTERM) is raised wherever the program
        is, and a run that ends by one writes its trace. Raised while the columns were being
        extended one after the other, it would leave them of unequal lengths with the tuples
        still pending (moved again by the next flush). So the columns are first cut back to
        the committed length (what an interrupted flush left beyond it), extended, and only then
        committed together with an empty pending list by one assignment (Python runs signal
        handlers at calls and loops; the assignment's stores come after its last call).
        """
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
        n = self._length
        values = (
            t_s,
            bytes(map(KIND_CODE.__getitem__, kind)),
            src_codes,
            dst_codes,
            frame_id,
            part,
            size_bytes,
            bit_errors,
        )
        columns = tuple(
            _extend(_cut(column, n), new) for column, new in zip(self._columns, values, strict=True)
        )
        self._columns, self._length, self._pending = columns, n + len(pending), []

    @property
    def events(self) -> TraceEvents:
        """The recorded events in recording order (a read-only sequence view)."""
        return TraceEvents(self)

    def columns(self) -> TraceColumns:
        """NumPy views of the columns (see :class:`TraceColumns`)."""
        self._flush()
        t, kind, src, dst, frame, part, size, bits = map(_view, self._columns)
        return TraceColumns(
            t, kind, src, dst, frame, part, size, bits, KIND_BY_CODE, tuple(self._names)
        )

    def name_code(self, name: str) -> int | None:
        """The code of node ``name`` in :attr:`TraceColumns.names`; None if never recorded."""
        self._flush()
        return self._name_code.get(name)

    @property
    def nbytes(self) -> int:
        """Bytes held by the columns (the pending tuples not counted)."""
        return sum(c.itemsize * len(c) for c in self._columns)

    def _slice(self, start: int, stop: int) -> list[LinkEvent]:
        """Events ``start:stop`` (``0 ≤ start ≤ stop ≤ len``) built as :class:`LinkEvent`."""
        self._flush()
        names = self._names
        return [
            LinkEvent(t, KIND_BY_CODE[k], names[s], names[d], f, p, n, b)
            for t, k, s, d, f, p, n, b in zip(
                *(column[start:stop] for column in self._columns), strict=True
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
        return self._length + len(self._pending)

    def __iter__(self) -> Iterator[LinkEvent]:
        self._flush()
        start = 0
        while start < len(self):
            stop = min(start + _CHUNK, len(self))
            yield from self._slice(start, stop)
            start = stop


class ListEquality(Sequence[Any]):
    """A read-only sequence view that compares equal to any sequence of equal items (a list
    included), as the list it stands for would; unhashable, like a list."""

    __slots__ = ()

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Sequence) or isinstance(other, str | bytes):
            return NotImplemented
        return len(self) == len(other) and all(a == b for a, b in zip(self, other, strict=True))

    __hash__ = None  # type: ignore[assignment]


class TraceEvents(ListEquality, Sequence[LinkEvent]):
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

    def __repr__(self) -> str:
        return f"<{len(self)} link events>"
