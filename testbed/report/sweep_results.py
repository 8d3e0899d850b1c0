"""A sweep's ``results.csv`` as the plots read it: the successful rows, cells as strings.

:func:`read_results` reads the file ``testbed sweep`` writes (:mod:`testbed.sweep`: ``point``,
``seed``, the grid keys, ``status``, ``error``, then the metrics); :class:`Results` gives a
column as numbers and splits the rows into the lines of a plot.
"""

from __future__ import annotations

import csv
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from testbed.config import ConfigError

__all__ = ["Results", "check_results_file", "read_results", "short_key", "sweep_label"]


@dataclass(frozen=True, slots=True)
class Results:
    """The successful rows of a ``results.csv``.

    Attributes:
        path: where it was read from, for messages.
        columns: every column, in file order.
        grid: the grid keys (the columns between ``seed`` and ``status``).
        rows: the rows with ``status = ok``, cells as the file's strings.
        row_numbers: each of ``rows``' place in the file, for messages (the head is row 1).
        failed: the other rows (runs that failed: no metrics to plot, but not to be hidden).
    """

    path: Path
    columns: tuple[str, ...]
    grid: tuple[str, ...]
    rows: tuple[dict[str, str], ...]
    row_numbers: tuple[int, ...]
    failed: tuple[dict[str, str], ...] = ()

    def runs_label(self) -> str:
        """``"4 runs ok"``, or with failed runs ``"4 runs ok, 2 failed at link.ber 0.001"``
        (the grid values where they failed): a title says what the curves leave out."""
        label = f"{len(self.rows)} runs ok"
        if not self.failed:
            return label
        swept = [  # the grid keys with more than one value: where the failures lie
            key for key in self.grid if len({row[key] for row in self.rows + self.failed}) > 1
        ]
        where = "; ".join(
            f"{key} {', '.join(dict.fromkeys(row[key] for row in self.failed))}" for key in swept
        )
        return f"{label}, {len(self.failed)} failed" + (f" at {where}" if where else "")

    def require(self, column: str, option: str) -> None:
        """Raise a one-line :class:`ConfigError` unless ``column`` exists.

        Raises:
            ConfigError: naming ``option`` and the column, listing the known columns.
        """
        if column not in self.columns:
            known = ", ".join(c for c in self.columns if c not in ("status", "error"))
            raise ConfigError(f"{self.path}: {option}: unknown column {column!r} (known: {known})")

    def numbers(self, column: str) -> np.ndarray:
        """``column`` of every row as floats; NaN for an empty or non-numeric cell."""
        return np.array([_number(row.get(column, "")) for row in self.rows], dtype=float)

    def failed_numbers(self, column: str) -> np.ndarray:
        """:meth:`numbers` of the failed rows (their grid values: where runs failed)."""
        return np.array([_number(row.get(column, "")) for row in self.failed], dtype=float)

    def metric(self, column: str, option: str) -> np.ndarray:
        """``column`` of every row as floats, NaN for an empty cell (a metric the run did not
        give); unlike :meth:`numbers`, any other cell must be a number.

        Raises:
            ConfigError: a cell that is not a number, naming its row, ``option`` and the column.
        """
        values = np.full(len(self.rows), math.nan)
        for index, (number, row) in enumerate(zip(self.row_numbers, self.rows, strict=True)):
            cell = row.get(column, "")
            if cell:
                try:
                    values[index] = float(cell)
                except ValueError:
                    raise ConfigError(
                        f"{self.path}: row {number}: {option}: column {column!r} holds "
                        f"{cell[:40]!r}, not a number"
                    ) from None
        return values

    def labels(self, columns: Sequence[str]) -> list[str]:
        """Per row, ``key=value`` of ``columns`` joined by ``, `` (``""`` for no columns)."""
        return [", ".join(f"{short_key(c)}={row[c]}" for c in columns) for row in self.rows]

    def groups(self, by: Sequence[str]) -> list[tuple[str, np.ndarray]]:
        """``(label, row mask)`` per distinct value of the ``by`` columns, in first-seen order."""
        labels = self.labels(by)
        seen = list(dict.fromkeys(labels))
        array = np.array(labels, dtype=object)
        return [(label, array == label) for label in seen]


def _number(cell: str) -> float:
    try:
        return float(cell)
    except ValueError:
        return math.nan


def short_key(key: str) -> str:
    """``link.ipg_s`` → ``ipg_s``: the last part of a dotted key, for legends."""
    return key.rsplit(".", 1)[-1]


_NOT_RESULTS = "not a results.csv of testbed sweep"


def check_results_file(results_csv: Path | str) -> None:
    """Cheap check before any work: the file can be read and starts with the ``point, seed``
    head of a results.csv (its first line only).

    Raises:
        ConfigError: missing, a directory, unreadable, binary (NUL bytes, not UTF-8), or
            another head.
    """
    path = Path(results_csv)
    if path.is_dir():
        raise ConfigError(f"{path}: is a directory, not a results.csv")
    try:
        with path.open("rb") as handle:
            head = handle.readline(1 << 16)
    except OSError as err:
        raise ConfigError(f"{path}: cannot read: {err.strerror}") from None
    try:
        text = head.decode("utf-8")
    except UnicodeDecodeError:
        raise ConfigError(f"{path}: {_NOT_RESULTS} (binary, not UTF-8 text)") from None
    if "\0" in text or not text.startswith("point,seed,"):
        raise ConfigError(f"{path}: {_NOT_RESULTS} (no point, seed, status head)")


def read_results(results_csv: Path | str) -> Results:
    """Read a sweep's ``results.csv``.

    Raises:
        ConfigError: a missing file, a binary or garbled one (not UTF-8, NUL bytes, rows the
            CSV reader rejects, a row with more or fewer cells than the head: ``row N:
            expected M fields, got K``), or one without the ``point, seed, …, status, error``
            head.
    """
    path = Path(results_csv)
    try:
        with path.open(encoding="utf-8", newline="") as handle:
            reader = csv.DictReader(handle)
            columns = tuple(reader.fieldnames or ())
            all_rows = list(reader)
    except OSError as err:
        raise ConfigError(f"{path}: cannot read: {err.strerror}") from None
    except UnicodeDecodeError:
        raise ConfigError(f"{path}: {_NOT_RESULTS} (binary, not UTF-8 text)") from None
    except csv.Error as err:
        raise ConfigError(f"{path}: {_NOT_RESULTS} (line {reader.line_num}: {err})") from None
    if columns[:2] != ("point", "seed") or "status" not in columns:
        raise ConfigError(f"{path}: {_NOT_RESULTS} (no point, seed, status)")
    width = len(columns)
    for number, row in enumerate(all_rows, start=2):
        extra = row.get(None)
        if extra is not None:  # more cells than columns: DictReader keeps them under None
            raise ConfigError(
                f"{path}: row {number}: expected {width} fields, got {width + len(extra)} "
                "(more cells than the head)"
            )
        missing = sum(row.get(column) is None for column in columns)  # filled with None
        if missing:
            raise ConfigError(
                f"{path}: row {number}: expected {width} fields, got {width - missing}"
            )
    ok = [(number, row) for number, row in enumerate(all_rows, start=2) if row["status"] == "ok"]
    grid = columns[2 : columns.index("status")]
    rows = tuple(row for _, row in ok)
    failed = tuple(row for row in all_rows if row["status"] != "ok")
    return Results(path, columns, grid, rows, tuple(number for number, _ in ok), failed)


def sweep_label(results: Results) -> str:
    """What a plot's title names: the id in the ``sweep.json`` beside ``results.csv`` (so the
    same results give the same PNG whatever their folder is called), else the folder's name."""
    try:
        manifest = json.loads((results.path.parent / "sweep.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return results.path.parent.name
    label = manifest.get("id") if isinstance(manifest, dict) else None
    return label if isinstance(label, str) else results.path.parent.name
