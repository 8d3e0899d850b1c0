"""A run's results directory, written so that what is there is never mixed or silently partial.

:func:`prepare_out_dir` checks ``--out`` before any work starts: it must be creatable and writable,
not a file, and empty unless the user said ``--force``. :func:`write_run` then writes
``events.csv``, ``series.csv``, ``images.csv``, ``images.npz`` and ``image_progress.csv`` (image
scenarios), ``arm.csv`` (a vehicle with an arm), ``link_state.csv`` (a link model with
``state``) and the plots, each under a temporary name renamed into place, and
``metrics.json`` **last**, carrying ``"complete"`` (true for a run that reached its end, false for
one ended early by Ctrl-C or SIGTERM, or by an error, whose ``sim_s`` says how far it got; then
``"failure"`` is the error in one line) and ``"files"``, the sibling files of this run with their
sizes. A directory without ``metrics.json`` holds no finished result (a run killed while writing);
a ``metrics.json`` names exactly the files that belong to it. ``--force`` removes the previous
``metrics.json`` before anything else is written, and the previous run's files that this run does
not write again (:mod:`testbed.run.trials` also removes earlier trials' results, and a single run's
when trials replace it: :func:`remove_run_results`).
"""

from __future__ import annotations

import contextlib
import functools
import json
import math
import os
import shutil
import tempfile
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import Any

from testbed.config import ConfigError
from testbed.run.atomic import TMP_PREFIX as _TMP_PREFIX
from testbed.run.atomic import replace_atomically
from testbed.run.image_record import write_images_csv, write_images_npz, write_progress_csv
from testbed.run.interrupts import deferred_interrupts
from testbed.run.runner import RunResult

__all__ = [
    "METRICS_FILE",
    "claimed_out_dir",
    "json_ready",
    "prepare_out_dir",
    "remove_run_results",
    "replace_atomically",
    "write_json_atomic",
    "write_run",
]

METRICS_FILE = "metrics.json"

PlotWriter = Callable[[RunResult, Path], list[Path]]
"""Writes a run's plots into a directory, returns the files written."""


def prepare_out_dir(out: Path, *, force: bool = False) -> None:
    """Check and create ``--out`` before any work: a directory that can be written, empty
    unless ``force``.

    Raises:
        ConfigError: ``out`` is a file, cannot be created or written, or is a non-empty
            directory and ``force`` is false (one line naming ``--out``).
    """
    try:
        if out.exists() and not out.is_dir():
            raise ConfigError(f"--out: {out} exists and is not a directory")
        out.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=out, prefix=_TMP_PREFIX):
            pass
    except OSError as err:
        raise ConfigError(f"--out: {out}: cannot write there ({err.strerror or err})") from None
    if not force and any(out.iterdir()):
        raise ConfigError(f"--out: {out} is not empty (use --force to replace its results)")


@contextlib.contextmanager
def claimed_out_dir(out: Path, *, force: bool = False) -> Iterator[Path]:
    """:func:`prepare_out_dir`, then the work inside; when that work ends by an error or an
    interrupt, the directories ``out`` made (``out`` and parents that did not exist) are
    removed again if they are still empty: bad input found after the check (a port that does
    not open) or a Ctrl-C before anything was written leaves nothing behind. Whatever was
    written is kept."""
    try:
        missing = [path for path in (out, *out.absolute().parents) if not path.exists()]
    except OSError as err:  # a name too long to look at
        raise ConfigError(f"--out: {out}: cannot write there ({err.strerror or err})") from None
    prepare_out_dir(out, force=force)
    try:
        yield out
    except BaseException:
        for path in missing:  # deepest first; stops at the first that is not empty
            try:
                path.rmdir()
            except OSError:
                break
        raise


def json_ready(value: Any) -> Any:
    """NaN and infinities become null (strict JSON); containers are converted recursively."""
    if isinstance(value, dict):
        return {k: json_ready(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [json_ready(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def _remove_leftovers(out_dir: Path) -> None:
    """Remove the temporary files and folders (``.tmp-*``) a run killed while writing left in
    ``out_dir`` (a link among them is removed, never followed)."""
    for path in out_dir.glob(f"{_TMP_PREFIX}*"):
        with contextlib.suppress(OSError):
            if path.is_dir() and not path.is_symlink():
                shutil.rmtree(path)
            else:
                path.unlink()


def write_json_atomic(path: Path, document: dict[str, Any]) -> Path:
    """``document`` as indented strict JSON at ``path``, by write-and-rename."""
    text = json.dumps(json_ready(document), indent=2, allow_nan=False) + "\n"
    return replace_atomically(lambda tmp: tmp.write_text(text, encoding="utf-8"), path)


def _previous_files(out_dir: Path) -> list[str]:
    """The files a previous ``metrics.json`` in ``out_dir`` listed (none if unreadable)."""
    try:
        files = json.loads((out_dir / METRICS_FILE).read_text(encoding="utf-8")).get("files", {})
    except (OSError, ValueError, AttributeError):
        return []
    return [name for name in files if isinstance(name, str) and "/" not in name]


def remove_run_results(out_dir: Path) -> None:
    """Remove a run's results from ``out_dir``: its ``metrics.json`` (first) and the files it
    lists; nothing else there is touched. What ``--force`` replaces when the new results take
    another shape (trials after a single run, or the other way round)."""
    previous = _previous_files(out_dir)
    with contextlib.suppress(FileNotFoundError):
        (out_dir / METRICS_FILE).unlink()
    for name in previous:
        with contextlib.suppress(OSError):
            (out_dir / name).unlink()


def write_run(
    result: RunResult,
    out_dir: Path,
    *,
    plots: PlotWriter | None = None,
    extras: Mapping[str, Callable[[Path], None]] | None = None,
) -> list[Path]:
    """Write one run's results into ``out_dir`` (see the module docstring).

    Args:
        result: the run, finished or ended early (``result.stopped``).
        out_dir: the results directory (checked by :func:`prepare_out_dir` beforehand).
        plots: writes the plots into a directory (e.g.
            :func:`testbed.report.run_plots.write_run_plots`); None for no plots.
        extras: more data files, ``name → writer(path)`` (e.g. a HIL session's ``ports.csv``),
            written with the data files and listed in ``metrics.json``.

    Returns:
        The files written, ``metrics.json`` last.

    Raises:
        KeyboardInterrupt: an interrupt while the files were written, raised again once the
            data files and ``metrics.json`` (listing the plots made before it) are written: the
            data and ``metrics.json`` are written whole whenever it comes, the plots are cut
            short (or not begun).
    """
    written: list[Path] = []
    interrupted: KeyboardInterrupt | None = None
    while True:  # again if an interrupt came as the held stretch began: nothing written yet
        try:
            with deferred_interrupts() as late:  # the data whole, even on a (second) Ctrl-C now
                out_dir.mkdir(parents=True, exist_ok=True)
                _remove_leftovers(out_dir)
                previous = _previous_files(out_dir)
                with contextlib.suppress(FileNotFoundError):
                    (out_dir / METRICS_FILE).unlink()  # first: no stale marker over new files
                recorder = result.recorder
                until_s = float(result.metrics.get("sim_s", math.inf))
                write_events = functools.partial(recorder.write_events_csv, until_s=until_s)
                written += [
                    replace_atomically(write_events, out_dir / "events.csv"),
                    replace_atomically(recorder.write_series_csv, out_dir / "series.csv"),
                ]
                images = result.scenario.images
                if images.enabled:
                    log, chunk = recorder.images, images.chunk_bytes
                    write = functools.partial(write_images_csv, log, chunk)
                    written.append(replace_atomically(write, out_dir / "images.csv"))
                    write = functools.partial(write_images_npz, log)
                    written.append(replace_atomically(write, out_dir / "images.npz"))
                    write = functools.partial(write_progress_csv, log)
                    written.append(replace_atomically(write, out_dir / "image_progress.csv"))
                if recorder.arm is not None:
                    arm_csv = out_dir / "arm.csv"
                    written.append(replace_atomically(recorder.arm.write_csv, arm_csv))
                if recorder.link_state is not None:
                    link_csv = out_dir / "link_state.csv"
                    written.append(replace_atomically(recorder.link_state.write_csv, link_csv))
                for name, writer in (extras or {}).items():
                    written.append(replace_atomically(writer, out_dir / name))
            interrupted = interrupted or (late[0] if late else None)
            break
        except KeyboardInterrupt as interrupt:  # one that came as the held stretch began or ended
            interrupted = interrupted or interrupt
            if len(written) >= 2:  # the data files are written: on to metrics.json
                break
            written.clear()  # before them: write them now (nothing accepted is lost), then go on
    if plots is not None and interrupted is None:
        staging: Path | None = None
        try:
            staging = Path(tempfile.mkdtemp(prefix=_TMP_PREFIX, dir=out_dir))
            for made in plots(result, staging):
                target = out_dir / made.name
                os.replace(made, target)
                written.append(target)
        except KeyboardInterrupt as interrupt:  # Ctrl-C while plotting: the results first
            interrupted = interrupt
        finally:
            if staging is not None:
                shutil.rmtree(staging, ignore_errors=True)
    with deferred_interrupts() as late:
        names = {path.name for path in written}
        for stale in previous:
            if stale not in names and stale != METRICS_FILE:
                with contextlib.suppress(OSError):
                    (out_dir / stale).unlink()
        document = dict(result.metrics)
        document["complete"] = result.stopped is None and result.failure is None
        if result.failure is not None:
            document["failure"] = result.failure
        document["files"] = {path.name: path.stat().st_size for path in written}
        written.append(write_json_atomic(out_dir / METRICS_FILE, document))
    interrupted = interrupted or (late[0] if late else None)
    if interrupted is not None:
        raise interrupted
    return written
