"""What ``testbed run`` (and ``testbed hil``, ``testbed mavlink``) says of a run: the text.

:func:`format_summary` is the few lines a person reads after a run, :func:`format_trial` a
trial's line and :func:`format_trials_summary` the mean ± std line over trials; the notes they
are made of (the arm's TPIK solves, the navigation gate's rejections, the link failsafe, silent
navigation sources, a mission never started, how frames were lost, a capsize) each read one
part of ``metrics.json``. Figures are printed in the units named beside them (s, ms, m, mm,
deg, Wh, %). Pure functions of the metrics: nothing here runs, writes or parses arguments
(:mod:`testbed.cli.run` does).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from testbed.cli.options import format_value as _num
from testbed.cli.options import missing

__all__ = [
    "arm_note",
    "failsafe_note",
    "format_summary",
    "format_trial",
    "format_trials_summary",
    "gate_rejections",
    "loss_note",
    "never_ready",
    "silent_sources",
]


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
