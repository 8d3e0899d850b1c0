"""PNG plots of autonomous missions: the path flown against its target (Angler Figs. 6–7).

What is drawn is what the mission flies (:func:`~testbed.run.metrics.tracked_positions`): the
vehicle's body origin against its pose target, or the arm's end effector against its target
(with the body's path in grey on the single-run figure).

- ``mission.png`` (:func:`plot_mission`, one run) — a top view, east across and north up, of the
  true path, the navigation estimate (thin; from ``mission.ready_s`` on), the pose target
  (dashed) and the mission's waypoints (markers); beside it the position error |truth − target|
  over time with the goal tolerance and the settling time.
- ``trials.png`` (:func:`plot_trials`, repeated trials) — the same top view with one true path
  per trial, and the error over time of each trial.

The error drawn is the one ``metrics.json``'s ``"mission"`` key reduces (armed, with a target):
:func:`testbed.run.metrics.position_error`. Figures are built on :class:`matplotlib.figure.Figure`
directly (:mod:`testbed.report.figures`), never through ``pyplot``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from testbed.report.figures import no_data, save
from testbed.run.metrics import position_error, tracked_positions
from testbed.run.trials import TrialTrack

__all__ = ["estimate_track", "has_target", "mission_error", "plot_mission", "plot_trials"]

_TRUTH, _ESTIMATE, _TARGET = "tab:blue", "tab:orange", "k"


def has_target(series: Mapping[str, np.ndarray]) -> bool:
    """Whether the series recorded a pose or end-effector target at some row (a vehicle
    under autonomy)."""
    return bool(np.isfinite(tracked_positions(series)[1]).all(axis=1).any())


def mission_error(series: Mapping[str, np.ndarray]) -> np.ndarray:
    """(n,) |truth − target| [m] per row of what the mission flies (the body, or the end
    effector: :func:`~testbed.run.metrics.tracked_positions`); NaN where there is no target
    or it is disarmed."""
    truth, target, _ = tracked_positions(series)
    error = position_error(truth, target)
    error[np.asarray(series["armed"], dtype=float) <= 0.5] = np.nan
    return error


def estimate_track(
    series: Mapping[str, np.ndarray], ready_s: float | None
) -> tuple[np.ndarray, np.ndarray]:
    """The navigation estimate's (east, north) [m] per row, NaN before navigation was ready.

    Until its first position fix the filter sits at north = east = 0 with σ 10 m; the mission
    tree waits for σ ≤ ``ready_sigma_m`` (``mission.ready_s``), and so does the drawn estimate
    (else a line runs from (0, 0) to the true start).

    Args:
        series: the ``t_s``, ``est_e`` and ``est_n`` columns.
        ready_s: when the estimate was first ready [s]; NaN: never (nothing drawn); None: not
            known (every row drawn).

    Returns:
        ``(east, north)``, (n,) each, copies.
    """
    east = np.array(series["est_e"], dtype=float)
    north = np.array(series["est_n"], dtype=float)
    if ready_s is not None:
        early = ~(np.asarray(series["t_s"], dtype=float) >= ready_s)  # all rows when NaN
        east[early] = north[early] = np.nan
    return east, north


def _top_view(ax: Axes) -> None:
    ax.set_xlabel("east [m]")
    ax.set_ylabel("north [m]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(alpha=0.3)


def _error_axes(ax: Axes, tolerance_m: float | None, settle_s: float | None) -> None:
    if tolerance_m is not None:
        ax.axhline(
            tolerance_m, color="tab:red", ls=":", lw=1.0, label=f"tolerance {tolerance_m:g} m"
        )
    if settle_s is not None and settle_s > 0.0:
        ax.axvline(settle_s, color="0.5", ls="--", lw=0.8, label=f"settle {settle_s:g} s")
    ax.set_xlabel("simulated time [s]")
    ax.set_ylabel("position error |p − p*| [m]")
    ax.set_ylim(bottom=0.0)
    ax.grid(alpha=0.3)


def plot_mission(
    series: Mapping[str, np.ndarray],
    path: Path,
    *,
    title: str,
    waypoints_ned: Sequence[Sequence[float]] = (),
    tolerance_m: float | None = None,
    settle_s: float | None = None,
    ready_s: float | None = None,
) -> Path:
    """Draw one run's mission: top view of truth, estimate, target and waypoints; e(t).

    Args:
        series: :meth:`~testbed.run.recorder.Recorder.series` columns (``t_s``, truth,
            ``target_*``, ``est_*``, ``armed``).
        path: PNG file to write.
        title: the run's title.
        waypoints_ned: (k, 3) the mission's waypoints [m], NED (none: no markers).
        tolerance_m: the goal tolerance drawn on the error panel [m], or None.
        settle_s: the settling time marked on the error panel [s], or None.
        ready_s: ``mission.ready_s`` [s]: the estimate is drawn from then on
            (:func:`estimate_track`); None: all of it.

    Returns:
        ``path``.
    """
    fig = Figure(figsize=(12.0, 5.5), layout="constrained")
    top, err = fig.subplots(1, 2, gridspec_kw={"width_ratios": (1.0, 1.3)})
    fig.suptitle(f"{title}\nmission: path against the pose target")
    _top_view(top)
    if not has_target(series):
        no_data(top, "no pose target recorded")
        no_data(err, "no pose target recorded")
        return save(fig, path)
    truth, target, reaching = tracked_positions(series)
    if reaching:  # the end effector flies the mission; the body's path beside it
        top.plot(series["east_m"], series["north_m"], color="0.6", lw=0.8, label="body")
        top.plot(truth[:, 1], truth[:, 0], color=_TRUTH, lw=1.6, label="end effector")
    else:
        top.plot(series["east_m"], series["north_m"], color=_TRUTH, lw=1.6, label="truth")
        east, north = estimate_track(series, ready_s)
        top.plot(east, north, color=_ESTIMATE, lw=0.7, label="estimate")
    top.plot(target[:, 1], target[:, 0], color=_TARGET, lw=1.2, ls="--", label="target")
    points = np.asarray(waypoints_ned, dtype=float).reshape(-1, 3)
    if points.size:
        top.plot(
            points[:, 1], points[:, 0], "s", color="tab:red", ms=7, mfc="none", label="waypoints"
        )
    top.plot(truth[:1, 1], truth[:1, 0], "o", color=_TRUTH, ms=5, label="start")
    top.legend(loc="best", fontsize=8)
    t = np.asarray(series["t_s"], dtype=float)
    error = mission_error(series)
    err.plot(t, error, color=_TRUTH, lw=1.2, label="|truth − target|")
    _error_axes(err, tolerance_m, settle_s)
    err.legend(loc="upper right", fontsize=8)
    return save(fig, path)


def plot_trials(tracks: Sequence[TrialTrack], path: Path, title: str) -> Path:
    """Draw repeated trials: one true path per trial over the target (top view), and e(t)
    per trial (Angler Figs. 6–7).

    Args:
        tracks: the trials' tracks (:class:`~testbed.run.trials.TrialTrack`).
        path: PNG file to write.
        title: the figure's title.

    Returns:
        ``path``.
    """
    fig = Figure(figsize=(12.0, 5.5), layout="constrained")
    top, err = fig.subplots(1, 2, gridspec_kw={"width_ratios": (1.0, 1.3)})
    fig.suptitle(f"{title}\npaths and position error per trial")
    _top_view(top)
    drawn = [track for track in tracks if has_target(track.series)]
    if not drawn:
        no_data(top, "no pose target recorded")
        no_data(err, "no pose target recorded")
        return save(fig, path)
    colours = [f"C{k % 10}" for k in range(len(drawn))]
    _, first_target, _ = tracked_positions(drawn[0].series)
    top.plot(first_target[:, 1], first_target[:, 0], color=_TARGET, lw=1.2, ls="--", label="target")
    for track, colour in zip(drawn, colours, strict=True):
        s = track.series
        label = f"trial {track.trial} (seed {track.seed})"
        path_ned, _, _ = tracked_positions(s)
        top.plot(path_ned[:, 1], path_ned[:, 0], color=colour, lw=1.0, label=label)
        err.plot(s["t_s"], mission_error(s), color=colour, lw=1.0)
    legend_size = 8 if len(drawn) <= 10 else 6
    top.legend(loc="best", fontsize=legend_size, ncol=1 if len(drawn) <= 10 else 2)
    _error_axes(err, drawn[0].tolerance_m, drawn[0].settle_s)
    err.legend(loc="upper right", fontsize=8)
    return save(fig, path)
