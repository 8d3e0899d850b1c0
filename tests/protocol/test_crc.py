"""CRC-16/XMODEM against the catalogue check value and an independent bit-by-bit implementation."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from testbed.protocol import CRC16_CHECK_VALUE, crc16
from tests.strategies import crc16_bitwise


def test_check_value_is_the_xmodem_catalogue_value() -> None:
    assert crc16(b"123456789") == 0x31C3 == CRC16_CHECK_VALUE
    assert crc16_bitwise(b"123456789") == 0x31C3


def test_is_not_ccitt_false_or_kermit() -> None:
    # CCITT-FALSE (init 0xFFFF) gives 0x29B1; KERMIT (reflected) gives 0x2189.
    assert crc16(b"123456789") not in (0x29B1, 0x2189)
    assert crc16_bitwise(b"123456789", 0xFFFF) == 0x29B1  # the reference handles an init value


def test_empty_input_keeps_initial_value() -> None:
    assert crc16(b"") == 0
    assert crc16(b"", 0x1234) == 0x1234


@given(st.binary(max_size=300))
def test_matches_bitwise_reference(data: bytes) -> None:
    assert crc16(data) == crc16_bitwise(data)


@given(st.binary(max_size=100), st.binary(max_size=100))
def test_running_crc_chains(a: bytes, b: bytes) -> None:
    assert crc16(b, crc16(a)) == crc16(a + b)


@given(st.binary(max_size=300))
def test_appended_big_endian_fcs_leaves_zero_residue(data: bytes) -> None:
    fcs = crc16(data).to_bytes(2, "big")
    assert crc16(data + fcs) == 0
    assert crc16_bitwise(data + fcs) == 0


@given(st.binary(min_size=1, max_size=64), st.data())
def test_detects_every_burst_of_up_to_16_bits(data: bytes, draw: st.DataObject) -> None:
    """A degree-16 polynomial with a nonzero constant term catches every burst ≤ 16 bits."""
    nbits = len(data) * 8
    length = draw.draw(st.integers(1, min(16, nbits)))
    start = draw.draw(st.integers(0, nbits - length))
    inner = draw.draw(st.integers(0, (1 << max(0, length - 2)) - 1)) if length > 2 else 0
    burst = 1 | (inner << 1) | (1 << (length - 1))  # first and last bit of the burst set
    error = burst << (nbits - start - length)
    corrupted = (int.from_bytes(data, "big") ^ error).to_bytes(len(data), "big")
    assert crc16(corrupted) != crc16(data)


@pytest.mark.parametrize("crc", [-1, 0x10000])
def test_rejects_out_of_range_initial_value(crc: int) -> None:
    with pytest.raises(ValueError, match="crc"):
        crc16(b"x", crc)
