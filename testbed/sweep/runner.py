"""Driving a sweep: run what the results directory lacks, record it, write the tables.

:func:`run_sweep` checks the directory against the sweep (``sweep.json``), skips every
(point, seed) already in the journal, runs the rest on a backend, appends finished runs to the
journal in batches and rewrites ``results.csv`` and ``aggregate.csv``. :func:`format_summary`
is the few lines a person reads afterwards.
"""

from __future__ import annotations

import json
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO

from testbed.config import ConfigError
from testbed.sweep.aggregate import aggregate_rows
from testbed.sweep.backends import outcomes
from testbed.sweep.journal import (
    append_rows,
    csv_text,
    read_journal,
    results_csv,
    sorted_unique,
    write_atomic,
)
from testbed.sweep.progress import Progress
from testbed.sweep.spec import Sweep, describe_point, expand

__all__ = ["SweepSummary", "format_summary", "run_sweep"]


@dataclass(frozen=True, slots=True)
class SweepSummary:
    """How a sweep ended: runs in all, run now, every failed run ``(point, seed, grid values,
    error)`` recorded earlier or now, wall time of this invocation [s], the results directory."""

    total: int
    ran: int
    failed: tuple[tuple[int, int, str, str], ...]
    wall_s: float
    out: Path


def run_sweep(
    sweep: Sweep,
    out: Path,
    *,
    workers: int | None = None,
    dask: str | None = None,
    resume: bool = False,
    flush_interval_s: float = 1.0,
    stream: TextIO | None = None,
) -> SweepSummary:
    """Run every (point, seed) not yet recorded in ``out`` and write the tables.

    Args:
        sweep: the loaded sweep.
        out: results directory (``sweep.json``, ``runs.jsonl``, ``results.csv``,
            ``aggregate.csv``).
        workers: local processes (default: one per core), or LocalCluster workers.
        dask: None for the process pool; a scheduler address; or ``"local"``.
        resume: continue a sweep already in ``out``; without it ``out`` must hold no sweep.
        flush_interval_s: how long finished runs may wait before they are written [s].
        stream: progress output (default: stderr).

    Raises:
        ConfigError: ``out`` holds another sweep, or a sweep and no ``resume``; bad workers.
    """
    stream = sys.stderr if stream is None else stream
    workers = workers if workers is not None else (os.cpu_count() or 1)
    if workers < 1:
        raise ConfigError(f"--workers: must be ≥ 1, got {workers}")
    manifest = out / "sweep.json"
    journal = out / "runs.jsonl"
    identity = json.dumps(sweep.identity(), indent=1, sort_keys=True) + "\n"
    if manifest.exists():
        if not resume:
            raise ConfigError(f"--out: {out} already holds a sweep (add --resume to continue)")
        if manifest.read_text(encoding="utf-8") != identity:
            raise ConfigError(f"--resume: {out} holds a different sweep than {sweep.source}")
    elif out.exists() and not out.is_dir():
        raise ConfigError(f"--out: {out} exists and is not a directory")
    out.mkdir(parents=True, exist_ok=True)
    write_atomic(manifest, identity)
    rows = read_journal(journal, repair=True)
    done = {(r["point"], r["seed"]) for r in rows}
    specs = [s for s in expand(sweep) if (s.point, s.seed) not in done]
    points = sweep.points
    total = len(points) * len(sweep.seeds)
    progress = Progress(total, total - len(specs), stream, sweep.id)
    start = time.monotonic()
    pending: list[dict[str, Any]] = []
    last_flush = start

    def flush() -> None:
        nonlocal last_flush
        if pending:
            append_rows(journal, pending)
            rows.extend(pending)
            pending.clear()
        write_atomic(out / "results.csv", results_csv(sweep, rows))
        last_flush = time.monotonic()

    try:
        for outcome in outcomes(specs, workers, dask) if specs else ():
            status = "ok" if outcome.metrics is not None else "failed"
            pending.append(
                {"point": outcome.point, "seed": outcome.seed, **points[outcome.point]}
                | {"status": status, "error": outcome.error, **(outcome.metrics or {})}
            )
            if time.monotonic() - last_flush >= flush_interval_s:
                flush()
            progress.update(outcome.metrics is None)
        flush()
    finally:
        progress.close()
    table = aggregate_rows(sweep, rows)
    columns: dict[str, None] = {}
    for entry in table:
        columns.update(dict.fromkeys(entry))
    write_atomic(out / "aggregate.csv", csv_text(list(columns), table))
    failed = tuple(
        (r["point"], r["seed"], describe_point(points[r["point"]]), r["error"])
        for r in sorted_unique(rows)
        if r["status"] != "ok"
    )
    return SweepSummary(total, len(specs), failed, time.monotonic() - start, out)


def format_summary(sweep: Sweep, summary: SweepSummary) -> str:
    """A few lines a person reads after a sweep, listing every failed run."""
    lines = [
        f"{sweep.id}: {summary.total} runs, {len(summary.failed)} failed; "
        f"{summary.ran} run now in {summary.wall_s:.1f} s"
    ]
    for point, seed, values, error in summary.failed:
        lines.append(f"  FAILED point {point} seed {seed} ({values}): {error}")
    out = summary.out
    lines.append(f"  wrote {out / 'results.csv'} and {out / 'aggregate.csv'}")
    return "\n".join(lines)
