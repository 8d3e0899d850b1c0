"""Per-type binary codec of replicated component values, compiled once from their field types.

:func:`compile_codec` turns a registered component type (a frozen dataclass whose fields the
:class:`~testbed.ecs.ComponentRegistry` has already checked) into a :class:`FieldCodec` that
writes a value as bytes and reads it back. Both nodes compile the same layout from the same
type, so the bytes carry no names, tags or type information: only field values, in declaration
order, big-endian, without padding.

Value layout, by field type:

==========================  ==============================================================
``bool``                    1 byte: ``0x00`` False, ``0x01`` True, written by truth value
                            (reading any other byte is malformed)
``int``                     8 bytes, signed two's complement (i64). Values outside
                            −2⁶³ … 2⁶³−1 cannot be encoded (``ValueError``). A fixed width
                            rather than a zigzag varint: every all-fixed layout then packs
                            with one precompiled ``struct`` format.
``float``                   8 bytes, IEEE 754 binary64: every float round-trips exactly,
                            −0.0 and ±inf included. NaN stays a NaN (``struct`` keeps its
                            bits), but NaN ≠ NaN, so a component holding one never compares
                            equal to its decoded copy and ``World.set`` records every receipt.
``str``                     u16 byte count + UTF-8 (≤ 65 535 bytes; lone surrogates cannot
                            be encoded; invalid UTF-8 is malformed)
``bytes``                   u16 byte count + the bytes (≤ 65 535)
enum with int values        its value as an i64 (a value that names no member is malformed)
enum with str values        its value as a ``str``
``tuple[A, B, …]``          the items in order, no count
``tuple[A, ...]``           u16 item count + the items (≤ 65 535 items)
nested frozen dataclass     its fields in declaration order
==========================  ==============================================================

Enums whose values are neither all ints nor all strs cannot be compiled (``TypeError``).

A layout without ``str``, ``bytes``, str-valued enums or variable tuples is *fixed*: it has one
size (:attr:`FieldCodec.fixed_size`) and encodes with a single precompiled ``struct`` call. A
variable layout is written field by field, consecutive fixed fields still packed together.

Local misuse (a value of the wrong type, an int out of range, an over-long string) raises
``ValueError`` naming the component type. Remote garbage raises
:class:`~testbed.common.field_layouts.FieldDecodeError` and nothing else (a ``ValueError``/
``TypeError`` from a component's own ``__post_init__`` included); the change-set codec turns it
into a value. Standard library only; no pickle, no eval.

Where things live: this module holds the table above, the compiler (annotation → layout node),
the composite layout of fixed tuples and dataclasses (consecutive fixed fields packed with one
``struct`` each way) and :class:`FieldCodec`; the node of each single field kind, and
``FieldDecodeError``, live in :mod:`testbed.common.field_layouts`. A new field type is a node
there, a branch of :func:`_compile` and a row of the table.
"""

from __future__ import annotations

import dataclasses
import enum
import operator
import struct
import typing
from collections.abc import Callable, Sequence
from typing import Any

from testbed.common.field_layouts import (
    BoolLayout,
    Buffer,
    BytesLayout,
    FieldDecodeError,
    IntEnumLayout,
    LayoutNode,
    PlainLayout,
    StrEnumLayout,
    StrLayout,
    VarTupleLayout,
)

__all__ = ["FieldCodec", "compile_codec"]

_I64_MIN = -(2**63)
_I64_MAX = 2**63 - 1


# ------------------------------------------------------------------------ composite layouts


class _Composite(LayoutNode):
    """A fixed tuple or a dataclass: its children in order.

    Attributes:
        children: the item (or field) layouts, in order.
        parts: the value → its child values (a tuple), checking the shape.
        make: child values → the value.
        flat_ops, build_ops: how each child is flattened and built (:func:`_flat_op`,
            :func:`_build_op`), compiled once.
        segments: for a variable composite, runs of fixed children (one struct each) and
            single variable ones.
    """

    __slots__ = ("build_ops", "children", "flat_ops", "make", "parts", "segments")

    def __init__(
        self,
        children: Sequence[LayoutNode],
        parts: Callable[[Any], Sequence[Any]],
        make: Callable[..., Any],
    ) -> None:
        fixed = all(child.fixed for child in children)
        super().__init__("".join(c.pack_fmt for c in children) if fixed else None)
        if fixed:
            self.unpack_fmt = "".join(c.unpack_fmt for c in children)
            self.width = sum(c.width for c in children)
        self.children = tuple(children)
        self.parts = parts
        self.make = make
        self.flat_ops = tuple(_flat_op(c) if c.fixed else (_CALL, 0, c.flatten) for c in children)
        self.build_ops = tuple(_build_op(c) if c.fixed else (_CALL, 0, c.build) for c in children)
        self.segments = _segments(self)

    def flatten(self, value: Any, out: list[Any]) -> None:
        _flatten_parts(self.flat_ops, self.parts(value), out)

    def build(self, values: Sequence[Any], i: int) -> Any:
        args: list[Any] = []
        _build_parts(self.build_ops, values, i, args)
        return self.make(*args)

    def write(self, value: Any, out: bytearray) -> None:
        if self.fixed:
            LayoutNode.write(self, value, out)
            return
        parts = self.parts(value)
        for start, stop, run in self.segments:
            if run is None:
                self.children[start].write(parts[start], out)
            else:
                flat: list[Any] = []
                _flatten_parts(run.flat_ops, parts[start:stop], flat)
                out += run.pack(*flat)

    def read(self, buf: Buffer, pos: int) -> tuple[Any, int]:
        if self.fixed:
            return LayoutNode.read(self, buf, pos)
        args: list[Any] = []
        for start, _, run in self.segments:
            if run is None:
                value, pos = self.children[start].read(buf, pos)
                args.append(value)
            else:
                values = run.unpack_from(buf, pos)
                pos += run.size
                _build_parts(run.build_ops, values, 0, args)
        return self.make(*args), pos


_APPEND, _SPREAD, _CALL = 0, 1, 2
"""How a composite flattens (or builds) one fixed child: the value is its own primitive, the
value is a tuple of plain items spread into (sliced from) the flat form, or the child's own
``flatten``/``build`` is called."""

_FlatOp = tuple[int, int, Callable[[Any, list[Any]], None]]
_BuildOp = tuple[int, int, Callable[[Sequence[Any], int], Any]]


def _flat_op(child: LayoutNode) -> _FlatOp:
    if child.plain_out:
        return (_APPEND, 1, child.flatten)
    if _plain_tuple(child, "plain_out"):
        return (_SPREAD, child.width, child.flatten)
    return (_CALL, child.width, child.flatten)


def _build_op(child: LayoutNode) -> _BuildOp:
    if child.plain_in:
        return (_APPEND, 1, child.build)
    if _plain_tuple(child, "plain_in"):
        return (_SPREAD, child.width, child.build)
    return (_CALL, child.width, child.build)


def _plain_tuple(child: LayoutNode, plain: str) -> bool:
    """Whether ``child`` is a fixed tuple whose items are all plain (``plain_out``/``plain_in``)."""
    return (
        isinstance(child, _Composite)
        and child.fixed
        and child.make is _make_tuple
        and all(getattr(c, plain) for c in child.children)
    )


def _flatten_parts(ops: Sequence[_FlatOp], parts: Sequence[Any], out: list[Any]) -> None:
    """Append the flat primitives of ``parts`` (one per op) to ``out``: one loop, no call per
    plain scalar or plain tuple."""
    for (kind, width, flatten), part in zip(ops, parts, strict=True):
        if kind == _APPEND:
            out.append(part)
        elif kind == _SPREAD:
            if type(part) is not tuple or len(part) != width:
                raise TypeError(f"expected a tuple of {width} items, got {part!r}")
            out += part
        else:
            flatten(part, out)


def _build_parts(ops: Sequence[_BuildOp], values: Sequence[Any], i: int, args: list[Any]) -> None:
    """Append the values built from ``values[i:]`` (one per op) to ``args``."""
    for kind, width, build in ops:
        if kind == _APPEND:
            args.append(values[i])
        elif kind == _SPREAD:
            args.append(values[i : i + width])
        else:
            args.append(build(values, i))
        i += width


class _Run:
    """A run of consecutive fixed children of a variable composite: one struct each way."""

    __slots__ = ("build_ops", "flat_ops", "pack", "size", "unpack_from")

    def __init__(self, composite: _Composite, start: int, stop: int) -> None:
        run = composite.children[start:stop]
        self.pack = struct.Struct(">" + "".join(c.pack_fmt for c in run)).pack
        unpack = struct.Struct(">" + "".join(c.unpack_fmt for c in run))
        self.unpack_from = unpack.unpack_from
        self.size = unpack.size
        self.flat_ops = composite.flat_ops[start:stop]
        self.build_ops = composite.build_ops[start:stop]


_Segment = tuple[int, int, _Run | None]


def _segments(composite: _Composite) -> tuple[_Segment, ...]:
    """Runs of consecutive fixed children (one pack/unpack struct each) and single variable ones."""
    children = composite.children
    if composite.fixed:
        return ()
    segments: list[_Segment] = []
    i = 0
    while i < len(children):
        if not children[i].fixed:
            segments.append((i, i + 1, None))
            i += 1
            continue
        stop = i
        while stop < len(children) and children[stop].fixed:
            stop += 1
        segments.append((i, stop, _Run(composite, i, stop)))
        i = stop
    return tuple(segments)


# ----------------------------------------------------------------------------- compilation


_INT = PlainLayout("q")
_FLOAT = PlainLayout("d")
_BOOL = BoolLayout()
_STR = StrLayout()
_BYTES = BytesLayout()


def _compile(annotation: Any, where: str) -> LayoutNode:
    """The layout of one (registry-checked) field type."""
    if annotation is bool:
        return _BOOL
    if annotation is int:
        return _INT
    if annotation is float:
        return _FLOAT
    if annotation is str:
        return _STR
    if annotation is bytes:
        return _BYTES
    if isinstance(annotation, type) and issubclass(annotation, enum.Enum):
        return _compile_enum(annotation, where)
    if isinstance(annotation, type) and dataclasses.is_dataclass(annotation):
        hints = typing.get_type_hints(annotation)
        fields = dataclasses.fields(annotation)
        children = [_compile(hints[f.name], f"{where}.{f.name}") for f in fields]
        return _Composite(children, _field_getter(annotation, [f.name for f in fields]), annotation)
    if typing.get_origin(annotation) is tuple:
        args = typing.get_args(annotation)
        if len(args) == 2 and args[1] is Ellipsis:
            return VarTupleLayout(_compile(args[0], f"{where}[]"))
        children = [_compile(arg, f"{where}[{k}]") for k, arg in enumerate(args)]
        return _Composite(children, _tuple_checker(len(children)), _make_tuple)
    raise TypeError(f"{where}: no codec for field type {annotation!r}")


def _compile_enum(cls: type[enum.Enum], where: str) -> LayoutNode:
    values = [member.value for member in cls]
    if all(isinstance(v, int) for v in values):
        if not all(_I64_MIN <= v <= _I64_MAX for v in values):
            raise TypeError(f"{where}: enum {cls.__qualname__} has values outside i64")
        return IntEnumLayout(cls)
    if all(isinstance(v, str) for v in values):
        return StrEnumLayout(cls)
    raise TypeError(
        f"{where}: enum {cls.__qualname__} must have all-int or all-str values to be replicated"
    )


def _field_getter(cls: type[Any], names: list[str]) -> Callable[[Any], Sequence[Any]]:
    """value → its field values as a tuple, rejecting a value of another type."""
    if not names:
        get: Callable[[Any], Any] = _no_fields
    elif len(names) == 1:
        name = names[0]

        def get(value: Any) -> tuple[Any]:
            return (getattr(value, name),)

    else:
        get = operator.attrgetter(*names)

    def parts(value: Any) -> Sequence[Any]:
        if type(value) is not cls:
            raise TypeError(f"expected a {cls.__qualname__}, got {value!r}")
        return get(value)  # type: ignore[no-any-return]  # attrgetter of several names: tuple

    return parts


def _no_fields(value: Any) -> tuple[()]:
    return ()


def _tuple_checker(length: int) -> Callable[[Any], Sequence[Any]]:
    def parts(value: Any) -> Sequence[Any]:
        if not isinstance(value, tuple) or len(value) != length:
            raise TypeError(f"expected a tuple of {length} items, got {value!r}")
        return value

    return parts


def _make_tuple(*items: Any) -> tuple[Any, ...]:
    return items


_ENCODE_ERRORS = (struct.error, TypeError, ValueError, AttributeError, OverflowError)
_DECODE_ERRORS = (struct.error, TypeError, ValueError, IndexError, OverflowError)


class FieldCodec:
    """The compiled codec of one component type.

    Attributes:
        cls: the component type.
        fixed_size: the size of every encoded value [B], or None for a variable layout.
    """

    __slots__ = (
        "_build_ops",
        "_flat_ops",
        "_pack",
        "_parts",
        "_root",
        "_unpack",
        "_variable",
        "cls",
        "fixed_size",
        "float_widths",
    )

    def __init__(self, cls: type[Any], fields: Sequence[tuple[str, Any]] | None = None) -> None:
        """Compile the layout of ``cls`` (see :func:`compile_codec`)."""
        if fields is None:
            root = _compile(cls, cls.__qualname__)
        else:
            children = [_compile(kind, f"{cls.__qualname__}.{name}") for name, kind in fields]
            names = [name for name, _ in fields]
            root = _Composite(children, _field_getter(cls, names), cls)
        assert isinstance(root, _Composite)
        self.cls = cls
        self._root = root
        self.fixed_size: int | None = root.size if root.fixed else None
        self._pack = struct.Struct(">" + root.pack_fmt).pack
        self._unpack = struct.Struct(">" + root.unpack_fmt).unpack
        # The common layouts get their own straight-line paths, chosen here once: plain (only
        # int/float fields out, only int/float in: one struct call and the constructor), fixed
        # (one struct call, the children flattened/built by their compiled ops) or variable.
        self._parts = root.parts
        self._flat_ops: tuple[_FlatOp, ...] | None = root.flat_ops
        self._build_ops: tuple[_BuildOp, ...] | None = root.build_ops
        self._variable = not root.fixed
        if root.fixed and all(c.plain_out for c in root.children):
            self._flat_ops = None
        if root.fixed and all(c.plain_in for c in root.children):
            self._build_ops = None
        self.float_widths: tuple[int, ...] | None = (
            tuple(c.width for c in root.children)
            if root.fixed and root.pack_fmt and set(root.pack_fmt) == {"d"}
            else None
        )
        """The fields' flat widths, in order, when every field encodes as doubles only (floats,
        fixed tuples of floats): then :meth:`encode_floats` encodes a value from its floats."""

    def encode(self, value: Any) -> bytes:
        """The bytes of ``value`` (an instance of :attr:`cls`).

        Raises:
            ValueError: ``value`` is not a valid instance (wrong type, int outside i64, string
                or tuple longer than a u16 count, lone surrogate in a string…), naming the type.
        """
        try:
            if self._variable:
                out = bytearray()
                self._root.write(value, out)
                return bytes(out)
            ops = self._flat_ops
            if ops is None:
                return self._pack(*self._parts(value))
            flat: list[Any] = []
            _flatten_parts(ops, self._parts(value), flat)
            return self._pack(*flat)
        except _ENCODE_ERRORS as err:
            raise ValueError(f"cannot encode {self.cls.__qualname__}: {err}") from err

    def encode_floats(self, floats: Sequence[float]) -> bytes:
        """The bytes of the value whose flat form is ``floats`` (its fields' floats in order),
        for a type with :attr:`float_widths`: what :meth:`encode` packs after flattening.

        Raises:
            ValueError: not as many floats as the layout has, or one that is not a number.
        """
        try:
            return self._pack(*floats)
        except _ENCODE_ERRORS as err:
            raise ValueError(f"cannot encode {self.cls.__qualname__}: {err}") from err

    def decode(self, data: Buffer) -> Any:
        """The value encoded in exactly ``data``.

        Raises:
            FieldDecodeError: ``data`` is not exactly one valid encoding (truncated, trailing
                bytes, bad count, bad UTF-8, bad bool byte, enum value naming no member, or a
                value the component's constructor rejects).
        """
        try:
            if self._variable:
                return self._decode_variable(data)
            ops = self._build_ops
            if ops is None:
                return self.cls(*self._unpack(data))
            args: list[Any] = []
            _build_parts(ops, self._unpack(data), 0, args)
            return self.cls(*args)
        except FieldDecodeError:
            raise
        except _DECODE_ERRORS as err:
            raise FieldDecodeError(f"{self.cls.__qualname__}: {err}") from None

    def _decode_variable(self, data: Buffer) -> Any:
        value, end = self._root.read(data, 0)
        if end != len(data):
            raise FieldDecodeError(
                f"{self.cls.__qualname__}: {len(data) - end} trailing bytes after the value"
            )
        return value


def compile_codec(cls: type[Any], fields: Sequence[tuple[str, Any]] | None = None) -> FieldCodec:
    """Compile the field codec of a component type once; reuse it for every value.

    Args:
        cls: a frozen dataclass whose field types the component registry accepts.
        fields: its ``(name, resolved type)`` pairs in declaration order, as in
            :attr:`~testbed.ecs.Registration.fields`; resolved from ``cls`` if omitted.

    Raises:
        TypeError: a field type has no codec (an enum with values neither all int nor all str
            or outside i64, or a type the registry would not have accepted).
    """
    return FieldCodec(cls, fields)
