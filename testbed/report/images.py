"""The image strip of a run: captured frames over what the operator received.

:func:`plot_image_strip` draws up to ``count`` completed images, spread evenly over the run: the
top row the vehicle's captures, the bottom row the operator's decoded images, each labelled with
its capture time, transfer latency, coded size and PSNR. Built on a bare
:class:`~matplotlib.figure.Figure` (Agg canvas), like :mod:`testbed.report.run_plots`.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from testbed.report.figures import DPI
from testbed.run.image_record import ImageLog, ReceivedImage, psnr_db

__all__ = ["plot_image_strip", "strip_selection"]


def strip_selection(received: list[ReceivedImage], count: int) -> list[ReceivedImage]:
    """Up to ``count`` of ``received``, evenly spread from the first to the last (in order)."""
    if count <= 0 or not received:
        return []
    if len(received) <= count:
        return list(received)
    picks = np.linspace(0, len(received) - 1, count).round().astype(int)
    return [received[i] for i in dict.fromkeys(picks.tolist())]


def plot_image_strip(log: ImageLog, path: Path, *, title: str, count: int = 6) -> Path:
    """Write ``path``: captured (top) and received (bottom) images of the run.

    Args:
        log: the run's image record.
        path: the PNG to write.
        title: figure title (scenario and seed).
        count: most image pairs shown.

    Returns:
        ``path``.
    """
    shown = [r for r in strip_selection(log.received, count) if r.number in log.captured]
    columns = max(1, len(shown))
    figure = Figure(figsize=(max(4.6, 2.2 * columns + 0.4), 4.6), dpi=DPI)  # room for the title
    FigureCanvasAgg(figure)
    figure.suptitle(f"{title}\nimages: captured (top) vs received (bottom)", fontsize=9)
    if not shown:
        axes = figure.add_subplot(1, 1, 1)
        axes.axis("off")
        axes.text(0.5, 0.5, "no image completed", ha="center", va="center")
        figure.savefig(path)
        return path
    grid = figure.subplots(2, columns, squeeze=False)
    for column, image in enumerate(shown):
        source = log.captured[image.number]
        top, bottom = grid[0][column], grid[1][column]
        top.imshow(source.pixels, cmap="gray", vmin=0, vmax=255, interpolation="nearest")
        bottom.imshow(image.pixels, cmap="gray", vmin=0, vmax=255, interpolation="nearest")
        psnr = psnr_db(source.pixels, image.pixels)
        if math.isnan(psnr):  # its bits decode to no picture (a budget below the header)
            quality = "undecodable"
        else:
            quality = "lossless" if math.isinf(psnr) else f"{psnr:.1f} dB"
        top.set_title(f"#{image.number} at {source.t_s:.1f} s", fontsize=8)
        bottom.set_title(
            f"+{image.t_s - source.t_s:.1f} s, {image.encoded_bytes} B, {quality}", fontsize=8
        )
        for axes in (top, bottom):
            axes.set_xticks([])
            axes.set_yticks([])
    figure.tight_layout()
    figure.savefig(path)
    return path
