"""The EndEffectorGoTo order (code 8, the extension of the paper's order table).

Expected bytes are written by hand from the layout documented in ``orders.py`` (three int16
big-endian centimetre coordinates, then a u16 tool yaw in 0.01° with 0xFFFF = no yaw), not
taken from the encoder; frames are checked with a bit-by-bit CRC-16/XMODEM.
"""

from __future__ import annotations

from collections.abc import Callable

import pytest
from hypothesis import given
from hypothesis import strategies as st

from testbed.protocol import (
    ORDER_TYPES,
    DisableKeepHeading,
    GoTo,
    HoldChannel,
    ImageSettings,
    KeepHeading,
    MalformedPayload,
    Move,
    NoOrder,
    OperatorMessage,
    OrderIncoming,
    decode_operator_message,
    encode_frame,
    order_type_of,
)
from testbed.protocol.orders import EE_NO_YAW, EndEffectorGoTo
from tests.strategies import crc16_bitwise, int16

yaw_codes = st.none() | st.integers(0, 35999)
"""A tool yaw field over its whole range: none, or 0.00..359.99° in 0.01° codes."""
end_effector_goals = st.builds(EndEffectorGoTo, int16, int16, int16, yaw_codes)


# ------------------------------------------------------------------------------ the table


def test_code_8_extends_the_papers_table_and_9_to_15_stay_unused() -> None:
    assert (EndEffectorGoTo.CODE, EndEffectorGoTo.BODY_SIZE) == (8, 8)
    assert ORDER_TYPES[8] is EndEffectorGoTo
    paper = {
        0: NoOrder,
        1: Move,
        2: KeepHeading,
        3: HoldChannel,
        4: ImageSettings,
        5: DisableKeepHeading,
        6: GoTo,
        7: OrderIncoming,
    }
    assert {code: cls for code, cls in ORDER_TYPES.items() if code != 8} == paper
    assert all(code == cls.CODE for code, cls in ORDER_TYPES.items())
    assert order_type_of(bytes((0x80, 0xC8))) is EndEffectorGoTo  # flags set, body absent
    for code in range(9, 16):
        assert order_type_of(bytes((0, code))) is None


# ------------------------------------------------------------------------ bytes by hand


def test_body_bytes_by_hand() -> None:
    # x = 1234 cm = 0x04D2; y = −2 cm = 0xFFFE; z = −32768 cm = 0x8000;
    # yaw = 270.00° = 27000 = 0x6978
    assert EndEffectorGoTo(1234, -2, -32768, 27000).encode() == bytes.fromhex("04D2 FFFE 8000 6978")
    # no yaw target: the 0xFFFF sentinel; 32767 = 0x7FFF, 0, 1 = 0x0001
    assert EndEffectorGoTo(32767, 0, 1).encode() == bytes.fromhex("7FFF 0000 0001 FFFF")
    assert EE_NO_YAW == 0xFFFF
    # yaw 0.01° = code 1, 359.99° = code 35999 = 0x8C9F
    assert EndEffectorGoTo(0, 0, 0, 1).encode()[6:] == b"\x00\x01"
    assert EndEffectorGoTo(0, 0, 0, 35999).encode()[6:] == b"\x8c\x9f"
    assert EndEffectorGoTo.decode(bytes.fromhex("04D2 FFFE 8000 6978")) == EndEffectorGoTo(
        1234, -2, -32768, 27000
    )
    assert EndEffectorGoTo.decode(bytes.fromhex("7FFF 0000 0001 FFFF")).yaw_cdeg is None


def test_payload_and_frame_by_hand() -> None:
    order = EndEffectorGoTo(300, -125, 250, 9000)
    payload = OperatorMessage(True, False, 5, True, True, order).encode()
    # byte 0: image bit 7 set, chunk 5 = 0x85; byte 1: seq bit 7, cancel bit 6, type 8 = 0xC8
    # 300 = 0x012C, −125 = 0xFF83, 250 = 0x00FA, 90.00° = 9000 = 0x2328
    expected = bytes.fromhex("85 C8 012C FF83 00FA 2328")
    assert payload == expected
    head = bytes((0x55, 0x55, 0x55, 0x0A)) + expected  # WAFrame: CRC over preamble and all
    frame = head + crc16_bitwise(head).to_bytes(2, "big")
    assert encode_frame(payload, 3) == frame and len(frame) == 16  # a GoTo's 16-B frame
    assert decode_operator_message(payload) == OperatorMessage(True, False, 5, True, True, order)


# --------------------------------------------------------------------------- round trips


@given(end_effector_goals)
def test_round_trip_over_the_whole_range(order: EndEffectorGoTo) -> None:
    body = order.encode()
    assert len(body) == EndEffectorGoTo.BODY_SIZE
    assert EndEffectorGoTo.decode(body) == order
    message = OperatorMessage(False, True, 63, False, True, order)
    assert decode_operator_message(message.encode()) == message


@given(st.binary(min_size=8, max_size=8))
def test_decode_accepts_only_canonical_bodies(body: bytes) -> None:
    try:
        order = EndEffectorGoTo.decode(body)
    except ValueError:
        assert 36000 <= int.from_bytes(body[6:], "big") <= 0xFFFE  # only reserved yaw codes
        return
    assert order.encode() == body


# ---------------------------------------------------------------------- local misuse


@pytest.mark.parametrize(
    "build",
    [
        lambda: EndEffectorGoTo(32768, 0, 0),
        lambda: EndEffectorGoTo(0, -32769, 0),
        lambda: EndEffectorGoTo(0, 0, 40000),
        lambda: EndEffectorGoTo(0, 0, 0, -1),
        lambda: EndEffectorGoTo(0, 0, 0, 36000),
        lambda: EndEffectorGoTo(0, 0, 0, EE_NO_YAW),  # the sentinel is None, not a value
        lambda: EndEffectorGoTo(1.5, 0, 0),  # type: ignore[arg-type]  # not an int
        lambda: EndEffectorGoTo(0, 0, 0, 90.0),  # type: ignore[arg-type]  # not an int
    ],
)
def test_out_of_range_values_raise(build: Callable[[], object]) -> None:
    with pytest.raises(ValueError, match="must be"):
        build()


@pytest.mark.parametrize(
    ("body", "match"),
    [
        (bytes(7), "8 B"),
        (bytes(9), "8 B"),
        (bytes.fromhex("0000 0000 0000 8CA0"), "reserved"),  # 36000
        (bytes.fromhex("0000 0000 0000 FFFE"), "reserved"),  # 65534
    ],
)
def test_bad_bodies_raise_value_error(body: bytes, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        EndEffectorGoTo.decode(body)


# ------------------------------------------------------------ remote garbage is a value


@pytest.mark.parametrize(
    ("payload", "match"),
    [
        (bytes.fromhex("00 08"), "8 B"),  # the header alone
        (bytes.fromhex("00 08 0000 0000 0000"), "8 B"),  # truncated yaw
        (bytes.fromhex("00 08 0000 0000 0000 FFFF 00"), "8 B"),  # one byte too many
        (bytes.fromhex("00 08 0000 0000 0000 9000"), "reserved"),  # yaw code 36864
        (bytes.fromhex("00 38 0000 0000 0000 0000"), "reserved"),  # header bits 5..4
        *(
            (bytes((0, code)) + bytes(8), f"unknown order type {code}")
            for code in range(9, 16)  # an EndEffectorGoTo body under an unused code
        ),
    ],
)
def test_garbled_or_unknown_codes_are_malformed_values(payload: bytes, match: str) -> None:
    result = decode_operator_message(payload)
    assert isinstance(result, MalformedPayload)
    assert match in result.reason


@given(st.integers(0, 255), st.integers(8, 15), st.binary(max_size=12))
def test_decoding_never_raises_on_any_body_under_codes_8_to_15(
    byte0: int, code: int, body: bytes
) -> None:
    payload = bytes((byte0, code)) + body
    result = decode_operator_message(payload)
    if code > 8:
        assert isinstance(result, MalformedPayload)
    else:
        assert isinstance(result, MalformedPayload) or result.encode() == payload


def test_every_single_bit_flip_of_a_valid_payload_decodes_canonically_or_is_a_value() -> None:
    payload = OperatorMessage(True, True, 9, True, False, EndEffectorGoTo(-1, 2, -3, 35999))
    data = payload.encode()
    for bit in range(8 * len(data)):
        flipped = bytearray(data)
        flipped[bit // 8] ^= 0x80 >> (bit % 8)
        result = decode_operator_message(bytes(flipped))
        assert isinstance(result, MalformedPayload) or result.encode() == bytes(flipped)
