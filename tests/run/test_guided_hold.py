"""GUIDED with no goal on the PID vehicle holds a point (ArduSub's GUIDED always holds a
position target): after the operator's cancel, and when GUIDED is entered without a goal, the
vehicle holds the stopping point of its own fix and velocity estimate against a water current,
where it used to hold only depth and attitude and drift with the current.

Independent truth: the stopping point's closed form, ArduPilot's ``stopping_distance`` for a
demand without acceleration shaping (``min(|v|, max_speed) / kp`` along the velocity, AP_Math
``control.cpp``), worked out here from the recorded (true) position and velocity at the frame
the vehicle let go of its goal, with the loop's packaged gains (0.8 /s, 0.5 m/s).

The current leaves the loop, which has no integral term, an offset downstream of
drag(c) / (kv kp) = drag / 24 N/m per level axis (guidance.py's docstring), the drag from the
BlueROV2's published damping (Wu 2018; bluerov2_gz's quadratic surge and sway), heading north:
at (0.1, 0.05) m/s, 0.741 N and 0.447 N, so (31, 19) mm.

Tolerance (``TOLERANCE_M``): the vehicle takes the point from its fix and its velocity
estimate, not the truth: the fix's noise σ = 5 mm; the velocity, differenced fixes (20 Hz)
low-passed (τ = 0.15 s, α = dt / (τ + dt) = 0.25), has a noise of σ √2 / dt · √(α / (2 − α)) =
0.141 × 0.378 = 0.053 m/s per axis, 0.067 m once divided by kp; three σ of both, summed over
the two axes (√2), is 0.30 m. The point must hold for 30 s, in which the current alone carries
a vehicle that holds only depth and attitude 3.4 m (0.11 m/s).
"""

from __future__ import annotations

import math
import textwrap
from importlib import resources
from pathlib import Path

import numpy as np
import pytest

from testbed.cli.main import main
from testbed.common.components import ControlMode
from testbed.config import ConfigError
from testbed.run import load_scenario, run_scenario

GAIN_1_S, MAX_SPEED_M_S = 0.8, 0.5  # the packaged GUIDED loop (vehicle/guidance.py)
FIX_NOISE_M, FIX_RATE_HZ, VELOCITY_TAU_S = 0.005, 20.0, 0.15
_ALPHA = (1.0 / FIX_RATE_HZ) / (VELOCITY_TAU_S + 1.0 / FIX_RATE_HZ)
_VELOCITY_SIGMA = FIX_NOISE_M * math.sqrt(2.0) * FIX_RATE_HZ * math.sqrt(_ALPHA / (2.0 - _ALPHA))
TOLERANCE_M = 3.0 * math.sqrt(2.0) * (FIX_NOISE_M + _VELOCITY_SIGMA / GAIN_1_S)
CURRENT = (0.1, 0.05, 0.0)
KV_N_S_M = 30.0  # the loop's force per m/s of speed error
LINEAR_DAMPING = (4.03, 6.22)  # X_u, Y_v [N·s/m] (Wu 2018)
QUADRATIC_DAMPING = (33.8, 54.269)  # X_u|u|, Y_v|v| [N·s²/m²] (bluerov2_gz)
CURRENT_OFFSET = np.array(
    [
        (LINEAR_DAMPING[i] * CURRENT[i] + QUADRATIC_DAMPING[i] * CURRENT[i] ** 2)
        / (KV_N_S_M * GAIN_1_S)
        for i in (0, 1)
    ]
)
"""Where the loop holds, from the point, heading north: drag(c) / (kv kp) per axis [m]."""
GOTO_S, CANCEL_S = 5.0, 7.0
HOLD_S = 30.0
SETTLE_S = 5.0 / GAIN_1_S
"""The coast onto the point: at the switch the demand is the vehicle's speed, which then decays
as the error does, time constant 1 / kp = 1.25 s; five of them leave < 1 % of the ≤ 0.625 m."""


def _scenario(folder: Path, codec: str, goals: str, mode: str = "depth_hold") -> Path:
    tether = 'preset = "tether"\ncodec = "changeset"\nmac = "free"'  # as tether-teleop-v1's
    link = 'preset = "s100"' if codec == "teleop" else tether
    path = folder / f"guided-hold-{codec}.toml"
    path.write_text(
        textwrap.dedent(
            f"""\
            schema = 1
            id = "guided-hold-v1"
            description = "GUIDED with no goal on the PID vehicle with a position fix"
            duration_s = 50.0
            [link]
            {link}
            [vehicle]
            model = "bluerov2"
            [vehicle.sensors.position]
            rate_hz = {FIX_RATE_HZ}
            noise_m = {FIX_NOISE_M}
            [vehicle.current]
            velocity_ned_mps = [{CURRENT[0]}, {CURRENT[1]}, {CURRENT[2]}]
            [operator]
            arm_at_s = 1.0
            mode = "{mode}"
            [pilot]
            kind = "supervisor"
            goals = {goals}
            """
        ).replace("{link}", link)
    )
    return path


def _stopping_point(t: np.ndarray, north: np.ndarray, east: np.ndarray, at: int) -> np.ndarray:
    """The closed-form stopping point of the true position and velocity at sample ``at``."""
    dt = t[at + 1] - t[at - 1]
    velocity = np.array([north[at + 1] - north[at - 1], east[at + 1] - east[at - 1]]) / dt
    speed = float(np.hypot(*velocity))
    along = min(speed, MAX_SPEED_M_S) / GAIN_1_S
    ahead = velocity / speed * along if speed > 0.0 else np.zeros(2)
    return np.array([north[at], east[at]]) + ahead


def _held_from(series: dict[str, np.ndarray], start: int) -> tuple[np.ndarray, np.ndarray]:
    """The stopping point at sample ``start`` with the current's offset, and the distance from
    it [m] over the 30 s after the coast onto it (heading north throughout); the coast itself
    must not carry the vehicle past it (by more than the tolerance, along its way)."""
    t, north, east = series["t_s"], series["north_m"], series["east_m"]
    point = _stopping_point(t, north, east, start) + CURRENT_OFFSET
    ahead = point - np.array([north[start], east[start]])
    coast = (t >= t[start]) & (t < t[start] + SETTLE_S)
    if np.hypot(*ahead) > 0.0:
        way = ahead / np.hypot(*ahead)
        past = (north[coast] - point[0]) * way[0] + (east[coast] - point[1]) * way[1]
        assert past.max() < TOLERANCE_M, ("carried past the point", past.max(), point)
    window = (t >= t[start] + SETTLE_S) & (t <= t[start] + SETTLE_S + HOLD_S)
    assert t[window][-1] - t[window][0] > HOLD_S - 0.1, "the run ended too soon"
    miss = np.hypot(north[window] - point[0], east[window] - point[1])
    return point, miss


@pytest.mark.parametrize("codec", ["teleop", "changeset"])
def test_a_cancelled_goto_holds_the_stopping_point_against_the_current(
    tmp_path: Path, codec: str
) -> None:
    goals = (
        f"[{{ t_s = {GOTO_S}, position_ned_m = [2.0, 0.0, 1.0], yaw_deg = 0.0 }},"
        f" {{ t_s = {CANCEL_S}, cancel = true }}]"
    )
    result = run_scenario(load_scenario(str(_scenario(tmp_path, codec, goals))))
    series = result.recorder.series()
    t, mode, target = series["t_s"], series["mode"], series["target_n"]
    guided = mode == float(ControlMode.GUIDED.value)
    # the frame the vehicle let go of its goal: the recorded target no longer the goal's 2 m
    let_go = np.flatnonzero((t > CANCEL_S) & guided & (target != 2.0))
    assert let_go.size, "the cancel never reached the vehicle"
    start = int(let_go[0])
    # what the series records as the target from then on: the point the vehicle holds, the
    # stopping point it chose from its own fix and velocity estimate, at the goal's depth
    held = np.column_stack([target, series["target_e"], series["target_d"]])[t > t[start]]
    expected = _stopping_point(t, series["north_m"], series["east_m"], start)
    assert np.all(np.hypot(*(held[:, :2] - expected).T) < TOLERANCE_M), (held[0], expected)
    assert np.all(held == held[0]) and held[0, 2] == 1.0, held[0]  # chosen once
    assert t[start] < CANCEL_S + 3.0, t[start]
    assert np.all(guided[t > t[start]]), "left GUIDED"
    point, miss = _held_from(series, start)
    assert 0.3 < point[0] < 1.5, point  # on the way to the goal at 2 m, stopped short
    assert miss.max() < TOLERANCE_M, (miss.max(), TOLERANCE_M, point)
    yaw = series["yaw_deg"][t > t[start]]
    assert np.all(np.abs(yaw) < 2.0), (yaw.min(), yaw.max())  # heading north, as the offset has
    depth = series["down_m"][t > t[start] + 5.0]
    assert np.all(np.abs(depth - 1.0) < 0.05), (depth.min(), depth.max())  # the goal's depth


@pytest.mark.parametrize("codec", ["teleop", "changeset"])
def test_guided_entered_without_a_goal_holds_where_it_was(tmp_path: Path, codec: str) -> None:
    # GUIDED asked for at arming with no goal: the scenario's operator.mode
    result = run_scenario(load_scenario(str(_scenario(tmp_path, codec, "[]", mode="guided"))))
    series = result.recorder.series()
    t, mode = series["t_s"], series["mode"]
    guided = np.flatnonzero(mode == float(ControlMode.GUIDED.value))
    assert guided.size, "never entered GUIDED"
    entered = int(guided[0])
    assert np.all(mode[entered:] == float(ControlMode.GUIDED.value))
    # the loop's velocity estimate starts at zero on entry: the point is chosen once that start
    # weighs ≤ 5 % in it, after k fix differences, (1 − α)^k ≤ 0.05 (0.55 s at 20 Hz), give or
    # take the half fix interval from entry to the first fix (at ≈ 0.1 m/s: ±2.5 mm)
    k = math.ceil(math.log(0.05) / math.log(1.0 - _ALPHA))
    start = int(np.searchsorted(t, t[entered] + (k + 0.5) / FIX_RATE_HZ))
    yaw = series["yaw_deg"][t > t[start]]
    assert np.all(np.abs(yaw) < 2.0), (yaw.min(), yaw.max())
    point, miss = _held_from(series, start)
    assert miss.max() < TOLERANCE_M, (miss.max(), TOLERANCE_M, point)


def test_guided_is_a_scenario_mode_listed_and_refused_without_a_position_fix(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``operator.mode = "guided"`` is offered (the list of valid modes names it) and needs a
    position fix: without one the vehicle refuses GUIDED (ArduSub's needs a position estimate),
    so the scenario is refused at load, one line naming the key, exit 2."""
    path = _scenario(tmp_path, "teleop", "[]", mode="guided")
    assert main(["run", str(path), "--set", "operator.mode=guidd", "--out", "out"]) == 2
    err = capsys.readouterr().err
    assert err == (
        "testbed: error: --set: operator.mode: expected one of 'manual', 'stabilize', "
        "'depth_hold', 'guided', got 'guidd'\n"
    )
    no_fix = path.read_text().replace("[vehicle.sensors.position]", "[vehicle.sensors.depth]")
    no_fix = no_fix.replace(f"noise_m = {FIX_NOISE_M}", "noise_pa = 1.0")
    path.write_text(no_fix)
    assert main(["run", str(path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err == (
        f"testbed: error: {path}: operator.mode: 'guided' needs a position fix "
        "(vehicle.sensors.position or vehicle.navigation), and the vehicle has none: add one, "
        "or use 'manual', 'stabilize' or 'depth_hold'\n"
    )
    assert not (tmp_path / "out").exists()
    path.write_text(no_fix.replace('mode = "guided"', 'mode = "depth_hold"'))
    load_scenario(str(path))  # the same vehicle in depth hold is fine


def test_a_live_session_of_a_guided_scenario_asks_for_guided(tmp_path: Path) -> None:
    """``testbed live`` maps the scenario's mode as ``testbed run`` does (it kept a table of
    its own without GUIDED, so the session failed as it was built): 3 s in real time, armed
    at 1 s, the vehicle is in GUIDED."""
    from testbed.live.hub import Hub
    from testbed.live.session import LiveSession

    scenario = load_scenario(str(_scenario(tmp_path, "teleop", "[]", mode="guided")))
    session = LiveSession(scenario, Hub(), pilot=None)
    result = session.run(3.0)
    mode = result.recorder.series()["mode"]
    assert mode[-1] == float(ControlMode.GUIDED.value), np.unique(mode)


def test_guided_is_refused_on_a_layout_that_cannot_push_sideways(tmp_path: Path) -> None:
    """A layout of two forward thrusters either side of the centre (surge and yaw, no sway) and
    two verticals cannot hold a point: one line naming operator.mode and the layout; the same
    layout in depth hold is fine."""
    text = Path(str(resources.files("testbed.vehicle") / "data/thrusters/ecs-2h.toml")).read_text()
    text = text.replace('name = "ecs-2h"', 'name = "no-sway"')
    text = text.replace("position_m = [-0.10, 0.14, -0.07]", "position_m = [-0.10, 0.0, -0.07]")
    text = text.replace("position_m = [0.10, -0.14, -0.07]", "position_m = [0.10, 0.0, -0.07]")
    text = text.replace("direction = [0.707, 0.707, 0.0]", "direction = [0.0, 1.0, 0.0]")
    text = text.replace("direction = [-0.707, -0.707, 0.0]", "direction = [0.0, 1.0, 0.0]")
    (tmp_path / "no-sway.toml").write_text(text)
    path = _scenario(tmp_path, "teleop", "[]", mode="guided")
    path.write_text(path.read_text().replace('model = "bluerov2"', 'thrusters = "no-sway.toml"'))
    with pytest.raises(ConfigError) as refused:
        load_scenario(str(path))
    assert str(refused.value).startswith(
        f"{path}: operator.mode: 'guided' holds a point, which needs a force along each of the "
        f"body's x and y axes on its own, and the layout {str(tmp_path / 'no-sway.toml')!r} "
        "cannot make one"
    )
    assert "y 0 N" in str(refused.value)
    path.write_text(path.read_text().replace('mode = "guided"', 'mode = "depth_hold"'))
    load_scenario(str(path))
