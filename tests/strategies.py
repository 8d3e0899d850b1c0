"""Hypothesis strategies and reference helpers shared by several test modules.

Test modules import them as ``from tests.strategies import …`` (pytest runs with
``--import-mode=importlib`` and ``pythonpath = ["."]``, so test modules cannot import each
other, but this module is importable). Only what more than one test module uses lives here.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterable

from hypothesis import strategies as st

from testbed.protocol import (
    DisableKeepHeading,
    GoTo,
    HoldChannel,
    ImageSettings,
    KeepHeading,
    Mode,
    Move,
    NoOrder,
    Order,
    OrderIncoming,
)

__all__ = ["axis", "crc16_bitwise", "cut_lists", "int16", "orders", "roi", "split_at"]


def crc16_bitwise(data: bytes, crc: int = 0) -> int:
    """Textbook MSB-first CRC: poly 0x1021, no reflection, no final XOR (one bit at a time).

    With the default ``crc=0`` this is CRC-16/XMODEM, the link's frame and image checksum.
    """
    for byte in data:
        crc ^= byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) if crc & 0x8000 else (crc << 1)
            crc &= 0xFFFF
    return crc


def split_at(data: bytes, cuts: Iterable[int]) -> list[bytes]:
    """``data`` cut at ``cuts`` (positions in any order, taken modulo ``len(data) + 1``).

    The pieces, empty ones included, concatenate back to ``data``: feed them one by one to check
    that a stream parser's output does not depend on how the bytes arrive.
    """
    edges = [0, *sorted(c % (len(data) + 1) for c in cuts), len(data)]
    return [data[a:b] for a, b in itertools.pairwise(edges)]


def cut_lists(max_size: int) -> st.SearchStrategy[list[int]]:
    """Cut positions for :func:`split_at`: up to ``max_size`` of them, anywhere in the stream."""
    return st.lists(st.integers(0, 10_000), max_size=max_size)


axis = st.integers(-127, 127)
"""A joystick axis of a ``Move`` order."""
roi = st.integers(0, 1023)
"""One corner coordinate of an ``ImageSettings`` region of interest."""
int16 = st.integers(-32768, 32767)
"""A signed 16-bit field (``GoTo``)."""
orders: st.SearchStrategy[Order] = st.one_of(
    st.just(NoOrder()),
    st.builds(Move, axis, axis, axis, axis, st.booleans(), st.booleans(), st.sampled_from(Mode)),
    st.builds(KeepHeading, st.integers(0, 359)),
    st.builds(HoldChannel, st.integers(0, 255)),
    st.builds(
        ImageSettings, roi, roi, roi, roi, st.integers(0, 15), st.booleans(), st.integers(0, 65535)
    ),
    st.just(DisableKeepHeading()),
    st.builds(GoTo, int16, int16, int16, int16),
    st.just(OrderIncoming()),
)
"""Every kind of operator order, each field over its whole wire range."""
