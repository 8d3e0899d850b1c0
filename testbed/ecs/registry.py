"""Replication registry: which component types replicate, under which id, owned by which side.

Only registered component types on entities carrying the :class:`Replicate` marker travel to the
peer, each under a stable numeric id (1–65535) and owned by one :class:`Side`: the operator owns
intents and settings, the vehicle owns state, and each side may write only what it owns.
Registered types must be frozen dataclasses whose fields are plain values a codec can write:
``bool``, ``int``, ``float``, ``str``, ``bytes``, enums, tuples of allowed types (fixed
``tuple[A, B]`` or variable ``tuple[A, ...]``) and nested frozen dataclasses of allowed types.

:func:`replicated_changes` lists what a node must send since a tick; the change-set codecs (a
later module) decide how it travels. No wire encoding here, and no pickle, ever.
"""

from __future__ import annotations

import dataclasses
import enum
import operator
import types
import typing
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from testbed.ecs.component import Entity, Origin, Replicate, check_component_type
from testbed.ecs.storage import GONE, Column
from testbed.ecs.store import StoreColumn
from testbed.ecs.world import World

__all__ = [
    "Change",
    "ChangeKind",
    "ComponentRegistry",
    "RawChange",
    "Registration",
    "Replicate",
    "Side",
    "replicated_changes",
    "replicated_entries",
]

TYPE_ID_MIN = 1
TYPE_ID_MAX = 65535
_SCALARS: tuple[type[Any], ...] = (bool, int, float, str, bytes)
LOCAL = Origin.LOCAL


class Side(enum.Enum):
    """The two nodes of a teleoperation session."""

    VEHICLE = enum.auto()
    OPERATOR = enum.auto()


@dataclass(frozen=True, slots=True)
class Registration:
    """One registered component type.

    Attributes:
        cls: the component type.
        type_id: its stable wire id, 1–65535.
        owner: the side that may write it.
        fields: ``(name, resolved type)`` of each dataclass field, in declaration order.
    """

    cls: type[Any]
    type_id: int
    owner: Side
    fields: tuple[tuple[str, Any], ...]


class ComponentRegistry:
    """Registered replicated component types, iterated in type-id order."""

    __slots__ = ("_by_cls", "_by_id", "_ordered")

    def __init__(self) -> None:
        self._by_id: dict[int, Registration] = {}
        self._by_cls: dict[type[Any], Registration] = {}
        self._ordered: list[Registration] = []

    def register(self, cls: type[Any], type_id: int, owner: Side) -> Registration:
        """Register ``cls`` for replication under ``type_id``, written only by ``owner``.

        Raises:
            TypeError: ``cls`` is not a frozen dataclass, a field has an unsupported type, the id
                is not an int, or ``owner`` is not a :class:`Side`.
            ValueError: the id is out of 1–65535, or the id or the type is already registered.
        """
        if not isinstance(type_id, int) or isinstance(type_id, bool):
            raise TypeError(f"type_id must be an int, got {type_id!r}")
        if not TYPE_ID_MIN <= type_id <= TYPE_ID_MAX:
            raise ValueError(f"type_id must be in {TYPE_ID_MIN}..{TYPE_ID_MAX}, got {type_id}")
        if not isinstance(owner, Side):
            raise TypeError(f"owner must be a Side, got {owner!r}")
        if cls is Replicate:
            raise ValueError("Replicate is the replication marker itself; it is not registered")
        check_component_type(cls)
        if type_id in self._by_id:
            other = self._by_id[type_id].cls.__qualname__
            raise ValueError(f"type_id {type_id} is already registered to {other}")
        if cls in self._by_cls:
            raise ValueError(
                f"{cls.__qualname__} is already registered as {self._by_cls[cls].type_id}"
            )
        entry = Registration(cls, type_id, owner, _field_types(cls))
        self._by_id[type_id] = entry
        self._by_cls[cls] = entry
        self._ordered = sorted(self._by_id.values(), key=_registration_id)
        return entry

    def by_id(self, type_id: int) -> type[Any]:
        """The component type registered under ``type_id``.

        Raises:
            KeyError: no type has that id.
        """
        return self.entry_by_id(type_id).cls

    def entry_by_id(self, type_id: int) -> Registration:
        """The registration under ``type_id``.

        Raises:
            KeyError: no type has that id.
        """
        try:
            return self._by_id[type_id]
        except KeyError:
            raise KeyError(f"no component type registered under id {type_id}") from None

    def entry(self, cls: type[Any]) -> Registration:
        """The registration of ``cls``.

        Raises:
            KeyError: ``cls`` is not registered.
        """
        try:
            return self._by_cls[cls]
        except KeyError:
            raise KeyError(f"{cls.__qualname__} is not a registered component type") from None

    def id_of(self, cls: type[Any]) -> int:
        """The type id of ``cls`` (KeyError if unregistered)."""
        return self.entry(cls).type_id

    def owner_of(self, cls: type[Any]) -> Side:
        """The side that owns ``cls`` (KeyError if unregistered)."""
        return self.entry(cls).owner

    def is_registered(self, cls: type[Any]) -> bool:
        """Whether ``cls`` is registered."""
        return cls in self._by_cls

    def may_write(self, cls: type[Any], side: Side) -> bool:
        """Whether ``side`` may write ``cls`` through replication (False if unregistered)."""
        entry = self._by_cls.get(cls)
        return entry is not None and entry.owner is side

    def __iter__(self) -> Iterator[Registration]:
        """Registrations in ascending type-id order."""
        return iter(self._ordered)

    def __len__(self) -> int:
        return len(self._ordered)

    def __contains__(self, cls: object) -> bool:
        return cls in self._by_cls


def _registration_id(entry: Registration) -> int:
    return entry.type_id


def _field_types(cls: type[Any]) -> tuple[tuple[str, Any], ...]:
    """Resolved ``(name, type)`` of each field, checking every type is replicable."""
    try:
        hints = typing.get_type_hints(cls)
    except Exception as err:  # NameError and friends from unresolvable string annotations
        raise TypeError(f"cannot resolve field types of {cls.__qualname__}: {err}") from None
    result = []
    for field in dataclasses.fields(cls):
        annotation = hints[field.name]
        _check_field_type(annotation, f"{cls.__qualname__}.{field.name}", (cls,))
        result.append((field.name, annotation))
    return tuple(result)


def _check_field_type(annotation: Any, where: str, outer: tuple[type[Any], ...]) -> None:
    """Raise TypeError unless ``annotation`` is a replicable field type."""
    if annotation in _SCALARS:
        return
    if isinstance(annotation, type) and issubclass(annotation, enum.Enum):
        return
    if isinstance(annotation, type) and dataclasses.is_dataclass(annotation):
        if annotation in outer:
            raise TypeError(f"{where}: recursive dataclass {annotation.__qualname__}")
        check_component_type(annotation)
        hints = typing.get_type_hints(annotation)
        for field in dataclasses.fields(annotation):
            inner = f"{where}.{field.name}"
            _check_field_type(hints[field.name], inner, (*outer, annotation))
        return
    if typing.get_origin(annotation) is tuple:
        args = typing.get_args(annotation)
        if len(args) == 2 and args[1] is Ellipsis:
            args = args[:1]
        if not args:
            raise TypeError(f"{where}: empty tuple type {annotation!r}")
        for arg in args:
            _check_field_type(arg, f"{where}[]", outer)
        return
    shown = annotation.__qualname__ if isinstance(annotation, type) else repr(annotation)
    kind = " (unions/None are not replicable)" if _is_union(annotation) else ""
    raise TypeError(
        f"{where}: unsupported field type {shown}{kind}; allowed: bool, int, float, str, "
        f"bytes, enums, tuples of those and nested frozen dataclasses"
    )


def _is_union(annotation: Any) -> bool:
    return typing.get_origin(annotation) in (typing.Union, types.UnionType)


class ChangeKind(enum.Enum):
    """What happened to a replicated component (or entity) since a tick."""

    ADDED = enum.auto()
    CHANGED = enum.auto()
    REMOVED = enum.auto()
    DESPAWNED = enum.auto()


@dataclass(frozen=True, slots=True)
class Change:
    """One entry of a change set: the net effect on one component (or entity) since a tick.

    Attributes:
        entity: the entity, in the sending world's ids.
        kind: added, changed, removed, or (with ``component=None``) the entity despawned.
        component: the component type, None for a despawn.
        type_id: its registered id, None for a despawn.
        value: the current component for ADDED/CHANGED, None otherwise.
        tick: world tick of the change (the latest write, the removal or the despawn).
    """

    entity: Entity
    kind: ChangeKind
    component: type[Any] | None
    type_id: int | None
    value: object | None
    tick: int


def replicated_changes(
    world: World, since: int, registry: ComponentRegistry, *, side: Side | None = None
) -> list[Change]:
    """The LOCAL-origin changes of registered types on replicated entities since ``since``.

    Reports the *net* effect since the tick, at most one entry per (entity, component):

    - a registered component present now whose latest write is LOCAL and newer than ``since``:
      ADDED if it was added after ``since``, else CHANGED, with its current value;
    - every registered component of an entity whose :class:`Replicate` marker was added LOCALly
      after ``since`` (the peer has never seen it): ADDED;
    - a registered component absent now whose last removal after ``since`` was LOCAL and made
      while the entity carried ``Replicate``: REMOVED;
    - an entity despawned LOCALly after ``since`` while carrying ``Replicate``: one DESPAWNED
      entry and nothing else for it.

    Writes with ``Origin.REMOTE`` (applied from the peer) are never reported, so nothing echoes.
    Removing ``Replicate`` from a live entity just stops its replication (the peer keeps its copy).
    ``since=0`` gives a full snapshot of the local state for a new peer.

    Args:
        world: the sending node's world.
        since: report what happened at ticks newer than this.
        registry: the registered component types.
        side: if given, report only component types this side owns.

    Returns:
        Changes ordered by entity, then type id (a despawn alone for its entity).
    """
    entries = [e for e in registry if side is None or e.owner is side]
    return [
        Change(entity, kind, None if entry is None else entry.cls, type_id or None, value, tick)
        for entity, type_id, kind, entry, value, tick in replicated_entries(world, since, entries)
    ]


RawChange = tuple[Entity, int, ChangeKind, Registration | None, object, int]
"""One change as :func:`replicated_entries` lists it: entity, type id (0 for a despawn), kind,
registration (None for a despawn), value (None unless added or changed; a store row's floats
for a type the caller takes as floats), tick."""

_RAW_ORDER = operator.itemgetter(0, 1)


def replicated_entries(
    world: World,
    since: int,
    entries: Sequence[Registration],
    floats: Mapping[type[Any], tuple[int, ...]] | None = None,
) -> list[RawChange]:
    """:func:`replicated_changes` of the types ``entries`` as plain tuples (:data:`RawChange`),
    in the same order: the one implementation of the rule, for senders that poll every frame.

    Columns whose newest change is not after ``since`` are skipped unread, and so is the removal
    log when nothing was removed after ``since``.

    Args:
        world: the sending node's world.
        since: report what happened at ticks newer than this.
        entries: the types to report, in type-id order.
        floats: types the caller can take as their flat floats, with their fields' widths: a
            store-backed type whose row holds exactly those fields
            (:attr:`~testbed.ecs.store.Layout.float_widths` equal) is given as its row's floats
            (a ``list``, field by field) instead of a component built from the row.
    """
    changes: list[RawChange] = []
    # Same package as the world: read its columns and slots directly (this runs every frame of
    # every replicating node).
    columns = world._columns
    marker = columns.get(Replicate)
    if marker is None:
        return changes  # no entity ever carried the marker: nothing replicates
    marked = marker.slots
    # entities whose marker is new here: the peer has never seen them (rare after the start)
    fresh: set[Entity] | tuple[()] = ()
    if marker.added_max > since:
        fresh = {e for e, _ in world.query1(Replicate, added=True, since=since, origin=LOCAL)}
    added, changed = ChangeKind.ADDED, ChangeKind.CHANGED
    for entry in entries:
        column = columns.get(entry.cls)
        if column is None or (not fresh and column.changed_max <= since):
            continue
        type_id = entry.type_id
        rows = _float_rows(column, floats, entry.cls)
        for entity, slot in column.pairs():
            if entity not in marked:
                continue
            tick = slot.changed  # read first: a store row's value is rebuilt only if sent
            if fresh and entity in fresh:
                kind = added
            elif tick <= since or slot.origin is not LOCAL:
                continue
            elif slot.added > since:
                kind = added
            else:
                kind = changed
            if rows is not None:  # a live slot of a store column: its row is its value
                value = rows[slot._row].tolist()  # type: ignore[attr-defined]  # a StoreSlot
            else:
                value = slot.value
                if value is GONE:
                    continue
            changes.append((entity, type_id, kind, entry, value, tick))
    log = world._removals
    if log and log[-1].tick > since:
        _removed_entries(world, since, entries, changes)
    if len(changes) > 1:
        changes.sort(key=_RAW_ORDER)
    return changes


def _float_rows(
    column: Column, floats: Mapping[type[Any], tuple[int, ...]] | None, cls: type[Any]
) -> np.ndarray | None:
    """The values table of a store-backed column the caller takes as floats, else None."""
    if floats is None or type(column) is not StoreColumn:
        return None
    table = column.table
    widths = floats.get(cls)
    return table.values if widths is not None and widths == table.layout.float_widths else None


def _removed_entries(
    world: World, since: int, entries: Sequence[Registration], changes: list[RawChange]
) -> None:
    """Append the REMOVED and DESPAWNED entries of the removal log after ``since``."""
    owned = {e.cls: e for e in entries}
    last_removal: dict[tuple[Entity, type[Any] | None], tuple[int, bool]] = {}
    for removal in world.removals_since(since):
        if removal.component is None or removal.component in owned:
            key = (removal.entity, removal.component)
            local = removal.origin is LOCAL and removal.replicated
            last_removal[key] = (removal.tick, local)
    for (entity, cls), (tick, local) in last_removal.items():
        if not local:
            continue
        if cls is None:
            changes.append((entity, 0, ChangeKind.DESPAWNED, None, None, tick))
        elif world.is_alive(entity) and not world.has(entity, cls):
            entry = owned[cls]
            changes.append((entity, entry.type_id, ChangeKind.REMOVED, entry, None, tick))
