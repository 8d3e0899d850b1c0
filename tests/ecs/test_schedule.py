"""testbed.ecs.schedule: phase order, tick advance, and "each change seen exactly once"."""

from __future__ import annotations

from dataclasses import dataclass

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from testbed.ecs import Entity, Phase, Schedule, World


@dataclass(frozen=True, slots=True)
class Command:
    value: int


def test_phases_run_in_order_and_systems_in_added_order() -> None:
    ran: list[str] = []

    def make(label: str) -> object:
        def system(world: World) -> None:
            ran.append(label)

        return system

    schedule = Schedule()
    plan = [
        (Phase.POST_UPDATE, "post_a"),
        (Phase.UPDATE, "update_a"),
        (Phase.PRE_UPDATE, "pre_a"),
        (Phase.POST_UPDATE, "post_b"),
        (Phase.PRE_UPDATE, "pre_b"),
        (Phase.UPDATE, "update_b"),
    ]
    for phase, label in plan:
        schedule.add(phase, make(label), name=label)  # type: ignore[arg-type]  # closure
    world = World()
    schedule.run(world)
    expected = ["pre_a", "pre_b", "update_a", "update_b", "post_a", "post_b"]
    assert ran == expected
    assert schedule.names() == expected
    assert schedule.names(Phase.UPDATE) == ["update_a", "update_b"]
    assert [int(p) for p in Phase] == [0, 1, 2]


def test_add_rejects_bad_phase_duplicate_name_and_non_callables() -> None:
    def read_sensors(world: World) -> None:
        pass

    schedule = Schedule()
    schedule.add(Phase.PRE_UPDATE, read_sensors)
    assert schedule.names() == ["read_sensors"]
    with pytest.raises(ValueError, match="read_sensors"):
        schedule.add(Phase.UPDATE, read_sensors)
    schedule.add(Phase.UPDATE, read_sensors, name="read_sensors_again")
    with pytest.raises(TypeError):
        schedule.add(1, read_sensors, name="x")  # type: ignore[arg-type]  # misuse on purpose
    with pytest.raises(TypeError):
        schedule.add(Phase.UPDATE, 3, name="y")  # type: ignore[arg-type]  # misuse on purpose


def test_each_system_runs_at_its_own_tick_and_the_tick_advances_per_system() -> None:
    seen: list[tuple[str, int, int]] = []

    def pre(world: World) -> None:
        seen.append(("pre", world.tick, world.last_run_tick))

    def post(world: World) -> None:
        seen.append(("post", world.tick, world.last_run_tick))

    schedule = Schedule()
    schedule.add(Phase.PRE_UPDATE, pre)
    schedule.add(Phase.POST_UPDATE, post)
    world = World()
    world.last_run_tick = 77  # the caller's value, restored after each frame
    schedule.run(world)
    assert world.tick == 3
    assert world.last_run_tick == 77
    schedule.run(world)
    assert world.tick == 5
    assert seen == [("pre", 1, 0), ("post", 2, 0), ("pre", 3, 1), ("post", 4, 2)]
    assert schedule.last_run_tick("pre") == 3
    assert schedule.last_run_tick("post") == 4
    with pytest.raises(KeyError):
        schedule.last_run_tick("nope")


def _changed_values(world: World) -> list[int]:
    return [command.value for _, command in world.query1(Command, changed=True)]


def test_update_write_is_seen_by_post_same_frame_and_pre_next_frame_once() -> None:
    entity_box: list[Entity] = []
    pre_seen: list[list[int]] = []
    post_seen: list[list[int]] = []
    frame = [0]

    def read_inputs(world: World) -> None:
        pre_seen.append(_changed_values(world))

    def decide_command(world: World) -> None:
        if frame[0] in (1, 4):  # writes on frames 1 and 4 only
            world.set(entity_box[0], Command(frame[0]))
        world.set(entity_box[0], world.get_or(entity_box[0], Command, Command(0)))  # no-op

    def send_outputs(world: World) -> None:
        post_seen.append(_changed_values(world))

    world = World()
    entity_box.append(world.spawn(Command(0)))
    schedule = Schedule()
    schedule.add(Phase.POST_UPDATE, send_outputs)
    schedule.add(Phase.UPDATE, decide_command)
    schedule.add(Phase.PRE_UPDATE, read_inputs)
    for k in range(7):
        frame[0] = k
        schedule.run(world)
    # Frame k: PRE sees the writes of frame k-1's UPDATE; POST those of frame k's UPDATE.
    # Frame 0: the spawned value is news to both (neither has run before).
    assert post_seen == [[0], [1], [], [], [4], [], []]
    assert pre_seen == [[0], [], [1], [], [], [4], []]


def test_a_later_system_in_the_same_phase_is_seen_next_frame_by_an_earlier_one() -> None:
    seen: list[list[int]] = []
    frame = [0]

    def first(world: World) -> None:
        seen.append(_changed_values(world))

    def second(world: World) -> None:
        world.set(Entity(1), Command(frame[0] * 10))

    world = World()
    world.spawn(Command(0))
    schedule = Schedule()
    schedule.add(Phase.UPDATE, first)
    schedule.add(Phase.UPDATE, second)
    for k in range(4):
        frame[0] = k
        schedule.run(world)
    # Frame 0: everything is new to `first` (spawned before its first run).
    assert seen == [[0], [], [10], [20]]


def test_a_system_does_not_see_its_own_earlier_writes_but_sees_external_ones() -> None:
    seen: list[list[int]] = []
    frame = [0]

    def write_then_read(world: World) -> None:
        seen.append(_changed_values(world))
        world.set(Entity(1), Command(100 + frame[0]))

    world = World()
    world.spawn(Command(0))
    schedule = Schedule()
    schedule.add(Phase.UPDATE, write_then_read)
    schedule.run(world)
    frame[0] = 1
    schedule.run(world)
    world.set(Entity(1), Command(7))  # a node ingesting between frames
    frame[0] = 2
    schedule.run(world)
    schedule.run(world)
    assert seen == [[0], [], [7], []]


def test_a_failing_system_keeps_its_last_run_tick_and_the_world_is_restored() -> None:
    seen: list[list[int]] = []
    fail = [True]

    def flaky_reader(world: World) -> None:
        seen.append(_changed_values(world))
        if fail[0]:
            raise RuntimeError("boom")

    world = World()
    world.spawn(Command(5))
    world.last_run_tick = 9
    schedule = Schedule()
    schedule.add(Phase.UPDATE, flaky_reader)
    with pytest.raises(RuntimeError):
        schedule.run(world)
    assert world.last_run_tick == 9
    assert world.tick == 2
    fail[0] = False
    schedule.run(world)
    schedule.run(world)
    assert seen == [[5], [5], []]


def test_a_schedule_belongs_to_one_world() -> None:
    schedule = Schedule()
    schedule.run(World())
    with pytest.raises(ValueError, match="another world"):
        schedule.run(World())


# A random frame plan: per frame, writes made between frames and by each system
# (entity index, value); values from a tiny set so many writes are no-op equal writes.
_WRITE = st.tuples(st.integers(0, 3), st.integers(0, 2))
_WRITES = st.lists(_WRITE, max_size=3)


@settings(max_examples=60, deadline=None)
@given(
    phases=st.lists(st.sampled_from(list(Phase)), min_size=1, max_size=5),
    frames=st.data(),
    frame_count=st.integers(1, 6),
)
def test_every_system_sees_every_change_exactly_once(
    phases: list[Phase], frames: st.DataObject, frame_count: int
) -> None:
    """Reference model: a per-system set of entities changed by anyone else since its last run."""
    n = len(phases)
    world = World()
    entities = [world.spawn(Command(0)) for _ in range(4)]
    # Model: every system has seen nothing yet, so all four spawned entities are news to it.
    model_values = {e: 0 for e in entities}
    dirty: list[set[Entity]] = [set(entities) for _ in range(n)]
    plan: list[list[list[tuple[int, int]]]] = []
    observed: list[list[tuple[Entity, int]]] = [[] for _ in range(n)]
    expected: list[list[tuple[Entity, int]]] = [[] for _ in range(n)]

    def model_write(writer: int | None, index: int, value: int) -> None:
        entity = entities[index]
        if model_values[entity] != value:
            model_values[entity] = value
            for j in range(n):
                if j != writer:
                    dirty[j].add(entity)

    def make(i: int) -> object:
        def system(world: World) -> None:
            observed[i].extend((e, c.value) for e, c in world.query1(Command, changed=True))
            for index, value in plan[-1][i]:
                world.set(entities[index], Command(value))

        return system

    schedule = Schedule()
    for i, phase in enumerate(phases):
        schedule.add(phase, make(i), name=f"system_{i}")  # type: ignore[arg-type]  # closure
    order = sorted(range(n), key=lambda i: (phases[i], i))  # stable: phase, then added order
    for _ in range(frame_count):
        external = frames.draw(_WRITES)
        plan.append([frames.draw(_WRITES) for _ in range(n)])
        for index, value in external:
            world.set(entities[index], Command(value))
            model_write(None, index, value)
        schedule.run(world)
        for i in order:  # replay the frame on the model
            expected[i].extend((e, model_values[e]) for e in sorted(dirty[i]))
            dirty[i].clear()
            for index, value in plan[-1][i]:
                model_write(i, index, value)
    assert observed == expected
