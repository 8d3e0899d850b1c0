"""PNG plots of one run, drawn from its :class:`~testbed.run.recorder.Recorder`.

:func:`write_plots` writes, into one directory:

- ``timeline.png`` — the link's PDUs over time, one row per direction, a bar per transmission
  from ``tx_start`` to ``tx_end`` as tall as the packet is long, coloured by what became of it
  (the narrow-band paper's Fig. 4; drawn by :mod:`testbed.report.timeline`).
- ``speeds.png`` — the pilot's sticks against the sticks the vehicle applies, per axis
  (its Fig. 5), with the cross-correlation lag of each axis.
- ``state.png`` — depth and depth target, roll/pitch/yaw over time, the north–east track;
  disarmed and failsafe intervals shaded, node events marked.
- ``attitude_errors.png`` (attitude experiments only) — probability-density histograms of the
  attitude error per axis after the settling time (the ECS paper's Figs. 2–3).
- ``mission.png`` (vehicles under autonomy that recorded a pose target, written by
  :func:`write_run_plots`) — the path against the target and the error over time
  (:func:`testbed.report.mission_plots.plot_mission`).

Figures are built with :class:`matplotlib.figure.Figure` directly (Agg canvas, see
:mod:`testbed.report.figures`), never through ``pyplot``, so no global figure state is touched.
Nothing here simulates or computes metrics beyond what a plot states.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

from testbed.report.arm_plots import plot_arm
from testbed.report.figures import no_data, save
from testbed.report.images import plot_image_strip
from testbed.report.mission_plots import has_target, plot_mission
from testbed.report.timeline import TIMELINE_WINDOW_S, plot_timeline
from testbed.run.metrics import SIGNAL_LAG_WINDOW_S
from testbed.run.recorder import NodeEvent, Recorder
from testbed.run.run_metrics import stick_lag_s
from testbed.run.runner import RunResult
from testbed.vehicle.autonomy import resolve_mission

__all__ = [
    "plot_attitude_errors",
    "plot_speeds",
    "plot_state",
    "write_plots",
    "write_run_plots",
]


def _intervals(t: np.ndarray, mask: np.ndarray) -> list[tuple[float, float]]:
    """Maximal [t_start, t_end) runs where ``mask`` holds; a run lasts until the next sample."""
    if t.size == 0:
        return []
    step = float(np.median(np.diff(t))) if t.size > 1 else 0.0
    edges = np.diff(np.concatenate(([0], mask.astype(np.int8), [0])))
    starts = np.flatnonzero(edges == 1)
    stops = np.flatnonzero(edges == -1)
    return [
        (float(t[a]), float(t[b]) if b < t.size else float(t[-1]) + step)
        for a, b in zip(starts, stops, strict=True)
    ]


def _wrap_breaks(angle_deg: np.ndarray) -> np.ndarray:
    """A copy with NaN where the angle wraps (|jump| > 180°), so lines do not cross the plot."""
    out = angle_deg.astype(float).copy()
    if out.size > 1:
        jumps = np.flatnonzero(np.abs(np.diff(out)) > 180.0) + 1
        out[jumps] = np.nan
    return out


# -- commanded vs received sticks (Fig. 5) -----------------------------------------------------

_STICKS = (
    ("x", "surge stick x"),
    ("y", "sway stick y"),
    ("z", "heave stick z"),
    ("yaw", "yaw stick"),
)


def plot_speeds(
    series: Mapping[str, np.ndarray],
    path: Path,
    *,
    title: str,
    max_lag_s: float = SIGNAL_LAG_WINDOW_S,
    settle_s: float = 0.0,
) -> Path:
    """Draw the pilot's sticks (operator) against those the vehicle applies, one axis per row.

    Sticks are normalised to [−1, 1]. Each row's legend gives the delay that best aligns the
    vehicle's stick with the pilot's (:func:`testbed.run.metrics.signal_lag_s`) as
    ``metrics.json`` takes it: after ``settle_s`` [s], over the rows the link's sticks were
    flown (:func:`~testbed.run.run_metrics.received_from_the_link`).

    Args:
        series: :meth:`Recorder.series` columns (``t_s``, ``cmd_*``, ``rx_*``).
        path: PNG file to write.
        title: the run's title.
        max_lag_s: upper end of the lag search [s] (the scenario's
            :attr:`~testbed.run.sections.LinkSection.signal_lag_window_s`).

    Returns:
        ``path``.
    """
    t = np.asarray(series["t_s"], dtype=float)
    after = t >= settle_s  # the lag as metrics.json's signal_lag_s takes it
    fig = Figure(figsize=(11.0, 8.5), layout="constrained")
    axes = fig.subplots(len(_STICKS), 1, sharex=True, squeeze=False)[:, 0]
    fig.suptitle(f"{title}\ncommanded (operator) vs received (vehicle) sticks")
    for ax, (axis, name) in zip(axes, _STICKS, strict=True):
        ax.set_ylabel(f"{name} [−1…1]")
        if t.size == 0:
            no_data(ax, "no series recorded")
            continue
        cmd = np.asarray(series[f"cmd_{axis}"], dtype=float)
        rx = np.asarray(series[f"rx_{axis}"], dtype=float)
        lag = stick_lag_s(series, axis, after, max_lag_s)
        lag_text = "lag n/a" if math.isnan(lag) else f"lag ≈ {lag:.2f} s"
        commanded, received = "commanded (operator)", f"received (vehicle), {lag_text}"
        ax.plot(t, cmd, drawstyle="steps-post", color="tab:blue", lw=1.6, label=commanded)
        ax.plot(t, rx, drawstyle="steps-post", color="tab:red", lw=1.2, ls="--", label=received)
        both = np.concatenate([cmd, rx])
        ax.set_ylim(min(-1.05, np.nanmin(both) - 0.05), max(1.05, np.nanmax(both) + 0.05))
        ax.axhline(0.0, color="0.6", lw=0.6)
        ax.grid(alpha=0.3)
        ax.legend(loc="upper right", fontsize=8)
    axes[-1].set_xlabel("simulated time [s]")
    if t.size:
        axes[-1].set_xlim(float(t[0]), float(t[-1]))
    return save(fig, path)


# -- vehicle state -----------------------------------------------------------------------------


def _shade_flags(
    axes: Sequence[Axes], t: np.ndarray, series: Mapping[str, np.ndarray]
) -> list[Patch]:
    """Shade disarmed and failsafe intervals on time axes; return legend handles for those drawn."""
    handles = []
    shades = (  # column, value range [low, high), colour, label
        ("armed", -math.inf, 0.5, "0.85", "disarmed"),
        ("failsafe", 0.5, 1.5, "gold", "failsafe: hold"),
        ("failsafe", 1.5, math.inf, "salmon", "failsafe: surface"),
    )
    for column, low, high, colour, label in shades:
        values = np.asarray(series[column], dtype=float)
        spans = _intervals(t, (values >= low) & (values < high))
        for ax in axes:
            for a, b in spans:
                ax.axvspan(a, b, color=colour, alpha=0.5, lw=0)
        if spans:
            handles.append(Patch(color=colour, alpha=0.5, label=label))
    return handles


_EVENTS_LISTED = 16
"""Most node events numbered and listed on the state plot (the rest are only lines)."""


def _mark_events(
    axes: Sequence[Axes], events: Sequence[NodeEvent], t_span: tuple[float, float]
) -> list[Line2D]:
    """Dotted lines at node events; the first few numbered above the top axes (staggered)."""
    if not events:
        return []
    for ax in axes:
        for n in events:
            ax.axvline(n.t_s, color="tab:red", lw=0.8, ls=":")
    close_s = 0.02 * (t_span[1] - t_span[0])
    last_s, level = -math.inf, 0
    for number, n in enumerate(events[:_EVENTS_LISTED], start=1):
        if not t_span[0] <= n.t_s <= t_span[1]:
            continue
        level = (level + 1) % 3 if n.t_s - last_s < close_s else 0
        last_s = n.t_s
        axes[0].annotate(str(number), (n.t_s, 1.0), xycoords=("data", "axes fraction"),
                         xytext=(0.0, 1.0 + 8.0 * level), textcoords="offset points",
                         ha="center", va="bottom", fontsize=7, color="tab:red")  # fmt: skip
    return [Line2D([], [], color="tab:red", lw=0.8, ls=":", label="node event (numbered)")]


def _list_events(ax: Axes, events: Sequence[NodeEvent]) -> None:
    """The numbered node events as text in an empty panel."""
    ax.set_axis_off()
    ax.set_title("node events", fontsize=10, loc="left")
    lines = []
    for number, n in enumerate(events[:_EVENTS_LISTED], start=1):
        what = f"{n.kind} {n.detail}".strip()
        lines.append(f"{number:>2}  t = {n.t_s:7.2f} s  {n.node}: {what}")
    if len(events) > _EVENTS_LISTED:
        lines.append(f"    … and {len(events) - _EVENTS_LISTED} more (see events.csv)")
    ax.text(0.0, 1.0, "\n".join(lines), va="top", ha="left", fontsize=8, family="monospace",
            transform=ax.transAxes)  # fmt: skip


def plot_state(
    series: Mapping[str, np.ndarray],
    events: Sequence[NodeEvent],
    path: Path,
    *,
    title: str,
) -> Path:
    """Draw depth (and target), roll/pitch/yaw over time, and the north–east track.

    Disarmed and failsafe intervals (from the ``armed``/``failsafe`` columns) are shaded on the
    time plots, node events are dotted lines; the track marks start, end and where events
    happened, with equal axes.

    Args:
        series: :meth:`Recorder.series` columns.
        events: the recorder's node events.
        path: PNG file to write.
        title: the run's title.

    Returns:
        ``path``.
    """
    t = np.asarray(series["t_s"], dtype=float)
    fig = Figure(figsize=(13.0, 9.0), layout="constrained")
    grid = fig.add_gridspec(3, 2, width_ratios=(1.6, 1.0))
    ax_depth = fig.add_subplot(grid[0, 0])
    ax_tilt = fig.add_subplot(grid[1, 0], sharex=ax_depth)
    ax_yaw = fig.add_subplot(grid[2, 0], sharex=ax_depth)
    ax_track = fig.add_subplot(grid[:2, 1] if events else grid[:, 1])
    fig.suptitle(f"{title}\nvehicle state (physics truth)")
    ax_depth.set_ylabel("depth [m] (down)")
    ax_tilt.set_ylabel("roll, pitch [deg]")
    ax_yaw.set_ylabel("yaw [deg] (from north)")
    ax_yaw.set_xlabel("simulated time [s]")
    ax_track.set_xlabel("east [m]")
    ax_track.set_ylabel("north [m]")
    ax_track.set_title("track (north–east plane)", fontsize=10)
    if events:
        _list_events(fig.add_subplot(grid[2, 1]), events)
    if t.size == 0:
        for ax in (ax_depth, ax_tilt, ax_yaw, ax_track):
            no_data(ax, "no series recorded")
        return save(fig, path)

    time_axes = (ax_depth, ax_tilt, ax_yaw)
    flags = _shade_flags(time_axes, t, series)
    marks = _mark_events(time_axes, events, (float(t[0]), float(t[-1])))

    ax_depth.plot(t, series["down_m"], color="tab:blue", label="depth")
    target = np.asarray(series["depth_target_m"], dtype=float)
    if np.isfinite(target).any():
        ax_depth.plot(t, target, color="k", ls="--", lw=1.0, label="depth target (hold)")
    ax_depth.invert_yaxis()
    handles = [*ax_depth.get_legend_handles_labels()[0], *flags, *marks]
    ax_depth.legend(handles=handles, loc="best", fontsize=8)
    ax_depth.set_xlim(float(t[0]), float(t[-1]))
    ax_tilt.plot(t, series["roll_deg"], color="tab:blue", label="roll")
    ax_tilt.plot(t, series["pitch_deg"], color="tab:green", label="pitch")
    ax_tilt.legend(loc="best", fontsize=8, ncols=2)
    ax_yaw.plot(t, _wrap_breaks(np.asarray(series["yaw_deg"])), color="tab:orange")
    for ax in time_axes:
        ax.grid(alpha=0.3)

    north = np.asarray(series["north_m"], dtype=float)
    east = np.asarray(series["east_m"], dtype=float)
    ax_track.plot(east, north, color="tab:blue", lw=1.2)
    ax_track.plot(east[0], north[0], "o", color="tab:green", label=f"start (t = {t[0]:.1f} s)")
    ax_track.plot(east[-1], north[-1], "s", color="k", label=f"end (t = {t[-1]:.1f} s)")
    if events:
        times = np.array([n.t_s for n in events])
        at_east, at_north = np.interp(times, t, east), np.interp(times, t, north)
        ax_track.plot(at_east, at_north, "v", color="tab:red", label="node events")
    ax_track.set_aspect("equal", adjustable="datalim")
    ax_track.grid(alpha=0.3)
    ax_track.legend(loc="best", fontsize=8)
    return save(fig, path)


# -- attitude error distributions (ECS paper, Figs. 2-3) ---------------------------------------

_ERRORS = (("err_roll_deg", "roll"), ("err_pitch_deg", "pitch"), ("err_yaw_deg", "yaw"))


def plot_attitude_errors(
    series: Mapping[str, np.ndarray], path: Path, *, title: str, settle_s: float
) -> Path:
    """Draw probability-density histograms of the attitude error per axis after settling.

    Samples with ``t_s ≥ settle_s`` and a finite error (a target in force) are used; each
    legend gives their mean, standard deviation and count.

    Args:
        series: :meth:`Recorder.series` columns (``t_s``, ``err_*_deg``).
        path: PNG file to write.
        title: the run's title.
        settle_s: samples before this simulated time are left out [s].

    Returns:
        ``path``.
    """
    t = np.asarray(series["t_s"], dtype=float)
    fig = Figure(figsize=(13.0, 4.6), layout="constrained")
    axes = fig.subplots(1, len(_ERRORS), squeeze=False)[0]
    fig.suptitle(f"{title}\nattitude error distributions after t = {settle_s:g} s")
    for ax, (column, name) in zip(axes, _ERRORS, strict=True):
        values = np.asarray(series[column], dtype=float)
        values = values[(t >= settle_s) & np.isfinite(values)]
        ax.set_title(f"{name} error", fontsize=10)
        ax.set_xlabel(f"{name} error [deg]")
        ax.set_ylabel("probability density [1/deg]")
        if values.size == 0:
            no_data(ax, "no settled samples recorded")
            continue
        edges = np.histogram_bin_edges(values, bins="auto")
        if edges.size > 121:
            edges = np.histogram_bin_edges(values, bins=120)
        mean, std = float(values.mean()), float(values.std())
        label = f"mean {mean:+.2f}°, std {std:.2f}°\nn = {values.size}"
        density = ax.hist(values, edges, density=True, color="tab:blue", alpha=0.8, label=label)[0]
        ax.axvline(mean, color="k", ls="--", lw=1.0, label="mean")
        ax.set_ylim(0.0, 1.3 * float(np.max(density)))
        ax.grid(alpha=0.3)
        ax.legend(loc="upper right", fontsize=8)
    return save(fig, path)


# -- entry point -------------------------------------------------------------------------------


def write_plots(
    recorder: Recorder,
    out_dir: Path,
    *,
    title: str,
    attitude_experiment: bool,
    settle_s: float,
    timeline_window_s: float = TIMELINE_WINDOW_S,
    max_lag_s: float = SIGNAL_LAG_WINDOW_S,
) -> list[Path]:
    """Write the run's PNG plots into ``out_dir`` (created if missing).

    Args:
        recorder: the run's record.
        out_dir: directory for the PNG files.
        title: the run's title, first line of every figure title (e.g. scenario and link).
        attitude_experiment: also write ``attitude_errors.png``.
        settle_s: start of the attitude error window [s of simulated time].
        timeline_window_s: length of the timeline's window from the first transmission [s].
        max_lag_s: upper end of the stick-lag search in ``speeds.png`` [s].

    Returns:
        The files written: ``timeline.png``, ``speeds.png``, ``state.png`` and, for attitude
        experiments, ``attitude_errors.png``.
    """
    out_dir.mkdir(parents=True, exist_ok=True)
    series = recorder.series()
    paths = [
        plot_timeline(
            recorder.trace, out_dir / "timeline.png", title=title, window_s=timeline_window_s
        ),
        plot_speeds(
            series, out_dir / "speeds.png", title=title, max_lag_s=max_lag_s, settle_s=settle_s
        ),
        plot_state(series, recorder.events, out_dir / "state.png", title=title),
    ]
    if attitude_experiment:
        path = out_dir / "attitude_errors.png"
        paths.append(plot_attitude_errors(series, path, title=title, settle_s=settle_s))
    return paths


def write_run_plots(result: RunResult, out_dir: Path) -> list[Path]:
    """The plots of one run (:func:`write_plots`, and the image strip of image runs), titled
    with its scenario and seed; the files written."""
    scenario = result.scenario
    title = f"{scenario.id} (seed {result.seed})"
    written = write_plots(
        result.recorder,
        out_dir,
        title=title,
        attitude_experiment=scenario.pilot.kind == "attitude",
        settle_s=scenario.metrics.settle_s,
        max_lag_s=scenario.link.signal_lag_window_s,
    )
    if scenario.images.enabled and scenario.images.strip_images:  # 0: no strip
        written.append(
            plot_image_strip(
                result.recorder.images,
                out_dir / "images.png",
                title=title,
                count=scenario.images.strip_images,
            )
        )
    if result.recorder.arm is not None:
        written.append(plot_arm(result.recorder.arm, out_dir / "arm.png", title=title))
    autonomy = scenario.vehicle.autonomy
    series = result.recorder.series()
    if autonomy is not None and has_target(series):
        mission = None if autonomy.mission is None else resolve_mission(autonomy.mission)
        written.append(
            plot_mission(
                series,
                out_dir / "mission.png",
                title=title,
                waypoints_ned=[]
                if mission is None
                else [w.position_ned for w in mission.waypoints],
                tolerance_m=autonomy.tree.goal_tolerance_m,
                settle_s=scenario.metrics.settle_s,
                ready_s=result.metrics.get("mission", {}).get("ready_s"),
            )
        )
    return written
