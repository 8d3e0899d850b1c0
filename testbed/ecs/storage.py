"""Component storage for the world: one column per component type, and the query scans.

A column maps entities to slots (the stored component plus its added tick, changed tick and
origin), caches its ``(entity, slot)`` pairs in ascending entity order, and remembers the newest
added and changed ticks so a change-filtered scan of a quiet column returns at once. The scans
here yield in ascending entity order; :class:`~testbed.ecs.world.World` is the only user.
Internal: nothing here is public API.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from testbed.ecs.component import Entity, Origin

__all__ = ["GONE", "Column", "Slot", "iter_all", "iter_filtered", "scan_one"]

GONE: Any = object()
"""Value of a slot whose component was removed (seen only by iterations already under way)."""


class Slot:
    """One stored component and its bookkeeping (mutable; never handed out)."""

    __slots__ = ("added", "changed", "origin", "value")

    def __init__(self, value: object, tick: int, origin: Origin) -> None:
        self.value = value
        self.added = tick
        self.changed = tick
        self.origin = origin


class Column:
    """All components of one type, keyed by entity.

    Keeps a cached ascending ``(entity, slot)`` list (rebuilt after an insertion or deletion,
    never mutated once built, so iterations under way are unaffected) and the newest added and
    changed ticks in the column, so a change-filtered query on a quiet column costs nothing.
    """

    __slots__ = ("_pairs", "added_max", "changed_max", "slots")

    def __init__(self) -> None:
        self.slots: dict[Entity, Slot] = {}
        self._pairs: list[tuple[Entity, Slot]] | None = []
        self.added_max = 0
        self.changed_max = 0

    def pairs(self) -> list[tuple[Entity, Slot]]:
        """``(entity, slot)`` ascending by entity."""
        pairs = self._pairs
        if pairs is None:
            pairs = self._pairs = sorted(self.slots.items(), key=_pair_entity)
        return pairs

    def insert(self, entity: Entity, slot: Slot) -> None:
        self.slots[entity] = slot
        self._pairs = None
        self.added_max = self.changed_max = slot.added

    def delete(self, entity: Entity) -> None:
        self.slots.pop(entity).value = GONE
        self._pairs = None


def _pair_entity(pair: tuple[Entity, Slot]) -> Entity:
    return pair[0]


def scan_one(
    column: Column, changed: bool, added: bool, since: int, origin: Origin | None, packed: bool
) -> Iterator[Any]:
    """One column's ``(entity, (value,))`` (packed) or ``(entity, value)``, filtered."""
    if changed:
        if column.changed_max <= since:
            return
    elif added and column.added_max <= since:
        return
    filtering = changed or added
    if not filtering and origin is None:
        for entity, slot in column.pairs():
            value = slot.value
            if value is not GONE:
                yield (entity, (value,)) if packed else (entity, value)
        return
    for entity, slot in column.pairs():
        value = slot.value
        if value is GONE:
            continue
        if origin is not None and slot.origin is not origin:
            continue
        if filtering and not ((changed and slot.changed > since) or (added and slot.added > since)):
            continue
        yield (entity, (value,)) if packed else (entity, value)


def _smallest(columns: list[Column]) -> Column:
    driver = columns[0]
    for column in columns:
        if len(column.slots) < len(driver.slots):
            driver = column
    return driver


def iter_all(columns: list[Column]) -> Iterator[tuple[Entity, tuple[Any, ...]]]:
    driver = _smallest(columns)
    if len(columns) == 2:
        first = driver is columns[0]
        other = columns[1].slots if first else columns[0].slots
        for entity, slot in driver.pairs():
            found = other.get(entity)
            if found is None or slot.value is GONE:
                continue
            yield entity, ((slot.value, found.value) if first else (found.value, slot.value))
        return
    all_slots = [c.slots for c in columns]
    for entity, slot in driver.pairs():
        if slot.value is GONE:
            continue
        values = []
        for slots in all_slots:
            found = slots.get(entity)
            if found is None:
                break
            values.append(found.value)
        else:
            yield entity, tuple(values)


def iter_filtered(
    columns: list[Column], changed: bool, added: bool, since: int, origin: Origin | None
) -> Iterator[tuple[Entity, tuple[Any, ...]]]:
    if changed or added:
        for column in columns:  # skip the scan when no queried column has anything newer
            if column.changed_max > since if changed else column.added_max > since:
                break
        else:
            return
    driver = _smallest(columns)
    all_slots = [c.slots for c in columns]
    only_origin = not (changed or added)
    for entity, driver_slot in driver.pairs():
        if driver_slot.value is GONE:
            continue
        values = []
        keep = False
        for slots in all_slots:
            slot = slots.get(entity)
            if slot is None:
                break
            values.append(slot.value)
            if keep or (origin is not None and slot.origin is not origin):
                continue
            keep = (
                only_origin or (changed and slot.changed > since) or (added and slot.added > since)
            )
        else:
            if keep:
                yield entity, tuple(values)
