"""Water Linked Modem-M64 adapter (sans-IO; REFERENCE §1.12, waterlinked modem-python).

The M64 carries fixed 8-byte packets (≈ 1 per second). Its UART protocol is ASCII sentences:
``w``, direction ``c`` (command) or ``r`` (response), a command letter, ``,options``, an
optional ``*xx`` CRC-8 (poly 0x07, init 0, lowercase hex over everything before the ``*``) and
LF (CR LF is accepted). Packets are queued with ``wcq,8,<8 raw bytes>`` (answer ``wrq,a``) and
arrive as ``wrp,8,<8 raw bytes>``: after ``w?q,<n>,`` or ``w?p,<n>,`` the next ``n`` bytes are
raw and may hold CR, LF, ``*`` or ``w``, so they are read by count.

Fragmentation: each of our frames starts a new packet and the last packet is padded with zero
bytes. Reassembly follows the frame header (preamble + length byte) at the start of a packet to
know where the frame ends and drops the padding after it. A packet starting with a whole
preamble always starts a new frame, so a lost packet costs only the frame it belonged to; all
non-padding bytes go to the frame decoder, which rejects the damaged frame by its CRC.

Packet boundary (:meth:`M64Adapter.receive`): one frame is several 8-byte packets, seconds
apart, so the end of a modem *message* is the end of the frame's last packet, not of each
packet: the packet that completes the length its first packet announced, a packet that is not
part of a frame the adapter follows, and, before a packet that starts a new frame, the previous
frame if it is still short of its length (its last packets were lost). A frame decoder that
is still waiting for bytes there holds a mis-framed candidate (a corrupted length byte, whose
claim the adapter followed too): it gives it up instead of holding the next frames for the
packets its false length claims. Idle time is no boundary.

No I/O, no clock. Remote garbage never raises.
"""

from __future__ import annotations

from collections.abc import Sequence

from testbed.protocol import START_BYTE, frame_overhead

from .adapters import Segment, SegmentStream, Write, is_printable

__all__ = [
    "CRC8_CHECK_VALUE",
    "M64_PACKET_SIZE",
    "M64Adapter",
    "crc8",
    "m64_sentence",
]

M64_PACKET_SIZE = 8
"""Payload of one M64 packet [B]."""

CRC8_CHECK_VALUE = 0xF4
"""CRC-8 (poly 0x07, init 0) of ``b"123456789"``."""

_MAX_LINE = 64
_PAD = 0x00


def _crc8_table() -> tuple[int, ...]:
    table = []
    for byte in range(256):
        crc = byte
        for _ in range(8):
            crc = ((crc << 1) ^ 0x07) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
        table.append(crc)
    return tuple(table)


_CRC8_TABLE = _crc8_table()


def crc8(data: bytes | bytearray) -> int:
    """CRC-8 as used by the M64: poly 0x07, init 0, no reflection, no final XOR."""
    crc = 0
    for byte in data:
        crc = _CRC8_TABLE[crc ^ byte]
    return crc


def m64_sentence(
    command: str, options: Sequence[bytes] = (), *, direction: str = "c", checksum: bool = False
) -> bytes:
    """One M64 sentence, e.g. ``m64_sentence("s", [b"a", b"4"])`` → ``b"wcs,a,4\\n"``.

    Args:
        command: command letter (``v``, ``n``, ``c``, ``s``, ``q``, ``l``, ``f``, ``d``, ``p``).
        options: comma-joined options (raw bytes for ``q``/``p``).
        direction: ``"c"`` command or ``"r"`` response.
        checksum: append ``*xx``.

    Raises:
        ValueError: command or direction not one letter.
    """
    if len(command) != 1 or direction not in ("c", "r"):
        raise ValueError(f"bad command {command!r} or direction {direction!r}")
    body = b"w" + direction.encode("ascii") + command.encode("ascii")
    if options:
        body += b"," + b",".join(options)
    if checksum:
        body += b"*%02x" % crc8(body)
    return body + b"\n"


class M64Adapter:
    """Water Linked Modem-M64: frames in 8-byte ``wcq`` packets, ``wrp`` packets reassembled.

    Args:
        checksum: append ``*xx`` to the sentences we send.
        packet_hold_s: hold after each queued packet [s] (0: the modem's queue buffers them).
        preamble_len: preamble length of our frames (1 or 3); with 1 a data packet starting with
            0x55 is taken for a frame start 1 time in 256, so 3 is advised.
        role: ``"a"`` or ``"b"``: configure the modem on open with ``wcs,<role>,<channel>``
            (peers need different roles, same channel); None leaves its settings alone.
        channel: acoustic channel 1..7 (used with ``role``).

    Attributes:
        packets_in: data packets received (``wrp``) with a good or absent CRC.
        crc_errors: sentences whose ``*xx`` did not match (dropped).
        parse_errors: malformed sentences (dropped).
        garbage_bytes: bytes outside sentences [B].
        padding_bytes: padding dropped from the last packet of a frame [B].
        acks: ``wrq,a`` answers; nacks: other ``wrq`` answers.
        replies: other response sentences (version, diagnostics…); last_reply: the last one.
        bytes_in: bytes received [B].

    Raises:
        ValueError: negative hold, bad ``preamble_len``, role or channel.
    """

    __slots__ = (
        "_buf",
        "_preamble",
        "_remaining",
        "_stream",
        "acks",
        "bytes_in",
        "channel",
        "checksum",
        "crc_errors",
        "garbage_bytes",
        "last_reply",
        "nacks",
        "packet_hold_s",
        "packets_in",
        "padding_bytes",
        "parse_errors",
        "replies",
        "role",
    )

    def __init__(
        self,
        *,
        checksum: bool = True,
        packet_hold_s: float = 0.0,
        preamble_len: int = 3,
        role: str | None = None,
        channel: int = 4,
    ) -> None:
        if packet_hold_s < 0:
            raise ValueError(f"packet_hold_s must be >= 0, got {packet_hold_s!r}")
        if role not in (None, "a", "b"):
            raise ValueError(f"role must be 'a', 'b' or None, got {role!r}")
        if not 1 <= channel <= 7:
            raise ValueError(f"channel must be in 1..7, got {channel!r}")
        self.role = role
        self.channel = channel
        frame_overhead(preamble_len)  # validates preamble_len
        self.checksum = checksum
        self.packet_hold_s = float(packet_hold_s)
        self._preamble = bytes([START_BYTE]) * preamble_len
        self._buf = bytearray()
        self._remaining = 0
        self._stream = SegmentStream()
        self.packets_in = 0
        self.crc_errors = 0
        self.parse_errors = 0
        self.garbage_bytes = 0
        self.padding_bytes = 0
        self.acks = 0
        self.nacks = 0
        self.replies = 0
        self.last_reply = b""
        self.bytes_in = 0

    def setup(self) -> list[Write]:
        """Sent on each open, as Water Linked's own library connects: a lone LF (ends any half
        sentence the modem holds), ``wcv`` (version) and ``wcn`` (payload size), whose answers
        are counted as replies; ``wcs,<role>,<channel>`` when a role was given; and ``wcf``,
        which flushes packets queued before the (re)open so no stale frame goes out."""
        sentences = [b"\n", self._command("v"), self._command("n")]
        if self.role is not None:
            sentences.append(self._command("s", [self.role.encode(), b"%d" % self.channel]))
        sentences.append(self._command("f"))
        return [Write(s) for s in sentences]

    def _command(self, command: str, options: Sequence[bytes] = ()) -> bytes:
        return m64_sentence(command, options, checksum=self.checksum)

    def writes(self, frame: bytes) -> list[Write]:
        """One ``wcq,8,<packet>`` per 8-byte piece; the last piece padded with zeros."""
        frame = bytes(frame)
        out: list[Write] = []
        size = b"%d" % M64_PACKET_SIZE
        for i in range(0, len(frame), M64_PACKET_SIZE):
            packet = frame[i : i + M64_PACKET_SIZE].ljust(M64_PACKET_SIZE, bytes([_PAD]))
            sentence = m64_sentence("q", [size, packet], checksum=self.checksum)
            out.append(Write(sentence, self.packet_hold_s))
        return out

    def feed(self, data: bytes) -> bytes:
        """Parse sentences; return the reassembled frame bytes of received packets."""
        return b"".join(segment.data for segment in self.receive(data))

    def idle(self) -> list[Segment]:
        """Nothing: packets, not idle time, mark the end of a frame (module docstring)."""
        return []

    def receive(self, data: bytes) -> list[Segment]:
        """:meth:`feed`, cut after the last packet of each frame (the module's packet
        boundary)."""
        self.bytes_in += len(data)
        buf = self._buf
        buf += data
        out = self._stream.out
        pos = 0
        n = len(buf)
        while pos < n:
            if buf[pos] in b"\r\n":
                pos += 1
                continue
            start = buf.find(b"w", pos)
            if start < 0:
                self.garbage_bytes += _non_eol(buf, pos, n)
                pos = n
                break
            self.garbage_bytes += _non_eol(buf, pos, start)
            pos = start
            end = self._sentence(buf, start, out)
            if end is None:
                break
            pos = end
        del buf[:pos]
        return self._stream.take()

    def _end_packet(self) -> None:
        """A modem message ends after the payload stream so far."""
        self._stream.end_packet()

    def _sentence(self, buf: bytearray, start: int, out: bytearray) -> int | None:
        """Parse the sentence at ``start``; the index after it, or None to wait for bytes."""
        n = len(buf)
        if n - start < 3:
            return None
        if buf[start + 1] not in b"cr":
            return self._bad(start)
        if buf[start + 2] in b"qp" and n - start >= 4 and buf[start + 3] == 0x2C:
            counted = self._counted(buf, start, out)
            if counted != 0:
                return counted
        eol = -1
        for terminator in (b"\n", b"\r"):
            j = buf.find(terminator, start, start + _MAX_LINE)
            if j >= 0 and (eol < 0 or j < eol):
                eol = j
        if eol < 0:
            return None if n - start < _MAX_LINE else self._bad(start)
        sentence = self._checked(bytes(buf[start:eol]))
        if sentence is not None:
            if not is_printable(sentence):
                self.parse_errors += 1
            elif sentence[1:3] == b"rq":
                if sentence == b"wrq,a":
                    self.acks += 1
                else:
                    self.nacks += 1
            else:
                self.replies += 1
                self.last_reply = sentence
        return eol + 1

    def _counted(self, buf: bytearray, start: int, out: bytearray) -> int | None:
        """``w?q,<n>,<n raw bytes>[*xx]`` EOL; 0 if this is not a counted sentence."""
        comma = buf.find(b",", start + 4, start + 8)
        if comma < 0:
            digits = bytes(buf[start + 4 : start + 8])
            return None if len(digits) < 4 and (not digits or digits.isdigit()) else 0
        count_text = bytes(buf[start + 4 : comma])
        if not count_text.isdigit():
            return 0
        count = int(count_text)
        raw_end = comma + 1 + count
        if count > _MAX_LINE:
            return self._bad(start)
        n = len(buf)
        if n <= raw_end:
            return None
        crc_text = None
        eol = raw_end
        if buf[raw_end] == 0x2A:  # '*'
            if n < raw_end + 4:
                return None
            crc_text = bytes(buf[raw_end + 1 : raw_end + 3])
            eol = raw_end + 3
        if buf[eol] not in b"\r\n":
            return self._bad(start)
        sentence = bytes(buf[start:raw_end])
        if crc_text is None or self._crc_ok(sentence, crc_text):
            if sentence[1:3] == b"rp":
                self.packets_in += 1
                self._reassemble(sentence[comma + 1 - start :], out)
            else:
                self.replies += 1
                self.last_reply = sentence
        return eol + 1

    def _checked(self, sentence: bytes) -> bytes | None:
        """A line without its ``*xx`` if the CRC matches or is absent; None (counted) if not."""
        if len(sentence) >= 6 and sentence[-3] == 0x2A:
            return sentence[:-3] if self._crc_ok(sentence[:-3], sentence[-2:]) else None
        return sentence

    def _crc_ok(self, body: bytes, text: bytes) -> bool:
        """Check ``text`` (two hex digits) against the CRC-8 of ``body``; count a failure."""
        if len(text) != 2 or not all(c in b"0123456789abcdefABCDEF" for c in text):
            self.parse_errors += 1
            return False
        if int(text, 16) != crc8(body):
            self.crc_errors += 1
            return False
        return True

    def _bad(self, start: int) -> int:
        """A malformed sentence: count it and hunt again after its ``w``."""
        self.parse_errors += 1
        self.garbage_bytes += 1
        return start + 1

    def _reassemble(self, packet: bytes, out: bytearray) -> None:
        """Append one received packet to the payload stream, dropping frame padding."""
        plen = len(self._preamble)
        if packet.startswith(self._preamble) and len(packet) > plen:
            if self._remaining:
                self._end_packet()  # the frame before lost its last packets
            self._remaining = plen + 1 + packet[plen] + 2
        if not self._remaining:
            out += packet  # not part of a frame we can follow: the frame decoder judges it
            self._end_packet()
            return
        take = min(self._remaining, len(packet))
        out += packet[:take]
        self._remaining -= take
        self.padding_bytes += len(packet) - take
        if not self._remaining:
            self._end_packet()

    def counters(self) -> dict[str, int]:
        """Packets, CRC and parse errors, garbage, padding, acks, nacks, replies, bytes in."""
        return {
            "bytes_in": self.bytes_in,
            "packets_in": self.packets_in,
            "crc_errors": self.crc_errors,
            "parse_errors": self.parse_errors,
            "garbage_bytes": self.garbage_bytes,
            "padding_bytes": self.padding_bytes,
            "acks": self.acks,
            "nacks": self.nacks,
            "replies": self.replies,
        }


def _non_eol(buf: bytearray, start: int, end: int) -> int:
    """Bytes in ``buf[start:end]`` other than CR and LF (line ends are not garbage)."""
    return end - start - buf.count(b"\r", start, end) - buf.count(b"\n", start, end)
