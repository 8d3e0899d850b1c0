"""What the endpoint sends, and on which link: its channels, their outboxes, its STATUSTEXTs.

:class:`Outbound` is the sending half of :class:`~testbed.mavlink.endpoint.VehicleEndpoint`
(its base class): it opens one :class:`~testbed.mavlink.channel.Channel` per ground-station link
(the n-th is SERIALn: a high-latency link when SERIALn_PROTOCOL was
:data:`MAVLINK_HL_PROTOCOL` at boot), encodes packets onto their outboxes (bounded, and silent
on a high-latency link while those are disabled), and holds the STATUSTEXTs said during an
update until its end, as ArduPilot's text queue does. Packets go out with the system id read at
boot.

Nothing here handles a message, reads the vehicle or keeps a clock: what to send and when is
the endpoint's (:mod:`~testbed.mavlink.endpoint`, its handlers and stream schedule).
"""

from __future__ import annotations

from collections import Counter

from pymavlink.dialects.v20 import ardupilotmega as mav

from testbed.mavlink.channel import OUTBOX_LIMIT, Channel
from testbed.mavlink.params import ParamTable
from testbed.mavlink.streams import StreamSchedule
from testbed.mavlink.wire import MavlinkWire

__all__ = ["MAVLINK_HL_PROTOCOL", "SERIAL_PORTS", "STATUSTEXT_LIMIT", "Outbound"]

MAVLINK_HL_PROTOCOL = 43
"""SERIALn_PROTOCOL's MAVLink High Latency (``AP_SerialManager.h`` SerialProtocol_MAVLinkHL)."""
SERIAL_PORTS = 3
"""Serial ports whose SERIALn_PROTOCOL the table carries (SERIAL0–2, ArduPilot's MAVLink2 ports
by default: console, TELEM1, TELEM2): the first three channels opened."""
STATUSTEXT_LIMIT = 50
"""STATUSTEXT's text field [bytes]: a longer text is cut there."""


class Outbound:
    """The endpoint's links and what is queued on them (module docstring).

    Args:
        params: the parameter table; SYSID_THISMAV and SERIAL0–2_PROTOCOL are read once, here
            (ArduPilot reads them at boot).

    Attributes:
        params: the parameter table.
        channels: the links opened, in order (the n-th is SERIALn).
        sent: packets queued, by message type.
        rejected: what was dropped, by reason (here ``outbox_full``; the endpoint counts what
            it drops on receipt in the same counter).
        high_latency_enabled: the high-latency links send (MAV_CMD_CONTROL_HIGH_LATENCY; off
            at boot: :mod:`~testbed.mavlink.high_latency`).
    """

    def __init__(self, params: ParamTable) -> None:
        self.params = params
        self.channels: list[Channel] = []
        self.sent: Counter[str] = Counter()
        self.rejected: Counter[str] = Counter()
        self.high_latency_enabled = False
        self._system_id = int(params["SYSID_THISMAV"])  # ArduPilot's GCS::init, at boot only
        self._serial_protocols = [int(params[f"SERIAL{n}_PROTOCOL"]) for n in range(SERIAL_PORTS)]
        self._texts_said: set[str] = set()
        self._statustexts: list[mav.MAVLink_message] = []

    @property
    def system_id(self) -> int:
        """SYSID_THISMAV at boot (a value set later takes effect at the next boot, as in
        ArduPilot, whose ``GCS::init`` reads it once)."""
        return self._system_id

    def open_channel(
        self,
        name: str,
        *,
        high_latency: bool | None = None,
        stream_rates_hz: dict[int, float] | None = None,
    ) -> Channel:
        """A new link, streaming at the SR0_* rates until the ground station asks otherwise.

        Args:
            name: the link's name.
            high_latency: a high-latency link (:mod:`~testbed.mavlink.high_latency`):
                HIGH_LATENCY2 every 5 s, no HEARTBEAT, silent while the endpoint's high-latency
                links are disabled. None (the default): as its serial port's protocol was at
                boot — the n-th channel opened (from 0) is SERIALn, as SITL's ``--serialN``, and
                is a high-latency link when SERIALn_PROTOCOL is :data:`MAVLINK_HL_PROTOCOL`
                (ArduPilot's ``GCS_MAVLINK::init``: ``is_high_latency_link`` for a
                SerialProtocol_MAVLinkHL port); any other protocol, and channels past
                :data:`SERIAL_PORTS`, are ordinary MAVLink links.
            stream_rates_hz: its stream groups' rates [Hz] (group id → rate) instead of the
                SR0_* parameters' (default for a high-latency link: all 0, its SRn_* set to 0).
        """
        if high_latency is None:
            n = len(self.channels)
            high_latency = n < SERIAL_PORTS and self._serial_protocols[n] == MAVLINK_HL_PROTOCOL
        if stream_rates_hz is None and not high_latency:
            streams = StreamSchedule.from_params(self)
        else:
            streams = StreamSchedule(stream_rates_hz or {}, high_latency=high_latency)
        wire = MavlinkWire(self.system_id, 1)
        channel = Channel(name, wire, streams, high_latency=high_latency)
        self.channels.append(channel)
        return channel

    def queue(self, channel: Channel, message: mav.MAVLink_message) -> None:
        """Encode ``message`` onto ``channel`` (dropped and counted if its outbox is full; not
        sent, counted ``held``, on a high-latency link while they are disabled)."""
        if channel.high_latency and not self.high_latency_enabled:
            channel.held += 1
            return
        if len(channel.outbox) >= OUTBOX_LIMIT:
            channel.dropped += 1
            self.rejected["outbox_full"] += 1
            return
        channel.wire.system_id = self.system_id
        channel.outbox.append(channel.wire.encode(message))
        self.sent[message.get_type()] += 1

    def broadcast(self, message: mav.MAVLink_message) -> None:
        """Queue ``message`` on every channel."""
        for channel in self.channels:
            self.queue(channel, message)

    def statustext(self, severity: int, text: str) -> None:
        """STATUSTEXT for every channel (≤ :data:`STATUSTEXT_LIMIT` bytes), sent by the next
        :meth:`send_statustexts` — at the end of the endpoint's next update, after what that
        update queues and after the replies to what has arrived meanwhile: ArduPilot's
        ``GCS::send_textv`` only queues the text once the vehicle is initialised, and
        ``GCS::update_send`` sends the queue (``service_statustext``) after every link's
        messages, so a command's COMMAND_ACK, written as its handler returns
        (``handle_command_long``), goes out before a text the handler said."""
        encoded = text.encode()[:STATUSTEXT_LIMIT]
        self._statustexts.append(mav.MAVLink_statustext_message(severity, encoded, 0, 0))

    def statustext_once(self, severity: int, text: str) -> None:
        """:meth:`statustext`, the first time ``text`` is said only."""
        if text not in self._texts_said:
            self._texts_said.add(text)
            self.statustext(severity, text)

    def send_statustexts(self) -> None:
        """Queue the STATUSTEXTs said since the last call on every channel, in the order said."""
        texts, self._statustexts = self._statustexts, []
        for text in texts:
            self.broadcast(text)
