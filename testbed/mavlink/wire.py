"""MAVLink bytes ↔ messages through pymavlink's generated ``ardupilotmega`` dialect.

:class:`MavlinkWire` is one MAVLink channel's codec: :meth:`~MavlinkWire.decode` takes any
bytes (whole packets, pieces of packets, garbage) and returns the messages that parsed plus the
reasons for what did not; a piece of a packet waits for the rest in the next call unless the
call ends the packet (``end``: the end of a UDP datagram, of a TCP client's stream), when it is
dropped and counted as ``truncated``. :meth:`~MavlinkWire.encode` packs a message as MAVLink 2
with this system's ids and the channel's sequence number. pymavlink's parser runs with robust
parsing, so a bad CRC, a bad start byte or an unknown message id becomes a counted value;
anything else it might raise on hostile input is caught, counted as ``parser_error`` and the
parser is replaced. No I/O, no clock. No hand-written codec: pymavlink's is used as is.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

from pymavlink.dialects.v20 import ardupilotmega as mav

__all__ = ["MAX_FEED_BYTES", "Decoded", "MavlinkWire", "bad_data_reason"]

MAX_FEED_BYTES = 65536
"""Bytes decoded per call at most (one UDP datagram); beyond, the rest is dropped and
counted as ``oversize``."""


class _Sink:
    """The file pymavlink writes packed messages to: the bytes are collected, not sent."""

    __slots__ = ("data",)

    def __init__(self) -> None:
        self.data = bytearray()

    def write(self, data: bytes) -> None:
        self.data += data


def bad_data_reason(text: str) -> str:
    """A short counter name for one of pymavlink's bad-data reasons."""
    lowered = text.lower()
    if "crc" in lowered:
        return "crc"
    if "unknown" in lowered:
        return "unknown_id"
    if "prefix" in lowered:
        return "garbage"
    if "unpack" in lowered or "length" in lowered:
        return "malformed"
    return "bad_data"


@dataclass(slots=True)
class Decoded:
    """What one :meth:`MavlinkWire.decode` call found.

    Attributes:
        messages: the messages that parsed, in order.
        bad: counts of what did not, by reason (``crc``, ``garbage``, ``unknown_id``,
            ``malformed``, ``bad_data``, ``parser_error``, ``oversize``, ``truncated``).
    """

    messages: list[mav.MAVLink_message] = field(default_factory=list)
    bad: Counter[str] = field(default_factory=Counter)


class MavlinkWire:
    """One channel's MAVLink codec.

    Args:
        system_id: this system's id (ArduSub: SYSID_THISMAV, 1).
        component_id: this component's id (the autopilot, 1).
    """

    def __init__(self, system_id: int = 1, component_id: int = 1) -> None:
        self.system_id = system_id
        self.component_id = component_id
        self._sink = _Sink()
        self._encoder = mav.MAVLink(self._sink, srcSystem=system_id, srcComponent=component_id)
        self._decoder = self._new_decoder()
        self.bytes_in = 0
        self.bytes_out = 0

    @staticmethod
    def _new_decoder() -> mav.MAVLink:
        decoder = mav.MAVLink(None, srcSystem=0, srcComponent=0)
        decoder.robust_parsing = True
        return decoder

    def decode(self, data: bytes, end: bool = False) -> Decoded:
        """Parse ``data``, continuing any packet a previous call left incomplete.

        Args:
            data: any bytes.
            end: ``data`` ends a datagram (or a stream): a packet still incomplete after it is
                dropped and counted as ``truncated`` (its bytes are not joined with the next
                call's, which would make a stray start byte swallow the packets behind it).
        """
        out = Decoded()
        if len(data) > MAX_FEED_BYTES:
            out.bad["oversize"] += 1
            data = data[:MAX_FEED_BYTES]
        self.bytes_in += len(data)
        try:
            parsed = self._decoder.parse_buffer(bytes(data)) or []
        except Exception:  # hostile input must never escape: count it, start afresh
            out.bad["parser_error"] += 1
            self._decoder = self._new_decoder()
            return out
        if end and self._decoder.buf_len() > 0:
            out.bad["truncated"] += 1
            self._decoder = self._new_decoder()  # ≈ 2 µs: cheaper than any datagram's read
        for message in parsed:
            if isinstance(message, mav.MAVLink_bad_data):
                out.bad[bad_data_reason(str(getattr(message, "reason", "")))] += 1
            elif isinstance(message, mav.MAVLink_unknown):  # an id outside the dialect
                out.bad["unknown_id"] += 1
            else:
                out.messages.append(message)
        return out

    def encode(self, message: mav.MAVLink_message) -> bytes:
        """Pack ``message`` as MAVLink 2 from this system and component (next sequence
        number)."""
        self._encoder.srcSystem = self.system_id
        self._encoder.srcComponent = self.component_id
        self._encoder.send(message)
        data = bytes(self._sink.data)
        self._sink.data.clear()
        self.bytes_out += len(data)
        return data
