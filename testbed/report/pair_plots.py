"""``testbed plot``: any column of a sweep's ``results.csv`` against any other, as a PNG.

:func:`plot_pair` scatters every successful run (``status = ok``) and joins the per-x medians
over seeds, with the 95 % Student-t interval of the mean as error bars, kept within the values
the metric can take (:func:`~testbed.run.metric_bounds.metric_bounds`); the lines and the log
x axis are :mod:`testbed.report.sweep_axes`'. :func:`default_plot_name` is the file name the
CLI writes when given none. The BER plots that ``testbed sweep`` draws are
:mod:`testbed.report.sweep_plots`. A top-level module: only the CLI imports it; nothing here
simulates.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from testbed.config import ConfigError
from testbed.report.figures import footnote, save
from testbed.report.sweep_axes import BARS_NOTE, LogAxis, draw
from testbed.report.sweep_results import read_results, sweep_label
from testbed.run.metric_bounds import metric_bounds

__all__ = ["default_plot_name", "plot_pair"]


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
            (naming it and listing the known ones), or ``y`` has no numeric value, or a cell
            of ``y`` is neither empty nor a number (naming its row).
    """
    results = read_results(results_csv)
    for option, column in (("--x", x), ("--y", y), ("--hue", hue)):
        if column is not None:
            results.require(column, option)
    values = results.metric(y, "--y")
    if not np.isfinite(values).any():
        raise ConfigError(f"{results.path}: --y: column {y!r} has no numeric value in ok rows")
    raw_x = [row[x] for row in results.rows]
    xs = results.numbers(x)
    ticks: list[str] = []
    if np.isnan(xs).any() and any(cell for cell in raw_x):
        ticks = list(dict.fromkeys(raw_x))  # categorical
        xs = np.array([ticks.index(cell) for cell in raw_x], dtype=float)
    axis = None if ticks else LogAxis.fit(xs)
    bounds = metric_bounds(y)  # intervals within the values y can take (≥ 0, [0, 1], …)
    fig = Figure(figsize=(8.0, 5.0), layout="constrained")
    ax = fig.subplots()
    groups = results.groups([hue] if hue else [])
    for index, (label, mask) in enumerate(groups):
        colour = f"C{index % 10}"
        placed = axis.place(xs[mask]) if axis is not None else xs[mask]
        ax.scatter(placed, values[mask], s=12, alpha=0.35, color=colour)
        draw(ax, axis, xs[mask], values[mask], color=colour, label=label or None, bounds=bounds)
    if ticks:
        ax.set_xticks(range(len(ticks)), ticks)
    if axis is not None:
        axis.apply(ax)
    ax.set_xlabel(x)
    ax.set_ylabel(y)
    ax.grid(True, alpha=0.3)
    if hue:
        ax.legend(fontsize="small")
    ax.set_title(f"{y} vs {x} — {sweep_label(results)} ({results.runs_label()})")
    footnote(fig, "dots: runs; " + BARS_NOTE)
    out = Path(out_path)
    if out.suffix == "":  # what matplotlib would write: the returned path is the real one
        out = out.with_name(out.name + ".png")
    out.parent.mkdir(parents=True, exist_ok=True)
    return save(fig, out)
