"""The recorded pilot: the sticks of an earlier run played back, open loop, as a function of time.

A run's ``series.csv`` (``testbed run``, ``testbed live``, ``testbed hil``) holds, per row, the
sticks its pilot held (``cmd_x, cmd_y, cmd_z, cmd_yaw``: surge, sway, heave, yaw in [−1, 1]) at
the row's time ``t_s``. :func:`load_recorded_pilot` reads those five columns of such a file (any
other columns are left alone) once, checks them, and makes a :class:`RecordedPilot`: a pure
function of time, so the recorder samples it again at its rows (``cmd_*``) as it does the
scripted pilot. The sticks are held: at time ``t`` the pilot gives the row in force at ``t``, the
last one at or before it (zero-order hold at the file's rate); before the first row and after
the last one it gives centred sticks. Roll and pitch sticks stay centred (the columns hold none).
Only the sticks are replayed: a person's mode changes, arming, go-to clicks and link changes
are in ``events.csv``, not here.

The file is data: each value is parsed with ``float`` and checked; nothing in it is evaluated.

Imports: ``config`` and the standard library only; ``operator.pilots`` (which lists this pilot
among its pure ones, :data:`~testbed.operator.pilots.PURE_PILOTS`) when a pilot samples.
"""

from __future__ import annotations

import bisect
import csv
import math
from array import array
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, NoReturn, TextIO

from testbed.config import CSV_SIGNIFICANT_DIGITS, ConfigError

if TYPE_CHECKING:
    from testbed.operator.pilots import PilotSample

__all__ = [
    "MAX_LINE_CHARS",
    "MAX_ROWS",
    "STICK_COLUMNS",
    "TIME_COLUMN",
    "RecordedPilot",
    "load_recorded_pilot",
]

TIME_COLUMN = "t_s"
"""The column of each row's time [s]."""
STICK_COLUMNS = ("cmd_x", "cmd_y", "cmd_z", "cmd_yaw")
"""The columns of the sticks replayed: surge, sway, heave (+ down), yaw, each in [−1, 1]."""
MAX_LINE_CHARS = 65536
"""Longest accepted line [characters] (a ``series.csv`` row is ≈ 500): a file without line ends
(``/dev/zero``) is refused, not read into memory."""
MAX_ROWS = 20_000_000
"""Most rows accepted: a simulated day (the longest run) at 200 Hz."""


def _half_unit(written_s: float) -> float:
    """Half a unit of the last of :data:`~testbed.config.CSV_SIGNIFICANT_DIGITS` digits of
    ``written_s`` [s]: how far the instant a time written that way stands for may lie from it."""
    if written_s == 0.0:
        return 0.0
    exponent = math.floor(math.log10(abs(written_s))) - (CSV_SIGNIFICANT_DIGITS - 1)
    return 0.5 * 10.0**exponent


@dataclass(frozen=True, slots=True, eq=False)
class RecordedPilot:
    """Recorded sticks, held: at time ``t`` the row in force at ``t − shift_s``.

    A row's time is read as ``series.csv`` writes it, to six significant digits, so it stands
    for any instant that rounds to it: row ``k`` (time ``t_k``) is in force from half a unit of
    its sixth digit before ``t_k`` (but not before the middle of the gap since row ``k − 1``)
    until row ``k + 1`` is; the last row until half a unit after its time. Outside that span
    the sticks are centred. So a run's recorder, sampling at the instants the recording's did,
    reads back each row's own values, although those instants (sums of physics steps) differ
    from the written times by rounding.

    Attributes:
        source: the file the sticks came from (for messages).
        times_s: (n,) each row's time as written [s], increasing.
        sticks: (n × 4,) surge, sway, heave and yaw of each row in turn, in [−1, 1].
        shift_s: the recording plays this much later [s] (negative: its first ``−shift_s``
            seconds are skipped).
    """

    source: str
    times_s: array[float]
    sticks: array[float]
    shift_s: float = 0.0
    _starts: array[float] = field(init=False, repr=False)
    _end_s: float = field(init=False, repr=False)

    def __post_init__(self) -> None:
        times = self.times_s
        if len(self.sticks) != 4 * len(times) or not times:
            raise ValueError("a recorded pilot needs at least one row and four sticks a row")
        starts = array("d")
        for k, written in enumerate(times):
            start = written - _half_unit(written)
            if k:
                start = max(start, 0.5 * (times[k - 1] + written))
            starts.append(start)
        object.__setattr__(self, "_starts", starts)
        object.__setattr__(self, "_end_s", times[-1] + _half_unit(times[-1]))

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, RecordedPilot):
            return NotImplemented
        return (self.source, self.times_s, self.sticks, self.shift_s) == (
            other.source,
            other.times_s,
            other.sticks,
            other.shift_s,
        )

    def shifted(self, shift_s: float) -> RecordedPilot:
        """The same recording played ``shift_s`` [s] later than it was recorded."""
        return RecordedPilot(self.source, self.times_s, self.sticks, shift_s)

    def sticks_at(self, t_s: float) -> tuple[float, float, float, float]:
        """Surge, sway, heave and yaw at run time ``t_s`` [s]: the row in force at
        ``t_s − shift_s`` (class docstring), or centred sticks outside the recording."""
        tau = t_s - self.shift_s
        k = bisect.bisect_right(self._starts, tau) - 1
        if k < 0 or tau > self._end_s:
            return (0.0, 0.0, 0.0, 0.0)
        x, y, z, yaw = self.sticks[4 * k : 4 * k + 4]
        return (x, y, z, yaw)

    def sample(self, t_s: float) -> PilotSample:
        """The held sticks at ``t_s`` [s]; roll and pitch stay centred."""
        from testbed.operator.pilots import PilotSample  # pilots imports this module

        x, y, z, yaw = self.sticks_at(t_s)
        return PilotSample((x, y, z, 0.0, 0.0, yaw))


def load_recorded_pilot(path: str | Path, shift_s: float = 0.0) -> RecordedPilot:
    """Read the sticks of a ``series.csv`` (module docstring) once, checked, into a pilot.

    The file is CSV with a header line naming its columns; it must have :data:`TIME_COLUMN`
    and :data:`STICK_COLUMNS` (others are ignored), and each data line as many fields as the
    header. Blank lines are skipped.

    Args:
        path: the file.
        shift_s: the recording plays this much later [s] (:class:`RecordedPilot`).

    Raises:
        ConfigError: one line naming the file and, for a bad value, its line (the header is
            line 1) and column: the file is missing or unreadable; a column is missing or
            named twice; a line is too long or has the wrong number of fields; a value is not
            a number or not finite; a stick is outside [−1, 1]; a time is not greater than the
            one before; no data line; more than :data:`MAX_ROWS`.
    """
    path = Path(path)
    try:
        with path.open(encoding="utf-8-sig", newline="") as handle:
            return _read(handle, str(path), shift_s)
    except FileNotFoundError:
        raise ConfigError(f"{path}: file not found") from None
    except IsADirectoryError:
        raise ConfigError(f"{path}: not a file") from None
    except (OSError, UnicodeDecodeError) as err:
        raise ConfigError(f"{path}: cannot read: {err}") from None


def _lines(handle: TextIO, source: str) -> Iterator[str]:
    """The file's lines, each at most :data:`MAX_LINE_CHARS` characters."""
    number = 0
    while True:
        line = handle.readline(MAX_LINE_CHARS + 1)
        if not line:
            return
        number += 1
        if len(line) > MAX_LINE_CHARS and not line.endswith("\n"):
            raise ConfigError(
                f"{source}: line {number}: longer than {MAX_LINE_CHARS} characters "
                "(not a series.csv)"
            )
        yield line


def _read(handle: TextIO, source: str, shift_s: float) -> RecordedPilot:
    reader = csv.reader(_lines(handle, source))
    try:
        header = next(reader, None)
        if header is None:
            raise ConfigError(f"{source}: empty file (expected a series.csv header line)")
        at_t, at_x, at_y, at_z, at_yaw = _columns(header, source)
        width = len(header)
        times, sticks = array("d"), array("d")
        last_s = -math.inf
        for row in reader:
            if len(row) != width:
                if not row:  # a blank line
                    continue
                raise ConfigError(
                    f"{source}: line {reader.line_num}: {len(row)} fields, expected {width} "
                    "(as the header)"
                )
            try:  # the common case in one go; anything off is looked at field by field
                t_s, x, y, z, yaw = (float(row[k]) for k in (at_t, at_x, at_y, at_z, at_yaw))
                good = last_s < t_s < math.inf and all(-1.0 <= v <= 1.0 for v in (x, y, z, yaw))
            except ValueError:
                good = False
            if not good:
                _refuse(row, (at_t, at_x, at_y, at_z, at_yaw), last_s, source, reader.line_num)
            if len(times) >= MAX_ROWS:
                raise ConfigError(f"{source}: more than {MAX_ROWS} rows")
            times.append(t_s)
            sticks.extend((x, y, z, yaw))
            last_s = t_s
    except csv.Error as err:
        raise ConfigError(f"{source}: line {reader.line_num}: malformed CSV: {err}") from None
    if not times:
        raise ConfigError(f"{source}: no data lines after the header")
    return RecordedPilot(source, times, sticks, shift_s)


def _refuse(row: list[str], at: tuple[int, ...], last_s: float, source: str, line: int) -> NoReturn:
    """Raise the first problem of a data row: a field that is not a finite number, a time not
    greater than ``last_s`` [s], a stick outside [−1, 1].

    Raises:
        ConfigError: naming ``source``, ``line`` and the column.
    """
    t_s = _number(row[at[0]], source, line, TIME_COLUMN)
    if not t_s > last_s:
        raise ConfigError(
            f"{source}: line {line}: {TIME_COLUMN}: times must increase, got {t_s:g} "
            f"after {last_s:g}"
        )
    for name, k in zip(STICK_COLUMNS, at[1:], strict=True):
        value = _number(row[k], source, line, name)
        if not -1.0 <= value <= 1.0:
            raise ConfigError(
                f"{source}: line {line}: {name}: a stick must be in [-1, 1], got {value:g}"
            )
    raise AssertionError(f"{source}: line {line}: refused, but no problem found")  # unreachable


def _columns(header: list[str], source: str) -> tuple[int, ...]:
    """Where :data:`TIME_COLUMN` and :data:`STICK_COLUMNS` are in ``header``."""
    names = [name.strip() for name in header]
    wanted = (TIME_COLUMN, *STICK_COLUMNS)
    missing = [name for name in wanted if name not in names]
    if missing:
        raise ConfigError(
            f"{source}: line 1: missing column{'s' if len(missing) > 1 else ''} "
            f"{', '.join(missing)} (a run's series.csv has {', '.join(wanted)})"
        )
    twice = [name for name in wanted if names.count(name) > 1]
    if twice:
        raise ConfigError(f"{source}: line 1: column {twice[0]} appears more than once")
    return tuple(names.index(name) for name in wanted)


def _number(text: str, source: str, line: int, column: str) -> float:
    """``text`` of ``column`` on ``line`` as a finite float."""
    try:
        value = float(text)
    except ValueError:
        shown = text if len(text) <= 40 else f"{text[:40]}…"
        raise ConfigError(
            f"{source}: line {line}: {column}: expected a number, got {shown!r}"
        ) from None
    if not math.isfinite(value):
        raise ConfigError(f"{source}: line {line}: {column}: must be finite, got {text.strip()}")
    return value
