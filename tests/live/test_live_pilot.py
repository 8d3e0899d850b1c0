"""LivePilot, the console's receive path and the live operator hooks, without a browser."""

from __future__ import annotations

import threading

import pytest

from testbed.channel.mac import TELEROBOTICS_2021
from testbed.common.components import ArmRequest, ControlMode, ModeRequest, PositionSetpoint
from testbed.ecs import World
from testbed.live.hub import Hub
from testbed.live.intents import LiveImageConsole, LiveIpg, LiveRequests
from testbed.live.messages import Arm, StickInput
from testbed.live.server import _Console
from testbed.operator.live_pilot import LivePilot
from testbed.protocol import ImageSettings

CENTRE = (0.0,) * 6


class Clock:
    def __init__(self) -> None:
        self.ns = 0

    def __call__(self) -> int:
        return self.ns


def test_the_newest_sample_wins_and_its_wait_is_measured() -> None:
    clock = Clock()
    pilot = LivePilot(clock_ns=clock)
    pilot.submit((0.1, 0, 0, 0, 0, 0), received_ns=0)
    pilot.submit((0.5, 0, 0, 0, 0, -0.5), received_ns=1_000_000)
    clock.ns = 3_000_000
    assert pilot.sample(0.0).sticks == (0.5, 0, 0, 0, 0, -0.5)
    assert pilot.taken == 2
    assert list(pilot.latencies_ns) == [3_000_000, 2_000_000]
    assert pilot.sample(1.0).sticks == (0.5, 0, 0, 0, 0, -0.5)  # held without news
    assert pilot.taken == 2


def test_the_dead_man_centres_sticks_held_without_news() -> None:
    clock = Clock()
    pilot = LivePilot(hold_s=0.5, clock_ns=clock)
    pilot.submit((1.0, 0, 0, 0, 0, 0))
    clock.ns = 400_000_000
    assert pilot.sample(0.0).sticks[0] == 1.0
    clock.ns = 600_000_000
    assert pilot.sample(0.0).sticks == CENTRE
    assert pilot.timeouts == 1
    pilot.sample(0.0)
    assert pilot.timeouts == 1  # counted once


def test_samples_from_another_thread_arrive_in_order() -> None:
    pilot = LivePilot()

    def feed() -> None:
        for k in range(1000):
            pilot.submit((k / 1000, 0, 0, 0, 0, 0))

    thread = threading.Thread(target=feed)
    thread.start()
    thread.join()
    assert pilot.drain() == 1000
    assert pilot.sticks[0] == pytest.approx(0.999)


def test_hold_must_be_positive() -> None:
    with pytest.raises(ValueError):
        LivePilot(hold_s=0.0)


def _console() -> tuple[_Console, LivePilot, Hub]:
    hub, pilot = Hub(), LivePilot()
    return _Console(hub, pilot), pilot, hub


class _Socket:
    pass


def test_the_first_browser_pilots_and_the_next_one_only_watches() -> None:
    console, pilot, hub = _console()
    for _ in range(2):  # as the server does: seated, then listed
        console.connections.append(console.connect(_Socket()))  # type: ignore[arg-type]
    first, second = console.connections
    assert first.pilot and not second.pilot
    console.receive(second, '{"t": "arm", "armed": false}')
    assert hub.counters.not_pilot == 1 and hub.take() == []
    console.receive(first, '{"t": "arm", "armed": false}')
    console.receive(first, '{"t": "sticks", "x": 0.5, "y": 0, "z": 0, "yaw": 0}')
    assert [m for m, _ in hub.take()] == [Arm(False)]
    pilot.drain()
    assert pilot.sticks == StickInput(0.5, 0.0, 0.0, 0.0).sticks()
    console.leave(first)  # the pilot's tab closes: sticks centre, the viewer takes the seat
    pilot.drain()
    assert pilot.sticks == CENTRE and second.pilot
    # who flew when, for events.csv (a study with a seat handover could not tell)
    assert hub.take_seat_events() == [
        ("connect", "browser 1 as pilot"),
        ("connect", "browser 2 as viewer"),
        ("disconnect", "browser 1 (pilot) left"),
        ("seat", "browser 2 took the pilot's seat"),
    ]


def test_garbage_and_floods_are_counted_and_answered_never_raised() -> None:
    console, _, hub = _console()
    conn = console.connect(_Socket())  # type: ignore[arg-type]
    console.connections.append(conn)
    answer = console.receive(conn, "{oops")
    assert answer is not None and answer["t"] == "rejected"
    console.receive(conn, '{"t": "sticks", "x": 3, "y": 0, "z": 0, "yaw": 0}')
    for _ in range(1000):
        console.receive(conn, '{"t": "mode", "mode": "manual"}')
    counters = hub.counters
    assert counters.malformed == 1 and counters.out_of_range == 1
    assert counters.flooded > 0
    assert counters.accepted + counters.flooded == 1000
    pong = console.receive(conn, '{"t": "ping", "c": 5}')
    assert pong is None or pong["t"] == "pong"  # a ping inside the flood may be shed too


def test_live_requests_write_fresh_arm_requests_and_modes() -> None:
    world = World()
    entity = world.spawn()
    requests = LiveRequests(entity)
    requests(world)
    assert world.get(entity, ArmRequest) is None
    requests.arm(True)
    requests.mode(ControlMode.MANUAL)
    requests(world)
    first = world.get(entity, ArmRequest)
    assert first is not None and first.armed
    assert world.get(entity, ModeRequest) == ModeRequest(ControlMode.MANUAL)
    requests.arm(True)
    requests(world)
    again = world.get(entity, ArmRequest)
    assert again is not None and again.seq > first.seq  # asks again, e.g. after a failsafe


def test_pushed_image_settings_go_out_until_acknowledged() -> None:
    initial = ImageSettings(0, 0, 0, 0, 0, True, 1200)
    console = LiveImageConsole(schedule=[(0.0, initial)], max_pixels=160 * 120)
    assert console.settings_due(0.0) == initial
    roi = ImageSettings(40, 30, 119, 89, 4, True, 600)
    console.push(roi)
    assert console.settings_due(1.0) == roi
    console.settings_sent_with(True)
    assert console.settings_due(2.0) == roi  # not acknowledged yet: resent
    assert console.pushed == 1


def test_the_gap_can_be_fixed_and_restored() -> None:
    ipg = LiveIpg(TELEROBOTICS_2021)
    assert ipg.gap_after(13) == pytest.approx(13 * 8 / 175)
    ipg.set_gap(2.0)
    assert ipg.gap_after(60) == 2.0
    ipg.set_gap(None)
    assert ipg.gap_after(13) == pytest.approx(13 * 8 / 175)


def test_a_go_to_point_is_a_position_setpoint_in_guided() -> None:
    world = World()
    entity = world.spawn()
    requests = LiveRequests(entity)
    requests.goto((1.0, 2.0, 0.9))
    requests(world)
    setpoint = world.get(entity, PositionSetpoint)
    assert setpoint is not None and setpoint.position_ned_m == (1.0, 2.0, 0.9)
    assert not setpoint.use_yaw  # keeps the heading it has
    assert world.get(entity, ModeRequest) == ModeRequest(ControlMode.GUIDED)
    requests.mode(ControlMode.DEPTH_HOLD)  # any mode ends it
    requests(world)
    assert world.get(entity, ModeRequest) == ModeRequest(ControlMode.DEPTH_HOLD)
