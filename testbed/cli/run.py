"""``testbed run`` (one scenario end to end, its summary) and ``testbed scenarios``.

The summary's text is :mod:`testbed.cli.run_summary`'s; here the arguments, the run or trials,
writing the results and the exit code.
"""

from __future__ import annotations

import argparse
import sys
import traceback
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

from testbed.cli.options import (
    EXIT_FAILED,
    EXIT_OK,
    Subparsers,
    add_set_option,
    check_seed,
    exit_code_of,
    warn_late_goals,
    warn_token_cycle,
)
from testbed.cli.run_summary import format_summary, format_trial, format_trials_summary
from testbed.config import ConfigError
from testbed.run.failures import failed_trial, partial_run

if TYPE_CHECKING:
    from testbed.run.runner import RunResult
    from testbed.run.scenario_config import Scenario

__all__ = [
    "add_run_parser",
    "add_scenarios_parser",
    "finish_run",
    "format_summary",
    "format_trial",
    "format_trials_summary",
]


def add_run_parser(sub: Subparsers) -> None:
    """``testbed run``: one end-to-end teleoperation run of a scenario."""
    run = sub.add_parser(
        "run",
        help="simulate one scenario end to end and write metrics, events and plots",
        description="Simulate a scenario: operator and vehicle, each with its ECS world, over "
        "the simulated link. Writes metrics.json, events.csv, series.csv and plots to --out; "
        "a scenario with trials = N > 1 runs seeds seed … seed+N−1 into --out/trial-K/ and "
        "writes trials.json (and trials.png) across them.",
    )
    run.add_argument(
        "scenario",
        nargs="?",
        default="s100-teleop-v1",
        help="packaged scenario id or a .toml path (default: s100-teleop-v1; "
        "`testbed scenarios` lists them)",
    )
    add_set_option(run, "override a scenario key, e.g. --set link.ber=1e-4 (repeatable)")
    run.add_argument("--seed", type=int, default=None, help="random seed (default: the scenario's)")
    run.add_argument(
        "--out", type=Path, default=None, help="output directory (default: runs/<id>-<time>/)"
    )
    run.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    run.add_argument(
        "--force",
        action="store_true",
        help="write into a non-empty --out, replacing the results there",
    )
    run.set_defaults(handler=_run_scenario)


def _run_scenario(args: argparse.Namespace) -> int:
    """Handler of ``testbed run``: load, simulate, write, summarise."""
    import time

    from testbed.run.outputs import claimed_out_dir
    from testbed.run.runner import run_scenario
    from testbed.run.scenario import load_scenario

    check_seed(args.seed)
    scenario = load_scenario(args.scenario, args.overrides)
    warn_token_cycle(scenario)
    warn_late_goals(scenario)
    out = args.out
    if out is None:
        stamp = time.strftime("%Y%m%d-%H%M%S")
        out = Path("runs") / f"{scenario.id}-{stamp}"
    with claimed_out_dir(out, force=args.force):
        try:
            if scenario.trials > 1:
                return _run_trials(scenario, out, seed=args.seed, plots=not args.no_plots)
            result = run_scenario(scenario, seed=args.seed)
        except Exception as error:  # trials wrote a failed trial's part themselves
            if scenario.trials == 1 and (partial := partial_run(error)) is not None:
                from testbed.run.outputs import write_run
                from testbed.run.trials import remove_trials

                write_run(partial, out)
                remove_trials(out)
            return report_failed_run(error, out, scenario.duration_s, trials=scenario.trials)
        return finish_run(result, out, plots=not args.no_plots, planned_s=scenario.duration_s)


def report_failed_run(error: Exception, out: Path, planned_s: float, *, trials: int = 1) -> int:
    """Report a run (or trial) that ``error`` ended, what ran written (:mod:`testbed.run.failures`):
    for bad input (a ``ConfigError``, e.g. a pilot's sample that is no ``PilotSample``) one
    line, exit 2, naming where what ran is; for any other error its traceback, then that line,
    exit 1. An error that left nothing (not a run's, or a single run's at its first instant)
    is raised again, its traceback ending in "testbed: the run failed as it began; nothing was
    written" (a note on the error).

    Args:
        error: what ended the run.
        out: the results directory (trials: their parent).
        planned_s: the run's planned duration [s].
        trials: the scenario's trials; with more than one, the failed trial's number is the
            one :func:`~testbed.run.failures.failed_trial` noted, its outputs in ``out/trial-k``.
    """
    partial, k = partial_run(error), failed_trial(error)
    if partial is None and (k is None or trials == 1):
        if not isinstance(error, ConfigError):  # its traceback ends in the closing line
            error.add_note("testbed: the run failed as it began; nothing was written")
        raise error
    reached = (
        "" if partial is None else f"to t = {partial.metrics['sim_s']:.1f} s of {planned_s:g} s"
    )
    if k is not None and trials > 1:
        if partial is None:
            kept = f"trial {k} of {trials} failed as it began; the trials before it are in {out}"
        else:
            kept = f"what ran in trial {k} of {trials}, {reached}, is in {out / f'trial-{k}'}"
    else:
        kept = f"what ran {reached}, is in {out}"
    if isinstance(error, ConfigError):
        raise ConfigError(f"{error} ({kept})") from None
    traceback.print_exception(error)
    print(f"testbed: the run failed; {kept}", file=sys.stderr)
    return EXIT_FAILED


def _run_trials(scenario: Scenario, out: Path, *, seed: int | None, plots: bool) -> int:
    """``testbed run`` of a scenario with ``trials > 1``: the trials
    (:func:`testbed.run.trials.run_trials`), a line per trial and the mean ± std line on
    stdout, or for an interrupted one a line on stderr and 130/143."""
    from testbed.run.trials import run_trials

    run_plots = trials_plot = None
    if plots:
        from testbed.report.mission_plots import plot_trials
        from testbed.report.run_plots import write_run_plots

        run_plots, trials_plot = write_run_plots, plot_trials

    def said(trial: int, result: RunResult) -> None:
        print(format_trial(trial, result.metrics), flush=True)

    trials = run_trials(
        scenario, out, seed=seed, plots=run_plots, trials_plot=trials_plot, on_trial=said
    )
    document = trials.document
    if trials.stopped is not None:
        k, finished = document["interrupted_trial"], document["trials_finished"]
        reached = trials.interrupted_sim_s
        at = "" if reached != reached else f" at t = {reached:.1f} s of {scenario.duration_s:g} s"
        where = f"in trial {k} of {scenario.trials}{at}"
        if k is None:  # while a finished trial's plots or the trials figure were drawn
            where = f"while writing results, after trial {finished} of {scenario.trials}"
        print(
            f"testbed: interrupted {where}; {finished} finished, results in {out}", file=sys.stderr
        )
        return exit_code_of(trials.stopped)
    print(format_trials_summary(document, out))
    return EXIT_OK


def finish_run(
    result: RunResult,
    out: Path,
    *,
    plots: bool,
    planned_s: float,
    summary: Callable[[dict[str, Any], Path], str] | None = None,
    extras: Mapping[str, Callable[[Path], None]] | None = None,
) -> int:
    """Write a finished or interrupted run (``testbed run`` and ``testbed hil``) and say so:
    the summary on stdout, or for an interrupted run one line on stderr and 130/143.

    Args:
        result: the run.
        out: its results directory (checked before the run).
        plots: write the plots (never for an interrupted run: what ran is kept, fast).
        planned_s: the run's planned duration [s], for the interrupted line.
        summary: formats the summary (default :func:`format_summary`).
        extras: more data files to write (:func:`~testbed.run.outputs.write_run`).
    """
    from testbed.run.interrupts import deferred_interrupts
    from testbed.run.outputs import write_run
    from testbed.run.trials import remove_trials

    writer = None
    if plots and result.stopped is None:
        from testbed.report.run_plots import write_run_plots  # matplotlib only when plotting

        writer = write_run_plots
    late: KeyboardInterrupt | None = None
    try:
        write_run(result, out, plots=writer, extras=extras)
    except KeyboardInterrupt as interrupt:  # its data and metrics.json are written first
        late = interrupt
    with deferred_interrupts() as held:
        remove_trials(out)  # an earlier trials run's results (--force)
    late = late or (held[0] if held else None)
    if late is not None and result.stopped is None:  # the run finished; it was plotting
        print(
            f"testbed: interrupted while plotting; results without plots in {out}", file=sys.stderr
        )
        return exit_code_of(late)
    if result.stopped is not None:  # a second signal while its partial results were written too
        reached = result.metrics["sim_s"]
        print(
            f"testbed: interrupted at t = {reached:.1f} s of {planned_s:g} s; "
            f"partial results in {out}",
            file=sys.stderr,
        )
        return exit_code_of(result.stopped)
    print((summary or format_summary)(result.metrics, out))
    return EXIT_OK


def _list_scenarios(args: argparse.Namespace) -> int:
    """Handler of ``testbed scenarios``: one line per packaged scenario."""
    from testbed.run.scenario import load_scenario
    from testbed.run.scenario_files import scenario_names

    del args
    for name in scenario_names():
        print(f"{name:28s} {load_scenario(name).description.splitlines()[0]}")
    return EXIT_OK


def add_scenarios_parser(sub: Subparsers) -> None:
    """``testbed scenarios``: list the packaged scenarios."""
    scenarios = sub.add_parser("scenarios", help="list the packaged scenarios")
    scenarios.set_defaults(handler=_list_scenarios)
