"""Store-backed columns: a component type's values kept in float64 tables that a compiled frame
can read and write, seen through the world's API as frozen components with change ticks.

A :class:`FrameStore` holds one :class:`Table` per registered component type: ``values``, a
``(capacity, width)`` float64 array with one row per entity holding the component's fields
(:class:`Layout`), ``marks``, a ``(capacity, 2)`` int64 array with the world tick at which
each row last changed (0: a free row; the column is also the view ``ticks``) and the row's
write count, and ``origins``, ``(capacity,)`` int8 (0 LOCAL, 1 REMOTE).
:meth:`~testbed.ecs.world.World.use_store` makes the world keep those types in the tables.
Everything the world offers works the same for them: ``set`` records a change only for a value
that differs, ``get`` returns the object that was set (or, after a write into the table, a new
one built from the row), queries filter on the rows' ticks and origins, removals are logged.

A compiled frame writes a row's fields and then its mark: the change tick (the world's tick
while its system runs: each system runs at a tick of its own) and one more write in the row's
write count; it leaves a row whose value is unchanged alone, so that readers are not woken,
and leaves the origin as it is (the vehicle's rows are its own: LOCAL). The write count, not
the tick, tells a slot that the object it keeps is stale, so a kernel may write a row at the
tick a Python ``set`` wrote it at (between frames, the next frame's first system runs at the
tick of the writes made before it). Stage 1 of the plan in ``docs/performance.md``; the vehicle
keeps its frame's components here (stages 2 and 3).

Fields a table holds: ``float``, ``int`` (exact within ±2⁵³), ``bool``, enums (their index in
the enum) and tuples of floats of the length the prototype has, all in the row; and ``str``
(a label, such as the source of a force intent), kept beside the row in ``Table.texts``: a
compiled frame cannot change it, and a row it writes keeps its labels. Other field types are
refused.
"""

from __future__ import annotations

import dataclasses
import enum
from collections.abc import Iterator
from typing import TYPE_CHECKING, Any

import numpy as np

from testbed.ecs.component import Origin
from testbed.ecs.storage import GONE, Column, Slot

if TYPE_CHECKING:
    from testbed.ecs.component import Entity

__all__ = ["FrameStore", "Layout", "RowView", "StoreColumn", "Table"]

_FLOAT, _INT, _BOOL, _ENUM, _TUPLE, _TEXT = range(6)
_EXACT_INT = 2**53


class Layout:
    """Where each field of one component type sits in a row of floats, taken from a
    prototype instance (its tuples' lengths included).

    Raises:
        TypeError: a field of a kind a table cannot hold, or one not set by ``__init__``.
    """

    __slots__ = ("cls", "fields", "float_widths", "n_texts", "width")

    def __init__(self, prototype: object) -> None:
        cls = type(prototype)
        self.cls = cls
        fields: list[tuple[str, int, int, Any]] = []  # (name, kind, offset, size or members)
        offset = 0
        n_texts = 0
        for spec in dataclasses.fields(cls):  # type: ignore[arg-type]
            name = f"{cls.__qualname__}.{spec.name}"
            if not spec.init:
                raise TypeError(f"{name}: a stored field must be set by __init__")
            value = getattr(prototype, spec.name)
            if isinstance(value, bool):
                fields.append((spec.name, _BOOL, offset, 1))
            elif isinstance(value, enum.Enum):
                fields.append((spec.name, _ENUM, offset, tuple(type(value))))
            elif isinstance(value, int):
                fields.append((spec.name, _INT, offset, 1))
            elif isinstance(value, float):
                fields.append((spec.name, _FLOAT, offset, 1))
            elif isinstance(value, tuple) and all(type(v) is float for v in value):
                fields.append((spec.name, _TUPLE, offset, len(value)))
                offset += len(value) - 1
            elif isinstance(value, str):
                fields.append((spec.name, _TEXT, n_texts, 0))
                n_texts += 1
                continue
            else:
                raise TypeError(
                    f"{name}: a table holds floats, ints, bools, enums, tuples of floats and str, "
                    f"got {type(value).__name__}"
                )
            offset += 1
        self.fields = tuple(fields)
        self.width = offset
        self.n_texts = n_texts
        self.float_widths: tuple[int, ...] | None = (
            tuple(1 if kind == _FLOAT else extra for _, kind, _, extra in fields)
            if all(kind in (_FLOAT, _TUPLE) for _, kind, _, _ in fields)
            else None
        )
        """The fields' widths in the row, in order, when every field is a float or a tuple of
        floats (the row is then the value's floats, field by field); None otherwise."""

    def write(self, row: np.ndarray, value: object) -> tuple[str, ...]:
        """Put ``value``'s fields into ``row`` (a ``(width,)`` view); return its ``str`` fields
        in field order (kept beside the row).

        Raises:
            ValueError: a tuple of another length than the layout's, an int beyond ±2⁵³.
            TypeError: a ``str`` field holding something else.
        """
        texts: list[str] = []
        flat: list[object] = []  # the row's values in order: the fields tile the row
        for name, kind, _, extra in self.fields:
            field = getattr(value, name)
            if kind == _FLOAT:
                flat.append(field)
            elif kind == _TUPLE:
                if len(field) != extra:
                    raise ValueError(
                        f"{self.cls.__qualname__}.{name}: {extra} values, got {len(field)}"
                    )
                flat.extend(field)
            elif kind == _TEXT:
                if type(field) is not str:
                    raise TypeError(f"{self.cls.__qualname__}.{name}: a str, got {field!r}")
                texts.append(field)
            elif kind == _ENUM:
                flat.append(extra.index(field))
            else:
                if kind == _INT and not -_EXACT_INT <= field <= _EXACT_INT:
                    raise ValueError(f"{self.cls.__qualname__}.{name}: beyond ±2**53: {field}")
                flat.append(field)
        row[:] = flat
        return tuple(texts)

    def read(self, row: np.ndarray, texts: tuple[str, ...] = ()) -> object:
        """A new component built from ``row`` and its ``str`` fields ``texts``."""
        xs = row.tolist()
        args: list[object] = []
        for _, kind, offset, extra in self.fields:
            if kind == _FLOAT:
                args.append(xs[offset])
            elif kind == _TUPLE:
                args.append(tuple(xs[offset : offset + extra]))
            elif kind == _ENUM:
                args.append(extra[int(xs[offset])])
            elif kind == _INT:
                args.append(int(xs[offset]))
            elif kind == _TEXT:
                args.append(texts[offset])
            else:
                args.append(xs[offset] != 0.0)
        return self.cls(*args)


class Table:
    """One component type's rows: ``values`` (capacity, width) float64; ``marks`` (capacity, 2)
    int64, each row's change tick (0 for a free row; also the view ``ticks``) and write count
    (one more at every write, from Python or from a kernel: what tells a cached object from a
    stale one); ``origins`` (capacity,) int8 (0 LOCAL, 1 REMOTE); and ``texts``, each row's
    ``str`` fields."""

    __slots__ = ("_free", "capacity", "layout", "marks", "origins", "texts", "ticks", "values")

    def __init__(self, layout: Layout, capacity: int) -> None:
        if capacity < 1:
            raise ValueError(f"capacity must be ≥ 1, got {capacity}")
        self.layout = layout
        self.capacity = capacity
        self.values = np.zeros((capacity, layout.width))
        self.marks = np.zeros((capacity, 2), dtype=np.int64)
        self.ticks = self.marks[:, 0]
        self.origins = np.zeros(capacity, dtype=np.int8)
        self.texts: list[tuple[str, ...]] = [()] * capacity
        self._free = list(range(capacity - 1, -1, -1))  # the lowest row first

    def allocate(self) -> int:
        """A free row.

        Raises:
            RuntimeError: every row is in use.
        """
        if not self._free:
            raise RuntimeError(
                f"the {self.layout.cls.__qualname__} table is full ({self.capacity} rows)"
            )
        return self._free.pop()

    def write(self, row: int, value: object) -> int:
        """Put ``value`` into ``row`` (its fields; not its tick) and count the write.

        Returns:
            The row's write count after it.
        """
        self.texts[row] = self.layout.write(self.values[row], value)
        marks = self.marks
        count = int(marks[row, 1]) + 1
        marks[row, 1] = count
        return count

    def read(self, row: int) -> object:
        """A new component built from ``row``."""
        return self.layout.read(self.values[row], self.texts[row])

    def release(self, row: int) -> None:
        """Free ``row`` (its tick goes back to 0; its write count carries on)."""
        self.marks[row, 0] = 0
        self._free.append(row)


class RowView:
    """One entity's row of a table, as a compiled frame writes it: ``values``, the row's
    ``(width,)`` view, and ``mark``, a ``(2,)`` view of its change tick and write count (write
    the fields, then, only when a field changed, the tick and one more write; see the module
    docstring)."""

    __slots__ = ("mark", "values")

    def __init__(self, table: Table, row: int) -> None:
        self.values = table.values[row]
        self.mark = table.marks[row]

    @classmethod
    def detached(cls, width: int) -> RowView:
        """A row of ``width`` floats of its own, in no table (a scratch row)."""
        view = cls.__new__(cls)
        view.values = np.zeros(width)
        view.mark = np.zeros(2, dtype=np.int64)
        return view


class FrameStore:
    """The tables of the component types a world keeps store-backed."""

    __slots__ = ("_tables",)

    def __init__(self) -> None:
        self._tables: dict[type[Any], Table] = {}

    def add(self, prototype: object, capacity: int = 8) -> Table:
        """A table for ``type(prototype)`` with ``capacity`` rows (one per entity).

        Raises:
            ValueError: the type already has a table, or ``capacity`` < 1.
            TypeError: a field a table cannot hold (:class:`Layout`).
        """
        cls = type(prototype)
        if cls in self._tables:
            raise ValueError(f"{cls.__qualname__} already has a table")
        table = self._tables[cls] = Table(Layout(prototype), capacity)
        return table

    def table(self, cls: type[Any]) -> Table:
        """The table of ``cls`` (KeyError if it has none)."""
        return self._tables[cls]

    def tables(self) -> Iterator[tuple[type[Any], Table]]:
        """Every ``(type, table)``, in the order they were added."""
        return iter(self._tables.items())


_ORIGINS = (Origin.LOCAL, Origin.REMOTE)
"""The origins by their codes in ``Table.origins``: 0 LOCAL, 1 REMOTE."""


class StoreSlot(Slot):
    """A slot whose value, change tick and origin live in a table row (see the module
    docstring); ``added`` stays an attribute. The value last set from Python, or last built from
    the row, is kept and returned while the row's write count is the one it was kept at."""

    __slots__ = ("_cached", "_count", "_row", "_table")
    _cached: object
    _count: int

    def __init__(self, table: Table, row: int, slot: Slot) -> None:
        self._table = table
        self._row = row
        self.added = slot.added
        self.origin = slot.origin
        self.value = slot.value
        self.changed = slot.changed

    @property
    def value(self) -> object:
        cached = self._cached
        if cached is GONE:
            return GONE
        table, row = self._table, self._row
        count = table.marks.item(row, 1)  # a Python int (half the cost of indexing)
        if count == self._count:
            return cached
        cached = self._cached = table.read(row)
        self._count = count
        return cached

    @value.setter
    def value(self, component: object) -> None:
        if component is GONE:
            self._table.release(self._row)
        else:
            self._count = self._table.write(self._row, component)
        self._cached = component

    @property
    def changed(self) -> int:
        return self._table.marks.item(self._row, 0)

    @changed.setter
    def changed(self, tick: int) -> None:
        self._table.marks[self._row, 0] = tick

    @property
    def origin(self) -> Origin:
        return _ORIGINS[self._table.origins.item(self._row)]

    @origin.setter
    def origin(self, origin: Origin) -> None:
        self._table.origins[self._row] = origin is not Origin.LOCAL  # 0 LOCAL, 1 REMOTE


class StoreColumn(Column):
    """A column whose slots are rows of ``table``; its newest change tick is the table's."""

    __slots__ = ("table",)

    def __init__(self, table: Table) -> None:
        super().__init__()
        self.table = table

    def insert(self, entity: Entity, slot: Slot) -> None:
        super().insert(entity, StoreSlot(self.table, self.table.allocate(), slot))

    def row_view(self, entity: Entity) -> RowView:
        """``entity``'s row (KeyError if it has none)."""
        slot = self.slots[entity]
        assert isinstance(slot, StoreSlot)
        return RowView(self.table, slot._row)

    @property
    def changed_max(self) -> int:
        ticks = self.table.ticks
        return int(ticks[0]) if ticks.size == 1 else max(ticks.tolist())  # faster than .max()

    @changed_max.setter
    def changed_max(self, tick: int) -> None:
        pass  # the rows' ticks are the record
