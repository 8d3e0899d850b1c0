"""``testbed run`` (one scenario end to end, its summary) and ``testbed scenarios``."""

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
    missing,
    warn_late_goals,
    warn_token_cycle,
)
from testbed.cli.options import format_value as _num
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


def format_trial(trial: int, metrics: dict[str, Any]) -> str:
    """One line for a finished trial: seed, real-time factor, then under autonomy the mission
    error and command lag (and, when it never started, why: :func:`never_ready`), otherwise
    the teleoperation figures (command lag and age, yaw error, energy)."""
    from testbed.run.trials import headline

    h = headline(metrics)
    line = f"trial {trial} seed {metrics['seed']}: {_num(h['rtf'], digits=0)}x real time; "
    mission = metrics.get("mission")
    if mission is None:
        line += (
            f"command lag mean {_num(h['command_lag_mean_s'], 1000.0, 0, ' ms')}, age mean "
            f"{_num(h['command_age_mean_s'], 1000.0, 0, ' ms')}; yaw error std "
            f"{_num(h['yaw_error_std_deg'], digits=2, unit=' deg')}; depth error mean "
            f"{_num(h['depth_error_mean_m'], 1000.0, 0, ' mm')}; energy "
            f"{_num(h['energy_wh'], unit=' Wh')}"
        )
        if "images" not in metrics:
            return line
        return line + (
            f"; images {_num(h['images_per_minute'], digits=1)}/min, latency mean "
            f"{_num(h['image_latency_mean_s'], digits=1, unit=' s')}"
        )
    line += (
        f"position error mean {_num(h['position_error_mean_m'])} m, "
        f"final {_num(h['position_error_final_m'])} m; "
        f"settled {_num(h['time_to_converge_s'], digits=2)} s after the final target; "
        f"command lag mean {_num(h['command_lag_mean_s'], 1000.0, 0)} ms"
    )
    never = never_ready(mission)
    line = line if never is None else f"{line}; {never}"
    gated = gate_rejections(metrics, brief=True)
    return line if gated is None else f"{line}; {gated}"


def format_trials_summary(document: dict[str, Any], out: Path) -> str:
    """The mean ± std line over the trials (and where they were written): the mission's
    figures under autonomy, the teleoperation figures otherwise."""

    def pm(name: str, scale: float = 1.0, digits: int = 3) -> str:
        figure = document["across_trials"][name]
        return f"{_num(figure['mean'], scale, digits)} ± {_num(figure['std'], scale, digits)}"

    def pm_unit(name: str, unit: str, scale: float = 1.0, digits: int = 3) -> str:
        """:func:`pm` with its unit, or ``n/a`` alone for a figure no trial measured."""
        figure = document["across_trials"][name]
        return "n/a" if figure["n"] == 0 else f"{pm(name, scale, digits)} {unit}"

    head = f"{document['trials_finished']} trials (mean ± std over trials): "
    if not document.get("mission", True):
        images = ""
        if document["across_trials"].get("images_per_minute", {}).get("n"):
            images = (
                f"; images {pm('images_per_minute', digits=1)} /min, latency mean "
                f"{pm_unit('image_latency_mean_s', 's', digits=1)}"
            )
        return (
            f"{head}command lag mean {pm_unit('command_lag_mean_s', 'ms', 1000.0, 0)}, age "
            f"mean {pm_unit('command_age_mean_s', 'ms', 1000.0, 0)}; yaw error std "
            f"{pm_unit('yaw_error_std_deg', 'deg', digits=2)}; depth error mean "
            f"{pm_unit('depth_error_mean_m', 'mm', 1000.0, 0)}; energy "
            f"{pm_unit('energy_wh', 'Wh')}{images}\n  wrote {out}/"
        )
    return (
        f"{head}position error mean "
        f"{pm('position_error_mean_m')} m, final {pm('position_error_final_m')} m; settled "
        f"{pm('time_to_converge_s', digits=2)} s after the final target; command lag mean "
        f"{pm('command_lag_mean_s', 1000.0, 0)} ms\n  wrote {out}/"
    )


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


def format_summary(metrics: dict[str, Any], out: Path) -> str:
    """A few lines a person reads after a run."""

    def ms(value: float | None) -> str:
        return _num(value, 1000.0, 0, " ms")

    def per(value: float | None) -> str:
        return _num(value, 100.0, 2, " %")

    up, down = metrics["link"]["uplink"], metrics["link"]["downlink"]
    lag, age = metrics["command_lag_s"], metrics["command_age_s"]
    yaw = metrics["attitude_error_deg"]["yaw"]
    depth = metrics["depth_error_m"]["mean"]
    lines = [
        f"{metrics['scenario']} seed {metrics['seed']}: {metrics['sim_s']:.0f} s simulated in "
        f"{metrics['wall_s']:.1f} s ({metrics['rtf']:.0f}x real time)",
        f"  uplink   {up['frames_delivered']}/{up['frames_sent']} frames, PER "
        f"{per(up['per'])}{loss_note(up)}, {up['goodput_bps']:.0f} bit/s",
        f"  downlink {down['frames_delivered']}/{down['frames_sent']} frames, PER "
        f"{per(down['per'])}{loss_note(down)}, {down['goodput_bps']:.0f} bit/s",
        f"  command lag mean {ms(lag['mean'])} p95 {ms(lag['p95'])}; command age mean "
        f"{ms(age['mean'])}; odometry age mean {ms(metrics['odometry_age_s']['mean'])}",
        f"  yaw error std {_num(yaw['std'], digits=2, unit=' deg')}; "
        f"depth error mean {_num(depth, 1000.0, 0, ' mm')}; energy {metrics['energy_wh']:.3f} Wh",
    ]
    if (failsafe := failsafe_note(metrics)) is not None:
        lines.append(f"  {failsafe}")
    images = metrics.get("images")
    if images is not None:
        latency, psnr = images["latency_s"]["mean"], images["psnr_db"]["mean"]
        lines.append(
            f"  images {images['completed']}/{images['captured']} completed "
            f"({images['per_minute']:.1f}/min), latency mean {_num(latency, digits=1, unit=' s')}"
            f", PSNR mean {_num(psnr, digits=1, unit=' dB')}"
        )
    mission = metrics.get("mission")
    if mission is not None:
        error = mission["position_error_m"]
        arrival = mission.get("final_target_s")
        settled = (
            f"settled {_num(mission['time_to_converge_s'], digits=2)} s after the final target "
            f"(at {_num(arrival, digits=1)} s)"
        )
        if missing(arrival) and mission.get("samples"):
            settled = "no final target: it still moved at the last armed row"
        lines.append(
            f"  mission position error mean {_num(error['mean'])} m, std {_num(error['std'])} m, "
            f"final {_num(error['final'])} m; {settled}; goals reached "
            f"{_goals(mission['goals_reached'], mission['goals'])}; estimate error mean "
            f"{_num(mission['estimate_error_m']['mean'])} m"
        )
        heading = mission.get("yaw_error_deg")
        if heading is not None and not missing(heading["mean"]):  # none: an end effector flown
            lines.append(
                f"  mission yaw error (|truth − target|) mean {_num(heading['mean'], digits=2)} "
                f"deg, p95 {_num(heading['p95'], digits=2)} deg"
            )
        if (never := never_ready(mission)) is not None:
            lines.append(f"  {never}")
    if (arm := arm_note(metrics)) is not None:
        lines.append(f"  {arm}")
    if (gated := gate_rejections(metrics)) is not None:
        lines.append(f"  {gated}")
    lines += [f"  {line}" for line in silent_sources(metrics)]
    if (capsized := _capsized(metrics)) is not None:
        lines.append(f"  {capsized}")
    lines.append(f"  wrote {out}/")
    return "\n".join(lines)


def arm_note(metrics: dict[str, Any]) -> str | None:
    """``"arm: 870 TPIK solves, 12 with a joint-limit task; closest to a limit: axis_e
    5.1°"`` for a vehicle with an arm (``margin_deg`` below 0: "past its safety limit by"),
    else None."""
    arm = metrics.get("arm")
    if arm is None:
        return None
    line = f"arm: {arm['solves']} TPIK solves, {arm['limit_activations']} with a joint-limit task"
    margins = {
        name: joint["margin_deg"]
        for name, joint in arm["joints"].items()
        if not missing(joint["margin_deg"])
    }
    if margins:
        joint = min(margins, key=margins.__getitem__)
        margin = margins[joint]
        closest = f"{margin:.1f}°" if margin >= 0 else f"past its limit by {-margin:.1f}°"
        line += f"; closest to a limit: {joint} {closest}"
    return line


def _capsized(metrics: dict[str, Any]) -> str | None:
    """``"warning: the vehicle capsized …"`` when its roll or pitch passed 90°, else None
    (keys only ever added: an older metrics.json has no ``max_tilt_deg``)."""
    tilt = metrics.get("max_tilt_deg")
    if tilt is None or missing(tilt.get("capsized_s")):
        return None
    return (
        f"warning: the vehicle capsized at t = {tilt['capsized_s']:.1f} s (largest roll "
        f"{tilt['roll']:.0f}°, pitch {tilt['pitch']:.0f}°)"
    )


def gate_rejections(metrics: dict[str, Any], *, brief: bool = False) -> str | None:
    """The line saying the navigation filter's χ² gate rejected measurements (how many, of
    which source), or None when it rejected none (or there is no filter). When it rejected
    far more than its ``1 − gate_probability`` of good measurements would be by chance (more
    than 3 and ten times that), the line says which key to look at (docs/autonomy.md);
    ``brief``: the count alone (a trial's line)."""
    navigation = metrics.get("navigation") or {}
    counts = navigation.get("filter")
    if not counts or not counts.get("rejected"):
        return None
    rejected = counts["rejected"]
    given = counts["accepted"] + counts["rejected"] + counts["invalid"] + counts["stale"]
    if brief:
        return f"navigation gate rejected {rejected} of {given}"
    sources = ", ".join(
        f"{name} {c['rejected']}/{c['accepted'] + c['rejected']}"
        for name, c in (navigation.get("by_source") or {}).items()
        if c["rejected"]
    )
    which = f" ({sources})" if sources else ""
    line = (
        f"navigation filter's χ² gate rejected {rejected} of {given} measurements{which}, "
        f"re-acquired {counts['reacquired']}"
    )
    gate = navigation.get("gate_probability")
    chance = (1.0 - gate) * (counts["accepted"] + rejected) if gate is not None else 0.0
    if rejected > max(3.0, 10.0 * chance):
        line += (
            ": far more than chance; good fixes at a slow rate want a larger "
            "vehicle.navigation.filter.accel_noise_m2_s3 (docs/autonomy.md)"
        )
    return line


def failsafe_note(metrics: dict[str, Any]) -> str | None:
    """The line saying the vehicle's link failsafe engaged (and surfaced it, which disarms
    it), or None when it never did (keys only ever added: older files have no
    ``failsafe_surfaced``)."""
    events = metrics.get("events", {})
    engaged, surfaced = events.get("failsafe"), events.get("failsafe_surfaced")
    if missing(engaged) or not engaged:  # none, or counted on another computer (HIL)
        return None
    note = f"link failsafe engaged {engaged} time{'s' if engaged != 1 else ''}"
    if not missing(surfaced) and surfaced:
        note += f", surfaced {surfaced} (then disarmed; events.csv has when)"
    return note


def silent_sources(metrics: dict[str, Any]) -> list[str]:
    """A warning line for each fitted navigation source that delivered nothing (a DVL out of
    bottom lock the whole run, say), with what it lost when it counts that."""
    navigation = metrics.get("navigation") or {}
    lost = navigation.get("lost") or {}
    lines = []
    for name, count in (navigation.get("delivered") or {}).items():
        if count:
            continue
        why = ""
        if (losses := lost.get(name)) is not None:
            why = (
                f": {losses['unlocked']} samples without bottom lock, {losses['dropouts']} dropped"
            )
        lines.append(f"warning: navigation source {name} delivered nothing{why}")
    return lines


def never_ready(mission: dict[str, Any]) -> str | None:
    """The line saying a mission never started because navigation was never ready (its
    position σ never came within ``ready_sigma_m``), or None when it was (or is not known)."""
    if "ready_s" not in mission or not missing(mission["ready_s"]):
        return None
    sigma = mission.get("ready_sigma_m")
    limit = "" if missing(sigma) else f" = {sigma:g} m"
    return (
        f"mission never started: navigation not ready (position σ > ready_sigma_m{limit} "
        "for the whole run)"
    )


def loss_note(direction: dict[str, Any]) -> str:
    """``" (collided N, …)"``: how the frames in the PER were lost when not by bit errors
    alone (collisions, out of range, outages; with the copies a half-duplex receiver lost to
    its own transmission, ``copies_lost_transmitting``), then ``", dropped N (P %)"``: frames
    the sender's FIFO dropped (never on the air, so not in the PER); nothing for what did not
    happen."""
    causes = [
        f"{label} {direction[key]}"
        for key, label in _LOSS_CAUSES
        if direction.get(key)  # keys only ever added: an older metrics.json may lack one
    ]
    deaf = direction.get("copies_lost_transmitting")
    if deaf and direction.get("frames_collided"):
        copies = "copy" if deaf == 1 else "copies"
        causes[0] += f": {deaf} {copies} lost while the receiver transmitted"
    lost = f" ({', '.join(causes)})" if causes else ""
    dropped = direction["frames_dropped"]
    if not dropped:
        return lost
    rate = _num(direction["drop_rate"], 100.0, 1, " %")
    return f"{lost}, dropped {dropped} ({rate}) at the sender"


_LOSS_CAUSES = (
    ("frames_collided", "collided"),
    ("frames_out_of_range", "out of range"),
    ("frames_outage", "in an outage"),
)


def _count(value: int | None) -> str:
    return "n/a" if value is None else str(value)


def _goals(reached: int | None, goals: int | None) -> str:
    """``"reached/goals"``, or one ``"n/a"`` when both are null (the vehicle never published a
    mission status, e.g. a mission that never started), not ``"n/a/n/a"``."""
    if reached is None and goals is None:
        return "n/a"
    return f"{_count(reached)}/{_count(goals)}"


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
