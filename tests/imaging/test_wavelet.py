"""The CDF 9/7 lifting transform: invertible, equal to PyWavelets' bior4.4, symmetric borders;
the layout's parent links; ROI masks checked by synthesis."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import pywt

from testbed.imaging.wavelet import forward, inverse, layout, roi_mask


@pytest.mark.parametrize("shape", [(120, 160), (240, 320), (17, 33), (1, 9), (64, 64)])
def test_transform_is_exactly_invertible(shape: tuple[int, int]) -> None:
    img = np.random.default_rng(3).uniform(-128, 128, size=shape)
    lay = layout(*shape, 4)
    flat = forward(img, 4)
    assert flat.size == lay.size >= img.size
    if shape[0] % 16 == 0 and shape[1] % 16 == 0:
        assert flat.size == img.size  # periodization is non-expansive on whole blocks
    assert np.max(np.abs(inverse(flat, lay) - img)) < 1e-9


def test_parent_of_every_detail_coefficient_is_one_group_coarser() -> None:
    lay = layout(128, 160, 4)  # whole 2x2 blocks at every level
    for g in range(1, len(lay.bounds) - 1):
        par = lay.parent[lay.bounds[g] : lay.bounds[g + 1]]
        assert par.min() >= lay.bounds[g - 1] and par.max() < lay.bounds[g]
    assert np.all(lay.parent[: lay.bounds[1]] == -1)
    # Four children per detail parent, three per LL parent
    counts = np.bincount(lay.parent[lay.bounds[2] :], minlength=lay.size)
    assert set(counts[lay.bounds[1] : lay.bounds[2]].tolist()) == {4}
    assert set(np.bincount(lay.parent[lay.bounds[1] : lay.bounds[2]]).tolist()) == {3}


def test_roi_mask_holds_every_coefficient_that_reaches_the_roi() -> None:
    # Independent check by synthesis: coefficients outside the mask never touch ROI pixels,
    # and each one inside does (probed on a sample of them).
    lay = layout(120, 160, 4)
    roi = (50, 30, 90, 70)
    mask = roi_mask(lay, roi)
    rng = np.random.default_rng(4)
    outside = np.where(mask, 0.0, rng.normal(size=lay.size))
    assert np.max(np.abs(inverse(outside, lay)[30:71, 50:91])) < 1e-9
    for i in rng.choice(np.flatnonzero(mask), size=40, replace=False):
        unit = np.zeros(lay.size)
        unit[i] = 1.0
        assert np.max(np.abs(inverse(unit, lay)[30:71, 50:91])) > 1e-6
    assert 0.1 < mask.mean() < 0.5  # padded rectangle, not the whole image


@pytest.mark.parametrize("levels", [1, 3])
def test_interior_coefficients_equal_pywavelets_bior44(levels: int) -> None:
    # Away from the borders the extension does not matter: compare with pywt's periodization.
    img = np.random.default_rng(6).normal(size=(128, 192))
    lay = layout(128, 192, levels)
    ours = forward(img, levels)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        ref = pywt.wavedec2(img, "bior4.4", mode="periodization", level=levels)
    bands = [ref[0], *(band for details in ref[1:] for band in details)]
    pos = 0
    for (rows, cols), band in zip(lay.shapes, bands, strict=True):
        mine = ours[pos : pos + rows * cols].reshape(rows, cols)
        pos += rows * cols
        assert band.shape == mine.shape
        edge = 5
        assert np.max(np.abs(mine - band)[edge:-edge, edge:-edge]) < 1e-9


def test_symmetric_borders_leave_a_smooth_ramp_without_edge_energy() -> None:
    # A ramp wraps around into a step under periodization; under symmetric extension it only
    # folds, so the finest detail bands stay far smaller.
    ramp = np.add.outer(np.arange(64.0), 2.0 * np.arange(96.0))
    lay = layout(64, 96, 1)
    ours = forward(ramp, 1)[lay.bounds[1] :]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        _, details = pywt.dwt2(ramp, "bior4.4", mode="periodization")
    wrapped = np.concatenate([np.ravel(d) for d in details])
    assert np.sum(ours**2) < 0.01 * np.sum(wrapped**2)
