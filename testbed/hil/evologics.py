"""EvoLogics S2C adapter for the modem's data mode (sans-IO; REFERENCE §1.11).

In data mode the port is transparent, and commands are escaped with ``+++``: we send each frame
as instant messages ``+++AT*SENDIM,<len>,<addr>,<ack|noack>,<data>`` (≤ 64 B each; a longer
frame is several messages, joined again by the receiver's frame decoder). The modem wraps its
replies and events as ``+++AT<cmd>:<len>:<body>`` CR LF, the body ``len`` bytes long, so binary
bodies with commas, CR or LF are read by count. Received instant messages arrive as the event
``RECVIM,<len>,<src>,<dst>,<ack>,<duration>,<rssi>,<integrity>,<velocity>,<data>`` (``RECVIMS``
has a timestamp for the ack field; ``RECVPBM`` has no ack field); their data is cut from the end
of the body by its length, so commas in the data do not matter. Bytes outside the wrappers are
burst data from a peer in transparent mode and are passed on as payload stream.

Packet boundary (:meth:`EvoLogicsAdapter.receive`): a frame is one instant message, or several
when longer than 64 B, so the end of a frame's *last* message ends the packet: a message shorter
than 64 B (the sender cuts frames into 64-B pieces, the last one shorter or full), or the message
that completes the length the frame's first message announced (its preamble and length byte).
A message starting a new frame while the previous one is still short of its length ends that one
first (its last message was lost). Idle time is no boundary: the messages of one frame are an
acoustic slot apart.

No I/O, no clock. Remote garbage never raises.
"""

from __future__ import annotations

from testbed.protocol import START_BYTE, frame_overhead

from .adapters import Segment, SegmentStream, Write, is_printable

__all__ = ["SENDIM_MAX", "EvoLogicsAdapter", "parse_received_message"]

SENDIM_MAX = 64
"""Largest instant-message payload [B] (REFERENCE §1.11)."""

_ESCAPE = b"+++AT"
_CRLF = b"\r\n"
_MAX_CMD_LEN = 32
_MAX_BODY_LEN = 4096
_RECEIVE_FIELDS = {b"RECVIM": 8, b"RECVIMS": 8, b"RECVPBM": 7}
"""Comma-separated fields between the event name and the data, by receive event."""


def parse_received_message(body: bytes) -> tuple[bytes, list[bytes], bytes] | None:
    """Split a RECVIM / RECVIMS / RECVPBM event body.

    Args:
        body: the event body, e.g. ``b"RECVIM,3,1,2,noack,1125,-46,191,0.0,a,b"``.

    Returns:
        ``(name, fields, data)`` with the fields between the name and the data
        (``fields[0]`` is the data length), or None if the body is not a well-formed receive
        event (unknown name, wrong field count, length field not matching the data).
    """
    name, sep, rest = body.partition(b",")
    n_fields = _RECEIVE_FIELDS.get(name)
    if n_fields is None or not sep:
        return None
    length_text, sep, _ = rest.partition(b",")
    if not sep or not length_text.isdigit() or len(length_text) > 4:
        return None
    length = int(length_text)
    if length > len(rest):
        return None
    head = rest[: len(rest) - length]
    data = rest[len(rest) - length :]
    if not head.endswith(b","):
        return None
    fields = head[:-1].split(b",")
    if len(fields) != n_fields or not is_printable(head):
        return None
    return name, fields, data


class EvoLogicsAdapter:
    """EvoLogics S2C in data mode: frames as instant messages, events parsed and counted.

    Args:
        remote_address: acoustic address of the peer modem (1..254).
        ack: ask the modem for delivery reports (``ack``) instead of ``noack``.
        message_hold_s: hold after each instant message [s], so the modem is not handed a new
            message while one is on the air (it answers ``BUSY``/``ERROR`` otherwise; those
            are counted in :attr:`event_counts`).
        line_end: terminator of the commands we send.
        local_address: this modem's acoustic address (1..254), set with ``AT!AL`` on open; None
            leaves the modem's own setting.
        preamble_len: preamble length of our frames (1 or 3), to follow frames across messages.

    Attributes:
        messages_in: instant messages received (RECVIM, RECVIMS, RECVPBM).
        event_counts: replies and events by name: ``"OK"``, ``"DELIVEREDIM"``,
            ``"FAILEDIM"``, ``"BUSY"``, ``"ERROR"``…  (the body up to the first comma or space).
        parse_errors: ``+++AT`` wrappers or receive events that did not parse.
        garbage_bytes: bytes dropped with a bad wrapper [B].
        transparent_bytes: bytes received outside wrappers and passed on [B].
        bytes_in: bytes received [B].

    Raises:
        ValueError: address out of range, bad ``preamble_len``.
    """

    __slots__ = (
        "_buf",
        "_flag",
        "_preamble",
        "_remaining",
        "_stream",
        "bytes_in",
        "event_counts",
        "garbage_bytes",
        "line_end",
        "local_address",
        "message_hold_s",
        "messages_in",
        "parse_errors",
        "remote_address",
        "transparent_bytes",
    )

    def __init__(
        self,
        remote_address: int,
        *,
        ack: bool = False,
        message_hold_s: float = 0.0,
        line_end: bytes = b"\n",
        local_address: int | None = None,
        preamble_len: int = 3,
    ) -> None:
        frame_overhead(preamble_len)  # validates preamble_len
        if not 1 <= remote_address <= 254:
            raise ValueError(f"remote_address must be in 1..254, got {remote_address!r}")
        if local_address is not None and not 1 <= local_address <= 254:
            raise ValueError(f"local_address must be in 1..254, got {local_address!r}")
        self.local_address = local_address
        if message_hold_s < 0:
            raise ValueError(f"message_hold_s must be >= 0, got {message_hold_s!r}")
        self.remote_address = remote_address
        self._flag = b"ack" if ack else b"noack"
        self.message_hold_s = float(message_hold_s)
        self.line_end = bytes(line_end)
        self._buf = bytearray()
        self._preamble = bytes([START_BYTE]) * preamble_len
        self._remaining = 0
        self._stream = SegmentStream()
        self.messages_in = 0
        self.event_counts: dict[str, int] = {}
        self.parse_errors = 0
        self.garbage_bytes = 0
        self.transparent_bytes = 0
        self.bytes_in = 0

    def command(self, text: str) -> bytes:
        """A data-mode command: ``+++`` + ``text`` (e.g. ``"AT?MODE"``) + line end."""
        return b"+++" + text.encode("ascii") + self.line_end

    def setup(self) -> list[Write]:
        """Sent on each open: ``+++ATZ4`` drops instant messages still queued in the modem from
        before (a reopened port must not replay stale orders; DESERT's ms2c_evologics driver
        does the same), then ``+++AT!AL<n>`` if a local address was given. The modem must be
        in data mode (``ATO`` from command mode); its replies are parsed and counted."""
        out = [Write(self.command("ATZ4"))]
        if self.local_address is not None:
            out.append(Write(self.command(f"AT!AL{self.local_address}")))
        return out

    def writes(self, frame: bytes) -> list[Write]:
        """One ``+++AT*SENDIM`` per ≤ 64 B piece of the frame."""
        frame = bytes(frame)
        addr = str(self.remote_address).encode("ascii")
        out: list[Write] = []
        for i in range(0, len(frame), SENDIM_MAX):
            piece = frame[i : i + SENDIM_MAX]
            head = b"+++AT*SENDIM,%d,%s,%s," % (len(piece), addr, self._flag)
            out.append(Write(head + piece + self.line_end, self.message_hold_s))
        return out

    def feed(self, data: bytes) -> bytes:
        """Parse wrapped events; return received message data and transparent bytes."""
        return b"".join(segment.data for segment in self.receive(data))

    def idle(self) -> list[Segment]:
        """Nothing: the modem frames its messages (see the module's packet boundary)."""
        return []

    def receive(self, data: bytes) -> list[Segment]:
        """:meth:`feed`, cut after the last message of each frame (the module's packet
        boundary)."""
        self.bytes_in += len(data)
        buf = self._buf
        buf += data
        out = self._stream.out
        pos = 0
        while True:
            i = buf.find(_ESCAPE, pos)
            if i < 0:
                keep = _partial_escape(buf, pos)
                self.transparent_bytes += len(buf) - keep - pos
                out += buf[pos : len(buf) - keep]
                pos = len(buf) - keep
                break
            self.transparent_bytes += i - pos
            out += buf[pos:i]
            pos = i
            end = self._wrapped(buf, i, out)
            if end is None:
                break
            pos = end
        del buf[:pos]
        return self._stream.take()

    def _end_packet(self) -> None:
        """A packet ends after the payload stream so far."""
        self._stream.end_packet()

    def _message(self, data: bytes) -> None:
        """One received instant message's data: into the stream, and the packet boundary."""
        plen = len(self._preamble)
        starts = data.startswith(self._preamble) and len(data) > plen
        if starts and self._remaining:
            self._end_packet()  # the previous frame's last message was lost
        if starts:
            self._remaining = plen + 1 + data[plen] + 2
        self._remaining = max(0, self._remaining - len(data))
        self._stream.out += data
        if len(data) < SENDIM_MAX or not self._remaining:
            self._remaining = 0
            self._end_packet()

    def _wrapped(self, buf: bytearray, i: int, out: bytearray) -> int | None:
        """Parse ``+++AT<cmd>:<len>:<body>`` CR LF at ``i``; the index after it, None to wait."""
        start = i + len(_ESCAPE)
        colon = buf.find(b":", start, start + _MAX_CMD_LEN + 1)
        if colon < 0:
            if len(buf) - start <= _MAX_CMD_LEN and is_printable(buf[start:]):
                return None
            return self._bad(i)
        cmd = bytes(buf[start:colon])
        colon2 = buf.find(b":", colon + 1, colon + 6)
        if colon2 < 0:
            tail = bytes(buf[colon + 1 :])
            if (len(tail) < 5 and tail.isdigit()) or not tail:
                return None
            return self._bad(i)
        length_text = bytes(buf[colon + 1 : colon2])
        if not is_printable(cmd) or not length_text.isdigit():
            return self._bad(i)
        length = int(length_text)
        if length > _MAX_BODY_LEN:
            return self._bad(i)
        body_end = colon2 + 1 + length
        if len(buf) < body_end + len(_CRLF):
            return None
        if buf[body_end : body_end + 2] != _CRLF:
            return self._bad(i)
        body = bytes(buf[colon2 + 1 : body_end])
        self._event(cmd, body, out)
        return body_end + 2

    def _bad(self, i: int) -> int:
        """Drop the ``+++AT`` of a malformed wrapper and hunt on after it."""
        self.parse_errors += 1
        self.garbage_bytes += len(_ESCAPE)
        return i + len(_ESCAPE)

    def _event(self, cmd: bytes, body: bytes, out: bytearray) -> None:
        received = parse_received_message(body)
        if received is not None:
            self.messages_in += 1
            self._count(received[0].decode("ascii"))
            self._message(received[2])
            return
        if body.startswith(tuple(_RECEIVE_FIELDS)):
            self.parse_errors += 1
            return
        name = body.split(b",", 1)[0].split(b" ", 1)[0]
        if not is_printable(name) or not name:
            self.parse_errors += 1
            return
        self._count(name.decode("ascii"))

    def _count(self, name: str) -> None:
        self.event_counts[name] = self.event_counts.get(name, 0) + 1

    def counters(self) -> dict[str, int]:
        """Messages in, parse errors, garbage, transparent bytes, bytes in, and each event."""
        counts = {
            "bytes_in": self.bytes_in,
            "messages_in": self.messages_in,
            "parse_errors": self.parse_errors,
            "garbage_bytes": self.garbage_bytes,
            "transparent_bytes": self.transparent_bytes,
        }
        counts.update({f"event_{name}": n for name, n in self.event_counts.items()})
        return counts


def _partial_escape(buf: bytearray, pos: int) -> int:
    """Length of the longest tail of ``buf[pos:]`` that is a proper prefix of ``+++AT``."""
    for keep in range(min(len(_ESCAPE) - 1, len(buf) - pos), 0, -1):
        if buf.endswith(_ESCAPE[:keep]):
            return keep
    return 0
