"""The scenario loader: versioned TOML files, with ``--set`` overrides, into checked scenarios.

:func:`load_scenario` reads a packaged scenario by id (:mod:`testbed.run.scenario_files`) or a
scenario file by path into a :class:`~testbed.run.scenario_config.Scenario`. A changed meaning
gets a new version of the id.

Loading is strict (:mod:`testbed.config`): an unknown key at any level, a wrong type, a value
out of range, an unknown preset, model, layout or thruster name, or a schema version other than
1 is a :class:`~testbed.config.ConfigError` whose one-line message names the file (or
``--set``) and the dotted key. ``--set a.b=value`` overrides are applied to the file's data and
checked exactly like the file: first the file alone is checked (errors name the file), then the
file with the overrides (errors name ``--set``).

The ``[link]`` table is flat: besides the :class:`~testbed.run.sections.LinkSection` options it
takes any key of :class:`~testbed.channel.LinkConfig` (``ber = 1e-4``,
``[link.propagation] speed_mps = 1500``), applied over the preset as
:func:`~testbed.channel.load_link_config` applies overrides, with nested tables merged key by
key.

``[vehicle.control]`` (:class:`~testbed.run.sections.ControlLawsSection`, the holds of the
user's own) is built apart from the rest of ``[vehicle]``
(:class:`~testbed.vehicle.vehicle_config.VehicleConfig`).

The checks that need other files or sections' data while building (the thruster layout against
the operator's mode and the thruster faults, a pilot's, link model's or control law's factory
against its arguments) are here; the whole scenario's own cross-section checks are in
:mod:`testbed.run.scenario_config`, each section's in :mod:`testbed.run.sections`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
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
    load_toml,
    parse_override,
)
from testbed.run.images import ImagesSection
from testbed.run.plugins import check_arguments, load_factory
from testbed.run.scenario_config import SCHEMA_VERSION, Scenario
from testbed.run.scenario_files import (
    file_digests,
    named_file_texts,
    paths_beside,
    scenario_dir,
    scenario_names,
    user_files,
)
from testbed.run.sections import (
    ControlLawsSection,
    FaultsSection,
    LinkSection,
    MetricsSection,
    OperatorSection,
    PilotSection,
)
from testbed.vehicle.allocation import Allocator
from testbed.vehicle.t200 import T200
from testbed.vehicle.thruster_config import ThrusterConfig, load_thruster_config
from testbed.vehicle.vehicle_config import VehicleConfig

__all__ = ["load_scenario"]

T = TypeVar("T")


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


_CONTROL = "control"
"""The ``[vehicle]`` key of :class:`~testbed.run.sections.ControlLawsSection`, built apart."""
_VEHICLE_KEYS = tuple(f.name for f in dataclasses.fields(VehicleConfig))
_LINK_OPTIONS = tuple(f.name for f in dataclasses.fields(LinkSection) if f.name != "channel")
_CHANNEL_KEYS = tuple(f.name for f in dataclasses.fields(LinkConfig))


def _check_guided(vehicle: VehicleConfig, layout: ThrusterConfig, where: str) -> None:
    """``operator.mode = 'guided'`` needs what GUIDED flies with: a position fix (the vehicle
    refuses GUIDED without one, as ArduSub does) and a pure force along each of the body's x
    and y axes (it holds a point).

    The force is judged as the allocator judges it (:meth:`Allocator.axis_maxima`, both
    directions, healthy thrusters, the vehicle's supply and current budget): a layout whose
    thrusters push along x and y only together (``ecs-2h``: its pair moves along a diagonal)
    has none along either.

    Raises:
        ConfigError: one line naming ``operator.mode``.
    """
    if vehicle.sensors.position is None and vehicle.navigation_in_use is None:
        raise ConfigError(
            f"{where}: operator.mode: 'guided' needs a position fix (vehicle.sensors.position "
            "or vehicle.navigation), and the vehicle has none: add one, or use 'manual', "
            "'stabilize' or 'depth_hold'"
        )
    allocator = Allocator(
        layout, T200.from_table(vehicle.supply_voltage_v), current_limit_a=vehicle.current_limit_a
    )
    surge_n, sway_n = (float(v) for v in allocator.axis_maxima()[:2])
    if not (surge_n > 0.0 and sway_n > 0.0):
        raise ConfigError(
            f"{where}: operator.mode: 'guided' holds a point, which needs a force along each of "
            f"the body's x and y axes on its own, and the layout {vehicle.thrusters!r} cannot "
            f"make one (its allocator's largest pure force: x {surge_n:.3g} N, y "
            f"{sway_n:.3g} N): use 'manual', 'stabilize' or 'depth_hold'"
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
        data = paths_beside(load_toml(text), Path(text).parent)
        scenario = _file_scenario(Path(text), data, source)
    else:
        known = scenario_names()
        if text not in known:
            raise ConfigError(f"scenario {text!r}: unknown scenario id (known: {', '.join(known)})")
        packaged_id = text
        source = f"package:{text}"
        with resources.as_file(scenario_dir().joinpath(f"{text}.toml")) as file:
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
        scenario, overrides=tuple(overrides), files=file_digests([*own, *user_files(scenario)])
    )


def _file_scenario(file: Path, data: dict[str, Any], source: str) -> Scenario:
    """The scenario of a file's own ``data`` (read from ``file``, the one ``source`` names),
    without overrides, so that its errors name the file, not ``--set``; built once per text of
    the file and of the user files it names in this process (a sweep loads it once per grid
    point)."""
    link_keys = data.get("link")
    given = set(link_keys) if isinstance(link_keys, Mapping) else set()
    named = tuple(named_file_texts(data))
    return built_from_text(
        "scenario", file, lambda: _from_data(data, source, source, given), *named
    )


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
    vehicle_table = {k: v for k, v in top.vehicle.items() if k != _CONTROL}
    unknown = sorted(set(vehicle_table) - set(_VEHICLE_KEYS))
    if unknown:
        listed = ", ".join(sorted((*_VEHICLE_KEYS, _CONTROL)))
        raise ConfigError(f"{where}: vehicle.{unknown[0]}: unknown key (known: {listed})")
    vehicle = build(VehicleConfig, vehicle_table, source=where, prefix="vehicle.")
    _check_file(lambda _: vehicle.hydro_model(), vehicle.model, where, "vehicle.model")
    layout = _loaded(load_thruster_config, vehicle.thrusters, where, "vehicle.thrusters")
    operator = build(OperatorSection, top.operator, source=where, prefix="operator.")
    if operator.mode in ("depth_hold", "guided") and not layout.matrix[2].any():
        raise ConfigError(
            f"{where}: operator.mode: {operator.mode!r} needs thrust along the body's z axis, and "
            f"the layout {vehicle.thrusters!r} has none (no vertical thruster): use 'manual' or "
            "'stabilize'"
        )
    if operator.mode == "guided":
        _check_guided(vehicle, layout, where)
    holds_heading = operator.mode in ("stabilize", "depth_hold", "guided")
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
    if not pilot.timed and "start_s" in top.pilot:  # its default: only the loader sees it given
        hint = " (pilot.shift_s moves the recording in time)" if pilot.kind == "recorded" else ""
        raise ConfigError(f"{where}: pilot.start_s: not used when kind = {pilot.kind!r}{hint}")
    if pilot.kind == "python":
        factory = load_factory(pilot.factory, where, "pilot.factory")
        keys = ("pilot.factory", "pilot.args", "(**args)")
        check_arguments(factory, pilot.factory, (), pilot.args, where, keys)
    control_laws = _build_control_laws(top.vehicle.get(_CONTROL, {}), where)
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
            control_laws=control_laws,
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
    if "mac" not in options:  # the access the codec works with: token passing for the paper's
        options["mac"] = "token" if options.get("codec", "teleop") == "teleop" else "free"
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
    if section.codec != "teleop" and section.mac == "token":
        raise ConfigError(
            f"{where}: link.mac: 'token' does not work with link.codec = '{section.codec}' (its "
            "vehicle sends on its own and answers no order: use link.mac = 'free', the default "
            "for that codec)"
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


def _build_control_laws(table: Any, where: str) -> ControlLawsSection:
    """``[vehicle.control]``, each law's factory imported and bound to its arguments (keys
    ``vehicle.control.*``)."""
    prefix = f"vehicle.{_CONTROL}."
    section = build(ControlLawsSection, table, source=where, prefix=prefix)
    for name, target in section.targets().items():
        factory = load_factory(target, where, f"{prefix}{name}")
        keys = (f"{prefix}{name}", f"{prefix}{name}_args", f"(**{name}_args)")
        check_arguments(factory, target, (), getattr(section, f"{name}_args"), where, keys)
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
