"""The byte layout of each kind of field value, and the error a garbled one raises.

A layout node is the compiled form of one field annotation. :class:`LayoutNode` is the base:
fixed nodes carry ``struct`` format characters and a flat form, so a run of them packs with one
call. One subclass per field kind writes and reads its values: :class:`PlainLayout` (int,
float), :class:`BoolLayout`, :class:`IntEnumLayout`, :class:`StrLayout`, :class:`BytesLayout`,
:class:`StrEnumLayout` and :class:`VarTupleLayout` (``tuple[A, ...]``). Which annotation becomes
which node, and the bytes of every kind, are described once in :mod:`testbed.common.fieldcodec`,
whose compiler builds these nodes (and the composite of a fixed tuple or a dataclass) into a
``FieldCodec``. A new field kind is a node here, a branch of that compiler and a row of its
table.

Reading remote garbage raises :class:`FieldDecodeError`, or a ``struct.error``, ``IndexError``,
``TypeError`` or ``ValueError`` that the field codec turns into one. Standard library only; no
pickle, no eval.
"""

from __future__ import annotations

import enum
import struct
from collections.abc import Sequence
from typing import Any

__all__ = [
    "U16_MAX",
    "BoolLayout",
    "Buffer",
    "BytesLayout",
    "FieldDecodeError",
    "IntEnumLayout",
    "LayoutNode",
    "PlainLayout",
    "StrEnumLayout",
    "StrLayout",
    "VarTupleLayout",
]

U16_MAX = 0xFFFF
_U16 = struct.Struct(">H")
_BOOLS = (False, True)

Buffer = bytes | bytearray | memoryview


class FieldDecodeError(ValueError):
    """Bytes that are not a valid encoding of the component type (remote data)."""


class LayoutNode:
    """One field type's layout. Fixed nodes also have struct formats and a flat form.

    Attributes:
        fixed: whether every value has the same size (then the struct attributes are set).
        pack_fmt, unpack_fmt: struct format characters (no byte-order prefix); they differ only
            for bools (packed with ``?``, which writes any truth value as 0/1, read as ``B``).
        width: number of flat primitives a value becomes.
        size: encoded size [B].
        plain_out: the value is its own flat form (appended as is when flattening).
        plain_in: the flat primitive is the value (no conversion when building).
    """

    __slots__ = ("fixed", "pack_fmt", "plain_in", "plain_out", "size", "unpack_fmt", "width")

    def __init__(self, pack_fmt: str | None, unpack_fmt: str | None = None) -> None:
        self.fixed = pack_fmt is not None
        self.pack_fmt = pack_fmt or ""
        self.unpack_fmt = unpack_fmt if unpack_fmt is not None else self.pack_fmt
        self.width = len(self.pack_fmt)
        self.size = struct.calcsize(">" + self.pack_fmt) if self.fixed else 0
        self.plain_out = False
        self.plain_in = False

    # Fixed nodes: flat forms.
    def flatten(self, value: Any, out: list[Any]) -> None:
        """Append the flat primitives of ``value`` to ``out``."""
        raise NotImplementedError

    def build(self, values: Sequence[Any], i: int) -> Any:
        """The value made of ``values[i : i + width]``."""
        raise NotImplementedError

    # Every node: streaming form.
    def write(self, value: Any, out: bytearray) -> None:
        """Append the encoding of ``value`` to ``out``."""
        flat: list[Any] = []
        self.flatten(value, flat)
        out += struct.pack(">" + self.pack_fmt, *flat)

    def read(self, buf: Buffer, pos: int) -> tuple[Any, int]:
        """The value encoded at ``buf[pos:]`` and the position after it."""
        values = struct.unpack_from(">" + self.unpack_fmt, buf, pos)
        return self.build(values, 0), pos + self.size


class PlainLayout(LayoutNode):
    """int (``q``) or float (``d``): the Python value is the struct value."""

    __slots__ = ()

    def __init__(self, fmt: str) -> None:
        super().__init__(fmt)
        self.plain_out = self.plain_in = True

    def flatten(self, value: Any, out: list[Any]) -> None:
        out.append(value)

    def build(self, values: Sequence[Any], i: int) -> Any:
        return values[i]


class BoolLayout(LayoutNode):
    """bool: packed by truth as 0/1, read back strictly (only 0 or 1)."""

    __slots__ = ()

    def __init__(self) -> None:
        super().__init__("?", "B")
        self.plain_out = True

    def flatten(self, value: Any, out: list[Any]) -> None:
        out.append(value)

    def build(self, values: Sequence[Any], i: int) -> Any:
        return _BOOLS[values[i]]  # IndexError on 2..255: malformed


class IntEnumLayout(LayoutNode):
    """Enum with int values: its value as an i64."""

    __slots__ = ("cls", "members", "values")

    def __init__(self, cls: type[enum.Enum]) -> None:
        super().__init__("q")
        self.cls = cls
        self.values = {member: member.value for member in cls}
        self.members = {member.value: member for member in cls}

    def flatten(self, value: Any, out: list[Any]) -> None:
        try:
            out.append(self.values[value])
        except (KeyError, TypeError):
            raise TypeError(f"expected a {self.cls.__qualname__}, got {value!r}") from None

    def build(self, values: Sequence[Any], i: int) -> Any:
        member = self.members.get(values[i])
        return self.cls(values[i]) if member is None else member  # flags: composite values


class StrLayout(LayoutNode):
    """str: u16 byte count + UTF-8."""

    __slots__ = ()

    def __init__(self) -> None:
        super().__init__(None)

    def write(self, value: Any, out: bytearray) -> None:
        if not isinstance(value, str):
            raise TypeError(f"expected a str, got {value!r}")
        data = value.encode("utf-8")
        _write_counted(data, out)

    def read(self, buf: Buffer, pos: int) -> tuple[Any, int]:
        data, pos = _read_counted(buf, pos)
        return str(data, "utf-8"), pos


class BytesLayout(LayoutNode):
    """bytes: u16 byte count + the bytes."""

    __slots__ = ()

    def __init__(self) -> None:
        super().__init__(None)

    def write(self, value: Any, out: bytearray) -> None:
        if not isinstance(value, bytes | bytearray):
            raise TypeError(f"expected bytes, got {value!r}")
        _write_counted(value, out)

    def read(self, buf: Buffer, pos: int) -> tuple[Any, int]:
        return _read_counted(buf, pos)


class StrEnumLayout(LayoutNode):
    """Enum with str values: its value as a str."""

    __slots__ = ("cls",)

    def __init__(self, cls: type[enum.Enum]) -> None:
        super().__init__(None)
        self.cls = cls

    def write(self, value: Any, out: bytearray) -> None:
        if not isinstance(value, self.cls):
            raise TypeError(f"expected a {self.cls.__qualname__}, got {value!r}")
        _write_counted(value.value.encode("utf-8"), out)

    def read(self, buf: Buffer, pos: int) -> tuple[Any, int]:
        data, pos = _read_counted(buf, pos)
        return self.cls(str(data, "utf-8")), pos


def _write_counted(data: bytes | bytearray, out: bytearray) -> None:
    if len(data) > U16_MAX:
        raise ValueError(f"{len(data)} B is longer than the {U16_MAX} B a u16 count allows")
    out += _U16.pack(len(data))
    out += data


def _read_counted(buf: Buffer, pos: int) -> tuple[bytes, int]:
    (count,) = _U16.unpack_from(buf, pos)
    start = pos + 2
    end = start + count
    if end > len(buf):
        raise FieldDecodeError(f"{count} B announced, {len(buf) - start} B left")
    return bytes(buf[start:end]), end


class VarTupleLayout(LayoutNode):
    """``tuple[A, ...]``: u16 item count + the items (fixed items in one struct call)."""

    __slots__ = ("item", "packers", "unpackers")

    def __init__(self, item: LayoutNode) -> None:
        super().__init__(None)
        self.item = item
        # Structs per item count, for counts up to _CACHED_COUNT (bounded memory).
        self.packers: dict[int, struct.Struct] = {}
        self.unpackers: dict[int, struct.Struct] = {}

    def write(self, value: Any, out: bytearray) -> None:
        if not isinstance(value, tuple):
            raise TypeError(f"expected a tuple, got {value!r}")
        count = len(value)
        if count > U16_MAX:
            raise ValueError(f"{count} items; a u16 count allows at most {U16_MAX}")
        item = self.item
        if not item.fixed:
            out += _U16.pack(count)
            for part in value:
                item.write(part, out)
            return
        flat: list[Any] | tuple[Any, ...] = value
        if not item.plain_out:
            flat = []
            for part in value:
                item.flatten(part, flat)
        packer = self.packers.get(count) or _cached(self.packers, "H", item.pack_fmt, count)
        out += packer.pack(count, *flat)

    def read(self, buf: Buffer, pos: int) -> tuple[Any, int]:
        (count,) = _U16.unpack_from(buf, pos)
        pos += 2
        item = self.item
        if not item.fixed:
            items = []
            for _ in range(count):
                part, pos = item.read(buf, pos)
                items.append(part)
            return tuple(items), pos
        end = pos + count * item.size
        if end > len(buf):
            raise FieldDecodeError(f"{count} items announced, {len(buf) - pos} B left")
        unpacker = self.unpackers.get(count) or _cached(self.unpackers, "", item.unpack_fmt, count)
        values = unpacker.unpack_from(buf, pos)
        if item.plain_in:
            return values, end
        width = item.width
        return tuple(item.build(values, k * width) for k in range(count)), end


_CACHED_COUNT = 256


def _cached(cache: dict[int, struct.Struct], prefix: str, fmt: str, count: int) -> struct.Struct:
    """The struct of ``prefix`` then ``count`` repetitions of ``fmt``, cached for small counts."""
    packer = struct.Struct(">" + prefix + _repeat(fmt, count))
    if count <= _CACHED_COUNT:
        cache[count] = packer
    return packer


def _repeat(fmt: str, count: int) -> str:
    return f"{count}{fmt}" if len(fmt) == 1 else fmt * count
