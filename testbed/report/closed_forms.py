"""Closed forms the sweep plots draw over the simulated points, and the frame lengths they use.

Frame lengths come from the protocol's layouts (:mod:`testbed.protocol`): a move order is
``frame_overhead() + OPERATOR_HEADER_SIZE + Move.BODY_SIZE`` = 6 + 2 + 5 = 13 B on the air, a
reply with an image chunk of ``c`` bytes ``frame_overhead() + VEHICLE_HEADER_SIZE + c`` =
6 + 14 + c B (60 B with the 40-B chunk of the paper). Under independent bit errors a frame of
``L`` bytes survives with ``q = (1 − BER)^(8·L)``; the age and image-rate forms follow from it.
"""

from __future__ import annotations

import math

import numpy as np

from testbed.protocol import (
    DEFAULT_CHUNK_SIZE,
    IMAGE_CRC_SIZE,
    OPERATOR_HEADER_SIZE,
    VEHICLE_HEADER_SIZE,
    Move,
    frame_overhead,
)

__all__ = [
    "ORDER_FRAME_BYTES",
    "REPLY_FRAME_BYTES",
    "aoi_periodic_closed_form",
    "closed_form_age_s",
    "closed_form_images_per_minute",
    "closed_form_per",
    "image_chunks",
    "reply_frame_bytes",
]

ORDER_FRAME_BYTES = frame_overhead() + OPERATOR_HEADER_SIZE + Move.BODY_SIZE
"""Length of the operator's move-order frame on the air [B] (13: 7-B payload, 6-B framing)."""


def reply_frame_bytes(chunk_bytes: int) -> int:
    """Length on the air of a vehicle reply carrying an image chunk of ``chunk_bytes`` [B].

    Args:
        chunk_bytes: image bytes in the reply [B].

    Returns:
        Framing + reply header (header, state, chunk info) + chunk [B]: 60 for 40.
    """
    return frame_overhead() + VEHICLE_HEADER_SIZE + chunk_bytes


REPLY_FRAME_BYTES = reply_frame_bytes(DEFAULT_CHUNK_SIZE)
"""Length of a reply with the protocol's default 40-B image chunk [B] (60)."""


def image_chunks(image_bytes: float, chunk_bytes: int) -> int:
    """Chunks of ``chunk_bytes`` that carry a coded image of ``image_bytes`` and its CRC.

    Args:
        image_bytes: coded image size [B].
        chunk_bytes: image bytes per reply [B].

    Returns:
        ``⌈(image_bytes + 2) / chunk_bytes⌉``.
    """
    return math.ceil((image_bytes + float(IMAGE_CRC_SIZE)) / chunk_bytes)


def closed_form_per(ber: np.ndarray | float, frame_bytes: float) -> np.ndarray:
    """Packet error rate of a frame of ``frame_bytes`` under independent bit errors.

    A frame survives only if all its ``8·L`` bits do: ``PER = 1 − (1 − BER)^(8·L)``.

    Args:
        ber: bit error rate(s), each in [0, 1].
        frame_bytes: frame length on the air, framing included [B].

    Returns:
        PER, the shape of ``ber``.
    """
    log_survival = 8.0 * frame_bytes * np.log1p(-np.asarray(ber, dtype=float))
    return np.asarray(-np.expm1(log_survival), dtype=float)  # expm1: no 1 − (≈1) cancellation


def aoi_periodic_closed_form(period_s: float, delivery_probability: float, delay_s: float) -> float:
    """Mean age of periodic updates with independent losses: ``D + T(2 − q)/(2q)`` [s]."""
    q = delivery_probability
    if not 0.0 < q <= 1.0:
        raise ValueError(f"delivery probability must be in (0, 1], got {q}")
    return delay_s + period_s * (2.0 - q) / (2.0 * q)


def closed_form_age_s(
    ber: np.ndarray | float,
    period_s: float,
    delay_s: float,
    frame_bytes: float = ORDER_FRAME_BYTES,
) -> np.ndarray:
    """Mean age of the command a vehicle applies when orders go out every ``period_s``.

    Each order frame is delivered independently with probability ``q = (1 − BER)^(8·L)`` (all
    ``8·L`` bits intact; ``L = 13`` B for the move order). A delivered order is applied
    ``delay_s`` after the sticks were sampled; a lost one leaves the previous command in force
    until the next delivery, so the gaps between applications are ``K·T`` with ``K`` geometric.
    The renewal-reward argument of :mod:`testbed.run.metrics` gives ``E[age] = D + T(2 − q)/(2q)``
    (:func:`aoi_periodic_closed_form`); at BER 0 it is ``D + T/2``.

    Args:
        ber: bit error rate(s), each in [0, 1).
        period_s: the order period ``T`` (the token-passing inter-packet gap) [s].
        delay_s: ``D``, sampling to application of a delivered order [s]; in the plots the
            measured mean command lag at BER 0 for the same gap.
        frame_bytes: the order frame length ``L`` [B].

    Returns:
        Mean age [s], the shape of ``ber``.
    """
    q = 1.0 - closed_form_per(ber, frame_bytes)
    ages = [aoi_periodic_closed_form(period_s, float(p), delay_s) for p in np.ravel(q)]
    return np.reshape(np.array(ages, dtype=float), np.shape(q))


def closed_form_images_per_minute(
    ber: np.ndarray | float,
    gap_s: float,
    chunks: int,
    *,
    selective_repeat: bool,
    order_bytes: float = ORDER_FRAME_BYTES,
    reply_bytes: float = REPLY_FRAME_BYTES,
) -> np.ndarray:
    """Images per minute over a token-passing link with one chunk per reply.

    One order goes out every ``gap_s`` (``T``); it survives with ``q_o = (1 − BER)^(8·L_o)``
    and the vehicle answers it with a reply that survives with ``q_r = (1 − BER)^(8·L_r)``.
    Selective repeat: a chunk is done in an exchange where both survive (``q = q_o·q_r``), so
    an image of ``n`` chunks takes ``n/q`` gaps on average (the order that acknowledges one
    image already fetches chunk 0 of the next): ``60·q / (n·T)``. Paper mode: the vehicle
    streams one chunk per order it receives, so an image takes ``n/q_o`` gaps, and it is whole
    only if all ``n`` replies survive: ``60·q_o·q_r^n / (n·T)``.

    Args:
        ber: bit error rate(s), each in [0, 1).
        gap_s: the inter-packet gap ``T`` [s].
        chunks: chunks per image ``n`` (:func:`image_chunks`).
        selective_repeat: the transfer mode.
        order_bytes: the order frame ``L_o`` [B] (13: a move).
        reply_bytes: the reply frame ``L_r`` [B] (:func:`reply_frame_bytes`; 60 with a 40-B
            chunk).

    Returns:
        Images per minute, the shape of ``ber``.
    """
    q_order = 1.0 - closed_form_per(ber, order_bytes)
    q_reply = 1.0 - closed_form_per(ber, reply_bytes)
    if selective_repeat:
        return np.asarray(60.0 * q_order * q_reply / (chunks * gap_s), dtype=float)
    return np.asarray(60.0 * q_order * q_reply**chunks / (chunks * gap_s), dtype=float)
