"""Order bodies: REFERENCE §1.3 layouts by hand, round trips, validation."""

from __future__ import annotations

import math
import struct
from collections.abc import Callable

import pytest
from hypothesis import given
from hypothesis import strategies as st

from testbed.protocol import (
    AXIS_SCALE,
    ORDER_TYPES,
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
from testbed.protocol.orders import EndEffectorGoTo
from tests.strategies import orders, roi


def test_type_codes_and_body_sizes_follow_the_reference_table() -> None:
    table = {
        0: (NoOrder, 0),
        1: (Move, 5),
        2: (KeepHeading, 2),
        3: (HoldChannel, 1),
        4: (ImageSettings, 8),
        5: (DisableKeepHeading, 0),
        6: (GoTo, 8),
        7: (OrderIncoming, 0),
        8: (EndEffectorGoTo, 8),  # the extension of the paper's table
    }
    assert {code: (cls, cls.BODY_SIZE) for code, cls in ORDER_TYPES.items()} == table
    assert all(code == cls.CODE for code, cls in ORDER_TYPES.items())


def test_modes() -> None:
    assert [(m.name, m.value) for m in Mode] == [
        ("MANUAL", 0),
        ("STABILIZE", 1),
        ("DEPTH_HOLD", 2),
        ("POS_HOLD", 3),
        ("GUIDED", 4),
    ]


@given(orders)
def test_round_trip(order: Order) -> None:
    body = order.encode()
    assert len(body) == order.BODY_SIZE
    assert type(order).decode(body) == order


# --- layouts by hand --------------------------------------------------------------------------


def test_move_layout() -> None:
    # int8 1, -1, 127, -127; flags 0b1000_0011 = arm, POS_HOLD.
    move = Move(1, -1, 127, -127, arm=True, mode=Mode.POS_HOLD)
    assert move.encode() == bytes([0x01, 0xFF, 0x7F, 0x81, 0x83])
    assert Move(0, 0, 0, 0, disarm=True, mode=Mode.GUIDED).encode()[4] == 0b0100_0100


def test_image_settings_packing_of_the_reference_bit_diagram() -> None:
    # b0 x0[9:2]; b1 x0[1:0]·y0[9:4]; b2 y0[3:0]·x1[9:6]; b3 x1[5:0]·y1[9:8]; b4 y1[7:0]
    assert ImageSettings(1, 1, 1, 1, 0, False, 0).encode()[:5] == bytes(
        [0b00000000, 0b01_000000, 0b0001_0000, 0b000001_00, 0b00000001]
    )
    assert ImageSettings(1023, 0, 1023, 0, 0, False, 0).encode()[:5] == bytes(
        [0xFF, 0b11_000000, 0b0000_1111, 0b111111_00, 0x00]
    )
    # byte 5: shift 5 in bits 7..4, mono in bit 0; budget 2558 = 0x09FE big-endian.
    assert ImageSettings(0, 0, 0, 0, 5, True, 2558).encode()[5:] == bytes([0x51, 0x09, 0xFE])


@given(roi, roi, roi, roi)
def test_image_settings_roi_equals_concatenated_10_bit_fields(
    x0: int, y0: int, x1: int, y1: int
) -> None:
    bits = "".join(format(v, "010b") for v in (x0, y0, x1, y1))
    expected = bytes(int(bits[k : k + 8], 2) for k in range(0, 40, 8))
    assert ImageSettings(x0, y0, x1, y1, 0, False, 0).encode()[:5] == expected


def test_keep_heading_hold_channel_and_goto_are_big_endian() -> None:
    assert KeepHeading(359).encode() == bytes([0x01, 0x67])
    assert HoldChannel(30).encode() == bytes([30])
    # The original code sent go-to in host order (little-endian); we send network order.
    goto = GoTo(1, -2, 300, -90)
    assert goto.encode() == bytes([0x00, 0x01, 0xFF, 0xFE, 0x01, 0x2C, 0xFF, 0xA6])
    assert goto.encode() != struct.pack("<hhhh", 1, -2, 300, -90)
    for empty in (NoOrder(), DisableKeepHeading(), OrderIncoming()):
        assert empty.encode() == b""


# --- stick axes and headings ---------------------------------------------------------------


@given(st.lists(st.floats(-1.0, 1.0), min_size=4, max_size=4))
def test_from_axes_quantises_to_the_nearest_code(values: list[float]) -> None:
    move = Move.from_axes(*values)
    for value, code, back in zip(
        values, (move.x, move.y, move.z, move.yaw), move.axes, strict=True
    ):
        assert abs(code - value * 127) <= 0.5
        assert back == code / 127
        assert abs(back - value) <= 0.5 / 127 + 1e-12
    assert Move.from_axes(*move.axes) == move


def test_from_axes_saturates_and_rejects_nan() -> None:
    move = Move.from_axes(2.0, -7.5, 1.0, -1.0, arm=True, mode=Mode.STABILIZE)
    assert (move.x, move.y, move.z, move.yaw) == (127, -127, 127, -127)
    assert move.axes == (1.0, -1.0, 1.0, -1.0)
    assert move.arm and move.mode is Mode.STABILIZE
    assert AXIS_SCALE == 127
    for bad in (math.nan, math.inf):
        with pytest.raises(ValueError, match="finite"):
            Move.from_axes(bad, 0, 0, 0)


def test_keep_heading_from_degrees_reduces_modulo_360() -> None:
    assert KeepHeading.from_degrees(-10.2) == KeepHeading(350)
    assert KeepHeading.from_degrees(359.6) == KeepHeading(0)
    assert KeepHeading.from_degrees(720 + 45.4) == KeepHeading(45)
    with pytest.raises(ValueError, match="finite"):
        KeepHeading.from_degrees(math.nan)


def test_mode_given_as_int_is_stored_as_mode() -> None:
    move = Move(0, 0, 0, 0, mode=2)  # type: ignore[arg-type]  # an int from untyped callers
    assert move.mode is Mode.DEPTH_HOLD


# --- local misuse and malformed bodies -----------------------------------------------------


@pytest.mark.parametrize(
    "build",
    [
        lambda: Move(-128, 0, 0, 0),
        lambda: Move(0, 128, 0, 0),
        lambda: Move(0, 0, 0, 0.5),
        lambda: Move(0, 0, 0, 0, mode=5),
        lambda: KeepHeading(360),
        lambda: KeepHeading(-1),
        lambda: HoldChannel(256),
        lambda: ImageSettings(1024, 0, 0, 0, 0, False, 0),
        lambda: ImageSettings(0, 0, 0, 0, 16, False, 0),
        lambda: ImageSettings(0, 0, 0, 0, 0, False, 65536),
        lambda: GoTo(32768, 0, 0, 0),
        lambda: GoTo(0, 0, 0, -32769),
    ],
)
def test_out_of_range_values_raise(build: Callable[[], object]) -> None:
    with pytest.raises(ValueError):
        build()


@pytest.mark.parametrize(
    ("cls", "body", "match"),
    [
        (Move, bytes([0x80, 0, 0, 0, 0]), "-127..127"),  # int8 -128 is not a stick code
        (Move, bytes([0, 0, 0, 0, 0x08]), "reserved"),
        (Move, bytes([0, 0, 0, 0, 0x05]), "mode"),
        (Move, bytes(4), "5 B"),
        (KeepHeading, bytes([0x01, 0x68]), "0..359"),  # 360
        (HoldChannel, b"", "1 B"),
        (ImageSettings, bytes([0, 0, 0, 0, 0, 0x02, 0, 0]), "reserved"),
        (GoTo, bytes(9), "8 B"),
        (NoOrder, b"\x00", "0 B"),
        (OrderIncoming, b"\x00", "0 B"),
        (DisableKeepHeading, b"\x00", "0 B"),
    ],
)
def test_malformed_bodies_raise_value_error(cls: type[Order], body: bytes, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        cls.decode(body)


@given(st.sampled_from(sorted(ORDER_TYPES)), st.binary(max_size=10))
def test_decode_accepts_only_canonical_bodies(code: int, body: bytes) -> None:
    cls = ORDER_TYPES[code]
    try:
        order = cls.decode(body)
    except ValueError:
        return
    assert order.encode() == body
