"""Our small Entity-Component-System: world, change ticks, three-phase schedule, replication.

Each node (vehicle, operator) owns one :class:`World` ticked by a :class:`Schedule` in three
phases. Components are frozen dataclasses written with :meth:`World.set`, which records a change
(tick and :class:`Origin`) only when the value differs; systems ask for what changed since they
last ran. :mod:`testbed.ecs.registry` says which component types replicate, under which id and
owned by which side, and lists the local changes a link codec must send. :mod:`testbed.ecs.store`
keeps chosen component types in float64 tables a compiled frame can write (the world's API
unchanged for them).

Standard library only (the layering test allows numpy); no I/O, no clock, no global state.
"""

from __future__ import annotations

from testbed.ecs.component import Entity, Origin, Removal, Replicate, check_component_type
from testbed.ecs.registry import (
    Change,
    ChangeKind,
    ComponentRegistry,
    RawChange,
    Registration,
    Side,
    replicated_changes,
    replicated_entries,
)
from testbed.ecs.schedule import Phase, Schedule, System
from testbed.ecs.store import FrameStore
from testbed.ecs.world import World

__all__ = [
    "Change",
    "ChangeKind",
    "ComponentRegistry",
    "Entity",
    "FrameStore",
    "Origin",
    "Phase",
    "RawChange",
    "Registration",
    "Removal",
    "Replicate",
    "Schedule",
    "Side",
    "System",
    "World",
    "check_component_type",
    "replicated_changes",
    "replicated_entries",
]
