"""Payload layouts of the teleoperation protocol (REFERENCE §1.3–1.5), sans-IO.

* :class:`OperatorMessage`, operator → vehicle: a 2-byte header (image acknowledgement and
  order sequencing) followed by one order body (:mod:`testbed.protocol.orders`).
* :class:`VehicleMessage`, vehicle → operator: a 1-byte header, the 12-byte
  :class:`VehicleState`, a chunk-info byte and an image chunk of 0..150 bytes.

These are frame *payloads*; :mod:`testbed.protocol.framing` wraps them in frames. With a 40-B
chunk a reply payload is 54 B and its 3-preamble frame 60 B; a move order is 7 B (13-B frame),
a go-to (``GoTo``) or an end-effector go-to (``EndEffectorGoTo``, code 8, the extension of the
paper's order table) 10 B (16-B frame). Order codes 9..15 name no order: such a payload is a
:class:`MalformedPayload`.

**Byte order.** Every multi-byte field is big-endian. The original telerobotics code
(``src/nodes/ROV.cpp``, ``Operator.cpp``) wrote the state's x, y, z and the go-to fields in host
byte order; this implementation does not depend on the host.

**Errors.** Constructors and the ``decode`` classmethods raise :class:`ValueError` for values that
do not fit the wire format (local misuse). :func:`decode_operator_message` and
:func:`decode_vehicle_message` never raise on any ``bytes``: garbled remote data comes back as a
:class:`MalformedPayload` value. Encodings are canonical (reserved bits zero, values in range), so
``encode(decode(b)) == b`` for every payload ``b`` that decodes.

Standard library only; no I/O, no clock.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from typing import Self

from .orders import (
    AXIS_SCALE,
    ORDER_TYPES,
    DisableKeepHeading,
    EndEffectorGoTo,
    GoTo,
    HoldChannel,
    ImageSettings,
    KeepHeading,
    Mode,
    Move,
    NoOrder,
    Order,
    OrderIncoming,
    check_int,
    coerce_mode,
)

__all__ = [
    "AXIS_SCALE",
    "DEFAULT_CHUNK_SIZE",
    "MAX_CHUNK_INDEX",
    "MAX_CHUNK_SIZE",
    "OPERATOR_HEADER_SIZE",
    "ORDER_TYPES",
    "STATE_SIZE",
    "VEHICLE_HEADER_SIZE",
    "DisableKeepHeading",
    "EndEffectorGoTo",
    "GoTo",
    "HoldChannel",
    "ImageSettings",
    "KeepHeading",
    "MalformedPayload",
    "Mode",
    "Move",
    "NoOrder",
    "OperatorMessage",
    "Order",
    "OrderIncoming",
    "VehicleMessage",
    "VehicleState",
    "decode_operator_message",
    "decode_vehicle_message",
    "order_type_of",
]

OPERATOR_HEADER_SIZE = 2
"""Operator message header [B]; the order body follows."""

STATE_SIZE = 12
"""Encoded :class:`VehicleState` [B]; also written in the reply header's bits 4..0."""

VEHICLE_HEADER_SIZE = 1 + STATE_SIZE + 1
"""Reply bytes before the image chunk: header, state, chunk info [B]."""

DEFAULT_CHUNK_SIZE = 40
"""Image chunk per reply in the telerobotics code [B]."""

MAX_CHUNK_SIZE = 150
"""Largest image chunk per reply [B]."""

MAX_CHUNK_INDEX = 63
"""Chunk indices are 6 bits: an image is at most 64 chunks."""

_CM_PER_M = 100
_POSITION_CODES = (-32768, 32767)
_ANGLE_CODES_PER_DEG = (
    20  # 0.05° per LSB: inferred from the 13-bit field (REFERENCE §1.4: unverified)
)
_ANGLE_CODE_MAX = 180 * _ANGLE_CODES_PER_DEG  # ±180° = ±3600, inside the 13-bit ±4096
_ORDER_CLASSES = tuple(ORDER_TYPES.values())


@dataclass(frozen=True, slots=True)
class MalformedPayload:
    """A payload that passed the frame CRC but does not parse (remote data, so a value).

    Attributes:
        reason: one line saying what was wrong.
    """

    reason: str


def order_type_of(payload: bytes) -> type[Order] | None:
    """The order class an operator payload's header names (low nibble of byte 1), without
    decoding the body; None if the payload is shorter than the header or names no order."""
    if len(payload) < OPERATOR_HEADER_SIZE:
        return None
    return ORDER_TYPES.get(payload[1] & 0x0F)


@dataclass(frozen=True, slots=True)
class OperatorMessage:
    """Operator → vehicle payload: 2-byte header, then the order body.

    Byte 0: bit 7 image sequence bit expected, bit 6 cancel image, bits 5..0 index of the first
    missing chunk. Byte 1: bit 7 order sequence bit (alternates per new order), bit 6 cancel
    last order, bits 5..4 reserved (0), bits 3..0 order type (:attr:`Order.CODE`).

    Attributes:
        image_seq_bit: sequence bit of the image the operator is assembling.
        cancel_image: ask the vehicle to abandon the current image.
        first_missing_chunk: the chunk the vehicle should send next, 0..63.
        order_seq_bit: alternating bit; a change marks a new order.
        cancel_order: cancel the last order.
        order: the order (its type code and body).
    """

    image_seq_bit: bool
    cancel_image: bool
    first_missing_chunk: int
    order_seq_bit: bool
    cancel_order: bool
    order: Order

    def __post_init__(self) -> None:
        check_int("first_missing_chunk", self.first_missing_chunk, 0, MAX_CHUNK_INDEX)
        if not isinstance(self.order, _ORDER_CLASSES):
            raise ValueError(f"order must be an order message, got {self.order!r}")

    def encode(self) -> bytes:
        """The payload: header then order body (2 + ``order.BODY_SIZE`` bytes)."""
        byte0 = (
            (0x80 if self.image_seq_bit else 0)
            | (0x40 if self.cancel_image else 0)
            | self.first_missing_chunk
        )
        byte1 = (0x80 if self.order_seq_bit else 0) | (0x40 if self.cancel_order else 0)
        return bytes((byte0, byte1 | self.order.CODE)) + self.order.encode()

    @classmethod
    def decode(cls, data: bytes) -> Self:
        """Parse a payload.

        Raises:
            ValueError: too short, reserved bits set, unknown order type or a bad order body.
        """
        if len(data) < OPERATOR_HEADER_SIZE:
            raise ValueError(f"operator message needs {OPERATOR_HEADER_SIZE} B, got {len(data)}")
        byte0, byte1 = data[0], data[1]
        if byte1 & 0x30:
            raise ValueError(f"operator header byte 1 reserved bits 5..4 set: {byte1:#04x}")
        order_type = order_type_of(data)
        if order_type is None:
            raise ValueError(f"unknown order type {byte1 & 0x0F}")
        return cls(
            image_seq_bit=bool(byte0 & 0x80),
            cancel_image=bool(byte0 & 0x40),
            first_missing_chunk=byte0 & 0x3F,
            order_seq_bit=bool(byte1 & 0x80),
            cancel_order=bool(byte1 & 0x40),
            order=order_type.decode(bytes(data[OPERATOR_HEADER_SIZE:])),
        )


@dataclass(frozen=True, slots=True)
class VehicleState:
    """The vehicle's status and pose as sent in every reply (12 B).

    Layout: byte 0 flags (bit 7 ready, 6 order-sequence ack, 5 last order cancelled, 4 keeping
    heading, 3 armed, 2..0 mode); bytes 1–6 x, y, z int16 big-endian [cm]; bytes 7–11 a 40-bit
    big-endian field, MSB first: heading 9 bits unsigned · roll 13 bits two's complement ·
    pitch 13 bits two's complement · 5 spare bits (0).

    Quantisation on encode (round half to even throughout):

    * x, y, z: code = round(100 · value_m), 1 cm step; codes saturate at −32768..32767
      (±327.67 m). Values beyond never wrap.
    * heading: code = round(heading_deg) mod 360, 1° step, 0..359. Heading is a compass angle,
      so −10° is sent as 350° and 359.6° as 0°: reducing an angle modulo 360 is not an overflow.
    * roll, pitch: code = round(20 · value_deg), 0.05° step (13 bits would reach ±204.75°);
      codes saturate at ±3600 (±180°). Values beyond never wrap.

    A decoder rejects heading codes above 359, roll/pitch codes beyond ±3600, nonzero spare bits
    and mode codes 5..7. :meth:`quantized` gives the state exactly as the receiver decodes it.

    Frames: x, y, z are the vehicle origin in the world NED frame [m] (+z down = depth);
    heading is yaw clockwise from north; roll and pitch are the ZYX Euler angles of body FRD
    relative to NED [deg].

    Attributes:
        ready: the vehicle is up and accepting orders.
        order_ack_bit: the order sequence bit of the last order applied.
        last_order_cancelled: the last order was cancelled.
        keeping_heading: heading hold is active.
        armed: motors armed.
        mode: current flight mode.
        x_m: north [m].
        y_m: east [m].
        z_m: down [m].
        heading_deg: heading [deg], clockwise from north.
        roll_deg: roll [deg].
        pitch_deg: pitch [deg].

    Raises:
        ValueError: a non-finite float or an unknown mode (local misuse).
    """

    ready: bool
    order_ack_bit: bool
    last_order_cancelled: bool
    keeping_heading: bool
    armed: bool
    mode: Mode
    x_m: float
    y_m: float
    z_m: float
    heading_deg: float
    roll_deg: float
    pitch_deg: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "mode", coerce_mode(self.mode))
        for name in ("x_m", "y_m", "z_m", "heading_deg", "roll_deg", "pitch_deg"):
            value = getattr(self, name)
            if not isinstance(value, int | float) or not math.isfinite(value):
                raise ValueError(f"{name} must be a finite number, got {value!r}")

    def _codes(self) -> tuple[int, int, int, int, int, int]:
        """Integer wire codes (x, y, z [cm], heading [deg], roll, pitch [0.05°])."""
        lo, hi = _POSITION_CODES
        cm = [min(hi, max(lo, round(v * _CM_PER_M))) for v in (self.x_m, self.y_m, self.z_m)]
        angles = [
            min(_ANGLE_CODE_MAX, max(-_ANGLE_CODE_MAX, round(v * _ANGLE_CODES_PER_DEG)))
            for v in (self.roll_deg, self.pitch_deg)
        ]
        return cm[0], cm[1], cm[2], round(self.heading_deg) % 360, angles[0], angles[1]

    def quantized(self) -> Self:
        """This state as the receiver reads it: ``decode(encode(s)) == s.quantized()``."""
        flags = (self.ready, self.order_ack_bit, self.last_order_cancelled, self.keeping_heading)
        return type(self)(*flags, self.armed, self.mode, *_values(*self._codes()))

    def encode(self) -> bytes:
        """The 12-byte state."""
        x, y, z, heading, roll, pitch = self._codes()
        flags = (
            (0x80 if self.ready else 0)
            | (0x40 if self.order_ack_bit else 0)
            | (0x20 if self.last_order_cancelled else 0)
            | (0x10 if self.keeping_heading else 0)
            | (0x08 if self.armed else 0)
            | int(self.mode)
        )
        attitude = (heading << 31) | ((roll & 0x1FFF) << 18) | ((pitch & 0x1FFF) << 5)
        return struct.pack(">Bhhh", flags, x, y, z) + attitude.to_bytes(5, "big")

    @classmethod
    def decode(cls, data: bytes) -> Self:
        """Parse 12 bytes.

        Raises:
            ValueError: wrong size, unknown mode, heading above 359, roll or pitch beyond
                ±180°, or spare bits set.
        """
        if len(data) != STATE_SIZE:
            raise ValueError(f"vehicle state must be {STATE_SIZE} B, got {len(data)}")
        flags, x, y, z = struct.unpack(">Bhhh", data[:7])
        attitude = int.from_bytes(data[7:12], "big")
        heading = attitude >> 31
        roll = _signed13((attitude >> 18) & 0x1FFF)
        pitch = _signed13((attitude >> 5) & 0x1FFF)
        if attitude & 0x1F:
            raise ValueError(f"vehicle state spare bits set: {attitude & 0x1F:#04x}")
        if heading > 359:
            raise ValueError(f"vehicle state heading code {heading} > 359")
        for name, code in (("roll", roll), ("pitch", pitch)):
            if abs(code) > _ANGLE_CODE_MAX:
                raise ValueError(f"vehicle state {name} code {code} beyond ±{_ANGLE_CODE_MAX}")
        return cls(
            bool(flags & 0x80),
            bool(flags & 0x40),
            bool(flags & 0x20),
            bool(flags & 0x10),
            bool(flags & 0x08),
            coerce_mode(flags & 0x07),
            *_values(x, y, z, heading, roll, pitch),
        )


def _values(
    x: int, y: int, z: int, heading: int, roll: int, pitch: int
) -> tuple[float, float, float, float, float, float]:
    """Wire codes → (x_m, y_m, z_m, heading_deg, roll_deg, pitch_deg), the one conversion."""
    return (
        x / _CM_PER_M,
        y / _CM_PER_M,
        z / _CM_PER_M,
        float(heading),
        roll / _ANGLE_CODES_PER_DEG,
        pitch / _ANGLE_CODES_PER_DEG,
    )


def _signed13(code: int) -> int:
    return code - 0x2000 if code & 0x1000 else code


@dataclass(frozen=True, slots=True)
class VehicleMessage:
    """Vehicle → operator payload: header, state, chunk info, image chunk (14 + chunk bytes).

    Byte 0: bit 7 first chunk of an image, bit 6 last chunk, bit 5 reserved (0), bits 4..0 state
    length (always 12). Bytes 1–12: :class:`VehicleState`. Byte 13: bit 7 image sequence bit,
    bit 6 image cancelled, bits 5..0 chunk index. Bytes 14…: the chunk, 0..150 B (40 B in the
    original code; 0 B when there is no image to send).

    Attributes:
        first_chunk: this chunk starts an image.
        last_chunk: this chunk ends an image.
        state: the vehicle state.
        image_seq_bit: sequence bit of the image the chunk belongs to.
        cancel_image: the vehicle abandoned the image.
        chunk_index: index of the chunk in its image, 0..63.
        chunk: chunk bytes, at most 150.

    Raises:
        ValueError: chunk index out of range or chunk too long (local misuse).
    """

    first_chunk: bool
    last_chunk: bool
    state: VehicleState
    image_seq_bit: bool
    cancel_image: bool
    chunk_index: int
    chunk: bytes

    def __post_init__(self) -> None:
        check_int("chunk_index", self.chunk_index, 0, MAX_CHUNK_INDEX)
        if not isinstance(self.chunk, bytes | bytearray | memoryview):
            raise ValueError(f"chunk must be bytes, got {type(self.chunk).__name__}")
        object.__setattr__(self, "chunk", bytes(self.chunk))
        if len(self.chunk) > MAX_CHUNK_SIZE:
            raise ValueError(f"chunk is {len(self.chunk)} B, at most {MAX_CHUNK_SIZE} B")

    def encode(self) -> bytes:
        """The payload (14 + ``len(chunk)`` bytes)."""
        byte0 = (0x80 if self.first_chunk else 0) | (0x40 if self.last_chunk else 0) | STATE_SIZE
        byte13 = (
            (0x80 if self.image_seq_bit else 0)
            | (0x40 if self.cancel_image else 0)
            | self.chunk_index
        )
        return bytes((byte0,)) + self.state.encode() + bytes((byte13,)) + self.chunk

    @classmethod
    def decode(cls, data: bytes) -> Self:
        """Parse a payload.

        Raises:
            ValueError: wrong size, reserved bit set, state length other than 12 or a bad state.
        """
        size = len(data)
        if not VEHICLE_HEADER_SIZE <= size <= VEHICLE_HEADER_SIZE + MAX_CHUNK_SIZE:
            raise ValueError(
                f"vehicle message must be {VEHICLE_HEADER_SIZE}.."
                f"{VEHICLE_HEADER_SIZE + MAX_CHUNK_SIZE} B, got {size}"
            )
        byte0 = data[0]
        if byte0 & 0x20:
            raise ValueError(f"vehicle header reserved bit 5 set: {byte0:#04x}")
        if byte0 & 0x1F != STATE_SIZE:
            raise ValueError(f"vehicle header state length {byte0 & 0x1F}, expected {STATE_SIZE}")
        byte13 = data[VEHICLE_HEADER_SIZE - 1]
        return cls(
            first_chunk=bool(byte0 & 0x80),
            last_chunk=bool(byte0 & 0x40),
            state=VehicleState.decode(bytes(data[1 : 1 + STATE_SIZE])),
            image_seq_bit=bool(byte13 & 0x80),
            cancel_image=bool(byte13 & 0x40),
            chunk_index=byte13 & 0x3F,
            chunk=bytes(data[VEHICLE_HEADER_SIZE:]),
        )


def decode_operator_message(payload: bytes) -> OperatorMessage | MalformedPayload:
    """Parse a received operator payload; never raises on any bytes.

    Returns:
        The message, or :class:`MalformedPayload` saying why it does not parse.
    """
    try:
        return OperatorMessage.decode(payload)
    except ValueError as err:
        return MalformedPayload(str(err))


def decode_vehicle_message(payload: bytes) -> VehicleMessage | MalformedPayload:
    """Parse a received vehicle payload; never raises on any bytes.

    Returns:
        The message, or :class:`MalformedPayload` saying why it does not parse.
    """
    try:
        return VehicleMessage.decode(payload)
    except ValueError as err:
        return MalformedPayload(str(err))
