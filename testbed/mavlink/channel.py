"""One ground-station link of the endpoint: its codec, stream rates, outbox and parameter
download.

A :class:`Channel` is state only: the endpoint (:mod:`testbed.mavlink.endpoint`) decodes what
arrives on it, queues encoded packets on it (at most :data:`OUTBOX_LIMIT`, more dropped and
counted) and a link (:mod:`testbed.mavlink.links`, a test) takes them (:meth:`Channel.take`).
No socket, no clock, no message handling here.
"""

from __future__ import annotations

from testbed.mavlink.streams import StreamSchedule
from testbed.mavlink.wire import MavlinkWire

__all__ = ["OUTBOX_LIMIT", "Channel"]

OUTBOX_LIMIT = 1024
"""Packets a channel's outbox holds at most; more are dropped and counted (``outbox_full``)."""


class Channel:
    """One ground-station link: its codec, stream rates, outbox and pending parameter list.

    Args:
        name: the link's name (for logs and metrics).
        wire: its MAVLink codec (system and component of the vehicle).
        streams: its telemetry stream rates.
        high_latency: a high-latency link (ArduPilot's SERIALn_PROTOCOL 43, MAVLinkHL:
            :mod:`~testbed.mavlink.high_latency`): no HEARTBEAT, HIGH_LATENCY2 instead, and
            nothing at all while the endpoint's high-latency links are disabled.

    Attributes:
        outbox: encoded packets queued and not yet taken, oldest first.
        param_cursor: the next parameter index of a download under way (None: none).
        dropped: packets dropped because the outbox was full.
        held: packets not sent because this high-latency link was disabled (ArduPilot's
            ``comm_send_buffer`` drops them).
    """

    def __init__(
        self, name: str, wire: MavlinkWire, streams: StreamSchedule, *, high_latency: bool = False
    ) -> None:
        self.name = name
        self.wire = wire
        self.streams = streams
        self.high_latency = high_latency
        self.outbox: list[bytes] = []
        self.param_cursor: int | None = None
        self.dropped = 0
        self.held = 0

    def take(self) -> list[bytes]:
        """The encoded packets queued since the last call, in order."""
        out, self.outbox = self.outbox, []
        return out
