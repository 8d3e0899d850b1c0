"""Operator and vehicle payloads: REFERENCE §1.3–1.6 layouts and sizes, quantisation, decoding."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from testbed.protocol import (
    DEFAULT_CHUNK_SIZE,
    MAX_CHUNK_SIZE,
    STATE_SIZE,
    DisableKeepHeading,
    GoTo,
    HoldChannel,
    ImageSettings,
    KeepHeading,
    MalformedPayload,
    Mode,
    Move,
    NoOrder,
    OperatorMessage,
    OrderIncoming,
    VehicleMessage,
    VehicleState,
    decode_operator_message,
    decode_vehicle_message,
    encode_frame,
    order_type_of,
)
from tests.strategies import orders

chunk_index = st.integers(0, 63)
operator_messages = st.builds(
    OperatorMessage, st.booleans(), st.booleans(), chunk_index, st.booleans(), st.booleans(), orders
)
finite = st.floats(-1e6, 1e6, allow_nan=False)
states = st.builds(
    VehicleState,
    *[st.booleans()] * 5,
    st.sampled_from(Mode),
    finite,
    finite,
    finite,
    finite,
    finite,
    finite,
)
vehicle_messages = st.builds(
    VehicleMessage,
    st.booleans(),
    st.booleans(),
    states,
    st.booleans(),
    st.booleans(),
    chunk_index,
    st.binary(max_size=MAX_CHUNK_SIZE),
)


def state(**changes: object) -> VehicleState:
    fields: dict[str, object] = dict(
        ready=False,
        order_ack_bit=False,
        last_order_cancelled=False,
        keeping_heading=False,
        armed=False,
        mode=Mode.MANUAL,
        x_m=0.0,
        y_m=0.0,
        z_m=0.0,
        heading_deg=0.0,
        roll_deg=0.0,
        pitch_deg=0.0,
    )
    fields.update(changes)
    return VehicleState(**fields)  # type: ignore[arg-type]  # test helper, fields checked above


def reply(chunk: bytes = b"") -> VehicleMessage:
    return VehicleMessage(False, False, state(), False, False, 0, chunk)


# --- operator messages -------------------------------------------------------------------------


@given(operator_messages)
def test_operator_message_round_trip(message: OperatorMessage) -> None:
    payload = message.encode()
    assert len(payload) == 2 + message.order.BODY_SIZE
    assert OperatorMessage.decode(payload) == message
    assert decode_operator_message(payload) == message


def test_operator_header_layout() -> None:
    # byte 0: seq 1, cancel 0, chunk 5 → 0b1000_0101; byte 1: seq 1, cancel 1, type 3 → 0b1100_0011
    message = OperatorMessage(True, False, 5, True, True, HoldChannel(30))
    assert message.encode() == bytes([0b1000_0101, 0b1100_0011, 30])
    message = OperatorMessage(False, True, 63, False, False, NoOrder())
    assert message.encode() == bytes([0b0111_1111, 0x00])


# --- vehicle state ------------------------------------------------------------------------------


def test_state_layout_by_bit_string() -> None:
    s = state(
        ready=True,
        armed=True,
        mode=Mode.GUIDED,
        x_m=1.5,
        y_m=-0.01,
        z_m=2.0,
        heading_deg=359,
        roll_deg=-180,
        pitch_deg=90,
    )
    flags = 0b1000_1100  # ready, armed, mode 4
    positions = bytes([0x00, 0x96, 0xFF, 0xFF, 0x00, 0xC8])  # 150, -1, 200 cm big-endian
    # heading 359 (9 bits) · roll -3600 (13-bit two's complement) · pitch 1800 · 5 spare zeros
    bits = format(359, "09b") + format(8192 - 3600, "013b") + format(1800, "013b") + "00000"
    attitude = bytes(int(bits[k : k + 8], 2) for k in range(0, 40, 8))
    assert s.encode() == bytes([flags]) + positions + attitude
    assert len(s.encode()) == STATE_SIZE


@given(states)
def test_state_round_trip_is_quantisation(s: VehicleState) -> None:
    q = s.quantized()
    assert VehicleState.decode(s.encode()) == q
    assert q.quantized() == q
    assert q.encode() == s.encode()


@given(st.floats(-327.67, 327.67), st.floats(-360, 720), st.floats(-180, 180))
def test_quantisation_errors_within_range(position: float, heading: float, angle: float) -> None:
    """Inside ±327.67 m (the range both x and its mirror y can carry) error ≤ half a step."""
    q = state(x_m=position, y_m=-position, heading_deg=heading, roll_deg=angle).quantized()
    assert abs(q.x_m - position) <= 0.005 + 1e-9
    assert abs(q.y_m + position) <= 0.005 + 1e-9
    assert 0 <= q.heading_deg <= 359 and q.heading_deg == int(q.heading_deg)
    assert abs((q.heading_deg - heading + 180) % 360 - 180) <= 0.5 + 1e-9  # circular error
    assert abs(q.roll_deg - angle) <= 0.025 + 1e-9


@given(st.floats(327.68, 1e9), st.floats(180.0001, 1e9))
def test_positions_and_angles_saturate_never_wrap(position: float, angle: float) -> None:
    q = state(x_m=position, z_m=-position, roll_deg=angle, pitch_deg=-angle).quantized()
    assert (q.x_m, q.z_m) == (327.67, -327.68)
    assert (q.roll_deg, q.pitch_deg) == (180.0, -180.0)


def test_state_rejects_non_finite_and_unknown_mode() -> None:
    for bad in (math.nan, math.inf, -math.inf):
        with pytest.raises(ValueError, match="finite"):
            state(pitch_deg=bad)
    with pytest.raises(ValueError, match="mode"):
        state(mode=5)


@pytest.mark.parametrize(
    ("mutate", "match"),
    [
        (lambda b: b[:11], "12 B"),
        (lambda b: bytes([b[0] | 0x07]) + b[1:], "mode"),
        (lambda b: b[:11] + bytes([b[11] | 0x01]), "spare"),
        (lambda b: b[:7] + bytes([0xB4, 0x00]) + b[9:], "heading code 360"),  # 360 << 31
        (lambda b: b[:7] + (3601 << 18).to_bytes(5, "big"), "roll code 3601"),
        (lambda b: b[:7] + ((8192 - 3601) << 5).to_bytes(5, "big"), "pitch code -3601"),
    ],
)
def test_state_decode_rejects_non_canonical(mutate: object, match: str) -> None:
    good = state().encode()
    with pytest.raises(ValueError, match=match):
        VehicleState.decode(mutate(good))  # type: ignore[operator]  # parametrized lambda


# --- vehicle messages ---------------------------------------------------------------------------


@given(vehicle_messages)
def test_vehicle_message_round_trip(message: VehicleMessage) -> None:
    payload = message.encode()
    assert len(payload) == 14 + len(message.chunk)
    expected = VehicleMessage(
        message.first_chunk,
        message.last_chunk,
        message.state.quantized(),
        message.image_seq_bit,
        message.cancel_image,
        message.chunk_index,
        message.chunk,
    )
    assert VehicleMessage.decode(payload) == expected
    assert decode_vehicle_message(payload) == expected


def test_vehicle_header_and_chunk_info_layout() -> None:
    message = VehicleMessage(True, False, state(), True, True, 9, b"\xab")
    payload = message.encode()
    assert payload[0] == 0b1000_1100  # first chunk, state length 12
    assert payload[13] == 0b1100_1001  # seq 1, cancel 1, index 9
    assert payload[14:] == b"\xab"
    assert VehicleMessage(False, True, state(), False, False, 0, b"").encode()[0] == 0b0100_1100


def test_vehicle_message_local_misuse() -> None:
    with pytest.raises(ValueError, match="150"):
        reply(bytes(151))
    with pytest.raises(ValueError, match="chunk_index"):
        VehicleMessage(False, False, state(), False, False, 64, b"")
    assert reply(bytearray(b"ab")).chunk == b"ab"  # type: ignore[arg-type]  # buffer accepted


# --- frame sizes (REFERENCE §1.6) ----------------------------------------------------------------


@pytest.mark.parametrize(
    ("payload", "wa_frame", "variable_length"),
    [
        (OperatorMessage(False, False, 0, True, False, Move(0, 0, 0, 0)).encode(), 13, 11),
        (
            OperatorMessage(
                False, False, 0, True, False, ImageSettings(0, 0, 1, 1, 2, True, 9)
            ).encode(),
            16,
            14,
        ),
        (OperatorMessage(False, False, 0, False, False, GoTo(1, 2, 3, 4)).encode(), 16, 14),
        (reply(bytes(DEFAULT_CHUNK_SIZE)).encode(), 60, 58),
        (reply().encode(), 20, 18),
    ],
)
def test_frame_sizes_match_the_reference_table(
    payload: bytes, wa_frame: int, variable_length: int
) -> None:
    assert len(encode_frame(payload, 3)) == wa_frame
    assert len(encode_frame(payload, 1)) == variable_length


def test_reply_with_default_chunk_is_54_bytes() -> None:
    assert DEFAULT_CHUNK_SIZE == 40
    assert len(reply(bytes(40)).encode()) == 54


# --- remote garbage is a value -----------------------------------------------------------------


@pytest.mark.parametrize(
    ("payload", "match"),
    [
        (b"", "needs 2 B"),
        (b"\x00", "needs 2 B"),
        (bytes([0, 0x09]), "unknown order type 9"),
        (bytes([0, 0x0F]), "unknown order type 15"),
        (bytes([0, 0x10]), "reserved"),
        (bytes([0, 0x01, 0, 0, 0]), "5 B"),
    ],
)
def test_malformed_operator_payloads(payload: bytes, match: str) -> None:
    result = decode_operator_message(payload)
    assert isinstance(result, MalformedPayload)
    assert match in result.reason


@pytest.mark.parametrize(
    ("mutate", "match"),
    [
        (lambda b: b[:13], "14..164 B"),
        (lambda b: b + bytes(151), "14..164 B"),
        (lambda b: bytes([b[0] | 0x20]) + b[1:], "reserved"),
        (lambda b: bytes([0x0B]) + b[1:], "state length 11"),
        (lambda b: b[:12] + bytes([b[12] | 1]) + b[13:], "spare"),
    ],
)
def test_malformed_vehicle_payloads(mutate: object, match: str) -> None:
    result = decode_vehicle_message(mutate(reply(b"xyz").encode()))  # type: ignore[operator]  # lambda
    assert isinstance(result, MalformedPayload)
    assert match in result.reason


@given(st.binary(max_size=200))
def test_decoders_never_raise_and_accept_only_canonical_payloads(payload: bytes) -> None:
    for decode in (decode_operator_message, decode_vehicle_message):
        result = decode(payload)
        assert isinstance(result, MalformedPayload) or result.encode() == payload


def test_fuzz_decoders_with_mutated_valid_payloads() -> None:
    """50,000 seeded bit-flipped, truncated and extended valid payloads of both kinds."""
    rng = np.random.default_rng(1234)
    valid = [
        OperatorMessage(True, False, 3, False, True, Move(5, -5, 100, -100, True)).encode(),
        OperatorMessage(
            False, True, 63, True, False, ImageSettings(1, 2, 3, 4, 5, True, 6)
        ).encode(),
        OperatorMessage(True, True, 0, True, True, GoTo(-1, 2, -3, 359)).encode(),
        VehicleMessage(
            True, True, state(x_m=3.2, roll_deg=-7.5), True, False, 17, bytes(40)
        ).encode(),
        reply().encode(),
    ]
    rows = rng.integers(0, 1 << 30, size=(50_000, 4)).tolist()
    decoded = 0
    for kind, flip, cut, extra in rows:
        payload = bytearray(valid[kind % len(valid)])
        payload[flip % len(payload)] ^= 1 << (flip % 8)
        if cut % 4 == 0:
            del payload[cut % (len(payload) + 1) :]
        if extra % 8 == 0:
            payload += bytes([extra % 256])
        data = bytes(payload)
        for decode in (decode_operator_message, decode_vehicle_message):
            result = decode(data)
            if not isinstance(result, MalformedPayload):
                decoded += 1
                assert result.encode() == data
    assert decoded > 10_000  # many single-bit flips still parse, and re-encode identically


def test_order_type_of_reads_the_header_nibble_without_the_body() -> None:
    by_hand = {  # REFERENCE §1.3: the order type codes of the telerobotics protocol
        0: NoOrder,
        1: Move,
        2: KeepHeading,
        3: HoldChannel,
        4: ImageSettings,
        5: DisableKeepHeading,
        6: GoTo,
        7: OrderIncoming,
    }
    for code, cls in by_hand.items():
        assert order_type_of(bytes((0x80, 0xC0 | code))) is cls  # flags set, body absent
    assert order_type_of(bytes((0, 9))) is None  # codes 9..15 name no order (8: the extension)
    assert order_type_of(b"\x01") is None and order_type_of(b"") is None
