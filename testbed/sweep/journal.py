"""The files of a results directory: the ``runs.jsonl`` journal and the CSV tables.

The journal holds one JSON line per finished run, appended in batches with one ``write`` and an
``fsync`` (:func:`append_rows`); a torn last line (a kill in the middle of a write) is cut off
by :func:`read_journal` with ``repair``; any other line that is not a record the sweep wrote
(the file was edited or damaged) is refused, named by its line number. Tables are written whole
by write-and-rename (:func:`write_atomic`), so a reader never sees a partial row.
:func:`results_csv` is the ``results.csv`` text: one row per (point, seed), sorted.
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import math
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from testbed.config import ConfigError
from testbed.run.outputs import replace_atomically
from testbed.sweep.keys import toml_literal
from testbed.sweep.spec import Sweep

__all__ = [
    "append_rows",
    "csv_text",
    "journal_text",
    "read_journal",
    "results_csv",
    "sorted_unique",
    "write_atomic",
]


_STATUSES = ("ok", "failed")


def read_journal(
    path: Path, sweep: Sweep | None = None, *, repair: bool = False, renumber: bool = False
) -> list[dict[str, Any]]:
    """The rows in ``runs.jsonl`` (none if it does not exist); with ``repair``, cut off a torn
    tail (no final newline).

    Every complete line must be a record as :mod:`testbed.sweep.runner` writes it: a JSON object
    with an integer ``point`` and ``seed`` ≥ 0, ``status`` ``"ok"`` or ``"failed"`` and a string
    ``error``; with ``sweep``, its grid values must be those of one of its points (numbers by
    value) and its seed one of its seeds. Its ``point`` must be that point's number, or with
    ``renumber`` (a grown sweep: values added to its grid) is set to it.

    Raises:
        ConfigError: the file cannot be read (a directory, no permission), or a complete line
            is not such a record: ``<path>: line N: damaged record …`` (the file was edited).
    """
    try:
        data = path.read_bytes() if path.exists() else b""
    except OSError as err:
        raise ConfigError(f"{path}: cannot read the journal: {err.strerror or err}") from None
    complete = data[: data.rfind(b"\n") + 1]
    seeds = None if sweep is None else set(sweep.seeds)
    numbers = None
    if sweep is not None:
        keys = [key for key, _ in sweep.axes]
        numbers = {_values_key(point, keys): i for i, point in enumerate(sweep.points)}
    rows = []
    for number, line in enumerate(complete.splitlines(), start=1):
        row = _record(line, seeds)
        if row is not None and sweep is not None and numbers is not None:
            index = numbers.get(_values_key(row, keys))
            if index is None or (index != row["point"] and not renumber):
                row = None
            else:
                row["point"] = index
        if row is None:
            raise ConfigError(
                f"{path}: line {number}: damaged record (not written by testbed sweep)"
            )
        rows.append(row)
    if repair and len(complete) < len(data):
        with path.open("r+b") as handle:
            handle.truncate(len(complete))
            os.fsync(handle.fileno())
    return rows


def _values_key(row: Mapping[str, Any], keys: Sequence[str]) -> str:
    """The grid values of a row or point, as one canonical text (``0`` = ``0.0``)."""
    from testbed.sweep.manifest import key_of

    return key_of([row.get(key) for key in keys])


def _record(line: bytes, seeds: set[int] | None) -> dict[str, Any] | None:
    """The journal record on ``line``, or None if it is not one (of these ``seeds``, when
    given)."""
    try:
        row = json.loads(line)
    except ValueError:  # not JSON, or not UTF-8
        return None
    if not isinstance(row, dict):
        return None
    point, seed = row.get("point"), row.get("seed")
    if not isinstance(point, int) or not _count(point) or not _count(seed):
        return None
    if row.get("status") not in _STATUSES or not isinstance(row.get("error"), str):
        return None
    if seeds is not None and seed not in seeds:
        return None
    return row


def _count(value: Any) -> bool:
    """``value`` is an integer ≥ 0 (not a bool)."""
    return isinstance(value, int) and not isinstance(value, bool) and value >= 0


def _settled(value: Any) -> Any:
    """``value`` with each number that is not finite as its TOML spelling (``"inf"``): a grid
    value such as ``link.max_range_m = inf``, kept in strict JSON as ``sweep.json`` keeps it
    (:func:`~testbed.sweep.manifest.canonical`, which reads both forms as one; metrics are
    ``None`` already)."""
    if isinstance(value, float) and not math.isfinite(value):
        return toml_literal(value)
    if isinstance(value, Mapping):
        return {k: _settled(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_settled(v) for v in value]
    return value


def journal_text(rows: Sequence[Mapping[str, Any]]) -> str:
    """``rows`` as the journal's lines: one strict JSON object per row, each ending in a
    newline."""
    return "".join(json.dumps(_settled(row), allow_nan=False) + "\n" for row in rows)


def append_rows(path: Path, rows: Sequence[Mapping[str, Any]]) -> None:
    """Append rows as JSON lines (:func:`journal_text`) in one write, then fsync.

    Raises:
        OSError: the write failed (a full disk); its ``filename`` is ``path``, and the file is
            cut back to its length before the write, so no partial line stays in it.
    """
    data = journal_text(rows).encode()
    try:
        fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
    except OSError as err:
        raise OSError(err.errno, err.strerror, str(path)) from None
    try:
        length = os.fstat(fd).st_size
        view = memoryview(data)
        while view:
            view = view[os.write(fd, view) :]
        os.fsync(fd)
    except OSError as err:
        with contextlib.suppress(OSError):
            os.ftruncate(fd, length)
        raise OSError(err.errno, err.strerror, str(path)) from None
    finally:
        os.close(fd)


def write_atomic(path: Path, text: str) -> None:
    """Write ``text`` to a new temporary file beside ``path``, fsync, and rename it over
    ``path`` (:func:`~testbed.run.outputs.replace_atomically`).

    Raises:
        OSError: the write failed (a full disk): ``filename`` is ``path``, and the temporary
            file is removed.
    """

    def write(tmp: Path) -> None:
        with tmp.open("w", encoding="utf-8", newline="") as handle:
            handle.write(text)
            handle.flush()
            os.fsync(handle.fileno())

    replace_atomically(write, path)


def _cell(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, list | dict):
        return toml_literal(value)
    return str(value)


def csv_text(columns: Sequence[str], rows: Sequence[Mapping[str, Any]]) -> str:
    """A CSV table of ``columns`` (head row first); a cell a row lacks is empty."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(columns)
    for row in rows:
        writer.writerow([_cell(row.get(c)) for c in columns])
    return buffer.getvalue()


def sorted_unique(rows: Sequence[Mapping[str, Any]]) -> list[Mapping[str, Any]]:
    """One row per (point, seed), the last recorded (a failed run retried on ``--resume`` is
    recorded again), sorted by point then seed."""
    by_key: dict[tuple[int, int], Mapping[str, Any]] = {}
    for row in rows:
        by_key[(row["point"], row["seed"])] = row
    return [by_key[key] for key in sorted(by_key)]


def results_csv(sweep: Sweep, rows: Sequence[Mapping[str, Any]]) -> str:
    """The results table: one row per (point, seed), sorted; metric columns in first-seen
    order."""
    rows = sorted_unique(rows)
    head = ["point", "seed", *(key for key, _ in sweep.axes), "status", "error"]
    metric_columns: dict[str, None] = {}
    for row in rows:
        for key in row:
            if key not in head:
                metric_columns.setdefault(key)
    return csv_text([*head, *metric_columns], rows)
