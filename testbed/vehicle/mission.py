"""Mission files in Angler's JSON layout, and the time-stamped trajectories planned from them.

A mission file (Angler's ``preplanned_end_effector_planner`` library format) is::

    {"name": "square", "parent": "map", "child": "base_link",
     "waypoints": [{"time_from_start": 10.0,
                    "transform": {"x": 0, "y": 0, "z": 1, "rx": 0, "ry": 0, "rz": 0},
                    "velocity": [6 numbers, optional], "acceleration": [6 numbers, optional]}]}

**Frames.** Angler's ``map`` frame is z-up; this testbed reads every mission coordinate as
**world NED metres** (x north, y east, z down: ``z = 1`` is 1 m deep) and converts nothing.
``rx, ry, rz`` are Euler angles ``xyz`` in **radians** (extrinsic x, y, z, which is the Z-Y-X
roll–pitch–yaw of :mod:`testbed.common.geometry`), so ``rz`` is the yaw, clockwise from north,
in [−2π, 2π]. Roll and pitch are not flown (the vehicle, and the arm's tool, are steered in
position and yaw and kept level), so ``rx`` and ``ry`` must be 0 (within
:data:`LEVEL_TOLERANCE_RAD`): a non-zero one is refused rather than silently flown level.
``parent`` must be ``map`` (:data:`PARENT_FRAMES`; kept for Angler compatibility, read as world
NED). ``child`` names the frame the waypoints are for: Angler's tool frame
``alpha_standard_jaws_tool`` (or ``end_effector``) makes them the arm's end effector's
(:data:`TOOL_FRAMES`), ``base_link`` (:data:`BODY_FRAMES`) the body's; any other name is refused
(a typo must not quietly fly the hull instead of the jaws).

**Checks.** Missing or unknown keys, unknown frame names, non-numbers, non-finite numbers, a
waypoint above the surface (``z < 0``) or beyond ±10 km (:data:`MAX_POSITION_M`), a non-zero
``rx`` or ``ry``, an ``|rz|`` beyond 2π (degrees given for radians, most likely), an empty
waypoint list, a negative first time and repeated or decreasing times (Angler's library has
repeated ones; they make a zero-length segment) are :class:`~testbed.config.ConfigError`\\ s
whose one-line message names the file and the field path, e.g. ``missions/square.json:
waypoints[2].time_from_start: must be > 3 s (the previous waypoint's), got 3``.

**Trajectories.** :func:`plan` prepends the vehicle's pose at ``t = 0`` when the first waypoint
is later than 0 (as Angler does), then interpolates linearly: position per axis, yaw along the
shorter way round; the feed-forward velocity is the segment's slope. The optional ``velocity``
and ``acceleration`` of a waypoint must be zeros (Angler's files carry them so; a non-zero one
is refused, since Angler's Hermite variant is not implemented and it would not be flown).
After the last waypoint the trajectory holds the last pose, velocity zero.

Pure: standard library and ``testbed.config`` / ``testbed.common.geometry`` only; no py_trees, no
ECS (the behaviour tree that runs missions is :mod:`testbed.vehicle.behaviours`).
"""

from __future__ import annotations

import bisect
import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from importlib import resources
from importlib.resources.abc import Traversable
from pathlib import Path
from typing import Any

from testbed.common.geometry import Vec3, wrap_angle
from testbed.config import ConfigError, read_text, shown, to_float

__all__ = [
    "BODY_FRAMES",
    "LEVEL_TOLERANCE_RAD",
    "MAX_POSITION_M",
    "PARENT_FRAMES",
    "TOOL_FRAMES",
    "Mission",
    "Trajectory",
    "TrajectorySample",
    "Waypoint",
    "load_mission",
    "load_packaged_mission",
    "mission_names",
    "mission_path",
    "parse_mission",
    "plan",
    "single_goal",
]

_PACKAGE_DIR = ("scenarios", "missions")
TOOL_FRAMES = ("alpha_standard_jaws_tool", "end_effector")
"""``child`` frame names that put a mission's waypoints on the arm's end effector."""
BODY_FRAMES = ("base_link",)
"""``child`` frame names that put a mission's waypoints on the vehicle's body origin."""
PARENT_FRAMES = ("map",)
"""``parent`` frame names: the world frame the waypoints are given in (read as NED)."""
_TOP_KEYS = ("name", "parent", "child", "waypoints")
_WAYPOINT_KEYS = ("time_from_start", "transform", "velocity", "acceleration")
_TRANSFORM_KEYS = ("x", "y", "z", "rx", "ry", "rz")

MAX_POSITION_M = 10000.0
"""Largest accepted ``|coordinate|`` [m] of a position in the world (a waypoint, a vehicle's start
position): the ±10 km the simulation is meant to cover."""

LEVEL_TOLERANCE_RAD = 1e-6
"""Largest ``|rx|``, ``|ry|`` [rad] a waypoint may have: roll and pitch are not flown (the pose
law and the arm's TPIK steer position and yaw), so anything else is refused, not ignored; the
tolerance lets a file converted from quaternions through rounding."""

Vec6 = tuple[float, float, float, float, float, float]


@dataclass(frozen=True, slots=True)
class Waypoint:
    """One mission point.

    Attributes:
        time_from_start_s: when the vehicle should be there [s] after the mission starts.
        position_ned: (3,) position [m], world NED.
        euler_xyz_rad: (3,) ``rx, ry, rz`` [rad]; ``rz`` is the yaw (clockwise from north).
        velocity: (6,) optional twist from the file (kept, not used), or None.
        acceleration: (6,) optional acceleration from the file (kept, not used), or None.
    """

    time_from_start_s: float
    position_ned: Vec3
    euler_xyz_rad: Vec3 = (0.0, 0.0, 0.0)
    velocity: Vec6 | None = None
    acceleration: Vec6 | None = None

    @property
    def yaw_rad(self) -> float:
        """The heading [rad, clockwise from north]: ``rz``."""
        return self.euler_xyz_rad[2]


@dataclass(frozen=True, slots=True)
class Mission:
    """A checked mission file.

    Attributes:
        name: the mission's ``name``.
        parent: Angler's reference frame name (:data:`PARENT_FRAMES`; read as world NED).
        child: Angler's controlled frame name: a tool frame (:data:`TOOL_FRAMES`) makes the
            waypoints the end effector's (:attr:`end_effector`), a body frame
            (:data:`BODY_FRAMES`) the body's.
        waypoints: the points, times strictly increasing.
        source: the file the mission came from (for messages).
    """

    name: str
    parent: str
    child: str
    waypoints: tuple[Waypoint, ...]
    source: str = "<mission>"

    @property
    def end_effector(self) -> bool:
        """The waypoints are for the arm's end effector (``child`` is a tool frame)."""
        return self.child in TOOL_FRAMES

    @property
    def duration_s(self) -> float:
        """The last waypoint's ``time_from_start`` [s]."""
        return self.waypoints[-1].time_from_start_s


@dataclass(frozen=True, slots=True)
class TrajectorySample:
    """The trajectory at one instant.

    Attributes:
        position_ned: (3,) desired position [m], world NED.
        yaw_rad: desired heading [rad, clockwise from north], in (−π, π].
        velocity_ned: (3,) feed-forward velocity [m/s], world NED (zero while holding).
        done: the last waypoint's time has passed (the pose is now held).
        yaw_rate_rad_s: feed-forward heading rate [rad/s] (the segment's slope; zero while
            holding).
    """

    position_ned: Vec3
    yaw_rad: float
    velocity_ned: Vec3
    done: bool
    yaw_rate_rad_s: float = 0.0


@dataclass(frozen=True, slots=True)
class Trajectory:
    """Knots of a piecewise-linear pose trajectory (build with :func:`plan` / :func:`single_goal`).

    Attributes:
        times_s: knot times [s] since the start, strictly increasing, first ≥ 0.
        positions_ned: (n, 3) knot positions [m], world NED.
        yaws_rad: knot headings [rad], unwrapped (each within π of the previous one).
        start_time_s: the clock time [s] of ``t = 0`` (e.g. the simulation time at planning).
        name: what was planned (the mission's name, or ``"goto"``).
    """

    times_s: tuple[float, ...]
    positions_ned: tuple[Vec3, ...]
    yaws_rad: tuple[float, ...]
    start_time_s: float = 0.0
    name: str = ""

    def __post_init__(self) -> None:
        n = len(self.times_s)
        if n == 0 or len(self.positions_ned) != n or len(self.yaws_rad) != n:
            raise ValueError("a trajectory needs ≥ 1 knot and as many positions and yaws")
        if any(b <= a for a, b in zip(self.times_s, self.times_s[1:], strict=False)):
            raise ValueError(f"knot times must increase strictly, got {self.times_s}")

    @property
    def end_time_s(self) -> float:
        """The last knot's time [s] since the start."""
        return self.times_s[-1]

    @property
    def final_position_ned(self) -> Vec3:
        """(3,) the pose held after the end [m], world NED."""
        return self.positions_ned[-1]

    @property
    def final_yaw_rad(self) -> float:
        """The heading held after the end [rad], wrapped to (−π, π]."""
        return wrap_angle(self.yaws_rad[-1])

    def sample(self, t_since_start_s: float) -> TrajectorySample:
        """The pose and feed-forward velocity and heading rate at ``t_since_start_s`` [s] after
        the start.

        Before the first knot the first pose is held; after the last, the last one.
        """
        times = self.times_s
        zero = (0.0, 0.0, 0.0)
        if t_since_start_s >= times[-1]:
            return TrajectorySample(self.positions_ned[-1], self.final_yaw_rad, zero, True)
        if t_since_start_s <= times[0]:
            return TrajectorySample(
                self.positions_ned[0], wrap_angle(self.yaws_rad[0]), zero, False
            )
        i = bisect.bisect_right(times, t_since_start_s) - 1  # times[i] ≤ t < times[i + 1]
        dt = times[i + 1] - times[i]
        f = (t_since_start_s - times[i]) / dt
        a, b = self.positions_ned[i], self.positions_ned[i + 1]
        position = (a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]), a[2] + f * (b[2] - a[2]))
        velocity = ((b[0] - a[0]) / dt, (b[1] - a[1]) / dt, (b[2] - a[2]) / dt)
        ya, yb = self.yaws_rad[i], self.yaws_rad[i + 1]
        yaw = wrap_angle(ya + f * (yb - ya))
        return TrajectorySample(position, yaw, velocity, False, (yb - ya) / dt)


def plan(
    mission: Mission, start_position_ned: Sequence[float], start_yaw_rad: float, start_time_s: float
) -> Trajectory:
    """The trajectory of ``mission`` from the vehicle's pose at ``start_time_s``.

    Args:
        mission: the mission.
        start_position_ned: (3,) the vehicle's position [m] at the start, world NED.
        start_yaw_rad: its heading [rad, clockwise from north].
        start_time_s: the clock time [s] the mission starts at (``t = 0``).

    Returns:
        Knots: the start pose at ``t = 0`` when the first waypoint is later (Angler), then the
        waypoints; yaws unwrapped so each segment turns the shorter way.
    """
    times: list[float] = []
    positions: list[Vec3] = []
    yaws: list[float] = []
    if mission.waypoints[0].time_from_start_s > 0.0:
        times.append(0.0)
        positions.append(_vec3(start_position_ned))
        yaws.append(float(start_yaw_rad))
    for point in mission.waypoints:
        times.append(point.time_from_start_s)
        positions.append(point.position_ned)
        yaws.append(_unwrap(yaws[-1], point.yaw_rad) if yaws else point.yaw_rad)
    return Trajectory(tuple(times), tuple(positions), tuple(yaws), start_time_s, mission.name)


def single_goal(
    start_position_ned: Sequence[float],
    start_yaw_rad: float,
    goal_position_ned: Sequence[float],
    goal_yaw_rad: float | None,
    speed_m_s: float,
    start_time_s: float,
    *,
    yaw_rate_rad_s: float = 0.3,
    min_duration_s: float = 0.1,
) -> Trajectory:
    """A one-leg trajectory from the current pose to a goal (a supervised GoTo order).

    The leg lasts ``max(distance / speed_m_s, |turn| / yaw_rate_rad_s, min_duration_s)``.

    Args:
        start_position_ned: (3,) current position [m], world NED.
        start_yaw_rad: current heading [rad].
        goal_position_ned: (3,) goal [m], world NED.
        goal_yaw_rad: goal heading [rad], or None to keep the current one.
        speed_m_s: cruise speed [m/s], > 0.
        start_time_s: the clock time [s] of the start.
        yaw_rate_rad_s: turn rate [rad/s] that bounds the duration of a turn, > 0.
        min_duration_s: shortest leg [s], > 0.

    Raises:
        ValueError: a non-positive speed, rate or duration, or a non-finite coordinate.
    """
    if not (speed_m_s > 0.0 and yaw_rate_rad_s > 0.0 and min_duration_s > 0.0):
        raise ValueError("speed, yaw rate and minimum duration must be > 0")
    start, goal = _vec3(start_position_ned), _vec3(goal_position_ned)
    if not all(math.isfinite(v) for v in (*start, *goal, start_yaw_rad)):
        raise ValueError(f"non-finite pose: {start}, {goal}, {start_yaw_rad}")
    target_yaw = start_yaw_rad if goal_yaw_rad is None else _unwrap(start_yaw_rad, goal_yaw_rad)
    distance = math.dist(start, goal)
    turn = abs(target_yaw - start_yaw_rad)
    duration = max(distance / speed_m_s, turn / yaw_rate_rad_s, min_duration_s)
    return Trajectory(
        (0.0, duration), (start, goal), (float(start_yaw_rad), target_yaw), start_time_s, "goto"
    )


def _unwrap(previous_rad: float, angle_rad: float) -> float:
    """``angle_rad`` moved by whole turns to within π of ``previous_rad``."""
    return previous_rad + wrap_angle(angle_rad - previous_rad)


def _vec3(values: Sequence[float]) -> Vec3:
    x, y, z = (float(v) for v in values)
    return (x, y, z)


# --- loading -------------------------------------------------------------------------------


def mission_names() -> list[str]:
    """Names of the packaged missions (``testbed/scenarios/missions/*.json``), sorted."""
    folder = resources.files("testbed").joinpath(*_PACKAGE_DIR)
    return sorted(
        e.name.removesuffix(".json") for e in folder.iterdir() if e.name.endswith(".json")
    )


def mission_path(name: str) -> Traversable:
    """The packaged mission file ``name`` (without ``.json``).

    Raises:
        ConfigError: no packaged mission has that name (the message lists the known ones).
    """
    known = mission_names()
    if name not in known:
        raise ConfigError(f"mission {name!r}: unknown mission (known: {', '.join(known)})")
    return resources.files("testbed").joinpath(*_PACKAGE_DIR, f"{name}.json")


def load_packaged_mission(name: str) -> Mission:
    """Load the packaged mission ``name``; messages name it ``missions/<name>.json``.

    Raises:
        ConfigError: unknown name, or the file does not check (see :func:`parse_mission`).
    """
    text = mission_path(name).read_text(encoding="utf-8")
    return _parse_text(text, f"missions/{name}.json")


def load_mission(path: str | Path) -> Mission:
    """Load and check a mission file.

    Raises:
        ConfigError: missing or unreadable file, malformed JSON, or a field that does not check;
            one line naming the file and the field path.
    """
    return _parse_text(read_text(path), str(path))


def _parse_text(text: str, source: str) -> Mission:
    def no_duplicates(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
        result: dict[str, Any] = {}
        for key, value in pairs:
            if key in result:
                raise ConfigError(f"{source}: {key}: key given twice")
            result[key] = value
        return result

    try:
        data = json.loads(text, object_pairs_hook=no_duplicates)
    except ConfigError:  # a key given twice
        raise
    except ValueError as err:  # JSONDecodeError, or an integer past Python's 4300-digit limit
        raise ConfigError(f"{source}: malformed JSON: {err}") from None
    return parse_mission(data, source)


def parse_mission(data: Any, source: str = "<mission>") -> Mission:
    """Check a decoded mission mapping (the layout in the module docstring).

    Args:
        data: the decoded JSON.
        source: the file name used in messages.

    Raises:
        ConfigError: ``"<source>: <field path>: <what is wrong>"``.
    """
    _keys(data, "", _TOP_KEYS, _TOP_KEYS, source)
    name = _string(data["name"], "name", source)
    parent = _frame(data["parent"], "parent", PARENT_FRAMES, source)
    child = _frame(data["child"], "child", BODY_FRAMES + TOOL_FRAMES, source)
    raw_points = data["waypoints"]
    if not isinstance(raw_points, list) or not raw_points:
        raise ConfigError(
            f"{source}: waypoints: expected a non-empty array, got {shown(raw_points)}"
        )
    points: list[Waypoint] = []
    for i, raw in enumerate(raw_points):
        key = f"waypoints[{i}]"
        _keys(raw, key, _WAYPOINT_KEYS, ("time_from_start", "transform"), source)
        t = _number(raw["time_from_start"], f"{key}.time_from_start", source)
        if not points and t < 0.0:
            raise ConfigError(f"{source}: {key}.time_from_start: must be ≥ 0 s, got {t:g}")
        if points and t <= points[-1].time_from_start_s:
            previous = points[-1].time_from_start_s
            raise ConfigError(
                f"{source}: {key}.time_from_start: must be > {previous:g} s "
                f"(the previous waypoint's), got {t:g}"
            )
        transform = raw["transform"]
        _keys(transform, f"{key}.transform", _TRANSFORM_KEYS, _TRANSFORM_KEYS, source)
        x, y, z, rx, ry, rz = (
            _number(transform[k], f"{key}.transform.{k}", source) for k in _TRANSFORM_KEYS
        )
        if z < 0.0:
            raise ConfigError(
                f"{source}: {key}.transform.z: must be ≥ 0 m (z is down: {z:g} m is above the "
                "surface)"
            )
        for axis, value in (("x", x), ("y", y), ("z", z)):
            if abs(value) > MAX_POSITION_M:
                raise ConfigError(
                    f"{source}: {key}.transform.{axis}: must be in [{-MAX_POSITION_M:g}, "
                    f"{MAX_POSITION_M:g}] m (the world's extent), got {value:g}"
                )
        for axis, angle in (("rx", rx), ("ry", ry)):
            if abs(angle) > LEVEL_TOLERANCE_RAD:
                raise ConfigError(
                    f"{source}: {key}.transform.{axis}: must be 0 (roll and pitch are not "
                    f"flown: the vehicle and the arm's tool keep level; only rz, the yaw, is), "
                    f"got {angle:g} rad"
                )
        if abs(rz) > 2.0 * math.pi:
            raise ConfigError(
                f"{source}: {key}.transform.rz: must be in [-2π, 2π] (the yaw in radians, "
                f"clockwise from north), got {rz:g}"
            )
        points.append(
            Waypoint(
                t,
                (x, y, z),
                (rx, ry, rz),
                _six(raw.get("velocity"), f"{key}.velocity", source),
                _six(raw.get("acceleration"), f"{key}.acceleration", source),
            )
        )
    return Mission(name, parent, child, tuple(points), source)


def _keys(data: Any, key: str, known: Sequence[str], required: Sequence[str], source: str) -> None:
    where = key or "<root>"
    if not isinstance(data, Mapping):
        raise ConfigError(f"{source}: {where}: expected an object, got {shown(data)}")
    prefix = f"{key}." if key else ""
    unknown = sorted(set(data) - set(known))
    if unknown:
        raise ConfigError(
            f"{source}: {prefix}{unknown[0]}: unknown key (known: {', '.join(known)})"
        )
    for name in required:
        if name not in data:
            raise ConfigError(f"{source}: {prefix}{name}: required key missing")


def _number(value: Any, key: str, source: str) -> float:
    number = to_float(value, source, key)
    if not math.isfinite(number):
        raise ConfigError(f"{source}: {key}: must be finite, got {number}")
    return number


def _string(value: Any, key: str, source: str) -> str:
    if not isinstance(value, str):
        raise ConfigError(f"{source}: {key}: expected a string, got {shown(value)}")
    return value


def _frame(value: Any, key: str, known: Sequence[str], source: str) -> str:
    """The frame name ``value`` of field ``key``, one of ``known``.

    Raises:
        ConfigError: not a string, or not a known name (the message lists them).
    """
    name = _string(value, key, source)
    if name not in known:
        accepted = ", ".join(known)
        raise ConfigError(f"{source}: {key}: unknown frame {name!r} (accepted: {accepted})")
    return name


def _six(value: Any, key: str, source: str) -> Vec6 | None:
    """A waypoint's optional ``velocity`` or ``acceleration``: six numbers, all zero (the
    trajectory is linear between waypoints, its velocity the segment's slope; a non-zero
    one would be ignored, which flies another experiment than the file describes)."""
    if value is None:
        return None
    if not isinstance(value, list) or len(value) != 6:
        raise ConfigError(f"{source}: {key}: expected an array of 6 numbers, got {shown(value)}")
    a, b, c, d, e, f = (_number(v, f"{key}[{i}]", source) for i, v in enumerate(value))
    if any((a, b, c, d, e, f)):
        raise ConfigError(
            f"{source}: {key}: must be zeros or left out (not flown: the trajectory runs "
            "straight between waypoints at the segment's slope; Angler's Hermite variant is "
            f"not implemented), got {[a, b, c, d, e, f]}"
        )
    return (a, b, c, d, e, f)
