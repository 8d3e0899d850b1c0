"""The link timeline of a run (the narrow-band paper's Fig. 4): ``timeline.png``.

:func:`plot_timeline` draws one row per sending node and a bar per transmitted packet, from its
``tx_start`` to its ``tx_end`` and as tall as the packet is long, coloured and hatched by what
became of it (:func:`testbed.channel.transmissions`, :class:`testbed.channel.FrameOutcome`);
dropped frames are crosses. Long runs show a window from the first transmission
(:func:`timeline_window`).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.collections import PolyCollection
from matplotlib.colors import to_rgb
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

from testbed.channel import (
    RECEPTION_OUTCOMES,
    EventKind,
    FrameOutcome,
    LinkEvent,
    Trace,
    Transmission,
)
from testbed.channel.outcomes import (
    TransmissionColumns,
    frame_outcome_columns,
    outcome_of_rank,
    transmission_columns,
)
from testbed.report.figures import no_data, note, save

__all__ = ["TIMELINE_MAX_PACKETS", "TIMELINE_WINDOW_S", "plot_timeline", "timeline_window"]

TIMELINE_WINDOW_S = 20.0
"""Default longest window of the timeline, from the first transmission [s]."""
TIMELINE_MAX_PACKETS = 300
"""Default most transmissions the timeline draws (its window shrinks to fit)."""


_STYLE: dict[FrameOutcome, tuple[str, str, str]] = {  # colour, hatch, legend label
    FrameOutcome.DELIVERED: ("tab:blue", "", "delivered"),
    FrameOutcome.CORRUPTED: ("tab:orange", "////", "corrupted (bit errors)"),
    FrameOutcome.COLLIDED: ("tab:purple", "xxxx", "collided"),
    FrameOutcome.OUTAGE: ("tab:cyan", "....", "lost in outage"),
    FrameOutcome.OUT_OF_RANGE: ("tab:brown", "\\\\\\\\", "out of range"),
    FrameOutcome.PENDING: ("0.75", "", "in flight at end of run"),
}
_DROP_COLOUR = "tab:red"
_NODE_ORDER = ("operator", "vehicle")


def _row_title(src: str, dsts: set[str], outcomes: Mapping[FrameOutcome, int]) -> str:
    arrow = f"{src} → {', '.join(sorted(dsts)) or '?'}"
    counts = {o: outcomes.get(o, 0) for o in FrameOutcome if outcomes.get(o, 0)}
    tally = ", ".join(f"{n} {o.value.replace('_', ' ')}" for o, n in counts.items())
    total = sum(counts.values())
    return f"{arrow}:  {total} frames in the run ({tally})" if total else arrow


def _draw_row(ax: Axes, sent: list[Transmission], dropped: list[LinkEvent]) -> set[FrameOutcome]:
    """One direction's bars and drop crosses; returns the outcomes drawn."""
    drawn = set()
    for outcome, (colour, hatch, _) in _STYLE.items():
        group = [x for x in sent if x.outcome is outcome]
        if group:
            drawn.add(outcome)
            boxes = [
                ((x.start_s, 0.0), (x.start_s, x.size_bytes), (x.end_s, x.size_bytes),
                 (x.end_s, 0.0))
                for x in group
            ]  # fmt: skip
            bars = PolyCollection(
                boxes, facecolors=colour, edgecolors=_darker(colour), linewidths=0.6, hatch=hatch
            )
            bars.set_hatchcolor("white")
            ax.add_collection(bars, autolim=False)
    if dropped:
        drawn.add(FrameOutcome.DROPPED)
        times = [e.t_s for e in dropped]
        sizes = [e.size_bytes for e in dropped]
        ax.scatter(times, sizes, marker="x", s=40, color=_DROP_COLOUR, zorder=3)
    ax.set_ylabel("PDU size [B]")
    top = max([x.size_bytes for x in sent] + [e.size_bytes for e in dropped] + [1])
    ax.set_ylim(0.0, 1.12 * top)
    ax.grid(axis="y", alpha=0.3)
    if not drawn:
        note(ax, "nothing sent in this window")
    return drawn


def _darker(colour: str) -> tuple[float, float, float]:
    """``colour`` at 60 % brightness: bar outlines that separate adjacent packets."""
    r, g, b = to_rgb(colour)
    return (0.6 * r, 0.6 * g, 0.6 * b)


def _legend_handle(outcome: FrameOutcome) -> Patch | Line2D:
    if outcome is FrameOutcome.DROPPED:
        label = "dropped (transmit FIFO full)"
        return Line2D([], [], marker="x", linestyle="", color=_DROP_COLOUR, label=label)
    colour, hatch, label = _STYLE[outcome]
    edge = _darker(colour)
    return Patch(facecolor=colour, edgecolor=edge, hatch=hatch, hatchcolor="white", label=label)


def timeline_window(
    sent: Sequence[Transmission] | TransmissionColumns,
    *,
    window_s: float = TIMELINE_WINDOW_S,
    max_packets: int = TIMELINE_MAX_PACKETS,
) -> tuple[float, float]:
    """The time window :func:`plot_timeline` draws.

    It starts at the first transmission and lasts ``window_s``, cut short at the start of the
    first transmission beyond ``max_packets``, and never past the last transmission's end.

    Args:
        sent: the transmissions, in order of start time (:func:`transmissions`, or
            :func:`~testbed.channel.trace.transmission_columns`).
        window_s: longest window [s].
        max_packets: most transmissions starting in the window.

    Returns:
        ``(t0, t1)`` [s]; ``(0.0, 0.0)`` when nothing was sent.
    """
    if not len(sent):
        return 0.0, 0.0
    if isinstance(sent, TransmissionColumns):
        t0, t_end = float(sent.start_s[0]), float(sent.end_s.max())
        cut = float(sent.start_s[max_packets]) if len(sent) > max_packets else math.inf
    else:
        t0, t_end = sent[0].start_s, max(x.end_s for x in sent)
        cut = sent[max_packets].start_s if len(sent) > max_packets else math.inf
    return t0, min(t_end, t0 + window_s, cut)  # cut: where the first packet left out starts


def plot_timeline(
    events: Iterable[LinkEvent],
    path: Path,
    *,
    title: str,
    window_s: float = TIMELINE_WINDOW_S,
    max_packets: int = TIMELINE_MAX_PACKETS,
) -> Path:
    """Draw the link timeline: one row per sending node, a bar per transmitted packet.

    Each bar spans ``tx_start`` → ``tx_end`` and is as tall as the packet [B]; its colour and
    hatch say what became of it. Dropped frames are red crosses at their enqueue time and size.
    Only a window from the first transmission ``t0`` is drawn: ``window_s`` long, or shorter
    so that at most ``max_packets`` transmissions start in it (fast links send hundreds a
    second); the figure title states it. The row titles count every frame of the run.

    Args:
        events: link events (a :class:`~testbed.channel.Trace` or any iterable of them).
        path: PNG file to write.
        title: the run's title (first line of the figure title).
        window_s: longest window drawn [s], > 0.
        max_packets: most transmissions drawn, ≥ 1.

    Returns:
        ``path``.

    Raises:
        ValueError: ``window_s`` ≤ 0 or ``max_packets`` < 1.
    """
    if not window_s > 0.0:
        raise ValueError(f"window_s must be > 0, got {window_s}")
    if max_packets < 1:
        raise ValueError(f"max_packets must be ≥ 1, got {max_packets}")
    trace = Trace.of(events)
    sent = transmission_columns(trace)  # arrays: only the window's packets become objects
    frames, ranks = frame_outcome_columns(trace)
    columns = trace.columns()
    names = columns.names
    _, last = np.unique(columns.frame_id[::-1], return_index=True)  # by frame id
    src_of = columns.src[::-1][last]  # each frame's sender (its last event's src)
    rank_of = ranks[np.argsort(frames, kind="stable")]  # each frame's outcome, by frame id
    received = np.isin(columns.kind, [columns.code_of(k) for k in RECEPTION_OUTCOMES])
    heard = np.unique(columns.src[received].astype(np.int64) << 32 | columns.dst[received])
    dsts: dict[str, set[str]] = {names[c]: set() for c in np.unique(columns.src).tolist()}
    for pair in heard.tolist():
        dsts[names[pair >> 32]].add(names[pair & 0xFFFFFFFF])
    known = [n for n in _NODE_ORDER if n in dsts]  # operator's row first, then vehicle's
    rows = known + sorted(set(dsts) - set(known)) or list(_NODE_ORDER)

    fig = Figure(figsize=(12.0, 2.2 + 2.3 * len(rows)), layout="constrained")
    axes = fig.subplots(len(rows), 1, sharex=True, squeeze=False)[:, 0]
    if not len(sent):
        fig.suptitle(f"{title}\nlink timeline")
        for ax in axes:
            no_data(ax, "no transmissions recorded")
        return save(fig, path)

    t0, t1 = timeline_window(sent, window_s=window_s, max_packets=max_packets)
    t_last = float(sent.end_s.max())
    if t1 < t_last:
        span = f"first {t1 - t0:.3g} s of {t_last - t0:.3g} s of link activity, from t = {t0:.2f} s"
    else:
        span = f"whole run ({t_last - t0:.3g} s of link activity)"
    fig.suptitle(f"{title}\nlink timeline (PDUs per direction): {span}")

    drawn: set[FrameOutcome] = set()
    drop = columns.kind == columns.code_of(EventKind.DROP)
    in_window = drop & (columns.t_s >= t0) & (columns.t_s <= t1)
    for ax, src in zip(axes, rows, strict=True):
        code = names.index(src) if src in names else -1
        shown = (sent.src == code) & (sent.end_s >= t0) & (sent.start_s <= t1)
        mine = sent.take(np.flatnonzero(shown))
        lost = [trace.events[i] for i in np.flatnonzero(in_window & (columns.src == code)).tolist()]
        drawn |= _draw_row(ax, mine, lost)
        tally = np.bincount(rank_of[src_of == code], minlength=len(FrameOutcome))
        counts = {outcome_of_rank(r): n for r, n in enumerate(tally.tolist()) if n}
        ax.set_title(_row_title(src, dsts.get(src, set()), counts), loc="left", fontsize=10)
    margin = 0.01 * max(t1 - t0, 1e-3)
    axes[-1].set_xlim(t0 - margin, t1 + margin)
    axes[-1].set_xlabel("simulated time [s]")
    handles = [_legend_handle(o) for o in FrameOutcome if o in drawn]
    if handles:
        fig.legend(handles=handles, loc="outside lower center", ncols=min(len(handles), 4))
    return save(fig, path)
