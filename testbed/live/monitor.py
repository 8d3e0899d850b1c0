"""What the console shows, read from the running session (simulation thread only).

:class:`LinkMonitor` follows the link trace incrementally (per direction: frames sent,
delivered, corrupted, collided (or lost to the receiver transmitting), lost to an outage,
dropped, out of range; the packet timeline);
:func:`image_view` packs the operator's current picture for the browser; :func:`latency_ms`
summarises latency samples. Everything returned is plain JSON-ready data (lists, floats,
strings), built here and handed to the server thread as a finished value.
"""

from __future__ import annotations

import base64
import math
from collections import deque
from collections.abc import Iterable
from typing import Any

import numpy as np

from testbed.channel import EventKind, Trace

__all__ = ["TIMELINE_EVENTS", "LinkMonitor", "finite_or_none", "image_view", "latency_ms"]

TIMELINE_EVENTS = 120
"""Packet timeline entries kept for the browser (the newest)."""

_DIRECTIONS = {"uplink": "operator", "downlink": "vehicle"}
_LOST = {
    EventKind.CORRUPT: "corrupted",
    EventKind.COLLIDE: "collided",
    EventKind.DEAF: "collided",  # lost to the receiver's own transmission: a collision too
    EventKind.OUTAGE: "outage",
    EventKind.OUT_OF_RANGE: "out_of_range",
    EventKind.DROP: "dropped",
}
_TIMELINE_KINDS = {EventKind.TX_START, EventKind.DELIVER, *_LOST}


class LinkMonitor:
    """Per-direction link counters and the recent packet timeline, from a growing trace.

    Args:
        trace: the session's link trace.
    """

    def __init__(self, trace: Trace) -> None:
        self._trace = trace
        self._seen = 0
        self.counts: dict[str, dict[str, int]] = {
            direction: {"sent": 0, "corrupted": 0, "collided": 0, "outage": 0, "dropped": 0}
            | {"out_of_range": 0}
            for direction in _DIRECTIONS
        }
        self.timeline: deque[tuple[float, str, str]] = deque(maxlen=TIMELINE_EVENTS)

    def update(self) -> None:
        """Take in the events recorded since the last call."""
        events = self._trace.events
        end = len(events)
        if end == self._seen:
            return
        for event in events[self._seen : end]:
            direction = "uplink" if event.src == "operator" else "downlink"
            counts = self.counts[direction]
            kind = event.kind
            if kind is EventKind.ENQUEUE:
                counts["sent"] += 1
            elif kind in _LOST:
                counts[_LOST[kind]] += 1
            if kind in _TIMELINE_KINDS:
                self.timeline.append((round(event.t_s, 3), direction, str(kind)))
        self._seen = end

    def direction(self, direction: str, delivered: int) -> dict[str, Any]:
        """One direction's counters with ``delivered`` (frames decoded) and the PER
        (1 − delivered / settled; settled = delivered + lost; None before any)."""
        counts = self.counts[direction]
        lost = sum(counts[k] for k in ("corrupted", "collided", "outage", "out_of_range"))
        settled = delivered + lost
        return counts | {
            "delivered": delivered,
            "per": None if settled == 0 else 1.0 - delivered / settled,
        }


def image_view(pixels: np.ndarray | None) -> dict[str, Any] | None:
    """(h, w) uint8 grey → ``{"w", "h", "grey"}`` (base64 bytes, row-major), or None."""
    if pixels is None or pixels.size == 0 or pixels.ndim != 2:
        return None
    grey = np.ascontiguousarray(pixels, dtype=np.uint8)
    return {
        "w": int(grey.shape[1]),
        "h": int(grey.shape[0]),
        "grey": base64.b64encode(grey.tobytes()).decode("ascii"),
    }


def latency_ms(samples_ns: Iterable[float]) -> dict[str, float | int | None]:
    """``{"p50", "p95", "max", "n"}`` [ms] of latency samples [ns] (None when empty)."""
    values = np.asarray(list(samples_ns), dtype=float) / 1e6
    values = values[np.isfinite(values)]
    if values.size == 0:
        return {"p50": None, "p95": None, "max": None, "n": 0}
    return {
        "p50": float(np.percentile(values, 50)),
        "p95": float(np.percentile(values, 95)),
        "max": float(values.max()),
        "n": int(values.size),
    }


def finite_or_none(value: float) -> float | None:
    """JSON-ready float: None for NaN and infinities."""
    return value if math.isfinite(value) else None
