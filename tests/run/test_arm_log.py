"""``arm.csv``, the ``"arm"`` metrics and the ``limit_tasks`` events of a vehicle with an arm
(uvms-station-keeping-v1, shortened), with a TPIK configuration of the user's whose axis-e
safety range puts the arm's start angle (3.14 rad) inside that joint's high activation band.

Truth: the configuration file's own numbers (the band the joint starts in, the safety limit it
must not cross, the joint velocity limits) and the arm model's acceleration limit; the rates
column against a second method (the angles' finite differences); the events against the
columns' transitions.
"""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest

from testbed.run.outputs import write_run
from testbed.run.runner import RunResult, run_scenario
from testbed.run.scenario import load_scenario
from testbed.vehicle.arm import load_arm_model

SAFETY_E = (1.745, 3.20)  # rad; high threshold 3.20 − 0.087 = 3.113 < start 3.14
ACTIVATION = 0.087
VELOCITY_LIMITS = (0.5, 1.0, 1.0, 1.0)  # rad/s, e d c b
TPIK = f"""
rate_hz = 30.0
level_gain = 0.5
ee_gain = 0.3
ee_orientation = false
orientation_gain = 0.3
yaw_gain = 0.5
max_linear_m_s = 0.5
max_angular_rad_s = 0.5
joint_velocity_limits = {list(VELOCITY_LIMITS)}
singular_threshold = 0.01

[[limit_tasks]]
joint = 0
physical = [1.571, 3.316]
safety = {list(SAFETY_E)}
activation = {ACTIVATION}
gain = 0.3
"""


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> tuple[RunResult, Path]:
    folder = tmp_path_factory.mktemp("arm")
    tpik = folder / "tight-e.toml"
    tpik.write_text(TPIK, encoding="utf-8")
    overrides = ["duration_s=12", "trials=1", f"vehicle.arm.tpik='{tpik}'"]
    result = run_scenario(load_scenario("uvms-station-keeping-v1", overrides), seed=2)
    out = folder / "out"
    write_run(result, out)
    return result, out


def _columns(path: Path) -> dict[str, np.ndarray]:
    with path.open(encoding="utf-8") as handle:
        rows = list(csv.reader(handle))
    table = np.array(rows[1:], dtype=float)
    return {name: table[:, k] for k, name in enumerate(rows[0])}


def test_the_limit_task_is_in_force_while_the_joint_is_in_its_band_and_the_safety_holds(
    run: tuple[RunResult, Path],
) -> None:
    _, out = run
    arm = _columns(out / "arm.csv")
    e = np.radians(arm["axis_e_deg"])
    side = arm["axis_e_limit"]
    assert np.all(np.isnan(arm["axis_d_limit"]))  # no limit task of this joint in the file
    assert set(np.unique(side)) <= {0.0, 1.0}  # only the high band is ever reached
    active = side == 1.0
    assert active.any()
    high_threshold = SAFETY_E[1] - ACTIVATION
    # in force only where the joint was in its band at the solve (≤ one solve, 1/30 s, before
    # the row: the joint moves at most 0.5 rad/s · 1/30 s meanwhile)
    assert np.all(e[active] >= high_threshold - VELOCITY_LIMITS[0] / 30.0)
    assert np.all(e <= SAFETY_E[1])  # never past the safety limit
    document = json.loads((out / "metrics.json").read_text(encoding="utf-8"))
    margin = document["arm"]["joints"]["axis_e"]["margin_deg"]
    closest = np.min(np.minimum(e - SAFETY_E[0], SAFETY_E[1] - e))
    assert margin == pytest.approx(math.degrees(closest), abs=1e-3)
    assert 0 < document["arm"]["limit_activations"] <= document["arm"]["solves"]


def test_commands_keep_the_velocity_and_acceleration_limits(run: tuple[RunResult, Path]) -> None:
    _, out = run
    arm = _columns(out / "arm.csv")
    t = arm["t_s"]
    acceleration = load_arm_model("alpha5").acceleration_rad_s2
    for joint, limit in zip(("axis_e", "axis_d", "axis_c", "axis_b"), VELOCITY_LIMITS, strict=True):
        command = np.radians(arm[f"{joint}_cmd_deg_s"])
        assert np.all(np.abs(command) <= limit + 1e-6)
        steps = np.abs(np.diff(command)) / np.diff(t)
        assert np.all(steps <= acceleration * (1 + 1e-3) + 1e-6)


def test_the_rates_agree_with_the_angles_finite_differences(run: tuple[RunResult, Path]) -> None:
    _, out = run
    arm = _columns(out / "arm.csv")
    t = arm["t_s"]
    for joint in ("axis_e", "axis_d", "axis_c"):
        angle = np.radians(arm[f"{joint}_deg"])
        rate = np.radians(arm[f"{joint}_rate_deg_s"])
        moved = np.diff(angle) / np.diff(t)
        trapezoid = 0.5 * (rate[1:] + rate[:-1])
        assert np.max(np.abs(moved - trapezoid)) < 0.02  # rad/s, over 50-ms rows


def test_events_mark_every_change_of_the_limit_tasks_in_force(run: tuple[RunResult, Path]) -> None:
    result, out = run
    events = [e for e in result.recorder.events if e.kind == "limit_tasks"]
    assert events and events[0].detail == "axis_e"
    assert [e.detail for e in events[1::2]] == ["none"] * len(events[1::2])
    arm = _columns(out / "arm.csv")
    on = arm["axis_e_limit"] != 0.0
    switches = np.flatnonzero(np.diff(on.astype(int)))
    # every change seen in the rows has its event between the two rows
    times = [e.t_s for e in events]
    t = arm["t_s"]
    for k in switches:
        assert any(t[k] < when <= t[k + 1] for when in times)
    with (out / "events.csv").open(encoding="utf-8") as handle:
        written = [row for row in csv.reader(handle) if row[2] == "limit_tasks"]
    assert [row[-1] for row in written] == [e.detail for e in events]


def test_runs_without_an_arm_write_no_arm_file(tmp_path: Path) -> None:
    scenario = load_scenario("s100-teleop-v1", ["duration_s=12", "trials=1"])
    result = run_scenario(scenario, seed=0)
    written = write_run(result, tmp_path)
    assert result.recorder.arm is None
    assert "arm" not in result.metrics
    assert not (tmp_path / "arm.csv").exists() and all(p.name != "arm.csv" for p in written)


def test_the_summary_says_the_arm_line_and_no_empty_heading_line(
    run: tuple[RunResult, Path],
) -> None:
    """An end-effector mission has no pose-target heading: the summary leaves out the mission
    yaw line (it read "n/a deg, n/a deg"), and says the arm's line with its closest joint."""
    from testbed.cli.run_summary import format_summary

    result, _ = run
    text = format_summary(result.metrics, Path("out"))
    assert "mission yaw error" not in text
    (line,) = [row for row in text.splitlines() if row.startswith("  arm: ")]
    solves = result.metrics["arm"]["solves"]
    assert line.startswith(f"  arm: {solves} TPIK solves, ")
    assert "closest to a limit: axis_e" in line
