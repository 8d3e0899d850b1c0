"""What the world stores and records: entity ids, component types, and the records of writes.

An :data:`Entity` is a plain integer id. A component type is a frozen dataclass
(:func:`check_component_type` says whether a type qualifies); :class:`Replicate` is the marker
component that makes an entity's registered components travel to the peer. Every write carries
the :class:`Origin` of whoever made it, and every removal leaves a :class:`Removal` in the
world's removal log.

Value types only: the container that holds them is :class:`~testbed.ecs.world.World`. No
storage, no scheduling, no replication, no I/O; the standard library only.
"""

from __future__ import annotations

import dataclasses
import enum
from dataclasses import dataclass
from typing import Any, NewType

__all__ = [
    "Entity",
    "Origin",
    "Removal",
    "Replicate",
    "check_component_type",
]

Entity = NewType("Entity", int)
"""An entity id: allocated in order from 1 within one world and never reused."""


class Origin(enum.Enum):
    """Who made a write: this node (LOCAL) or the peer, through replication (REMOTE).

    Replication applies inbound changes with ``Origin.REMOTE`` and sends only ``LOCAL`` ones, so a
    change never echoes back to the node that made it.
    """

    LOCAL = enum.auto()
    REMOTE = enum.auto()


@dataclass(frozen=True, slots=True)
class Replicate:
    """Marker component: this entity's registered components are replicated to the peer.

    Defined here because the world notes, in each :class:`Removal`, whether the entity carried
    the marker; :mod:`testbed.ecs.registry` re-exports it.
    """


@dataclass(frozen=True, slots=True)
class Removal:
    """One entry of the removal log.

    Attributes:
        tick: world tick at which the removal happened.
        entity: the entity the component was removed from (or that was despawned).
        component: the removed component's type, or ``None`` for the despawn of the entity itself
            (logged after the removals of all its components).
        origin: who made the removal.
        replicated: whether the entity carried :class:`Replicate` at the time (for a despawn or
            the removal of ``Replicate`` itself: whether it carried it just before).
    """

    tick: int
    entity: Entity
    component: type[Any] | None
    origin: Origin
    replicated: bool

    @property
    def is_despawn(self) -> bool:
        """Whether this entry is the despawn of the entity itself."""
        return self.component is None


_CHECKED_TYPES: set[type[Any]] = {Replicate}


def check_component_type(cls: type[Any]) -> None:
    """Check that ``cls`` may be used as a component type: a frozen dataclass.

    Raises:
        TypeError: ``cls`` is not a class, not a dataclass, or not frozen.
    """
    if cls in _CHECKED_TYPES:
        return
    if not isinstance(cls, type):
        raise TypeError(f"component types must be classes, got {cls!r}")
    if not dataclasses.is_dataclass(cls):
        raise TypeError(f"component type {cls.__qualname__} must be a frozen dataclass")
    params = getattr(cls, "__dataclass_params__", None)
    if params is None or not params.frozen:
        raise TypeError(
            f"component type {cls.__qualname__} must be frozen: use @dataclass(frozen=True)"
        )
    _CHECKED_TYPES.add(cls)
