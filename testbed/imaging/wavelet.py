"""The CDF 9/7 transform, the coefficient layout the bit-plane coder walks, and ROI masks.

The transform is PyWavelets' ``bior4.4`` (the CDF 9/7 pair of JPEG 2000 Part 1) in
``periodization`` mode. That mode is non-expansive (a band at level j has ceil(n / 2^j) samples
per axis: as many coefficients as pixels when 2^levels divides the sides, a few more when an
odd length is rounded up) and is exactly invertible to float
rounding (about 1e-12 on 8-bit images); every band has a clean 2x2 parent-child relation, which
the set-partitioning coder needs. Its price is that the wavelets wrap around the image border.

Coefficients are kept in one flat vector ordered coarse to fine: group 0 is the LL band; group g
(1..levels) holds the three detail bands (horizontal, vertical, diagonal detail, pywt order) of
level ``levels - g + 1``, each in raster order. Every coefficient of group g >= 1 has a parent in
group g - 1: an LL coefficient parents the three coarsest detail coefficients at its position,
and a detail coefficient at (r, c) parents its band's 2x2 block at (2r, 2c) one level finer.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import pywt
from numpy.typing import NDArray

WAVELET = "bior4.4"
MODE = "periodization"


@dataclass(frozen=True, slots=True)
class Layout:
    """Where each band lives in the flat coefficient vector.

    Attributes:
        height: image height [px].
        width: image width [px].
        levels: decomposition levels.
        shapes: (rows, cols) per band, in flat order: LL, then 3 bands per group.
        bounds: group g occupies flat[bounds[g]:bounds[g + 1]]; len = levels + 2.
        parent: (n,) flat index of each coefficient's parent, -1 for the LL band.
    """

    height: int
    width: int
    levels: int
    shapes: tuple[tuple[int, int], ...]
    bounds: tuple[int, ...]
    parent: NDArray[np.int64]

    @property
    def size(self) -> int:
        """Number of coefficients (= pixels)."""
        return self.bounds[-1]


def default_levels(height: int, width: int) -> int:
    """Decomposition levels that leave an LL band of 3..4 samples on the short side.

    Deep decompositions measured best at the link's budgets: 160 x 120 gets 5 levels, 320 x 240
    gets 6 (0.1–0.2 dB over one level fewer at 300–2400 B).
    """
    levels, side = 0, min(height, width)
    while side > 4 and levels < 7:
        side = (side + 1) // 2
        levels += 1
    return levels


@lru_cache(maxsize=32)
def layout(height: int, width: int, levels: int) -> Layout:
    """The flat layout for an image of (height, width) pixels and ``levels`` levels."""
    sizes = [(height, width)]
    for _ in range(levels):
        h, w = sizes[-1]
        sizes.append(((h + 1) // 2, (w + 1) // 2))
    shapes: list[tuple[int, int]] = [sizes[levels]]
    bounds = [0, sizes[levels][0] * sizes[levels][1]]
    parents: list[NDArray[np.int64]] = [np.full(bounds[1], -1, dtype=np.int64)]
    prev_starts = [0, 0, 0]  # flat start of the parent band for each orientation
    for g in range(1, levels + 1):
        rows, cols = sizes[levels - g + 1]
        starts = []
        for o in range(3):
            start = bounds[-1] + o * rows * cols
            starts.append(start)
            r = np.arange(rows)[:, None]
            c = np.arange(cols)[None, :]
            if g == 1:
                pidx = r * cols + c  # the LL coefficient at the same position
            else:
                pcols = shapes[-3 + o][1]
                pidx = prev_starts[o] + (r // 2) * pcols + c // 2
            parents.append(np.broadcast_to(pidx, (rows, cols)).ravel().astype(np.int64))
        shapes.extend([(rows, cols)] * 3)
        bounds.append(bounds[-1] + 3 * rows * cols)
        prev_starts = starts
    return Layout(height, width, levels, tuple(shapes), tuple(bounds), np.concatenate(parents))


def forward(image: NDArray[np.float64], levels: int) -> NDArray[np.float64]:
    """(n,) flat coefficient vector of a (height, width) float image."""
    with warnings.catch_warnings():  # periodization has no boundary limit on the level count
        warnings.simplefilter("ignore", UserWarning)
        coeffs = pywt.wavedec2(image, WAVELET, mode=MODE, level=levels)
    parts = [np.ravel(coeffs[0])]
    for details in coeffs[1:]:
        parts.extend(np.ravel(d) for d in details)
    return np.concatenate(parts)


def inverse(flat: NDArray[np.float64], lay: Layout) -> NDArray[np.float64]:
    """(height, width) float image from a flat coefficient vector (inverse of ``forward``)."""
    pieces = []
    pos = 0
    for rows, cols in lay.shapes:
        pieces.append(flat[pos : pos + rows * cols].reshape(rows, cols))
        pos += rows * cols
    if lay.levels == 0:
        return pieces[0]
    coeffs: list[object] = [pieces[0]]
    for g in range(lay.levels):
        coeffs.append(tuple(pieces[1 + 3 * g : 4 + 3 * g]))
    out = pywt.waverec2(coeffs, WAVELET, mode=MODE)
    return np.asarray(out[: lay.height, : lay.width], dtype=np.float64)


@lru_cache(maxsize=1)
def _support_wavelet() -> pywt.Wavelet:
    """A filter bank whose analysis is the adjoint of bior4.4 synthesis with |taps|."""
    base = pywt.Wavelet(WAVELET)
    lo = np.abs(np.asarray(base.rec_lo)[::-1])
    hi = np.abs(np.asarray(base.rec_hi)[::-1])
    return pywt.Wavelet("support", filter_bank=[lo, hi, lo, hi])


def roi_mask(lay: Layout, roi: tuple[int, int, int, int]) -> NDArray[np.bool_]:
    """(n,) True for coefficients whose synthesis basis function touches the ROI rectangle.

    The rectangle (x0, y0, x1, y1), inclusive pixels, is mapped to every band by running the
    adjoint of the synthesis transform, with absolute filter taps, on the rectangle's indicator:
    a coefficient is marked exactly when its synthesis filter support (7 or 9 taps per level)
    overlaps the ROI, which is the per-band rectangle scaled by 2^level and padded by the filter
    support, wrap-around included.
    """
    x0, y0, x1, y1 = roi
    indicator = np.zeros((lay.height, lay.width))
    indicator[min(y0, y1) : max(y0, y1) + 1, min(x0, x1) : max(x0, x1) + 1] = 1.0
    if lay.levels == 0:
        return indicator.ravel() > 0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        coeffs = pywt.wavedec2(indicator, _support_wavelet(), mode=MODE, level=lay.levels)
    parts = [np.ravel(coeffs[0])]
    for details in coeffs[1:]:
        parts.extend(np.ravel(d) for d in details)
    return np.concatenate(parts) > 1e-9
