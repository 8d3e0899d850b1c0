"""Medium access: the paper's token passing, and free (uncoordinated) access.

**Token passing** (Centelles et al., §III; telerobotics Operator/ROV nodes, REFERENCE §1.7): the
operator is the master and sends one frame per inter-packet gap (IPG); the vehicle is the slave
and transmits only in answer to a valid frame. With an IPG longer than the round trip the two
never transmit at once and a half-duplex link never collides.

**Free access**: every node sends on its own schedule (:func:`run_periodic_sender`); on a shared
half-duplex medium their frames then collide.

This module is the one implementation of both rules: the simulated nodes and the real-time
(HIL) runs use it (:mod:`testbed.run.nodes`), as do the link probe and the tests. The master and
the periodic sender are simpy processes (``env.process(run_token_master(...))``) around a
``send`` callback, so the same rule drives a simulated :class:`~testbed.channel.medium.Modem`,
a serial modem or a node's link codec; :class:`TokenSlave` answers frames as they are decoded.
They move bytes only and know nothing of the messages.
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
    "TokenSlave",
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

    def gap_after(self, size_bytes: int) -> float:
        """The gap [s] to wait after sending a frame of ``size_bytes`` [B]."""
        return self.gap_s

    def gap_for(self, frame: bytes) -> float:
        """The gap [s] to wait after sending ``frame``."""
        return self.gap_after(len(frame))


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

    def gap_after(self, size_bytes: int) -> float:
        """The gap [s] to wait after sending a frame of ``size_bytes`` [B]."""
        return max(size_bytes, self.min_bytes) * 8.0 / self.divisor_bps

    def gap_for(self, frame: bytes) -> float:
        """The gap [s] to wait after sending ``frame``."""
        return self.gap_after(len(frame))


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
    send_slot: Callable[[], int],
    ipg: IpgPolicy,
    count: int | None = None,
) -> Generator[simpy.Event, Any, None]:
    """Token master: use the first slot now, then one slot per IPG.

    Args:
        env: simpy environment (simulated or real time).
        send_slot: sends this slot's frame(s) and returns the size [B] the gap follows (the
            largest frame just sent; the telerobotics rules size the gap on it).
        ipg: the inter-packet-gap policy.
        count: stop after this many slots; None = forever.
    """
    sent = 0
    while count is None or sent < count:
        size_bytes = send_slot()
        sent += 1
        if count is not None and sent >= count:
            break
        yield env.timeout(ipg.gap_after(size_bytes))


class TokenSlave:
    """Token slave: answer each valid frame at once, and nothing else.

    Corrupted frames never reach :meth:`on_frame` (the stream decoder drops them), so they get
    no answer, as in the paper.

    Args:
        reply: a valid frame's payload → the bytes to send back, or None to stay silent.
        send: hands the answer to the modem.
    """

    __slots__ = ("_reply", "_send")

    def __init__(
        self, reply: Callable[[bytes], bytes | None], send: Callable[[bytes], object]
    ) -> None:
        self._reply = reply
        self._send = send

    def on_frame(self, payload: bytes) -> None:
        """A valid frame arrived: answer it now."""
        answer = self._reply(payload)
        if answer is not None:
            self._send(answer)


def run_token_slave(
    env: simpy.Environment,
    modem: Modem,
    reply: Callable[[bytes], bytes | None],
    decoder: FrameSource,
) -> Generator[simpy.Event, Any, None]:
    """Token slave on a simulated modem: feed every delivery to ``decoder`` and let a
    :class:`TokenSlave` answer each valid frame at once.

    The modem's ``on_receive`` must be None (deliveries are read from its inbox).

    Args:
        env: simpy environment.
        modem: the slave's modem.
        reply: maps a valid frame's payload to the frame bytes to send back (already encoded),
            or None to stay silent.
        decoder: stream decoder fed with every delivered copy's bytes.
    """
    del env
    slave = TokenSlave(reply, modem.send)
    while True:
        yield modem.wait()
        for delivery in modem.drain():
            for item in decoder.feed(delivery.data):
                if isinstance(item, Frame):
                    slave.on_frame(item.payload)


def run_periodic_sender(
    env: simpy.Environment,
    send: Callable[[], object],
    interval_s: float,
    count: int | None = None,
    start_s: float = 0.0,
) -> Generator[simpy.Event, Any, None]:
    """Free access: call ``send()`` every ``interval_s``, regardless of anyone else.

    Args:
        env: simpy environment (simulated or real time).
        send: sends the next frame(s).
        interval_s: time between sends [s], > 0.
        count: stop after this many sends; None = forever.
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
        send()
        sent += 1
        if count is not None and sent >= count:
            break
        yield env.timeout(interval_s)
