"""Embedded bit-plane wavelet coder: ``encode`` an image to a truncatable stream, ``decode`` any
prefix of one.

The coder is in the SPIHT family. Wavelet coefficients (CDF 9/7, see ``wavelet``) are quantised
to integer magnitudes ``floor(|c|)`` (ROI coefficients first scaled by 2^shift, Maxshift-style)
and sent bit plane by bit plane, top plane first, in the steps ``passes`` schedules: per plane,
significance bits (each new significant coefficient followed by its sign) and descendant-set
bits group by group, coarse to fine, the coefficients with a significant neighbour or parent
first and the rest in a second pass, then refinement bits (bit p of the magnitude) of the
coefficients significant before the plane. A coefficient is *active* (gets significance bits)
once its parent's descendant set is significant; LL coefficients always are.

Significance and descendant bits are coded by the adaptive run-length coder of ``runlength``
(one adaptation state per group, kind and pass); refinement bits are raw. The stream is the
header (``header``) followed by the packed bits; the encoder stops when the byte budget is
spent. The decoder replays the same schedule and stops at the first step the data does not
complete, keeping what that step's available bits say. A significant coefficient is rebuilt at
3/8 of the interval its known bits leave (wavelet magnitudes are denser at the low end; the
midpoint measured the same PSNR but let refinement bits lower it slightly more often).

Remote data never raises here: a stream whose header is short or invalid, or claims more than
``max_pixels`` (default ``MAX_PIXELS``, 1024 x 1024), decodes to a mid-grey image of the ``shape``
the caller expects, or to an empty (0, 0) array if none was given. The decoder's work follows the
data, not the header: no image-sized array exists before the header passes the size limit, a
header with no coded bit (or none that makes a coefficient significant) is the flat image without
the transform, and each step that carries coefficients reads at least one coded bit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from testbed.imaging.header import MAX_PLANES, MAX_SHIFT, MAX_SIDE, Header, parse_header
from testbed.imaging.passes import DESC, REF, SIG, State, steps
from testbed.imaging.runlength import Reader, Writer
from testbed.imaging.wavelet import Layout, default_levels, forward, inverse, layout, roi_mask

_OFFSET = 128.0  # level shift of 8-bit samples before the transform


def _grey(image: NDArray[np.generic]) -> NDArray[np.float64]:
    """(h, w) float luma of a grey (h, w) or colour (h, w, 3) image (ITU-R BT.601 weights)."""
    arr = np.asarray(image)
    if arr.ndim == 3 and arr.shape[2] in (3, 4):
        rgb = arr[..., :3].astype(np.float64)
        luma: NDArray[np.float64] = np.round(rgb @ np.array([0.299, 0.587, 0.114]))
        return luma
    if arr.ndim != 2:
        raise ValueError(f"image must be (h, w) or (h, w, 3), got shape {arr.shape}")
    return arr.astype(np.float64)


def _normalise_roi(
    roi: tuple[int, int, int, int], height: int, width: int
) -> tuple[int, int, int, int]:
    """Order the corners and clip them to the image (inclusive pixels)."""
    x0, y0, x1, y1 = (int(v) for v in roi)
    xa, xb = sorted((x0, x1))
    ya, yb = sorted((y0, y1))
    return (
        min(max(xa, 0), width - 1),
        min(max(ya, 0), height - 1),
        min(max(xb, 0), width - 1),
        min(max(yb, 0), height - 1),
    )


def encode(
    image: NDArray[np.generic],
    budget_bytes: int,
    roi: tuple[int, int, int, int] | None = None,
    roi_shift: int = 0,
    mono: bool = True,
    *,
    levels: int | None = None,
) -> bytes:
    """Encode an 8-bit image into an embedded stream of at most ``budget_bytes`` bytes.

    Any prefix of the result is itself a valid stream (see ``decode``), so the caller may cut
    it anywhere.

    Args:
        image: (h, w) grey or (h, w, 3) RGB uint8-range image, 1..1024 px per side.
        budget_bytes: largest stream size [B], header included; 0 gives an empty stream.
        roi: (x0, y0, x1, y1) inclusive pixel rectangle in image-settings units (0..1023);
            corners are ordered and clipped to the image. Ignored when ``roi_shift`` is 0.
        roi_shift: bit planes the ROI coefficients are scaled up by, 0..15 (Maxshift-style).
        mono: code greyscale. Colour images are coded as their luma; mono=False is reserved
            for a colour mode that is not implemented.
        levels: wavelet levels, 0..7; default leaves an LL band of 3..4 samples.

    Returns:
        The stream: header and coded bits, ``len <= budget_bytes``.

    Raises:
        ValueError: on a bad image shape, budget, ROI, shift or level count.
        NotImplementedError: if mono is False.
    """
    if not mono:
        raise NotImplementedError("colour coding is not implemented; use mono=True")
    pixels = _grey(image)
    height, width = pixels.shape
    if not (1 <= height <= MAX_SIDE and 1 <= width <= MAX_SIDE):
        raise ValueError(f"image sides must be 1..{MAX_SIDE} px, got {width} x {height}")
    if budget_bytes < 0:
        raise ValueError(f"budget_bytes must be >= 0, got {budget_bytes}")
    if not 0 <= roi_shift <= MAX_SHIFT:
        raise ValueError(f"roi_shift must be in 0..{MAX_SHIFT}, got {roi_shift}")
    nlev = default_levels(height, width) if levels is None else levels
    if not 0 <= nlev <= 7:
        raise ValueError(f"levels must be in 0..7, got {nlev}")
    lay = layout(height, width, nlev)
    coef = forward(pixels - _OFFSET, nlev)
    mag_f = np.abs(coef)
    rect = None
    if roi is not None and roi_shift > 0:
        if len(roi) != 4 or not all(0 <= int(v) <= MAX_SIDE - 1 for v in roi):
            raise ValueError(f"roi must be 4 ints in 0..{MAX_SIDE - 1}, got {roi!r}")
        rect = _normalise_roi(roi, height, width)
        inside = roi_mask(lay, rect)
        mag_f = np.where(inside, mag_f * float(1 << roi_shift), mag_f)
    mag = np.floor(mag_f).astype(np.int64)
    planes = int(mag.max()).bit_length() if mag.size else 0
    planes = min(planes, MAX_PLANES)
    mag = np.minimum(mag, (1 << planes) - 1)
    head = Header(width, height, nlev, planes, True, rect, roi_shift if rect else 0).pack()
    if budget_bytes <= len(head):
        return head[:budget_bytes]
    bits = _encode_bits(mag, coef < 0, lay, planes, 8 * (budget_bytes - len(head)))
    return head + np.packbits(bits).tobytes()[: budget_bytes - len(head)]


def _encode_bits(
    mag: NDArray[np.int64],
    neg: NDArray[np.bool_],
    lay: Layout,
    planes: int,
    max_bits: int,
) -> NDArray[np.uint8]:
    """The coded bits, step by step, stopping once ``max_bits`` are produced."""
    bounds, parent = lay.bounds, lay.parent
    ngroups = len(bounds) - 1
    nd = bounds[-2]  # coefficients with descendants: all groups but the finest
    desc = np.zeros(nd, dtype=np.int64)
    for g in range(ngroups - 1, 0, -1):
        a, b = bounds[g], bounds[g + 1]
        below = mag[a:b] if g == ngroups - 1 else np.maximum(mag[a:b], desc[a:b])
        np.maximum.at(desc, parent[a:b], below)
    state = State.empty(lay)
    out = Writer()
    adapt: dict[int, int] = {}
    for step in steps(state, lay, planes):
        t = 1 << step.plane
        idx = step.idx
        if step.kind == SIG:
            bits = mag[idx] >= t
            new = idx[bits]
            adapt[step.context] = out.runs(bits, neg[new], adapt.get(step.context, 0))
            state.sig[new] = True
        elif step.kind == DESC:
            bits = desc[idx] >= t
            adapt[step.context] = out.runs(bits, None, adapt.get(step.context, 0))
            state.desc_sig[idx[bits]] = True
        else:
            out.raw((mag[idx] & t) != 0)
        if out.size >= max_bits:
            break
    return out.bits()


MAX_PIXELS = MAX_SIDE * MAX_SIDE
"""Default largest image ``decode`` builds [px]: 1024 x 1024, every size the header can state and
every camera size the testbed allows (``CameraConfig``: 8..1024 px per side)."""

OK = "ok"
INVALID = "invalid"
TOO_LARGE = "too_large"


@dataclass(slots=True)
class DecodeWork:
    """What one ``decode`` call did; pass one in to have it filled (all counts from zero).

    Attributes:
        status: ``OK``, ``INVALID`` (short or invalid header) or ``TOO_LARGE`` (the header
            claims more than ``max_pixels``); the last two return the "nothing" image.
        pixels: pixels of the image the header claims (0 if it could not be read).
        body_bits: coded bits after the header.
        bits_read: coded bits the schedule consumed (<= body_bits).
        planes: bit planes whose steps carried coefficients (<= bits_read).
        steps: coding steps run that carried coefficients; each reads at least one bit, so
            ``steps <= bits_read``.
        coefficients: coefficients those steps carried (sum of their lengths).
        transform: whether the inverse wavelet transform ran (not when no coefficient is
            significant: the image is then exactly flat mid-grey).
    """

    status: str = ""
    pixels: int = 0
    body_bits: int = 0
    bits_read: int = 0
    planes: int = 0
    steps: int = 0
    coefficients: int = 0
    transform: bool = False


def _nothing(shape: tuple[int, int] | None) -> NDArray[np.uint8]:
    """What an unreadable stream decodes to: mid-grey of ``shape``, or a (0, 0) array."""
    if shape is None:
        return np.zeros((0, 0), dtype=np.uint8)
    return np.full(shape, 128, dtype=np.uint8)


def decode(
    data: bytes,
    shape: tuple[int, int] | None = None,
    *,
    max_pixels: int = MAX_PIXELS,
    work: DecodeWork | None = None,
) -> NDArray[np.uint8]:
    """Decode a stream or any prefix of one to the best image its bytes allow.

    The work is bounded by the data and by ``max_pixels``, never by the header alone: nothing
    the size of the image is allocated before the header's width x height passes
    ``max_pixels``; with no coded bit after the header (or none that makes a coefficient
    significant) the result is the flat mid-grey image, built without the transform; the
    schedule stops at the first step the data does not complete, and each bit plane it enters
    consumes at least one coded bit.

    Args:
        data: the stream, possibly truncated or corrupted.
        shape: (height, width) [px] to return as mid-grey if the header is short, invalid or
            claims more than ``max_pixels``.
        max_pixels: largest width x height [px] to decode (default ``MAX_PIXELS``, 1024 x
            1024); a header claiming more decodes like an invalid one.
        work: if given, filled with what the call did (see ``DecodeWork``).

    Returns:
        (height, width) uint8 image; mid-grey (128) of ``shape`` if the header cannot be read
        or is too large and a shape was given, else an empty (0, 0) array. Never raises on
        bad data.

    Raises:
        ValueError: if ``max_pixels`` < 1 (local misuse).
    """
    if max_pixels < 1:
        raise ValueError(f"max_pixels must be >= 1, got {max_pixels}")
    work = DecodeWork() if work is None else work
    raw = bytes(data)
    hdr = parse_header(raw)
    if hdr is None:
        work.status = INVALID
        return _nothing(shape)
    work.pixels = hdr.width * hdr.height
    if work.pixels > max_pixels:
        work.status = TOO_LARGE
        return _nothing(shape)
    work.status = OK
    body = raw[hdr.size :]
    work.body_bits = 8 * len(body)
    if not body or hdr.planes == 0:  # no coded bit: every coefficient is zero
        return np.full((hdr.height, hdr.width), 128, dtype=np.uint8)
    lay = layout(hdr.height, hdr.width, hdr.levels)
    rec = _decode_coefficients(body, lay, hdr.planes, work)
    if rec is None:  # nothing significant: the transform of zeros is exactly 0
        return np.full((hdr.height, hdr.width), 128, dtype=np.uint8)
    if hdr.roi is not None:
        inside = roi_mask(lay, hdr.roi)
        rec = np.where(inside, rec / float(1 << hdr.roi_shift), rec)
    work.transform = True
    pixels = inverse(rec, lay) + _OFFSET
    return np.clip(np.round(pixels), 0, 255).astype(np.uint8)


def _decode_coefficients(
    body: bytes, lay: Layout, planes: int, work: DecodeWork
) -> NDArray[np.float64] | None:
    """(n,) coefficients rebuilt from the coded bits, at 3/8 of the interval still open; None
    if no coefficient became significant (all are zero)."""
    n = lay.size
    stream = Reader(body)
    # Magnitudes have at most 31 bits (MAX_PLANES), planes fit a byte: 5 B per coefficient.
    mag = np.zeros(n, dtype=np.int32)
    low = np.full(n, planes, dtype=np.int8)  # lowest plane known for significant coefficients
    neg = np.zeros(n, dtype=bool)
    state = State.empty(lay)
    adapt: dict[int, int] = {}
    plane = planes
    for step in steps(state, lay, planes):
        p = step.plane
        idx = step.idx
        if idx.size:  # an empty step reads nothing
            work.steps += 1
            work.coefficients += idx.size
            if p != plane:
                plane = p
                work.planes += 1
        if step.kind == REF:
            rbits = stream.raw(idx.size)
            part = idx[: rbits.size]
            mag[part] |= rbits.astype(np.int32) << p
            low[part] = p
            complete = rbits.size == idx.size
        else:
            ones, signs, k, complete = stream.runs(
                idx.size, step.kind == SIG, adapt.get(step.context, 0)
            )
            adapt[step.context] = k
            hit = idx[np.asarray(ones, dtype=np.int64)]
            if step.kind == SIG:
                mag[hit], low[hit], neg[hit] = 1 << p, p, np.asarray(signs, dtype=bool)
                state.sig[hit] = True
            else:
                state.desc_sig[hit] = True
        if not complete or stream.left == 0:
            break
    work.bits_read = stream.pos
    found = np.flatnonzero(state.sig)
    if not found.size:
        return None
    value = mag[found].astype(np.int64) + 0.375 * np.left_shift(1, low[found].astype(np.int64))
    out = np.zeros(n)
    out[found] = np.where(neg[found], -value, value)
    return out
