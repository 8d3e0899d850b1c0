"""Per-type field codec: exact layouts, exact round trips, local errors and remote garbage."""

from __future__ import annotations

import enum
import math
import struct
from dataclasses import dataclass
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from testbed.common.field_layouts import FieldDecodeError
from testbed.common.fieldcodec import compile_codec

I64_MIN = -(2**63)
I64_MAX = 2**63 - 1


class Color(enum.Enum):
    RED = 1
    GREEN = -7
    MAX = I64_MAX
    MIN = I64_MIN


class Level(enum.IntEnum):
    LOW = 0
    HIGH = 2


class Tag(enum.Enum):
    ALPHA = "alpha"
    BETA = "βήτα"
    EMPTY = ""


@dataclass(frozen=True, slots=True)
class Inner:
    flag: bool
    count: int
    ratio: float


@dataclass(frozen=True, slots=True)
class Scalars:
    flag: bool
    count: int
    ratio: float
    name: str
    raw: bytes


@dataclass(frozen=True, slots=True)
class Fixed:
    position: tuple[float, float, float]
    color: Color
    level: Level
    inner: Inner
    pair: tuple[int, bool]
    nested: tuple[Inner, tuple[float, int]]


@dataclass(frozen=True, slots=True)
class Variable:
    tags: tuple[Tag, ...]
    items: tuple[Inner, ...]
    words: tuple[str, ...]
    grid: tuple[tuple[int, float], ...]
    flags: tuple[bool, ...]
    mixed: tuple[str, Color]
    tag: Tag
    tail: float


@dataclass(frozen=True, slots=True)
class Empty:
    pass


@dataclass(frozen=True, slots=True)
class Positive:
    value: int

    def __post_init__(self) -> None:
        if self.value <= 0:
            raise ValueError("value must be positive")


# ------------------------------------------------------------------------------ strategies

i64 = st.integers(I64_MIN, I64_MAX)
extreme_ints = st.sampled_from([I64_MIN, I64_MIN + 1, -1, 0, 1, I64_MAX - 1, I64_MAX])
ints = st.one_of(i64, extreme_ints)
floats = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0.0, -0.0, math.inf, -math.inf, 5e-324, -5e-324, 1.7976931348623157e308]),
)
texts = st.text(max_size=12)  # any code point but lone surrogates (not encodable in UTF-8)
inner = st.builds(Inner, st.booleans(), ints, floats)
scalars = st.builds(Scalars, st.booleans(), ints, floats, texts, st.binary(max_size=12))
fixed = st.builds(
    Fixed,
    st.tuples(floats, floats, floats),
    st.sampled_from(Color),
    st.sampled_from(Level),
    inner,
    st.tuples(ints, st.booleans()),
    st.tuples(inner, st.tuples(floats, ints)),
)
variable = st.builds(
    Variable,
    st.lists(st.sampled_from(Tag), max_size=5).map(tuple),
    st.lists(inner, max_size=4).map(tuple),
    st.lists(texts, max_size=4).map(tuple),
    st.lists(st.tuples(ints, floats), max_size=4).map(tuple),
    st.lists(st.booleans(), max_size=6).map(tuple),
    st.tuples(texts, st.sampled_from(Color)),
    st.sampled_from(Tag),
    floats,
)


def same(a: Any, b: Any) -> bool:
    """Exact equality: same types all the way down, floats bit for bit up to NaN payloads."""
    if type(a) is not type(b):
        return False
    if isinstance(a, float):
        if math.isnan(a) or math.isnan(b):
            return math.isnan(a) and math.isnan(b)
        return a == b and math.copysign(1.0, a) == math.copysign(1.0, b)
    if isinstance(a, tuple):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b, strict=True))
    if hasattr(a, "__dataclass_fields__"):
        return all(same(getattr(a, f), getattr(b, f)) for f in a.__dataclass_fields__)
    return bool(a == b)


# ------------------------------------------------------------------------------ layouts


def test_fixed_scalar_layout_byte_for_byte() -> None:
    codec = compile_codec(Inner)
    # bool 0x01 · i64 −1 (two's complement) · binary64 1.5 = 0x3FF8000000000000
    assert codec.encode(Inner(True, -1, 1.5)) == bytes.fromhex("01" + "ff" * 8 + "3ff8" + "00" * 6)
    assert codec.encode(Inner(False, 258, -2.0)) == bytes.fromhex(
        "00" + "0000000000000102" + "c000000000000000"
    )
    assert codec.fixed_size == 1 + 8 + 8


def test_variable_layout_byte_for_byte() -> None:
    value = Scalars(True, 3, 0.0, "é", b"\x00\xff")
    expected = (
        b"\x01"
        + (3).to_bytes(8, "big")
        + b"\x00" * 8
        + b"\x00\x02"
        + "é".encode()  # u16 byte count 2, then UTF-8 C3 A9
        + b"\x00\x02\x00\xff"
    )
    codec = compile_codec(Scalars)
    assert codec.encode(value) == expected
    assert codec.fixed_size is None
    variable_value = Variable(
        tags=(Tag.BETA,),
        items=(),
        words=("a", ""),
        grid=((1, 0.5),),
        flags=(True, False, True),
        mixed=("", Color.GREEN),
        tag=Tag.EMPTY,
        tail=-0.0,
    )
    expected_variable = (
        b"\x00\x01" + b"\x00\x08" + "βήτα".encode()  # 1 tag: its value as a str
        + b"\x00\x00"  # no items
        + b"\x00\x02" + b"\x00\x01a" + b"\x00\x00"  # two words
        + b"\x00\x01" + (1).to_bytes(8, "big") + bytes.fromhex("3fe0000000000000")
        + b"\x00\x03\x01\x00\x01"
        + b"\x00\x00" + (-7).to_bytes(8, "big", signed=True)
        + b"\x00\x00"  # Tag.EMPTY: ""
        + bytes.fromhex("8000000000000000")  # −0.0
    )  # fmt: skip
    assert compile_codec(Variable).encode(variable_value) == expected_variable


def test_fixed_sizes_are_the_sum_of_their_fields() -> None:
    assert compile_codec(Fixed).fixed_size == 3 * 8 + 8 + 8 + 17 + (8 + 1) + (17 + 8 + 8)
    assert compile_codec(Empty).fixed_size == 0
    assert compile_codec(Empty).encode(Empty()) == b""
    assert compile_codec(Empty).decode(b"") == Empty()


# ------------------------------------------------------------------------------ round trips


@settings(max_examples=300)
@given(st.one_of(inner, scalars, fixed, variable))
def test_round_trip_is_exact(value: Any) -> None:
    codec = compile_codec(type(value))
    data = codec.encode(value)
    if codec.fixed_size is not None:
        assert len(data) == codec.fixed_size
    assert same(codec.decode(data), value)


def test_nan_stays_nan_with_its_bits_but_never_equal() -> None:
    quiet_with_payload = struct.unpack(">d", bytes.fromhex("7ff8000000000123"))[0]
    codec = compile_codec(Inner)
    decoded = codec.decode(codec.encode(Inner(True, 0, quiet_with_payload)))
    assert math.isnan(decoded.ratio)
    assert struct.pack(">d", decoded.ratio) == bytes.fromhex("7ff8000000000123")
    assert decoded != Inner(True, 0, quiet_with_payload)  # NaN != NaN: documented


def test_ints_are_i64_and_floats_accept_ints() -> None:
    codec = compile_codec(Inner)
    for count in (I64_MIN, I64_MAX):
        assert codec.decode(codec.encode(Inner(False, count, 0.0))).count == count
    decoded = codec.decode(codec.encode(Inner(False, 0, 3)))  # an int in a float field
    assert decoded.ratio == 3.0 and type(decoded.ratio) is float


# ------------------------------------------------------------------------------ local errors


_INNER = Inner(True, 0, 0.0)
_NESTED = (_INNER, (0.0, 0))


@pytest.mark.parametrize(
    ("value", "cls_name"),
    [  # wrong on purpose: out of range, too long, unencodable or of the wrong type
        (Inner(True, 2**63, 0.0), "Inner"),
        (Inner(True, I64_MIN - 1, 0.0), "Inner"),
        (Inner(True, 1.5, 0.0), "Inner"),
        (Scalars(True, 0, 0.0, "x" * 65536, b""), "Scalars"),
        (Scalars(True, 0, 0.0, "\ud800", b""), "Scalars"),  # lone surrogate
        (Scalars(True, 0, 0.0, "", "text"), "Scalars"),
        (Fixed((0.0, 0.0), Color.RED, Level.LOW, _INNER, (0, True), _NESTED), "Fixed"),
        (Fixed((0.0, 0.0, 0.0), 1, Level.LOW, _INNER, (0, True), _NESTED), "Fixed"),
        (Fixed((0.0, 0.0, 0.0), Color.RED, Level.LOW, _INNER, (0, True), (_INNER,)), "Fixed"),
        (Variable((), (), (), (), (True,) * 65536, ("", Color.RED), Tag.ALPHA, 0.0), "Variable"),
        (Variable((), (), (), (), [True], ("", Color.RED), Tag.ALPHA, 0.0), "Variable"),
        (Variable(("alpha",), (), (), (), (), ("", Color.RED), Tag.ALPHA, 0.0), "Variable"),
    ],
)
def test_unencodable_values_raise_value_error_naming_the_type(value: Any, cls_name: str) -> None:
    with pytest.raises(ValueError, match=cls_name):
        compile_codec(type(value)).encode(value)


def test_a_value_of_another_type_is_refused() -> None:
    with pytest.raises(ValueError, match="expected a Inner"):
        compile_codec(Inner).encode(Scalars(True, 0, 0.0, "", b""))


class Ratio(enum.Enum):
    HALF = 0.5


class Huge(enum.Enum):
    BIG = 2**64


@dataclass(frozen=True, slots=True)
class WithRatio:
    ratio: Ratio


@dataclass(frozen=True, slots=True)
class WithHuge:
    huge: Huge


def test_enums_without_int_or_str_values_do_not_compile() -> None:
    with pytest.raises(TypeError, match="Ratio"):
        compile_codec(WithRatio)
    with pytest.raises(TypeError, match="outside i64"):
        compile_codec(WithHuge)


# ------------------------------------------------------------------------------ remote garbage


def _variable_sample() -> Variable:
    return Variable(
        tags=(Tag.ALPHA, Tag.BETA),
        items=(Inner(True, 1, 2.0),),
        words=("x",),
        grid=((1, 2.0),),
        flags=(True,),
        mixed=("m", Color.RED),
        tag=Tag.BETA,
        tail=1.0,
    )


@pytest.mark.parametrize("value", [Inner(True, 5, 1.0), _variable_sample()])
def test_every_truncation_and_any_trailing_byte_is_malformed(value: Any) -> None:
    codec = compile_codec(type(value))
    data = codec.encode(value)
    for cut in range(len(data)):
        with pytest.raises(FieldDecodeError):
            codec.decode(data[:cut])
    with pytest.raises(FieldDecodeError, match=r"Inner|trailing"):
        codec.decode(data + b"\x00")


def test_bad_bool_enum_utf8_and_count_are_malformed() -> None:
    inner_codec = compile_codec(Inner)
    good = inner_codec.encode(Inner(True, 0, 0.0))
    with pytest.raises(FieldDecodeError):
        inner_codec.decode(b"\x02" + good[1:])  # a bool is 0 or 1
    fixed_codec = compile_codec(Fixed)
    sample = Fixed(
        (0.0, 0.0, 0.0),
        Color.RED,
        Level.HIGH,
        Inner(True, 0, 0.0),
        (0, True),
        (Inner(True, 0, 0.0), (0.0, 0)),
    )
    data = bytearray(fixed_codec.encode(sample))
    data[24:32] = (2).to_bytes(8, "big")  # Color has no member 2
    with pytest.raises(FieldDecodeError, match="Fixed"):
        fixed_codec.decode(bytes(data))
    scalars_codec = compile_codec(Scalars)
    text = scalars_codec.encode(Scalars(False, 0, 0.0, "ab", b""))
    with pytest.raises(FieldDecodeError):
        scalars_codec.decode(text.replace(b"ab", b"\xc3\x28"))  # invalid UTF-8
    with pytest.raises(FieldDecodeError):
        scalars_codec.decode(text[:17] + b"\x00\x09" + text[19:])  # count beyond the data
    tag_codec = compile_codec(Variable)
    data = tag_codec.encode(_variable_sample())
    with pytest.raises(FieldDecodeError):
        tag_codec.decode(data.replace("βήτα".encode(), "βήτb".encode()))  # no such Tag value


def test_constructor_rejections_are_malformed() -> None:
    codec = compile_codec(Positive)
    assert codec.decode((7).to_bytes(8, "big")) == Positive(7)
    with pytest.raises(FieldDecodeError, match="positive"):
        codec.decode((0).to_bytes(8, "big"))


@settings(max_examples=400)
@given(st.sampled_from([Inner, Scalars, Fixed, Variable, Empty]), st.binary(max_size=80))
def test_any_bytes_decode_or_raise_field_decode_error(cls: type[Any], data: bytes) -> None:
    codec = compile_codec(cls)
    try:
        value = codec.decode(data)
    except FieldDecodeError:
        return
    assert type(value) is cls
    assert codec.encode(value) == data  # a decodable encoding is the canonical one


def test_long_variable_tuples_round_trip() -> None:
    codec = compile_codec(Variable)
    value = Variable(
        tags=(Tag.ALPHA,) * 300,
        items=tuple(Inner(k % 3 == 0, k, k / 7) for k in range(300)),
        words=(),
        grid=tuple((k, -k / 3) for k in range(257)),
        flags=tuple(k % 2 == 0 for k in range(1000)),
        mixed=("", Color.MIN),
        tag=Tag.ALPHA,
        tail=0.0,
    )
    for _ in range(2):  # the second pass reuses what the first compiled
        data = codec.encode(value)
        assert len(data) == 2 + 300 * 7 + 2 + 300 * 17 + 2 + 2 + 257 * 16 + 2 + 1000 + 2 + 8 + 7 + 8
        assert same(codec.decode(data), value)
