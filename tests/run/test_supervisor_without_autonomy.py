"""A supervisor's GoTo to a vehicle without autonomy (the PID stack with a position fix, which
flies a position goal in GUIDED, as the live console's go-to has it): the station asks for
GUIDED with the goal, so the vehicle flies to the goal and stays there. Before, the station kept
asking for the scenario's DEPTH_HOLD, whose Move went out first at the next gap and left GUIDED
≈ 0.7 s after the GoTo: the vehicle coasted 0.7 m of 2 m and stopped."""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np
import pytest

from testbed.common.components import ControlMode
from testbed.run import load_scenario, run_scenario

GOAL_N_M = 2.0
GOTO_S = 5.0


def _scenario(folder: Path, codec: str) -> Path:
    tether = 'preset = "tether"\ncodec = "changeset"\nmac = "free"'  # as tether-teleop-v1's
    link = 'preset = "s100"' if codec == "teleop" else tether
    path = folder / f"supervised-pid-{codec}.toml"
    path.write_text(
        textwrap.dedent(
            f"""\
            schema = 1
            id = "supervised-pid-v1"
            description = "a supervisor's GoTo to the PID vehicle with a position fix"
            duration_s = 40.0
            [link]
            {{link}}
            [vehicle]
            model = "bluerov2"
            [vehicle.sensors.position]
            rate_hz = 20.0
            noise_m = 0.005
            [operator]
            arm_at_s = 1.0
            [pilot]
            kind = "supervisor"
            goals = [{{ t_s = {GOTO_S}, position_ned_m = [{GOAL_N_M}, 0.0, 1.0], yaw_deg = 0.0 }}]
            [metrics]
            settle_s = 5.0
            """
        ).replace("{link}", link)
    )
    return path


@pytest.mark.parametrize("codec", ["teleop", "changeset"])
def test_a_supervisors_goto_is_flown_to_the_goal_in_guided(tmp_path: Path, codec: str) -> None:
    result = run_scenario(load_scenario(str(_scenario(tmp_path, codec))))
    series = result.recorder.series()
    t, north, mode = series["t_s"], series["north_m"], series["mode"]
    modes = [e.detail for e in result.recorder.events if e.kind == "mode" and e.t_s > GOTO_S]
    assert modes == ["GUIDED"], modes  # entered once, never left
    after = t > GOTO_S + 2.0
    assert np.all(mode[after] == float(ControlMode.GUIDED.value)), set(mode[after])
    last = t > 30.0  # GUIDED's horizontal loop: 0.5 m/s top speed, 0.8 1/s gain
    assert np.all(np.abs(north[last] - GOAL_N_M) < 0.05), north[last].min()
