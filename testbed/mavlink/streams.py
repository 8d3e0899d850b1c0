"""Telemetry stream rates of one channel: REQUEST_DATA_STREAM groups and per-message intervals.

A channel starts at the SR0_* parameter rates (ArduPilot's per-link stream rates, so a ground
station that asks for nothing still gets telemetry); REQUEST_DATA_STREAM sets a whole group
(:data:`~testbed.mavlink.ardusub.STREAM_GROUPS`; stream 0 = all), SET_MESSAGE_INTERVAL one
message as ArduPilot's ``GCS_MAVLINK::set_message_interval`` reads param2 (:func:`interval_ms`:
−1 off, 0 back to its group's rate, any other interval below 1000 µs — negative ones too — 1 ms,
above 60 s a minute). Rates are capped at :data:`MAX_RATE_HZ` (the endpoint runs once per
vehicle frame, 100 Hz), so 1 ms is served, and answered, as :data:`MAX_RATE_HZ`. Due times
advance by whole intervals and skip ahead after a stall, so a late run never sends a burst.

HIGH_LATENCY2 is ArduPilot's one "deferred" message here (``GCS_MAVLINK::deferred_message``, not
a stream group): every :data:`HIGH_LATENCY2_INTERVAL_S` on a high-latency link
(``initialise_message_intervals_from_streamrates``: ``set_mavlink_message_id_interval(
HIGH_LATENCY2, 5000)`` when ``is_high_latency_link``), off on the others, and 5 s again after a
SET_MESSAGE_INTERVAL of 0 on any link (``get_default_interval_for_ap_message``). A deferred
message is first due one interval after its schedule starts or is set (``set_ap_message_interval``
stamps ``last_sent_ms`` now), not at once. No I/O, no clock.
"""

from __future__ import annotations

import math
from typing import Protocol

from testbed.mavlink.ardusub import STREAM_GROUPS

__all__ = [
    "GROUP_PARAMS",
    "HIGH_LATENCY2_INTERVAL_S",
    "MAX_INTERVAL_S",
    "MAX_RATE_HZ",
    "StreamSchedule",
    "interval_ms",
]

MAX_RATE_HZ = 50.0
"""Fastest telemetry rate served [Hz]."""
MAX_INTERVAL_S = 60.0
"""Longest interval SET_MESSAGE_INTERVAL sets [s]: ArduPilot's ``GCS_MAVLINK::
set_message_interval`` caps ``interval_us`` above 60 000 000 at 60 000 ms (so the
MESSAGE_INTERVAL answered fits its int32 field)."""
GROUP_PARAMS = {
    1: "SR0_RAW_SENS",
    2: "SR0_EXT_STAT",
    3: "SR0_RC_CHAN",
    6: "SR0_POSITION",
    10: "SR0_EXTRA1",
    11: "SR0_EXTRA2",
    12: "SR0_EXTRA3",
}
"""Stream group → the parameter holding its boot rate [Hz]."""
_GROUP_OF = {name: group for group, names in STREAM_GROUPS.items() for name in names}
HIGH_LATENCY2_INTERVAL_S = 5.0
"""HIGH_LATENCY2's interval on a high-latency link, and its default on any [s] (ArduPilot 4.5
``GCS_Common.cpp``: 5000 ms)."""
_DEFERRED = ("HIGH_LATENCY2",)


class _HasParams(Protocol):
    @property
    def params(self) -> _Params: ...


class _Params(Protocol):
    def __getitem__(self, name: str) -> float: ...


class StreamSchedule:
    """Which telemetry messages a channel sends, how often, and when each is next due.

    Args:
        group_rates_hz: boot rate of each stream group [Hz] (0 = off).
        high_latency: a high-latency link's schedule (HIGH_LATENCY2 every
            :data:`HIGH_LATENCY2_INTERVAL_S`; off otherwise).
    """

    def __init__(self, group_rates_hz: dict[int, float], *, high_latency: bool = False) -> None:
        self._defaults = {
            name: _interval(group_rates_hz.get(group, 0.0)) for name, group in _GROUP_OF.items()
        }
        self.interval_s: dict[str, float] = dict(self._defaults)
        for name in _DEFERRED:
            self._defaults[name] = HIGH_LATENCY2_INTERVAL_S
            self.interval_s[name] = HIGH_LATENCY2_INTERVAL_S if high_latency else 0.0
        self._next_s: dict[str, float] = {}

    @classmethod
    def from_params(cls, owner: _HasParams) -> StreamSchedule:
        """The SR0_* rates of ``owner.params``."""
        return cls({group: owner.params[name] for group, name in GROUP_PARAMS.items()})

    def set_group(self, stream_id: int, rate_hz: float) -> bool:
        """REQUEST_DATA_STREAM: every message of group ``stream_id`` (0 = all) at ``rate_hz``
        (≤ 0: off), which is then its messages' default too (ArduPilot sets the group's stream
        rate, from which SET_MESSAGE_INTERVAL 0 takes a message's default). Returns False for
        an unknown group."""
        if stream_id != 0 and stream_id not in STREAM_GROUPS:
            return False
        groups = STREAM_GROUPS if stream_id == 0 else {stream_id: STREAM_GROUPS[stream_id]}
        for names in groups.values():
            for name in names:
                self._defaults[name] = _interval(rate_hz)
                self._set(name, self._defaults[name])
        return True

    def set_interval(self, name: str, interval_us: float) -> bool:
        """SET_MESSAGE_INTERVAL's param2 ``interval_us`` [µs] read as ArduPilot reads it
        (:func:`interval_ms`): off, the group's rate (its boot rate, or the one
        REQUEST_DATA_STREAM set since), or every so many whole milliseconds (at least
        1 / :data:`MAX_RATE_HZ`). Returns False for a message not streamed or a NaN interval."""
        if name not in self._defaults or math.isnan(interval_us):
            return False
        ms = interval_ms(interval_us)
        if ms is None:
            self._set(name, self._defaults[name])
        elif ms == 0:
            self._set(name, 0.0)
        else:
            self._set(name, max(ms * 1e-3, 1.0 / MAX_RATE_HZ))
        return True

    def interval_us(self, name: str) -> int:
        """GET_MESSAGE_INTERVAL's answer: the interval [µs], −1 when off, 0 if not streamed."""
        if name not in self.interval_s:
            return 0
        interval = self.interval_s[name]
        return -1 if interval == 0 else round(interval * 1e6)

    def _set(self, name: str, interval_s: float) -> None:
        self.interval_s[name] = interval_s
        self._next_s.pop(name, None)

    def due(self, now_s: float) -> list[str]:
        """The messages due at ``now_s`` [s] (each then scheduled one interval on)."""
        out: list[str] = []
        for name, interval in self.interval_s.items():
            if interval <= 0:
                continue
            next_s = self._next_s.get(name)
            if next_s is None and name in _DEFERRED:  # first due one interval on
                self._next_s[name] = now_s + interval
                continue
            if next_s is not None and now_s < next_s - 1e-9:
                continue
            out.append(name)
            nxt = now_s + interval if next_s is None else next_s + interval
            self._next_s[name] = nxt if nxt > now_s else now_s + interval
        return out


_INT32_MIN, _INT32_MAX = -(2**31), 2**31 - 1


def interval_ms(interval_us: float) -> int | None:
    """The interval [ms] ArduPilot's ``GCS_MAVLINK::set_message_interval`` (``GCS_Common.cpp``)
    sets for SET_MESSAGE_INTERVAL's param2 ``interval_us`` [µs], a finite float or ±inf:
    0 = off, None = the message's default.

    ``handle_command_set_message_interval`` casts param2 to an int32 (C's conversion: toward
    0, so −1.5 is −1 and 0.5 is 0; beyond the int32 range saturated, as ARM's VCVT does);
    then 0 is "reset to default rate", −1 "stop sending", any other value below 1000 —
    negative ones too — "don't squash sub-ms times to zero": 1 ms; above 60 000 000 µs
    60 000 ms; else ``interval_us / 1000`` in integers (1999 µs → 1 ms).
    """
    us = math.trunc(max(_INT32_MIN, min(_INT32_MAX, interval_us)))
    if us == 0:
        return None
    if us == -1:
        return 0
    if us < 1000:
        return 1
    if us > 60_000_000:
        return round(MAX_INTERVAL_S * 1000)
    return us // 1000


def _interval(rate_hz: float) -> float:
    """Rate [Hz] → interval [s] (0 = off), capped at :data:`MAX_RATE_HZ`."""
    if not (math.isfinite(rate_hz) and rate_hz > 0):
        return 0.0
    return 1.0 / min(rate_hz, MAX_RATE_HZ)
