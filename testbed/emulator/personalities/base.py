"""Shared parts of the modem personalities: the air packet, the modems' headers, the protocol.

No I/O, no clock, standard library only.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, Protocol

__all__ = [
    "EVOLOGICS_IM_MAX",
    "M64_PAYLOAD",
    "AirPacket",
    "EvoLogicsHeader",
    "M64Header",
    "ModemPersonality",
]

EVOLOGICS_IM_MAX = 64
"""Largest EvoLogics instant message [B] (REFERENCE §1.11)."""

M64_PAYLOAD = 8
"""Payload of one Water Linked M64 packet [B] (REFERENCE §1.12)."""

EOL = b"\r\n"
MAX_COMMAND = 256
"""Longest command line a personality buffers before answering an error [B]."""


@dataclass(frozen=True, slots=True)
class EvoLogicsHeader:
    """What an S2C packet carries besides its data (ours: EvoLogics' air format is unpublished).

    Attributes:
        kind: ``"im"`` instant message, ``"ack"`` its acknowledgement, ``"burst"`` burst data.
        src: sender's address.
        dst: destination address (255 broadcast).
        ack: an acknowledgement was requested (instant messages).
        length: data length [B] (the link may pad the packet).
    """

    kind: Literal["im", "ack", "burst"]
    src: int
    dst: int
    ack: bool = False
    length: int = 0


@dataclass(frozen=True, slots=True)
class M64Header:
    """What an M64 packet carries besides its 8 bytes: the sender's role and channel."""

    role: str
    channel: int


@dataclass(frozen=True, slots=True)
class AirPacket:
    """One transmission a personality hands to the link.

    Attributes:
        data: the bytes on the air (their airtime is 8·len / bitrate).
        header: the modem's own header (:class:`EvoLogicsHeader` or :class:`M64Header`).
    """

    data: bytes
    header: EvoLogicsHeader | M64Header


class ModemPersonality(Protocol):
    """What the emulator needs from a modem personality (all times simulated [s])."""

    def feed(self, data: bytes, now_s: float) -> bytes:
        """Bytes the user wrote in; the modem's replies (to write back on the port) out."""
        ...

    def next_packet(self, now_s: float) -> AirPacket | None:
        """The next transmission, asked for when the link is free; None if nothing waits."""
        ...

    def receive(
        self, packet: AirPacket, data: bytes, *, bit_errors: int, duration_s: float, now_s: float
    ) -> bytes:
        """A copy the link delivered (``data`` as received); the bytes to write on the port."""
        ...

    def poll(self, now_s: float) -> bytes:
        """Timers (acknowledgement timeouts); bytes to write on the port."""
        ...

    def counters(self) -> dict[str, int]:
        """The personality's counters by name."""
        ...


def bump(counts: dict[str, int], name: str, n: int = 1) -> None:
    """Add ``n`` to the counter ``name`` (a zero leaves it absent)."""
    if n:
        counts[name] = counts.get(name, 0) + n


def parse_int(text: str) -> int | None:
    """A short decimal field (≤ 4 digits) as an int, None if it is not one."""
    return int(text) if text.isdigit() and len(text) <= 4 else None


def find_eol(buf: bytearray, start: int, end: int) -> int:
    """Index of the first CR or LF in ``buf[start:end]``, −1 if none."""
    hits = [j for j in (buf.find(b"\r", start, end), buf.find(b"\n", start, end)) if j >= 0]
    return min(hits) if hits else -1
