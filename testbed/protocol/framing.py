"""Frame codec and stream decoder: payload bytes ⇄ frames on a byte stream (sans-IO).

Wire format (REFERENCE §1.2)::

    0x55 × preamble_len · length u8 · payload (length bytes) · CRC-16/XMODEM big-endian

The CRC covers the preamble, the length byte and the payload, so a corrupted length byte is
caught like any other error. With ``preamble_len=3`` this is the telerobotics *WAFrame* (2021,
6 B overhead). With ``preamble_len=1`` it is dccomms' *VariableLengthPacket* (4 B overhead) with
the CRC extended over the start and length bytes; that is **not** byte-compatible with the
original VariableLengthPacket, whose CRC covers the payload only.

:class:`FrameDecoder` turns any byte stream, however it is chunked and however garbled, into a
sequence of :class:`Frame` and :class:`CorruptFrame` values. Remote garbage never raises;
only local misuse (a bad argument) raises :class:`ValueError`. Decoder rules:

* **Hunting.** The decoder looks for the preamble with :meth:`bytes.find`. Bytes skipped while
  hunting are *garbage*: they are only counted (:attr:`FrameDecoder.garbage_bytes`), never
  reported as events, because line noise between frames is normal on a modem link. A
  :class:`CorruptFrame` is reported only for a preamble + length that then failed.
* **Candidate.** After a preamble and its length byte, a length above ``max_payload`` is
  ``OVERSIZE``; a frame that could never fit in ``max_buffer`` bytes is ``OVERFLOW``. Otherwise
  the decoder waits for the whole claimed frame and checks the CRC: a match is a
  :class:`Frame`, a mismatch is ``BAD_CRC``.
* **Resynchronisation.** After *any* failed candidate the hunt resumes at the byte after the
  failed start byte, never after the claimed length, so the good frames behind a flipped length
  byte are found once the bogus candidate has failed. That failure is a CRC-16 check, not a
  certainty: about once in 2^16 mis-framed candidates the CRC matches by chance, the decoder
  delivers a false frame and, if the candidate reached past the corrupted frame, skips the
  frames it covers. Measured rate and derivation: docs/protocol.md, "Resynchronisation
  guarantee". A :meth:`FrameDecoder.flush` between packets confines that loss to the packet.
* **Latency of a bogus length.** A length byte corrupted upwards makes the decoder wait until
  the claimed number of bytes has arrived before it can reject the candidate, so the frames
  behind it are delivered late (but in order). There is no clock here: a node that wants to give
  up after a silence calls :meth:`FrameDecoder.flush`, which reports the pending candidate as
  ``TRUNCATED`` and returns any complete frames already received behind it.
  :meth:`FrameDecoder.close` (end of stream) only reports what is left as ``TRUNCATED``.
* **Bounded memory.** The decoder never holds more than ``max_buffer`` bytes; input larger than
  the free space is consumed in slices, so feeding a stream whole, byte by byte or in random
  chunks gives the same events.

Accounting: every byte fed ends up in exactly one of a returned frame, ``garbage_bytes``, the
``skipped_bytes`` of a :class:`CorruptFrame`, or :attr:`FrameDecoder.pending_bytes`.
"""

from __future__ import annotations

import binascii
import enum
from dataclasses import dataclass

__all__ = [
    "DEFAULT_PREAMBLE_LEN",
    "MAX_PAYLOAD",
    "PREAMBLE_LENGTHS",
    "START_BYTE",
    "CorruptFrame",
    "CorruptReason",
    "Frame",
    "FrameDecoder",
    "FrameEvent",
    "encode_frame",
    "frame_overhead",
]

START_BYTE = 0x55
"""Preamble byte (0b01010101, which also keeps Manchester-coded RF modems in lock)."""

MAX_PAYLOAD = 255
"""Largest payload a one-byte length field can announce [B]."""

DEFAULT_PREAMBLE_LEN = 3
"""Preamble length of the WAFrame (telerobotics 2021)."""

PREAMBLE_LENGTHS = (1, 3)
"""Supported preamble lengths: 1 (VariableLengthPacket style) and 3 (WAFrame)."""

_CRC_LEN = 2
_PREAMBLES = {n: bytes([START_BYTE]) * n for n in PREAMBLE_LENGTHS}
_HEADERS = {n: [_PREAMBLES[n] + bytes((k,)) for k in range(256)] for n in PREAMBLE_LENGTHS}
"""Preamble + length byte, by preamble length and payload length (saves work per frame)."""


def _bad_preamble_len(preamble_len: int) -> ValueError:
    return ValueError(f"preamble_len must be one of {PREAMBLE_LENGTHS}, got {preamble_len!r}")


def _check_preamble_len(preamble_len: int) -> None:
    if preamble_len not in PREAMBLE_LENGTHS:
        raise _bad_preamble_len(preamble_len)


def frame_overhead(preamble_len: int = DEFAULT_PREAMBLE_LEN) -> int:
    """Bytes a frame adds to its payload: preamble + length byte + CRC.

    Args:
        preamble_len: 1 or 3.

    Returns:
        4 for ``preamble_len=1``, 6 for ``preamble_len=3`` [B].

    Raises:
        ValueError: unsupported ``preamble_len``.
    """
    _check_preamble_len(preamble_len)
    return preamble_len + 1 + _CRC_LEN


def encode_frame(
    payload: bytes | bytearray | memoryview, preamble_len: int = DEFAULT_PREAMBLE_LEN
) -> bytes:
    """Wrap ``payload`` in a frame: preamble · length · payload · CRC-16 (big-endian).

    Args:
        payload: 0..255 bytes.
        preamble_len: 1 or 3 start bytes (0x55).

    Returns:
        The frame, ``len(payload) + frame_overhead(preamble_len)`` bytes long.

    Raises:
        ValueError: payload longer than 255 bytes or unsupported ``preamble_len``.
    """
    headers = _HEADERS.get(preamble_len)
    if headers is None:
        raise _bad_preamble_len(preamble_len)
    length = len(payload)
    if length > MAX_PAYLOAD:
        raise ValueError(f"payload is {length} B, the frame carries at most {MAX_PAYLOAD} B")
    body = headers[length] + payload
    return body + binascii.crc_hqx(body, 0).to_bytes(2, "big")


@dataclass(frozen=True, slots=True)
class Frame:
    """A frame whose CRC checked.

    Attributes:
        payload: the frame's payload (0..max_payload bytes).
    """

    payload: bytes


class CorruptReason(enum.Enum):
    """Why a candidate frame (a preamble followed by a length byte) was rejected."""

    BAD_CRC = "bad_crc"
    """The whole claimed frame arrived but its CRC did not match."""
    OVERSIZE = "oversize"
    """The length byte announced more than the decoder's ``max_payload``."""
    TRUNCATED = "truncated"
    """The stream ended (:meth:`FrameDecoder.close`) or went quiet (:meth:`FrameDecoder.flush`)
    before the claimed frame was complete."""
    OVERFLOW = "overflow"
    """The claimed frame is longer than the decoder's ``max_buffer`` and could never arrive."""


@dataclass(frozen=True, slots=True)
class CorruptFrame:
    """A rejected candidate frame.

    Attributes:
        reason: why it was rejected.
        skipped_bytes: bytes discarded because of this event [B]. 1 for ``BAD_CRC``,
            ``OVERSIZE``, ``OVERFLOW`` and a ``TRUNCATED`` from :meth:`FrameDecoder.flush` (only
            the failed start byte is dropped; the bytes after it are hunted again); everything
            left in the buffer for a ``TRUNCATED`` from :meth:`FrameDecoder.close`.
    """

    reason: CorruptReason
    skipped_bytes: int


FrameEvent = Frame | CorruptFrame
"""What :meth:`FrameDecoder.feed` returns, one per frame or rejected candidate."""


class FrameDecoder:
    """Incremental stream decoder: bytes in, :class:`Frame` / :class:`CorruptFrame` out.

    No I/O, no clock. See the module docstring for the resynchronisation rules.

    Args:
        preamble_len: number of 0x55 start bytes, 1 or 3.
        max_payload: largest payload accepted [B], 0..255; longer claims are ``OVERSIZE``.
        max_buffer: most bytes ever held [B]; at least one empty frame
            (``frame_overhead(preamble_len)``). Claimed frames longer than this are
            ``OVERFLOW``. With the default (4096 B) every frame fits and overflow cannot occur.

    Attributes:
        frames: frames decoded so far.
        corrupt: :class:`CorruptFrame` events reported so far.
        garbage_bytes: bytes skipped while hunting for a preamble [B].
        bytes_fed: bytes passed to :meth:`feed` so far [B].

    Raises:
        ValueError: an argument out of range (local misuse).
    """

    __slots__ = (
        "_buf",
        "_max_buffer",
        "_max_payload",
        "_preamble",
        "_preamble_len",
        "bytes_fed",
        "corrupt",
        "frames",
        "garbage_bytes",
    )

    def __init__(
        self,
        preamble_len: int = DEFAULT_PREAMBLE_LEN,
        max_payload: int = MAX_PAYLOAD,
        max_buffer: int = 4096,
    ) -> None:
        _check_preamble_len(preamble_len)
        if not 0 <= max_payload <= MAX_PAYLOAD:
            raise ValueError(f"max_payload must be in 0..{MAX_PAYLOAD}, got {max_payload}")
        if max_buffer < frame_overhead(preamble_len):
            raise ValueError(
                f"max_buffer must hold an empty frame ({frame_overhead(preamble_len)} B), "
                f"got {max_buffer}"
            )
        self._preamble_len = preamble_len
        self._preamble = _PREAMBLES[preamble_len]
        self._max_payload = max_payload
        self._max_buffer = max_buffer
        self._buf = bytearray()
        self.frames = 0
        self.corrupt = 0
        self.garbage_bytes = 0
        self.bytes_fed = 0

    @property
    def preamble_len(self) -> int:
        """Number of 0x55 start bytes."""
        return self._preamble_len

    @property
    def max_payload(self) -> int:
        """Largest payload accepted [B]."""
        return self._max_payload

    @property
    def max_buffer(self) -> int:
        """Most bytes ever held [B]."""
        return self._max_buffer

    @property
    def pending_bytes(self) -> int:
        """Bytes held: an incomplete candidate frame, or a partial preamble at the end [B]."""
        return len(self._buf)

    def feed(self, data: bytes | bytearray | memoryview) -> list[Frame | CorruptFrame]:
        """Consume received bytes; return the frames and rejected candidates they complete.

        Args:
            data: any bytes, in any chunking; may be empty.

        Returns:
            Events in stream order. Never raises on remote data.
        """
        events: list[Frame | CorruptFrame] = []
        size = len(data)
        self.bytes_fed += size
        buf = self._buf
        if not buf and size <= self._max_buffer and not isinstance(data, memoryview):
            # Nothing pending: scan the input in place and keep only its undecided tail.
            used = self._scan(data, events)
            if used < size:
                buf += data[used:]
            return events
        start = 0
        while start < size:
            take = self._max_buffer - len(buf)  # > 0: a scan always leaves the buffer non-full
            buf += data[start : start + take]
            start += take
            del buf[: self._scan(buf, events)]
        return events

    def feed_packet(
        self, data: bytes | bytearray | memoryview, *, packet_end: bool
    ) -> list[Frame | CorruptFrame]:
        """:meth:`feed` the bytes of (part of) a modem packet; at its end, :meth:`flush`.

        A candidate still incomplete when a whole packet has arrived had its length byte
        corrupted: waiting for the length it claims would hold the good frames behind it for
        many packets, so it is given up at the packet boundary. The simulated link and the
        hardware-in-the-loop endpoints both decode through this one rule.

        Args:
            data: received bytes, in any chunking.
            packet_end: these bytes end a modem packet (the last part of a transmission, an
                idle gap on a transparent line, a modem's end of message).

        Returns:
            Events in stream order.
        """
        events = self.feed(data)
        if packet_end and self._buf:
            events += self.flush()
        return events

    def flush(self) -> list[Frame | CorruptFrame]:
        """The sender has gone quiet: give up on pending candidates and decode what follows.

        Each pending candidate is reported as ``TRUNCATED`` with ``skipped_bytes=1`` (its start
        byte) and the hunt resumes after it, as for a failed CRC, so complete frames received
        behind a corrupted length byte are returned now instead of when more bytes arrive. A
        leftover partial preamble is counted as garbage. The buffer ends empty and the decoder
        stays usable.

        Returns:
            Events in stream order.
        """
        events: list[Frame | CorruptFrame] = []
        buf = self._buf
        while buf.startswith(self._preamble):
            events.append(CorruptFrame(CorruptReason.TRUNCATED, 1))
            self.corrupt += 1
            del buf[:1]
            del buf[: self._scan(buf, events)]
        self.garbage_bytes += len(buf)
        buf.clear()
        return events

    def close(self) -> list[CorruptFrame]:
        """End of stream: report an incomplete frame as ``TRUNCATED`` and empty the buffer.

        A leftover partial preamble (fewer than ``preamble_len`` start bytes, no length byte)
        cannot be told from noise and is counted as garbage, not reported. The decoder stays
        usable: later :meth:`feed` calls start a fresh hunt.

        Returns:
            ``[CorruptFrame(TRUNCATED, n)]`` if a candidate frame was pending, else ``[]``.
        """
        buf = self._buf
        events: list[CorruptFrame] = []
        if buf.startswith(self._preamble):
            events.append(CorruptFrame(CorruptReason.TRUNCATED, len(buf)))
            self.corrupt += 1
        else:
            self.garbage_bytes += len(buf)
        buf.clear()
        return events

    def _scan(self, buf: bytes | bytearray, events: list[Frame | CorruptFrame]) -> int:
        """Decode everything decodable in ``buf``; return how many leading bytes were used.

        The bytes after the returned position are undecided: an incomplete candidate frame or
        a partial preamble. The caller keeps them.
        """
        preamble = self._preamble
        plen = self._preamble_len
        max_payload = self._max_payload
        max_frame = self._max_buffer
        n = len(buf)
        pos = 0
        while True:
            i = buf.find(preamble, pos)
            if i < 0:
                # Keep a trailing run of start bytes that may begin the next preamble.
                keep = 0
                while keep < plen - 1 and keep < n - pos and buf[n - 1 - keep] == START_BYTE:
                    keep += 1
                self.garbage_bytes += n - keep - pos
                pos = n - keep
                break
            self.garbage_bytes += i - pos
            pos = i
            if i + plen >= n:
                break  # wait for the length byte
            length = buf[i + plen]
            end = i + plen + 1 + length + _CRC_LEN
            if length > max_payload:
                reason = CorruptReason.OVERSIZE
            elif end - i > max_frame:
                reason = CorruptReason.OVERFLOW
            elif end > n:
                break  # wait for the rest of the claimed frame
            elif binascii.crc_hqx(buf[i:end], 0) == 0:
                events.append(Frame(bytes(buf[i + plen + 1 : end - _CRC_LEN])))
                self.frames += 1
                pos = end
                continue
            else:
                reason = CorruptReason.BAD_CRC
            events.append(CorruptFrame(reason, 1))
            self.corrupt += 1
            pos = i + 1
        return pos
