"""The ECS world: entities, frozen components with change ticks, resources, removal log.

A :class:`World` holds entities (plain integers allocated in order from 1, never reused), their
components (frozen dataclass instances, one per type per entity) and resources (singletons of
any type: a physics handle, an allocator, an RNG). Change detection follows Bevy: every stored
component carries the world tick at which it was added and last changed, and the
:class:`~testbed.ecs.component.Origin` of that write. :meth:`World.set` records a change only
when the new value differs (``!=``) from the stored one, so systems may write every frame
without waking their readers.

Ticks are plain integers that only grow. The world never advances its own tick; the
:class:`~testbed.ecs.schedule.Schedule` advances it once after every system it runs (see that
module for the exact visibility rules). A query "changed" means "changed at a tick newer than
``since``", where ``since`` defaults to :attr:`World.last_run_tick`, the running system's
previous run tick.

The removal log grows with every removal; a node that removes components often should call
:meth:`World.trim_removals` with the oldest tick any reader still needs.

This module is the world's API. The value types it stores and records (entity ids, origins,
removal log entries, the component-type check) live in :mod:`testbed.ecs.component`; the
resources in :mod:`testbed.ecs.resources` (the world's base class); column storage and query
scans in :mod:`testbed.ecs.storage`; store-backed columns (float64 tables, numpy) in
:mod:`testbed.ecs.store`. No scheduling, no replication wire format, no I/O, no
randomness; otherwise the standard library only.
"""

from __future__ import annotations

import bisect
from collections.abc import Iterator
from typing import Any, TypeVar, overload

from testbed.ecs.component import Entity, Origin, Removal, Replicate, check_component_type
from testbed.ecs.resources import Resources
from testbed.ecs.storage import Column, Slot, iter_all, iter_filtered, scan_one
from testbed.ecs.store import FrameStore, RowView, StoreColumn

__all__ = ["World"]

C = TypeVar("C")
C1 = TypeVar("C1")
C2 = TypeVar("C2")
C3 = TypeVar("C3")
C4 = TypeVar("C4")
D = TypeVar("D")


class World(Resources):
    """Entities, components with change ticks, resources and a removal log.

    The resource methods (``insert_resource``, ``resource``, ``has_resource``,
    ``remove_resource``) come from its base class, :class:`~testbed.ecs.resources.Resources`.

    Attributes:
        last_run_tick: the default ``since`` of change-filtered queries. The schedule sets it to
            the running system's previous run tick (0 before its first run) and restores it
            afterwards; outside a schedule it is 0 unless the caller sets it.
    """

    __slots__ = (
        "_columns",
        "_entities",
        "_next_id",
        "_removals",
        "_tick",
        "last_run_tick",
    )

    def __init__(self) -> None:
        super().__init__()
        self._tick = 1
        self._next_id = 1
        # Alive entities (ascending by construction) → their component types in insertion order.
        self._entities: dict[Entity, dict[type[Any], None]] = {}
        self._columns: dict[type[Any], Column] = {}
        self._removals: list[Removal] = []
        self.last_run_tick: int = 0

    # ---------------------------------------------------------------- ticks

    @property
    def tick(self) -> int:
        """The current world tick (starts at 1); every write is stamped with it."""
        return self._tick

    def advance(self) -> int:
        """Increment the world tick and return the new value."""
        self._tick += 1
        return self._tick

    # ------------------------------------------------------------- entities

    def spawn(self, *components: object, origin: Origin = Origin.LOCAL) -> Entity:
        """Create an entity with the given components (all recorded as added now).

        Args:
            *components: frozen dataclass instances, at most one per type.
            origin: who made the spawn.

        Returns:
            The new entity id (the previous one plus one).

        Raises:
            TypeError: a component is not a frozen dataclass instance.
            ValueError: two components of the same type.
        """
        types = [type(c) for c in components]
        for cls in types:
            check_component_type(cls)
        if len(set(types)) != len(types):
            raise ValueError(f"spawn got two components of one type: {[t.__name__ for t in types]}")
        entity = Entity(self._next_id)
        self._next_id += 1
        self._entities[entity] = {}
        for component in components:
            self.set(entity, component, origin=origin)
        return entity

    def despawn(self, entity: Entity, *, origin: Origin = Origin.LOCAL) -> None:
        """Remove an entity and all its components.

        Logs one :class:`Removal` per component (in the order they were added), then one for the
        entity itself (``component=None``).

        Raises:
            LookupError: the entity is not alive.
        """
        types = self._alive_types(entity)
        replicated = Replicate in types
        tick = self._tick
        for cls in list(types):
            self._columns[cls].delete(entity)
            self._removals.append(Removal(tick, entity, cls, origin, replicated))
        del self._entities[entity]
        self._removals.append(Removal(tick, entity, None, origin, replicated))

    def is_alive(self, entity: Entity) -> bool:
        """Whether ``entity`` has been spawned and not despawned."""
        return entity in self._entities

    def entities(self) -> list[Entity]:
        """All alive entities, ascending."""
        return list(self._entities)

    def components(self, entity: Entity) -> tuple[object, ...]:
        """All components of an alive entity, in the order their types were first added.

        Raises:
            LookupError: the entity is not alive.
        """
        return tuple(self._columns[cls].slots[entity].value for cls in self._alive_types(entity))

    # ----------------------------------------------------------- components

    def set(self, entity: Entity, component: object, *, origin: Origin = Origin.LOCAL) -> bool:
        """Store ``component`` under its type on ``entity`` if it differs from the stored one.

        A new type on the entity records both the added and the changed tick; a value that
        differs (``!=``) from the stored one records the changed tick and origin; an equal value
        records nothing (and keeps the stored object).

        Args:
            entity: an alive entity.
            component: a frozen dataclass instance (stored as is, never copied).
            origin: who made the write.

        Returns:
            Whether a change was recorded.

        Raises:
            TypeError: ``component`` is not a frozen dataclass instance.
            LookupError: the entity is not alive.
        """
        cls = type(component)
        column = self._columns.get(cls) or self._new_column(cls)
        slot = column.slots.get(entity)
        if slot is not None:
            old = slot.value
            if old is component or old == component:  # dataclass != is `not ==`
                return False
            slot.value = component
            slot.changed = column.changed_max = self._tick
            slot.origin = origin
            return True
        types = self._alive_types(entity)
        types[cls] = None
        column.insert(entity, Slot(component, self._tick, origin))
        return True

    def get(self, entity: Entity, cls: type[C]) -> C | None:
        """The component of type ``cls`` on ``entity``, or None (also for a dead entity)."""
        column = self._columns.get(cls)
        if column is None:
            return None
        slot = column.slots.get(entity)
        return None if slot is None else slot.value  # type: ignore[return-value]  # column of cls

    def get_or(self, entity: Entity, cls: type[C], default: D) -> C | D:
        """The component of type ``cls`` on ``entity``, or ``default``."""
        value = self.get(entity, cls)
        return default if value is None else value

    def has(self, entity: Entity, cls: type[Any]) -> bool:
        """Whether ``entity`` is alive and has a component of type ``cls``."""
        column = self._columns.get(cls)
        return column is not None and entity in column.slots

    def remove(self, entity: Entity, cls: type[Any], *, origin: Origin = Origin.LOCAL) -> bool:
        """Remove the component of type ``cls`` from ``entity``, logging the removal.

        Returns:
            Whether there was such a component (nothing is logged otherwise).

        Raises:
            LookupError: the entity is not alive.
        """
        types = self._alive_types(entity)
        if cls not in types:
            return False
        replicated = Replicate in types
        del types[cls]
        self._columns[cls].delete(entity)
        self._removals.append(Removal(self._tick, entity, cls, origin, replicated))
        return True

    def changed_tick(self, entity: Entity, cls: type[Any]) -> int:
        """Tick of the last recorded change (or addition) of ``cls`` on ``entity``.

        Raises:
            LookupError: the entity has no such component.
        """
        return self._slot(entity, cls).changed

    def added_tick(self, entity: Entity, cls: type[Any]) -> int:
        """Tick at which ``cls`` was (last) added to ``entity``.

        Raises:
            LookupError: the entity has no such component.
        """
        return self._slot(entity, cls).added

    def origin_of(self, entity: Entity, cls: type[Any]) -> Origin:
        """Origin of the last recorded change (or addition) of ``cls`` on ``entity``.

        Raises:
            LookupError: the entity has no such component.
        """
        return self._slot(entity, cls).origin

    def removals_since(self, tick: int) -> list[Removal]:
        """Removal log entries with a tick newer than ``tick``, oldest first."""
        log = self._removals
        start = bisect.bisect_right(log, tick, key=_removal_tick)
        return log[start:]

    def trim_removals(self, through_tick: int) -> None:
        """Forget removal log entries with a tick ≤ ``through_tick`` (bounds memory)."""
        log = self._removals
        del log[: bisect.bisect_right(log, through_tick, key=_removal_tick)]

    # -------------------------------------------------------------- queries

    @overload
    def query(
        self,
        t1: type[C1],
        /,
        *,
        changed: bool = ...,
        added: bool = ...,
        since: int | None = ...,
        origin: Origin | None = ...,
    ) -> Iterator[tuple[Entity, tuple[C1]]]: ...
    @overload
    def query(
        self,
        t1: type[C1],
        t2: type[C2],
        /,
        *,
        changed: bool = ...,
        added: bool = ...,
        since: int | None = ...,
        origin: Origin | None = ...,
    ) -> Iterator[tuple[Entity, tuple[C1, C2]]]: ...
    @overload
    def query(
        self,
        t1: type[C1],
        t2: type[C2],
        t3: type[C3],
        /,
        *,
        changed: bool = ...,
        added: bool = ...,
        since: int | None = ...,
        origin: Origin | None = ...,
    ) -> Iterator[tuple[Entity, tuple[C1, C2, C3]]]: ...
    @overload
    def query(
        self,
        t1: type[C1],
        t2: type[C2],
        t3: type[C3],
        t4: type[C4],
        /,
        *,
        changed: bool = ...,
        added: bool = ...,
        since: int | None = ...,
        origin: Origin | None = ...,
    ) -> Iterator[tuple[Entity, tuple[C1, C2, C3, C4]]]: ...
    @overload
    def query(
        self,
        *types: type[Any],
        changed: bool = ...,
        added: bool = ...,
        since: int | None = ...,
        origin: Origin | None = ...,
    ) -> Iterator[tuple[Entity, tuple[Any, ...]]]: ...
    def query(
        self,
        *types: type[Any],
        changed: bool = False,
        added: bool = False,
        since: int | None = None,
        origin: Origin | None = None,
    ) -> Iterator[tuple[Entity, tuple[Any, ...]]]:
        """Entities having every one of ``types``, ascending, with those components.

        Filters (all optional):

        - ``changed``: keep an entity if any of the queried components changed (or was added)
          at a tick newer than ``since``;
        - ``added``: keep it if any of them was added at a tick newer than ``since``; with both
          flags an entity passes if any component satisfies either;
        - ``origin``: with ``changed``/``added``, the qualifying change must have that origin;
          alone, any queried component's last write must have it.

        Membership is fixed when iteration starts; a component removed during iteration makes
        its entity skipped, and values are read as each entity is reached.

        Args:
            *types: one or more component types.
            changed: filter to changed components.
            added: filter to added components.
            since: tick the filters compare against (default: :attr:`last_run_tick`).
            origin: filter on the origin of the write.

        Returns:
            An iterator of ``(entity, (component, ...))`` in the order of ``types``.

        Raises:
            TypeError: no types, or a type that is not a frozen dataclass.
            ValueError: ``since`` given without ``changed`` or ``added``.
        """
        tick = self.last_run_tick if since is None else since
        if len(types) == 1:
            column = self._query_column(types[0], changed, added, since)
            return scan_one(column, changed, added, tick, origin, packed=True)
        columns = self._query_columns(types, changed, added, since)
        if not (changed or added or origin is not None):
            return iter_all(columns)
        return iter_filtered(columns, changed, added, tick, origin)

    def query1(
        self,
        cls: type[C],
        *,
        changed: bool = False,
        added: bool = False,
        since: int | None = None,
        origin: Origin | None = None,
    ) -> Iterator[tuple[Entity, C]]:
        """Like :meth:`query` with one type, yielding ``(entity, component)`` unwrapped."""
        if since is None:  # the common case, checked inline (systems poll every frame)
            column = self._columns.get(cls) or self._new_column(cls)
            return scan_one(column, changed, added, self.last_run_tick, origin, packed=False)
        column = self._query_column(cls, changed, added, since)
        return scan_one(column, changed, added, since, origin, packed=False)

    def changed_any(self, *types: type[Any], since: int | None = None) -> bool:
        """Whether a component of these types was added or changed after ``since``.

        The cheap test in front of a system that only reacts to changes (each column keeps its
        newest change tick): false means every ``query1(cls, changed=True)`` of these types
        would yield nothing. A component changed and then removed may still count; removals
        themselves are not changes (see :meth:`removals_since`).

        Args:
            types: component types.
            since: a tick; default :attr:`last_run_tick` (the running system's previous run).
        """
        tick = self.last_run_tick if since is None else since
        columns = self._columns
        for cls in types:
            column = columns.get(cls)
            if column is not None and column.changed_max > tick and column.slots:
                return True
        return False

    def single(self, cls: type[C]) -> tuple[Entity, C]:
        """The one entity having ``cls``, with its component.

        Raises:
            LookupError: no entity, or more than one, has ``cls``.
        """
        column = self._columns.get(cls)
        count = 0 if column is None else len(column.slots)
        if column is None or count != 1:
            raise LookupError(f"single({cls.__name__}): expected exactly one entity, found {count}")
        ((entity, slot),) = column.slots.items()
        return entity, slot.value  # type: ignore[return-value]  # column of cls

    # -------------------------------------------------------------- helpers

    def _query_columns(
        self, types: tuple[type[Any], ...], changed: bool, added: bool, since: int | None
    ) -> list[Column]:
        known = self._columns
        columns = [known.get(cls) or self._new_column(cls) for cls in types]
        if not columns:
            raise TypeError("query needs at least one component type")
        if since is not None and not (changed or added):
            raise ValueError("query: 'since' needs changed=True or added=True")
        return columns

    def _query_column(
        self, cls: type[Any], changed: bool, added: bool, since: int | None
    ) -> Column:
        if since is not None and not (changed or added):
            raise ValueError("query: 'since' needs changed=True or added=True")
        return self._columns.get(cls) or self._new_column(cls)

    def use_store(self, store: FrameStore) -> None:
        """Keep the components of ``store``'s types in its tables (:mod:`testbed.ecs.store`):
        the world's API is unchanged for them, and a compiled frame may write their rows.

        Raises:
            TypeError: a type is not a frozen dataclass.
            ValueError: a type already has components (or a column) in this world.
        """
        tables = list(store.tables())
        for cls, _ in tables:
            check_component_type(cls)
            if cls in self._columns:
                raise ValueError(f"{cls.__qualname__} already has a column in this world")
        for cls, table in tables:
            self._columns[cls] = StoreColumn(table)

    def row_view(self, entity: Entity, cls: type[Any]) -> RowView:
        """Where a store-backed component lives (:meth:`use_store`): ``entity``'s row of the
        ``cls`` table, for a compiled frame to write. The view stays valid until the component
        is removed.

        Raises:
            LookupError: ``cls`` is not store-backed, or ``entity`` has no such component.
        """
        column = self._columns.get(cls)
        if not isinstance(column, StoreColumn):
            raise LookupError(f"{cls.__qualname__} is not kept in a frame store")
        if entity not in column.slots:
            raise LookupError(f"entity {entity} has no {cls.__qualname__} component")
        return column.row_view(entity)

    def _new_column(self, cls: type[Any]) -> Column:
        check_component_type(cls)
        column = self._columns[cls] = Column()
        return column

    def _alive_types(self, entity: Entity) -> dict[type[Any], None]:
        types = self._entities.get(entity)
        if types is None:
            raise LookupError(f"entity {entity} is not alive in this world")
        return types

    def _slot(self, entity: Entity, cls: type[Any]) -> Slot:
        column = self._columns.get(cls)
        slot = None if column is None else column.slots.get(entity)
        if slot is None:
            raise LookupError(f"entity {entity} has no {cls.__qualname__} component")
        return slot


def _removal_tick(removal: Removal) -> int:
    return removal.tick
