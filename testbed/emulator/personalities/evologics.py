"""EvoLogics S2C personality: the modem side of its data mode (REFERENCE §1.11), sans-IO.

Commands arrive escaped as ``+++AT<command>`` + line end (CR LF, LF or CR); replies and events
go out as ``+++AT<name>:<len>:<body>`` CR LF. See :mod:`testbed.emulator.personalities` for the
decisions where the reference is silent.
"""

from __future__ import annotations

from collections import deque

from .base import (
    EOL,
    EVOLOGICS_IM_MAX,
    MAX_COMMAND,
    AirPacket,
    EvoLogicsHeader,
    bump,
    find_eol,
    parse_int,
)

__all__ = ["EvoLogicsPersonality"]

_ESCAPE = b"+++AT"


class EvoLogicsPersonality:
    """EvoLogics S2C in data mode (REFERENCE §1.11).

    Args:
        local_address: this modem's address (1..254) until ``AT!AL`` changes it.
        remote_address: destination of burst data (``AT!AR``), 1..255.
        queue_bytes: transmit queue capacity [B]; an instant message that does not fit is
            answered ``ERROR BUFFER FULL``.
        ack_timeout_s: an acknowledged message with no acknowledgement this long after it went
            to the link (its transmission began) is reported ``FAILEDIM`` [s].
        rssi_dbm: RSSI reported in receive events [dBm] (constant: no level model).
        integrity: signal integrity reported in receive events (constant).

    Counters (:meth:`counters`): ``commands``, ``errors`` (commands answered ``ERROR``),
    ``ims_queued``, ``ims_sent``, ``ims_received``, ``ims_dropped_damaged``,
    ``ims_not_for_us``, ``acks_sent``, ``delivered``, ``failed``, ``burst_bytes_sent``,
    ``burst_bytes_received``, ``bursts_dropped_damaged``, ``queue_cleared``.

    Raises:
        ValueError: an address out of range or a non-positive capacity or timeout.
    """

    __slots__ = (
        "_buf",
        "_counts",
        "_pending_acks",
        "_queue",
        "_queued_bytes",
        "_swallow_lf",
        "ack_timeout_s",
        "integrity",
        "local_address",
        "queue_bytes",
        "remote_address",
        "rssi_dbm",
    )

    def __init__(
        self,
        local_address: int,
        *,
        remote_address: int = 255,
        queue_bytes: int = 9000,
        ack_timeout_s: float = 5.0,
        rssi_dbm: int = -50,
        integrity: int = 200,
    ) -> None:
        if not 1 <= local_address <= 254 or not 1 <= remote_address <= 255:
            raise ValueError(f"addresses out of range: {local_address!r}, {remote_address!r}")
        if queue_bytes < 1 or not ack_timeout_s > 0.0:
            raise ValueError(f"need queue_bytes ≥ 1, ack_timeout_s > 0: {queue_bytes!r}")
        self.local_address = local_address
        self.remote_address = remote_address
        self.queue_bytes = queue_bytes
        self.ack_timeout_s = float(ack_timeout_s)
        self.rssi_dbm = rssi_dbm
        self.integrity = integrity
        self._buf = bytearray()
        self._swallow_lf = False
        self._queue: deque[AirPacket] = deque()
        self._queued_bytes = 0
        self._pending_acks: list[tuple[float, int]] = []  # (deadline [s], destination)
        self._counts: dict[str, int] = {}

    # -- user side ---------------------------------------------------------------------------

    def feed(self, data: bytes, now_s: float) -> bytes:
        """Parse ``+++AT`` commands; bytes outside them are queued as burst data."""
        buf = self._buf
        buf += data
        out = bytearray()
        burst = bytearray()
        pos = 0
        while pos < len(buf):
            if self._swallow_lf:
                self._swallow_lf = False
                if buf[pos] == 0x0A:
                    pos += 1
                    continue
            i = buf.find(_ESCAPE, pos)
            if i < 0:
                keep = _escape_prefix_len(buf, pos)
                burst += buf[pos : len(buf) - keep]
                pos = len(buf) - keep
                break
            burst += buf[pos:i]
            end = self._command(buf, i + len(_ESCAPE), out)
            if end is None:
                pos = i
                break
            pos = end
        del buf[:pos]
        if burst:
            header = EvoLogicsHeader(
                "burst", self.local_address, self.remote_address, False, len(burst)
            )
            self._enqueue(AirPacket(bytes(burst), header))
            bump(self._counts, "burst_bytes_sent", len(burst))
        return bytes(out)

    def _command(self, buf: bytearray, start: int, out: bytearray) -> int | None:
        """Answer the command at ``start`` (after ``+++AT``); the index after it, None to wait."""
        if buf[start : start + 8] == b"*SENDIM,":
            return self._sendim(buf, start, out)
        if b"*SENDIM,".startswith(bytes(buf[start : start + 8])):
            return None  # could still become a SENDIM
        eol = find_eol(buf, start, start + MAX_COMMAND)
        if eol < 0:
            if len(buf) - start < MAX_COMMAND:
                return None
            self._reply(out, "", "ERROR WRONG FORMAT")  # a line too long to be a command
            return start
        line = bytes(buf[start:eol])
        self._line(line, out)
        return self._after_eol(buf, eol)

    def _after_eol(self, buf: bytearray, eol: int) -> int:
        """The index after the line end at ``eol`` (CR LF, LF or CR; a LF after a lone CR at
        the end of the buffer is swallowed when it arrives)."""
        if buf[eol] == 0x0D:
            if eol + 1 < len(buf):
                return eol + 2 if buf[eol + 1] == 0x0A else eol + 1
            self._swallow_lf = True
        return eol + 1

    def _line(self, line: bytes, out: bytearray) -> None:
        """A command other than ``*SENDIM``."""
        bump(self._counts, "commands")
        text = line.decode("ascii", "replace")
        name = _reply_name(text)
        if not line or not line.isascii() or not text.isprintable():
            self._error(out, name, "ERROR WRONG FORMAT")
        elif len(text) == 2 and text[0] == "Z" and text[1] in "01234":
            self._clear_queue()
            self._reply(out, name, "OK")
        elif text == "O":
            self._reply(out, name, "OK")  # already in data mode
        elif text in ("?AL", "?AR"):
            value = self.local_address if text == "?AL" else self.remote_address
            self._reply(out, name, str(value))
        elif text[:3] in ("!AL", "!AR"):
            address = parse_int(text[3:])
            limit = 254 if text[:3] == "!AL" else 255
            if address is None or not 1 <= address <= limit:
                self._error(out, name, "ERROR WRONG FORMAT")
            else:
                if text[:3] == "!AL":
                    self.local_address = address
                else:
                    self.remote_address = address
                self._reply(out, name, "OK")
        else:
            self._error(out, name, "ERROR UNKNOWN COMMAND")

    def _sendim(self, buf: bytearray, start: int, out: bytearray) -> int | None:
        """``*SENDIM,<len>,<dst>,<flag>,<data>`` + line end, the data read by count."""
        fields_start = start + 8
        commas: list[int] = []
        j = fields_start
        while len(commas) < 3:
            k = buf.find(b",", j, fields_start + 24)
            eol = find_eol(buf, j, k if k >= 0 else len(buf))
            if eol >= 0:  # the line ended before the data
                bump(self._counts, "commands")
                self._error(out, "*SENDIM", "ERROR WRONG FORMAT")
                return self._after_eol(buf, eol)
            if k < 0:
                if len(buf) - fields_start < 24:
                    return None
                bump(self._counts, "commands")
                self._error(out, "*SENDIM", "ERROR WRONG FORMAT")
                return start
            commas.append(k)
            j = k + 1
        length = parse_int(bytes(buf[fields_start : commas[0]]).decode("ascii", "replace"))
        dst_field = parse_int(bytes(buf[commas[0] + 1 : commas[1]]).decode("ascii", "replace"))
        dst = -1 if dst_field is None else dst_field
        flag = bytes(buf[commas[1] + 1 : commas[2]])
        data_start = commas[2] + 1
        if length is None:  # no count to read the data by: skip to the line end
            eol = find_eol(buf, data_start, data_start + MAX_COMMAND)
            if eol < 0 and len(buf) - data_start < MAX_COMMAND:
                return None
            bump(self._counts, "commands")
            self._error(out, "*SENDIM", "ERROR WRONG FORMAT")
            return data_start if eol < 0 else self._after_eol(buf, eol)
        end = data_start + length
        if len(buf) <= end:
            return None
        bump(self._counts, "commands")
        if buf[end] not in EOL:
            self._error(out, "*SENDIM", "ERROR WRONG FORMAT")  # data longer than its length
            eol = find_eol(buf, end, len(buf))
            return end if eol < 0 else self._after_eol(buf, eol)
        after = self._after_eol(buf, end)
        ack = flag == b"ack"
        well_formed = (
            1 <= length <= EVOLOGICS_IM_MAX
            and 0 <= dst <= 255
            and flag in (b"ack", b"noack", b"force")
            and not (ack and dst == 255)  # nobody acknowledges a broadcast
        )
        if not well_formed:
            self._error(out, "*SENDIM", "ERROR WRONG FORMAT")
        elif self._queued_bytes + length > self.queue_bytes:
            self._error(out, "*SENDIM", "ERROR BUFFER FULL")
        else:
            data = bytes(buf[data_start:end])
            header = EvoLogicsHeader("im", self.local_address, dst, ack, length)
            self._enqueue(AirPacket(data, header))
            bump(self._counts, "ims_queued")
            self._reply(out, "*SENDIM", "OK")
        return after

    def _enqueue(self, packet: AirPacket, *, first: bool = False) -> None:
        if first:
            self._queue.appendleft(packet)
        else:
            self._queue.append(packet)
        self._queued_bytes += len(packet.data)

    def _clear_queue(self) -> None:
        if self._queue:
            bump(self._counts, "queue_cleared", len(self._queue))
        self._queue.clear()
        self._queued_bytes = 0

    def _reply(self, out: bytearray, name: str, body: str) -> None:
        out += _wrap(name, body.encode("ascii"))

    def _error(self, out: bytearray, name: str, body: str) -> None:
        bump(self._counts, "errors")
        self._reply(out, name, body)

    # -- link side ---------------------------------------------------------------------------

    def next_packet(self, now_s: float) -> AirPacket | None:
        """Pop the next packet; an acknowledged message starts its timeout."""
        if not self._queue:
            return None
        packet = self._queue.popleft()
        self._queued_bytes -= len(packet.data)
        header = packet.header
        if isinstance(header, EvoLogicsHeader) and header.kind == "im":
            bump(self._counts, "ims_sent")
            if header.ack:
                self._pending_acks.append((now_s + self.ack_timeout_s, header.dst))
        return packet

    def receive(
        self, packet: AirPacket, data: bytes, *, bit_errors: int, duration_s: float, now_s: float
    ) -> bytes:
        """An RECVIM event, burst bytes, a DELIVEREDIM event, or nothing (dropped, counted)."""
        header = packet.header
        if not isinstance(header, EvoLogicsHeader):
            return b""
        counts = self._counts
        if bit_errors:
            bump(
                counts,
                "bursts_dropped_damaged" if header.kind == "burst" else "ims_dropped_damaged",
            )
            return b""
        if header.dst not in (self.local_address, 255):
            bump(counts, "ims_not_for_us")
            return b""
        data = data[: header.length]
        if header.kind == "burst":
            bump(counts, "burst_bytes_received", len(data))
            return data
        if header.kind == "ack":
            for k, (_, dst) in enumerate(self._pending_acks):
                if dst == header.src:
                    del self._pending_acks[k]
                    bump(counts, "delivered")
                    return _wrap("", b"DELIVEREDIM,%d" % header.src)
            return b""  # late: already reported FAILEDIM
        bump(counts, "ims_received")
        if header.ack and header.dst == self.local_address:
            ack = EvoLogicsHeader("ack", self.local_address, header.src, False, 1)
            self._enqueue(AirPacket(b"\x06", ack), first=True)
            bump(counts, "acks_sent")
        body = b"RECVIM,%d,%d,%d,%s,%d,%d,%d,0.0000," % (
            len(data),
            header.src,
            header.dst,
            b"ack" if header.ack else b"noack",
            round(duration_s * 1e6),
            self.rssi_dbm,
            self.integrity,
        )
        return _wrap("", body + data)

    def poll(self, now_s: float) -> bytes:
        """``FAILEDIM,<dst>`` for each acknowledged message whose timeout passed."""
        out = bytearray()
        while self._pending_acks and self._pending_acks[0][0] <= now_s:
            _, dst = self._pending_acks.pop(0)
            bump(self._counts, "failed")
            out += _wrap("", b"FAILEDIM,%d" % dst)
        return bytes(out)

    def counters(self) -> dict[str, int]:
        """See the class docstring (names absent until they count)."""
        return dict(self._counts)


def _reply_name(text: str) -> str:
    """The name a reply echoes: the command up to its first comma, if it is made of command
    characters (letters, digits, ``*!?@&``); empty otherwise, so a garbled command cannot
    garble the reply's framing."""
    name = text.split(",", 1)[0]
    return name if all(c.isascii() and (c.isalnum() or c in "*!?@&") for c in name) else ""


def _wrap(name: str, body: bytes) -> bytes:
    """Data-mode reply or event: ``+++AT<name>:<len>:<body>`` CR LF."""
    return b"+++AT" + name.encode("ascii", "replace") + b":%d:" % len(body) + body + EOL


def _escape_prefix_len(buf: bytearray, pos: int) -> int:
    """Length of the longest tail of ``buf[pos:]`` that is a proper prefix of ``+++AT``."""
    for keep in range(min(len(_ESCAPE) - 1, len(buf) - pos), 0, -1):
        if buf.endswith(_ESCAPE[:keep]):
            return keep
    return 0
