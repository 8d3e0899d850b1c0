"""What every report figure shares: the resolution, saving, and the grey notes on panels.

Figures are built with :class:`matplotlib.figure.Figure` directly on an Agg canvas, never
through ``pyplot``, so no global figure state is touched.
"""

from __future__ import annotations

from pathlib import Path

from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from testbed.run.atomic import replace_atomically

__all__ = ["DPI", "footnote", "no_data", "note", "save"]

DPI = 110
"""Resolution of every PNG [dots per inch]."""


def save(fig: Figure, path: Path) -> Path:
    """Write ``fig`` as a PNG at :data:`DPI` (no software stamp, so equal figures give equal
    bytes) and return ``path``. The PNG is written whole or not at all (under a temporary
    name, then renamed): a Ctrl-C while it is encoded leaves ``path`` as it was, never cut."""
    FigureCanvasAgg(fig)

    def write(tmp: Path) -> None:
        fig.savefig(tmp, format="png", dpi=DPI, metadata={"Software": None})

    return replace_atomically(write, path)


def note(ax: Axes, text: str) -> None:
    """Grey text in the middle of ``ax`` (for a panel with nothing to draw)."""
    ax.text(0.5, 0.5, text, ha="center", va="center", transform=ax.transAxes, color="0.35")


def no_data(ax: Axes, text: str) -> None:
    """:func:`note` ``text`` on a panel that has no axes to show: its ticks are removed."""
    note(ax, text)
    ax.set_xticks([])
    ax.set_yticks([])


def footnote(fig: Figure, text: str) -> None:
    """A grey line under every panel (constrained layout keeps room for it)."""
    fig.supxlabel(text, fontsize="small", color="0.3")
