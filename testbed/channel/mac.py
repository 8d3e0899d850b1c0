"""Medium access: the paper's token passing, and free (uncoordinated) access.

**Token passing** (Centelles et al., §III; telerobotics Operator/ROV nodes, REFERENCE §1.7): the
operator is the master and sends one frame per inter-packet gap (IPG); the vehicle is the slave
and transmits only in answer to a valid frame. With an IPG longer than the round trip the two
never transmit at once and a half-duplex link never collides.

**Free access**: every node sends on its own schedule (:func:`run_periodic_sender`); on a shared
half-duplex medium their frames then collide.

These are simpy processes (``env.process(run_token_master(...))``) over a
:class:`~testbed.channel.medium.Modem`; they move bytes only and know nothing of the messages.
"""

from __future__ import annotations

from collections.abc import Callable, Generator
from dataclasses import dataclass
from typing import Any, Protocol

import simpy

from testbed.channel.medium import Modem
from testbed.config import check
from testbed.protocol import Frame

__all__ = [
    "TELEROBOTICS_2018",
    "TELEROBOTICS_2019",
    "TELEROBOTICS_2021",
    "Fixed",
    "FrameSource",
    "FromFrameSize",
    "IpgPolicy",
    "run_periodic_sender",
    "run_token_master",
    "run_token_slave",
]


@dataclass(frozen=True, slots=True)
class Fixed:
    """A constant inter-packet gap.

    Attributes:
        gap_s: time between the starts of consecutive master frames [s], > 0.
    """

    gap_s: float

    def __post_init__(self) -> None:
        check(self.gap_s > 0.0, "gap_s", f"must be > 0, got {self.gap_s}")

    def gap_for(self, frame: bytes) -> float:
        """The gap [s] to wait after sending ``frame``."""
        return self.gap_s


@dataclass(frozen=True, slots=True)
class FromFrameSize:
    """An IPG proportional to the frame just sent: ``max(len, min_bytes) · 8 / divisor_bps``.

    Attributes:
        divisor_bps: the rate the gap is computed at [bit/s], > 0 (telerobotics: 50, then 175).
        min_bytes: frames shorter than this count as this long [B], ≥ 0.
    """

    divisor_bps: float
    min_bytes: int = 0

    def __post_init__(self) -> None:
        check(self.divisor_bps > 0.0, "divisor_bps", f"must be > 0, got {self.divisor_bps}")
        check(self.min_bytes >= 0, "min_bytes", f"must be ≥ 0, got {self.min_bytes}")

    def gap_for(self, frame: bytes) -> float:
        """The gap [s] to wait after sending ``frame``."""
        return max(len(frame), self.min_bytes) * 8.0 / self.divisor_bps


IpgPolicy = Fixed | FromFrameSize
"""How the master spaces its frames."""

TELEROBOTICS_2018 = Fixed(0.8)
"""telerobotics 2018-06 (434b9bb): 800 ms fixed."""
TELEROBOTICS_2019 = FromFrameSize(50.0)
"""telerobotics 2019-07 (856813b): pktSize·8/50 s (13 B → 2.08 s)."""
TELEROBOTICS_2021 = FromFrameSize(175.0, 13)
"""telerobotics 2021-01 (67fd087): max(pktSize, 13)·8/175 s (13 B → 0.594 s). The 2 s back-off
after a receive error of that version is left to the node that owns the decoder."""


class FrameSource(Protocol):
    """What the token slave needs of a decoder (e.g. :class:`testbed.protocol.FrameDecoder`)."""

    def feed(self, data: bytes) -> list[Any]:
        """Consume bytes; return decoded events (:class:`~testbed.protocol.Frame` or others)."""
        ...


def run_token_master(
    env: simpy.Environment,
    modem: Modem,
    next_frame: Callable[[], bytes],
    ipg: IpgPolicy,
    count: int | None = None,
) -> Generator[simpy.Event, Any, None]:
    """Token master: send ``next_frame()`` now, then once per IPG.

    Args:
        env: simpy environment.
        modem: the master's modem.
        next_frame: returns the next frame's bytes (already encoded), called at each slot.
        ipg: the inter-packet-gap policy.
        count: stop after this many frames; None = forever.
    """
    sent = 0
    while count is None or sent < count:
        frame = next_frame()
        modem.send(frame)
        sent += 1
        if count is not None and sent >= count:
            break
        yield env.timeout(ipg.gap_for(frame))


def run_token_slave(
    env: simpy.Environment,
    modem: Modem,
    reply: Callable[[bytes], bytes | None],
    decoder: FrameSource,
) -> Generator[simpy.Event, Any, None]:
    """Token slave: feed every delivery to ``decoder``; answer each valid frame at once.

    Corrupted frames are caught by the decoder and get no answer, as in the paper. The modem's
    ``on_receive`` must be None (deliveries are read from its inbox).

    Args:
        env: simpy environment.
        modem: the slave's modem.
        reply: maps a valid frame's payload to the frame bytes to send back (already encoded),
            or None to stay silent.
        decoder: stream decoder fed with every delivered copy's bytes.
    """
    while True:
        yield modem.wait()
        for delivery in modem.drain():
            for item in decoder.feed(delivery.data):
                if isinstance(item, Frame):
                    answer = reply(item.payload)
                    if answer is not None:
                        modem.send(answer)


def run_periodic_sender(
    env: simpy.Environment,
    modem: Modem,
    make_frame: Callable[[], bytes],
    interval_s: float,
    count: int | None = None,
    start_s: float = 0.0,
) -> Generator[simpy.Event, Any, None]:
    """Free access: send ``make_frame()`` every ``interval_s``, regardless of anyone else.

    Args:
        env: simpy environment.
        modem: the sender's modem.
        make_frame: returns the next frame's bytes, called at each send.
        interval_s: time between sends [s], > 0.
        count: stop after this many frames; None = forever.
        start_s: delay before the first send [s].

    Raises:
        ValueError: ``interval_s`` ≤ 0 or ``start_s`` < 0 (local misuse).
    """
    if interval_s <= 0.0:
        raise ValueError(f"interval_s must be > 0, got {interval_s}")
    if start_s < 0.0:
        raise ValueError(f"start_s must be ≥ 0, got {start_s}")
    if start_s > 0.0:
        yield env.timeout(start_s)
    sent = 0
    while count is None or sent < count:
        modem.send(make_frame())
        sent += 1
        if count is not None and sent >= count:
            break
        yield env.timeout(interval_s)
