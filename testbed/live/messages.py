"""What the browser may send the live console, parsed into values — never evaluated.

Every message is one JSON object (a WebSocket text frame of at most :data:`MAX_MESSAGE_BYTES`)
with a type key ``"t"``. :func:`parse_message` turns it into one of the frozen message classes
below or a :class:`Rejected` naming what was wrong; it never raises on any input, and nothing
from the browser is evaluated, unpickled or used as a path. :class:`InputCounters` counts what
came in (accepted, malformed, out of range, flooded); :class:`RateLimit` is a token bucket
that sheds floods.

Messages (units in brackets):

* ``{"t": "sticks", "x": s, "y": s, "z": s, "yaw": s}`` — surge, sway, heave (+ down), yaw
  stick positions, each a finite number in [−1, 1];
* ``{"t": "arm", "armed": bool}``; ``{"t": "mode", "mode": "manual"|"stabilize"|"depth_hold"}``;
* ``{"t": "image", "roi": [x0, y0, x1, y1] | null, "shift": 0..15, "budget": 1..65535}``:
  inclusive ROI pixels 0..1023 with x0 ≤ x1, y0 ≤ y1; budget [B];
* ``{"t": "link", "ber": p}`` (0..0.5), ``{"t": "link", "gap_s": g}`` (0.05..10 s, or null for
  the scenario's policy), ``{"t": "link", "distance_m": d}`` (0..10000 m, or null for the
  scenario's operator position); ``{"t": "outage", "duration_s": d}`` (0.1..60 s);
* ``{"t": "goto", "x": north, "y": east}`` [m], finite, |v| ≤ 327;
* ``{"t": "ping", "c": client_ms}`` — clock probe (answered by the server at once);
* ``{"t": "lat", "pixels_ms": a, "rtt_ms": b}`` — the browser's own latency measurements [ms]
  (state → pixels, WebSocket round trip), each optional, in [0, 60000].
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

__all__ = [
    "MAX_CONNECTIONS",
    "MAX_MESSAGE_BYTES",
    "MODES",
    "Arm",
    "GoToPoint",
    "ImageRequest",
    "InputCounters",
    "LatencyReport",
    "LinkChange",
    "Message",
    "Outage",
    "Ping",
    "RateLimit",
    "Rejected",
    "SetMode",
    "StickInput",
    "parse_message",
    "too_long",
]

MAX_MESSAGE_BYTES = 4096
"""Largest message accepted [B of UTF-8]; longer ones are rejected unread."""
MAX_CONNECTIONS = 32
"""WebSockets served at once (the pilot and viewers); more are refused 403, counted."""
MODES = ("manual", "stabilize", "depth_hold")
"""Control modes the browser may ask for."""

BER_MAX = 0.5
GAP_RANGE_S = (0.05, 10.0)
DISTANCE_MAX_M = 10_000.0
OUTAGE_RANGE_S = (0.1, 60.0)
GOTO_MAX_M = 327.0
"""|x|, |y| of a go-to point [m]: the GoTo order's int16 centimetres."""


@dataclass(frozen=True, slots=True)
class StickInput:
    """Stick positions in [−1, 1]: surge, sway, heave (+ down), yaw."""

    x: float
    y: float
    z: float
    yaw: float

    def sticks(self) -> tuple[float, float, float, float, float, float]:
        """The six sticks of a :class:`~testbed.operator.pilots.PilotSample` (roll, pitch 0)."""
        return (self.x, self.y, self.z, 0.0, 0.0, self.yaw)


@dataclass(frozen=True, slots=True)
class Arm:
    """Arm (True) or disarm (False) request."""

    armed: bool


@dataclass(frozen=True, slots=True)
class SetMode:
    """Control mode request: one of :data:`MODES`."""

    mode: str


@dataclass(frozen=True, slots=True)
class ImageRequest:
    """Coder settings: ROI (inclusive pixels) or None, ROI shift [bit planes], budget [B]."""

    roi: tuple[int, int, int, int] | None
    shift: int
    budget: int


@dataclass(frozen=True, slots=True)
class LinkChange:
    """One live link parameter: ``"ber"``, ``"gap_s"`` [s] or ``"distance_m"`` [m]; None
    restores the scenario's."""

    key: str
    value: float | None


@dataclass(frozen=True, slots=True)
class Outage:
    """Black the link out for ``duration_s`` [s] from now."""

    duration_s: float


@dataclass(frozen=True, slots=True)
class GoToPoint:
    """Supervised control: go to north ``x`` and east ``y`` [m] at the present depth."""

    x: float
    y: float


@dataclass(frozen=True, slots=True)
class Ping:
    """Clock probe: the client's send time [ms, its own clock]."""

    client_ms: float


@dataclass(frozen=True, slots=True)
class LatencyReport:
    """The browser's measurements [ms]: state → pixels and WebSocket round trip (None: none)."""

    pixels_ms: float | None
    rtt_ms: float | None


@dataclass(frozen=True, slots=True)
class Rejected:
    """A message that was refused: ``kind`` is ``"malformed"`` or ``"range"``."""

    kind: str
    reason: str


Message = (
    StickInput
    | Arm
    | SetMode
    | ImageRequest
    | LinkChange
    | Outage
    | GoToPoint
    | Ping
    | LatencyReport
)


def _number(obj: dict[str, Any], key: str, low: float, high: float) -> float | Rejected:
    value = obj.get(key)
    if isinstance(value, bool) or not isinstance(value, int | float):
        return Rejected("malformed", f"{key}: expected a number")
    try:
        number = float(value)
    except OverflowError:  # an integer beyond any float (JSON integers have no bound)
        number = math.inf
    if not (math.isfinite(number) and low <= number <= high):
        shown = f"{number!r}" if isinstance(value, int) and math.isinf(number) else f"{value!r}"
        return Rejected("range", f"{key}: must be in [{low:g}, {high:g}], got {shown}")
    return number


def _integer(obj: dict[str, Any], key: str, low: int, high: int) -> int | Rejected:
    value = obj.get(key)
    if isinstance(value, bool) or not isinstance(value, int):
        return Rejected("malformed", f"{key}: expected an integer")
    if not low <= value <= high:
        return Rejected("range", f"{key}: must be in [{low}, {high}], got {value}")
    return value


def _sticks(obj: dict[str, Any]) -> Message | Rejected:
    values = []
    for key in ("x", "y", "z", "yaw"):
        value = _number(obj, key, -1.0, 1.0)
        if isinstance(value, Rejected):
            return value
        values.append(value)
    return StickInput(*values)


def _image(obj: dict[str, Any]) -> Message | Rejected:
    roi = obj.get("roi")
    box: tuple[int, int, int, int] | None = None
    if roi is not None:
        if not (
            isinstance(roi, list)
            and len(roi) == 4
            and all(isinstance(v, int) and not isinstance(v, bool) for v in roi)
        ):
            return Rejected("malformed", "roi: expected [x0, y0, x1, y1] integers or null")
        x0, y0, x1, y1 = roi
        if not (all(0 <= v <= 1023 for v in roi) and x0 <= x1 and y0 <= y1):
            return Rejected("range", f"roi: need 0 ≤ x0 ≤ x1 ≤ 1023, 0 ≤ y0 ≤ y1 ≤ 1023: {roi}")
        box = (x0, y0, x1, y1)
    shift = _integer(obj, "shift", 0, 15)
    if isinstance(shift, Rejected):
        return shift
    budget = _integer(obj, "budget", 1, 0xFFFF)
    if isinstance(budget, Rejected):
        return budget
    return ImageRequest(box, shift, budget)


_LINK_RANGES = {
    "ber": (0.0, BER_MAX),
    "gap_s": GAP_RANGE_S,
    "distance_m": (0.0, DISTANCE_MAX_M),
}


def _link(obj: dict[str, Any]) -> Message | Rejected:
    keys = [key for key in _LINK_RANGES if key in obj]
    if len(keys) != 1:
        return Rejected("malformed", f"link: expected exactly one of {sorted(_LINK_RANGES)}")
    key = keys[0]
    if obj[key] is None and key != "ber":
        return LinkChange(key, None)
    value = _number(obj, key, *_LINK_RANGES[key])
    return value if isinstance(value, Rejected) else LinkChange(key, value)


def _latency(obj: dict[str, Any]) -> Message | Rejected:
    values: list[float | None] = []
    for key in ("pixels_ms", "rtt_ms"):
        if obj.get(key) is None:
            values.append(None)
            continue
        value = _number(obj, key, 0.0, 60_000.0)
        if isinstance(value, Rejected):
            return value
        values.append(value)
    return LatencyReport(*values)


def _typed(obj: dict[str, Any]) -> Message | Rejected:
    kind = obj.get("t")
    if kind == "sticks":
        return _sticks(obj)
    if kind == "arm":
        armed = obj.get("armed")
        return Arm(armed) if isinstance(armed, bool) else Rejected("malformed", "armed: bool")
    if kind == "mode":
        mode = obj.get("mode")
        if mode in MODES:
            return SetMode(str(mode))
        return Rejected("range", f"mode: expected one of {', '.join(MODES)}")
    if kind == "image":
        return _image(obj)
    if kind == "link":
        return _link(obj)
    if kind == "outage":
        duration = _number(obj, "duration_s", *OUTAGE_RANGE_S)
        return duration if isinstance(duration, Rejected) else Outage(duration)
    if kind == "goto":
        x = _number(obj, "x", -GOTO_MAX_M, GOTO_MAX_M)
        if isinstance(x, Rejected):
            return x
        y = _number(obj, "y", -GOTO_MAX_M, GOTO_MAX_M)
        return y if isinstance(y, Rejected) else GoToPoint(x, y)
    if kind == "ping":
        client = _number(obj, "c", -1e15, 1e15)
        return client if isinstance(client, Rejected) else Ping(client)
    if kind == "lat":
        return _latency(obj)
    return Rejected("malformed", f"unknown message type {str(kind)[:32]!r}")


def too_long(text: str | bytes) -> bool:
    """Whether ``text`` is over :data:`MAX_MESSAGE_BYTES` in bytes (UTF-8), not characters."""
    if len(text) > MAX_MESSAGE_BYTES:
        return True
    if isinstance(text, bytes) or 4 * len(text) <= MAX_MESSAGE_BYTES:
        return False  # at most 4 UTF-8 bytes a character
    return len(text.encode("utf-8", "surrogatepass")) > MAX_MESSAGE_BYTES


def parse_message(text: str | bytes) -> Message | Rejected:
    """One browser message → its value, or :class:`Rejected` (never raises)."""
    if too_long(text):
        return Rejected("malformed", f"longer than {MAX_MESSAGE_BYTES} B")
    try:
        obj = json.loads(text)
    except (ValueError, RecursionError):  # UnicodeDecodeError is a ValueError
        return Rejected("malformed", "not JSON")
    if not isinstance(obj, dict):
        return Rejected("malformed", "expected a JSON object")
    return _typed(obj)


@dataclass(slots=True)
class InputCounters:
    """What came in from the browsers (server thread writes, anyone reads).

    Attributes:
        accepted: messages parsed and acted on.
        malformed: not JSON, not an object, unknown type, wrong field types, too long.
        out_of_range: well-formed but a value outside its domain.
        flooded: shed by the rate limit.
        not_pilot: control messages from a read-only viewer, ignored.
        bad_requests: HTTP requests the server could not parse (garbled bytes on the socket,
            answered 400 Bad Request) or that asked for an upgrade other than WebSocket.
        foreign_host: HTTP requests and WebSockets whose ``Host`` is not one of the console's
            own names (DNS rebinding), answered 403.
        foreign_origin: WebSockets opened by a page of another origin (cross-site WebSocket
            hijacking), answered 403.
        too_many: WebSockets beyond :data:`MAX_CONNECTIONS`, answered 403.
    """

    accepted: int = 0
    malformed: int = 0
    out_of_range: int = 0
    flooded: int = 0
    not_pilot: int = 0
    bad_requests: int = 0
    foreign_host: int = 0
    foreign_origin: int = 0
    too_many: int = 0

    def count(self, parsed: Message | Rejected) -> None:
        """Count a parse result."""
        if isinstance(parsed, Rejected):
            if parsed.kind == "range":
                self.out_of_range += 1
            else:
                self.malformed += 1
        else:
            self.accepted += 1

    def as_dict(self) -> dict[str, int]:
        """The counters by name."""
        return {
            "accepted": self.accepted,
            "malformed": self.malformed,
            "out_of_range": self.out_of_range,
            "flooded": self.flooded,
            "not_pilot": self.not_pilot,
            "bad_requests": self.bad_requests,
            "foreign_host": self.foreign_host,
            "foreign_origin": self.foreign_origin,
            "too_many": self.too_many,
        }


class RateLimit:
    """Token bucket: ``rate_hz`` messages a second on average, bursts up to ``burst``.

    Args:
        rate_hz: sustained rate [1/s], > 0.
        burst: bucket size [messages], ≥ 1.
        clock_s: monotonic clock [s] (injectable for tests).
    """

    def __init__(
        self,
        rate_hz: float = 200.0,
        burst: int = 100,
        clock_s: Callable[[], float] = time.monotonic,
    ) -> None:
        if not (rate_hz > 0.0 and burst >= 1):
            raise ValueError(f"need rate_hz > 0 and burst ≥ 1, got {rate_hz}, {burst}")
        self._rate = rate_hz
        self._burst = float(burst)
        self._tokens = float(burst)
        self._clock = clock_s
        self._last = clock_s()

    def allow(self) -> bool:
        """Take one token; False (shed the message) if the bucket is empty."""
        now = self._clock()
        self._tokens = min(self._burst, self._tokens + (now - self._last) * self._rate)
        self._last = now
        if self._tokens >= 1.0:
            self._tokens -= 1.0
            return True
        return False
