"""``testbed sweep`` (a grid of runs) and ``testbed plot`` (one results.csv column vs another)."""

from __future__ import annotations

import argparse
from pathlib import Path

from testbed.cli.options import EXIT_OK, Subparsers, add_set_option
from testbed.config import ConfigError

__all__ = ["add_plot_parser", "add_sweep_parser"]


def add_sweep_parser(sub: Subparsers) -> None:
    """``testbed sweep``: a grid of runs on local processes or a Dask cluster (testbed.sweep)."""
    sweep = sub.add_parser(
        "sweep",
        help="run a scenario sweep (grid × seeds) locally or on a Dask cluster, resumable",
        description="Run every (grid point, seed) of a sweep file as an independent run. Writes "
        "runs.jsonl, results.csv (one row per run) and aggregate.csv (per point) to --out. "
        "Exit 0 when every run succeeded, 1 when some failed (listed), 2 on bad input.",
    )
    sweep.add_argument("sweep", help="packaged sweep id (e.g. ber-vs-lag-v1) or a sweep .toml path")
    add_set_option(
        sweep, "override a scenario key in every run, e.g. --set duration_s=30 (repeatable)"
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
        "--resume", action="store_true", help="continue the sweep in --out, skipping done runs"
    )
    sweep.set_defaults(handler=_run_sweep)


def _run_sweep(args: argparse.Namespace) -> int:
    """Handler of ``testbed sweep``: load and check the sweep, run it, summarise."""
    from testbed.sweep import format_summary, load_sweep, run_sweep

    if args.workers is not None and args.workers < 1:
        raise ConfigError(f"--workers: must be ≥ 1, got {args.workers}")
    if args.workers is not None and args.dask not in (None, "local"):
        raise ConfigError("--workers: a remote --dask cluster brings its own workers")
    sweep = load_sweep(args.sweep, args.overrides)
    out = args.out if args.out is not None else Path("sweeps") / sweep.id
    summary = run_sweep(sweep, out, workers=args.workers, dask=args.dask, resume=args.resume)
    print(format_summary(sweep, summary))
    if any(key.rsplit(".", 1)[-1] == "ber" for key, _ in sweep.axes):
        from testbed.report.sweep_plots import plot_ber_sweep

        paths = plot_ber_sweep(out / "results.csv", out)
        print(f"  plots: {', '.join(path.name for path in paths)}")
    return EXIT_OK if not summary.failed else 1


def add_plot_parser(sub: Subparsers) -> None:
    """``testbed plot``: any results.csv column against another (testbed.report.sweep_plots)."""
    plot = sub.add_parser(
        "plot",
        help="plot one column of a sweep's results.csv against another",
        description="Scatter a metric of every successful run against a grid key or another "
        "metric, with the median per x and 95 %% t-intervals of the mean; one colour per --hue "
        "value. Writes a PNG (default: RESULTS' folder, <y>_vs_<x>.png).",
    )
    plot.add_argument("results", type=Path, help="a results.csv written by testbed sweep")
    plot.add_argument("--x", required=True, metavar="KEY", help="x column, e.g. link.ber")
    plot.add_argument(
        "--y", required=True, metavar="METRIC", help="y column, e.g. command_age_s.mean"
    )
    plot.add_argument("--hue", default=None, metavar="KEY", help="colour by this column")
    plot.add_argument("--out", type=Path, default=None, help="PNG path")
    plot.set_defaults(handler=_run_plot)


def _run_plot(args: argparse.Namespace) -> int:
    """Handler of ``testbed plot``: check the columns, draw, print the path."""
    from testbed.report.sweep_plots import default_plot_name, plot_pair

    out = args.out
    if out is None:
        out = args.results.parent / default_plot_name(args.x, args.y)
    print(plot_pair(args.results, args.x, args.y, args.hue, out))
    return EXIT_OK
