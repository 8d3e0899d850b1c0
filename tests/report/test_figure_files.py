"""A figure's PNG is written whole or not at all (``testbed.report.figures.save``).

The sweep's plots (``ber_vs_*.png``), ``trials.png`` and ``testbed plot``'s PNG are written
straight to their final names. A Ctrl-C while PIL encodes one (its writer loop is Python, so
the handler runs there) left a cut file — 54 bytes, which no PNG reader opens — in place of
the figure an earlier sweep or ``--resume`` had drawn. Here the interrupt is raised from
inside PIL's writer after it has written the PNG signature, as the handler would raise it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from matplotlib.figure import Figure
from PIL import Image, ImageFile

from testbed.report.figures import save


def figure(label: str) -> Figure:
    fig = Figure(figsize=(3.0, 2.0))
    ax = fig.subplots()
    ax.plot([0.0, 1.0, 2.0], [0.0, 1.0, 0.5], label=label)
    ax.legend()
    return fig


def test_an_interrupt_while_the_png_is_written_leaves_the_earlier_figure(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = tmp_path / "ber_vs_lag.png"
    save(figure("earlier"), path)
    earlier = path.read_bytes()
    with Image.open(path) as image:  # a PNG a reader opens: the independent check
        image.load()

    def cut_short(image: Any, fp: Any, tile: Any, bufsize: int = 0) -> None:
        fp.write(b"\x89PNG\r\n\x1a\n")  # what PIL writes first
        raise KeyboardInterrupt  # Ctrl-C lands in PIL's Python writer loop

    monkeypatch.setattr(ImageFile, "_save", cut_short)
    with pytest.raises(KeyboardInterrupt):
        save(figure("later"), path)
    assert path.read_bytes() == earlier
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ber_vs_lag.png"]  # no temporary


def test_a_figure_saved_twice_gives_the_same_bytes_under_its_own_name(tmp_path: Path) -> None:
    first, second = tmp_path / "a.png", tmp_path / "b.png"
    assert save(figure("x"), first) == first
    save(figure("x"), second)
    assert first.read_bytes() == second.read_bytes()  # no time stamp in the file
    assert first.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
