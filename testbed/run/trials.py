"""Repeated trials of one scenario: runs with consecutive seeds, each written whole, and a
summary across them (Angler's "mean ± std over trials").

:func:`run_trials` runs ``scenario.trials`` runs with seeds ``seed, seed + 1, …`` one after the
other, writes trial ``K`` (1-based) into ``OUT/trial-K/`` with :func:`~testbed.run.outputs.
write_run` (its usual ``metrics.json``, ``events.csv``, ``series.csv`` and plots), and then
``OUT/trials.json``: per trial its seed and the headline metrics (:data:`HEADLINE`), and across
the trials the mean and the sample standard deviation (``ddof = 1``) of each, over the trials
where the value is finite (``n`` says how many). An interrupt (Ctrl-C, SIGTERM) during trial
``K`` keeps trials ``1 … K−1`` and ``K``'s partial outputs (no plots), and ``trials.json`` then
covers the finished trials only, with ``"complete": false`` and the interrupted trial named.
One that comes while a trial that ran to its end is written (its plots drawn) or while the
trials figure is drawn ends no trial part way: that trial is finished (its data and
``metrics.json`` are written whole first) and ``interrupted_trial`` is null.
An error that ends trial ``K`` (a pilot of the user's that raises, say) keeps the same, with
``K``'s partial outputs carrying the error (``"failure"``) and ``"failed_trial": K``, and is
then raised.

Only the few series columns the trials figure draws are kept from each run (:class:`TrialTrack`),
not its recording. Nothing here parses arguments or prints: :mod:`testbed.cli.run` does.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from testbed.run.failures import keep_trial, partial_run
from testbed.run.interrupts import deferred_interrupts, interrupt_of
from testbed.run.outputs import (
    METRICS_FILE,
    PlotWriter,
    remove_run_results,
    write_json_atomic,
    write_run,
)
from testbed.run.runner import RunResult, run_scenario
from testbed.run.scenario_config import Scenario

__all__ = [
    "HEADLINE",
    "TRIALS_FILE",
    "WALL_CLOCK_KEYS",
    "TrialTrack",
    "TrialsResult",
    "headline",
    "remove_trials",
    "run_trials",
    "trial_dir",
    "trials_document",
]

TRIALS_FILE = "trials.json"
TRIALS_PLOT = "trials.png"

HEADLINE: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("rtf", ("rtf",)),
    ("position_error_mean_m", ("mission", "position_error_m", "mean")),
    ("position_error_final_m", ("mission", "position_error_m", "final")),
    ("position_error_std_m", ("mission", "position_error_m", "std")),
    ("time_to_converge_s", ("mission", "time_to_converge_s")),
    ("command_lag_mean_s", ("command_lag_s", "mean")),
    ("command_age_mean_s", ("command_age_s", "mean")),
    ("yaw_error_std_deg", ("attitude_error_deg", "yaw", "std")),
    ("depth_error_mean_m", ("depth_error_m", "mean")),
    ("energy_wh", ("energy_wh",)),
    ("images_per_minute", ("images", "per_minute")),
    ("image_latency_mean_s", ("images", "latency_s", "mean")),
    ("image_psnr_mean_db", ("images", "psnr_db", "mean")),
)
"""The per-trial figures of ``trials.json``: name → path of keys into ``metrics.json`` (NaN
where the path is missing, e.g. the mission keys of a run without autonomy). The mission
figures summarise trials under autonomy (Angler's protocol), the command and yaw figures
teleoperated ones, the image figures those with image feedback."""

WALL_CLOCK_KEYS = ("rtf",)
"""Headline figures that depend on the machine's speed (not reproducible from the seed)."""

_TRACK_COLUMNS = (
    "t_s",
    "north_m",
    "east_m",
    "down_m",
    "target_n",
    "target_e",
    "target_d",
    "est_n",
    "est_e",
    "armed",
    "ee_n",
    "ee_e",
    "ee_d",
    "ee_target_n",
    "ee_target_e",
    "ee_target_d",
)


@dataclass(frozen=True, slots=True)
class TrialTrack:
    """What the trials figure draws of one trial: a few of its series columns (copies).

    Attributes:
        trial: the trial's number (1-based).
        seed: its seed.
        series: ``t_s``, truth, target and estimate positions and ``armed``, by column name.
        settle_s: the scenario's settling time [s] (the error statistics start there).
        tolerance_m: the mission tree's goal tolerance [m]; None without autonomy.
    """

    trial: int
    seed: int
    series: dict[str, np.ndarray]
    settle_s: float
    tolerance_m: float | None = None


@dataclass(frozen=True, slots=True)
class TrialsResult:
    """The trials of one scenario, run and written.

    Attributes:
        scenario: what was run.
        document: the ``trials.json`` content (:func:`trials_document`).
        tracks: one :class:`TrialTrack` per finished trial.
        stopped: the interrupt that ended the trials early, or None.
        interrupted_sim_s: simulated time the interrupted trial reached [s] (NaN if none, or
            if it was interrupted outside its simulation).
        files: every file written (each trial's, then ``trials.json`` and the figure).
    """

    scenario: Scenario
    document: dict[str, Any]
    tracks: list[TrialTrack]
    stopped: KeyboardInterrupt | None
    interrupted_sim_s: float
    files: list[Path]


TrialsPlot = Callable[[Sequence[TrialTrack], Path, str], Path]
"""Draws the trials figure: tracks, the PNG path, a title; returns the path."""


def trial_dir(out: Path, trial: int) -> Path:
    """The results directory of trial ``trial`` (1-based) under ``out``."""
    return out / f"trial-{trial}"


def headline(metrics: dict[str, Any]) -> dict[str, float]:
    """The :data:`HEADLINE` figures of one run's metrics (NaN where missing or null)."""
    figures: dict[str, float] = {}
    for name, keys in HEADLINE:
        value: Any = metrics
        for key in keys:
            value = value.get(key) if isinstance(value, dict) else None
        ok = isinstance(value, int | float) and not isinstance(value, bool)
        figures[name] = float(value) if ok else math.nan
    return figures


def trials_document(
    scenario: Scenario,
    first_seed: int,
    finished: Sequence[RunResult],
    interrupted: int | None,
    failed: int | None = None,
) -> dict[str, Any]:
    """The ``trials.json`` content of the finished trials (module docstring).

    Args:
        scenario: the scenario run.
        first_seed: the seed of trial 1.
        finished: the finished trials' results, in order.
        interrupted: the number of the trial an interrupt ended, or None.
        failed: the number of the trial an error ended, or None.
    """
    rows = [
        {"trial": k, "seed": result.seed, "dir": trial_dir(Path(), k).as_posix()}
        | headline(result.metrics)
        for k, result in enumerate(finished, start=1)
    ]
    across: dict[str, dict[str, float | int]] = {}
    for name, _ in HEADLINE:
        values = np.array([row[name] for row in rows], dtype=float)
        values = values[np.isfinite(values)]
        across[name] = {
            "mean": float(values.mean()) if values.size else math.nan,
            "std": float(values.std(ddof=1)) if values.size > 1 else math.nan,
            "n": int(values.size),
        }
    return {
        "scenario": scenario.id,
        "first_seed": first_seed,
        "trials_planned": scenario.trials,
        "trials_finished": len(finished),
        "complete": interrupted is None and failed is None and len(finished) == scenario.trials,
        "interrupted_trial": interrupted,
        "failed_trial": failed,
        "std_ddof": 1,
        "wall_clock_keys": list(WALL_CLOCK_KEYS),
        "mission": scenario.vehicle.autonomy is not None,
        "trials": rows,
        "across_trials": across,
    }


def _track(trial: int, result: RunResult) -> TrialTrack:
    series = result.recorder.series()
    kept = {name: np.array(series[name]) for name in _TRACK_COLUMNS}
    scenario = result.scenario
    autonomy = scenario.vehicle.autonomy
    tolerance = None if autonomy is None else autonomy.tree.goal_tolerance_m
    return TrialTrack(trial, result.seed, kept, scenario.metrics.settle_s, tolerance)


def run_trials(
    scenario: Scenario,
    out: Path,
    *,
    seed: int | None = None,
    plots: PlotWriter | None = None,
    trials_plot: TrialsPlot | None = None,
    on_trial: Callable[[int, RunResult], None] | None = None,
) -> TrialsResult:
    """Run ``scenario.trials`` trials with consecutive seeds and write them (module docstring).

    Args:
        scenario: the scenario (its ``trials`` says how many).
        out: the results directory (checked by :func:`~testbed.run.outputs.prepare_out_dir`
            beforehand); trial ``K`` goes to ``out/trial-K/``.
        seed: the seed of trial 1 (default: the scenario's).
        plots: each finished trial's plot writer (:func:`~testbed.run.outputs.write_run`'s),
            or None.
        trials_plot: draws ``out/trials.png`` when every trial finished, or None.
        on_trial: called after each finished trial is written, with its number and result.

    Returns:
        What ran and was written; ``stopped`` is the interrupt that ended it early, if any.
    """
    first = scenario.seed if seed is None else seed
    finished: list[RunResult] = []
    tracks: list[TrialTrack] = []
    files: list[Path] = []
    stopped: KeyboardInterrupt | None = None
    interrupted: int | None = None
    reached_s = math.nan
    for k in range(1, scenario.trials + 1):
        try:
            result = run_scenario(scenario, seed=first + k - 1)
            if result.stopped is not None:  # keep what ran, fast: no plots
                stopped, interrupted, reached_s = result.stopped, k, result.metrics["sim_s"]
                files += write_run(result, trial_dir(out, k))
                break
        except BaseException as error:  # an interrupt between runs, or an error
            if (stopped := interrupt_of(error)) is None:  # an error ended trial k
                _keep_failed(scenario, first, finished, out, k, partial_run(error))
                keep_trial(error, k)
                raise
            interrupted = k
            break
        try:
            files += write_run(result, trial_dir(out, k), plots=plots)
        except KeyboardInterrupt as interrupt:  # trial k is whole: write_run wrote its data and
            stopped = interrupt  # metrics.json before raising, only its plots are cut short
            if not (trial_dir(out, k) / METRICS_FILE).exists():  # it came before writing began
                files += _write_whole(result, trial_dir(out, k))
        finished.append(result)
        tracks.append(_track(k, result))
        if on_trial is not None:
            on_trial(k, result)
        if stopped is not None:
            break
    with deferred_interrupts() as late:  # the summary whole, even on a Ctrl-C now
        document = trials_document(scenario, first, finished, interrupted)
        files.append(write_json_atomic(out / TRIALS_FILE, document))
        written = len(finished) if interrupted is None else interrupted
        remove_trials(out, keep=written, keep_summary=True)  # an earlier run's, under --force
        remove_run_results(out)
    stopped = stopped or (late[0] if late else None)
    mission = scenario.vehicle.autonomy is not None  # the figure draws missions' tracks
    (out / TRIALS_PLOT).unlink(missing_ok=True)  # an earlier run's figure of other trials
    if trials_plot is not None and stopped is None and tracks and mission:
        title = f"{scenario.id}: {len(tracks)} trials, seeds {first}…{first + len(tracks) - 1}"
        try:
            files.append(trials_plot(tracks, out / TRIALS_PLOT, title))
        except KeyboardInterrupt as interrupt:  # the trials and trials.json are written
            stopped = interrupt
    return TrialsResult(scenario, document, tracks, stopped, reached_s, files)


def _write_whole(result: RunResult, out_dir: Path) -> list[Path]:
    """Write a finished trial without plots, an interrupt during it honoured after it."""
    with deferred_interrupts():  # the caller already stops for the interrupt that came first
        return write_run(result, out_dir)


def _keep_failed(
    scenario: Scenario,
    first: int,
    finished: Sequence[RunResult],
    out: Path,
    k: int,
    partial: RunResult | None,
) -> None:
    """Trial ``k`` failed: its partial outputs (no plots; none when it failed as it began) and
    ``trials.json`` over the finished trials with ``k`` named as the failed one; the error is
    raised by the caller."""
    if partial is not None:
        write_run(partial, trial_dir(out, k))
    document = trials_document(scenario, first, finished, None, failed=k)
    write_json_atomic(out / TRIALS_FILE, document)
    remove_trials(out, keep=k if partial is not None else k - 1, keep_summary=True)
    remove_run_results(out)
    (out / TRIALS_PLOT).unlink(missing_ok=True)


def remove_trials(out: Path, *, keep: int = 0, keep_summary: bool = False) -> None:
    """Remove earlier trials' results from ``out`` (``--force``): each ``trial-K`` directory
    with ``K > keep`` loses its run's results (:func:`~testbed.run.outputs.remove_run_results`)
    and goes if that leaves it empty; ``trials.json`` and ``trials.png`` go too unless
    ``keep_summary``. Nothing that is not a run's result is touched."""
    for path in out.glob("trial-*"):
        number = path.name.removeprefix("trial-")
        if path.is_dir() and number.isdigit() and int(number) > keep:
            remove_run_results(path)
            with contextlib.suppress(OSError):
                path.rmdir()
    if not keep_summary:
        for name in (TRIALS_FILE, TRIALS_PLOT):
            (out / name).unlink(missing_ok=True)
