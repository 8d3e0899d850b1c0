"""The frame store's write rule as the vehicle's kernels apply it (row_kernels.put_row, through
the compiled put_wrench): a changed row is a change the world's queries see, once, at the
writing system's tick; an unchanged row wakes no reader; the label beside the row survives.
And the vehicle's intents stay a seam: one a new controller spawns is summed with the rest."""

from __future__ import annotations

import numpy as np
import pytest

from testbed.ecs import Phase, Schedule, World
from testbed.ecs.store import FrameStore
from testbed.vehicle.components import AppliedWrench, ControlMode, ForceIntent
from testbed.vehicle.thrust_kernels import put_wrench
from testbed.vehicle.vehicle import Vehicle
from testbed.vehicle.vehicle_config import VehicleConfig

ZERO6 = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


def _world() -> tuple[World, int]:
    store = FrameStore()
    store.add(ForceIntent("", ZERO6), capacity=4)
    world = World()
    world.use_store(store)
    return world, world.spawn(ForceIntent("depth", ZERO6))


def test_a_kernel_write_is_seen_once_at_the_writers_tick_and_an_equal_one_not_at_all() -> None:
    world, intent = _world()
    row = world.row_view(intent, ForceIntent)
    wrenches = iter([(1.0, 2.0, 3.0, 0.0, 0.0, 0.0), (1.0, 2.0, 3.0, 0.0, 0.0, 0.0), ZERO6])
    seen: list[list[tuple[int, ForceIntent]]] = []

    def write(w: World) -> None:
        put_wrench(row.values, row.mark, w.tick, *next(wrenches))

    def read(w: World) -> None:
        seen.append(list(w.query1(ForceIntent, changed=True)))

    schedule = Schedule()
    schedule.add(Phase.UPDATE, write)
    schedule.add(Phase.POST_UPDATE, read)
    schedule.run(world)  # the spawn, and the first write: one change
    first_write_tick = world.changed_tick(intent, ForceIntent)
    schedule.run(world)  # the same wrench again: nothing
    schedule.run(world)  # back to zero: a change
    assert seen == [
        [(intent, ForceIntent("depth", (1.0, 2.0, 3.0, 0.0, 0.0, 0.0)))],
        [],
        [(intent, ForceIntent("depth", ZERO6))],
    ]
    assert first_write_tick == schedule.last_run_tick("write") - 2 * 2  # two frames earlier


def test_row_view_names_store_backed_components_only() -> None:
    world, intent = _world()
    assert world.row_view(intent, ForceIntent).values.shape == (6,)
    other = world.spawn()
    with pytest.raises(LookupError, match="has no ForceIntent"):
        world.row_view(other, ForceIntent)
    plain = World()
    entity = plain.spawn(ForceIntent("pilot", ZERO6))
    with pytest.raises(LookupError, match="not kept in a frame store"):
        plain.row_view(entity, ForceIntent)


def test_an_intent_a_new_controller_spawns_is_summed_into_the_allocation() -> None:
    """The seam for new controllers: an intent entity spawned and set from Python joins the
    vehicle's store-backed intents, and the allocation asks for the sum of all of them."""
    with Vehicle(VehicleConfig(), np.random.default_rng(0)) as vehicle:
        vehicle.arm()
        vehicle.set_mode(ControlMode.MANUAL)  # no loop adds a wrench; sticks at rest
        push = vehicle.world.spawn(ForceIntent("disturbance", (10.0, 0.0, 0.0, 0.0, 0.0, 0.0)))
        vehicle.advance(0.5)
        vehicle.world.set(push, ForceIntent("disturbance", (10.0, -4.0, 0.0, 0.0, 0.0, 1.5)))
        vehicle.advance(1.0)
        applied = vehicle.world.get(vehicle.entity, AppliedWrench)
        assert applied is not None
        assert applied.requested == (10.0, -4.0, 0.0, 0.0, 0.0, 1.5)
        assert vehicle.state().nu[0] > 0.05  # it surges ahead
