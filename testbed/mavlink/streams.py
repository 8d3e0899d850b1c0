"""Telemetry stream rates of one channel: REQUEST_DATA_STREAM groups and per-message intervals.

A channel starts at the SR0_* parameter rates (ArduPilot's per-link stream rates, so a ground
station that asks for nothing still gets telemetry); REQUEST_DATA_STREAM sets a whole group
(:data:`~testbed.mavlink.ardusub.STREAM_GROUPS`; stream 0 = all), SET_MESSAGE_INTERVAL one
message as ArduPilot's ``GCS_MAVLINK::set_message_interval`` reads param2 (:func:`interval_ms`:
−1 off, 0 back to its group's rate, any other interval below 1000 µs — negative ones too — 1 ms,
above 60 s a minute), kept as ArduPilot keeps it (:func:`stored_interval_ms`: at least
80 % of ArduSub's 400-Hz loop period, so 1–3 ms is 3 ms) and answered so by
GET_MESSAGE_INTERVAL. Rates are served at most at :data:`MAX_RATE_HZ` (the endpoint runs once
per vehicle frame, 100 Hz), so a message asked for every 3 ms is sent every 20 ms while
GET_MESSAGE_INTERVAL says 3000 µs, as ArduPilot would. A group's messages are served every
ArduPilot's whole milliseconds (3 Hz: 333 ms, so 3.003 a second, not 3). Due times advance by
whole intervals and skip ahead after a stall (ArduPilot's ``update_send``: ``last_sent_ms +=
interval_ms``, reset to now when that is more than an interval behind), so a late run never
sends a burst.

HIGH_LATENCY2 is ArduPilot's one "deferred" message here (``GCS_MAVLINK::deferred_message``, not
a stream group): every :data:`HIGH_LATENCY2_INTERVAL_S` on a high-latency link
(``initialise_message_intervals_from_streamrates``: ``set_mavlink_message_id_interval(
HIGH_LATENCY2, 5000)`` when ``is_high_latency_link``), off on the others, and 5 s again after a
SET_MESSAGE_INTERVAL of 0 on any link (``get_default_interval_for_ap_message``). A deferred
message is first due one interval after its schedule starts or is set (``set_ap_message_interval``
stamps ``last_sent_ms`` now), not at once.

HEARTBEAT is the other (``deferred_message[]`` in ``GCS.h``: MSG_HEARTBEAT, MSG_NEXT_PARAM,
MSG_HIGH_LATENCY2), per link as everything here: every :data:`HEARTBEAT_INTERVAL_S` from the
channel's first update on an ordinary link (``initialise_message_intervals_from_streamrates``:
``set_mavlink_message_id_interval(HEARTBEAT, 1000)`` unless ``is_high_latency_link``), none on
a high-latency one; SET_MESSAGE_INTERVAL sets it as any message (0: back to 1 s on any link,
``get_default_interval_for_ap_message``'s special case; −1: no heartbeat on that link) and
GET_MESSAGE_INTERVAL reads it back (1 000 000 µs by default, −1 when off).

:data:`ON_REQUEST` messages (HOME_POSITION, GPS_GLOBAL_ORIGIN, ATTITUDE_QUATERNION) are in no
stream group: off until SET_MESSAGE_INTERVAL streams them, as ArduPilot's
``set_ap_message_interval`` puts any ``ap_message`` in a bucket (0 sets them off again:
``get_default_interval_for_ap_message`` finds no stream holding them). No I/O, no clock.
"""

from __future__ import annotations

import math
from typing import Protocol

from testbed.mavlink.ardusub import STREAM_GROUPS

__all__ = [
    "ARDUSUB_LOOP_PERIOD_US",
    "GROUP_PARAMS",
    "HEARTBEAT_INTERVAL_S",
    "HIGH_LATENCY2_INTERVAL_S",
    "MAX_INTERVAL_S",
    "MAX_RATE_HZ",
    "ON_REQUEST",
    "StreamSchedule",
    "interval_ms",
    "stored_interval_ms",
    "stream_interval_ms",
]

MAX_RATE_HZ = 50.0
"""Fastest telemetry rate served [Hz]."""
ARDUSUB_LOOP_PERIOD_US = 1_000_000 // 400
"""ArduSub's main loop period [µs]: ``AP_Scheduler::init`` sets ``_loop_period_us = 1000000UL /
_loop_rate_hz``, SCHED_LOOP_RATE's default for ArduSub 400 Hz (``AP_Scheduler.cpp``
SCHEDULER_DEFAULT_LOOP_RATE)."""
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
ON_REQUEST = ("HOME_POSITION", "GPS_GLOBAL_ORIGIN", "ATTITUDE_QUATERNION")
"""Messages sent on request (REQUEST_MESSAGE, GET_HOME_POSITION) that no stream group holds in
ArduSub (its ``STREAM_*_msgs`` arrays, ``ArduSub/GCS_Mavlink.cpp``): not streamed until
SET_MESSAGE_INTERVAL asks."""
HEARTBEAT_INTERVAL_S = 1.0
"""HEARTBEAT's interval on an ordinary link, and its default on any [s] (ArduPilot's
``GCS_MAVLINK::get_default_interval_for_ap_message``: 1000 ms for MSG_HEARTBEAT, "because
heartbeat is not streamed")."""
_HEARTBEAT_MS = round(HEARTBEAT_INTERVAL_S * 1000)


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
            name: _group_interval_s(group_rates_hz.get(group, 0.0))
            for name, group in _GROUP_OF.items()
        }
        self.interval_s: dict[str, float] = dict(self._defaults)
        self._stored_ms: dict[str, int] = {}  # SET_MESSAGE_INTERVAL's, as ArduPilot keeps it
        self._group_ms = {  # the group rate's interval as ArduPilot keeps it
            name: stream_interval_ms(group_rates_hz.get(group, 0.0))
            for name, group in _GROUP_OF.items()
        }
        for name in _DEFERRED:
            self._defaults[name] = HIGH_LATENCY2_INTERVAL_S
            self.interval_s[name] = HIGH_LATENCY2_INTERVAL_S if high_latency else 0.0
        for name in ON_REQUEST:
            self._defaults[name] = self.interval_s[name] = 0.0
        self._next_s: dict[str, float] = {}
        self._heartbeat_ms = 0 if high_latency else _HEARTBEAT_MS  # as ArduPilot keeps it
        self.heartbeat_interval_s = 0.0 if high_latency else HEARTBEAT_INTERVAL_S
        """HEARTBEAT's interval as served [s] (0 = none on this link)."""
        self._next_heartbeat_s: float | None = 0.0  # None: set, first due one interval on

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
                self._defaults[name] = _group_interval_s(rate_hz)
                self._set(name, self._defaults[name])
                self._stored_ms.pop(name, None)
                self._group_ms[name] = stream_interval_ms(rate_hz)
        return True

    def set_interval(self, name: str, interval_us: float) -> bool:
        """SET_MESSAGE_INTERVAL's param2 ``interval_us`` [µs] read as ArduPilot reads it
        (:func:`interval_ms`): off, the group's rate (its boot rate, or the one
        REQUEST_DATA_STREAM set since), or every so many whole milliseconds, kept as
        :func:`stored_interval_ms` and served at least 1 / :data:`MAX_RATE_HZ` apart. Returns
        False for a message not streamed or a NaN interval. HEARTBEAT's default is
        :data:`HEARTBEAT_INTERVAL_S`, its first one then one interval on (:meth:`heartbeat_due`);
        an :data:`ON_REQUEST` message's is off.
        """
        if math.isnan(interval_us):
            return False
        if name == "HEARTBEAT":
            ms = interval_ms(interval_us)
            stored = stored_interval_ms(_HEARTBEAT_MS if ms is None else ms)
            self._heartbeat_ms = stored
            self.heartbeat_interval_s = _served_s(stored)
            self._next_heartbeat_s = None
            return True
        if name not in self._defaults:
            return False
        ms = interval_ms(interval_us)
        if ms is None:
            self._set(name, self._defaults[name])
            self._stored_ms.pop(name, None)
            return True
        stored = stored_interval_ms(ms)
        self._stored_ms[name] = stored
        self._set(name, _served_s(stored))
        return True

    def interval_us(self, name: str) -> int:
        """GET_MESSAGE_INTERVAL's answer [µs]: −1 when off or not streamed (an
        :data:`ON_REQUEST` message until SET_MESSAGE_INTERVAL streams it:
        ``handle_command_get_message_interval`` sends −1, "disabled", when
        ``get_ap_message_interval`` finds it in no bucket, or at an interval of 0); the interval
        SET_MESSAGE_INTERVAL set as ArduPilot keeps it (``handle_command_get_message_interval``
        answers ``interval_ms * 1000`` of what ``set_ap_message_interval`` stored: 3000 after a
        1-ms request, though it is served at :data:`MAX_RATE_HZ`), else its group rate's
        (:func:`stream_interval_ms`: 333 000 at 3 Hz), else the interval served. HEARTBEAT:
        1 000 000 by default, −1 on a high-latency link (``get_ap_message_interval`` reads the
        deferred message's ``interval_ms``, 0 there)."""
        if name == "HEARTBEAT":
            return -1 if self._heartbeat_ms == 0 else self._heartbeat_ms * 1000
        if name not in self.interval_s:
            return -1
        if name in self._stored_ms:
            stored = self._stored_ms[name]
            return -1 if stored == 0 else stored * 1000
        interval = self.interval_s[name]
        if interval == 0:
            return -1
        group_ms = self._group_ms.get(name)
        return round(interval * 1e6) if group_ms is None else group_ms * 1000

    def _set(self, name: str, interval_s: float) -> None:
        self.interval_s[name] = interval_s
        self._next_s.pop(name, None)

    def heartbeat_due(self, now_s: float) -> bool:
        """Whether this link's HEARTBEAT is due at ``now_s`` [s] (then scheduled one interval
        on; after a stall, one interval from now, as ArduPilot's ``update_send`` does for a
        deferred message that fell behind). Due at the channel's first update; after
        SET_MESSAGE_INTERVAL, first one interval on."""
        interval = self.heartbeat_interval_s
        if interval <= 0.0:
            return False
        next_s = self._next_heartbeat_s
        if next_s is None:
            self._next_heartbeat_s = now_s + interval
            return False
        if now_s < next_s:
            return False
        next_s += interval
        self._next_heartbeat_s = next_s if next_s > now_s else now_s + interval
        return True

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


def stored_interval_ms(ms: int) -> int:
    """The interval [ms] ArduPilot's ``GCS_MAVLINK::set_ap_message_interval`` (``GCS_Common.cpp``)
    keeps for a requested ``ms`` (0 = off): "send messages out at most 80% of main loop rate" —
    when ``interval_ms * 800`` is below the loop period (:data:`ARDUSUB_LOOP_PERIOD_US`), it
    becomes ``loop_period_us / 800.0f`` in its uint16, 2500 / 800 = 3.125 → 3 ms; so 1, 2 and
    3 ms are 3 ms, 4 ms and up as asked."""
    if ms != 0 and ms * 800 < ARDUSUB_LOOP_PERIOD_US:
        return int(ARDUSUB_LOOP_PERIOD_US / 800.0)
    return ms


def stream_interval_ms(rate_hz: float) -> int | None:
    """The interval [ms] ArduPilot keeps for a message of a stream group at ``rate_hz`` (an
    SRn_* parameter or REQUEST_DATA_STREAM's rate, an int16 there, so taken toward 0):
    ``GCS_MAVLINK::get_interval_for_stream`` (``GCS_Common.cpp``) is ``1000 / rate`` in integers
    (3 Hz → 333 ms; 0 Hz → 0, off), which ``initialise_message_intervals_for_stream`` passes to
    ``set_ap_message_interval`` (:func:`stored_interval_ms`). None above 1000 Hz and for
    negative or non-finite rates, which ArduPilot turns into an interval of 0 or a minute and
    this endpoint serves at :data:`MAX_RATE_HZ` (not modelled), and for a rate below 1 Hz that
    is not 0 (no int16 rate: a test's ``stream_rates_hz``)."""
    rate = math.trunc(rate_hz) if math.isfinite(rate_hz) else -1
    if not 0 <= rate <= 1000 or (rate == 0 and rate_hz != 0):  # a fraction of 1 Hz: ours
        return None
    return 0 if rate == 0 else stored_interval_ms(1000 // rate)


def _served_s(stored_ms: int) -> float:
    """The interval [s] a message kept at ``stored_ms`` (0 = off) is served at: at most
    :data:`MAX_RATE_HZ`."""
    return 0.0 if stored_ms == 0 else max(stored_ms * 1e-3, 1.0 / MAX_RATE_HZ)


def _group_interval_s(rate_hz: float) -> float:
    """The interval [s] a stream group's message is served at for ``rate_hz``: ArduPilot's
    whole milliseconds (:func:`stream_interval_ms`: ``1000 / rate`` in integers, so 3 Hz is every
    333 ms, not 333.3; ``update_send`` reschedules a bucket by ``last_sent_ms +=
    interval_ms``), at most :data:`MAX_RATE_HZ`; a rate ArduPilot cannot hold (below 1 Hz but not
    0, negative, above 1000 Hz) every 1 / ``rate_hz`` (:func:`_interval`)."""
    ms = stream_interval_ms(rate_hz)
    return _interval(rate_hz) if ms is None else _served_s(ms)


def _interval(rate_hz: float) -> float:
    """Rate [Hz] → interval [s] (0 = off), capped at :data:`MAX_RATE_HZ`."""
    if not (math.isfinite(rate_hz) and rate_hz > 0):
        return 0.0
    return 1.0 / min(rate_hz, MAX_RATE_HZ)
