"""Driving a sweep: run what the results directory lacks, record it, write the tables.

:func:`run_sweep` checks the directory against the sweep (``sweep.json``,
:mod:`~testbed.sweep.manifest`), skips every (point, seed) the journal holds a successful run
of (a failed run is run again on ``--resume``), runs the rest on a backend, appends finished
runs to the journal in batches and rewrites ``results.csv`` and ``aggregate.csv``.
:func:`format_summary` is the few lines a person reads afterwards.

Interrupted (a KeyboardInterrupt: Ctrl-C, or SIGTERM through the CLI's handler) or broken, it stops
the backend's workers, writes the runs that finished to the journal, regenerates both tables
from the journal and re-raises: ``--resume`` then runs exactly the missing (point, seed)s.
Before it writes anything it checks the directory and its journal, that every aggregated metric
is one a run produces (:func:`check_metrics`) and that a remote scheduler answers: a mistake,
an unreachable scheduler or an interrupt there leaves the directory as it was. While it writes
it holds an exclusive lock on the directory (:func:`out_lock`).
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import shlex
import signal
import sys
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO

from testbed.config import ConfigError
from testbed.sweep.aggregate import aggregate_rows
from testbed.sweep.backends import RunOutcome, execute_run, outcomes, scheduler_client
from testbed.sweep.journal import (
    append_rows,
    csv_text,
    journal_text,
    read_journal,
    results_csv,
    sorted_unique,
    write_atomic,
)
from testbed.sweep.keys import toml_literal
from testbed.sweep.manifest import FORMAT, compare, manifest, manifest_text
from testbed.sweep.progress import Progress
from testbed.sweep.spec import RunSpec, Sweep, describe_point, expand

__all__ = ["SweepSummary", "check_metrics", "format_summary", "run_sweep"]

DRY_RUN_S = 1.0
"""Simulated length of the dry run that lists the metric keys of a run [s]."""


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
    force: bool = False,
    flush_interval_s: float = 1.0,
    stream: TextIO | None = None,
) -> SweepSummary:
    """Run every (point, seed) that ``out`` holds no successful run of, and write the tables.

    Args:
        sweep: the loaded sweep.
        out: results directory (``sweep.json``, ``runs.jsonl``, ``results.csv``,
            ``aggregate.csv``).
        workers: local processes (default: one per core), or LocalCluster workers.
        dask: None for the process pool; a scheduler address; or ``"local"``.
        resume: continue the sweep in ``out`` (the same one, or the same with grid values or
            seeds added: :func:`~testbed.sweep.manifest.compare`); its failed runs are run
            again. Without it ``out`` must be empty.
        force: start afresh in a non-empty ``out``: the files a sweep writes there are removed
            first (not with ``resume``).
        flush_interval_s: how long finished runs may wait before they are written [s].
        stream: progress output (default: stderr).

    Raises:
        ConfigError: ``out`` is not empty (without ``resume`` or ``force``), holds another
            sweep or a damaged ``sweep.json``, is in use by another sweep (a lock), or has a
            damaged journal; bad workers; an unknown metric; an unreachable scheduler. Nothing
            is written then.
        WorkerLostError: a pool worker died (the runs that finished are kept).
        OSError: the disk refused a write (its ``filename`` names the file).
        KeyboardInterrupt: Ctrl-C or SIGTERM; before the runs start, nothing is written.
    """
    stream = sys.stderr if stream is None else stream
    workers = workers if workers is not None else (os.cpu_count() or 1)
    if workers < 1:
        raise ConfigError(f"--workers: must be ≥ 1, got {workers}")
    if force and resume:
        raise ConfigError("--force: not with --resume (--force starts the sweep afresh)")
    held, _ = _held_rows(sweep, out, resume, force)
    done = {(r["point"], r["seed"]) for r in held if _ok(r)}
    specs = [s for s in expand(sweep) if (s.point, s.seed) not in done]
    if specs:
        check_metrics(sweep)
    with scheduler_client(dask if specs else None) as client:
        out.mkdir(parents=True, exist_ok=True)
        with out_lock(out):
            rows, grown = _held_rows(sweep, out, resume, force)  # again: no other sweep now
            if force:
                remove_sweep_files(out)
            journal = out / "runs.jsonl"
            if grown:  # the rows renumbered (and a torn tail cut)
                write_atomic(journal, journal_text(rows))
            elif resume:
                read_journal(journal, sweep, repair=True)  # the same rows, a torn tail cut
            write_atomic(out / "sweep.json", manifest_text(sweep))
            done = {(r["point"], r["seed"]) for r in rows if _ok(r)}
            specs = [s for s in expand(sweep) if (s.point, s.seed) not in done]
            stream_of = outcomes(specs, workers, dask, client) if specs else iter(())
            return _record(sweep, out, specs, rows, stream_of, flush_interval_s, stream)


def _ok(row: dict[str, Any]) -> bool:
    return bool(row["status"] == "ok")


LOCK_FILE = ".sweep.lock"
"""The file in ``--out`` that a running sweep holds an exclusive ``flock`` on."""

SWEEP_FILES = ("sweep.json", "runs.jsonl", "results.csv", "aggregate.csv")
"""What a sweep writes in ``--out`` besides its plots (``ber_vs_*.png``) and its lock."""


@contextlib.contextmanager
def out_lock(out: Path) -> Iterator[None]:
    """Hold an exclusive lock on ``out`` (``flock`` of :data:`LOCK_FILE`) inside: two sweeps
    never write one folder.

    Raises:
        ConfigError: another sweep holds it.
    """
    import fcntl

    fd = os.open(out / LOCK_FILE, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise ConfigError(f"--out: {out} is in use by another testbed sweep") from None
        yield
    finally:
        os.close(fd)  # releases the lock


def remove_sweep_files(out: Path) -> None:
    """``--force``: remove what an earlier sweep wrote in ``out`` (other files stay)."""
    for path in [*(out / name for name in SWEEP_FILES), *out.glob("ber_vs_*.png")]:
        with contextlib.suppress(FileNotFoundError):
            path.unlink()


def out_is_empty(out: Path) -> bool:
    """``out`` holds nothing (but, perhaps, the lock file of an earlier sweep)."""
    return not out.is_dir() or all(entry.name == LOCK_FILE for entry in out.iterdir())


def _held_rows(
    sweep: Sweep, out: Path, resume: bool, force: bool
) -> tuple[list[dict[str, Any]], bool]:
    """The rows ``out`` holds that ``sweep`` keeps (renumbered by their grid values when the
    sweep grew; none when ``force`` starts it afresh), once ``out`` is checked, and whether
    the sweep grew. Reads only.

    Raises:
        ConfigError: ``out`` is a file; not empty without ``resume`` or ``force``; with
            ``resume``, holds no sweep, a damaged ``sweep.json``, another sweep (naming every
            difference) or a damaged journal.
    """
    manifest_path = out / "sweep.json"
    if out.exists() and not out.is_dir():
        raise ConfigError(f"--out: {out} exists and is not a directory")
    if not resume:
        if force or out_is_empty(out):
            return [], False
        if manifest_path.exists():
            raise ConfigError(
                f"--out: {out} already holds a sweep (add --resume to continue it, or --force "
                "to start it afresh)"
            )
        raise ConfigError(f"--out: {out} is not empty (use --force to write a sweep there)")
    if not manifest_path.exists():
        what = "does not exist" if not out.exists() else "holds no sweep (no sweep.json)"
        raise ConfigError(f"--resume: {out} {what}; drop --resume to start the sweep there")
    try:
        held = json.loads(manifest_path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as err:
        reason = getattr(err, "strerror", None) or "not UTF-8"
        raise ConfigError(f"{manifest_path}: cannot read: {reason}") from None
    except ValueError:
        held = None
    if not isinstance(held, dict) or not isinstance(held.get("id"), str):
        raise ConfigError(f"{manifest_path}: damaged (not a sweep.json written by testbed sweep)")
    if held.get("format") != FORMAT:
        raise ConfigError(
            f"--resume: {manifest_path} was written by an older testbed without input hashes, "
            "so its inputs cannot be checked; start the sweep in a new --out"
        )
    resumption = compare(held, manifest(sweep))
    if resumption.differences:
        raise ConfigError(
            f"--resume: {out} holds a different sweep than {sweep.source}: "
            + "; ".join(resumption.differences)
        )
    rows = read_journal(out / "runs.jsonl", sweep, renumber=resumption.grown)
    return rows, resumption.grown


def _record(
    sweep: Sweep,
    out: Path,
    specs: list[RunSpec],
    rows: list[dict[str, Any]],
    stream_of: Iterator[RunOutcome],
    flush_interval_s: float,
    stream: TextIO,
) -> SweepSummary:
    """Take the outcomes of ``specs`` as they come, append them to the journal (after ``rows``,
    those it holds) in batches, rewrite the tables; on an interrupt keep what finished."""
    journal = out / "runs.jsonl"
    points = sweep.points
    total = len(points) * len(sweep.seeds)
    progress = Progress(total, total - len(specs), stream, sweep.id)
    start = time.monotonic()
    pending: list[dict[str, Any]] = []
    last_flush = start

    def flush() -> None:
        nonlocal last_flush
        with _interrupts_deferred():  # a signal between the write and the bookkeeping would
            if pending:  # write the rows twice
                append_rows(journal, pending)
                rows.extend(pending)
                pending.clear()
        write_atomic(out / "results.csv", results_csv(sweep, rows))
        last_flush = time.monotonic()

    def write_aggregate() -> None:
        table = aggregate_rows(sweep, rows)
        columns: dict[str, None] = {}
        for entry in table:
            columns.update(dict.fromkeys(entry))
        write_atomic(out / "aggregate.csv", csv_text(list(columns), table))

    try:
        for outcome in stream_of:
            status = "ok" if outcome.metrics is not None else "failed"
            pending.append(
                {"point": outcome.point, "seed": outcome.seed, **points[outcome.point]}
                | {"status": status, "error": outcome.error, **(outcome.metrics or {})}
            )
            if time.monotonic() - last_flush >= flush_interval_s:
                flush()
            progress.update(outcome.metrics is None)
        flush()
    except BaseException as failure:  # interrupted (Ctrl-C, SIGTERM) or broken: keep what ran
        with _interrupts_ignored():
            close = getattr(stream_of, "close", None)
            if close is not None:
                close()  # stops the workers (a generator's finally)
            progress.close()
            try:
                # The journal on disk is the truth: an interrupt can land inside a flush,
                # after its write and before its bookkeeping (a signal already taken by Python
                # is not held back by the mask), so append only the finished rows it lacks.
                on_disk = read_journal(journal, repair=True)
                written = {(r["point"], r["seed"]) for r in on_disk[len(rows) :]}
                rest = [r for r in pending if (r["point"], r["seed"]) not in written]
                if rest:
                    append_rows(journal, rest)
                rows[:] = on_disk + rest
                pending.clear()
                flush()
                write_aggregate()
            except OSError:
                if not isinstance(failure, OSError):  # a full disk: its first error is raised
                    raise
        raise
    finally:
        progress.close()
    write_aggregate()
    failed = tuple(
        (r["point"], r["seed"], describe_point(points[r["point"]]), r["error"])
        for r in sorted_unique(rows)
        if r["status"] != "ok"
    )
    return SweepSummary(total, len(specs), failed, time.monotonic() - start, out)


@contextlib.contextmanager
def _interrupts_ignored() -> Iterator[None]:
    """SIGINT and SIGTERM ignored inside (on the main thread): a second Ctrl-C must not cut
    the journal's last write or leave workers behind."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old = {sig: signal.signal(sig, signal.SIG_IGN) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for sig, handler in old.items():
            signal.signal(sig, handler)


@contextlib.contextmanager
def _interrupts_deferred() -> Iterator[None]:
    """SIGINT and SIGTERM blocked inside (this thread), delivered on leaving."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def _metric_keys(spec: RunSpec) -> set[str] | None:
    """The flattened metric keys one run produces, or None if it fails."""
    result = execute_run(spec)
    return None if result.metrics is None else set(result.metrics)


def check_metrics(sweep: Sweep) -> None:
    """Check, before any run, that every metric of ``sweep.metrics`` is one a run produces.

    The key set comes from a dry run of the first grid point of :data:`DRY_RUN_S` simulated
    seconds (≈ 0.1 s). Only when a metric is missing there (or that point cannot run that
    short) does it look further, before rejecting: the first point at its own duration, then
    the first point with each non-numeric grid value in turn (a grid over ``images.enabled``
    or a layout changes which metrics exist; numbers do not). A point whose run fails is left
    to the sweep, which records the failure.

    Raises:
        ConfigError: a metric no probed run produces, listing the known ones.
        KeyboardInterrupt: Ctrl-C or SIGTERM during a dry run (which stops it part way).
    """
    first = expand(dataclasses.replace(sweep, seeds=sweep.seeds[:1]))[0]
    short = (f"duration_s={DRY_RUN_S!r}", "metrics.settle_s=0.0")
    probes = [dataclasses.replace(first, overrides=(*first.overrides, *short)), first]
    base = [key for key, _ in sweep.axes]
    for key, values in sweep.axes:
        for value in values:
            if not isinstance(value, int | float) or isinstance(value, bool):
                point = dict(sweep.points[0]) | {key: value}
                overrides = tuple(f"{k}={toml_literal(point[k])}" for k in base)
                probes.append(
                    dataclasses.replace(first, overrides=(*sweep.overrides, *overrides, *short))
                )
    known: set[str] = set(base)  # rows carry the grid values too
    ran = False
    for probe in probes:
        keys = _metric_keys(probe)
        if keys is None:
            continue
        ran = True
        known |= keys
        if all(name in known for name in sweep.metrics):
            return
    if not ran:
        return
    missing = next(name for name in sweep.metrics if name not in known)
    listed = ", ".join(sorted(known))
    raise ConfigError(f"{sweep.source}: metrics: unknown metric {missing!r} (known: {listed})")


def format_summary(sweep: Sweep, summary: SweepSummary) -> str:
    """A few lines a person reads after a sweep, listing every failed run."""
    lines = [
        f"{sweep.id}: {summary.total} runs, {len(summary.failed)} failed; "
        f"{summary.ran} ran now in {summary.wall_s:.1f} s"
    ]
    for point, seed, values, error in summary.failed:
        lines.append(f"  FAILED point {point} seed {seed} ({values}): {error}")
    if summary.failed:
        point, seed = summary.failed[0][:2]
        spec = next(s for s in expand(sweep) if (s.point, s.seed) == (point, seed))
        sets = " ".join(f"--set {shlex.quote(override)}" for override in spec.overrides)
        command = f"testbed run {shlex.quote(spec.scenario)} --seed {seed} {sets}".rstrip()
        lines.append(f"  the first failed run alone: {command}")
    out = summary.out
    lines.append(f"  wrote {out / 'results.csv'} and {out / 'aggregate.csv'}")
    return "\n".join(lines)
