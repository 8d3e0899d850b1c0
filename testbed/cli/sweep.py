"""``testbed sweep`` (a grid of runs) and ``testbed plot`` (one results.csv column vs another)."""

from __future__ import annotations

import argparse
import dataclasses
import errno
import os
import shlex
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from testbed.cli.options import (
    EXIT_FAILED,
    EXIT_OK,
    Subparsers,
    add_set_option,
    check_out_dir,
    exit_code_of,
)
from testbed.config import ConfigError

if TYPE_CHECKING:
    from testbed.sweep.spec import Sweep

__all__ = ["add_plot_parser", "add_sweep_parser"]

_DISK_ERRORS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EIO, errno.EROFS, errno.EFBIG})
"""A full or failing disk while the sweep writes: the journal is kept, the line says how to
resume once there is room."""


def check_writable_dir(out: Path, option: str = "--out") -> None:
    """``out`` is a writable directory, or can be created: its nearest existing ancestor is a
    writable directory, and a file can be made in it (tried: the directories made for the try
    are removed again). Else :class:`ConfigError` naming ``out`` (checked before any work)."""
    check_out_dir(out)
    if out.is_dir():
        if not os.access(out, os.W_OK | os.X_OK):
            raise ConfigError(f"{option}: {out} is not writable")
    else:
        parent = out.absolute().parent
        while not parent.exists():
            parent = parent.parent
        if not parent.is_dir():
            raise ConfigError(f"{option}: cannot create {out}: {parent} is a file")
        if not os.access(parent, os.W_OK | os.X_OK):
            raise ConfigError(f"{option}: cannot create {out}: {parent} is not writable")
    _try_writing(out, option)


def _try_writing(out: Path, option: str) -> None:
    """Make ``out`` (and its missing parents) and a temporary file in it, then remove what
    was made: the system's own answer (a folder under /proc, a read-only mount, a name too
    long) as one line.

    Raises:
        ConfigError: ``<option>: <out>: cannot write there (<reason>)``.
    """
    import tempfile

    made = [path for path in (out, *out.absolute().parents) if not path.exists()]
    try:
        out.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=out, prefix=".probe-"):
            pass
    except OSError as err:
        raise ConfigError(f"{option}: {out}: cannot write there ({err.strerror or err})") from None
    finally:
        for path in made:  # deepest first
            try:
                path.rmdir()
            except OSError:
                break


def add_sweep_parser(sub: Subparsers) -> None:
    """``testbed sweep``: a grid of runs on local processes or a Dask cluster (testbed.sweep)."""
    sweep = sub.add_parser(
        "sweep",
        help="run a scenario sweep (grid × seeds) locally or on a Dask cluster, resumable",
        description="Run every (grid point, seed) of a sweep file as an independent run. Writes "
        "runs.jsonl, results.csv (one row per run) and aggregate.csv (per point) to --out. "
        "Exit 0 when every run succeeded, 1 when some failed (listed), 2 on bad input.",
    )
    sweep.add_argument(
        "sweep",
        nargs="?",
        help="packaged sweep id (e.g. ber-vs-lag-v1; --list lists them) or a sweep .toml path",
    )
    sweep.add_argument(
        "--list", action="store_true", help="list the packaged sweeps (id: description) and exit"
    )
    add_set_option(
        sweep, "override a scenario key in every run, e.g. --set duration_s=30 (repeatable)"
    )
    sweep.add_argument(
        "--seeds",
        type=int,
        default=None,
        metavar="N",
        help="run only the sweep's first N seeds at every point (a quick look; default: all)",
    )
    sweep.add_argument(
        "--workers", type=int, default=None, help="worker processes (default: one per core)"
    )
    sweep.add_argument(
        "--dask",
        default=None,
        metavar="ADDRESS|local",
        help="run on a dask.distributed scheduler (tcp://host:8786) or a LocalCluster ('local')",
    )
    sweep.add_argument(
        "--out", type=Path, default=None, help="results directory (default: sweeps/<id>/)"
    )
    sweep.add_argument(
        "--resume",
        action="store_true",
        help="continue the sweep in --out: run what it lacks and what failed (grid values and "
        "seeds may be added; anything else, or a changed input file, is refused)",
    )
    sweep.add_argument(
        "--force",
        action="store_true",
        help="start the sweep afresh in a non-empty --out, removing an earlier sweep's files",
    )
    sweep.set_defaults(handler=_run_sweep)


def _resume_command(args: argparse.Namespace, out: Path) -> str:
    argv = ["testbed", "sweep", args.sweep]
    for override in args.overrides:
        argv += ["--set", override]
    if args.seeds is not None:
        argv += ["--seeds", str(args.seeds)]
    if args.workers is not None:
        argv += ["--workers", str(args.workers)]
    if args.dask is not None:
        argv += ["--dask", args.dask]
    return shlex.join([*argv, "--out", str(out), "--resume"])


def _interrupted_line(args: argparse.Namespace, out: Path | None, total: int | None) -> str:
    """The one line of an interrupted sweep: how far it got, where the journal is, how to
    go on."""

    if out is None or total is None or not (out / "sweep.json").exists():
        return "testbed: interrupted before the first run; nothing written"
    return _stopped_line(args, out, total, "interrupted")


def _stopped_line(args: argparse.Namespace, out: Path, total: int, what: str) -> str:
    """``testbed: <what> after K of N runs; journal kept in OUT; resume with: …``."""
    from testbed.sweep import read_journal

    try:
        rows = read_journal(out / "runs.jsonl")
        done = len({(r["point"], r["seed"]) for r in rows if r["status"] == "ok"})
    except (ConfigError, OSError, KeyError, TypeError):
        done = 0
    return (
        f"testbed: {what} after {done} of {total} runs; journal kept in {out}; "
        f"resume with: {_resume_command(args, out)}"
    )


def _run_sweep(args: argparse.Namespace) -> int:
    """Handler of ``testbed sweep``: check the options and every grid point, run, summarise.

    SIGINT and SIGTERM (both a ``KeyboardInterrupt`` through the CLI's one handler) stop the
    workers, keep the journal and the tables of the runs that finished, print one line and
    return 130 / 143.
    """
    from testbed.sweep.backends import WorkerLostError

    out: Path | None = args.out
    total: int | None = None
    try:
        try:
            return _sweep(args)
        finally:
            out, total = getattr(args, "_out", out), getattr(args, "_total", None)
    except KeyboardInterrupt as interrupt:
        print(_interrupted_line(args, out, total), file=sys.stderr, flush=True)
        return exit_code_of(interrupt)
    except (WorkerLostError, OSError) as err:
        if out is None or total is None or not (out / "sweep.json").exists():
            raise  # before the first run: the CLI's one line (OSError), nothing to resume
        if isinstance(err, OSError):
            if err.errno not in _DISK_ERRORS:
                raise
            where = f" {err.filename}" if err.filename else ""
            what = f"cannot write{where}: {err.strerror}"
        else:
            what = str(err)
        print(_stopped_line(args, out, total, what), file=sys.stderr, flush=True)
        return EXIT_FAILED


def _sweep(args: argparse.Namespace) -> int:
    from testbed.sweep import format_summary, load_sweep, run_sweep
    from testbed.sweep.backends import check_dask_address

    if args.list:
        print(_packaged_sweeps())
        return EXIT_OK
    if args.sweep is None:
        raise ConfigError("sweep: a packaged sweep id or a sweep .toml path is required")
    if args.force and args.resume:
        raise ConfigError("--force: not with --resume (--force starts the sweep afresh)")
    if args.workers is not None and args.workers < 1:
        raise ConfigError(f"--workers: must be ≥ 1, got {args.workers}")
    if args.dask is not None:
        check_dask_address(args.dask)
    if args.workers is not None and args.dask not in (None, "local"):
        raise ConfigError("--workers: a remote --dask cluster brings its own workers")
    if args.out is not None:
        _check_sweep_out(args.out, args.resume, args.force)
    sweep = first_seeds(load_sweep(args.sweep, args.overrides, stream=sys.stderr), args.seeds)
    out = args.out if args.out is not None else Path("sweeps") / sweep.id
    if args.out is None:
        _check_sweep_out(out, args.resume, args.force)
    args._out, args._total = out, len(sweep.points) * len(sweep.seeds)
    summary = run_sweep(
        sweep, out, workers=args.workers, dask=args.dask, resume=args.resume, force=args.force
    )
    print(format_summary(sweep, summary))
    if (late := late_replies(out / "results.csv")) is not None:
        print(f"  {late}")
    if any(key.rsplit(".", 1)[-1] == "ber" for key, _ in sweep.axes):
        from testbed.report.sweep_plots import plot_ber_sweep

        paths = plot_ber_sweep(out / "results.csv", out)
        if paths:
            print(f"  plots: {', '.join(path.name for path in paths)}")
    return EXIT_OK if not summary.failed else 1


def late_replies(results_csv: Path) -> str | None:
    """``"warning: …"`` when runs of the sweep had a token gap shorter than a move order's
    round trip (``reply_fits_gap`` false: the line ``testbed run`` warns with for one run),
    naming the grid values where it happens; else None."""
    from testbed.report.sweep_results import read_results

    results = read_results(results_csv)
    late = [row for row in results.rows if row.get("reply_fits_gap") == "false"]
    if not late:
        return None
    values = {  # the grid keys that tell them apart: not every value of theirs is late
        key: ", ".join(dict.fromkeys(row[key] for row in late))
        for key in results.grid
        if {row[key] for row in late} != {row[key] for row in results.rows}
    }
    where = "; ".join(f"{key} {shown}" for key, shown in values.items())
    return (
        f"warning: in {len(late)} of {len(results.rows)} runs a reply does not fit the token "
        f"gap (reply_fits_gap false{': ' + where if where else ''}): the next order leaves "
        "before the reply is in"
    )


def first_seeds(sweep: Sweep, count: int | None) -> Sweep:
    """``sweep`` with only its first ``count`` seeds (None: all of them); its identity, which
    ``--resume`` checks, then names those seeds.

    Raises:
        ConfigError: ``count`` below 1 or above the sweep's seed count.
    """
    if count is None:
        return sweep
    held = len(sweep.seeds)
    if not 1 <= count <= held:
        raise ConfigError(f"--seeds: must be in 1..{held} (the sweep's seeds), got {count}")
    return dataclasses.replace(sweep, seeds=sweep.seeds[:count])


def _check_sweep_out(out: Path, resume: bool, force: bool) -> None:
    """``--out`` of a sweep: creatable and writable; with ``--resume``, an existing sweep;
    without it, empty (or ``--force``). The run checks it again, under its lock."""
    check_writable_dir(out)
    if resume and not out.exists():
        raise ConfigError(f"--resume: {out} does not exist; drop --resume to start the sweep there")
    if resume and out.is_dir() and not (out / "sweep.json").exists():
        raise ConfigError(f"--resume: {out} holds no sweep (no sweep.json)")
    from testbed.sweep.runner import out_is_empty

    if not resume and not force and not out_is_empty(out):
        if (out / "sweep.json").exists():
            raise ConfigError(
                f"--out: {out} already holds a sweep (add --resume to continue it, or --force "
                "to start it afresh)"
            )
        raise ConfigError(f"--out: {out} is not empty (use --force to write a sweep there)")


def _packaged_sweeps() -> str:
    """``id: description`` of every packaged sweep, one a line."""
    from testbed.sweep import sweep_names
    from testbed.sweep.spec import sweep_description

    return "\n".join(f"{name}: {sweep_description(name)}" for name in sweep_names())


def add_plot_parser(sub: Subparsers) -> None:
    """``testbed plot``: any results.csv column against another (testbed.report.pair_plots)."""
    plot = sub.add_parser(
        "plot",
        help="plot one column of a sweep's results.csv against another",
        description="Scatter a metric of every successful run against a grid key or another "
        "metric, with the median per x and 95 % t-intervals of the mean; one colour per --hue "
        "value. Writes a PNG (default: RESULTS' folder, <y>_vs_<x>.png).",
    )
    plot.add_argument("results", type=Path, help="a results.csv written by testbed sweep")
    plot.add_argument("--x", required=True, metavar="KEY", help="x column, e.g. link.ber")
    plot.add_argument(
        "--y", required=True, metavar="METRIC", help="y column, e.g. command_age_s.mean"
    )
    plot.add_argument("--hue", default=None, metavar="KEY", help="colour by this column")
    plot.add_argument(
        "--out",
        type=Path,
        default=None,
        help="PNG path (.png added to a name without one), or an existing directory to write "
        "<y>_vs_<x>.png into (default: RESULTS' folder)",
    )
    plot.set_defaults(handler=_run_plot)


def plot_out_path(out: Path, name: str) -> Path:
    """``testbed plot --out``: the PNG path actually written, checked before any work: in an
    existing directory, ``name`` there; else ``out`` (``.png`` added to a name without an
    extension) with that extension and a creatable, writable parent.

    Raises:
        ConfigError: another extension, a parent that is a file or not writable.
    """
    if out.is_dir():  # before ".png" is added: `--out plots` writes into plots/
        out = out / name
    elif out.suffix == "":
        out = out.with_name(out.name + ".png")
    if out.suffix.lower() != ".png":
        raise ConfigError(f"--out: {out}: unsupported extension {out.suffix!r} (writes .png)")
    if out.is_dir():
        raise ConfigError(f"--out: {out} is a directory")
    if out.exists() and not os.access(out, os.W_OK):
        raise ConfigError(f"--out: {out} is not writable")
    check_writable_dir(out.absolute().parent, "--out")
    return out


def _run_plot(args: argparse.Namespace) -> int:
    """Handler of ``testbed plot``: check --out and the file, draw, print the path written."""
    from testbed.report.pair_plots import default_plot_name, plot_pair
    from testbed.report.sweep_results import check_results_file

    name = default_plot_name(args.x, args.y)
    out = plot_out_path(args.results.parent / name if args.out is None else args.out, name)
    check_results_file(args.results)
    print(plot_pair(args.results, args.x, args.y, args.hue, out))
    return EXIT_OK
