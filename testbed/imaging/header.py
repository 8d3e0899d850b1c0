"""The image stream header: what a decoder needs before the first coded bit.

Layout (big-endian bit order, 5 bytes, or 11 with a region of interest)::

    b0      magic 0xD (4 bits) · version 1 (2 bits) · ROI present (1) · mono (1)
    b1..b3  width - 1 (12 bits) · height - 1 (12 bits)
    b4      decomposition levels (3 bits) · bit planes coded (5 bits)
    b5..b9  ROI x0, y0, x1, y1, 10 bits each, packed as in the image-settings order
    b10     ROI shift (4 bits, bit planes) · reserved 0 (4 bits)

The ROI rectangle is in pixels, inclusive, in the same 10-bit units as the operator's
image-settings order; it is present only when the shift is above zero. Parsing is total: a short
or garbled header is ``None``, never an exception. No I/O lives here.
"""

from __future__ import annotations

from dataclasses import dataclass

MAGIC = 0xD
VERSION = 1
BASE_SIZE = 5
ROI_SIZE = 6
MAX_SIDE = 1024  # [px] the image-settings ROI units address 0..1023
MAX_LEVELS = 7
MAX_PLANES = 31
MAX_SHIFT = 15


@dataclass(frozen=True, slots=True)
class Header:
    """Decoded stream header.

    Attributes:
        width: image width [px], 1..1024.
        height: image height [px], 1..1024.
        levels: wavelet decomposition levels, 0..7.
        planes: bit planes coded (the top plane is ``planes - 1``), 0..31.
        mono: True for 8-bit greyscale.
        roi: (x0, y0, x1, y1) inclusive pixel rectangle, each 0..1023, or None.
        roi_shift: bit planes the ROI coefficients are scaled up by, 0..15 (0 when roi is None).
    """

    width: int
    height: int
    levels: int
    planes: int
    mono: bool = True
    roi: tuple[int, int, int, int] | None = None
    roi_shift: int = 0

    def __post_init__(self) -> None:
        for name, lo, hi in (
            ("width", 1, MAX_SIDE),
            ("height", 1, MAX_SIDE),
            ("levels", 0, MAX_LEVELS),
            ("planes", 0, MAX_PLANES),
            ("roi_shift", 0, MAX_SHIFT),
        ):
            value = getattr(self, name)
            if not isinstance(value, int) or not lo <= value <= hi:
                raise ValueError(f"Header.{name} must be an int in {lo}..{hi}, got {value!r}")
        if self.roi is None:
            if self.roi_shift != 0:
                raise ValueError("Header.roi_shift must be 0 without a roi")
        else:
            if len(self.roi) != 4 or not all(
                isinstance(c, int) and 0 <= c <= MAX_SIDE - 1 for c in self.roi
            ):
                raise ValueError(f"Header.roi must be 4 ints in 0..1023, got {self.roi!r}")
            if self.roi_shift == 0:
                raise ValueError("Header.roi needs roi_shift > 0")

    @property
    def size(self) -> int:
        """Packed size [B]."""
        return BASE_SIZE + (ROI_SIZE if self.roi is not None else 0)

    def pack(self) -> bytes:
        """The packed header bytes."""
        flags = (MAGIC << 4) | (VERSION << 2) | ((self.roi is not None) << 1) | int(self.mono)
        dims = ((self.width - 1) << 12) | (self.height - 1)
        out = bytes((flags,)) + dims.to_bytes(3, "big") + bytes(((self.levels << 5) | self.planes,))
        if self.roi is not None:
            x0, y0, x1, y1 = self.roi
            rect = (x0 << 30) | (y0 << 20) | (x1 << 10) | y1
            out += rect.to_bytes(5, "big") + bytes((self.roi_shift << 4,))
        return out


def parse_header(data: bytes) -> Header | None:
    """Parse the header at the start of ``data``; None if it is short or not a valid header."""
    if len(data) < BASE_SIZE:
        return None
    flags = data[0]
    if flags >> 4 != MAGIC or (flags >> 2) & 3 != VERSION:
        return None
    has_roi, mono = bool(flags & 2), bool(flags & 1)
    dims = int.from_bytes(data[1:4], "big")
    width, height = (dims >> 12) + 1, (dims & 0xFFF) + 1
    levels, planes = data[4] >> 5, data[4] & 0x1F
    roi: tuple[int, int, int, int] | None = None
    shift = 0
    if has_roi:
        if len(data) < BASE_SIZE + ROI_SIZE:
            return None
        rect = int.from_bytes(data[5:10], "big")
        roi = ((rect >> 30) & 1023, (rect >> 20) & 1023, (rect >> 10) & 1023, rect & 1023)
        shift = data[10] >> 4
        if data[10] & 0x0F or shift == 0:
            return None
    try:
        return Header(width, height, levels, planes, mono, roi, shift)
    except ValueError:
        return None
