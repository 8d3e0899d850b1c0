"""Scenarios: versioned TOML files loaded into frozen dataclasses, with ``--set`` overrides.

A scenario is everything one run needs apart from the seed: the link (a channel preset plus
overrides, the codec, the medium access and the operator's modem position), the vehicle
(a :class:`~testbed.vehicle.vehicle_config.VehicleConfig`), the operator's start-up requests,
the pilot, the faults and the metric settings. The packaged scenarios live in
``testbed/scenarios/*.toml`` (package data, each with a header saying what it reproduces and
where its figures come from) and are named by versioned ids (``s100-teleop-v1``): a changed
meaning gets a new version.

Loading is strict (:mod:`testbed.config`): an unknown key at any level, a wrong type, a value
out of range, an unknown preset, model, layout or thruster name, or a schema version other than
1 is a :class:`~testbed.config.ConfigError` whose one-line message names the file (or
``--set``) and the dotted key. ``--set a.b=value`` overrides are applied to the file's data and
checked exactly like the file: first the file alone is checked (errors name the file), then the
file with the overrides (errors name ``--set``).

The ``[link]`` table is flat: besides the :class:`LinkSection` options it takes any key of
:class:`~testbed.channel.LinkConfig` (``ber = 1e-4``, ``[link.propagation] speed_mps = 1500``),
applied over the preset as :func:`~testbed.channel.load_link_config` applies overrides, with
nested tables merged key by key.

The sections' dataclasses and their checks are in :mod:`testbed.run.sections`; this module
holds the whole :class:`Scenario`, its cross-section checks and the loader.
"""

from __future__ import annotations

import dataclasses
import hashlib
import re
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any, TypeVar

from testbed.channel import (
    LinkConfig,
    load_link_config,
)
from testbed.config import (
    ConfigError,
    FieldError,
    apply_overrides,
    build,
    built_from_text,
    check,
    check_range,
    load_toml,
    parse_override,
)
from testbed.run.images import ImagesSection
from testbed.run.plugins import (
    check_arguments,
    load_factory,
    takes_rng,
    target_file,
    target_files,
)
from testbed.run.sections import (
    MAX_DURATION_S,
    FaultsSection,
    LinkOutage,
    LinkSection,
    MetricsSection,
    OperatorSection,
    PilotSection,
    SineTerm,
    ThrusterFault,
)
from testbed.vehicle.t200 import T200
from testbed.vehicle.thruster_config import load_thruster_config
from testbed.vehicle.vehicle_config import VehicleConfig

__all__ = [
    "ID_PATTERN",
    "MAX_DURATION_S",
    "MAX_PHYSICS_STEPS",
    "MAX_SERIES_ROWS",
    "MAX_TOKEN_SLOTS",
    "MAX_TRIALS",
    "SCHEMA_VERSION",
    "FaultsSection",
    "LinkOutage",
    "LinkSection",
    "MetricsSection",
    "OperatorSection",
    "PilotSection",
    "Scenario",
    "SineTerm",
    "ThrusterFault",
    "load_scenario",
    "scenario_digest",
    "scenario_names",
]

SCHEMA_VERSION = 1
"""The only scenario schema version this loader reads."""

MAX_PHYSICS_STEPS = 100_000_000
"""Most physics steps a run may take (``duration_s / vehicle.physics_dt_s``): ≈ 1.3 h of wall
time at the ≈ 45 µs a step (with its share of the frames) costs on s100-teleop-v1. The
default step (1/240 s) allows the whole :data:`MAX_DURATION_S`."""
MAX_SERIES_ROWS = 10_000_000
"""Most series rows a run may record (``duration_s × min(metrics.sample_rate_hz,
vehicle.control_rate_hz)``, a row at most once a frame): ≈ 3.1 GB at 39 columns × 8 B."""
MAX_TRIALS = 100
"""Most trials (runs with consecutive seeds) one scenario may ask for."""
MAX_TOKEN_SLOTS = 10_000_000
"""Most token slots a fixed-gap run may hold (``duration_s / link.ipg_s``): the operator sends a
frame every gap whether or not the last one got through, so a gap of 1 ns on a 10-s run is
10¹⁰ frames queued (it ran for days, growing memory). 10⁷ slots is ≈ 10 min of wall time; the
whole :data:`MAX_DURATION_S` allows gaps from 8.64 ms."""

ID_PATTERN = re.compile(r"^[a-z0-9-]+-v[0-9]+$")
"""A versioned id (``s100-teleop-v1``): scenarios' and sweeps' (a sweep's names its default
results folder, so it can hold no path separator or ``..``)."""
_PACKAGE = "testbed"
_SCENARIO_DIR = "scenarios"
T = TypeVar("T")


@dataclass(frozen=True, slots=True, kw_only=True)
class Scenario:
    """One run's configuration (the seed aside, which the CLI's ``--seed`` may override).

    Attributes:
        id: versioned id, ``^[a-z0-9-]+-v[0-9]+$`` (``s100-teleop-v1``).
        description: one line for listings and reports.
        schema: scenario schema version; only :data:`SCHEMA_VERSION` is accepted.
        duration_s: simulated time [s], in (0, :data:`MAX_DURATION_S`] (one day), with at
            most :data:`MAX_PHYSICS_STEPS` physics steps, :data:`MAX_TOKEN_SLOTS` fixed-gap
            token slots and :data:`MAX_SERIES_ROWS` series rows.
        seed: default seed, ≥ 0.
        trials: how many runs ``testbed run`` makes, with seeds ``seed, seed + 1, …``
            (:mod:`testbed.run.trials`), in [1, :data:`MAX_TRIALS`].
        link, vehicle, operator, pilot, faults, metrics, images: the sections.
        source: where it was loaded from (a path or ``package:<id>``), for messages; not a
            TOML key.
        overrides: the ``--set`` overrides applied on top of ``source``, in order.
        files: SHA-256 (hex) of each user file the run reads, by path: the scenario file and
            a link preset, model, thruster layout or mission given by path (packaged ones are
            named by the package's version); taken when the scenario loads.
    """

    id: str
    description: str
    schema: int
    duration_s: float
    seed: int = 0
    trials: int = 1
    link: LinkSection
    vehicle: VehicleConfig
    operator: OperatorSection = field(default_factory=OperatorSection)
    pilot: PilotSection = field(default_factory=PilotSection)
    faults: FaultsSection = field(default_factory=FaultsSection)
    metrics: MetricsSection = field(default_factory=MetricsSection)
    images: ImagesSection = field(default_factory=ImagesSection)
    source: str
    overrides: tuple[str, ...] = ()
    files: tuple[tuple[str, str], ...] = ()

    def __post_init__(self) -> None:
        check(
            ID_PATTERN.fullmatch(self.id) is not None,  # `$` alone lets a final newline in
            "id",
            f"must match {ID_PATTERN.pattern} (e.g. 's100-teleop-v1'), got {self.id!r}",
        )
        check(
            self.schema == SCHEMA_VERSION,
            "schema",
            f"unsupported schema version {self.schema} (supported: {SCHEMA_VERSION})",
        )
        check_range(self.duration_s, "duration_s", 0.0, MAX_DURATION_S, "s", low_open=True)
        check(self.seed >= 0, "seed", f"must be ≥ 0, got {self.seed}")
        check(
            1 <= self.trials <= MAX_TRIALS,
            "trials",
            f"must be an integer in [1, {MAX_TRIALS}], got {self.trials}",
        )
        self._check_budget()
        end = self.duration_s
        for i, fault in enumerate(self.faults.thrusters):
            check(fault.t_s < end, f"faults.thrusters[{i}].t_s", f"must be < duration_s ({end})")
        for i, outage in enumerate(self.faults.link_outages):
            check(
                outage.end_s <= end,
                f"faults.link_outages[{i}].end_s",
                f"must be ≤ duration_s ({end}), got {outage.end_s}",
            )
        autonomy = self.vehicle.autonomy
        for key, value in (
            ("operator.arm_at_s", self.operator.arm_at_s),
            ("pilot.start_s", self.pilot.start_s),
            ("metrics.settle_s", self.metrics.settle_s),
            ("vehicle.autonomy.start_s", 0.0 if autonomy is None else autonomy.start_s),
        ):
            check(value < end, key, f"must be < duration_s ({end}), got {value}")
        self._check_images()
        check(
            self.pilot.kind != "attitude" or self.operator.mode != "manual",
            "operator.mode",
            "the attitude pilot needs 'stabilize' or 'depth_hold', got 'manual'",
        )
        if self.vehicle.arm is None:
            for i, goal in enumerate(self.pilot.goals):
                check(
                    goal.frame != "end_effector",
                    f"pilot.goals[{i}].frame",
                    "an 'end_effector' goal needs an arm on the vehicle (vehicle.arm)",
                )
        if self.pilot.kind == "attitude":  # a held setpoint is no news: it is not sent again
            period, hold = 1.0 / self.pilot.setpoint_rate_hz, self.vehicle.failsafe.hold_after_s
            check(
                period < hold,
                "pilot.setpoint_rate_hz",
                f"a setpoint every {period:g} s is no fresher than vehicle.failsafe.hold_after_s "
                f"({hold:g} s): the failsafe would hold between setpoints (raise one of them)",
            )

    def _check_budget(self) -> None:
        """The run's size is bounded, so every accepted scenario finishes."""
        vehicle = self.vehicle
        steps = self.duration_s / vehicle.physics_dt_s
        check(
            steps <= MAX_PHYSICS_STEPS,
            "duration_s",
            f"{self.duration_s:g} s at vehicle.physics_dt_s = {vehicle.physics_dt_s:g} s is "
            f"{steps:.3g} physics steps, more than the {MAX_PHYSICS_STEPS:.0e} allowed",
        )
        link = self.link
        if link.mac == "token" and link.ipg == "fixed":
            slots = self.duration_s / link.ipg_s
            check(
                slots <= MAX_TOKEN_SLOTS,
                "link.ipg_s",
                f"{link.ipg_s:g} s over duration_s = {self.duration_s:g} s is {slots:.3g} token "
                f"slots, more than the {MAX_TOKEN_SLOTS:.0e} allowed",
            )
        rate = min(self.metrics.sample_rate_hz, vehicle.control_rate_hz)
        rows = self.duration_s * rate
        check(
            rows <= MAX_SERIES_ROWS,
            "metrics.sample_rate_hz",
            f"{rate:g} Hz over duration_s = {self.duration_s:g} s is {rows:.3g} series rows, "
            f"more than the {MAX_SERIES_ROWS:.0e} allowed",
        )

    def _check_images(self) -> None:
        """Images ride on token-passing teleop replies and need the vehicle's camera."""
        images = self.images
        if not images.enabled:
            return
        check(
            self.link.codec == "teleop" and self.link.mac == "token",
            "images.enabled",
            "needs link.codec = 'teleop' and link.mac = 'token' (chunks ride on the replies)",
        )
        camera = self.vehicle.camera
        check(camera.enabled, "images.enabled", "needs vehicle.camera.enabled = true")
        rois: list[tuple[str, tuple[int, ...] | None]] = [("images.roi", images.roi)]
        rois += [(f"images.changes[{i}].roi", c.roi) for i, c in enumerate(images.changes)]
        for key, roi in rois:
            if roi:
                check(
                    roi[2] < camera.width_px and roi[3] < camera.height_px,
                    key,
                    f"must lie inside the {camera.width_px}x{camera.height_px} camera image, "
                    f"got {list(roi)}",
                )
        for i, change in enumerate(images.changes):
            check(
                change.t_s < self.duration_s,
                f"images.changes[{i}].t_s",
                f"must be < duration_s ({self.duration_s}), got {change.t_s}",
            )


# --- loading -----------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class _ScenarioFile:
    """The file's top level: header values typed here, section tables built separately."""

    schema: int
    id: str
    description: str
    duration_s: float
    seed: int = 0
    trials: int = 1
    link: dict[str, Any] = field(default_factory=dict)
    vehicle: dict[str, Any] = field(default_factory=dict)
    operator: dict[str, Any] = field(default_factory=dict)
    pilot: dict[str, Any] = field(default_factory=dict)
    faults: dict[str, Any] = field(default_factory=dict)
    metrics: dict[str, Any] = field(default_factory=dict)
    images: dict[str, Any] = field(default_factory=dict)


_LINK_OPTIONS = tuple(f.name for f in dataclasses.fields(LinkSection) if f.name != "channel")
_CHANNEL_KEYS = tuple(f.name for f in dataclasses.fields(LinkConfig))


def _scenario_dir() -> Any:
    return resources.files(_PACKAGE).joinpath(_SCENARIO_DIR)


def scenario_names() -> list[str]:
    """Ids of the packaged scenarios (``testbed/scenarios/*.toml``), sorted."""
    return sorted(
        entry.name.removesuffix(".toml")
        for entry in _scenario_dir().iterdir()
        if entry.name.endswith(".toml")
    )


def load_scenario(
    name_or_path: str, overrides: Sequence[str] = (), *, overrides_source: str = "--set"
) -> Scenario:
    """Load a packaged scenario by id, or a scenario file by path, and apply overrides.

    Args:
        name_or_path: a packaged id (``"s100-teleop-v1"``, see :func:`scenario_names`) or the
            path of a ``.toml`` file (anything ending in ``.toml``, containing a path separator
            or naming an existing file).
        overrides: ``"a.b=value"`` strings (``--set``), e.g. ``"link.ber=1e-4"``,
            ``"vehicle.model=bluerov2-heavy"``, ``"pilot.x=[{amplitude=0.2, period_s=30}]"``.
        overrides_source: what errors of the overridden scenario name as their source
            (``--set``; a sweep names its file's ``[set]`` or grid point).

    Returns:
        The checked scenario.

    Raises:
        ConfigError: one line naming the file (or ``--set``) and the dotted key: missing file,
            malformed TOML, unknown scenario id (listing the known ones), unknown key, wrong
            type, value out of range, unknown preset/model/layout/thruster, unsupported schema.
    """
    text = str(name_or_path)
    packaged_id: str | None = None
    if text.endswith(".toml") or "/" in text or "\\" in text or Path(text).is_file():
        source = text
        data = _paths_beside(load_toml(text), Path(text).parent)
        scenario = _file_scenario(Path(text), data, source)
    else:
        known = scenario_names()
        if text not in known:
            raise ConfigError(f"scenario {text!r}: unknown scenario id (known: {', '.join(known)})")
        packaged_id = text
        source = f"package:{text}"
        with resources.as_file(_scenario_dir().joinpath(f"{text}.toml")) as file:
            data = load_toml(file)
            scenario = _file_scenario(file, data, source)
    if packaged_id is not None and scenario.id != packaged_id:
        raise ConfigError(f"{source}: id: must equal the file name, got {scenario.id!r}")
    if overrides:
        given = set()
        for text_override in overrides:
            path_parts, _ = parse_override(text_override)
            if path_parts[0] == "link" and len(path_parts) > 1:
                given.add(path_parts[1])
        scenario = _from_data(apply_overrides(data, overrides), overrides_source, source, given)
    own = [] if packaged_id is not None else [source]
    return dataclasses.replace(
        scenario, overrides=tuple(overrides), files=_digests([*own, *_user_files(scenario)])
    )


_FILE_KEYS = (
    ("link", "preset"),
    ("vehicle", "model"),
    ("vehicle", "thrusters"),
    ("vehicle", "autonomy", "mission"),
    ("vehicle", "arm", "model"),
    ("vehicle", "arm", "tpik"),
    ("pilot", "factory"),
    ("link", "model"),
)
"""Keys that may name a user's file by path (the last two a Python file, ``FILE.py:NAME``)."""


FILE_KEY_NAMES = frozenset(".".join(key) for key in _FILE_KEYS)
"""The dotted names of :data:`_FILE_KEYS` (``vehicle.thrusters``...)."""


def path_beside(value: Any, folder: Path) -> Any:
    """``value`` of a file key (:data:`FILE_KEY_NAMES`) as written in a file kept in
    ``folder``: a relative path of a user file (ending in ``.toml``/``.json``, or a
    ``FILE.py:NAME`` target) taken from ``folder``; anything else (a packaged name, a module,
    an absolute path) as it is."""
    if isinstance(value, str):
        python = target_file(value)
        if python is not None and not Path(python).is_absolute():
            return f"{folder / python}:{value.rpartition(':')[2]}"
        path = Path(value)
        if not path.is_absolute() and path.suffix in (".toml", ".json"):
            return str(folder / path)
    return value


def _file_scenario(file: Path, data: dict[str, Any], source: str) -> Scenario:
    """The scenario of a file's own ``data`` (read from ``file``, the one ``source`` names),
    without overrides, so that its errors name the file, not ``--set``; built once per text of
    the file and of the user files it names in this process (a sweep loads it once per grid
    point)."""
    link_keys = data.get("link")
    given = set(link_keys) if isinstance(link_keys, Mapping) else set()
    named = tuple(_named_file_texts(data))
    return built_from_text(
        "scenario", file, lambda: _from_data(data, source, source, given), *named
    )


def _named_file_texts(data: Mapping[str, Any]) -> Iterator[str]:
    """The text of each user file a scenario's ``data`` names by path (:data:`_FILE_KEYS`;
    "" for one that cannot be read, which the build then names)."""
    for key in _FILE_KEYS:
        value: Any = data
        for part in key:
            value = value.get(part) if isinstance(value, Mapping) else None
        if not isinstance(value, str):
            continue
        path = target_file(value) or (value if Path(value).suffix in (".toml", ".json") else None)
        if path is not None:
            try:
                yield Path(path).read_text(encoding="utf-8")
            except (OSError, UnicodeDecodeError):
                yield ""


def _paths_beside(data: dict[str, Any], folder: Path) -> dict[str, Any]:
    """A scenario file's data with the relative paths of its user files (a preset, model,
    layout, mission, arm model or TPIK configuration ending in ``.toml``/``.json``) taken from
    the file's ``folder``, so a
    scenario kept beside its files runs from anywhere (``--set`` paths stay the working
    directory's, as on any command line)."""
    for key in _FILE_KEYS:
        table: Any = data
        for part in key[:-1]:
            table = table.get(part) if isinstance(table, dict) else None
        if isinstance(table, dict) and key[-1] in table:
            table[key[-1]] = path_beside(table[key[-1]], folder)
    return data


def _user_files(scenario: Scenario) -> list[str]:
    """The data files given by path (a link preset, a model, a thruster layout, a mission, an
    arm model, a TPIK configuration), not packaged."""
    vehicle = scenario.vehicle
    named = [scenario.link.preset, vehicle.model, vehicle.thrusters]
    if vehicle.autonomy is not None and vehicle.autonomy.mission is not None:
        named.append(vehicle.autonomy.mission)
    if vehicle.arm is not None:
        named += [vehicle.arm.model, vehicle.arm.tpik]
    files = [name for name in named if Path(name).suffix in (".toml", ".json")]
    for target in (scenario.pilot.factory, scenario.link.model):
        if target:
            files += target_files(target)
    return files


def scenario_digest(name_or_path: str) -> tuple[str, str]:
    """``(source, SHA-256 hex)`` of a scenario file's content: ``package:<id>`` for a packaged
    scenario (whose file a code update may change), else the path (as :func:`load_scenario`
    records it in ``files``)."""
    text = str(name_or_path)
    if text.endswith(".toml") or "/" in text or "\\" in text or Path(text).is_file():
        return _digests([text])[0]
    with resources.as_file(_scenario_dir().joinpath(f"{text}.toml")) as path:
        return f"package:{text}", _digests([str(path)])[0][1]


def _digests(paths: Sequence[str]) -> tuple[tuple[str, str], ...]:
    """``(path, SHA-256 hex)`` of each file, in order, once each (an unreadable one: "")."""
    digests: dict[str, str] = {}
    for path in paths:
        try:
            digests[path] = hashlib.sha256(Path(path).read_bytes()).hexdigest()
        except OSError:
            digests[path] = ""
    return tuple(digests.items())


def _from_data(
    data: Mapping[str, Any], where: str, source: str, given_link_keys: set[str]
) -> Scenario:
    """Build a scenario from a file's data; errors name ``where`` (the file or ``--set``)."""
    schema = data.get("schema")
    if schema is None:
        raise ConfigError(f"{where}: schema: required key missing (schema = {SCHEMA_VERSION})")
    if schema != SCHEMA_VERSION or isinstance(schema, bool):
        raise ConfigError(
            f"{where}: schema: unsupported schema version {schema!r} (supported: {SCHEMA_VERSION})"
        )
    top = build(_ScenarioFile, data, source=where)
    link = _build_link(top.link, where, given_link_keys)
    vehicle = build(VehicleConfig, top.vehicle, source=where, prefix="vehicle.")
    _check_file(lambda _: vehicle.hydro_model(), vehicle.model, where, "vehicle.model")
    layout = _loaded(load_thruster_config, vehicle.thrusters, where, "vehicle.thrusters")
    operator = build(OperatorSection, top.operator, source=where, prefix="operator.")
    if operator.mode == "depth_hold" and not layout.matrix[2].any():
        raise ConfigError(
            f"{where}: operator.mode: 'depth_hold' needs thrust along the body's z axis, and the "
            f"layout {vehicle.thrusters!r} has none (no vertical thruster): use 'manual' or "
            "'stabilize'"
        )
    holds_heading = operator.mode in ("stabilize", "depth_hold")
    if holds_heading and not layout.matrix[5].any():
        raise ConfigError(
            f"{where}: operator.mode: {operator.mode!r} holds the heading, which needs a yaw "
            f"moment, and the layout {vehicle.thrusters!r} can make none (every thruster's "
            "line of force passes through the centre of mass): use 'manual'"
        )
    if operator.depth_m is not None and link.codec != "changeset":
        raise ConfigError(
            f"{where}: operator.depth_m: only used when link.codec = 'changeset' (the teleop "
            "and MAVLink orders carry no depth setpoint: depth hold keeps the depth at arming)"
        )
    pilot = build(PilotSection, top.pilot, source=where, prefix="pilot.")
    if pilot.kind == "python":
        if "start_s" in top.pilot:  # a pilot of one's own starts when it says (its args)
            raise ConfigError(f"{where}: pilot.start_s: not used when kind = 'python'")
        factory = load_factory(pilot.factory, where, "pilot.factory")
        given = {**pilot.args, "rng": None} if takes_rng(factory) else pilot.args
        keys = ("pilot.factory", "pilot.args", "(**args)")
        check_arguments(factory, pilot.factory, (), given, where, keys)
    faults = build(FaultsSection, top.faults, source=where, prefix="faults.")
    metrics = build(MetricsSection, top.metrics, source=where, prefix="metrics.")
    images = build(ImagesSection, top.images, source=where, prefix="images.")
    if faults.thrusters:
        names = [t.name for t in load_thruster_config(vehicle.thrusters).thrusters]
        low, high = T200.from_table(vehicle.supply_voltage_v).force_limits_n
        for i, fault in enumerate(faults.thrusters):
            key = f"faults.thrusters[{i}].thruster"
            _check_name(fault.thruster, names, where, key, "thruster", f" of {vehicle.thrusters}")
            stuck_at = fault.value if fault.mode == "stuck" else None
            if stuck_at is not None and not low <= stuck_at <= high:
                raise ConfigError(
                    f"{where}: faults.thrusters[{i}].value: a stuck T200 at "
                    f"{vehicle.supply_voltage_v:g} V holds [{low:g}, {high:g}] N, "
                    f"got {stuck_at:g}"
                )
    try:
        return Scenario(
            id=top.id,
            description=top.description,
            schema=top.schema,
            duration_s=top.duration_s,
            seed=top.seed,
            trials=top.trials,
            link=link,
            vehicle=vehicle,
            operator=operator,
            pilot=pilot,
            faults=faults,
            metrics=metrics,
            images=images,
            source=source,
        )
    except FieldError as err:
        raise ConfigError(f"{where}: {err.key}: {err.message}") from None


def _build_link(table: Mapping[str, Any], where: str, given: set[str]) -> LinkSection:
    """Split ``[link]`` into section options and channel keys; build both (keys ``link.*``)."""
    known = (*_LINK_OPTIONS, *_CHANNEL_KEYS)
    unknown = sorted(set(table) - set(known))
    if unknown:
        listed = ", ".join(sorted(known))
        raise ConfigError(f"{where}: link.{unknown[0]}: unknown key (known: {listed})")
    options = {k: v for k, v in table.items() if k in _LINK_OPTIONS}
    preset = options.get("preset", "s100")
    base = dataclasses.asdict(_loaded(load_link_config, preset, where, "link.preset"))
    channel_data = _merge(base, {k: v for k, v in table.items() if k in _CHANNEL_KEYS})
    build(LinkConfig, channel_data, source=where, prefix="link.")  # errors name link.<key>
    section = build(LinkSection, {**options, "channel": channel_data}, source=where, prefix="link.")
    if section.codec == "teleop" and section.mac == "free":
        raise ConfigError(
            f"{where}: link.mac: 'free' does not work with link.codec = 'teleop' (its vehicle only "
            "answers orders, on a token-passing link: use link.mac = 'token' or another codec)"
        )
    if section.model:
        factory = load_factory(section.model, where, "link.model")
        keys = ("link.model", "link.model_args", "(config, **model_args)")
        check_arguments(factory, section.model, (section.channel,), section.model_args, where, keys)
    if "ipg_s" in given and section.ipg != "fixed":
        raise ConfigError(f"{where}: link.ipg_s: only used when link.ipg = 'fixed'")
    if "snapshot_period_s" in given and section.codec != "changeset":
        raise ConfigError(
            f"{where}: link.snapshot_period_s: only used when link.codec = 'changeset'"
        )
    for key in ("uplink_rate_hz", "downlink_rate_hz"):
        if key in given and not section.rates_used:
            when = "link.mac = 'free' or link.codec = 'changeset'"
            raise ConfigError(f"{where}: link.{key}: only used when {when}")
    return section


def _check_file(load: Callable[[str], object], name: str, where: str, key: str) -> None:
    """Load a named data file (packaged, or the user's own at a path) now, so a bad name or a
    bad file is a one-line error naming ``key`` before anything runs."""
    _loaded(load, name, where, key)


def _loaded(load: Callable[[str], T], name: str, where: str, key: str) -> T:
    """``load(name)``, its errors one line naming ``where`` and ``key``."""
    try:
        return load(name)
    except ConfigError as err:
        raise ConfigError(f"{where}: {key}: {err}") from None


def _check_name(
    value: object, known: Sequence[str], where: str, key: str, what: str, context: str = ""
) -> None:
    if value not in known:
        listed = ", ".join(known)
        raise ConfigError(f"{where}: {key}: unknown {what} {value!r}{context} (known: {listed})")


def _merge(base: Mapping[str, Any], changes: Mapping[str, Any]) -> dict[str, Any]:
    """``base`` with ``changes`` applied; tables present in both are merged key by key."""
    result = dict(base)
    for key, value in changes.items():
        old = result.get(key)
        if isinstance(old, Mapping) and isinstance(value, Mapping):
            result[key] = _merge(old, value)
        else:
            result[key] = value
    return result
