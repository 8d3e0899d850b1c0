"""Water Linked Modem-M64 personality (REFERENCE §1.12; modem-python's protocol), sans-IO.

Sentences ``w`` + ``c`` + command letter [``,options``] [``*xx``] LF in, ``wr…`` answers out;
``wcq,8,<8 raw bytes>`` is read by count. See :mod:`testbed.emulator.personalities`
for the decisions
where the reference is silent.
"""

from __future__ import annotations

from collections import deque

from .base import EOL, M64_PAYLOAD, MAX_COMMAND, AirPacket, M64Header, bump, find_eol, parse_int

__all__ = ["M64Personality", "m64_crc8"]


def _m64_crc_table() -> tuple[int, ...]:
    """Table of the CRC-8 with polynomial x⁸ + x² + x + 1 (0x07), MSB first."""
    table = []
    for byte in range(256):
        crc = byte
        for _ in range(8):
            crc = (crc << 1) ^ (0x07 if crc & 0x80 else 0)
        table.append(crc & 0xFF)
    return tuple(table)


_M64_CRC_TABLE = _m64_crc_table()


def m64_crc8(data: bytes) -> int:
    """CRC-8 of an M64 sentence: poly 0x07, init 0, no reflection, no final XOR (check 0xF4)."""
    crc = 0
    for byte in data:
        crc = _M64_CRC_TABLE[crc ^ byte]
    return crc


class M64Personality:
    """Water Linked Modem-M64 (REFERENCE §1.12; waterlinked modem-python's protocol).

    Args:
        role: ``"a"`` or ``"b"`` until ``wcs`` changes it.
        channel: acoustic channel 1..7 until ``wcs`` changes it.
        queue_packets: transmit queue capacity [packets]; ``wcq`` on a full queue → ``wrq,n``.
        version: answer to ``wcv`` (major 1: modem-python refuses others).
        link_timeout_s: ``wcd`` reports the link up while the last good packet from a peer is
            younger than this [s].

    Counters (:meth:`counters`): ``sentences``, ``errors`` (answered ``wr?`` or ``…,n``),
    ``crc_errors``, ``garbage_bytes`` (outside sentences), ``packets_queued``,
    ``packets_sent``, ``packets_received``, ``packets_lost`` (damaged, dropped),
    ``packets_not_heard`` (same role or other channel), ``flushed``.

    Raises:
        ValueError: bad role, channel or capacity.
    """

    __slots__ = (
        "_buf",
        "_checksum_out",
        "_counts",
        "_last_good_s",
        "_queue",
        "channel",
        "link_timeout_s",
        "queue_packets",
        "role",
        "version",
    )

    def __init__(
        self,
        role: str,
        *,
        channel: int = 4,
        queue_packets: int = 16,
        version: tuple[int, int, int] = (1, 0, 1),
        link_timeout_s: float = 3.0,
    ) -> None:
        if role not in ("a", "b") or not 1 <= channel <= 7 or queue_packets < 1:
            raise ValueError(f"bad role/channel/queue: {role!r}, {channel!r}, {queue_packets!r}")
        self.role = role
        self.channel = channel
        self.queue_packets = queue_packets
        self.version = version
        self.link_timeout_s = link_timeout_s
        self._buf = bytearray()
        self._queue: deque[bytes] = deque()
        self._checksum_out = True
        self._last_good_s = -float("inf")
        self._counts: dict[str, int] = {}

    def feed(self, data: bytes, now_s: float) -> bytes:
        """Parse sentences and answer each; bytes outside sentences are counted and ignored."""
        buf = self._buf
        buf += data
        out = bytearray()
        pos = 0
        while pos < len(buf):
            if buf[pos] in EOL:
                pos += 1
                continue
            start = buf.find(b"w", pos)
            stray = buf[pos : len(buf) if start < 0 else start]
            bump(
                self._counts, "garbage_bytes", len(stray) - stray.count(b"\r") - stray.count(b"\n")
            )
            if start < 0:
                pos = len(buf)
                break
            end = self._sentence(buf, start, out, now_s)
            if end is None:
                pos = start
                break
            pos = end
        del buf[:pos]
        return bytes(out)

    def _sentence(self, buf: bytearray, start: int, out: bytearray, now_s: float) -> int | None:
        """Answer the sentence at ``start``; the index after it, None to wait for bytes."""
        if buf[start + 1 : start + 4] == b"cq,":
            comma = buf.find(b",", start + 4, start + 8)
            if comma < 0 and len(buf) - start < 8:
                return None
            count = parse_int(bytes(buf[start + 4 : comma]).decode("ascii", "replace"))
            if comma >= 0 and count is not None and count <= 64:
                raw_end = comma + 1 + count
                if len(buf) <= raw_end:
                    return None
                if buf[raw_end] == 0x2A and len(buf) < raw_end + 4:  # '*' then 2 hex and EOL
                    return None
                eol = find_eol(buf, raw_end, raw_end + 4)
                if eol >= 0:
                    self._answer(bytes(buf[start:eol]), (comma + 1 - start, count), out, now_s)
                    return eol + 1
        eol = find_eol(buf, start, start + MAX_COMMAND)
        if eol < 0:
            if len(buf) - start < MAX_COMMAND:
                return None
            eol = start + MAX_COMMAND - 1
        self._answer(bytes(buf[start:eol]), None, out, now_s)
        return eol + 1

    def _answer(
        self, sentence: bytes, raw: tuple[int, int] | None, out: bytearray, now_s: float
    ) -> None:
        """Check one sentence and act on it; ``raw``: where ``wcq``'s raw bytes start and how
        many there are (None for a sentence without raw bytes)."""
        counts = self._counts
        bump(counts, "sentences")
        if raw is None:
            checksum = len(sentence) >= 6 and sentence[-3] == 0x2A
        else:
            checksum = len(sentence) == raw[0] + raw[1] + 3 and sentence[-3] == 0x2A
        if checksum:
            text = sentence[-2:]
            sentence = sentence[:-3]
            if not _is_hex(text) or int(text, 16) != m64_crc8(sentence):
                bump(counts, "crc_errors")
                self._respond(out, b"?", [], checksum)
                return
        self._checksum_out = checksum
        if len(sentence) < 3 or sentence[1:2] != b"c":
            self._respond(out, b"?", [], checksum)
            return
        cmd = sentence[2:3]
        if raw is not None:
            options = [sentence[4 : raw[0] - 1], sentence[raw[0] :]]
        else:
            options = sentence[4:].split(b",") if len(sentence) > 3 else []
            if len(sentence) > 3 and sentence[3:4] != b",":
                cmd = b"?"
        reply = self._command(cmd, options, now_s)
        if reply is None:
            self._respond(out, b"?", [], checksum)
        else:
            self._respond(out, cmd, reply, checksum)

    def _command(self, cmd: bytes, options: list[bytes], now_s: float) -> list[bytes] | None:
        """The answer's options, or None for ``wr?``."""
        nack = [b"n"]
        if cmd == b"q":
            if len(options) != 2 or options[0] != b"%d" % M64_PAYLOAD:
                return nack
            packet = options[1]
            if len(packet) != M64_PAYLOAD:
                return nack
            if len(self._queue) >= self.queue_packets:
                return nack
            self._queue.append(packet)
            bump(self._counts, "packets_queued")
            return [b"a"]
        if options and cmd in b"vnlfcd":
            return None  # these take no options
        if cmd == b"v":
            return [b"%d" % v for v in self.version]
        if cmd == b"n":
            return [b"%d" % M64_PAYLOAD]
        if cmd == b"l":
            return [b"%d" % len(self._queue)]
        if cmd == b"f":
            bump(self._counts, "flushed", len(self._queue))
            self._queue.clear()
            return [b"a"]
        if cmd == b"c":
            return [self.role.encode("ascii"), b"%d" % self.channel]
        if cmd == b"d":
            up = b"y" if now_s - self._last_good_s < self.link_timeout_s else b"n"
            good = self._counts.get("packets_received", 0)
            lost = self._counts.get("packets_lost", 0)
            bits = 8 * M64_PAYLOAD * (good + lost)
            ber = self._counts.get("bit_errors", 0) / bits if bits else 0.0
            return [up, b"%d" % good, b"%d" % lost, b"%.6f" % ber]
        if cmd == b"s":
            if len(options) != 2 or options[0] not in (b"a", b"b"):
                return nack
            if not (len(options[1]) == 1 and options[1] in b"1234567"):
                return nack
            self.role = options[0].decode("ascii")
            self.channel = int(options[1])
            return [b"a"]
        return None

    def _respond(self, out: bytearray, cmd: bytes, options: list[bytes], checksum: bool) -> None:
        if cmd == b"?" or options == [b"n"]:
            bump(self._counts, "errors")
        out += _m64_sentence(b"r" + cmd, options, checksum)

    def next_packet(self, now_s: float) -> AirPacket | None:
        """Pop the next queued 8-byte packet."""
        if not self._queue:
            return None
        bump(self._counts, "packets_sent")
        return AirPacket(self._queue.popleft(), M64Header(self.role, self.channel))

    def receive(
        self, packet: AirPacket, data: bytes, *, bit_errors: int, duration_s: float, now_s: float
    ) -> bytes:
        """``wrp,8,<8 bytes>[*xx]`` LF for a good packet from a peer; nothing otherwise."""
        header = packet.header
        if not isinstance(header, M64Header):
            return b""
        if header.role == self.role or header.channel != self.channel:
            bump(self._counts, "packets_not_heard")
            return b""
        if bit_errors:
            bump(self._counts, "packets_lost")
            bump(self._counts, "bit_errors", bit_errors)
            return b""
        self._last_good_s = now_s
        bump(self._counts, "packets_received")
        payload = data[:M64_PAYLOAD]
        return _m64_sentence(b"rp", [b"%d" % len(payload), payload], self._checksum_out)

    def poll(self, now_s: float) -> bytes:
        """Nothing: the M64 has no timed events here."""
        return b""

    def counters(self) -> dict[str, int]:
        """See the class docstring (names absent until they count)."""
        return dict(self._counts)


def _m64_sentence(head: bytes, options: list[bytes], checksum: bool) -> bytes:
    """``w`` + direction and command + ``,options`` [+ ``*xx``] + LF."""
    body = b"w" + head + b"".join(b"," + option for option in options)
    if checksum:
        body += b"*%02x" % m64_crc8(body)
    return body + b"\n"


def _is_hex(text: bytes) -> bool:
    return len(text) == 2 and all(c in b"0123456789abcdefABCDEF" for c in text)
