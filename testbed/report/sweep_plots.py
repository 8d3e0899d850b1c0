"""PNG plots of a sweep, drawn from its ``results.csv`` (one row per run, see
:mod:`testbed.sweep`; read by :mod:`testbed.report.sweep_results`).

:func:`plot_ber_sweep` draws the plots of a sweep with a bit-error-rate axis (a grid key whose
last part is ``ber``, e.g. ``link.ber``), one line per value of the other grid keys:

- ``ber_vs_lag.png`` — command lag and command age (age of information) against BER, with the
  closed-form age curve of :func:`~testbed.report.closed_forms.closed_form_age_s` over the
  simulated points;
- ``ber_vs_per.png`` — uplink and downlink packet error rate against BER, with the closed form
  :func:`~testbed.report.closed_forms.closed_form_per` for each direction's mean frame length;
- ``ber_vs_tracking.png`` — the velocity tracking RMSE of each axis against BER;
- ``ber_vs_mission.png`` (sweeps of supervised control) — mission completion time and final
  position error against BER;
- ``ber_vs_images.png`` (sweeps with images) — images per minute against BER with
  :func:`~testbed.report.closed_forms.closed_form_images_per_minute`, and image latency.

The closed forms (:mod:`testbed.report.closed_forms`) take what they need from the rows: frame
lengths from ``link.*.mean_frame_bytes``, gap from ``ipg_s``, chunk size and transfer mode from
``images.chunk_bytes`` and ``images.selective_repeat`` (a grid column, or the value
``testbed sweep`` records for every image run); the protocol's frame layouts fill in what a row
lacks (an older ``results.csv``: the default 40-B chunk, selective repeat).

Every line goes through the per-x medians over seeds; error bars are the 95 % Student-t
interval of the mean (what ``aggregate.csv`` holds); see :mod:`testbed.report.sweep_axes` for
the lines and the log BER axis, on which BER 0 is drawn one decade below the smallest positive
value. Any column against any other (``testbed plot``) is :mod:`testbed.report.pair_plots`.

Only successful rows (``status = ok``) are plotted; empty cells (a metric that does not apply)
are left out. A top-level module: only the CLI imports it; nothing here simulates.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from testbed.config import ConfigError
from testbed.protocol import DEFAULT_CHUNK_SIZE
from testbed.report.closed_forms import (
    ORDER_FRAME_BYTES,
    closed_form_age_s,
    closed_form_images_per_minute,
    closed_form_per,
    image_chunks,
    reply_frame_bytes,
)
from testbed.report.figures import footnote, note, save
from testbed.report.sweep_axes import BARS_NOTE, LogAxis, draw
from testbed.report.sweep_results import Results, read_results, short_key, sweep_label

__all__ = [
    "ImageRateModel",
    "ber_key",
    "image_rate_model",
    "plot_ber_sweep",
]

_TRACKING_AXES = (("x", "m/s"), ("y", "m/s"), ("z", "m/s"), ("yaw", "rad/s"))
NON_NEGATIVE = (0.0, math.inf)
"""Bounds of the plotted quantities that cannot be negative (lags, ages, counts, rates, RMS
errors; :func:`~testbed.run.metric_bounds.metric_bounds`): their error bars stop at 0."""
draw_non_negative = functools.partial(draw, bounds=NON_NEGATIVE)
""":func:`~testbed.report.sweep_axes.draw` of a quantity that cannot be negative (every
quantity of the BER plots: lags, ages, rates, RMS errors, times)."""


# --- the BER plots ------------------------------------------------------------------------------


def ber_key(results: Results) -> str | None:
    """The grid key of the bit error rate (last dotted part ``ber``), or None."""
    return next((key for key in results.grid if short_key(key) == "ber"), None)


def plot_ber_sweep(results_csv: Path | str, out_dir: Path | str) -> list[Path]:
    """Draw ``ber_vs_lag.png``, ``ber_vs_per.png``, ``ber_vs_tracking.png`` (and
    ``ber_vs_images.png``, ``ber_vs_mission.png`` when the rows have those metrics) of a BER
    sweep; a plot none of whose metrics has a value in an ok row (every run failed, or the
    scenario has no such metric: tracking under autonomy) is not drawn.

    One line per value of the other grid keys (e.g. the inter-packet gap). The age panel of
    ``ber_vs_lag.png`` carries, per line, the closed form :func:`closed_form_age_s` with
    ``T`` = the run's token-passing gap (the ``ipg_s`` metric, median over the line's runs),
    ``D`` = the mean of ``command_lag_s.mean`` over the line's runs at its smallest BER (0 in
    the shipped sweeps; the lag of a delivered order does not depend on BER) and ``L`` = the
    uplink's mean frame length (13 B, the move order). ``ber_vs_per.png`` carries
    :func:`closed_form_per` with ``L`` = each direction's median ``mean_frame_bytes`` (the
    frames' own bytes: bit errors in a modem's packet padding cost no frame).

    Args:
        results_csv: the sweep's ``results.csv``.
        out_dir: where the PNGs go (created if missing).

    Returns:
        The written paths (none when every run failed).

    Raises:
        ConfigError: the file cannot be read, or has no BER grid key.
    """
    results = read_results(results_csv)
    key = ber_key(results)
    if key is None:
        raise ConfigError(f"{results.path}: no BER grid key (grid: {', '.join(results.grid)})")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    ber = results.numbers(key)
    axis = LogAxis.fit(ber)
    others = [k for k in results.grid if k != key]
    groups = results.groups(others)
    colours = [f"C{i % 10}" for i in range(len(groups))]
    plots = (
        (("command_lag_s.mean", "command_age_s.mean"), "ber_vs_lag.png", _plot_lag),
        (("link.uplink.per", "link.downlink.per"), "ber_vs_per.png", _plot_per),
        (
            tuple(f"velocity_tracking_rmse.{a}" for a, _ in _TRACKING_AXES),
            "ber_vs_tracking.png",
            _plot_tracking,
        ),
        (("images.per_minute",), "ber_vs_images.png", _plot_images),
        (("mission.completion_s",), "ber_vs_mission.png", _plot_mission),
    )
    paths = []
    for columns, name, plot in plots:  # a plot with nothing to draw is not drawn
        if any(np.isfinite(results.numbers(c)).any() for c in columns if c in results.columns):
            paths.append(plot(results, out / name, ber, axis, groups, colours))
    return paths


def _plot_mission(
    results: Results,
    path: Path,
    ber: np.ndarray,
    axis: LogAxis | None,
    groups: list[tuple[str, np.ndarray]],
    colours: list[str],
) -> Path:
    """Supervised control: when the last goal was reached, and the final position error."""
    fig = Figure(figsize=(12.0, 4.8), layout="constrained")
    done_ax, error_ax = fig.subplots(1, 2, sharex=True)
    done = results.numbers("mission.completion_s")
    final = results.numbers("mission.position_error_m.final")
    for (label, mask), colour in zip(groups, colours, strict=True):
        draw_non_negative(done_ax, axis, ber[mask], done[mask], color=colour, label=label or None)
        draw_non_negative(error_ax, axis, ber[mask], final[mask], color=colour, label=label or None)
    done_ax.set_title("last goal reached")
    done_ax.set_ylabel("mission completion [s]")
    error_ax.set_title("final position error")
    error_ax.set_ylabel("|truth − target| [m]")
    for ax in (done_ax, error_ax):
        ax.set_xlabel("bit error rate")
        ax.grid(True, which="major", alpha=0.3)
    if axis is not None:
        axis.apply(done_ax)
    if any(label for label, _ in groups):
        done_ax.legend(title="grid", fontsize="small")
    footnote(fig, BARS_NOTE + "; a lost GoTo or its reply costs one more inter-packet gap")
    _title(fig, results, "BER vs supervised control")
    return save(fig, path)


def _ber_curve(ber: np.ndarray, axis: LogAxis | None) -> np.ndarray:
    """Dense BERs for a closed-form curve over the positive range of ``ber``."""
    positive = ber[np.isfinite(ber) & (ber > 0)]
    if positive.size == 0:
        return np.array([0.0])
    if axis is None:
        return np.linspace(0.0, positive.max(), 200)
    return np.geomspace(positive.min(), positive.max(), 200)


def _closed_form_at_zero(ax: Axes, axis: LogAxis | None, value: float, colour: str) -> None:
    """The closed form at BER 0: a short dashed bar at the zero position."""
    if axis is not None and axis.zero_at is not None:
        span = np.array([axis.zero_at / 1.6, axis.zero_at * 1.6])
        ax.plot(span, [value, value], ls="--", lw=1.2, color=colour)


def _title(fig: Figure, results: Results, what: str) -> None:
    """The figure's title (the sweep, its runs, the failed ones' grid values) and, on every
    panel, a red × at the foot of the axis at each BER where a run failed (no metric to draw
    there, but not to be hidden)."""
    failed = _failed_bers(results)
    marks = " (×: a failed run)" if failed.size else ""
    fig.suptitle(f"{what} — {sweep_label(results)} ({results.runs_label()}){marks}")
    if not failed.size:
        return
    for ax in fig.axes:
        ax.plot(
            failed, np.zeros_like(failed), "x", color="tab:red", ms=8, mew=1.8,
            transform=ax.get_xaxis_transform(), clip_on=False,
        )  # fmt: skip


def _failed_bers(results: Results) -> np.ndarray:
    """Where on the BER axis runs failed: the failed rows' BER, placed as the plots place the
    ok rows' (a BER of 0 one decade below the smallest on a log axis)."""
    key = ber_key(results)
    if key is None or not results.failed:
        return np.zeros(0)
    values = results.failed_numbers(key)
    values = np.unique(values[np.isfinite(values)])
    axis = LogAxis.fit(results.numbers(key))
    return values if axis is None else axis.place(values)


def _plot_lag(
    results: Results,
    path: Path,
    ber: np.ndarray,
    axis: LogAxis | None,
    groups: list[tuple[str, np.ndarray]],
    colours: list[str],
) -> Path:
    fig = Figure(figsize=(12.0, 4.8), layout="constrained")
    lag_ax, age_ax = fig.subplots(1, 2, sharex=True)
    lag = results.numbers("command_lag_s.mean")
    age = results.numbers("command_age_s.mean")
    period = results.numbers("ipg_s")
    frame = results.numbers("link.uplink.mean_frame_bytes")
    frame_bytes = float(np.nanmedian(frame)) if np.isfinite(frame).any() else ORDER_FRAME_BYTES
    curve_ber = _ber_curve(ber, axis)
    for (label, mask), colour in zip(groups, colours, strict=True):
        draw_non_negative(
            lag_ax, axis, ber[mask], 1000 * lag[mask], color=colour, label=label or None
        )
        draw_non_negative(
            age_ax, axis, ber[mask], 1000 * age[mask], color=colour, label=label or None
        )
        ok = mask & np.isfinite(lag) & np.isfinite(ber)
        t = period[mask & np.isfinite(period)]
        if not ok.any() or t.size == 0:
            continue
        low = ber[ok].min()
        delay = float(lag[ok & (ber == low)].mean())
        t_s = float(np.median(t))
        curve = closed_form_age_s(curve_ber, t_s, delay, frame_bytes)
        age_ax.plot(curve_ber, 1000 * curve, ls="--", lw=1.2, color=colour)
        _closed_form_at_zero(age_ax, axis, 1000 * float(closed_form_age_s(0.0, t_s, delay)), colour)
        lag_ax.axhline(1000 * delay, ls=":", lw=0.8, color=colour)
    for ax, what in ((lag_ax, "command lag"), (age_ax, "command age (AoI)")):
        if not np.isfinite(lag if ax is lag_ax else age).any():
            note(ax, f"no {what}")
        ax.set_ylabel(f"mean {what} [ms]")
        ax.set_xlabel("bit error rate")
        ax.grid(True, which="major", alpha=0.3)
    if np.isfinite(lag).any():  # from 0, so a lag that does not move with BER reads flat
        lag_ax.set_ylim(0.0, 1.25 * 1000 * float(np.nanmax(lag)))
    lag_ax.set_title("command lag of delivered commands (dotted: D)")
    age_ax.plot([], [], "k--", lw=1.2, label="closed form")
    age_ax.set_title(
        f"command age; dashed: D + T(2−q)/(2q), q = (1−BER)^(8·{frame_bytes:.0f})",
    )
    if axis is not None:
        axis.apply(lag_ax)
    if any(label for label, _ in groups):
        age_ax.legend(title="grid", fontsize="small")
    footnote(fig, BARS_NOTE + "; D = lag at the lowest BER, T = inter-packet gap")
    _title(fig, results, "BER vs command lag and age")
    return save(fig, path)


@dataclass(frozen=True, slots=True)
class ImageRateModel:
    """The closed form of one line of ``ber_vs_images.png`` and what it is built from.

    Attributes:
        gap_s: the inter-packet gap ``T``: median ``ipg_s`` of the line's runs [s].
        chunks: chunks per image ``n``: the median completed image (``images.bytes_delivered``
            over ``images.completed``) and its CRC over ``chunk_bytes``.
        chunk_bytes: image bytes per reply [B], from ``images.chunk_bytes``.
        selective_repeat: the transfer mode, from ``images.selective_repeat``.
    """

    gap_s: float
    chunks: int
    chunk_bytes: int
    selective_repeat: bool

    @property
    def reply_bytes(self) -> int:
        """The reply frame ``L_r`` on the air [B] (:func:`reply_frame_bytes`)."""
        return reply_frame_bytes(self.chunk_bytes)

    def per_minute(self, ber: np.ndarray | float) -> np.ndarray:
        """Images per minute at ``ber`` (:func:`closed_form_images_per_minute`)."""
        return closed_form_images_per_minute(
            ber,
            self.gap_s,
            self.chunks,
            selective_repeat=self.selective_repeat,
            order_bytes=ORDER_FRAME_BYTES,
            reply_bytes=self.reply_bytes,
        )


def image_rate_model(results: Results, mask: np.ndarray) -> ImageRateModel | None:
    """The image-rate closed form of the rows in ``mask`` (one line of the plot).

    The chunk size is the rows' ``images.chunk_bytes`` (median; the protocol's default chunk
    when no row has one), the mode the first row's ``images.selective_repeat`` (selective
    repeat when absent).

    Args:
        results: the sweep's rows.
        mask: which rows make the line.

    Returns:
        The model, or None when no row in ``mask`` completed an image or has a gap, or a row's
        reply does not fit its gap (``reply_fits_gap`` false: the closed form assumes each
        reply is in before the next order leaves).
    """
    if any(results.rows[i].get("reply_fits_gap") == "false" for i in np.flatnonzero(mask)):
        return None
    delivered = results.numbers("images.bytes_delivered")
    completed = results.numbers("images.completed")
    gap = results.numbers("ipg_s")
    some = mask & (completed > 0)
    sizes = delivered[some] / completed[some]
    t = gap[mask & np.isfinite(gap)]
    if sizes.size == 0 or t.size == 0:
        return None
    cells = results.numbers("images.chunk_bytes")[mask]
    known = cells[np.isfinite(cells)]
    chunk_bytes = round(float(np.median(known))) if known.size else DEFAULT_CHUNK_SIZE
    first = results.rows[int(np.flatnonzero(mask)[0])]
    selective = str(first.get("images.selective_repeat", "true")).lower() != "false"
    chunks = image_chunks(float(np.median(sizes)), chunk_bytes)
    return ImageRateModel(float(np.median(t)), chunks, chunk_bytes, selective)


def _plot_images(
    results: Results,
    path: Path,
    ber: np.ndarray,
    axis: LogAxis | None,
    groups: list[tuple[str, np.ndarray]],
    colours: list[str],
) -> Path:
    """Images per minute (with :func:`image_rate_model`) and image latency."""
    fig = Figure(figsize=(12.0, 4.8), layout="constrained")
    rate_ax, latency_ax = fig.subplots(1, 2, sharex=True)
    rate = results.numbers("images.per_minute")
    latency = results.numbers("images.latency_s.mean")
    curve_ber = _ber_curve(ber, axis)
    for (label, mask), colour in zip(groups, colours, strict=True):
        draw_non_negative(rate_ax, axis, ber[mask], rate[mask], color=colour, label=label or None)
        draw_non_negative(
            latency_ax, axis, ber[mask], latency[mask], color=colour, label=label or None
        )
        model = image_rate_model(results, mask)
        if model is None:
            continue
        rate_ax.plot(curve_ber, model.per_minute(curve_ber), ls="--", lw=1.2, color=colour)
        _closed_form_at_zero(rate_ax, axis, float(model.per_minute(0.0)), colour)
    rate_ax.plot([], [], "k--", lw=1.2, label="closed form")
    rate_ax.set_title("images completed per minute")
    rate_ax.set_ylabel("images / min")
    latency_ax.set_title("capture to complete, mean")
    latency_ax.set_ylabel("image latency [s]")
    for ax in (rate_ax, latency_ax):
        ax.set_xlabel("bit error rate")
        ax.grid(True, which="major", alpha=0.3)
    if axis is not None:
        axis.apply(rate_ax)
    rate_ax.legend(title="grid", fontsize="small")
    footnote(
        fig,
        BARS_NOTE + "; dashed: 60·q/(nT) selective repeat, 60·q_o·q_r^n/(nT) without (n "
        "chunks, gap T), not where replies outlast the gap",
    )
    _title(fig, results, "BER vs image feedback")
    return save(fig, path)


def _plot_per(
    results: Results,
    path: Path,
    ber: np.ndarray,
    axis: LogAxis | None,
    groups: list[tuple[str, np.ndarray]],
    colours: list[str],
) -> Path:
    fig = Figure(figsize=(12.0, 4.8), layout="constrained")
    axes = fig.subplots(1, 2, sharex=True, sharey=True)
    curve_ber = _ber_curve(ber, axis)
    for ax, direction in zip(axes, ("uplink", "downlink"), strict=True):
        per = results.numbers(f"link.{direction}.per")
        frame = results.numbers(f"link.{direction}.mean_frame_bytes")
        for (label, mask), colour in zip(groups, colours, strict=True):
            draw(
                ax,
                axis,
                ber[mask],
                100 * per[mask],
                color=colour,
                label=label or None,
                bounds=(0.0, 100.0),
            )
        if np.isfinite(frame).any():
            length = float(np.nanmedian(frame))
            ax.plot(
                curve_ber,
                100 * closed_form_per(curve_ber, length),
                "k--",
                lw=1.2,
                label=f"1 − (1 − BER)^(8·{length:.0f})",
            )
            _closed_form_at_zero(ax, axis, 0.0, "k")
        else:
            length = math.nan
        if not np.isfinite(per).any():
            note(ax, f"no {direction} PER")
        which = "operator → vehicle" if direction == "uplink" else "vehicle → operator"
        ax.set_title(f"{direction} ({which}), mean frame {length:.0f} B")
        ax.set_xlabel("bit error rate")
        ax.set_ylabel("packet error rate [%]")
        ax.grid(True, which="major", alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize="small")
    if axis is not None:
        axis.apply(axes[0])
    footnote(fig, BARS_NOTE + " (within 0–100 %); dashed: independent bit errors")
    _title(fig, results, "BER vs packet error rate")
    return save(fig, path)


def _plot_tracking(
    results: Results,
    path: Path,
    ber: np.ndarray,
    axis: LogAxis | None,
    groups: list[tuple[str, np.ndarray]],
    colours: list[str],
) -> Path:
    fig = Figure(figsize=(12.0, 7.5), layout="constrained")
    axes = fig.subplots(2, 2, sharex=True).ravel()
    for ax, (name, unit) in zip(axes, _TRACKING_AXES, strict=True):
        rmse = results.numbers(f"velocity_tracking_rmse.{name}")
        for (label, mask), colour in zip(groups, colours, strict=True):
            draw_non_negative(ax, axis, ber[mask], rmse[mask], color=colour, label=label or None)
        if not np.isfinite(rmse).any():
            note(ax, f"no {name} tracking error")
        ax.set_title(f"{name}: asked-for vs true body velocity")
        ax.set_ylabel(f"RMSE [{unit}]")
        ax.grid(True, which="major", alpha=0.3)
    for ax in axes[2:]:
        ax.set_xlabel("bit error rate")
    if axis is not None:
        axis.apply(axes[0])
    if any(label for label, _ in groups):
        axes[0].legend(title="grid", fontsize="small")
    footnote(fig, BARS_NOTE)
    _title(fig, results, "BER vs velocity tracking error")
    return save(fig, path)
