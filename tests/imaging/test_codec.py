"""The embedded wavelet coder: prefixes, monotone quality, ROI, garbage, header."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from testbed.imaging import Header, decode, encode, parse_header, pool_scene


def psnr_db(a: np.ndarray, b: np.ndarray) -> float:
    mse = float(np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2))
    return float("inf") if mse == 0 else 10.0 * np.log10(255.0**2 / mse)


@pytest.fixture(scope="module")
def small() -> np.ndarray:
    return pool_scene(160, 120, np.random.default_rng(1))


@pytest.fixture(scope="module")
def large() -> np.ndarray:
    return pool_scene(320, 240, np.random.default_rng(2))


AMPHORA_ROI = (30, 40, 80, 110)


@pytest.mark.parametrize(
    "header",
    [
        Header(160, 120, 4, 10),
        Header(1024, 1, 0, 0),
        Header(320, 240, 5, 31, True, (1023, 0, 5, 700), 15),
        Header(1, 1024, 7, 18, False, (10, 20, 30, 40), 1),
    ],
)
def test_header_round_trip(header: Header) -> None:
    packed = header.pack()
    assert len(packed) == header.size
    assert parse_header(packed) == header
    assert parse_header(packed + b"\xff\x00") == header
    assert parse_header(packed[:-1]) is None


def test_header_rejects_bad_magic_and_fields() -> None:
    good = Header(160, 120, 4, 10).pack()
    assert parse_header(bytes([good[0] ^ 0x80]) + good[1:]) is None
    assert parse_header(b"") is None
    with pytest.raises(ValueError):
        Header(0, 10, 1, 1)
    with pytest.raises(ValueError):
        Header(10, 10, 1, 1, True, None, 3)


def test_encoder_writes_the_header_it_was_asked_for(small: np.ndarray) -> None:
    hdr = parse_header(encode(small, 500, roi=(80, 100, 10, 20), roi_shift=3))
    assert hdr is not None
    assert (hdr.width, hdr.height, hdr.mono, hdr.roi_shift) == (160, 120, True, 3)
    assert hdr.roi == (10, 20, 80, 100)  # corners ordered
    assert parse_header(encode(small, 500, roi=(1, 2, 3, 4), roi_shift=0)) == Header(
        160, 120, hdr.levels, hdr.planes - 3
    )


def test_every_prefix_decodes_to_the_right_shape(small: np.ndarray) -> None:
    stream = encode(small, 2400)
    assert len(stream) == 2400
    lengths = list(range(0, 80)) + list(range(80, len(stream) + 1, 37)) + [len(stream)]
    for n in lengths:
        out = decode(stream[:n], shape=(120, 160))
        assert out.shape == (120, 160) and out.dtype == np.uint8
        if n >= 5:
            assert np.array_equal(decode(stream[:n]), out)
    assert decode(b"").shape == (0, 0)
    assert np.all(decode(stream[:4], shape=(120, 160)) == 128)


def test_a_prefix_is_the_stream_of_the_smaller_budget(small: np.ndarray) -> None:
    stream = encode(small, 3000)
    for budget in (0, 1, 5, 6, 300, 1201, 2999):
        assert encode(small, budget) == stream[:budget]


def test_psnr_never_drops_as_the_prefix_grows(small: np.ndarray, large: np.ndarray) -> None:
    for img in (small, large):
        stream = encode(img, 6000)
        values = [psnr_db(img, decode(stream[:n])) for n in range(10, len(stream) + 1, 25)]
        assert all(b >= a for a, b in itertools.pairwise(values))
        assert values[-1] > values[0] + 15.0


def test_large_budget_is_nearly_lossless(small: np.ndarray) -> None:
    stream = encode(small, 20_000)
    assert len(stream) < 20_000  # the whole stream fits
    assert psnr_db(small, decode(stream)) > 45.0


def test_flat_image_costs_only_the_header() -> None:
    flat = np.full((60, 80), 128, dtype=np.uint8)
    stream = encode(flat, 1000)
    assert len(stream) == 5
    assert np.array_equal(decode(stream), flat)


@pytest.mark.parametrize(("budget", "gain_db"), [(600, 3.0), (1200, 3.0), (2400, 5.0)])
def test_roi_shift_buys_quality_inside_the_roi(
    small: np.ndarray, budget: int, gain_db: float
) -> None:
    x0, y0, x1, y1 = AMPHORA_ROI
    inside = (slice(y0, y1 + 1), slice(x0, x1 + 1))
    plain = decode(encode(small, budget, roi=AMPHORA_ROI, roi_shift=0))
    shifted = decode(encode(small, budget, roi=AMPHORA_ROI, roi_shift=4))
    gain = psnr_db(small[inside], shifted[inside]) - psnr_db(small[inside], plain[inside])
    assert gain > gain_db
    # The bytes came from the background.
    assert psnr_db(small, shifted) < psnr_db(small, plain)


def test_colour_input_is_coded_as_luma() -> None:
    rgb = np.random.default_rng(5).integers(0, 256, size=(24, 32, 3), dtype=np.uint8)
    luma = np.round(rgb.astype(float) @ np.array([0.299, 0.587, 0.114]))
    out = decode(encode(rgb, 100_000))
    assert np.max(np.abs(out - luma)) <= 2


@pytest.mark.parametrize(
    "kwargs",
    [{"budget_bytes": -1}, {"roi_shift": 16}, {"mono": False}, {"levels": 8}],
)
def test_local_misuse_raises(small: np.ndarray, kwargs: dict[str, object]) -> None:
    args: dict[str, object] = {"budget_bytes": 100, **kwargs}
    with pytest.raises((ValueError, NotImplementedError)):
        encode(small, **args)  # type: ignore[arg-type]


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=300))
def test_garbage_never_raises(data: bytes) -> None:
    out = decode(data, shape=(12, 16))
    assert out.dtype == np.uint8 and out.ndim == 2


@settings(max_examples=100, deadline=None)
@given(st.binary(min_size=0, max_size=400), st.integers(1, 64), st.integers(1, 64))
def test_garbage_after_a_valid_header_decodes_to_its_shape(
    body: bytes, width: int, height: int
) -> None:
    head = Header(width, height, 3, 12, True, (0, 0, width // 2, height // 2), 2).pack()
    out = decode(head + body)
    assert out.shape == (height, width)
