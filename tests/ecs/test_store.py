"""testbed.ecs.store: store-backed columns behave as plain ones, and a frame's row writes are
seen as changes.

The reference-model state machine of ``test_world_model.py`` runs again on a world that keeps
two of its three types in a :class:`FrameStore`, with one more rule: a write straight into a
table row and its mark (tick and write count), as a compiled frame makes it (the model records
it as a change at the present tick, the origin left as it was), also at the tick of a Python
``set`` just made. Every invariant of that test must hold after every step.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest
from hypothesis import settings
from hypothesis import strategies as st
from hypothesis.stateful import precondition, rule

from testbed.ecs import Entity, World
from testbed.ecs.store import FrameStore, Layout, Table
from tests.ecs.test_world_model import TYPES, VALUES, A, B, WorldModel

STORED = (A, B)


class StoredWorldModel(WorldModel):
    def __init__(self) -> None:
        super().__init__()
        self.store = FrameStore()
        for cls in STORED:
            self.store.add(cls(0), capacity=256)
        self.world = World()
        self.world.use_store(self.store)

    @precondition(lambda self: any(cls in r for r in self.model.values() for cls in STORED))
    @rule(data=st.data(), value=VALUES)
    def frame_writes_a_row(self, data: st.DataObject, value: int) -> None:
        """A compiled frame's write: the row's field, then its mark, only for a new value."""
        cls = data.draw(st.sampled_from(STORED))
        holders = sorted(e for e, records in self.model.items() if cls in records)
        if not holders:
            return
        entity = data.draw(st.sampled_from(holders))
        record = self.model[entity][cls]
        if record.value == cls(value):
            return  # a frame leaves an unchanged row alone
        table = self.store.table(cls)
        row = _row_of(self.world, Entity(entity), cls)
        table.values[row, 0] = value
        frame_marks(table, row, self.tick)
        record.value, record.changed = cls(value), self.tick


def frame_marks(table: Table, row: int, tick: int) -> None:
    """What a compiled frame writes after a row's fields: the tick and one more write."""
    table.marks[row] = (tick, table.marks[row, 1] + 1)


def _row_of(world: World, entity: Entity, cls: type[Any]) -> int:
    slot = world._columns[cls].slots[entity]
    return int(slot._row)  # type: ignore[attr-defined]


assert set(STORED) < set(TYPES)  # the third type stays a plain column beside them
StoredWorldModel.TestCase.settings = settings(
    max_examples=60, stateful_step_count=30, deadline=None
)
test_a_store_backed_world_matches_the_reference_model = StoredWorldModel.TestCase


class Mode(enum.Enum):
    MANUAL = "manual"
    HOLD = "hold"


@dataclass(frozen=True, slots=True)
class Reading:
    time_s: float
    quaternion_wxyz: tuple[float, float, float, float]
    seq: int
    armed: bool
    mode: Mode


PROTOTYPE = Reading(0.0, (1.0, 0.0, 0.0, 0.0), 0, False, Mode.MANUAL)


def test_every_field_kind_goes_through_a_row_and_back() -> None:
    layout = Layout(PROTOTYPE)
    assert layout.width == 1 + 4 + 1 + 1 + 1
    row = np.zeros(layout.width)
    value = Reading(12.5, (0.5, -0.5, 0.5, -0.5), 2**53, True, Mode.HOLD)
    assert layout.write(row, value) == ()
    assert row.tolist() == [12.5, 0.5, -0.5, 0.5, -0.5, 2.0**53, 1.0, 1.0]
    back = layout.read(row)
    assert back == value and type(back.seq) is int and type(back.armed) is bool  # type: ignore[attr-defined]


def test_a_value_set_from_python_is_the_object_get_returns_until_a_frame_writes() -> None:
    store = FrameStore()
    table = store.add(PROTOTYPE, capacity=2)
    world = World()
    world.use_store(store)
    value = Reading(1.0, (1.0, 0.0, 0.0, 0.0), 3, True, Mode.HOLD)
    entity = world.spawn(value)
    assert world.get(entity, Reading) is value
    assert world.set(entity, Reading(1.0, (1.0, 0.0, 0.0, 0.0), 3, True, Mode.HOLD)) is False
    assert world.get(entity, Reading) is value  # an equal value records nothing, keeps the object
    world.advance()
    table.values[0, 0] = 2.0  # a frame's write: the field, then its mark
    frame_marks(table, 0, world.tick)
    got = world.get(entity, Reading)
    assert got == Reading(2.0, (1.0, 0.0, 0.0, 0.0), 3, True, Mode.HOLD)
    assert world.get(entity, Reading) is got  # built once per change
    assert world.changed_tick(entity, Reading) == world.tick
    assert list(world.query(Reading, changed=True, since=world.tick - 1)) == [(entity, (got,))]


def test_rows_are_freed_and_reused_and_a_full_table_says_so() -> None:
    store = FrameStore()
    table = store.add(PROTOTYPE, capacity=2)
    world = World()
    world.use_store(store)
    first = world.spawn(PROTOTYPE)
    second = world.spawn(PROTOTYPE)
    with pytest.raises(RuntimeError, match="Reading table is full \\(2 rows\\)"):
        world.spawn(PROTOTYPE)
    world.despawn(first)
    assert table.ticks.tolist() == [0, 1]  # the first row is free again
    third = world.spawn(Reading(5.0, (1.0, 0.0, 0.0, 0.0), 1, False, Mode.MANUAL))
    assert table.values[0, 0] == 5.0 and world.get(third, Reading).time_s == 5.0  # type: ignore[union-attr]
    assert world.get(second, Reading) == PROTOTYPE


@dataclass(frozen=True, slots=True)
class Labelled:
    source: str
    wrench: tuple[float, float]


def test_a_label_is_kept_beside_its_row_and_survives_a_frames_write() -> None:
    store = FrameStore()
    table = store.add(Labelled("", (0.0, 0.0)), capacity=2)
    assert table.layout.width == 2
    world = World()
    world.use_store(store)
    pilot = world.spawn(Labelled("pilot", (1.0, 2.0)))
    depth = world.spawn(Labelled("depth", (0.0, 0.0)))
    world.advance()
    table.values[0] = (3.0, 4.0)  # a frame writes the wrench, never the label
    frame_marks(table, 0, world.tick)
    assert world.get(pilot, Labelled) == Labelled("pilot", (3.0, 4.0))
    assert world.get(depth, Labelled) == Labelled("depth", (0.0, 0.0))
    with pytest.raises(TypeError, match=r"Labelled\.source: a str, got 7"):
        world.set(depth, Labelled(7, (0.0, 0.0)))  # type: ignore[arg-type]


def test_fields_a_table_cannot_hold_and_late_stores_are_refused() -> None:
    @dataclass(frozen=True, slots=True)
    class Listed:
        names: list[str]

    with pytest.raises(TypeError, match=r"Listed\.names: a table holds floats"):
        FrameStore().add(Listed(["pilot"]))
    store = FrameStore()
    store.add(PROTOTYPE)
    with pytest.raises(ValueError, match="already has a table"):
        store.add(PROTOTYPE)
    world = World()
    world.spawn(PROTOTYPE)
    with pytest.raises(ValueError, match="Reading already has a column in this world"):
        world.use_store(store)
    store2 = FrameStore()
    store2.add(PROTOTYPE)
    fresh = World()
    fresh.use_store(store2)
    entity = fresh.spawn(PROTOTYPE)
    with pytest.raises(ValueError, match=r"Reading\.quaternion_wxyz: 4 values, got 3"):
        fresh.set(entity, Reading(0.0, (1.0, 0.0, 0.0), 0, False, Mode.MANUAL))  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="beyond"):
        fresh.set(entity, Reading(0.0, (1.0, 0.0, 0.0, 0.0), 2**60, False, Mode.MANUAL))
