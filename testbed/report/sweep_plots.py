"""PNG plots of a sweep, drawn from its ``results.csv`` (one row per run, see
:mod:`testbed.sweep`).

:func:`plot_ber_sweep` draws the plots of a sweep with a bit-error-rate axis (a grid key whose
last part is ``ber``, e.g. ``link.ber``), one line per value of the other grid keys:

- ``ber_vs_lag.png`` — command lag and command age (age of information) against BER, with the
  closed-form age curve of :func:`closed_form_age_s` over the simulated points;
- ``ber_vs_per.png`` — uplink and downlink packet error rate against BER, with the closed form
  :func:`closed_form_per` for each direction's mean frame length;
- ``ber_vs_tracking.png`` — the velocity tracking RMSE of each axis against BER.

:func:`plot_pair` draws any column against any other (``testbed plot``). Every line goes through
the per-x medians over seeds; error bars are the 95 % Student-t interval of the mean (what
``aggregate.csv`` holds). BER 0 cannot sit on a log axis: it is drawn one decade below the
smallest positive value, labelled ``0``, with a break mark on the axis.

Only successful rows (``status = ok``) are plotted; empty cells (a metric that does not apply)
are left out. Figures are built with :class:`matplotlib.figure.Figure` (Agg canvas), never
through ``pyplot``. A top-level module: only the CLI imports it; nothing here simulates.
"""

from __future__ import annotations

import csv
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from testbed.config import ConfigError
from testbed.run.metrics import aoi_periodic_closed_form

__all__ = [
    "ORDER_FRAME_BYTES",
    "Results",
    "ber_key",
    "closed_form_age_s",
    "closed_form_images_per_minute",
    "closed_form_per",
    "default_plot_name",
    "plot_ber_sweep",
    "plot_pair",
    "read_results",
]

DPI = 110
ORDER_FRAME_BYTES = 13
"""Length of the operator's move-order frame [B]: 7 B payload + 6 B framing (README)."""
REPLY_FRAME_BYTES = 60
"""Length of a reply frame with a 40-B image chunk [B] (REFERENCE §1.6)."""
CHUNK_BYTES = 40
"""Image bytes per reply in the shipped image scenario [B]."""
_META_COLUMNS = ("point", "seed", "status", "error")
_TRACKING_AXES = (("x", "m/s"), ("y", "m/s"), ("z", "m/s"), ("yaw", "rad/s"))


# --- reading ------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Results:
    """The successful rows of a ``results.csv``.

    Attributes:
        path: where it was read from, for messages.
        columns: every column, in file order.
        grid: the grid keys (the columns between ``seed`` and ``status``).
        rows: the rows with ``status = ok``, cells as the file's strings.
    """

    path: Path
    columns: tuple[str, ...]
    grid: tuple[str, ...]
    rows: tuple[dict[str, str], ...]

    def require(self, column: str, option: str) -> None:
        """Raise a one-line :class:`ConfigError` unless ``column`` exists.

        Raises:
            ConfigError: naming ``option`` and the column, listing the known columns.
        """
        if column not in self.columns:
            known = ", ".join(c for c in self.columns if c not in ("status", "error"))
            raise ConfigError(f"{self.path}: {option}: unknown column {column!r} (known: {known})")

    def numbers(self, column: str) -> np.ndarray:
        """``column`` of every row as floats; NaN for an empty or non-numeric cell."""
        return np.array([_number(row.get(column, "")) for row in self.rows], dtype=float)

    def labels(self, columns: Sequence[str]) -> list[str]:
        """Per row, ``key=value`` of ``columns`` joined by ``, `` (``""`` for no columns)."""
        return [", ".join(f"{_short(c)}={row[c]}" for c in columns) for row in self.rows]


def _number(cell: str) -> float:
    try:
        return float(cell)
    except ValueError:
        return math.nan


def _short(key: str) -> str:
    """``link.ipg_s`` → ``ipg_s``: the last part of a dotted key, for legends."""
    return key.rsplit(".", 1)[-1]


def read_results(results_csv: Path | str) -> Results:
    """Read a sweep's ``results.csv``.

    Raises:
        ConfigError: a missing file, or one without the ``point, seed, …, status, error`` head.
    """
    path = Path(results_csv)
    try:
        with path.open(encoding="utf-8", newline="") as handle:
            reader = csv.DictReader(handle)
            columns = tuple(reader.fieldnames or ())
            rows = tuple(row for row in reader if row.get("status") == "ok")
    except OSError as err:
        raise ConfigError(f"{path}: cannot read: {err.strerror}") from None
    if columns[:2] != ("point", "seed") or "status" not in columns:
        raise ConfigError(f"{path}: not a results.csv of testbed sweep (no point, seed, status)")
    grid = columns[2 : columns.index("status")]
    return Results(path, columns, grid, rows)


# --- closed forms ---------------------------------------------------------------------------------


def closed_form_per(ber: np.ndarray | float, frame_bytes: float) -> np.ndarray:
    """Packet error rate of a frame of ``frame_bytes`` under independent bit errors.

    A frame survives only if all its ``8·L`` bits do: ``PER = 1 − (1 − BER)^(8·L)``.

    Args:
        ber: bit error rate(s), each in [0, 1].
        frame_bytes: frame length on the air, framing included [B].

    Returns:
        PER, the shape of ``ber``.
    """
    log_survival = 8.0 * frame_bytes * np.log1p(-np.asarray(ber, dtype=float))
    return np.asarray(-np.expm1(log_survival), dtype=float)  # expm1: no 1 − (≈1) cancellation


def closed_form_age_s(
    ber: np.ndarray | float,
    period_s: float,
    delay_s: float,
    frame_bytes: float = ORDER_FRAME_BYTES,
) -> np.ndarray:
    """Mean age of the command a vehicle applies when orders go out every ``period_s``.

    Each order frame is delivered independently with probability ``q = (1 − BER)^(8·L)`` (all
    ``8·L`` bits intact; ``L = 13`` B for the move order). A delivered order is applied
    ``delay_s`` after the sticks were sampled; a lost one leaves the previous command in force
    until the next delivery, so the gaps between applications are ``K·T`` with ``K`` geometric.
    The renewal-reward argument of :mod:`testbed.run.metrics` gives ``E[age] = D + T(2 − q)/(2q)``
    (:func:`~testbed.run.metrics.aoi_periodic_closed_form`); at BER 0 it is ``D + T/2``.

    Args:
        ber: bit error rate(s), each in [0, 1).
        period_s: the order period ``T`` (the token-passing inter-packet gap) [s].
        delay_s: ``D``, sampling to application of a delivered order [s]; in the plots the
            measured mean command lag at BER 0 for the same gap.
        frame_bytes: the order frame length ``L`` [B].

    Returns:
        Mean age [s], the shape of ``ber``.
    """
    q = 1.0 - closed_form_per(ber, frame_bytes)
    ages = [aoi_periodic_closed_form(period_s, float(p), delay_s) for p in np.ravel(q)]
    return np.reshape(np.array(ages, dtype=float), np.shape(q))


def closed_form_images_per_minute(
    ber: np.ndarray | float,
    gap_s: float,
    chunks: int,
    *,
    selective_repeat: bool,
    order_bytes: float = ORDER_FRAME_BYTES,
    reply_bytes: float = REPLY_FRAME_BYTES,
) -> np.ndarray:
    """Images per minute over a token-passing link with one chunk per reply.

    One order goes out every ``gap_s`` (``T``); it survives with ``q_o = (1 − BER)^(8·L_o)``
    and the vehicle answers it with a reply that survives with ``q_r = (1 − BER)^(8·L_r)``.
    Selective repeat: a chunk is done in an exchange where both survive (``q = q_o·q_r``), so
    an image of ``n`` chunks takes ``n/q`` gaps on average (the order that acknowledges one
    image already fetches chunk 0 of the next): ``60·q / (n·T)``. Paper mode: the vehicle
    streams one chunk per order it receives, so an image takes ``n/q_o`` gaps, and it is whole
    only if all ``n`` replies survive: ``60·q_o·q_r^n / (n·T)``.

    Args:
        ber: bit error rate(s), each in [0, 1).
        gap_s: the inter-packet gap ``T`` [s].
        chunks: chunks per image ``n`` (image and its 2-B CRC over the chunk size).
        selective_repeat: the transfer mode.
        order_bytes: the order frame ``L_o`` [B] (13: a move).
        reply_bytes: the reply frame ``L_r`` [B] (60: with a 40-B chunk).

    Returns:
        Images per minute, the shape of ``ber``.
    """
    q_order = 1.0 - closed_form_per(ber, order_bytes)
    q_reply = 1.0 - closed_form_per(ber, reply_bytes)
    if selective_repeat:
        return np.asarray(60.0 * q_order * q_reply / (chunks * gap_s), dtype=float)
    return np.asarray(60.0 * q_order * q_reply**chunks / (chunks * gap_s), dtype=float)


# --- statistics and axes -----------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class _Line:
    """Per distinct x: the median, the mean and the half-width of its 95 % t interval."""

    x: np.ndarray
    median: np.ndarray
    mean: np.ndarray
    half: np.ndarray  # NaN with fewer than two values


def _line(x: np.ndarray, y: np.ndarray) -> _Line:
    from scipy import stats

    keep = np.isfinite(x) & np.isfinite(y)
    xs = np.unique(x[keep])
    med, mean, half = [], [], []
    for value in xs:
        ys = y[keep & (x == value)]
        med.append(float(np.median(ys)))
        mean.append(float(ys.mean()))
        n = ys.size
        sd = float(ys.std(ddof=1)) if n >= 2 else math.nan
        half.append(float(stats.t.ppf(0.975, n - 1)) * sd / math.sqrt(n) if n >= 2 else math.nan)
    return _Line(xs, np.array(med), np.array(mean), np.array(half))


@dataclass(frozen=True, slots=True)
class _LogAxis:
    """A log x axis on which 0 is drawn at ``zero_at`` (one decade below the smallest value)."""

    zero_at: float | None

    @classmethod
    def fit(cls, values: np.ndarray) -> _LogAxis | None:
        """A log axis for ``values`` if they are ≥ 0 and the positive ones span ≥ 2 decades."""
        finite = values[np.isfinite(values)]
        positive = finite[finite > 0]
        if finite.size == 0 or np.any(finite < 0) or positive.size < 2:
            return None
        if positive.max() / positive.min() < 100.0:
            return None
        has_zero = bool(np.any(finite == 0))
        return cls(10.0 ** (math.floor(math.log10(positive.min())) - 1) if has_zero else None)

    def place(self, x: np.ndarray) -> np.ndarray:
        """Where each value is drawn (0 → ``zero_at``)."""
        if self.zero_at is None:
            return x
        return np.where(x == 0, self.zero_at, x)

    def apply(self, ax: Axes) -> None:
        """Log scale; with a zero, its tick labelled ``0`` and a break mark after it."""
        ax.set_xscale("log")
        if self.zero_at is None:
            return
        ticks = [t for t in ax.get_xticks() if t > self.zero_at * 5]
        low, high = ax.get_xlim()
        ax.set_xticks(
            [self.zero_at, *ticks], ["0", *(f"$10^{{{math.log10(t):.0f}}}$" for t in ticks)]
        )
        ax.set_xlim(min(low, self.zero_at / 2), high)
        gap = self.zero_at * math.sqrt(10.0)
        for shared in ax.get_shared_x_axes().get_siblings(ax):
            for dx in (0.9, 1.1):
                shared.plot(
                    [gap * dx / 1.15, gap * dx * 1.15],
                    [-0.02, 0.02],
                    transform=shared.get_xaxis_transform(),
                    color="k",
                    lw=1.0,
                    clip_on=False,
                )


def _draw(
    ax: Axes,
    axis: _LogAxis | None,
    x: np.ndarray,
    y: np.ndarray,
    *,
    color: str,
    label: str | None,
) -> None:
    """Medians joined by a line, 95 % t intervals of the mean as bars (at the mean)."""
    line = _line(x, y)
    if line.x.size == 0:
        return
    xs = axis.place(line.x) if axis is not None else line.x
    ax.plot(xs, line.median, marker="o", ms=4, color=color, label=label)
    bars = np.isfinite(line.half)
    if bars.any():
        ax.errorbar(
            xs[bars],
            line.mean[bars],
            yerr=line.half[bars],
            fmt="none",
            capsize=3,
            lw=1.0,
            color=color,
        )


def _groups(results: Results, by: Sequence[str]) -> list[tuple[str, np.ndarray]]:
    """``(label, row mask)`` per distinct value of the ``by`` columns, in first-seen order."""
    labels = results.labels(by)
    seen = list(dict.fromkeys(labels))
    array = np.array(labels, dtype=object)
    return [(label, array == label) for label in seen]


def _save(fig: Figure, path: Path) -> Path:
    FigureCanvasAgg(fig)
    fig.savefig(path, dpi=DPI, metadata={"Software": None})
    return path


def _footnote(fig: Figure, text: str) -> None:
    """A grey line under every panel (constrained layout keeps room for it)."""
    fig.supxlabel(text, fontsize="small", color="0.3")


def _no_data(ax: Axes, what: str) -> None:
    ax.text(0.5, 0.5, f"no {what}", ha="center", va="center", transform=ax.transAxes, color="0.35")


_BARS_NOTE = "lines: medians over seeds; bars: 95 % t-interval of the mean"


# --- the BER plots ------------------------------------------------------------------------------


def ber_key(results: Results) -> str | None:
    """The grid key of the bit error rate (last dotted part ``ber``), or None."""
    return next((key for key in results.grid if _short(key) == "ber"), None)


def plot_ber_sweep(results_csv: Path | str, out_dir: Path | str) -> list[Path]:
    """Draw ``ber_vs_lag.png``, ``ber_vs_per.png`` and ``ber_vs_tracking.png`` of a BER sweep.

    One line per value of the other grid keys (e.g. the inter-packet gap). The age panel of
    ``ber_vs_lag.png`` carries, per line, the closed form :func:`closed_form_age_s` with
    ``T`` = the run's token-passing gap (the ``ipg_s`` metric, median over the line's runs),
    ``D`` = the mean of ``command_lag_s.mean`` over the line's runs at its smallest BER (0 in
    the shipped sweeps; the lag of a delivered order does not depend on BER) and ``L`` = the
    uplink's mean frame length (13 B, the move order). ``ber_vs_per.png`` carries
    :func:`closed_form_per` with ``L`` = each direction's median ``mean_frame_bytes``.

    Args:
        results_csv: the sweep's ``results.csv``.
        out_dir: where the PNGs go (created if missing).

    Returns:
        The written paths.

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
    axis = _LogAxis.fit(ber)
    others = [k for k in results.grid if k != key]
    groups = _groups(results, others)
    colours = [f"C{i % 10}" for i in range(len(groups))]
    paths = [
        _plot_lag(results, out / "ber_vs_lag.png", ber, axis, groups, colours),
        _plot_per(results, out / "ber_vs_per.png", ber, axis, groups, colours),
        _plot_tracking(results, out / "ber_vs_tracking.png", ber, axis, groups, colours),
    ]
    if "images.per_minute" in results.columns:
        paths.append(_plot_images(results, out / "ber_vs_images.png", ber, axis, groups, colours))
    return paths


def _ber_curve(ber: np.ndarray, axis: _LogAxis | None) -> np.ndarray:
    """Dense BERs for a closed-form curve over the positive range of ``ber``."""
    positive = ber[np.isfinite(ber) & (ber > 0)]
    if positive.size == 0:
        return np.array([0.0])
    if axis is None:
        return np.linspace(0.0, positive.max(), 200)
    return np.geomspace(positive.min(), positive.max(), 200)


def _closed_form_at_zero(ax: Axes, axis: _LogAxis | None, value: float, colour: str) -> None:
    """The closed form at BER 0: a short dashed bar at the zero position."""
    if axis is not None and axis.zero_at is not None:
        span = np.array([axis.zero_at / 1.6, axis.zero_at * 1.6])
        ax.plot(span, [value, value], ls="--", lw=1.2, color=colour)


def _title(fig: Figure, results: Results, what: str) -> None:
    fig.suptitle(f"{what} — {results.path.parent.name} ({len(results.rows)} runs ok)")


def _plot_lag(
    results: Results,
    path: Path,
    ber: np.ndarray,
    axis: _LogAxis | None,
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
        _draw(lag_ax, axis, ber[mask], 1000 * lag[mask], color=colour, label=label or None)
        _draw(age_ax, axis, ber[mask], 1000 * age[mask], color=colour, label=label or None)
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
            _no_data(ax, what)
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
    _footnote(fig, _BARS_NOTE + "; D = lag at the lowest BER, T = inter-packet gap")
    _title(fig, results, "BER vs command lag and age")
    return _save(fig, path)


def _plot_images(
    results: Results,
    path: Path,
    ber: np.ndarray,
    axis: _LogAxis | None,
    groups: list[tuple[str, np.ndarray]],
    colours: list[str],
) -> Path:
    """Images per minute (with :func:`closed_form_images_per_minute`) and image latency."""
    fig = Figure(figsize=(12.0, 4.8), layout="constrained")
    rate_ax, latency_ax = fig.subplots(1, 2, sharex=True)
    rate = results.numbers("images.per_minute")
    latency = results.numbers("images.latency_s.mean")
    gap = results.numbers("ipg_s")
    delivered = results.numbers("images.bytes_delivered")
    completed = results.numbers("images.completed")
    repeat = np.array([row.get("images.selective_repeat", "true") for row in results.rows])
    curve_ber = _ber_curve(ber, axis)
    for (label, mask), colour in zip(groups, colours, strict=True):
        _draw(rate_ax, axis, ber[mask], rate[mask], color=colour, label=label or None)
        _draw(latency_ax, axis, ber[mask], latency[mask], color=colour, label=label or None)
        some = mask & (completed > 0)
        sizes = delivered[some] / completed[some]
        t = gap[mask & np.isfinite(gap)]
        if sizes.size == 0 or t.size == 0:
            continue
        chunks = math.ceil((float(np.median(sizes)) + 2.0) / CHUNK_BYTES)
        selective = str(repeat[mask][0]).lower() != "false"
        curve = closed_form_images_per_minute(
            curve_ber, float(np.median(t)), chunks, selective_repeat=selective
        )
        rate_ax.plot(curve_ber, curve, ls="--", lw=1.2, color=colour)
        at_zero = float(
            closed_form_images_per_minute(
                0.0, float(np.median(t)), chunks, selective_repeat=selective
            )
        )
        _closed_form_at_zero(rate_ax, axis, at_zero, colour)
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
    _footnote(
        fig,
        _BARS_NOTE + "; dashed: 60·q/(nT) with selective repeat, 60·q_o·q_r^n/(nT) without "
        "(n chunks, gap T)",
    )
    _title(fig, results, "BER vs image feedback")
    return _save(fig, path)


def _plot_per(
    results: Results,
    path: Path,
    ber: np.ndarray,
    axis: _LogAxis | None,
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
            _draw(ax, axis, ber[mask], 100 * per[mask], color=colour, label=label or None)
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
            _no_data(ax, f"{direction} PER")
        which = "operator → vehicle" if direction == "uplink" else "vehicle → operator"
        ax.set_title(f"{direction} ({which}), mean frame {length:.0f} B")
        ax.set_xlabel("bit error rate")
        ax.set_ylabel("packet error rate [%]")
        ax.grid(True, which="major", alpha=0.3)
        ax.legend(fontsize="small")
    if axis is not None:
        axis.apply(axes[0])
    _footnote(fig, _BARS_NOTE + "; dashed: independent bit errors")
    _title(fig, results, "BER vs packet error rate")
    return _save(fig, path)


def _plot_tracking(
    results: Results,
    path: Path,
    ber: np.ndarray,
    axis: _LogAxis | None,
    groups: list[tuple[str, np.ndarray]],
    colours: list[str],
) -> Path:
    fig = Figure(figsize=(12.0, 7.5), layout="constrained")
    axes = fig.subplots(2, 2, sharex=True).ravel()
    for ax, (name, unit) in zip(axes, _TRACKING_AXES, strict=True):
        rmse = results.numbers(f"velocity_tracking_rmse.{name}")
        for (label, mask), colour in zip(groups, colours, strict=True):
            _draw(ax, axis, ber[mask], rmse[mask], color=colour, label=label or None)
        if not np.isfinite(rmse).any():
            _no_data(ax, f"{name} tracking error")
        ax.set_title(f"{name}: asked-for vs true body velocity")
        ax.set_ylabel(f"RMSE [{unit}]")
        ax.grid(True, which="major", alpha=0.3)
    for ax in axes[2:]:
        ax.set_xlabel("bit error rate")
    if axis is not None:
        axis.apply(axes[0])
    if any(label for label, _ in groups):
        axes[0].legend(title="grid", fontsize="small")
    _footnote(fig, _BARS_NOTE)
    _title(fig, results, "BER vs velocity tracking error")
    return _save(fig, path)


# --- any pair ---------------------------------------------------------------------------------


def default_plot_name(x: str, y: str) -> str:
    """``y_vs_x.png`` with anything but letters, digits, ``_ - .`` replaced by ``_``."""
    return re.sub(r"[^\w.-]", "_", f"{y}_vs_{x}") + ".png"


def plot_pair(
    results_csv: Path | str, x: str, y: str, hue: str | None, out_path: Path | str
) -> Path:
    """Scatter ``y`` against ``x`` over every successful run, with a median line per x.

    A numeric ``x`` whose positive values span two decades or more gets a log axis (0 drawn
    one decade below the smallest positive value); a non-numeric ``x`` (a thruster layout) is
    categorical, in first-seen order. With ``hue``, one colour and one median line per value.

    Raises:
        ConfigError: the file cannot be read, or ``x``, ``y`` or ``hue`` is not a column
            (naming it and listing the known ones), or ``y`` has no numeric value.
    """
    results = read_results(results_csv)
    for option, column in (("--x", x), ("--y", y), ("--hue", hue)):
        if column is not None:
            results.require(column, option)
    values = results.numbers(y)
    if not np.isfinite(values).any():
        raise ConfigError(f"{results.path}: --y: column {y!r} has no numeric value in ok rows")
    raw_x = [row[x] for row in results.rows]
    xs = results.numbers(x)
    ticks: list[str] = []
    if np.isnan(xs).any() and any(cell for cell in raw_x):
        ticks = list(dict.fromkeys(raw_x))  # categorical
        xs = np.array([ticks.index(cell) for cell in raw_x], dtype=float)
    axis = None if ticks else _LogAxis.fit(xs)
    fig = Figure(figsize=(8.0, 5.0), layout="constrained")
    ax = fig.subplots()
    groups = _groups(results, [hue] if hue else [])
    for index, (label, mask) in enumerate(groups):
        colour = f"C{index % 10}"
        placed = axis.place(xs[mask]) if axis is not None else xs[mask]
        ax.scatter(placed, values[mask], s=12, alpha=0.35, color=colour)
        _draw(ax, axis, xs[mask], values[mask], color=colour, label=label or None)
    if ticks:
        ax.set_xticks(range(len(ticks)), ticks)
    if axis is not None:
        axis.apply(ax)
    ax.set_xlabel(x)
    ax.set_ylabel(y)
    ax.grid(True, alpha=0.3)
    if hue:
        ax.legend(fontsize="small")
    ax.set_title(f"{y} vs {x} — {results.path.parent.name} ({len(results.rows)} runs ok)")
    _footnote(fig, "dots: runs; " + _BARS_NOTE)
    out = Path(out_path)
    out.parent.mkdir(parents=True, exist_ok=True)
    return _save(fig, out)
