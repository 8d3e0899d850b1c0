"""``sys.exit`` in a law or pilot of the user's during a real-time run (``testbed hil``,
``live``, ``mavlink`` direct and through the gateway) keeps what ran, as any error there does.

Each run mode caught the user's errors as ``Exception``; ``SystemExit`` went past, out of the
command, with nothing of the session kept. Now it is raised as a
:class:`~testbed.run.failures.RunExit` (naming the user's line) carrying the partial result, as
``testbed run`` does (tests/run/test_plugin_exits.py). The sessions are those of the tests of
a law that raises (tests/live/test_session.py, tests/mavlink/test_failed_runs.py) and of a
pilot that raises over emulated modems (tests/run/test_failed_runs.py).
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mav

from testbed.live.hub import Hub
from testbed.live.session import LiveSession
from testbed.run.failures import RunExit, partial_run
from testbed.run.mavlink_gateway import run_gateway
from testbed.run.mavlink_run import run_mavlink
from testbed.run.runner import RunResult
from testbed.run.scenario import load_scenario
from tests.mavlink.rt_session import GatewaySession
from tests.run.test_plugins import write_study

LAW = """
import sys


class Quitter:
    def reset(self):
        pass

    def update(self, target, depth, imu, dt_s):
        sys.exit("the law gave up")
"""

PILOT = """
import sys

from testbed.operator.pilots import PilotSample


class Quitter:
    def __init__(self, at_s=2.0):
        self.at_s = at_s

    def sample(self, t_s):
        if t_s > self.at_s:
            sys.exit("the pilot gave up")
        return PilotSample((0.0,) * 6)
"""


def _check(error: BaseException | None, file: Path, line: int, said: str) -> RunResult:
    assert isinstance(error, RunExit) and error.code == said
    partial = partial_run(error)
    assert partial is not None and partial.failure is not None
    assert partial.failure == (
        f"RunExit: sys.exit({said!r}) called during the run (at {file}:{line})"
    )
    last = partial.recorder.events[-1]
    assert (last.node, last.kind) == ("testbed", "failed")
    return partial


def _law(tmp_path: Path) -> tuple[Path, list[str]]:
    laws = tmp_path / "my_laws.py"
    laws.write_text(LAW)
    return laws, [f"vehicle.control.depth={laws}:Quitter"]


LAW_LINE = LAW.split("\n").index('        sys.exit("the law gave up")') + 1
PILOT_LINE = PILOT.split("\n").index('            sys.exit("the pilot gave up")') + 1


def test_a_live_session_whose_law_calls_sys_exit_keeps_what_ran(tmp_path: Path) -> None:
    """s100-teleop-v1 arms in depth hold by itself, so the law flies without a console."""
    laws, overrides = _law(tmp_path)
    session = LiveSession(load_scenario("s100-teleop-v1", overrides), Hub(), pilot=None)
    with pytest.raises(RunExit) as raised:
        session.run(60.0)
    partial = _check(raised.value, laws, LAW_LINE, "the law gave up")
    assert 0.0 < partial.metrics["sim_s"] < 60.0


Runner = Callable[..., RunResult]


@pytest.mark.parametrize("run", [run_mavlink, run_gateway], ids=["direct", "gateway"])
def test_a_mavlink_run_whose_law_calls_sys_exit_keeps_what_ran(run: Runner, tmp_path: Path) -> None:
    laws, overrides = _law(tmp_path)
    scenario = load_scenario("s100-teleop-v1", overrides)

    def go(links: list[Any], stop: Any) -> RunResult:
        return run(scenario, links, duration_s=60.0, stop=stop)

    session = GatewaySession(go)
    try:
        session.gcs.wait_heartbeat(timeout=session.wait_s)
        session.gcs.mav.command_long_send(
            1, 1, mav.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0
        )
        session.gcs.mav.command_long_send(1, 1, mav.MAV_CMD_DO_SET_MODE, 0, 1, 2, 0, 0, 0, 0, 0)
        session.until(lambda: not session.thread.is_alive())  # the law flies in ALT_HOLD, exits
    finally:
        session.close()
    partial = _check(session.error, laws, LAW_LINE, "the law gave up")
    assert 0.0 < partial.metrics["sim_s"] < 60.0


def test_a_hil_run_whose_pilot_calls_sys_exit_keeps_what_ran_and_closes_the_ports(
    tmp_path: Path,
) -> None:
    """run_hil over emulated EvoLogics modems: the pilot exiting 2 s in ends the session with
    a RunExit carrying what ran (to ≈ 2 s of real time), both ports closed."""
    from testbed.channel import load_link_config
    from testbed.emulator.ptys import ModemEmulator
    from testbed.hil import PortSettings, open_endpoint
    from testbed.run.realtime import run_hil

    study = write_study(tmp_path / "study")
    pilots = study / "quitters.py"
    pilots.write_text(PILOT)
    config = load_link_config("s2c", ["intrinsic_delay_s=0.05"])
    short = ["metrics.settle_s=1", "link.ipg=fixed", "link.ipg_s=0.3"]
    quitter = [f"pilot.factory={pilots}:Quitter", "pilot.args={at_s=2.0}"]
    with ModemEmulator(config, seed=0, modem="evologics") as emulator:
        path_a, path_b = emulator.paths
        endpoints = {
            "operator": open_endpoint(PortSettings(path_a, "evologics", "operator")),
            "vehicle": open_endpoint(PortSettings(path_b, "evologics", "vehicle")),
        }
        scenario = load_scenario(str(study / "step.toml"), [*short, *quitter])
        with pytest.raises(RunExit) as raised:
            run_hil(scenario, endpoints, duration_s=4.0, modem="evologics")
    partial = _check(raised.value, pilots, PILOT_LINE, "the pilot gave up")
    assert 2.0 < partial.metrics["sim_s"] < 4.0
    assert [t.name for t in threading.enumerate() if t.name.startswith("serial:")] == []
