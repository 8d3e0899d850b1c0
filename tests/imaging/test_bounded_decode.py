"""Decoding work is bounded by the data and by ``max_pixels``, never by the header alone.

Asserted on the decoder's work counter (``DecodeWork``) and on tracemalloc peaks, not on time.
"""

from __future__ import annotations

import itertools
import tracemalloc
from collections.abc import Callable

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from testbed.imaging import MAX_PIXELS, DecodeWork, Header, decode, encode, pool_scene
from testbed.imaging.codec import INVALID, OK, TOO_LARGE
from testbed.imaging.wavelet import inverse, layout

KIB = 1024
SMALL = 64 * KIB  # [B] headroom for the decoder's own small objects

ADVERSARIAL = Header(1024, 1024, 7, 31, True, (0, 0, 1023, 1023), 15).pack()
"""11 bytes: a header claiming 1024 x 1024, 7 levels, 31 planes, a full-image ROI, no data."""


def peak_bytes(call: Callable[[], object]) -> int:
    """Peak traced allocation [B] while ``call`` runs."""
    tracemalloc.start()
    try:
        call()
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def psnr_db(a: np.ndarray, b: np.ndarray) -> float:
    mse = float(np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2))
    return float("inf") if mse == 0 else 10.0 * np.log10(255.0**2 / mse)


def slow_flat(hdr: Header) -> np.ndarray:
    """What the transform makes of all-zero coefficients (the path the decoder now skips)."""
    lay = layout(hdr.height, hdr.width, hdr.levels)
    pixels = inverse(np.zeros(lay.size), lay) + 128.0
    return np.clip(np.round(pixels), 0, 255).astype(np.uint8)


def test_header_only_1024_square_stream_does_no_coding_work() -> None:
    assert len(ADVERSARIAL) == 11
    work = DecodeWork()
    out = decode(ADVERSARIAL, work=work)
    assert out.shape == (1024, 1024) and out.dtype == np.uint8 and np.all(out == 128)
    assert work == DecodeWork(status=OK, pixels=1024 * 1024)  # no bit, no step, no transform
    # Only the output itself (1 MiB of uint8) is allocated: before, 44 MB.
    assert peak_bytes(lambda: decode(ADVERSARIAL)) <= 1024 * 1024 + SMALL


def test_header_only_stream_above_the_maximum_allocates_nothing_of_its_size() -> None:
    work = DecodeWork()
    out = decode(ADVERSARIAL, max_pixels=160 * 120, work=work)
    assert out.shape == (0, 0)
    assert work.status == TOO_LARGE and work.steps == 0 and not work.transform
    grey = decode(ADVERSARIAL, shape=(120, 160), max_pixels=160 * 120)
    assert grey.shape == (120, 160) and np.all(grey == 128)
    assert peak_bytes(lambda: decode(ADVERSARIAL, max_pixels=160 * 120)) <= SMALL


def test_a_huge_header_with_data_beyond_the_maximum_is_nothing() -> None:
    body = np.random.default_rng(3).bytes(300)
    stream = Header(1024, 1000, 7, 31).pack() + body
    work = DecodeWork()
    out = decode(stream, shape=(12, 16), max_pixels=64 * 64, work=work)
    assert out.shape == (12, 16) and np.all(out == 128)
    assert (work.status, work.pixels, work.bits_read) == (TOO_LARGE, 1024 * 1000, 0)
    assert peak_bytes(lambda: decode(stream, max_pixels=64 * 64)) <= SMALL
    # The limit is inclusive, and the default covers every camera size (8..1024 px per side).
    assert MAX_PIXELS == 1024 * 1024
    assert decode(Header(64, 64, 3, 5).pack(), max_pixels=64 * 64).shape == (64, 64)
    assert decode(Header(64, 64, 3, 5).pack(), max_pixels=64 * 64 - 1).shape == (0, 0)


def test_invalid_header_is_counted_and_misuse_raises() -> None:
    work = DecodeWork()
    assert decode(b"\x00" * 20, work=work).shape == (0, 0)
    assert work.status == INVALID
    with pytest.raises(ValueError):
        decode(ADVERSARIAL, max_pixels=0)


@pytest.mark.parametrize(
    "header",
    [
        Header(1024, 1024, 7, 31, True, (0, 0, 1023, 1023), 15),
        Header(160, 120, 5, 12),
        Header(33, 17, 7, 4, True, (3, 2, 20, 9), 2),
        Header(1, 1, 0, 1),
        Header(1000, 3, 2, 9),
    ],
)
def test_flat_short_cut_equals_the_transform_of_zeros(header: Header) -> None:
    head = header.pack()
    assert np.array_equal(decode(head), slow_flat(header))
    # Data whose bits make nothing significant ("1": a block of zeros) takes the same cut.
    work = DecodeWork()
    out = decode(head + b"\xff" * 4, work=work)
    assert work.bits_read > 0 and not work.transform
    assert np.array_equal(out, slow_flat(header))


def test_decoding_stops_when_the_bits_run_out() -> None:
    # One byte after the 1024 x 1024 header: a handful of steps, not the header's 31 planes.
    for byte in (0x00, 0x5A, 0xFF):
        work = DecodeWork()
        decode(ADVERSARIAL + bytes([byte]), work=work)
        assert work.body_bits == 8 and work.bits_read <= 8
        assert 1 <= work.steps <= work.bits_read and work.planes <= work.bits_read


@pytest.fixture(scope="module")
def streams() -> list[tuple[np.ndarray, bytes]]:
    small = pool_scene(64, 48, np.random.default_rng(1))
    other = pool_scene(48, 40, np.random.default_rng(2))
    return [
        (small, encode(small, 1500)),
        (other, encode(other, 1200, roi=(5, 5, 30, 25), roi_shift=3)),
    ]


def test_every_prefix_of_real_streams_keeps_the_invariants(
    streams: list[tuple[np.ndarray, bytes]],
) -> None:
    for img, stream in streams:
        hdr = Header(img.shape[1], img.shape[0], 0, 0)  # only the shape is used below
        values = []
        for n in range(len(stream) + 1):
            work = DecodeWork()
            out = decode(stream[:n], shape=img.shape, work=work)
            assert out.shape == img.shape and out.dtype == np.uint8
            assert work.bits_read <= work.body_bits
            assert work.steps <= work.bits_read and work.planes <= work.bits_read
            if n >= 11:
                values.append(psnr_db(img, out))
        # PSNR grows with the prefix in expectation; byte by byte it dips a little (measured
        # worst: 0.029 dB plain, 0.055 dB with the ROI, the same outputs as before the bound).
        assert all(b >= a - 0.1 for a, b in itertools.pairwise(values))
        assert values[-1] > values[0] + 10.0
        # The exact size limit admits the image; the full stream is the nearly lossless one.
        full = decode(stream, max_pixels=hdr.width * hdr.height)
        assert np.array_equal(full, decode(stream)) and psnr_db(img, full) > 30.0


@settings(max_examples=60, deadline=None)
@given(
    st.integers(1, 1024),
    st.integers(1, 1024),
    st.integers(0, 7),
    st.integers(0, 31),
    st.one_of(st.none(), st.tuples(*[st.integers(0, 1023)] * 4)),
    st.integers(1, 15),
    st.binary(max_size=200),
)
def test_random_streams_never_raise_nor_exceed_the_maximum(
    width: int,
    height: int,
    levels: int,
    planes: int,
    roi: tuple[int, int, int, int] | None,
    shift: int,
    body: bytes,
) -> None:
    limit = 64 * 64
    header = Header(width, height, levels, planes, True, roi, shift if roi else 0)
    stream = header.pack() + body
    result: list[np.ndarray] = []
    peak = peak_bytes(lambda: result.append(decode(stream, max_pixels=limit)))
    out = result[0]
    assert out.dtype == np.uint8 and out.size <= limit
    assert out.shape == ((height, width) if width * height <= limit else (0, 0))
    # A few float64 images of the largest allowed size, never the header's claim.
    assert peak <= 24 * 8 * limit + SMALL


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=300))
def test_random_bytes_never_raise_nor_exceed_the_maximum(data: bytes) -> None:
    limit = 32 * 32
    result: list[np.ndarray] = []
    peak = peak_bytes(lambda: result.append(decode(data, shape=(12, 16), max_pixels=limit)))
    out = result[0]
    assert out.dtype == np.uint8 and out.ndim == 2 and out.size <= limit
    assert peak <= 24 * 8 * limit + SMALL
