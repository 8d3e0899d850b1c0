"""What a modem hands its node, and what it counts: the deliveries of a :class:`~.medium.Medium`.

:class:`Delivery` is one received copy of a transmission (its bytes as received, bit errors
included, with times [s] of simulated time); :func:`decode_delivery` is the one rule by which a
simulated receiver feeds copies to its frame decoder; :class:`ModemCounters` are a modem's
per-transmission counts. Plain values: the timing, FIFOs and collisions that produce them are
:mod:`testbed.channel.medium`'s.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

from testbed.protocol import CorruptFrame, Frame, FrameDecoder

__all__ = ["Delivery", "ModemCounters", "decode_delivery"]


class Delivery(NamedTuple):
    """One received copy of a transmission, as handed to the receiving node (immutable).

    A ``NamedTuple`` rather than a frozen dataclass: one is built per received copy on the hot
    path and a frozen dataclass costs about five times as much to construct.

    Attributes:
        data: the bytes as received (bit errors included; packet padding included).
        t_tx_start_s: when the sender started this transmission (its intrinsic delay) [s].
        t_delivered_s: when the last bit arrived [s].
        frame_id: the medium's id of the frame this came from.
        src: sending modem's name.
        part: packet index within the frame (0 when frames go out whole).
        parts: number of packets of the frame (1 when frames go out whole).
        bit_errors: number of flipped bits. Ground truth for instrumentation only: nodes must
            detect corruption with their decoder, as on a real modem.
    """

    data: bytes
    t_tx_start_s: float
    t_delivered_s: float
    frame_id: int
    src: str
    part: int = 0
    parts: int = 1
    bit_errors: int = 0


def decode_delivery(decoder: FrameDecoder, delivery: Delivery) -> list[Frame | CorruptFrame]:
    """Feed one received copy to a node's decoder, flushing it when a transmission is complete.

    The one decoding rule of every simulated receiver (the run's nodes and ``testbed link``):
    the last packet of a transmission ends a modem packet, so a candidate still waiting for the
    length its (corrupted) length byte claims is given up there
    (:meth:`~testbed.protocol.FrameDecoder.feed_packet`) instead of holding later frames.

    Args:
        decoder: the receiving node's frame decoder.
        delivery: the copy the medium handed over.

    Returns:
        The decoder's events, in stream order.
    """
    last = delivery.part == delivery.parts - 1
    return decoder.feed_packet(delivery.data, packet_end=last)


@dataclass(slots=True)
class ModemCounters:
    """Per-modem counters (read them; the modem updates them).

    Transmit side counts frames handed to ``send``; the ``tx_`` and ``rx_`` counts are per
    transmission (per packet when ``packet_bytes > 0``).
    """

    frames_offered: int = 0
    frames_dropped: int = 0
    tx_transmissions: int = 0
    tx_bytes: int = 0
    rx_delivered: int = 0
    rx_corrupted: int = 0
    rx_collided: int = 0
    rx_deaf: int = 0
    """Of ``rx_collided``: the copies lost only because this modem was transmitting (half
    duplex), no other copy overlapping them."""
    rx_out_of_range: int = 0
    rx_outage: int = 0
    rx_bit_errors: int = 0
