"""The files of a results directory: the ``runs.jsonl`` journal and the CSV tables.

The journal holds one JSON line per finished run, appended in batches with one ``write`` and an
``fsync`` (:func:`append_rows`); a torn last line (a kill in the middle of a write) is cut off
by :func:`read_journal` with ``repair``. Tables are written whole by write-and-rename
(:func:`write_atomic`), so a reader never sees a partial row. :func:`results_csv` is the
``results.csv`` text: one row per (point, seed), sorted.
"""

from __future__ import annotations

import csv
import io
import json
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from testbed.config import ConfigError
from testbed.sweep.spec import Sweep, toml_literal

__all__ = [
    "append_rows",
    "csv_text",
    "read_journal",
    "results_csv",
    "sorted_unique",
    "write_atomic",
]


def read_journal(path: Path, *, repair: bool = False) -> list[dict[str, Any]]:
    """The rows in ``runs.jsonl``; with ``repair``, cut off a torn tail (no final newline).

    Raises:
        ConfigError: a complete line that is not a JSON record (the file was edited).
    """
    data = path.read_bytes() if path.exists() else b""
    complete = data[: data.rfind(b"\n") + 1]
    try:
        rows = [json.loads(line) for line in complete.splitlines()]
    except ValueError:
        raise ConfigError(f"{path}: damaged record (not written by testbed sweep)") from None
    if repair and len(complete) < len(data):
        with path.open("r+b") as handle:
            handle.truncate(len(complete))
            os.fsync(handle.fileno())
    return rows


def append_rows(path: Path, rows: Sequence[Mapping[str, Any]]) -> None:
    """Append rows as JSON lines in one write, then fsync."""
    data = "".join(json.dumps(row, allow_nan=False) + "\n" for row in rows).encode()
    fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
    try:
        view = memoryview(data)
        while view:
            view = view[os.write(fd, view) :]
        os.fsync(fd)
    finally:
        os.close(fd)


def write_atomic(path: Path, text: str) -> None:
    """Write ``text`` to a temporary file beside ``path``, fsync, and rename it over ``path``."""
    tmp = path.with_name(path.name + ".tmp")
    with tmp.open("w", encoding="utf-8", newline="") as handle:
        handle.write(text)
        handle.flush()
        os.fsync(handle.fileno())
    os.replace(tmp, path)


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
    """One row per (point, seed), the first recorded, sorted by point then seed."""
    by_key: dict[tuple[int, int], Mapping[str, Any]] = {}
    for row in rows:
        by_key.setdefault((row["point"], row["seed"]), row)
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
