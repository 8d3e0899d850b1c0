"""What one run records: link events, command and state updates, and vehicle time series.

The runner's nodes append to a :class:`Recorder` as the run goes (plain appends, nothing
computed); :mod:`testbed.run.metrics` and :mod:`testbed.report.run_plots` read it
afterwards. Link events and series rows are held as compact columns
(:class:`~testbed.channel.Trace`, :class:`SeriesRows`, :class:`FloatPairs`), so a long run's
memory grows by ≈ 21 B per link event, 8 B per series value and 16 B per command or odometry
update; the CSV files are written row by row from them.
The recorder is
the simulation's ground truth: it knows things the nodes cannot (when the sticks carried by a
frame were really sampled, the physics pose), and nodes never read it.

Series rows are taken at the first vehicle control frame at or after each sample instant
(``metrics.sample_rate_hz``, so their spacing is uneven by up to a frame). Node names on the link
are ``"operator"`` and ``"vehicle"``; the uplink is operator → vehicle.
"""

from __future__ import annotations

import csv
import math
from array import array
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, overload

import numpy as np
import numpy.typing as npt

from testbed.channel import Trace
from testbed.channel.trace import ListEquality
from testbed.config import CSV_NUMBER_FORMAT
from testbed.run.image_record import ImageLog

if TYPE_CHECKING:
    from testbed.run.arm_log import ArmLog
    from testbed.run.link_log import LinkStateLog

__all__ = [
    "SERIES_COLUMNS",
    "FloatPairs",
    "NodeEvent",
    "Recorder",
    "SeriesRows",
    "failsafe_engagements",
]

OPERATOR = "operator"
VEHICLE = "vehicle"

SERIES_COLUMNS = (
    "t_s",
    "cmd_x", "cmd_y", "cmd_z", "cmd_yaw",            # pilot's sticks at t (operator truth)
    "rx_x", "rx_y", "rx_z", "rx_yaw",                # sticks the vehicle is applying at t
    "ref_u", "ref_v", "ref_w", "ref_r",              # velocity the applied sticks ask for
    "north_m", "east_m", "down_m",                   # physics truth, body origin, NED
    "roll_deg", "pitch_deg", "yaw_deg",
    "u", "v", "w", "p", "q", "r",                    # body velocities [m/s, rad/s], FRD
    "err_roll_deg", "err_pitch_deg", "err_yaw_deg",  # attitude error against the target
    "depth_target_m",
    "current_a",                                     # total thruster current (plant forces)
    "armed", "failsafe",
    "target_n", "target_e", "target_d",              # autonomy's pose target, NED (NaN: none)
    "target_yaw_deg",
    "est_n", "est_e", "est_d",                       # navigation estimate, NED (NaN: none)
    "ee_n", "ee_e", "ee_d",                          # end effector, truth, NED (NaN: no arm)
    "ee_target_n", "ee_target_e", "ee_target_d",     # autonomy's end-effector target (NaN: none)
    "mode",                                          # mode in effect, ArduSub's number (NaN: none)
)  # fmt: skip
"""Columns of :attr:`Recorder.series`, in order (filled by
:meth:`~testbed.run.observer.VehicleObserver.row`)."""


class SeriesRows(Sequence[tuple[float, ...]]):
    """Append-only series rows of a fixed width, held in one flat ``array('d')`` (8 B per
    value) rather than as tuples of floats (≈ 30 B per value).

    Iterating gives the rows back as tuples of floats; ``np.asarray(rows)`` is the
    ``(len, width)`` table.

    Args:
        width: values per row.
        rows: rows to start with.
    """

    __slots__ = ("_values", "width")

    def __init__(self, width: int = len(SERIES_COLUMNS), rows: Iterable[Sequence[float]] = ()):
        self.width = width
        self._values = array("d")
        for row in rows:
            self.append(row)

    def append(self, row: Sequence[float]) -> None:
        """Append one row of :attr:`width` values."""
        if len(row) != self.width:
            raise ValueError(f"a series row has {self.width} values, got {len(row)}")
        try:
            self._values.extend(row)
        except BufferError:  # a view of the values is held (:meth:`table`): grow a copy
            self._values = array("d", self._values)
            self._values.extend(row)

    def table(self) -> np.ndarray:
        """The rows as a read-only ``(len, width)`` array sharing the buffer (no copy); rows
        appended later are not in it."""
        view = np.frombuffer(self._values, dtype=np.float64).reshape(-1, self.width)
        view.flags.writeable = False
        return view

    def __len__(self) -> int:
        return len(self._values) // self.width

    @overload
    def __getitem__(self, index: int) -> tuple[float, ...]: ...

    @overload
    def __getitem__(self, index: slice) -> list[tuple[float, ...]]: ...

    def __getitem__(self, index: int | slice) -> tuple[float, ...] | list[tuple[float, ...]]:
        if isinstance(index, slice):
            return [self[i] for i in range(*index.indices(len(self)))]
        i = index + len(self) if index < 0 else index
        if not 0 <= i < len(self):
            raise IndexError("series row index out of range")
        return tuple(self._values[i * self.width : (i + 1) * self.width])

    def __iter__(self) -> Iterator[tuple[float, ...]]:
        width = self.width
        values = self._values
        chunk = width * 1024
        for start in range(0, len(values), chunk):
            flat = values[start : start + chunk].tolist()
            for k in range(0, len(flat), width):
                yield tuple(flat[k : k + width])

    def __array__(self, dtype: npt.DTypeLike | None = None, copy: bool | None = None) -> np.ndarray:
        return np.array(self._values, dtype=np.float64 if dtype is None else dtype).reshape(
            -1, self.width
        )

    @property
    def nbytes(self) -> int:
        """Bytes held by the values."""
        return self._values.itemsize * len(self._values)


class FloatPairs(ListEquality, Sequence[tuple[float, float]]):
    """Append-only ``(a, b)`` float pairs in one flat ``array('d')`` (16 B per pair rather than
    ≈ 110 B as a tuple of floats in a list); iterating gives them back as tuples.

    Args:
        pairs: pairs to start with.
    """

    __slots__ = ("_values",)

    def __init__(self, pairs: Iterable[tuple[float, float]] = ()) -> None:
        self._values = array("d")
        for pair in pairs:
            self.append(pair)

    def append(self, pair: tuple[float, float]) -> None:
        """Append one pair (in one call: an interrupt lands before or after it, never between
        its two values)."""
        a, b = pair
        self._values.extend((a, b))

    def __len__(self) -> int:
        return len(self._values) // 2

    @overload
    def __getitem__(self, index: int) -> tuple[float, float]: ...

    @overload
    def __getitem__(self, index: slice) -> list[tuple[float, float]]: ...

    def __getitem__(self, index: int | slice) -> tuple[float, float] | list[tuple[float, float]]:
        if isinstance(index, slice):
            return [self[i] for i in range(*index.indices(len(self)))]
        i = index + len(self) if index < 0 else index
        if not 0 <= i < len(self):
            raise IndexError("pair index out of range")
        return self._values[2 * i], self._values[2 * i + 1]

    def __iter__(self) -> Iterator[tuple[float, float]]:
        values = self._values
        for start in range(0, len(values), 8192):
            flat = values[start : start + 8192].tolist()
            yield from zip(flat[::2], flat[1::2], strict=True)

    def __repr__(self) -> str:
        return f"FloatPairs({list(self)!r})"


@dataclass(frozen=True, slots=True)
class NodeEvent:
    """Something a node did, for the event file: arming, a fault, a failsafe change."""

    t_s: float
    node: str
    kind: str
    detail: str = ""


def failsafe_engagements(events: Sequence[NodeEvent]) -> int:
    """Times the failsafe engaged: its level left NOMINAL (a HOLD that went on to SURFACE is
    one engagement; the return to NOMINAL is not another)."""
    count = 0
    level = "NOMINAL"
    for event in events:
        if event.kind == "failsafe":
            if level == "NOMINAL" and event.detail != "NOMINAL":
                count += 1
            level = event.detail
    return count


@dataclass(slots=True)
class Recorder:
    """Append-only record of one run.

    Attributes:
        trace: every link event (both directions).
        commands_sampled: operator command seq → time its sticks were sampled [s].
        commands_applied: operator command seq → vehicle frame time it was first applied [s].
        uplink_commands: uplink frame id → (command seq, sampled time [s]) of the sticks it
            carries (teleop orders carry no time on the wire).
        command_updates: ``(applied_s, sampled_s)`` each time the vehicle started applying a
            newer command (for the age of the command in force).
        odometry_updates: ``(applied_s, sampled_s)`` each time the operator took in newer
            vehicle state.
        frames_decoded: link direction (``"uplink"``/``"downlink"``) → frames whose CRC checked
            at the receiver.
        frames_rejected: link direction → payloads that decoded as frames but were refused by
            the codec (garbled past the CRC, or written by the wrong side).
        frame_bytes_sent: link direction → bytes of the frames the sender handed to its modem
            [B], framing included, packet padding not (the modem adds that).
        events: node events in time order.
        rows: series rows (see :data:`SERIES_COLUMNS`): a :class:`SeriesRows`, or any list of
            row tuples.
        images: images captured, sent and received (image feedback runs).
        arm: the arm's joints and set tasks (a vehicle with an arm), else None.
        link_state: a link model's own state, sampled with the series rows (a model with
            ``state``: :mod:`testbed.run.link_log`), else None.
        stick_source: what the ``cmd_*`` columns hold: ``"pilot"`` (the pilot sampled at each
            row's instant, its continuous stick) or ``"operator samples"`` (a pilot that is not
            a pure function of time: the operator's own samples, held between its frames).
    """

    trace: Trace = field(default_factory=Trace)
    commands_sampled: dict[int, float] = field(default_factory=dict)
    commands_applied: dict[int, float] = field(default_factory=dict)
    uplink_commands: dict[int, tuple[int, float]] = field(default_factory=dict)
    command_updates: FloatPairs = field(default_factory=FloatPairs)
    odometry_updates: FloatPairs = field(default_factory=FloatPairs)
    frames_decoded: dict[str, int] = field(default_factory=lambda: {"uplink": 0, "downlink": 0})
    frames_rejected: dict[str, int] = field(default_factory=lambda: {"uplink": 0, "downlink": 0})
    frame_bytes_sent: dict[str, int] = field(default_factory=lambda: {"uplink": 0, "downlink": 0})
    events: list[NodeEvent] = field(default_factory=list)
    rows: SeriesRows | list[tuple[float, ...]] = field(default_factory=SeriesRows)
    images: ImageLog = field(default_factory=ImageLog)
    arm: ArmLog | None = None
    link_state: LinkStateLog | None = None
    stick_source: str = "pilot"

    def event(self, t_s: float, node: str, kind: str, detail: str = "") -> None:
        """Record a node event."""
        self.events.append(NodeEvent(t_s, node, kind, detail))

    def series(self) -> dict[str, np.ndarray]:
        """The series as one array per column (read-only views of the rows, no copy)."""
        rows = self.rows
        if isinstance(rows, SeriesRows) and rows.width == len(SERIES_COLUMNS):
            table = rows.table()  # no copy
        else:
            table = np.asarray(rows, dtype=float).reshape(-1, len(SERIES_COLUMNS))
        return {name: table[:, k] for k, name in enumerate(SERIES_COLUMNS)}

    def write_series_csv(self, path: Path) -> None:
        """Write the series rows as CSV: a header of :data:`SERIES_COLUMNS`, values to 6
        significant digits."""
        with path.open("w", encoding="utf-8") as handle:
            handle.write(",".join(SERIES_COLUMNS) + "\n")
            for row in self.rows:
                handle.write(",".join(f"{v:{CSV_NUMBER_FORMAT}}" for v in row) + "\n")

    def write_events_csv(self, path: Path, until_s: float = math.inf) -> None:
        """Write every link and node event, in time order, as CSV.

        Columns: ``t_s, source, kind, src, dst, frame_id, part, size_bytes, bit_errors, detail``;
        ``source`` is ``link`` or the node's name. Equal times keep recording order, link events
        before node events. Written row by row from the trace's columns (the memory it takes
        is one index per link event). Link events after ``until_s`` [s] (the run's end) are
        left out: a transmission's end is traced as it starts, and one still on the air when
        the run ended had not ended.
        """
        header = ["t_s", "source", "kind", "src", "dst", "frame_id", "part", "size_bytes"]
        header += ["bit_errors", "detail"]
        with path.open("w", newline="", encoding="utf-8") as handle:
            writer = csv.writer(handle, lineterminator="\n")
            writer.writerow(header)
            writer.writerows(self._event_rows(until_s))

    def _event_rows(self, until_s: float = math.inf) -> Iterator[list[object]]:
        """The rows of :meth:`write_events_csv`, in time order."""
        nodes = sorted(self.events, key=lambda n: n.t_s)  # stable: recording order on ties
        node_rows = iter(nodes)
        node = next(node_rows, None)
        columns = self.trace.columns()
        kinds = [str(kind) for kind in columns.kinds]
        names = columns.names
        for window in _time_order_chunks(columns.t_s):
            for start in range(0, len(window), _FORMAT_CHUNK):
                at = window[start : start + _FORMAT_CHUNK]
                chunk = zip(
                    columns.t_s[at].tolist(),
                    columns.kind[at].tolist(),
                    columns.src[at].tolist(),
                    columns.dst[at].tolist(),
                    columns.frame_id[at].tolist(),
                    columns.part[at].tolist(),
                    columns.size_bytes[at].tolist(),
                    columns.bit_errors[at].tolist(),
                    strict=True,
                )
                for t_s, kind, src, dst, frame_id, part, size_bytes, bit_errors in chunk:
                    if t_s > until_s:
                        continue
                    while node is not None and node.t_s < t_s:  # equal times: link first
                        yield _node_row(node)
                        node = next(node_rows, None)
                    fields: list[object] = [
                        f"{t_s:.9f}",
                        "link",
                        kinds[kind],
                        names[src],
                        names[dst],
                    ]
                    fields += [frame_id, part, size_bytes, bit_errors, ""]
                    yield fields
        while node is not None:
            yield _node_row(node)
            node = next(node_rows, None)


_WRITE_CHUNK = 262144
"""About how many link events :meth:`Recorder.write_events_csv` sorts at a time."""
_FORMAT_CHUNK = 8192
"""How many link events it turns into Python values at a time."""


def _time_order_chunks(t_s: np.ndarray) -> Iterator[np.ndarray]:
    """The indices of ``t_s`` in time order (stable: equal times keep their order), in
    consecutive chunks of successive time windows of ≈ :data:`_WRITE_CHUNK` events on average:
    no index over all events is ever held. Times that are not finite come last."""
    n = len(t_s)
    finite = np.isfinite(t_s)
    n_finite = int(np.count_nonzero(finite))
    if n_finite:
        lo = float(np.min(t_s, initial=np.inf, where=finite))
        hi = float(np.max(t_s, initial=-np.inf, where=finite))
        windows = max(1, -(-n_finite // _WRITE_CHUNK))
        edges = np.linspace(lo, hi, windows + 1)
        for k in range(windows):
            upper = t_s <= hi if k == windows - 1 else t_s < edges[k + 1]
            at = np.flatnonzero(upper & (t_s >= edges[k]))
            yield at[np.argsort(t_s[at], kind="stable")]
    if n_finite < n:
        yield np.flatnonzero(~finite)


def _node_row(n: NodeEvent) -> list[object]:
    return [f"{n.t_s:.9f}", n.node, n.kind, "", "", "", "", "", "", n.detail]
