"""Operator orders: the bodies that follow the 2-byte operator header (REFERENCE §1.3).

Each order is a frozen slotted dataclass with a type code (:attr:`CODE`, the low nibble of
header byte 1), a fixed body size (:attr:`BODY_SIZE`), ``encode() -> bytes`` (the body only) and
``decode(body) -> Self``. Constructors and ``decode`` raise :class:`ValueError` on values that do
not fit the wire format; :func:`testbed.protocol.messages.decode_operator_message` turns that
into a :class:`~testbed.protocol.messages.MalformedPayload` value for remote data.

The layouts follow the telerobotics code (``src/nodes/Operator.cpp``, ``src/msgs``), with one
deliberate change: **every multi-byte field is big-endian**. The original code wrote the go-to
coordinates and heading in host byte order (little-endian on the x86/ARM machines it ran on);
a simulator must not depend on the host, so this implementation uses network order throughout.

Encodings are canonical: reserved bits are written as zero and a body with a reserved bit set or
a value outside its documented range is rejected, so ``decode`` is the exact inverse of
``encode`` on every body it accepts.

Order table (code, body size): NoOrder (0, 0) · Move (1, 5) · KeepHeading (2, 2) ·
HoldChannel (3, 1) · ImageSettings (4, 8) · DisableKeepHeading (5, 0) · GoTo (6, 8) ·
OrderIncoming (7, 0) — the paper's layout, codes 0..7 — and, as an **extension** of it (not in
the telerobotics code): EndEffectorGoTo (8, 8), the manipulator arm's tool point to a position.
The type code is a 4-bit field, so codes 9..15 remain unused; a payload naming one is
malformed.

Standard library only; no I/O.
"""

from __future__ import annotations

import enum
import math
import struct
from dataclasses import dataclass
from typing import ClassVar, Self

__all__ = [
    "AXIS_SCALE",
    "EE_NO_YAW",
    "ORDER_TYPES",
    "DisableKeepHeading",
    "EndEffectorGoTo",
    "GoTo",
    "HoldChannel",
    "ImageSettings",
    "KeepHeading",
    "Mode",
    "Move",
    "NoOrder",
    "Order",
    "OrderIncoming",
]

AXIS_SCALE = 127
"""Stick-axis code for full deflection: axis value = code / 127, code in −127..127."""

_ROI_MAX = 1023
_INT16 = (-32768, 32767)

EE_NO_YAW = 0xFFFF
"""The :class:`EndEffectorGoTo` yaw field's sentinel: no tool yaw target."""
_EE_YAW_CODES = 36000  # 0.01° steps: 0..35999 = 0..359.99°


class Mode(enum.IntEnum):
    """ArduSub-style flight mode as carried in 3 bits of the move flags and the state flags."""

    MANUAL = 0
    STABILIZE = 1
    DEPTH_HOLD = 2
    POS_HOLD = 3
    GUIDED = 4


def check_int(name: str, value: int, low: int, high: int) -> None:
    """Raise ValueError unless ``value`` is an int in ``low..high`` (inclusive).

    Args:
        name: field name for the message.
        value: the value to check.
        low: smallest allowed value.
        high: largest allowed value.

    Raises:
        ValueError: not an int, or out of range.
    """
    if not isinstance(value, int):
        raise ValueError(f"{name} must be an int, got {type(value).__name__} {value!r}")
    if not low <= value <= high:
        raise ValueError(f"{name} must be in {low}..{high}, got {value}")


def coerce_mode(value: int) -> Mode:
    """``Mode(value)`` with a ValueError naming the field for unknown codes."""
    try:
        return Mode(value)
    except ValueError:
        raise ValueError(f"mode must be one of {[m.value for m in Mode]}, got {value!r}") from None


def _check_body(name: str, size: int, body: bytes) -> None:
    if len(body) != size:
        raise ValueError(f"{name} body must be {size} B, got {len(body)} B")


class _EmptyBody:
    """Shared codec of the orders that carry no body (their type code says everything)."""

    __slots__ = ()

    BODY_SIZE: ClassVar[int] = 0

    def encode(self) -> bytes:
        """The (empty) body."""
        return b""

    @classmethod
    def decode(cls, data: bytes) -> Self:
        """Parse an empty body. Raises ValueError if ``data`` is not empty."""
        _check_body(cls.__name__, cls.BODY_SIZE, data)
        return cls()


@dataclass(frozen=True, slots=True)
class NoOrder(_EmptyBody):
    """No order: the operator only polls the vehicle (and acknowledges image chunks)."""

    CODE: ClassVar[int] = 0


@dataclass(frozen=True, slots=True)
class Move:
    """Velocity command from the operator's sticks, plus arming and mode (5 B).

    Body: int8 x, y, z, yaw; flags byte (bit 7 arm, bit 6 disarm, bits 5..3 reserved = 0,
    bits 2..0 mode).

    The four axes are body-frame (FRD) stick deflections quantised to int8 codes in −127..127
    (−128 is not used, so the range is symmetric): axis value = code / 127 ∈ [−1, 1], where
    +x = surge forward, +y = sway to starboard (right), +z = heave down, +yaw = turn clockwise
    seen from above. The vehicle scales a deflection of 1 to its maximum effort on that axis.

    Attributes:
        x: surge code, −127..127.
        y: sway code, −127..127.
        z: heave code, −127..127.
        yaw: yaw code, −127..127.
        arm: request arming.
        disarm: request disarming.
        mode: requested flight mode.
    """

    CODE: ClassVar[int] = 1
    BODY_SIZE: ClassVar[int] = 5

    x: int
    y: int
    z: int
    yaw: int
    arm: bool = False
    disarm: bool = False
    mode: Mode = Mode.MANUAL

    def __post_init__(self) -> None:
        for name in ("x", "y", "z", "yaw"):
            check_int(name, getattr(self, name), -AXIS_SCALE, AXIS_SCALE)
        object.__setattr__(self, "mode", coerce_mode(self.mode))

    @classmethod
    def from_axes(
        cls,
        x: float,
        y: float,
        z: float,
        yaw: float,
        arm: bool = False,
        disarm: bool = False,
        mode: Mode = Mode.MANUAL,
    ) -> Self:
        """Quantise stick deflections in [−1, 1] (FRD) to int8 codes.

        code = round(127 · value) (round half to even); values outside [−1, 1] saturate.

        Args:
            x: surge deflection, + forward.
            y: sway deflection, + right.
            z: heave deflection, + down.
            yaw: yaw deflection, + clockwise seen from above.
            arm: request arming.
            disarm: request disarming.
            mode: requested flight mode.

        Raises:
            ValueError: a non-finite deflection or an unknown mode.
        """
        codes = [_axis_code(name, v) for name, v in (("x", x), ("y", y), ("z", z), ("yaw", yaw))]
        return cls(codes[0], codes[1], codes[2], codes[3], arm, disarm, mode)

    @property
    def axes(self) -> tuple[float, float, float, float]:
        """(x, y, z, yaw) deflections in [−1, 1], FRD: code / 127."""
        return (
            self.x / AXIS_SCALE,
            self.y / AXIS_SCALE,
            self.z / AXIS_SCALE,
            self.yaw / AXIS_SCALE,
        )

    def encode(self) -> bytes:
        """The 5-byte body."""
        flags = (0x80 if self.arm else 0) | (0x40 if self.disarm else 0) | int(self.mode)
        return struct.pack(">bbbbB", self.x, self.y, self.z, self.yaw, flags)

    @classmethod
    def decode(cls, data: bytes) -> Self:
        """Parse a 5-byte body. Raises ValueError on a bad size, −128, reserved bits or mode."""
        _check_body(cls.__name__, cls.BODY_SIZE, data)
        x, y, z, yaw, flags = struct.unpack(">bbbbB", data)
        if flags & 0x38:
            raise ValueError(f"Move flags reserved bits 5..3 set: {flags:#04x}")
        return cls(x, y, z, yaw, bool(flags & 0x80), bool(flags & 0x40), coerce_mode(flags & 7))


def _axis_code(name: str, value: float) -> int:
    if not math.isfinite(value):
        raise ValueError(f"{name} deflection must be finite, got {value!r}")
    return round(max(-1.0, min(1.0, value)) * AXIS_SCALE)


@dataclass(frozen=True, slots=True)
class KeepHeading:
    """Hold a compass heading (2 B: u16 big-endian).

    Unit and quantisation: whole degrees, 0..359, clockwise from north (the same 1° step as
    the heading the vehicle reports in its state). The u16 field leaves room for 360..65535,
    which are rejected as malformed.

    Attributes:
        heading_deg: target heading [deg], 0..359.
    """

    CODE: ClassVar[int] = 2
    BODY_SIZE: ClassVar[int] = 2

    heading_deg: int

    def __post_init__(self) -> None:
        check_int("heading_deg", self.heading_deg, 0, 359)

    @classmethod
    def from_degrees(cls, heading_deg: float) -> Self:
        """Round a heading in degrees to the nearest whole degree, reduced modulo 360.

        Raises:
            ValueError: non-finite heading.
        """
        if not math.isfinite(heading_deg):
            raise ValueError(f"heading_deg must be finite, got {heading_deg!r}")
        return cls(round(heading_deg) % 360)

    def encode(self) -> bytes:
        """The 2-byte body."""
        return self.heading_deg.to_bytes(2, "big")

    @classmethod
    def decode(cls, data: bytes) -> Self:
        """Parse a 2-byte body. Raises ValueError on a bad size or a heading above 359."""
        _check_body(cls.__name__, cls.BODY_SIZE, data)
        return cls(int.from_bytes(data, "big"))


@dataclass(frozen=True, slots=True)
class HoldChannel:
    """Give the vehicle the channel: it streams image chunks for a while (1 B).

    Attributes:
        duration_s: how long the vehicle may keep the channel [s], 0..255.
    """

    CODE: ClassVar[int] = 3
    BODY_SIZE: ClassVar[int] = 1

    duration_s: int

    def __post_init__(self) -> None:
        check_int("duration_s", self.duration_s, 0, 255)

    def encode(self) -> bytes:
        """The 1-byte body."""
        return bytes((self.duration_s,))

    @classmethod
    def decode(cls, data: bytes) -> Self:
        """Parse a 1-byte body. Raises ValueError on a bad size."""
        _check_body(cls.__name__, cls.BODY_SIZE, data)
        return cls(data[0])


@dataclass(frozen=True, slots=True)
class ImageSettings:
    """Image coder settings for the next images (8 B).

    Bytes 0–4 hold the region of interest x0, y0, x1, y1, 10 bits each, packed MSB-first::

        b0 = x0[9:2]; b1 = x0[1:0]·y0[9:4]; b2 = y0[3:0]·x1[9:6]; b3 = x1[5:0]·y1[9:8]; b4 = y1[7:0]

    byte 5 = bits 7..4 ROI shift, bits 3..1 reserved (0), bit 0 mono; bytes 6–7 = byte budget,
    u16 big-endian. The codec does not require x0 ≤ x1 or y0 ≤ y1; that is the image coder's
    business.

    Attributes:
        x0: ROI left column [px], 0..1023.
        y0: ROI top row [px], 0..1023.
        x1: ROI right column [px], 0..1023.
        y1: ROI bottom row [px], 0..1023.
        roi_shift: bit planes the ROI is shifted up (Maxshift), 0..15.
        mono: encode 8-bit greyscale instead of colour.
        budget_bytes: largest encoded image size [B], 0..65535.
    """

    CODE: ClassVar[int] = 4
    BODY_SIZE: ClassVar[int] = 8

    x0: int
    y0: int
    x1: int
    y1: int
    roi_shift: int
    mono: bool
    budget_bytes: int

    def __post_init__(self) -> None:
        for name in ("x0", "y0", "x1", "y1"):
            check_int(name, getattr(self, name), 0, _ROI_MAX)
        check_int("roi_shift", self.roi_shift, 0, 15)
        check_int("budget_bytes", self.budget_bytes, 0, 0xFFFF)

    def encode(self) -> bytes:
        """The 8-byte body."""
        roi = (self.x0 << 30) | (self.y0 << 20) | (self.x1 << 10) | self.y1
        settings = (self.roi_shift << 4) | (1 if self.mono else 0)
        return roi.to_bytes(5, "big") + bytes((settings,)) + self.budget_bytes.to_bytes(2, "big")

    @classmethod
    def decode(cls, data: bytes) -> Self:
        """Parse an 8-byte body. Raises ValueError on a bad size or reserved bits set."""
        _check_body(cls.__name__, cls.BODY_SIZE, data)
        roi = int.from_bytes(data[:5], "big")
        settings = data[5]
        if settings & 0x0E:
            raise ValueError(f"ImageSettings byte 5 reserved bits 3..1 set: {settings:#04x}")
        return cls(
            (roi >> 30) & _ROI_MAX,
            (roi >> 20) & _ROI_MAX,
            (roi >> 10) & _ROI_MAX,
            roi & _ROI_MAX,
            settings >> 4,
            bool(settings & 1),
            int.from_bytes(data[6:8], "big"),
        )


@dataclass(frozen=True, slots=True)
class DisableKeepHeading(_EmptyBody):
    """Stop holding a heading (no body)."""

    CODE: ClassVar[int] = 5


@dataclass(frozen=True, slots=True)
class GoTo:
    """Go to a position (8 B: four int16, **big-endian**; the original used host order).

    Position in the world NED frame of the vehicle's positioning system, the same frame as the
    x, y, z of the vehicle state: +x north, +y east, +z down (depth).

    Attributes:
        x_cm: north [cm], −32768..32767.
        y_cm: east [cm], −32768..32767.
        z_cm: down [cm], −32768..32767.
        heading: heading on arrival [deg, whole degrees, clockwise from north], any int16;
            the vehicle reduces it modulo 360.
    """

    CODE: ClassVar[int] = 6
    BODY_SIZE: ClassVar[int] = 8

    x_cm: int
    y_cm: int
    z_cm: int
    heading: int

    def __post_init__(self) -> None:
        for name in ("x_cm", "y_cm", "z_cm", "heading"):
            check_int(name, getattr(self, name), *_INT16)

    def encode(self) -> bytes:
        """The 8-byte body."""
        return struct.pack(">hhhh", self.x_cm, self.y_cm, self.z_cm, self.heading)

    @classmethod
    def decode(cls, data: bytes) -> Self:
        """Parse an 8-byte body. Raises ValueError on a bad size."""
        _check_body(cls.__name__, cls.BODY_SIZE, data)
        x_cm, y_cm, z_cm, heading = struct.unpack(">hhhh", data)
        return cls(x_cm, y_cm, z_cm, heading)


@dataclass(frozen=True, slots=True)
class OrderIncoming(_EmptyBody):
    """Announces that an order follows (no body)."""

    CODE: ClassVar[int] = 7


@dataclass(frozen=True, slots=True)
class EndEffectorGoTo:
    """Move the manipulator arm's tool point to a position (8 B) — an extension of the paper's
    order table (code 8; the telerobotics code has no arm).

    Body (big-endian)::

        bytes 0–1  x_cm  int16   north [cm]  ┐ the GoTo's coordinates: world NED frame of the
        bytes 2–3  y_cm  int16   east [cm]   │ vehicle's positioning system, 1 cm step,
        bytes 4–5  z_cm  int16   down [cm]   ┘ −327.68..327.67 m
        bytes 6–7  yaw   uint16  tool yaw: 0..35999 = 0.00..359.99° in 0.01° steps, clockwise
                                 from north (about the world down axis); 0xFFFF
                                 (:data:`EE_NO_YAW`) = no yaw target (the tool keeps its yaw);
                                 36000..65534 reserved, rejected

    The position is the target of the arm's tool point (the end effector), not of the vehicle;
    the vehicle-manipulator system decides how vehicle and arm share the motion.

    Attributes:
        x_cm: north [cm], −32768..32767.
        y_cm: east [cm], −32768..32767.
        z_cm: down [cm], −32768..32767.
        yaw_cdeg: tool yaw target [0.01°, clockwise from north], 0..35999, or None for no
            yaw target.
    """

    CODE: ClassVar[int] = 8
    BODY_SIZE: ClassVar[int] = 8

    x_cm: int
    y_cm: int
    z_cm: int
    yaw_cdeg: int | None = None

    def __post_init__(self) -> None:
        for name in ("x_cm", "y_cm", "z_cm"):
            check_int(name, getattr(self, name), *_INT16)
        if self.yaw_cdeg is not None:
            check_int("yaw_cdeg", self.yaw_cdeg, 0, _EE_YAW_CODES - 1)

    def encode(self) -> bytes:
        """The 8-byte body."""
        yaw = EE_NO_YAW if self.yaw_cdeg is None else self.yaw_cdeg
        return struct.pack(">hhhH", self.x_cm, self.y_cm, self.z_cm, yaw)

    @classmethod
    def decode(cls, data: bytes) -> Self:
        """Parse an 8-byte body. Raises ValueError on a bad size or a reserved yaw code."""
        _check_body(cls.__name__, cls.BODY_SIZE, data)
        x_cm, y_cm, z_cm, yaw = struct.unpack(">hhhH", data)
        if yaw == EE_NO_YAW:
            return cls(x_cm, y_cm, z_cm)
        if yaw >= _EE_YAW_CODES:
            raise ValueError(f"EndEffectorGoTo yaw code {yaw} is reserved (36000..65534)")
        return cls(x_cm, y_cm, z_cm, yaw)


Order = (
    NoOrder
    | Move
    | KeepHeading
    | HoldChannel
    | ImageSettings
    | DisableKeepHeading
    | GoTo
    | OrderIncoming
    | EndEffectorGoTo
)
"""Any order an :class:`~testbed.protocol.messages.OperatorMessage` can carry."""

ORDER_TYPES: dict[int, type[Order]] = {
    cls.CODE: cls
    for cls in (
        NoOrder,
        Move,
        KeepHeading,
        HoldChannel,
        ImageSettings,
        DisableKeepHeading,
        GoTo,
        OrderIncoming,
        EndEffectorGoTo,
    )
}
"""Order class by type code: the paper's 0..7 and the extension's 8 (codes 9..15 unused)."""
