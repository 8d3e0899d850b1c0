"""testbed.ecs.world against a plain-dict reference model, driven by hypothesis.

Random sequences of spawn / set / remove / despawn / advance (with both origins) are applied to a
World and to a model made of dicts; after every step get, has, ticks, origins, every query (one
and two types, unfiltered and filtered by changed/added/since/origin) and the removal log must
agree.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Any

from hypothesis import settings
from hypothesis import strategies as st
from hypothesis.stateful import RuleBasedStateMachine, invariant, precondition, rule

from testbed.ecs import Entity, Origin, Removal, World


@dataclass(frozen=True, slots=True)
class A:
    value: int


@dataclass(frozen=True, slots=True)
class B:
    value: int


@dataclass(frozen=True, slots=True)
class C:
    value: int


TYPES: tuple[type[Any], ...] = (A, B, C)
VALUES = st.integers(0, 2)
ORIGINS = st.sampled_from(list(Origin))


@dataclass
class Record:
    value: object
    added: int
    changed: int
    origin: Origin


class WorldModel(RuleBasedStateMachine):
    def __init__(self) -> None:
        super().__init__()
        self.world = World()
        self.tick = 1
        self.next_id = 1
        self.model: dict[int, dict[type[Any], Record]] = {}
        self.removals: list[tuple[int, int, type[Any] | None, Origin]] = []
        self.dead: list[int] = []

    # ------------------------------------------------------------------ rules

    @rule(
        types=st.lists(st.sampled_from(TYPES), unique=True, max_size=3),
        value=VALUES,
        origin=ORIGINS,
    )
    def spawn(self, types: list[type[Any]], value: int, origin: Origin) -> None:
        entity = self.world.spawn(*(cls(value) for cls in types), origin=origin)
        assert entity == self.next_id
        self.model[self.next_id] = {
            cls: Record(cls(value), self.tick, self.tick, origin) for cls in types
        }
        self.next_id += 1

    @precondition(lambda self: bool(self.model))
    @rule(data=st.data(), cls=st.sampled_from(TYPES), value=VALUES, origin=ORIGINS)
    def set(self, data: st.DataObject, cls: type[Any], value: int, origin: Origin) -> None:
        entity = data.draw(st.sampled_from(sorted(self.model)))
        component = cls(value)
        record = self.model[entity].get(cls)
        if record is None:
            self.model[entity][cls] = Record(component, self.tick, self.tick, origin)
            expected = True
        elif record.value != component:
            record.value, record.changed, record.origin = component, self.tick, origin
            expected = True
        else:
            expected = False
        assert self.world.set(Entity(entity), component, origin=origin) is expected

    @precondition(lambda self: bool(self.model))
    @rule(data=st.data(), cls=st.sampled_from(TYPES), origin=ORIGINS)
    def remove(self, data: st.DataObject, cls: type[Any], origin: Origin) -> None:
        entity = data.draw(st.sampled_from(sorted(self.model)))
        present = cls in self.model[entity]
        if present:
            del self.model[entity][cls]
            self.removals.append((self.tick, entity, cls, origin))
        assert self.world.remove(Entity(entity), cls, origin=origin) is present

    @precondition(lambda self: bool(self.model))
    @rule(data=st.data(), origin=ORIGINS)
    def despawn(self, data: st.DataObject, origin: Origin) -> None:
        entity = data.draw(st.sampled_from(sorted(self.model)))
        for cls in self.model.pop(entity):  # dicts keep insertion order, as the world does
            self.removals.append((self.tick, entity, cls, origin))
        self.removals.append((self.tick, entity, None, origin))
        self.dead.append(entity)
        self.world.despawn(Entity(entity), origin=origin)

    @rule()
    def advance(self) -> None:
        self.tick += 1
        assert self.world.advance() == self.tick

    # ------------------------------------------------------------- invariants

    @invariant()
    def entities_and_components_agree(self) -> None:
        world = self.world
        assert world.tick == self.tick
        assert world.entities() == sorted(self.model)
        for entity in self.dead:
            assert not world.is_alive(Entity(entity))
        for entity, records in self.model.items():
            for cls in TYPES:
                record = records.get(cls)
                assert world.has(Entity(entity), cls) is (record is not None)
                if record is None:
                    assert world.get(Entity(entity), cls) is None
                    continue
                assert world.get(Entity(entity), cls) == record.value
                assert world.added_tick(Entity(entity), cls) == record.added
                assert world.changed_tick(Entity(entity), cls) == record.changed
                assert world.origin_of(Entity(entity), cls) is record.origin

    @invariant()
    def queries_agree(self) -> None:
        combos = [(cls,) for cls in TYPES] + list(itertools.combinations(TYPES, 2))
        for types in combos:
            assert list(self.world.query(*types)) == self.expected(types, None, None, None)
            for since in {0, self.tick - 2, self.tick - 1}:
                for changed, added in ((True, False), (False, True), (True, True)):
                    for origin in (None, *Origin):
                        got = self.world.query(
                            *types, changed=changed, added=added, since=since, origin=origin
                        )
                        want = self.expected(types, (changed, added), since, origin)
                        assert list(got) == want
            for origin in Origin:
                got = self.world.query(*types, origin=origin)
                assert list(got) == self.expected(types, None, None, origin)

    @invariant()
    def changed_any_agrees(self) -> None:
        for cls in TYPES:
            removed = any(r[2] is cls or r[2] is None for r in self.removals)
            for since in {0, self.tick - 2, self.tick - 1}:
                want = bool(self.expected((cls,), (True, False), since, None))
                got = self.world.changed_any(cls, since=since)
                # a removed component's last change may still count: exact without removals
                assert got == want if not removed else got or not want
            assert self.world.changed_any(*TYPES, since=0) is any(
                self.world.changed_any(cls, since=0) for cls in TYPES
            )

    @invariant()
    def removal_log_agrees(self) -> None:
        for since in {0, self.tick - 1}:
            log = self.world.removals_since(since)
            want = [r for r in self.removals if r[0] > since]
            assert [(r.tick, r.entity, r.component, r.origin) for r in log] == want
            assert all(isinstance(r, Removal) for r in log)

    # ------------------------------------------------------------------ model

    def expected(
        self,
        types: tuple[type[Any], ...],
        flags: tuple[bool, bool] | None,
        since: int | None,
        origin: Origin | None,
    ) -> list[tuple[Entity, tuple[object, ...]]]:
        """Entities with all ``types`` ascending; with flags, some type passes the filter."""
        result = []
        for entity in sorted(self.model):
            records = self.model[entity]
            if not all(cls in records for cls in types):
                continue
            chosen = [records[cls] for cls in types]
            if flags is not None or origin is not None:
                changed, added = flags if flags is not None else (False, False)
                assert since is not None or flags is None

                def passes(r: Record, changed: bool = changed, added: bool = added) -> bool:
                    if origin is not None and r.origin is not origin:
                        return False
                    if flags is None:
                        return True
                    assert since is not None
                    return (changed and r.changed > since) or (added and r.added > since)

                if not any(passes(r) for r in chosen):
                    continue
            result.append((Entity(entity), tuple(r.value for r in chosen)))
        return result


WorldModel.TestCase.settings = settings(max_examples=60, stateful_step_count=30, deadline=None)
test_world_matches_reference_model = WorldModel.TestCase
