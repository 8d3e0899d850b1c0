"""A control law of the user's own that raises part way through a MAVLink run (direct and
through the narrow link's gateway): the error is raised carrying what ran, as ``testbed run``
and ``testbed hil`` keep it (:mod:`testbed.run.failures`), and ``testbed mavlink`` writes it.

Real time on 127.0.0.1, pymavlink as the ground station; the waits are failure bounds only.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mav

from testbed.run.failures import partial_run
from testbed.run.mavlink_gateway import run_gateway
from testbed.run.mavlink_run import run_mavlink
from testbed.run.runner import RunResult
from testbed.run.scenario import load_scenario
from testbed.vehicle.control_laws import ControlLawError
from tests.mavlink.rt_session import GatewaySession

LAW = """
class Boom:
    def reset(self):
        pass

    def update(self, target, depth, imu, dt_s):
        raise RuntimeError("boom in the law")
"""

Runner = Callable[..., RunResult]


@pytest.mark.parametrize("run", [run_mavlink, run_gateway], ids=["direct", "gateway"])
def test_a_law_that_raises_part_way_keeps_what_ran(run: Runner, tmp_path: Path) -> None:
    (tmp_path / "my_laws.py").write_text(LAW)
    scenario = load_scenario(
        "s100-teleop-v1", [f"vehicle.control.depth={tmp_path / 'my_laws.py'}:Boom"]
    )

    def go(links: list[Any], stop: Any) -> RunResult:
        return run(scenario, links, duration_s=60.0, stop=stop)

    session = GatewaySession(go)
    try:
        session.gcs.wait_heartbeat(timeout=session.wait_s)
        session.gcs.mav.command_long_send(
            1, 1, mav.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0
        )
        session.gcs.mav.command_long_send(1, 1, mav.MAV_CMD_DO_SET_MODE, 0, 1, 2, 0, 0, 0, 0, 0)
        session.until(lambda: not session.thread.is_alive())  # the law flies in ALT_HOLD, raises
    finally:
        session.close()
    error = session.error
    assert isinstance(error, ControlLawError)  # one line naming the law, exit 2 on the CLI
    laws = tmp_path / "my_laws.py"
    assert str(error) == f"depth law Boom ({laws}): update raised RuntimeError: boom in the law"
    causes = [error.__cause__, getattr(error.__cause__, "__cause__", None)]  # simpy's copy
    assert any(isinstance(c, RuntimeError) for c in causes)  # the law's own, traced
    partial = partial_run(error)
    assert partial is not None
    assert partial.failure is not None
    assert partial.failure.startswith(f"ControlLawError: {error} (at ")
    assert (partial.recorder.events[-1].node, partial.recorder.events[-1].kind) == (
        "testbed",
        "failed",
    )
    assert 0.0 < partial.metrics["sim_s"] < 60.0
    assert partial.metrics["inputs"]["depth_law"]["factory"].endswith("my_laws.py:Boom")
