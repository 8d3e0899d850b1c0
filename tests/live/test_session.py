"""LiveSession's hooks applied to a built (not running) session: the link model changes, the
orders queue up, refusals are recorded, and the console's state is plain JSON.

The sessions these tests run (no console, no modem, no wall-clock figure asserted) run
unpaced (the ``unpaced`` fixture): what they check happens in simulated time, the same whether
the real-time clock waits for the wall clock or not (the session's clock is ``strict=False``,
so running ahead of or behind it changes nothing but the waiting). The real-time sessions are
test_browser.py's, test_console_page.py's and test_hil_live.py's."""

from __future__ import annotations

import json
import math
from collections.abc import Iterator
from pathlib import Path

import pytest
import simpy.rt

from testbed.common.components import ControlMode, ModeRequest
from testbed.live.console_state import console_state
from testbed.live.hub import Hub
from testbed.live.messages import (
    Arm,
    GoToPoint,
    ImageRequest,
    LinkChange,
    Outage,
    SetMode,
)
from testbed.live.session import GOTO_NO_FIX, GOTO_REFUSED, LiveSession
from testbed.run.failures import partial_run
from testbed.run.scenario import load_scenario
from testbed.vehicle.control_laws import ControlLawError


class _Unpaced(simpy.rt.RealtimeEnvironment):
    """simpy's real-time environment at factor 0: every event is due at the instant the clock
    started, so it never sleeps; events run in the same order at the same simulated times."""

    def __init__(self, initial_time: float = 0, factor: float = 1.0, strict: bool = True) -> None:
        del factor
        super().__init__(initial_time, factor=0.0, strict=strict)


@pytest.fixture
def unpaced(monkeypatch: pytest.MonkeyPatch) -> None:
    """Sessions built in the test run unpaced (:class:`_Unpaced`)."""
    monkeypatch.setattr(simpy.rt, "RealtimeEnvironment", _Unpaced)


@pytest.fixture(scope="module")
def session() -> Iterator[LiveSession]:
    built = LiveSession(load_scenario("s100-video-v1"), Hub(), pilot=None)
    yield built
    built.vehicle.close()


def test_link_controls_change_the_running_model(session: LiveSession) -> None:
    medium, ipg = session.medium, session.ipg
    assert medium is not None and ipg is not None
    session.apply(LinkChange("ber", 1e-3))
    assert medium.config.ber == 1e-3
    session.apply(LinkChange("gap_s", 2.0))
    assert ipg.gap_after(13) == 2.0
    session.apply(LinkChange("gap_s", None))
    assert ipg.gap_after(13) == pytest.approx(13 * 8 / 175)
    session.apply(LinkChange("distance_m", 300.0))
    operator, vehicle = session._operator_position(), session.vehicle.truth.position_ned_m
    assert math.dist(operator, vehicle) == pytest.approx(300.0)
    session.apply(LinkChange("distance_m", None))
    assert session._operator_position() == session.scenario.link.operator_position_ned_m
    session.apply(Outage(3.0))
    assert medium.in_outage(1.0, 1.0) and not medium.in_outage(3.5, 4.0)
    keys = [change["key"] for change in session.link_changes]
    assert keys == ["ber", "gap_s", "gap_s", "distance_m", "distance_m", "outage"]
    assert (
        sum(e.node == "live" and e.kind.startswith("link_") for e in session.recorder.events) == 6
    )


def test_orders_and_refusals(session: LiveSession) -> None:
    console = session.image_console
    assert console is not None
    session.apply(ImageRequest((40, 30, 119, 89), 4, 600))
    settings = console.settings_due(0.0)
    assert settings is not None and (settings.x0, settings.roi_shift) == (40, 4)
    session.apply(ImageRequest(None, 7, 900))
    cleared = console.settings_due(0.0)
    assert cleared is not None and (cleared.x1, cleared.roi_shift, cleared.budget_bytes) == (
        0,
        0,
        900,
    )
    session.apply(Arm(False))
    session.apply(SetMode("manual"))
    session.apply(GoToPoint(1.0, 2.0))
    kinds = [e.kind for e in session.recorder.events if e.node == "live"]
    assert {"disarm_request", "mode_request", "goto_refused"} <= set(kinds)
    assert GOTO_REFUSED in session.hub.notes


def test_the_state_is_plain_json(session: LiveSession) -> None:
    state = session.state()
    text = json.dumps(state, allow_nan=False)
    assert json.loads(text)["link"]["simulated"] is True
    assert state["truth"]["failsafe"] == "NOMINAL"


@pytest.mark.parametrize(
    ("name", "refused"), [("s100-thruster-failure-v1", True), ("s100-supervised-v1", False)]
)
def test_a_goto_to_a_vehicle_that_knows_no_position_is_refused_with_a_note(
    name: str, refused: bool, unpaced: None
) -> None:
    """A review's click went out as a GoTo and left the vehicle in GUIDED holding still, with
    nothing said: a vehicle with no position fix and no navigation cannot fly to a point (its
    position loop has nothing to close on). One with navigation (the supervised mission's)
    takes the order."""
    session = LiveSession(load_scenario(name), Hub(), pilot=None)
    try:
        env = session.env
        env.process(session.vehicle_node.run())
        env.process(session.operator_node.run())
        env.run(until=3.0)  # a reply has come: the depth to hold is known
        assert session.station.vehicle_odometry() is not None
        session.apply(GoToPoint(1.0, 0.5))
        kinds = [e.kind for e in session.recorder.events if e.node == "live"]
        assert kinds[-1] == ("goto_refused" if refused else "goto_sent")
        assert (GOTO_NO_FIX in session.hub.notes) is refused
    finally:
        session.vehicle.close()


def test_the_console_says_the_mode_asked_at_once_and_the_last_asked_is_the_one_sent(
    unpaced: None,
) -> None:
    """The state's ``pilot.mode`` is the session plan's mode until the pilot asks, then the
    mode asked, from the moment the message is taken (the menu shows it, not a stale one until
    the next operator frame); a go-to asks GUIDED; asked in one frame, the later ask wins: a
    go-to after a mode request flies the go-to, a mode request after a go-to ends it."""
    session = LiveSession(load_scenario("s100-supervised-v1"), Hub(), pilot=None)
    try:
        env = session.env
        env.process(session.vehicle_node.run())
        env.process(session.operator_node.run())
        env.run(until=3.0)  # a reply has come: a go-to's depth is known
        planned = session.scenario.operator.mode  # "depth_hold" here, as the menu's names
        assert console_state(session)["pilot"]["mode"] == planned
        world, entity = session.station.world, session.station.entity
        for messages, expected in (
            ([SetMode("stabilize")], ControlMode.STABILIZE),
            ([SetMode("manual"), GoToPoint(1.0, 0.5)], ControlMode.GUIDED),
            ([GoToPoint(1.0, 0.5), SetMode("depth_hold")], ControlMode.DEPTH_HOLD),
        ):
            for message in messages:
                session.apply(message)
            assert console_state(session)["pilot"]["mode"] == expected.name.lower()
            env.run(until=env.now + 0.7)  # an operator frame (≈ 0.3 s apart) writes it
            assert world.get(entity, ModeRequest).mode is expected
    finally:
        session.vehicle.close()


def test_a_vehicle_under_autonomy_gives_no_stick_to_vehicle_latency() -> None:
    """s100-supervised-v1's vehicle flies its mission: a stick change it receives is not one
    it applies, so it is not a latency sample (a review saw p50 378 ms while rx_x stayed 0);
    the same change on s100-teleop-v1's vehicle is one."""
    from testbed.vehicle.resources import Controllers

    pushed = (0.5, 0.0, 0.0, 0.0, 0.0, 0.0)
    for name, samples in (("s100-supervised-v1", 0), ("s100-teleop-v1", 1)):
        session = LiveSession(load_scenario(name), Hub(), pilot=None)
        try:
            session.pilot.submit(pushed)
            session.pilot.drain()
            session._watch_sticks()  # the change is seen
            session.vehicle.world.resource(Controllers).sticks = pushed  # … and received
            session._watch_sticks()
            assert len(session.stick_lags_s) == samples, name
        finally:
            session.vehicle.close()


def test_a_law_of_ones_own_that_raises_part_way_keeps_what_ran(
    tmp_path: Path, unpaced: None
) -> None:
    """As ``testbed run`` and ``testbed hil``: the error is raised carrying the session up to it
    (it raised with a traceback and nothing kept), as a ControlLawError naming the law, the
    method and the law's own error (which causes it). The scenario arms in depth hold by itself, so
    the law flies, and raises, without a console."""
    (tmp_path / "my_laws.py").write_text(
        "class Boom:\n"
        "    def reset(self):\n"
        "        pass\n\n"
        "    def update(self, target, depth, imu, dt_s):\n"
        "        raise RuntimeError('boom in the law')\n"
    )
    law = f"vehicle.control.depth={tmp_path / 'my_laws.py'}:Boom"
    session = LiveSession(load_scenario("s100-teleop-v1", [law]), Hub(), pilot=None)
    with pytest.raises(ControlLawError, match="boom in the law") as raised:
        session.run(60.0)
    assert str(raised.value) == (
        f"depth law Boom ({tmp_path / 'my_laws.py'}): update raised RuntimeError: boom in the law"
    )
    causes = [
        raised.value.__cause__,
        getattr(raised.value.__cause__, "__cause__", None),
    ]  # simpy's copy
    assert any(isinstance(c, RuntimeError) for c in causes)  # the law's own, traced
    partial = partial_run(raised.value)
    assert partial is not None and partial.failure is not None
    assert partial.failure.startswith(f"ControlLawError: {raised.value} (at ")
    assert 0.0 < partial.metrics["sim_s"] < 60.0
    assert partial.metrics["inputs"]["depth_law"]["factory"].endswith("my_laws.py:Boom")
    last = partial.recorder.events[-1]
    assert (last.node, last.kind) == ("testbed", "failed")


def test_a_half_duplex_link_counts_its_deaf_losses_in_the_panel_and_the_metrics(
    unpaced: None,
) -> None:
    """On s2c the vehicle's replies outlast the token gap: each is lost to ``deaf`` (the
    operator transmitting the next order). The panel counts them as collided, and metrics.json
    has them as collided and as ``copies_lost_transmitting``, as ``testbed run`` writes it
    (a live session lacked that key). Truth: the trace's ``deaf`` events."""
    scenario = load_scenario("s100-teleop-v1", ["link.preset=s2c"])
    session = LiveSession(scenario, Hub(), pilot=None)
    result = session.run(3.0)
    deaf = {
        direction: sum(
            1
            for event in result.recorder.trace.events
            if event.src == src and str(event.kind) == "deaf"
        )
        for direction, src in (("uplink", "operator"), ("downlink", "vehicle"))
    }
    assert deaf["downlink"] > 0
    panel = session.state()["link"]["downlink"]
    downlink = result.metrics["link"]["downlink"]
    assert panel["collided"] == downlink["frames_collided"] == deaf["downlink"]
    for direction, count in deaf.items():
        assert result.metrics["link"][direction]["copies_lost_transmitting"] == count
