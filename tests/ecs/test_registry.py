"""testbed.ecs.registry: registration checks, ownership, and replicated_changes content."""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from typing import Any

import pytest

from testbed.ecs import (
    Change,
    ChangeKind,
    ComponentRegistry,
    Entity,
    Origin,
    Replicate,
    Side,
    World,
    replicated_changes,
)
from testbed.ecs.registry import Replicate as ReexportedReplicate


class Mode(enum.Enum):
    MANUAL = 1
    DEPTH_HOLD = 2


@dataclass(frozen=True, slots=True)
class Vector3:
    x: float
    y: float
    z: float


@dataclass(frozen=True, slots=True)
class VehicleState:
    position_m: Vector3
    depth_m: float
    armed: bool
    mode: Mode
    thrust_n: tuple[float, ...]
    label: str
    blob: bytes
    pair: tuple[int, str]
    waypoints: tuple[Vector3, ...] = ()


@dataclass(frozen=True, slots=True)
class MovementIntent:
    surge: float


@dataclass(frozen=True, slots=True)
class Gains:
    kp: float


@dataclass(frozen=True, slots=True)
class LocalOnly:
    value: int


@dataclass(slots=True)
class NotFrozen:
    value: int


@dataclass(frozen=True)
class WithList:
    values: list[float]


@dataclass(frozen=True)
class WithOptional:
    value: float | None


@dataclass(frozen=True)
class WithDict:
    values: dict[str, int]


@dataclass(frozen=True)
class WithBareTuple:
    values: tuple  # type: ignore[type-arg]  # unparametrised on purpose


@dataclass(frozen=True)
class WithObject:
    value: object


@dataclass(frozen=True)
class WithAny:
    value: Any


@dataclass
class MutableInner:
    value: int


@dataclass(frozen=True)
class WithMutableInner:
    inner: MutableInner


@dataclass(frozen=True)
class WithTupleOfList:
    values: tuple[list[int], ...]


@dataclass(frozen=True)
class WithDefaultFactory:
    values: tuple[int, ...] = field(default_factory=tuple)


def test_register_accepts_every_allowed_field_type_and_resolves_fields() -> None:
    registry = ComponentRegistry()
    entry = registry.register(VehicleState, 2, Side.VEHICLE)
    assert entry.type_id == 2
    assert entry.fields == (
        ("position_m", Vector3),
        ("depth_m", float),
        ("armed", bool),
        ("mode", Mode),
        ("thrust_n", tuple[float, ...]),
        ("label", str),
        ("blob", bytes),
        ("pair", tuple[int, str]),
        ("waypoints", tuple[Vector3, ...]),
    )
    assert registry.register(WithDefaultFactory, 3, Side.OPERATOR).fields == (
        ("values", tuple[int, ...]),
    )


@pytest.mark.parametrize(
    "cls",
    [
        NotFrozen,
        WithList,
        WithOptional,
        WithDict,
        WithBareTuple,
        WithObject,
        WithAny,
        WithMutableInner,
        WithTupleOfList,
        int,
    ],
)
def test_register_rejects_unsupported_types(cls: type[Any]) -> None:
    registry = ComponentRegistry()
    with pytest.raises(TypeError):
        registry.register(cls, 1, Side.VEHICLE)
    assert len(registry) == 0


def test_register_rejects_bad_and_duplicate_ids_and_types() -> None:
    registry = ComponentRegistry()
    for bad_id in (0, 65536, -1):
        with pytest.raises(ValueError, match=r"1\.\.65535"):
            registry.register(Gains, bad_id, Side.OPERATOR)
    for bad_type in (True, 1.0, "1"):
        with pytest.raises(TypeError):
            registry.register(Gains, bad_type, Side.OPERATOR)  # type: ignore[arg-type]
    with pytest.raises(TypeError):
        registry.register(Gains, 1, "operator")  # type: ignore[arg-type]  # misuse on purpose
    registry.register(Gains, 1, Side.OPERATOR)
    registry.register(MovementIntent, 65535, Side.OPERATOR)
    with pytest.raises(ValueError, match="already registered to Gains"):
        registry.register(VehicleState, 1, Side.VEHICLE)
    with pytest.raises(ValueError, match="already registered"):
        registry.register(Gains, 7, Side.OPERATOR)
    with pytest.raises(ValueError, match="marker"):
        registry.register(Replicate, 9, Side.VEHICLE)
    assert [e.cls for e in registry] == [Gains, MovementIntent]


def test_lookups_iteration_order_and_ownership() -> None:
    registry = ComponentRegistry()
    registry.register(VehicleState, 300, Side.VEHICLE)
    registry.register(MovementIntent, 10, Side.OPERATOR)
    registry.register(Gains, 20, Side.OPERATOR)
    assert [e.type_id for e in registry] == [10, 20, 300]
    assert [e.cls for e in registry] == [MovementIntent, Gains, VehicleState]
    assert registry.by_id(300) is VehicleState
    assert registry.id_of(Gains) == 20
    assert registry.owner_of(MovementIntent) is Side.OPERATOR
    assert registry.is_registered(Gains) and Gains in registry
    assert not registry.is_registered(LocalOnly)
    assert registry.may_write(VehicleState, Side.VEHICLE)
    assert not registry.may_write(VehicleState, Side.OPERATOR)
    assert registry.may_write(MovementIntent, Side.OPERATOR)
    assert not registry.may_write(MovementIntent, Side.VEHICLE)
    assert not registry.may_write(LocalOnly, Side.VEHICLE)
    assert not registry.may_write(LocalOnly, Side.OPERATOR)
    with pytest.raises(KeyError, match="id 11"):
        registry.by_id(11)
    with pytest.raises(KeyError, match="LocalOnly"):
        registry.id_of(LocalOnly)
    with pytest.raises(KeyError):
        registry.owner_of(LocalOnly)
    assert ReexportedReplicate is Replicate


def _registry() -> ComponentRegistry:
    registry = ComponentRegistry()
    registry.register(MovementIntent, 1, Side.OPERATOR)
    registry.register(Gains, 2, Side.OPERATOR)
    registry.register(VehicleState, 3, Side.VEHICLE)
    return registry


def _kinds(changes: list[Change]) -> list[tuple[int, ChangeKind, type[Any] | None]]:
    return [(c.entity, c.kind, c.component) for c in changes]


def test_replicated_changes_reports_only_local_registered_changes_on_marked_entities() -> None:
    registry = _registry()
    world = World()
    rov = world.spawn(Replicate(), MovementIntent(0.0), Gains(1.0), LocalOnly(1))
    unmarked = world.spawn(MovementIntent(0.0))
    since = world.tick
    world.advance()  # tick 2
    world.set(rov, MovementIntent(0.5))  # LOCAL change: reported
    world.set(rov, Gains(2.0), origin=Origin.REMOTE)  # applied from the peer: not echoed
    world.set(rov, LocalOnly(2))  # unregistered: not reported
    world.set(unmarked, MovementIntent(0.9))  # no Replicate marker: not reported
    world.set(rov, Gains(2.0))  # equal: no change, origin stays REMOTE
    assert replicated_changes(world, since, registry) == [
        Change(rov, ChangeKind.CHANGED, MovementIntent, 1, MovementIntent(0.5), 2)
    ]
    assert replicated_changes(world, world.tick, registry) == []


def test_added_removed_readded_and_despawned() -> None:
    registry = _registry()
    world = World()
    a = world.spawn(Replicate(), MovementIntent(0.0), Gains(1.0))
    b = world.spawn(Replicate(), Gains(1.0))
    c = world.spawn(Replicate(), Gains(1.0))
    d = world.spawn(Replicate(), Gains(1.0))
    since = world.tick
    world.advance()  # tick 2
    world.set(b, MovementIntent(1.0))  # added
    world.remove(a, Gains)  # removed
    world.remove(c, Gains)
    world.set(c, Gains(1.0))  # removed then re-added: net ADDED with its value
    world.despawn(d)  # despawned: one DESPAWNED entry, no component removals
    world.remove(a, MovementIntent, origin=Origin.REMOTE)  # peer's removal: not echoed
    assert replicated_changes(world, since, registry) == [
        Change(a, ChangeKind.REMOVED, Gains, 2, None, 2),
        Change(b, ChangeKind.ADDED, MovementIntent, 1, MovementIntent(1.0), 2),
        Change(c, ChangeKind.ADDED, Gains, 2, Gains(1.0), 2),
        Change(d, ChangeKind.DESPAWNED, None, None, None, 2),
    ]


def test_added_then_removed_in_the_window_is_reported_as_removed_only_once() -> None:
    registry = _registry()
    world = World()
    entity = world.spawn(Replicate())
    since = world.tick
    world.advance()
    world.set(entity, Gains(1.0))
    world.remove(entity, Gains)
    world.set(entity, Gains(2.0))
    world.advance()
    world.remove(entity, Gains)
    assert _kinds(replicated_changes(world, since, registry)) == [
        (entity, ChangeKind.REMOVED, Gains)
    ]


def test_late_marker_sends_every_registered_component_and_remote_despawns_are_silent() -> None:
    registry = _registry()
    world = World()
    entity = world.spawn(MovementIntent(0.2), Gains(3.0), LocalOnly(0))
    mirrored = world.spawn(Replicate(), Gains(1.0), origin=Origin.REMOTE)
    world.advance()
    world.advance()
    since = world.tick - 1
    world.set(entity, Replicate())  # the peer has never seen this entity
    world.despawn(mirrored, origin=Origin.REMOTE)
    assert replicated_changes(world, since, registry) == [
        Change(entity, ChangeKind.ADDED, MovementIntent, 1, MovementIntent(0.2), 1),
        Change(entity, ChangeKind.ADDED, Gains, 2, Gains(3.0), 1),
    ]


def test_removing_the_marker_stops_replication_and_unmarked_removals_are_silent() -> None:
    registry = _registry()
    world = World()
    entity = world.spawn(Replicate(), Gains(1.0), MovementIntent(0.0))
    plain = world.spawn(Gains(1.0))
    since = world.tick
    world.advance()
    world.remove(entity, Replicate)
    world.remove(entity, Gains)
    world.set(entity, MovementIntent(1.0))
    world.despawn(plain)
    assert replicated_changes(world, since, registry) == []


def test_snapshot_side_filter_and_order() -> None:
    registry = _registry()
    world = World()
    state = VehicleState(
        Vector3(0, 0, 1), 1.0, True, Mode.MANUAL, (1.0, 2.0), "rov", b"\x00", (1, "a")
    )
    e1 = world.spawn(Gains(1.0), Replicate(), state, MovementIntent(0.0))
    e2 = world.spawn(state, Replicate())
    snapshot = replicated_changes(world, 0, registry)
    assert [(c.entity, c.type_id) for c in snapshot] == [(e1, 1), (e1, 2), (e1, 3), (e2, 3)]
    assert all(c.kind is ChangeKind.ADDED for c in snapshot)
    vehicle_only = replicated_changes(world, 0, registry, side=Side.VEHICLE)
    assert [(c.entity, c.component) for c in vehicle_only] == [
        (e1, VehicleState),
        (e2, VehicleState),
    ]


def apply_changes(world: World, changes: list[Change], ids: dict[Entity, Entity]) -> None:
    """A minimal receiving side: map sender ids to local ones and apply with REMOTE origin."""
    for change in changes:
        if change.kind is ChangeKind.DESPAWNED:
            if change.entity in ids:
                world.despawn(ids.pop(change.entity), origin=Origin.REMOTE)
            continue
        if change.entity not in ids:
            ids[change.entity] = world.spawn(Replicate(), origin=Origin.REMOTE)
        local = ids[change.entity]
        if change.kind is ChangeKind.REMOVED:
            assert change.component is not None
            world.remove(local, change.component, origin=Origin.REMOTE)
        else:
            world.set(local, change.value, origin=Origin.REMOTE)


def test_a_mirror_fed_with_changes_matches_and_does_not_echo() -> None:
    """Apply successive change sets to a second world: its registered state equals the source's."""
    registry = _registry()
    source, mirror = World(), World()
    ids: dict[Entity, Entity] = {}
    a = source.spawn(Replicate(), Gains(1.0), MovementIntent(0.0))
    b = source.spawn(Replicate(), Gains(2.0))
    source.spawn(Gains(5.0))  # not replicated
    script = [
        lambda: source.set(a, Gains(1.5)),
        lambda: source.remove(b, Gains),
        lambda: source.set(b, MovementIntent(3.0)),
        lambda: source.despawn(a),
        lambda: source.spawn(Replicate(), Gains(9.0)),
    ]
    since = 0
    for step in [*script, lambda: None]:
        changes = replicated_changes(source, since, registry)
        since = source.tick
        source.advance()
        apply_changes(mirror, changes, ids)
        mirror.advance()
        assert replicated_changes(mirror, 0, registry) == []  # everything there is REMOTE
        step()
    expected = {
        (e, type(c).__name__, c)
        for e in source.entities()
        if source.has(e, Replicate)
        for c in source.components(e)
        if registry.is_registered(type(c))
    }
    mirrored = {
        (sender, type(c).__name__, c)
        for sender, local in ids.items()
        for c in mirror.components(local)
        if registry.is_registered(type(c))
    }
    assert mirrored == expected
    assert len(expected) == 2  # b's MovementIntent, the new entity's Gains
