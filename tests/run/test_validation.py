"""Every numeric scenario key has a domain: a bad value is a one-line error naming the key
(exit 2), never a crash or a run that does not end.

The keys are enumerated from the loaded :class:`~testbed.run.scenario_config.Scenario` dataclass
tree (defaults included, so a new field is covered without touching this file), as the loader
names them: ``vehicle.gains.roll.kp``, ``link.ber`` (the channel keys sit flat in ``[link]``),
``pilot.x[0].period_s``. Each is fed nan, ±inf, 0, −1 and ±1e308 through ``--set``; an integer
key gets the floats (not integers) and 0, −1 and the largest TOML integers for ±1e308, and a
tuple key gets one bad element at a time (``[inf, 0, 0]``) with the others kept. Either the load
raises :class:`~testbed.config.ConfigError`, one line naming the key, or the value is legal and
a short run of the scenario with it must finish. The legal values of one scenario that share a
value (and tuple position) run together in one short run; a failing group is rerun one override
at a time to name the culprit.

The default run covers every key of s100-teleop-v1 (teleop codec, token passing),
tether-teleop-v1 (change-set codec, free access) and s100-video-v1 (camera and images);
``-m slow`` adds every other packaged scenario.
"""

from __future__ import annotations

import dataclasses
import math
import types
import typing
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import pytest

from testbed.cli.main import main
from testbed.config import ConfigError
from testbed.run.runner import run_scenario
from testbed.run.scenario import load_scenario
from testbed.run.scenario_config import Scenario
from testbed.run.scenario_files import scenario_names
from testbed.run.sections import LinkSection

BAD_FLOATS = (math.nan, math.inf, -math.inf, 0.0, -1.0, 1e308, -1e308)
"""The bad values every numeric key is fed."""
TOML_INT_MAX = 2**63 - 1
"""TOML's largest integer: an integer key's stand-in for 1e308 (and its negation, −1 − it)."""

DEFAULT_SCENARIOS = ("s100-teleop-v1", "tether-teleop-v1", "s100-video-v1", "s100-supervised-v1")
"""One scenario per codec (teleop, changeset), the one with the camera and images, and the one
with navigation and autonomy."""


@dataclass(frozen=True, slots=True)
class Leaf:
    """One numeric key of a loaded scenario.

    Attributes:
        key: dotted key as the loader names it (``vehicle.sensors.imu.rate_hz``).
        kind: ``"float"``, ``"int"``, ``"floats"`` (fixed tuple) or ``"ints"`` (variable
            tuple of integers).
        value: the loaded value (None for an optional key left out).
    """

    key: str
    kind: str
    value: Any


@dataclass(frozen=True, slots=True)
class Case:
    """One bad value for one key: the ``--set`` override and the key its error must name."""

    key: str
    override: str
    label: str


def _without_none(tp: Any) -> Any:
    if typing.get_origin(tp) in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        if len(args) == 1:
            return args[0]
    return tp


def numeric_leaves(obj: Any, cls: type[Any], prefix: str = "") -> Iterator[Leaf]:
    """Every numeric key of ``obj`` (an instance of dataclass ``cls``, or None for an
    optional table left out: its keys are still settable and are listed from the type)."""
    hints = typing.get_type_hints(cls)
    for field in dataclasses.fields(cls):
        if not field.init or (cls is Scenario and field.name == "source"):
            continue
        tp = _without_none(hints[field.name])
        value = None if obj is None else getattr(obj, field.name)
        if cls is LinkSection and field.name == "channel":  # channel keys sit flat in [link]
            yield from numeric_leaves(value, tp, prefix)
            continue
        key = prefix + field.name
        args = typing.get_args(tp)
        if dataclasses.is_dataclass(tp) and isinstance(tp, type):
            yield from numeric_leaves(value, tp, f"{key}.")
        elif tp is float or tp is int:
            yield Leaf(key, tp.__name__, value)
        elif typing.get_origin(tp) is tuple and len(args) == 2 and args[1] is Ellipsis:
            element = args[0]
            if dataclasses.is_dataclass(element) and isinstance(element, type):
                for i, item in enumerate(value or ()):
                    yield from numeric_leaves(item, element, f"{key}[{i}].")
            elif element is int or element is float:
                yield Leaf(key, f"{element.__name__}s", value)
        elif typing.get_origin(tp) is tuple and args and all(a in (int, float) for a in args):
            yield Leaf(key, "floats" if float in args else "ints", value)


def toml(value: Any) -> str:
    """``value`` spelt as a TOML value (dataclasses as inline tables, None fields left out)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, int | str):
        return repr(value) if isinstance(value, str) else str(value)
    if isinstance(value, tuple | list):
        return "[" + ", ".join(toml(v) for v in value) + "]"
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        parts = [
            f"{f.name} = {toml(getattr(value, f.name))}"
            for f in dataclasses.fields(value)
            if getattr(value, f.name) is not None
        ]
        return "{" + ", ".join(parts) + "}"
    raise TypeError(f"no TOML spelling for {value!r}")


def _bad_values(kind: str) -> tuple[Any, ...]:
    if kind.startswith("int"):  # floats are wrong for an integer key; ±1e308 become ±int max
        return (math.nan, math.inf, -math.inf, 0, -1, TOML_INT_MAX, -TOML_INT_MAX - 1)
    return BAD_FLOATS


def _unchecked(item: Any, name: str, value: Any) -> Any:
    """A copy of dataclass instance ``item`` with ``name`` set, skipping its checks."""
    copy = object.__new__(type(item))
    for field in dataclasses.fields(item):
        object.__setattr__(
            copy, field.name, value if field.name == name else getattr(item, field.name)
        )
    return copy


def _tuples(current: Any, bad: Any) -> Iterator[tuple[int, tuple[Any, ...]]]:
    """(position, the tuple with ``bad`` there) for each position of ``current``."""
    values = tuple(current or ())
    if not values:
        yield 0, (bad,)
    for i in range(len(values)):
        yield i, (*values[:i], bad, *values[i + 1 :])


def cases(scenario: Scenario) -> Iterator[Case]:
    """Every (key, bad value) ``--set`` case of ``scenario``."""
    for leaf in numeric_leaves(scenario, Scenario):
        for bad in _bad_values(leaf.kind):
            label = toml(bad)
            if "[" in leaf.key:  # a field of a table in an array: the whole array is set
                head, _, rest = leaf.key.partition("[")
                index_text, _, name = rest.partition("].")
                items: list[Any] = list(_get(scenario, head))
                index = int(index_text)
                if leaf.kind in ("floats", "ints"):
                    for j, values in _tuples(leaf.value, bad):
                        changed = list(items)
                        changed[index] = _unchecked(items[index], name, values)
                        yield Case(leaf.key, f"{head}={toml(changed)}", f"{label}@{j}")
                else:
                    items[index] = _unchecked(items[index], name, bad)
                    yield Case(leaf.key, f"{head}={toml(items)}", label)
            elif leaf.kind in ("floats", "ints"):
                for j, values in _tuples(leaf.value, bad):
                    yield Case(leaf.key, f"{leaf.key}={toml(values)}", f"{label}@{j}")
            else:
                yield Case(leaf.key, f"{leaf.key}={label}", label)


def _get(obj: Any, dotted: str) -> Any:
    for part in dotted.split("."):
        obj = getattr(obj, part)
    return obj


def short_run_overrides(scenario: Scenario) -> list[str]:
    """Overrides that cut ``scenario`` to a couple of seconds past its last scheduled event."""
    events = [scenario.operator.arm_at_s, scenario.pilot.start_s]
    events += [fault.t_s for fault in scenario.faults.thrusters]
    events += [outage.end_s for outage in scenario.faults.link_outages]
    events += [change.t_s for change in scenario.images.changes]
    return [f"duration_s={max(events) + 2.0}", "metrics.settle_s=0"]


def legal_groups(name: str) -> tuple[list[str], dict[str, list[str]]]:
    """Check every case of scenario ``name``; the legal ones grouped by value and position, no
    key set twice in a group.

    Returns:
        (the rejection problems found: crashes at load, errors not naming the key or not one
        line; the legal overrides by value label).
    """
    base = load_scenario(name)
    problems: list[str] = []
    legal: dict[str, list[str]] = {}
    sets: dict[tuple[str, str], int] = {}  # how often a group has set each key so far
    for case in cases(base):
        try:
            load_scenario(name, [case.override])
        except ConfigError as err:
            message = str(err)
            if "\n" in message or not message.startswith("--set: ") or case.key not in message:
                problems.append(f"{name} {case.override}: error does not name the key: {message}")
        except Exception as err:
            problems.append(f"{name} {case.override}: crashed at load: {err!r}")
        else:
            # a later --set of a key replaces an earlier one (a whole array of tables, e.g.
            # pilot.goals, holds one bad field per case): one group per setting of a key
            key = case.override.partition("=")[0]
            nth = sets[case.label, key] = sets.get((case.label, key), -1) + 1
            legal.setdefault(f"{case.label}#{nth}", []).append(case.override)
    return problems, legal


def _finishes(name: str, overrides: list[str]) -> str | None:
    """None if the short run with ``overrides`` loads and finishes, else what went wrong.

    Later image-setting changes are dropped unless an override sets them, so the run can end
    a couple of seconds after the pilot starts.
    """
    if not any(override.startswith("images.changes=") for override in overrides):
        overrides = ["images.changes=[]", *overrides]
    try:
        scenario = load_scenario(name, overrides)
    except ConfigError as err:
        return f"legal alone, rejected together: {err}"
    scenario = load_scenario(name, [*overrides, *short_run_overrides(scenario)])
    try:
        result = run_scenario(scenario)
    except Exception as err:
        return f"crashed: {err!r}"
    sim_s = result.metrics["sim_s"]
    if not sim_s >= scenario.duration_s - 1e-6:
        return f"stopped at {sim_s} s of {scenario.duration_s}"
    return None


def check_scenario(name: str) -> None:
    """The property for every key of scenario ``name``."""
    problems, legal = legal_groups(name)
    for overrides in legal.values():
        if _finishes(name, overrides) is None:
            continue
        for override in overrides:  # name the culprits one by one
            failure = _finishes(name, [override])
            if failure is not None:
                problems.append(f"{name} {override}: {failure}")
    assert not problems, "\n".join(problems)


@pytest.mark.parametrize("name", DEFAULT_SCENARIOS)
def test_every_numeric_key_rejects_bad_values_or_runs(name: str) -> None:
    check_scenario(name)


@pytest.mark.slow
@pytest.mark.parametrize(
    "name", [n for n in scenario_names() if n not in DEFAULT_SCENARIOS] or ["s100-teleop-v1"]
)
def test_every_numeric_key_of_every_scenario(name: str) -> None:
    check_scenario(name)


def test_default_scenarios_cover_both_codecs_and_every_key() -> None:
    codecs = {load_scenario(name).link.codec for name in DEFAULT_SCENARIOS}
    assert codecs == {"teleop", "changeset"}
    keys = {leaf.key for name in DEFAULT_SCENARIOS for leaf in _leaves(name)}
    every = {leaf.key for name in scenario_names() for leaf in _leaves(name)}
    # only array entries (pilot.x[1].…, faults.…[0].…) may be absent from the default three
    assert {key for key in every - keys if "[" not in key} == set()


def _leaves(name: str) -> list[Leaf]:
    return list(numeric_leaves(load_scenario(name), Scenario))


def test_enumeration_reaches_nested_flat_optional_and_array_keys() -> None:
    keys = {leaf.key: leaf for leaf in _leaves("s100-video-v1")}
    for key in (
        "duration_s",
        "link.ber",
        "link.propagation.speed_mps",
        "link.operator_position_ned_m",
        "vehicle.gains.roll.kp",
        "vehicle.current_limit_a",
        "vehicle.current.velocity_ned_mps",
        "vehicle.sensors.position.noise_m",
        "vehicle.camera.width_px",
        "pilot.x[0].period_s",
        "images.changes[0].roi",
    ):
        assert key in keys, key
    assert keys["vehicle.current_limit_a"].value is None
    assert keys["vehicle.camera.width_px"].kind == "int"


@pytest.mark.parametrize(
    ("override", "key"),
    [
        ("vehicle.supply_voltage_v=25", "vehicle.supply_voltage_v"),
        ("vehicle.supply_voltage_v=11.9", "vehicle.supply_voltage_v"),
        ("vehicle.gains.depth.kp=1e308", "vehicle.gains.depth.kp"),
        ("vehicle.current.velocity_ned_mps=[inf, 0, 0]", "vehicle.current.velocity_ned_mps[0]"),
        ("vehicle.current.velocity_ned_mps=[4, 4, 0]", "vehicle.current.velocity_ned_mps"),
        ("vehicle.start_euler_rad=[0, 0, inf]", "vehicle.start_euler_rad[2]"),
        ("vehicle.sensors.depth.water_density_kg_m3=1e308", "vehicle.sensors.depth"),
        ("duration_s=1e300", "duration_s"),
        ("vehicle.physics_dt_s=1e-300", "vehicle.physics_dt_s"),
        ("link.uplink_rate_hz=1e308", "link.uplink_rate_hz"),
    ],
)
def test_reported_crashes_and_hangs_are_one_line_errors(override: str, key: str) -> None:
    with pytest.raises(ConfigError) as info:
        load_scenario("tether-teleop-v1", [override])
    message = str(info.value)
    assert message.startswith(f"--set: {key}")
    assert "\n" not in message


def test_run_budget_bounds_duration_with_the_physics_step() -> None:
    with pytest.raises(ConfigError, match=r"--set: duration_s: .* physics steps"):
        load_scenario("s100-teleop-v1", ["duration_s=86400", "vehicle.physics_dt_s=1e-4"])
    fast = ["vehicle.control_rate_hz=1000", "vehicle.physics_dt_s=1e-3"]
    with pytest.raises(ConfigError, match=r"--set: metrics.sample_rate_hz: .* series rows"):
        load_scenario("s100-teleop-v1", ["duration_s=86400", *fast, "metrics.sample_rate_hz=1000"])
    longest = load_scenario("s100-teleop-v1", ["duration_s=86400"])  # the default step: ok
    assert longest.duration_s == 86400.0


def test_run_budget_bounds_a_fixed_token_gap() -> None:
    """The operator sends a frame every fixed gap whether or not the last got through: a 1-ns
    gap on a 10-s run queued 10^10 frames (it ran for days, memory growing)."""
    fixed = ["link.ipg=fixed", "metrics.settle_s=1"]
    with pytest.raises(ConfigError, match=r"--set: link.ipg_s: 1e-09 s .* 1e\+10 token slots"):
        load_scenario("s100-teleop-v1", ["duration_s=10", *fixed, "link.ipg_s=1e-9"])
    day = load_scenario("s100-teleop-v1", ["duration_s=86400", *fixed, "link.ipg_s=0.00864"])
    assert day.duration_s / day.link.ipg_s == pytest.approx(1e7)  # the limit itself: ok


def test_cli_bad_supply_voltage_exits_2_naming_the_key(
    capsys: pytest.CaptureFixture[str], tmp_path: Any
) -> None:
    out = tmp_path / "run"
    code = main(["run", "--set", "vehicle.supply_voltage_v=25", "--no-plots", "--out", str(out)])
    assert code == 2
    err = capsys.readouterr().err
    assert err == (
        "testbed: error: --set: vehicle.supply_voltage_v: must be in [12, 20] V, got 25.0\n"
    )
    assert not out.exists()


@pytest.mark.parametrize("scenario_id", ["s100-teleop-v1", "s100-mavlink-raw-v1"])
def test_a_depth_setpoint_the_codec_cannot_carry_is_refused(scenario_id: str) -> None:
    """The teleop and MAVLink orders carry no depth setpoint: operator.depth_m there was
    silently ignored (the same run whatever its value); the change-set codec carries it."""
    with pytest.raises(ConfigError, match=r"^--set: operator.depth_m: only used when link.codec"):
        load_scenario(scenario_id, ["operator.depth_m=5"])
    assert load_scenario("tether-teleop-v1", ["operator.depth_m=5"]).operator.depth_m == 5.0


def test_attitude_setpoints_slower_than_the_failsafe_are_refused() -> None:
    """The attitude pilot's setpoints are its only contact (a held one is not sent again): at
    0.5 Hz against the 1-s hold the failsafe held and released every second over a perfect
    tether. Raising the hold admits the slow rate."""
    with pytest.raises(ConfigError, match=r"^--set: pilot.setpoint_rate_hz: a setpoint every 2 s"):
        load_scenario("ecs-rollpitch-6dof-v1", ["pilot.setpoint_rate_hz=0.5"])
    slow = ["pilot.setpoint_rate_hz=0.5", "vehicle.failsafe.hold_after_s=2.5"]
    assert load_scenario("ecs-rollpitch-6dof-v1", slow).pilot.setpoint_rate_hz == 0.5


def test_an_end_effector_goal_needs_an_arm() -> None:
    """It was accepted on a vehicle without an arm and flown as a body goal."""
    goal = "pilot.goals=[{t_s = 2.0, position_ned_m = [1.0, 0.0, 1.0], frame = 'end_effector'}]"
    with pytest.raises(ConfigError, match=r"^--set: pilot.goals\[0\].frame: an 'end_effector'"):
        load_scenario("s100-supervised-v1", [goal])
    armed = load_scenario("uvms-waypoint-v1")
    assert armed.vehicle.arm is not None


def test_a_vehicle_cannot_start_above_the_surface() -> None:
    """It was accepted 10 km up and fell at a water-drag terminal velocity."""
    with pytest.raises(ConfigError, match=r"^--set: vehicle.start_position_ned_m: the depth"):
        load_scenario("s100-teleop-v1", ["vehicle.start_position_ned_m=[0.0, 0.0, -10000.0]"])
    surface = load_scenario("s100-teleop-v1", ["vehicle.start_position_ned_m=[0.0, 0.0, 0.0]"])
    assert surface.vehicle.start_position_ned_m[2] == 0.0


def test_an_arm_under_the_pid_controller_is_refused(
    capsys: pytest.CaptureFixture[str], tmp_path: Any
) -> None:
    """TPIK's vehicle twist is flown only by the ISMC: with controller = "pid" an arm's
    mission left the hull with no horizontal control (it drifted 4.5 m with the current, the
    end effector 1.6 m off, no goal reached) and no word of it."""
    out = tmp_path / "run"
    pid = "vehicle.autonomy.controller=pid"
    code = main(["run", "uvms-waypoint-v1", "--set", pid, "--no-plots", "--out", str(out)])
    assert code == 2
    err = capsys.readouterr().err
    assert err.startswith("testbed: error: --set: vehicle.autonomy.controller: 'pid' cannot fly")
    assert "vehicle.arm" in err and err.count("\n") == 1
    assert not out.exists()
    assert load_scenario("heavy-waypoint-v1", [pid]).vehicle.autonomy is not None  # no arm: ok


def test_a_supervisor_goal_above_the_surface_is_refused() -> None:
    """The GoTo was sent and flown: the hull broached."""
    goal = "pilot.goals=[{t_s = 2.0, position_ned_m = [1.0, 0.0, -2.0]}]"
    with pytest.raises(ConfigError, match=r"^--set: pilot.goals\[0\].position_ned_m: the depth"):
        load_scenario("s100-supervised-v1", [goal])
    surface = "pilot.goals=[{t_s = 2.0, position_ned_m = [1.0, 0.0, 0.0]}]"
    assert load_scenario("s100-supervised-v1", [surface]).pilot is not None


@pytest.mark.parametrize(
    ("override", "key", "says"),
    [
        ("images.roi=[40, 30, 119, 89]", "images.roi", "needs roi_shift ≥ 1"),
        ("images.changes=[{t_s=20, roi=[1, 2, 3, 4]}]", "images.changes[0].roi", "needs roi_sh"),
        ("images.changes=[{t_s=20, roi=[], roi_shift=3}]", "images.changes[0].roi_shift", "clears"),
        ("images.changes=[{t_s=inf}]", "images.changes[0].t_s", "must be a finite time ≥ 0"),
    ],
)
def test_a_region_of_interest_the_coder_would_ignore_is_refused(
    override: str, key: str, says: str
) -> None:
    """A region with roi_shift 0 (the coder's "no region"), or a change that clears the region
    and sets a shift, was accepted and silently coded no region (an images researcher's
    review: the ROI baseline was unmeasurable from the outputs); a region with a shift runs."""
    with pytest.raises(ConfigError) as info:
        load_scenario("s100-video-v1", [override])
    message = str(info.value)
    assert message.startswith(f"--set: {key}: ") and says in message and "\n" not in message
    shifted = load_scenario("s100-video-v1", ["images.roi=[40, 30, 119, 89]", "images.roi_shift=4"])
    assert shifted.images.roi == (40, 30, 119, 89) and shifted.images.roi_shift == 4
