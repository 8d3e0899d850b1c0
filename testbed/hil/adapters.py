"""Modem adapters (sans-IO): our frames ⇄ the bytes a modem's serial interface wants.

An adapter sits between the frame codec (:mod:`testbed.protocol`) and a transport. It never does
I/O and never reads a clock:

* :meth:`Adapter.writes` turns one encoded frame into the :class:`Write` chunks to put on the
  port, each with the time the writer must hold off afterwards (air-rate pacing).
* :meth:`Adapter.feed` takes whatever the port returned and gives back the *payload stream*:
  the bytes of our frames, to be fed to a :class:`~testbed.protocol.FrameDecoder`. Modem chatter
  (status lines, replies, command framing) is removed and counted. Remote data never raises;
  a garbled modem sentence is a counter, and stray bytes are passed on for the frame decoder to
  count as garbage.
* :meth:`Adapter.receive` is :meth:`~Adapter.feed` cut into :class:`Segment` values that say
  where a received modem message (a *packet*) ends, and :meth:`Adapter.idle` is what the
  transport calls when the line has been idle for a packet gap. The frame decoder gives up a
  mis-framed candidate (a corrupted length byte claiming more than arrived) at a packet end,
  as the simulated modem's receiver does at the end of each transmission.

Packet boundaries by modem: a byte-transparent modem (:class:`RawAdapter`,
:class:`S100Adapter`) has no message framing on its serial side, so a packet ends when the line
goes idle (:meth:`~Adapter.idle`, detected by the transport); the EvoLogics and M64 adapters
mark the end of the last received message of each frame (their own modules say how) and ignore
idle time, since the messages of one frame may be seconds apart.

This module holds the :class:`Adapter` protocol, :class:`RawAdapter` (a byte-transparent cable
or socket) and :class:`S100Adapter` (WFS Seatooth S100, REFERENCE §1.10). The EvoLogics and
Water Linked adapters live in :mod:`.evologics` and :mod:`.m64`. Nothing here may import
threads, sockets or pyserial.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

from testbed.protocol import START_BYTE, frame_overhead

__all__ = [
    "S100_MAX_STATUS_LEN",
    "S100_MAX_WRITE",
    "Adapter",
    "RawAdapter",
    "S100Adapter",
    "Segment",
    "Write",
]

S100_MAX_WRITE = 45
"""Largest write the S100 takes without RTS/CTS, CR LF included [B] (REFERENCE §1.10)."""

S100_MAX_STATUS_LEN = 200
"""Longest status line the S100 injects, ``+++`` and CR LF excluded [B] (REFERENCE §1.10)."""

_CRLF = b"\r\n"
_PRINTABLE = bytes(range(0x20, 0x7F))


@dataclass(frozen=True, slots=True)
class Write:
    """One write to the port.

    Attributes:
        data: bytes to write.
        hold_s: time the writer waits after this write before the next one [s] (pacing to the
            modem's air rate; 0 when the modem buffers or flow control paces).
    """

    data: bytes
    hold_s: float = 0.0


@dataclass(frozen=True, slots=True)
class Segment:
    """Payload-stream bytes from the adapter, and whether a received packet ends after them.

    Attributes:
        data: bytes for the frame decoder (may be empty when only ``end`` is news).
        end: True if the modem's received message (packet) ends after ``data``: the frame
            decoder then gives up a candidate still incomplete (see the module docstring).
    """

    data: bytes
    end: bool = False


class SegmentStream:
    """The payload-stream bytes an adapter gathers while it parses, cut into
    segments (:class:`Segment`) where a received packet ends.

    Attributes:
        out: bytes gathered since the last segment (append to it while parsing).
    """

    __slots__ = ("_segments", "out")

    def __init__(self) -> None:
        self.out = bytearray()
        self._segments: list[Segment] = []

    def end_packet(self) -> None:
        """A received packet ends after the bytes gathered so far."""
        self._segments.append(Segment(bytes(self.out), end=True))
        self.out.clear()

    def take(self) -> list[Segment]:
        """The segments since the last call, the bytes gathered since the last end included."""
        if self.out:
            self._segments.append(Segment(bytes(self.out)))
            self.out.clear()
        segments, self._segments = self._segments, []
        return segments


class Adapter(Protocol):
    """What a transport needs from a modem adapter."""

    def writes(self, frame: bytes) -> list[Write]:
        """The writes that send one encoded frame."""
        ...

    def feed(self, data: bytes) -> bytes:
        """Received port bytes in; payload-stream bytes (for the frame decoder) out."""
        ...

    def receive(self, data: bytes) -> list[Segment]:
        """:meth:`feed`, with the ends of received packets marked (the bytes joined are what
        :meth:`feed` returns)."""
        ...

    def idle(self) -> list[Segment]:
        """The line has been idle for a packet gap: what that ends (a transparent modem: the
        packet, and bytes held for a possible status line); empty for an adapter whose modem
        frames its messages."""
        ...

    def counters(self) -> dict[str, int]:
        """The adapter's counters by name (status lines, garbage, parse errors…)."""
        ...

    def setup(self) -> list[Write]:
        """The writes that configure the modem, sent each time the port (re)opens, before any
        frame (empty for a modem that needs none)."""
        ...


def is_printable(data: bytes | bytearray) -> bool:
    """True if every byte is printable ASCII (0x20–0x7E)."""
    return not bytes(data).translate(None, _PRINTABLE)


class RawAdapter:
    """Byte-transparent link (a cable, a socket, a transparent modem with flow control).

    Each frame is one write; received bytes are the payload stream unchanged.

    Attributes:
        bytes_in: bytes received [B].
    """

    __slots__ = ("bytes_in",)

    def __init__(self) -> None:
        self.bytes_in = 0

    def writes(self, frame: bytes) -> list[Write]:
        """One write holding the whole frame, no pacing."""
        return [Write(bytes(frame))]

    def feed(self, data: bytes) -> bytes:
        """Return ``data`` unchanged."""
        self.bytes_in += len(data)
        return bytes(data)

    def receive(self, data: bytes) -> list[Segment]:
        """``data`` unchanged; a cable marks no packet end (the idle line does)."""
        return [Segment(bytes(data))] if self.feed(data) else []

    def idle(self) -> list[Segment]:
        """The idle line ends the packet."""
        return [Segment(b"", end=True)]

    def counters(self) -> dict[str, int]:
        """``{"bytes_in": …}``."""
        return {"bytes_in": self.bytes_in}

    def setup(self) -> list[Write]:
        """Nothing: a cable needs no configuration."""
        return []


class S100Adapter:
    """WFS Seatooth S100 transparent RF modem (REFERENCE §1.10).

    Sending: every packet ends in CR LF. Without RTS/CTS the frame plus CR LF goes out in writes
    of at most 45 B, each followed by a hold of ``len·8/pace_bps`` so the modem's buffer never
    overruns (the S100Stream rule). With ``rtscts=True`` the frame and CR LF are one write and
    the port's hardware flow control paces it.

    Receiving: a packet ends when the line goes idle (:meth:`idle`), the serial side having no
    message framing. The modem injects status lines ``+++<printable text>`` CR LF (at most 200
    chars) anywhere in the stream; they are removed, counted and the last one kept. A ``+++`` not
    followed by printable text and CR LF within 200 chars is data. The CR LF that ends each of
    our frames is removed: the adapter follows the frame header (preamble and length byte) in
    the outgoing stream to know where a frame ends. Every other byte is passed on, so a
    corrupted length byte costs at most a CR LF left in the stream (which the frame decoder
    counts as garbage). Status lines are recognised inside frames too, so a frame whose payload
    happens to hold ``+++``, printable text and CR LF is lost (its CRC fails) — rare for binary
    payloads, and the price of stripping lines the modem injects mid-frame.

    Args:
        rtscts: True if the port uses RTS/CTS hardware flow control.
        pace_bps: rate the unflow-controlled writes are paced to [bit/s]; S100Stream uses
            the modem's air baud rate (2400 on v3 nodes).
        preamble_len: preamble length of our frames (1 or 3).

    Attributes:
        status_lines: status lines removed.
        last_status: text of the last status line (without ``+++`` and CR LF).
        terminators: frame-ending CR LF pairs removed.
        missing_terminators: frames not followed by CR LF.
        bytes_in: bytes received [B].

    Raises:
        ValueError: ``pace_bps`` not positive or bad ``preamble_len``.
    """

    __slots__ = (
        "_expect_crlf",
        "_held",
        "_packet_bytes",
        "_preamble",
        "_remaining",
        "_tail",
        "_terminated",
        "bytes_in",
        "last_status",
        "missing_terminators",
        "pace_bps",
        "rtscts",
        "status_lines",
        "terminators",
    )

    def __init__(
        self, *, rtscts: bool = False, pace_bps: float = 2400.0, preamble_len: int = 3
    ) -> None:
        if not pace_bps > 0:
            raise ValueError(f"pace_bps must be positive, got {pace_bps!r}")
        frame_overhead(preamble_len)  # validates preamble_len
        self.rtscts = rtscts
        self.pace_bps = float(pace_bps)
        self._preamble = bytes([START_BYTE]) * preamble_len
        self._held = b""
        self._tail = bytearray()
        self._remaining = 0
        self._expect_crlf = False
        self.status_lines = 0
        self.last_status = b""
        self.terminators = 0
        self.missing_terminators = 0
        self.bytes_in = 0
        self._packet_bytes = 0  # raw bytes of the packet being received
        self._terminated = False  # its last bytes were a frame's CR LF

    def writes(self, frame: bytes) -> list[Write]:
        """Frame + CR LF, in ≤ 45 B paced pieces unless RTS/CTS is on."""
        packet = bytes(frame) + _CRLF
        if self.rtscts:
            return [Write(packet)]
        return [
            Write(piece, len(piece) * 8 / self.pace_bps)
            for piece in (
                packet[i : i + S100_MAX_WRITE] for i in range(0, len(packet), S100_MAX_WRITE)
            )
        ]

    def feed(self, data: bytes) -> bytes:
        """Strip status lines and frame terminators; return the payload stream."""
        self.bytes_in += len(data)
        self._packet_bytes += len(data)
        buf = self._held + bytes(data)
        self._held = b""
        out = bytearray()
        n = len(buf)
        i = 0
        while i < n:
            b = buf[i]
            if self._expect_crlf:
                if b == 0x0D and i + 1 >= n:
                    self._held = buf[i:]
                    break
                self._expect_crlf = False
                if buf.startswith(_CRLF, i):
                    self.terminators += 1
                    self._terminated = True
                    i += 2
                    continue
                self.missing_terminators += 1
            if b == 0x2B:  # '+'
                status = self._status_line(buf, i)
                if status is None:
                    self._held = buf[i:]
                    break
                if status > 0:
                    i = status
                    continue
            out.append(b)
            self._terminated = False
            self._track(b)
            i += 1
        return bytes(out)

    def receive(self, data: bytes) -> list[Segment]:
        """:meth:`feed`; the end of a packet is the idle line's (:meth:`idle`)."""
        stream = self.feed(data)
        return [Segment(stream)] if stream else []

    def idle(self) -> list[Segment]:
        """The line is idle: the packet has ended. Bytes held for a status line that did not
        come (``+``, ``++``, ``+++`` and printable text without CR LF) are data after all; a
        lone CR held after a frame is its terminator, the LF lost. The header tracking starts
        afresh (a corrupted length byte stops at the packet's end).

        Except for a piece of a longer frame: without RTS/CTS an S100 packet holds at most
        45 B including its CR LF, so a sender splits a longer frame into 45-B pieces of which
        only the last ends in CR LF (:meth:`writes`, dccomms' S100Stream; REFERENCE §1.10). A
        packet of exactly 45 B, unterminated, inside a frame whose header announced more,
        continues in the next packet: no packet end then."""
        piece = self._packet_bytes == S100_MAX_WRITE and not self._terminated
        self._packet_bytes = 0
        if piece and self._remaining > 0 and not self._held:
            return []
        held, self._held = self._held, b""
        if self._expect_crlf and held.startswith(b"\r"):
            self.terminators += 1
            held = held[1:]
        self._expect_crlf = False
        self._remaining = 0
        self._tail.clear()
        return [Segment(held, end=True)]

    def _status_line(self, buf: bytes, i: int) -> int | None:
        """At a ``+``: the index after a complete status line, None to wait, 0 if data."""
        n = len(buf)
        if n - i < 3:
            return None if buf[i:] == b"+" * (n - i) else 0
        if not buf.startswith(b"+++", i):
            return 0
        limit = i + 3 + S100_MAX_STATUS_LEN
        end = buf.find(_CRLF, i + 3, limit + 2)
        if end >= 0:
            text = buf[i + 3 : end]
            if is_printable(text):
                self.status_lines += 1
                self.last_status = text
                return end + 2
            return 0
        text = buf[i + 3 : n].removesuffix(b"\r")
        if n < limit + 2 and is_printable(text):
            return None
        return 0

    def _track(self, b: int) -> None:
        """Follow frame headers in the outgoing stream to know where each frame ends."""
        if self._remaining:
            self._remaining -= 1
            if not self._remaining:
                self._expect_crlf = True
            return
        tail = self._tail
        tail.append(b)
        plen = len(self._preamble)
        if len(tail) > plen + 1:
            del tail[0]
        if len(tail) == plen + 1 and tail.startswith(self._preamble):
            self._remaining = tail[plen] + 2  # payload + CRC-16
            tail.clear()

    def counters(self) -> dict[str, int]:
        """Status lines, terminators, missing terminators, bytes in."""
        return {
            "bytes_in": self.bytes_in,
            "status_lines": self.status_lines,
            "terminators": self.terminators,
            "missing_terminators": self.missing_terminators,
        }

    def setup(self) -> list[Write]:
        """Nothing: the S100's data port is transparent and no configuration command for it is
        documented (REFERENCE §1.10)."""
        return []
