"""Scenarios: versioned TOML files loaded into frozen dataclasses, with ``--set`` overrides.

A scenario is everything one run needs apart from the seed: the link (a channel preset plus
overrides, the codec, the medium access and the operator's modem position), the vehicle (a
:class:`~testbed.vehicle.vehicle.VehicleConfig`), the operator's start-up requests, the pilot,
the faults and the metric settings. The packaged scenarios live in ``testbed/scenarios/*.toml``
(package data, each with a header saying what it reproduces and where its figures come from)
and are named by versioned ids (``s100-teleop-v1``): a changed meaning gets a new version.

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

This is a top-level module (DESIGN.md, "Layering"): it may import every layer; nothing below
``scenario`` imports it.
"""

from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any, Literal

from testbed.channel import (
    TELEROBOTICS_2018,
    TELEROBOTICS_2019,
    TELEROBOTICS_2021,
    Fixed,
    IpgPolicy,
    LinkConfig,
    load_link_config,
    preset_names,
)
from testbed.config import (
    ConfigError,
    FieldError,
    apply_overrides,
    build,
    check,
    load_toml,
    parse_override,
)
from testbed.operator.pilots import AttitudePilot, Pilot, ScriptedPilot, SineTerm
from testbed.run.images import ImagesSection
from testbed.vehicle.hydrodynamics import known_models
from testbed.vehicle.thruster_config import known_thruster_configs, load_thruster_config
from testbed.vehicle.vehicle import VehicleConfig

__all__ = [
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
    "scenario_names",
]

SCHEMA_VERSION = 1
"""The only scenario schema version this loader reads."""

_ID_PATTERN = re.compile(r"^[a-z0-9-]+-v[0-9]+$")
_PACKAGE = "testbed"
_SCENARIO_DIR = "scenarios"
_IPG_CONSTANTS: dict[str, IpgPolicy] = {
    "telerobotics-2018": TELEROBOTICS_2018,
    "telerobotics-2019": TELEROBOTICS_2019,
    "telerobotics-2021": TELEROBOTICS_2021,
}


def _finite(value: float, key: str) -> None:
    check(math.isfinite(value), key, f"must be finite, got {value}")


def _positive(value: float, key: str) -> None:
    check(value > 0.0 and math.isfinite(value), key, f"must be > 0 and finite, got {value}")


def _non_negative(value: float, key: str) -> None:
    check(value >= 0.0 and math.isfinite(value), key, f"must be ≥ 0 and finite, got {value}")


# --- sections ----------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True, kw_only=True)
class LinkSection:
    """The link between operator and vehicle.

    Attributes:
        preset: channel preset name (:func:`testbed.channel.preset_names`).
        channel: the preset with every other key of the ``[link]`` table applied over it.
        codec: ``"teleop"`` (the paper's compact orders and replies) or ``"changeset"`` (the ECS
            paper's full change-set sync).
        mac: ``"token"`` (the operator is master, the vehicle answers each frame) or ``"free"``
            (each node sends at its own rate).
        ipg: the token master's inter-packet-gap policy.
        ipg_s: the gap [s] when ``ipg == "fixed"``, > 0.
        uplink_rate_hz: operator send rate [Hz] when ``mac == "free"`` or
            ``codec == "changeset"``.
        downlink_rate_hz: vehicle send rate [Hz], same condition.
        snapshot_period_s: change-set codec: every this many seconds a node sends its full
            owned state instead of the changes alone, so a peer that lost a payload resyncs
            [s]; 0 = never.
        operator_position_ned_m: (3,) the operator's modem [m], world NED; the vehicle's modem
            moves with the vehicle.
    """

    preset: str = "s100"
    channel: LinkConfig
    codec: Literal["teleop", "changeset"] = "teleop"
    mac: Literal["token", "free"] = "token"
    ipg: Literal["fixed", "telerobotics-2018", "telerobotics-2019", "telerobotics-2021"] = (
        "telerobotics-2021"
    )
    ipg_s: float = 0.6
    uplink_rate_hz: float = 50.0
    downlink_rate_hz: float = 100.0
    snapshot_period_s: float = 5.0
    operator_position_ned_m: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        _positive(self.ipg_s, "ipg_s")
        check(
            self.snapshot_period_s >= 0.0 and math.isfinite(self.snapshot_period_s),
            "snapshot_period_s",
            f"must be a finite number ≥ 0, got {self.snapshot_period_s}",
        )
        _positive(self.uplink_rate_hz, "uplink_rate_hz")
        _positive(self.downlink_rate_hz, "downlink_rate_hz")
        for i, value in enumerate(self.operator_position_ned_m):
            _finite(value, f"operator_position_ned_m[{i}]")

    @property
    def ipg_policy(self) -> IpgPolicy:
        """The token master's gap policy: ``Fixed(ipg_s)`` or a ``TELEROBOTICS_*`` constant."""
        if self.ipg == "fixed":
            return Fixed(self.ipg_s)
        return _IPG_CONSTANTS[self.ipg]

    @property
    def rates_used(self) -> bool:
        """Whether the nodes send at ``uplink_rate_hz`` / ``downlink_rate_hz``."""
        return self.mac == "free" or self.codec == "changeset"


@dataclass(frozen=True, slots=True)
class OperatorSection:
    """What the operator requests at start.

    Attributes:
        mode: control mode requested at start.
        arm_at_s: when the operator requests arming [s], ≥ 0.
        depth_m: depth setpoint [m, positive down] sent at start (``depth_hold`` only);
            None = hold the depth at arming.
        precision: precision (fine) stick mode.
    """

    mode: Literal["manual", "stabilize", "depth_hold"] = "depth_hold"
    arm_at_s: float = 0.0
    depth_m: float | None = None
    precision: bool = False

    def __post_init__(self) -> None:
        _non_negative(self.arm_at_s, "arm_at_s")
        if self.depth_m is not None:
            _non_negative(self.depth_m, "depth_m")
            check(
                self.mode == "depth_hold",
                "depth_m",
                f"only used when mode = 'depth_hold', got mode {self.mode!r}",
            )


_STICK_AXES = ("x", "y", "z", "yaw")
_ATTITUDE_AMPLITUDES = ("roll_amplitude_deg", "pitch_amplitude_deg", "yaw_amplitude_deg")


@dataclass(frozen=True, slots=True)
class PilotSection:
    """The scripted operator's settings: smooth stick signals or oscillating attitude setpoints
    (the pilots themselves are :class:`~testbed.operator.pilots.ScriptedPilot` and
    :class:`~testbed.operator.pilots.AttitudePilot`; :meth:`pilot` builds the one configured).

    ``kind = "scripted"``: each stick is ``clip(Σ terms, −1, 1)`` of the time ``τ = t − start_s``
    since the pilot started, zero before (Centelles et al., Fig. 5: a few slow sinusoids per
    axis). ``kind = "attitude"``: the ECS paper's experiment, no sticks; roll, pitch and yaw
    setpoints ``A · sin(2π τ / T)`` [deg], sent as AttitudeSetpoint ``setpoint_rate_hz`` times
    a second. Each kind rejects the other's non-zero settings.

    Attributes:
        kind: ``"scripted"`` or ``"attitude"``.
        start_s: when the pilot starts [s], ≥ 0.
        x, y, z, yaw: surge, sway, heave (+ down) and yaw stick terms.
        roll_amplitude_deg, pitch_amplitude_deg: setpoint amplitudes [deg], |A| ≤ 89.9.
        yaw_amplitude_deg: yaw setpoint amplitude [deg], |A| ≤ 180.
        roll_period_s, pitch_period_s, yaw_period_s: setpoint periods [s], > 0.
        setpoint_rate_hz: how often the operator updates the setpoint [Hz], > 0.
    """

    kind: Literal["scripted", "attitude"] = "scripted"
    start_s: float = 5.0
    x: tuple[SineTerm, ...] = ()
    y: tuple[SineTerm, ...] = ()
    z: tuple[SineTerm, ...] = ()
    yaw: tuple[SineTerm, ...] = ()
    roll_amplitude_deg: float = 0.0
    roll_period_s: float = 20.0
    pitch_amplitude_deg: float = 0.0
    pitch_period_s: float = 30.0
    yaw_amplitude_deg: float = 0.0
    yaw_period_s: float = 25.0
    setpoint_rate_hz: float = 10.0

    def __post_init__(self) -> None:
        _non_negative(self.start_s, "start_s")
        for name, limit in zip(_ATTITUDE_AMPLITUDES, (89.9, 89.9, 180.0), strict=True):
            value = getattr(self, name)
            check(abs(value) <= limit, name, f"must be in [-{limit:g}, {limit:g}], got {value}")
        for name in ("roll_period_s", "pitch_period_s", "yaw_period_s", "setpoint_rate_hz"):
            _positive(getattr(self, name), name)
        used_by, unused = (
            ("attitude", _ATTITUDE_AMPLITUDES)
            if self.kind == "scripted"
            else ("scripted", _STICK_AXES)
        )
        for name in unused:
            check(not getattr(self, name), name, f"only used when kind = {used_by!r}")

    def pilot(self) -> Pilot:
        """The pilot this section configures (:mod:`testbed.operator.pilots`)."""
        if self.kind == "attitude":
            return AttitudePilot(
                self.start_s,
                self.roll_amplitude_deg,
                self.roll_period_s,
                self.pitch_amplitude_deg,
                self.pitch_period_s,
                self.yaw_amplitude_deg,
                self.yaw_period_s,
            )
        return ScriptedPilot(self.start_s, self.x, self.y, self.z, self.yaw)


@dataclass(frozen=True, slots=True)
class ThrusterFault:
    """A thruster failure from time ``t_s`` on (``Vehicle.fail_thruster``).

    Attributes:
        t_s: when it fails [s], in [0, duration_s).
        thruster: a thruster name of the scenario's layout.
        mode: ``"dead"`` (no force), ``"stuck"`` (holds ``value`` [N]) or ``"degraded"``
            (force scaled by ``value`` in [0, 1]).
        value: the stuck force [N] or degraded factor; must stay 0 for ``"dead"``.
    """

    t_s: float
    thruster: str
    mode: Literal["dead", "stuck", "degraded"]
    value: float = 0.0

    def __post_init__(self) -> None:
        _non_negative(self.t_s, "t_s")
        check(bool(self.thruster), "thruster", "must not be empty")
        _finite(self.value, "value")
        if self.mode == "dead":
            check(self.value == 0.0, "value", "not used when mode = 'dead' (leave it out)")
        if self.mode == "degraded":
            check(0.0 <= self.value <= 1.0, "value", f"must be in [0, 1], got {self.value}")


@dataclass(frozen=True, slots=True)
class LinkOutage:
    """A window [start_s, end_s) in which nothing is delivered in either direction.

    Attributes:
        start_s: window start [s], ≥ 0.
        end_s: window end [s], > start_s and ≤ the scenario's duration.
    """

    start_s: float
    end_s: float

    def __post_init__(self) -> None:
        _non_negative(self.start_s, "start_s")
        check(
            self.end_s > self.start_s and math.isfinite(self.end_s),
            "end_s",
            f"must be > start_s ({self.start_s}), got {self.end_s}",
        )

    @property
    def duration_s(self) -> float:
        """Length of the window [s]."""
        return self.end_s - self.start_s


@dataclass(frozen=True, slots=True)
class FaultsSection:
    """Scheduled faults: thruster failures and link outages (sorted, not overlapping)."""

    thrusters: tuple[ThrusterFault, ...] = ()
    link_outages: tuple[LinkOutage, ...] = ()

    def __post_init__(self) -> None:
        for i in range(1, len(self.link_outages)):
            previous, outage = self.link_outages[i - 1], self.link_outages[i]
            check(
                outage.start_s >= previous.end_s,
                f"link_outages[{i}].start_s",
                f"must be ≥ the previous window's end_s ({previous.end_s}), got {outage.start_s}",
            )


@dataclass(frozen=True, slots=True)
class MetricsSection:
    """What the recorder samples and the metrics leave out.

    Attributes:
        settle_s: samples before this time [s] are left out of error statistics.
        sample_rate_hz: time-series recording rate [Hz] for plots and tracking metrics.
    """

    settle_s: float = 10.0
    sample_rate_hz: float = 20.0

    def __post_init__(self) -> None:
        _non_negative(self.settle_s, "settle_s")
        _positive(self.sample_rate_hz, "sample_rate_hz")


@dataclass(frozen=True, slots=True, kw_only=True)
class Scenario:
    """One run's configuration (the seed aside, which the CLI's ``--seed`` may override).

    Attributes:
        id: versioned id, ``^[a-z0-9-]+-v[0-9]+$`` (``s100-teleop-v1``).
        description: one line for listings and reports.
        schema: scenario schema version; only :data:`SCHEMA_VERSION` is accepted.
        duration_s: simulated time [s], > 0.
        seed: default seed, ≥ 0.
        link, vehicle, operator, pilot, faults, metrics, images: the sections.
        source: where it was loaded from (a path or ``package:<id>``), for messages; not a
            TOML key.
    """

    id: str
    description: str
    schema: int
    duration_s: float
    seed: int = 0
    link: LinkSection
    vehicle: VehicleConfig
    operator: OperatorSection = field(default_factory=OperatorSection)
    pilot: PilotSection = field(default_factory=PilotSection)
    faults: FaultsSection = field(default_factory=FaultsSection)
    metrics: MetricsSection = field(default_factory=MetricsSection)
    images: ImagesSection = field(default_factory=ImagesSection)
    source: str

    def __post_init__(self) -> None:
        check(
            _ID_PATTERN.match(self.id) is not None,
            "id",
            f"must match {_ID_PATTERN.pattern} (e.g. 's100-teleop-v1'), got {self.id!r}",
        )
        check(
            self.schema == SCHEMA_VERSION,
            "schema",
            f"unsupported schema version {self.schema} (supported: {SCHEMA_VERSION})",
        )
        _positive(self.duration_s, "duration_s")
        check(self.seed >= 0, "seed", f"must be ≥ 0, got {self.seed}")
        end = self.duration_s
        for i, fault in enumerate(self.faults.thrusters):
            check(fault.t_s < end, f"faults.thrusters[{i}].t_s", f"must be < duration_s ({end})")
        for i, outage in enumerate(self.faults.link_outages):
            check(
                outage.end_s <= end,
                f"faults.link_outages[{i}].end_s",
                f"must be ≤ duration_s ({end}), got {outage.end_s}",
            )
        for key, value in (
            ("operator.arm_at_s", self.operator.arm_at_s),
            ("pilot.start_s", self.pilot.start_s),
            ("metrics.settle_s", self.metrics.settle_s),
        ):
            check(value < end, key, f"must be < duration_s ({end}), got {value}")
        self._check_images()
        check(
            self.pilot.kind != "attitude" or self.operator.mode != "manual",
            "operator.mode",
            "the attitude pilot needs 'stabilize' or 'depth_hold', got 'manual'",
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


def load_scenario(name_or_path: str, overrides: Sequence[str] = ()) -> Scenario:
    """Load a packaged scenario by id, or a scenario file by path, and apply overrides.

    Args:
        name_or_path: a packaged id (``"s100-teleop-v1"``, see :func:`scenario_names`) or the
            path of a ``.toml`` file (anything ending in ``.toml``, containing a path separator
            or naming an existing file).
        overrides: ``"a.b=value"`` strings (``--set``), e.g. ``"link.ber=1e-4"``,
            ``"vehicle.model=bluerov2-heavy"``, ``"pilot.x=[{amplitude=0.2, period_s=30}]"``.

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
        data = load_toml(text)
    else:
        known = scenario_names()
        if text not in known:
            raise ConfigError(f"scenario {text!r}: unknown scenario id (known: {', '.join(known)})")
        packaged_id = text
        source = f"package:{text}"
        with resources.as_file(_scenario_dir().joinpath(f"{text}.toml")) as path:
            data = load_toml(path)
    link_keys = data.get("link")
    scenario = _from_data(
        data, source, source, set(link_keys) if isinstance(link_keys, Mapping) else set()
    )
    if packaged_id is not None and scenario.id != packaged_id:
        raise ConfigError(f"{source}: id: must equal the file name, got {scenario.id!r}")
    if not overrides:
        return scenario
    given = set()
    for text_override in overrides:
        path_parts, _ = parse_override(text_override)
        if path_parts[0] == "link" and len(path_parts) > 1:
            given.add(path_parts[1])
    return _from_data(apply_overrides(data, overrides), "--set", source, given)


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
    _check_name(vehicle.model, known_models(), where, "vehicle.model", "vehicle model")
    layouts = known_thruster_configs()
    _check_name(vehicle.thrusters, layouts, where, "vehicle.thrusters", "thruster layout")
    operator = build(OperatorSection, top.operator, source=where, prefix="operator.")
    pilot = build(PilotSection, top.pilot, source=where, prefix="pilot.")
    faults = build(FaultsSection, top.faults, source=where, prefix="faults.")
    metrics = build(MetricsSection, top.metrics, source=where, prefix="metrics.")
    images = build(ImagesSection, top.images, source=where, prefix="images.")
    if faults.thrusters:
        names = [t.name for t in load_thruster_config(vehicle.thrusters).thrusters]
        for i, fault in enumerate(faults.thrusters):
            key = f"faults.thrusters[{i}].thruster"
            _check_name(fault.thruster, names, where, key, "thruster", f" of {vehicle.thrusters}")
    try:
        return Scenario(
            id=top.id,
            description=top.description,
            schema=top.schema,
            duration_s=top.duration_s,
            seed=top.seed,
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
    _check_name(preset, preset_names(), where, "link.preset", "link preset")
    base = dataclasses.asdict(load_link_config(preset))
    channel_data = _merge(base, {k: v for k, v in table.items() if k in _CHANNEL_KEYS})
    build(LinkConfig, channel_data, source=where, prefix="link.")  # errors name link.<key>
    section = build(LinkSection, {**options, "channel": channel_data}, source=where, prefix="link.")
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
