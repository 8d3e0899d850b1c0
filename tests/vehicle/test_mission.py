"""Mission files and trajectories: hand-computed interpolation, loader errors, packaged missions."""

from __future__ import annotations

import json
import math
from itertools import pairwise
from pathlib import Path
from typing import Any

import pytest

from testbed.config import ConfigError
from testbed.vehicle.mission import (
    LEVEL_TOLERANCE_RAD,
    MAX_POSITION_M,
    Trajectory,
    load_mission,
    load_packaged_mission,
    mission_names,
    mission_path,
    parse_mission,
    plan,
    single_goal,
)


def _point(t: float, x: float, y: float, z: float, rz: float = 0.0) -> dict[str, Any]:
    return {
        "time_from_start": t,
        "transform": {"x": x, "y": y, "z": z, "rx": 0.0, "ry": 0.0, "rz": rz},
    }


def _doc(*points: dict[str, Any]) -> dict[str, Any]:
    return {"name": "test", "parent": "map", "child": "base_link", "waypoints": list(points)}


def _close(a: tuple[float, ...], b: tuple[float, ...]) -> bool:
    return all(math.isclose(x, y, abs_tol=1e-12) for x, y in zip(a, b, strict=True))


def test_plan_prepends_the_start_pose_and_interpolates_linearly() -> None:
    mission = parse_mission(
        _doc(_point(2.0, 2.0, 0.0, 1.0), _point(4.0, 2.0, 4.0, 1.0, math.pi / 2))
    )
    trajectory = plan(mission, (0.0, 0.0, 0.0), 0.0, start_time_s=100.0)
    assert trajectory.times_s == (0.0, 2.0, 4.0)
    assert trajectory.start_time_s == 100.0
    # t = 1: halfway along (0,0,0) → (2,0,1) in 2 s
    s = trajectory.sample(1.0)
    assert _close(s.position_ned, (1.0, 0.0, 0.5))
    assert _close(s.velocity_ned, (1.0, 0.0, 0.5))
    assert s.yaw_rad == 0.0 and not s.done
    # t = 3: halfway along (2,0,1) → (2,4,1), yaw 0 → π/2
    s = trajectory.sample(3.0)
    assert _close(s.position_ned, (2.0, 2.0, 1.0))
    assert _close(s.velocity_ned, (0.0, 2.0, 0.0))
    assert math.isclose(s.yaw_rad, math.pi / 4)
    # t = 2.5: a quarter of the second leg
    assert _close(trajectory.sample(2.5).position_ned, (2.0, 1.0, 1.0))
    # before the start: the start pose; at and after the end: the last pose, held
    assert trajectory.sample(-1.0).position_ned == (0.0, 0.0, 0.0)
    for t in (4.0, 50.0):
        s = trajectory.sample(t)
        assert s.done and s.position_ned == (2.0, 4.0, 1.0) and s.velocity_ned == (0.0, 0.0, 0.0)
        assert math.isclose(s.yaw_rad, math.pi / 2)


def test_no_start_pose_when_the_first_point_is_at_zero() -> None:
    mission = parse_mission(_doc(_point(0.0, 1.0, 1.0, 1.0), _point(10.0, 2.0, 1.0, 1.0)))
    trajectory = plan(mission, (5.0, 5.0, 5.0), 1.0, start_time_s=0.0)
    assert trajectory.times_s == (0.0, 10.0)
    assert trajectory.sample(0.0).position_ned == (1.0, 1.0, 1.0)
    assert _close(trajectory.sample(5.0).position_ned, (1.5, 1.0, 1.0))


def test_yaw_turns_the_short_way_across_pi() -> None:
    # 3.0 → -3.0 rad is a 0.283 rad turn through ±π, not 6 rad the long way round
    mission = parse_mission(_doc(_point(0.0, 0.0, 0.0, 0.0, 3.0), _point(4.0, 0.0, 0.0, 0.0, -3.0)))
    trajectory = plan(mission, (0.0, 0.0, 0.0), 0.0, 0.0)
    quarter = 3.0 + 0.25 * (2.0 * math.pi - 6.0)
    assert math.isclose(trajectory.sample(1.0).yaw_rad, quarter)
    three_quarters = 3.0 + 0.75 * (2.0 * math.pi - 6.0) - 2.0 * math.pi
    assert math.isclose(trajectory.sample(3.0).yaw_rad, three_quarters)
    assert math.isclose(trajectory.sample(9.0).yaw_rad, -3.0)


def test_single_goal_is_timed_by_the_cruise_speed() -> None:
    leg = single_goal((0.0, 0.0, 1.0), 0.5, (3.0, 4.0, 1.0), None, 0.5, start_time_s=7.0)
    assert leg.times_s == (0.0, 10.0) and leg.start_time_s == 7.0  # 5 m at 0.5 m/s
    s = leg.sample(5.0)
    assert _close(s.position_ned, (1.5, 2.0, 1.0))
    assert _close(s.velocity_ned, (0.3, 0.4, 0.0))
    assert s.yaw_rad == 0.5  # None keeps the heading
    # a pure turn is timed by the yaw rate: π/2 at 0.3 rad/s
    turn = single_goal((1.0, 1.0, 1.0), 0.0, (1.0, 1.0, 1.0), math.pi / 2, 0.5, 0.0)
    assert math.isclose(turn.end_time_s, (math.pi / 2) / 0.3)
    with pytest.raises(ValueError):
        single_goal((0.0, 0.0, 0.0), 0.0, (1.0, 0.0, 0.0), None, 0.0, 0.0)


def test_trajectory_rejects_unordered_knots() -> None:
    with pytest.raises(ValueError):
        Trajectory((0.0, 0.0), ((0.0, 0.0, 0.0), (1.0, 0.0, 0.0)), (0.0, 0.0))


def _mutate(data: dict[str, Any], edit: str) -> str:
    """A text of a valid 3-point mission with one mistake ``edit`` in it."""
    points = data["waypoints"]
    if edit == "repeated time":
        points[2]["time_from_start"] = 20.0
    elif edit == "decreasing time":
        points[2]["time_from_start"] = 5.0
    elif edit == "missing z":
        del points[2]["transform"]["z"]
    elif edit == "missing transform":
        del points[2]["transform"]
    elif edit == "missing waypoints":
        del data["waypoints"]
    elif edit == "unknown waypoint key":
        points[2]["speed"] = 1.0
    elif edit == "unknown top key":
        data["frame"] = "ned"
    elif edit == "string number":
        points[2]["transform"]["x"] = "1.0"
    elif edit == "bool number":
        points[2]["transform"]["rz"] = True
    elif edit == "short velocity":
        points[2]["velocity"] = [0.0] * 5
    elif edit == "negative first time":
        points[0]["time_from_start"] = -1.0
    elif edit == "empty waypoints":
        data["waypoints"] = []
    elif edit == "tool frame typo":  # one letter off Angler's tool frame: flew the hull
        data["child"] = "alpha_standard_jaw_tool"
    elif edit == "unknown child":
        data["child"] = "gripper"
    elif edit == "unknown parent":
        data["parent"] = "odom"
    elif edit == "above the surface":
        points[2]["transform"]["z"] = -3.0
    elif edit == "roll":  # not flown: was accepted and the vehicle flew level
        points[2]["transform"]["rx"] = 0.1
    elif edit == "pitch":
        points[2]["transform"]["ry"] = -1e-5
    elif edit == "yaw in degrees":  # radians: 90.0 was accepted silently
        points[2]["transform"]["rz"] = 90.0
    elif edit == "far north":  # a review: x = 1e9 m ran, mean position error 3e8 m
        points[2]["transform"]["x"] = 1e9
    elif edit == "far west":
        points[1]["transform"]["y"] = -10000.5
    elif edit == "too deep":
        points[0]["transform"]["z"] = 20000.0
    text = json.dumps(data)
    if edit == "nan":
        text = text.replace('"y": 2.0', '"y": NaN')
    elif edit == "infinity":
        text = text.replace('"y": 2.0', '"y": Infinity')
    elif edit == "duplicate key":
        text = text.replace('"name": "test"', '"name": "test", "name": "again"')
    elif edit == "malformed":
        text = text[:-5]
    elif edit == "integer beyond any float":  # JSON integers have no bound
        text = text.replace('"y": 2.0', '"y": 1' + "0" * 400)
    elif edit == "integer beyond conversion":  # past Python's 4300-digit int parsing limit
        text = text.replace('"y": 2.0', '"y": 1' + "0" * 5000)
    return text


BAD_INPUTS = [
    ("repeated time", "waypoints[2].time_from_start: must be > 20 s"),
    ("decreasing time", "waypoints[2].time_from_start: must be > 20 s"),
    ("missing z", "waypoints[2].transform.z: required key missing"),
    ("missing transform", "waypoints[2].transform: required key missing"),
    ("missing waypoints", "waypoints: required key missing"),
    ("unknown waypoint key", "waypoints[2].speed: unknown key"),
    ("unknown top key", "frame: unknown key"),
    ("string number", "waypoints[2].transform.x: expected a number"),
    ("bool number", "waypoints[2].transform.rz: expected a number"),
    ("short velocity", "waypoints[2].velocity: expected an array of 6 numbers"),
    ("negative first time", "waypoints[0].time_from_start: must be ≥ 0 s"),
    ("empty waypoints", "waypoints: expected a non-empty array"),
    (
        "tool frame typo",
        "child: unknown frame 'alpha_standard_jaw_tool' "
        "(accepted: base_link, alpha_standard_jaws_tool, end_effector)",
    ),
    ("unknown child", "child: unknown frame 'gripper' (accepted: base_link, alpha_standard_"),
    ("unknown parent", "parent: unknown frame 'odom' (accepted: map)"),
    ("above the surface", "waypoints[2].transform.z: must be ≥ 0 m (z is down: -3 m is above"),
    ("roll", "waypoints[2].transform.rx: must be 0 (roll and pitch are not flown: "),
    ("pitch", "waypoints[2].transform.ry: must be 0 (roll and pitch are not flown: "),
    ("yaw in degrees", "waypoints[2].transform.rz: must be in [-2π, 2π] (the yaw in radians"),
    (
        "far north",
        "waypoints[2].transform.x: must be in [-10000, 10000] m (the world's extent), got 1e+09",
    ),
    (
        "far west",
        "waypoints[1].transform.y: must be in [-10000, 10000] m (the world's extent), got -10000.5",
    ),
    (
        "too deep",
        "waypoints[0].transform.z: must be in [-10000, 10000] m (the world's extent), got 20000",
    ),
    ("nan", "waypoints[2].transform.y: must be finite"),
    ("infinity", "waypoints[2].transform.y: must be finite"),
    ("duplicate key", "name: key given twice"),
    ("malformed", "malformed JSON"),
    ("integer beyond any float", "waypoints[2].transform.y: a 1329-bit integer, beyond any float"),
    ("integer beyond conversion", "malformed JSON: Exceeds the limit (4300 digits)"),
]


@pytest.mark.parametrize(("edit", "expected"), BAD_INPUTS, ids=[b[0] for b in BAD_INPUTS])
def test_loader_errors_name_the_file_and_the_field(
    tmp_path: Path, edit: str, expected: str
) -> None:
    good = _doc(
        _point(10.0, 0.0, 0.0, 1.0), _point(20.0, 2.0, 0.0, 1.0), _point(30.0, 2.0, 2.0, 1.0)
    )
    path = tmp_path / "square.json"
    path.write_text(_mutate(good, edit), encoding="utf-8")
    with pytest.raises(ConfigError) as info:
        load_mission(path)
    message = str(info.value)
    assert message.startswith(f"{path}: {expected}"), message
    assert "\n" not in message


def test_a_missing_file_is_named(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"nowhere\.json: file not found"):
        load_mission(tmp_path / "nowhere.json")


def test_zero_velocity_and_acceleration_are_kept_and_a_non_zero_one_is_refused(
    tmp_path: Path,
) -> None:
    """Angler's files carry zero velocities and accelerations: kept. A non-zero one would not
    be flown (the trajectory is linear between waypoints): refused, naming the field, where it
    used to be accepted and silently ignored."""
    point = _point(1.0, 0.0, 0.0, 1.0)
    point["velocity"] = [0, 0, 0, 0, 0, 0]
    point["acceleration"] = [0.0] * 6
    path = tmp_path / "m.json"
    path.write_text(json.dumps(_doc(point)), encoding="utf-8")
    mission = load_mission(path)
    assert mission.waypoints[0].velocity == (0.0,) * 6
    assert mission.waypoints[0].acceleration == (0.0,) * 6
    assert mission.source == str(path)
    point["velocity"] = [0.5, 0, 0, 0, 0, 0]
    path.write_text(json.dumps(_doc(point)), encoding="utf-8")
    with pytest.raises(ConfigError, match=r"m\.json: waypoints\[0\]\.velocity: must be zeros"):
        load_mission(path)


def test_a_huge_value_in_the_wrong_place_is_one_short_line(tmp_path: Path) -> None:
    """A 200 000-point array saved without its wrapper object made a 21-MB error message; 100 000
    points (10.5 MB: under the 16-Mi-character cap on configuration files) a 10-MB one."""
    path = tmp_path / "bare.json"
    path.write_text(json.dumps([_point(float(k + 1), 0.0, 0.0, 1.0) for k in range(100_000)]))
    with pytest.raises(ConfigError) as caught:
        load_mission(path)
    message = str(caught.value)
    assert message.startswith(f"{path}: <root>: expected an object, got [{{")
    assert len(message) < 400 and "\n" not in message and message.endswith("...]")


def test_all_packaged_missions_load() -> None:
    names = mission_names()
    assert {"square", "lawn_mower", "station_keeping", "waypoint"} <= set(names)
    for name in names:
        mission = load_packaged_mission(name)
        assert mission.name == name
        assert mission.source == f"missions/{name}.json"
        assert mission_path(name).name == f"{name}.json"
    with pytest.raises(ConfigError, match="unknown mission"):
        mission_path("nonesuch")


def test_packaged_missions_hold_the_documented_points() -> None:
    square = load_packaged_mission("square")
    corners = [(0, 0, 1), (2, 0, 1), (2, 2, 1), (0, 2, 1), (0, 0, 1)]
    assert [p.position_ned for p in square.waypoints] == corners
    times = [p.time_from_start_s for p in square.waypoints]
    assert [b - a for a, b in pairwise(times)] == [10.0] * 4
    lawn = load_packaged_mission("lawn_mower").waypoints
    assert len(lawn) == 8 and all(p.position_ned[2] == 1.0 for p in lawn)
    assert [p.position_ned[:2] for p in lawn][:3] == [(0.0, 0.0), (0.5, 0.0), (0.5, 0.5)]
    assert len(load_packaged_mission("station_keeping").waypoints) == 1
    waypoint = load_packaged_mission("waypoint").waypoints
    assert [p.position_ned for p in waypoint] == [(-1.0, 1.0, 0.5), (1.0, 1.0, 0.5)]


def test_samples_carry_the_segments_heading_rate() -> None:
    """The heading's feed-forward is the segment's slope, the short way across ±π: 0.283 rad in
    4 s; zero before the start and while the end is held; π/2 in 2 s on a plan's second leg."""
    mission = parse_mission(_doc(_point(0.0, 0.0, 0.0, 0.0, 3.0), _point(4.0, 0.0, 0.0, 0.0, -3.0)))
    trajectory = plan(mission, (0.0, 0.0, 0.0), 0.0, 0.0)
    assert math.isclose(trajectory.sample(1.0).yaw_rate_rad_s, (2.0 * math.pi - 6.0) / 4.0)
    assert trajectory.sample(-1.0).yaw_rate_rad_s == 0.0
    assert trajectory.sample(9.0).yaw_rate_rad_s == 0.0
    mission = parse_mission(
        _doc(_point(2.0, 2.0, 0.0, 1.0), _point(4.0, 2.0, 4.0, 1.0, math.pi / 2))
    )
    trajectory = plan(mission, (0.0, 0.0, 0.0), 0.0, start_time_s=100.0)
    assert trajectory.sample(1.0).yaw_rate_rad_s == 0.0
    assert math.isclose(trajectory.sample(3.0).yaw_rate_rad_s, math.pi / 4)
    turn = single_goal((1.0, 1.0, 1.0), 0.0, (1.0, 1.0, 1.0), math.pi / 2, 0.5, 0.0)
    assert math.isclose(turn.sample(1.0).yaw_rate_rad_s, 0.3)  # the GoTo's yaw rate


def test_rounding_in_roll_and_pitch_and_a_full_turn_of_yaw_are_accepted(tmp_path: Path) -> None:
    point = _point(10.0, 0.0, 0.0, 1.0, rz=-2.0 * math.pi)
    point["transform"]["rx"] = LEVEL_TOLERANCE_RAD
    point["transform"]["ry"] = -1e-17  # a quaternion's rounding
    path = tmp_path / "m.json"
    path.write_text(json.dumps(_doc(point)), encoding="utf-8")
    (waypoint,) = load_mission(path).waypoints
    assert waypoint.euler_xyz_rad == (LEVEL_TOLERANCE_RAD, -1e-17, -2.0 * math.pi)


def test_waypoints_at_the_worlds_edge_are_accepted() -> None:
    """±10 km (MAX_POSITION_M, the start position's domain too) is inside."""
    assert MAX_POSITION_M == 10000.0
    points = (_point(0.0, MAX_POSITION_M, -MAX_POSITION_M, MAX_POSITION_M),)
    mission = parse_mission(_doc(*points), "edge.json")
    assert mission.waypoints[0].position_ned == (10000.0, -10000.0, 10000.0)
