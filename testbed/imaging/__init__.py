"""imaging: the progressive, truncatable, ROI-aware wavelet image coder (numpy and PyWavelets only).

``encode(image, budget_bytes, roi, roi_shift, mono) -> bytes`` and ``decode(data, shape, *,
max_pixels, work) -> ndarray``: every prefix of a stream decodes, so a stream may be cut to any
byte budget, and decoding work is bounded by the data and ``max_pixels``, not by the header.
See ``codec`` for the coding steps, ``header`` for the stream header and ``wavelet`` for the
transform and layout.
No I/O, clock or global randomness lives here.
"""

from __future__ import annotations

from testbed.imaging.codec import MAX_PIXELS, DecodeWork, decode, encode
from testbed.imaging.header import Header, parse_header
from testbed.imaging.scenes import pool_scene

__all__ = ["MAX_PIXELS", "DecodeWork", "Header", "decode", "encode", "parse_header", "pool_scene"]
