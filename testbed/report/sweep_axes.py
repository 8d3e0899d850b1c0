"""How the sweep plots draw a metric against a grid key: per-x lines and the log BER axis.

:func:`draw` joins the per-x medians over seeds with a line and puts the 95 % Student-t
interval of the mean as error bars at the means (:func:`line` computes them; the same interval
as ``aggregate.csv``, kept within the quantity's bounds when it has some: a PER's in
[0, 100] %). :class:`LogAxis` is a log x axis on which 0 can sit: one decade below the
smallest positive value, labelled ``0``, with a break mark on the axis.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from matplotlib.axes import Axes

from testbed.run.metrics import mean_ci95

__all__ = ["BARS_NOTE", "Line", "LogAxis", "draw", "line"]

BARS_NOTE = "lines: medians over seeds; bars: 95 % t-interval of the mean"
"""The footnote that says what :func:`draw` draws (every sweep plot carries it)."""


@dataclass(frozen=True, slots=True)
class Line:
    """Per distinct x: the median, the mean and its 95 % t interval.

    Attributes:
        x: the distinct finite x values, ascending.
        median: median of y per x.
        mean: mean of y per x.
        low: low end of the 95 % t interval of the mean per x (:func:`mean_ci95`); NaN with
            fewer than two values.
        high: its high end, likewise.
    """

    x: np.ndarray
    median: np.ndarray
    mean: np.ndarray
    low: np.ndarray
    high: np.ndarray


def line(x: np.ndarray, y: np.ndarray, bounds: tuple[float, float] | None = None) -> Line:
    """The :class:`Line` of the pairs where both ``x`` and ``y`` are finite; intervals within
    ``bounds`` (the values ``y`` can take) when given."""
    keep = np.isfinite(x) & np.isfinite(y)
    xs = np.unique(x[keep])
    med, mean, low, high = [], [], [], []
    for value in xs:
        ys = y[keep & (x == value)]
        med.append(float(np.median(ys)))
        mean.append(float(ys.mean()))
        interval = mean_ci95(ys, bounds)
        low.append(interval[0])
        high.append(interval[1])
    return Line(xs, np.array(med), np.array(mean), np.array(low), np.array(high))


@dataclass(frozen=True, slots=True)
class LogAxis:
    """A log x axis on which 0 is drawn at ``zero_at`` (one decade below the smallest value)."""

    zero_at: float | None

    @classmethod
    def fit(cls, values: np.ndarray) -> LogAxis | None:
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


def draw(
    ax: Axes,
    axis: LogAxis | None,
    x: np.ndarray,
    y: np.ndarray,
    *,
    color: str,
    label: str | None,
    bounds: tuple[float, float] | None = None,
) -> None:
    """Medians joined by a line, 95 % t intervals of the mean as bars (at the mean), within
    ``bounds`` (the values ``y`` can take, e.g. ``(0, 100)`` for a percentage) when given."""
    stats = line(x, y, bounds)
    if stats.x.size == 0:
        return
    xs = axis.place(stats.x) if axis is not None else stats.x
    ax.plot(xs, stats.median, marker="o", ms=4, color=color, label=label)
    bars = np.isfinite(stats.low)
    if bars.any():
        mean = stats.mean[bars]
        ax.errorbar(
            xs[bars],
            mean,
            yerr=np.vstack([mean - stats.low[bars], stats.high[bars] - mean]),
            fmt="none",
            capsize=3,
            lw=1.0,
            color=color,
        )
