"""testbed.ecs.world: entities, set-if-not-equal, change ticks, origins, removals, queries."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import pytest

from testbed.ecs import Entity, Origin, Removal, Replicate, World


@dataclass(frozen=True, slots=True)
class Depth:
    depth_m: float


@dataclass(frozen=True, slots=True)
class Heading:
    heading_rad: float


@dataclass(frozen=True, slots=True)
class Armed:
    pass


@dataclass(slots=True)
class Mutable:
    value: int


class NotADataclass:
    pass


def test_entities_are_allocated_in_order_and_never_reused() -> None:
    world = World()
    first = [world.spawn() for _ in range(3)]
    assert first == [1, 2, 3]
    world.despawn(Entity(3))
    world.despawn(Entity(1))
    assert world.spawn() == 4
    assert world.entities() == [2, 4]
    assert not world.is_alive(Entity(1))
    assert world.is_alive(Entity(2))
    assert not world.is_alive(Entity(99))


def test_set_records_a_change_only_when_the_value_differs() -> None:
    world = World()
    entity = world.spawn(Depth(1.0))
    assert world.changed_tick(entity, Depth) == 1
    assert world.advance() == 2
    stored = world.get(entity, Depth)
    assert world.set(entity, Depth(1.0)) is False  # equal value: nothing recorded
    assert world.changed_tick(entity, Depth) == 1
    assert world.get(entity, Depth) is stored  # the stored object is kept
    world.advance()
    assert world.set(entity, Depth(2.5)) is True
    assert world.changed_tick(entity, Depth) == 3
    assert world.added_tick(entity, Depth) == 1
    assert world.get(entity, Depth) == Depth(2.5)


def test_set_does_not_copy_the_component() -> None:
    world = World()
    value = Depth(4.0)
    entity = world.spawn(value)
    assert world.get(entity, Depth) is value


def test_adding_a_component_records_added_and_changed_ticks() -> None:
    world = World()
    entity = world.spawn()
    world.advance()
    world.advance()
    assert world.set(entity, Heading(0.5)) is True
    assert world.added_tick(entity, Heading) == 3
    assert world.changed_tick(entity, Heading) == 3


def test_origin_follows_the_last_recorded_change() -> None:
    world = World()
    entity = world.spawn(Depth(1.0))
    assert world.origin_of(entity, Depth) is Origin.LOCAL
    world.set(entity, Depth(2.0), origin=Origin.REMOTE)
    assert world.origin_of(entity, Depth) is Origin.REMOTE
    # An equal write records nothing, so not its origin either.
    world.set(entity, Depth(2.0), origin=Origin.LOCAL)
    assert world.origin_of(entity, Depth) is Origin.REMOTE
    spawned = world.spawn(Depth(0.0), origin=Origin.REMOTE)
    assert world.origin_of(spawned, Depth) is Origin.REMOTE


def test_nan_fields_compare_unequal_so_each_write_is_a_change() -> None:
    world = World()
    entity = world.spawn(Depth(float("nan")))
    world.advance()
    assert world.set(entity, Depth(float("nan"))) is True
    assert world.changed_tick(entity, Depth) == 2


@pytest.mark.parametrize("bad", [Mutable(1), NotADataclass(), Depth, 3.0])
def test_components_must_be_frozen_dataclass_instances(bad: object) -> None:
    world = World()
    entity = world.spawn()
    with pytest.raises(TypeError):
        world.set(entity, bad)
    with pytest.raises(TypeError):
        world.spawn(bad)
    assert world.entities() == [entity]  # the failed spawn allocated nothing


def test_query_rejects_non_component_types() -> None:
    world = World()
    with pytest.raises(TypeError):
        list(world.query(Mutable))
    with pytest.raises(TypeError):
        world.query()


def test_spawn_rejects_two_components_of_one_type() -> None:
    world = World()
    with pytest.raises(ValueError, match="two components of one type"):
        world.spawn(Depth(1.0), Depth(2.0))


def test_writes_to_dead_entities_are_misuse() -> None:
    world = World()
    entity = world.spawn(Depth(1.0))
    world.despawn(entity)
    with pytest.raises(LookupError):
        world.set(entity, Depth(2.0))
    with pytest.raises(LookupError):
        world.remove(entity, Depth)
    with pytest.raises(LookupError):
        world.despawn(entity)
    with pytest.raises(LookupError):
        world.set(Entity(42), Depth(2.0))
    assert world.get(entity, Depth) is None
    assert not world.has(entity, Depth)


def test_get_get_or_has() -> None:
    world = World()
    entity = world.spawn(Depth(1.0))
    assert world.get(entity, Heading) is None
    assert world.get_or(entity, Heading, Heading(9.0)) == Heading(9.0)
    assert world.get_or(entity, Depth, Depth(0.0)) == Depth(1.0)
    assert world.has(entity, Depth)
    assert not world.has(entity, Heading)
    with pytest.raises(LookupError):
        world.changed_tick(entity, Heading)
    with pytest.raises(LookupError):
        world.added_tick(entity, Heading)
    with pytest.raises(LookupError):
        world.origin_of(entity, Heading)


def test_remove_logs_removals_with_tick_origin_and_marker() -> None:
    world = World()
    a = world.spawn(Depth(1.0), Heading(0.0), Replicate())
    b = world.spawn(Depth(2.0))
    world.advance()  # tick 2
    assert world.remove(a, Depth) is True
    assert world.remove(a, Depth) is False  # nothing left to remove: nothing logged
    world.advance()  # tick 3
    assert world.remove(b, Depth, origin=Origin.REMOTE) is True
    assert world.removals_since(0) == [
        Removal(2, a, Depth, Origin.LOCAL, True),
        Removal(3, b, Depth, Origin.REMOTE, False),
    ]
    assert world.removals_since(2) == [Removal(3, b, Depth, Origin.REMOTE, False)]
    assert world.removals_since(3) == []
    assert not world.has(a, Depth)
    assert world.has(a, Heading)


def test_removed_then_readded_component_has_a_new_added_tick() -> None:
    world = World()
    entity = world.spawn(Depth(1.0))
    world.advance()
    world.remove(entity, Depth)
    world.advance()
    world.set(entity, Depth(1.0))
    assert world.added_tick(entity, Depth) == 3
    assert world.changed_tick(entity, Depth) == 3


def test_despawn_logs_every_component_then_the_entity() -> None:
    world = World()
    entity = world.spawn(Heading(1.0), Replicate(), Depth(2.0))
    keep = world.spawn(Depth(3.0))
    world.advance()
    world.despawn(entity, origin=Origin.REMOTE)
    log = world.removals_since(1)
    assert [r.component for r in log] == [Heading, Replicate, Depth, None]
    assert all(r.tick == 2 and r.entity == entity for r in log)
    assert all(r.origin is Origin.REMOTE and r.replicated for r in log)
    assert log[-1].is_despawn and not log[0].is_despawn
    assert [e for e, _ in world.query(Depth)] == [keep]
    assert world.entities() == [keep]


def test_trim_removals_forgets_old_entries_only() -> None:
    world = World()
    entities = [world.spawn(Depth(float(i))) for i in range(4)]
    for entity in entities:
        world.advance()
        world.despawn(entity)
    world.trim_removals(3)
    assert [r.tick for r in world.removals_since(0)] == [4, 4, 5, 5]


def test_query_yields_ascending_entities_whatever_the_insertion_order() -> None:
    world = World()
    entities = [world.spawn() for _ in range(6)]
    for entity in reversed(entities):
        world.set(entity, Depth(float(entity)))
    for entity in (entities[4], entities[1], entities[2]):
        world.set(entity, Heading(float(-entity)))
    assert [e for e, _ in world.query(Depth)] == entities
    assert list(world.query(Depth, Heading)) == [
        (e, (Depth(float(e)), Heading(float(-e)))) for e in (2, 3, 5)
    ]
    assert list(world.query(Heading, Depth)) == [
        (e, (Heading(float(-e)), Depth(float(e)))) for e in (2, 3, 5)
    ]
    assert list(world.query1(Heading)) == [(e, Heading(float(-e))) for e in (2, 3, 5)]
    assert list(world.query(Armed)) == []


def test_query_skips_entities_whose_component_is_removed_during_iteration() -> None:
    world = World()
    entities = [world.spawn(Depth(float(i))) for i in range(5)]
    seen = []
    for entity, _ in world.query(Depth):
        seen.append(entity)
        if entity == entities[1]:
            world.remove(entities[2], Depth)
            world.despawn(entities[3])
    assert seen == [entities[0], entities[1], entities[4]]


def _filtered_world() -> tuple[World, list[Entity]]:
    """Five entities with Depth and Heading written at known ticks and origins.

    tick 1: all spawned with Depth and Heading (e1..e5).
    tick 2: e2 Depth changed (LOCAL), e3 Heading changed (REMOTE).
    tick 3: e4 gets Armed; e5 Heading removed and re-added (LOCAL), e1 Depth set to same value.
    """
    world = World()
    es = [world.spawn(Depth(float(i)), Heading(0.0)) for i in range(5)]
    world.advance()
    world.set(es[1], Depth(10.0))
    world.set(es[2], Heading(1.0), origin=Origin.REMOTE)
    world.advance()
    world.set(es[3], Armed())
    world.remove(es[4], Heading)
    world.set(es[4], Heading(0.0))
    world.set(es[0], Depth(0.0))
    return world, es


def _ids(items: Iterable[tuple[Entity, object]]) -> list[Entity]:
    return [entity for entity, _ in items]


def test_changed_and_added_filters_compare_strictly_against_since() -> None:
    world, es = _filtered_world()
    e1, e2, e3, e4, e5 = es
    assert _ids(world.query(Depth, Heading, changed=True, since=0)) == es
    assert _ids(world.query(Depth, Heading, changed=True, since=1)) == [e2, e3, e5]
    assert _ids(world.query(Depth, Heading, changed=True, since=2)) == [e5]
    assert _ids(world.query(Depth, Heading, changed=True, since=3)) == []
    assert _ids(world.query(Depth, changed=True, since=1)) == [e2]
    assert _ids(world.query(Depth, Heading, added=True, since=1)) == [e5]
    assert _ids(world.query(Armed, added=True, since=2)) == [e4]
    assert _ids(world.query(Depth, Armed, changed=True, since=2)) == [e4]
    assert _ids(world.query(Depth, added=True, changed=True, since=1)) == [e2]
    assert e1 not in _ids(world.query(Depth, changed=True, since=1))


def test_origin_filter() -> None:
    world, es = _filtered_world()
    _, e2, e3, _, e5 = es
    assert _ids(world.query(Heading, changed=True, since=1, origin=Origin.REMOTE)) == [e3]
    local = world.query(Depth, Heading, changed=True, since=1, origin=Origin.LOCAL)
    assert _ids(local) == [e2, e5]
    assert _ids(world.query(Heading, origin=Origin.REMOTE)) == [e3]
    assert _ids(world.query(Depth, Heading, added=True, since=1, origin=Origin.REMOTE)) == []


def test_changed_filter_defaults_to_last_run_tick() -> None:
    world, es = _filtered_world()
    world.last_run_tick = 2
    assert _ids(world.query(Depth, Heading, changed=True)) == [es[4]]
    world.last_run_tick = 0
    assert _ids(world.query(Depth, changed=True)) == es


def test_since_without_a_filter_is_misuse() -> None:
    world = World()
    with pytest.raises(ValueError, match="since"):
        world.query(Depth, since=3)


def test_single() -> None:
    world = World()
    with pytest.raises(LookupError, match="found 0"):
        world.single(Depth)
    entity = world.spawn(Depth(1.0))
    world.spawn(Heading(1.0))
    assert world.single(Depth) == (entity, Depth(1.0))
    world.spawn(Depth(2.0))
    with pytest.raises(LookupError, match="found 2"):
        world.single(Depth)


def test_resources() -> None:
    class Rng:
        pass

    world = World()
    assert not world.has_resource(Rng)
    with pytest.raises(KeyError, match=r"no resource of type .*Rng"):
        world.resource(Rng)
    rng = Rng()
    world.insert_resource(rng)
    assert world.has_resource(Rng)
    assert world.resource(Rng) is rng
    replacement = Rng()
    world.insert_resource(replacement)
    assert world.resource(Rng) is replacement
    assert world.remove_resource(Rng) is True
    assert world.remove_resource(Rng) is False
    assert not world.has_resource(Rng)


def test_components_lists_an_entity_in_insertion_order() -> None:
    world = World()
    entity = world.spawn(Heading(1.0))
    world.set(entity, Depth(2.0))
    assert world.components(entity) == (Heading(1.0), Depth(2.0))
