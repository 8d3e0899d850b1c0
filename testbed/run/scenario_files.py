"""The files of scenarios: the packaged ones by id, and the user files a scenario names by path.

Packaged scenarios live in ``testbed/scenarios/*.toml`` (package data, each with a header saying
what it reproduces and where its figures come from) and are named by versioned ids
(``s100-teleop-v1``, :func:`scenario_names`). A scenario's file may name a user's own files by
path (:data:`FILE_KEY_NAMES`: a link preset, a vehicle model, a thruster layout, a mission, an
arm model, a TPIK configuration, or a Python file's factory: a pilot's, a link model's or a
control law's): relative paths in a file are
taken from that file's folder (:func:`paths_beside`), and each such file's SHA-256 is recorded
with the run (:func:`user_files`, :func:`file_digests`, :func:`scenario_digest`).

Loading and checking a scenario is :mod:`testbed.run.scenario`; nothing here parses one.
"""

from __future__ import annotations

import hashlib
from collections.abc import Iterator, Mapping, Sequence
from importlib import resources
from pathlib import Path
from typing import Any

from testbed.config import ConfigError, read_text
from testbed.run.plugins import target_file, target_files
from testbed.run.scenario_config import Scenario

__all__ = [
    "FILE_KEY_NAMES",
    "file_digests",
    "named_file_texts",
    "path_beside",
    "paths_beside",
    "scenario_digest",
    "scenario_dir",
    "scenario_names",
    "user_files",
]

_PACKAGE = "testbed"
_SCENARIO_DIR = "scenarios"


def scenario_dir() -> Any:
    """The packaged scenarios' folder (``testbed/scenarios``), as package resources."""
    return resources.files(_PACKAGE).joinpath(_SCENARIO_DIR)


def scenario_names() -> list[str]:
    """Ids of the packaged scenarios (``testbed/scenarios/*.toml``), sorted."""
    return sorted(
        entry.name.removesuffix(".toml")
        for entry in scenario_dir().iterdir()
        if entry.name.endswith(".toml")
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
    ("vehicle", "control", "depth"),
    ("vehicle", "control", "attitude"),
    ("pilot", "file"),
)
"""Keys that may name a user's file by path (``link.model``, ``pilot.factory`` and the
``vehicle.control`` laws a Python file, ``FILE.py:NAME``; ``pilot.file`` a recorded pilot's
``.csv``)."""

_DATA_SUFFIXES = (".toml", ".json", ".csv")
"""The endings of the data files a scenario names by path."""


FILE_KEY_NAMES = frozenset(".".join(key) for key in _FILE_KEYS)
"""The dotted names of :data:`_FILE_KEYS` (``vehicle.thrusters``...)."""


def path_beside(value: Any, folder: Path) -> Any:
    """``value`` of a file key (:data:`FILE_KEY_NAMES`) as written in a file kept in
    ``folder``: a relative path of a user file (ending in ``.toml``/``.json``/``.csv``, or a
    ``FILE.py:NAME`` target) taken from ``folder``; anything else (a packaged name, a module,
    an absolute path) as it is."""
    if isinstance(value, str):
        python = target_file(value)
        if python is not None and not Path(python).is_absolute():
            return f"{folder / python}:{value.rpartition(':')[2]}"
        path = Path(value)
        if not path.is_absolute() and path.suffix in _DATA_SUFFIXES:
            return str(folder / path)
    return value


def named_file_texts(data: Mapping[str, Any]) -> Iterator[str]:
    """The text of each user file a scenario's ``data`` names by path (:data:`_FILE_KEYS`;
    "" for one that cannot be read, which the build then names); for a ``.csv`` (a recorded
    pilot's sticks, which may be tens of MB) its SHA-256 instead, if it is a regular file (a
    device that never ends is not read: the build names it)."""
    for key in _FILE_KEYS:
        value: Any = data
        for part in key:
            value = value.get(part) if isinstance(value, Mapping) else None
        if not isinstance(value, str):
            continue
        path = target_file(value) or (value if Path(value).suffix in _DATA_SUFFIXES else None)
        if path is not None and Path(path).suffix == ".csv":  # tens of MB: its digest
            yield file_digests([path])[0][1]
        elif path is not None:
            try:
                yield read_text(path)  # bounded: a device that never ends is named, not read
            except ConfigError:
                yield ""


def paths_beside(data: dict[str, Any], folder: Path) -> dict[str, Any]:
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


def user_files(scenario: Scenario) -> list[str]:
    """The data files given by path (a link preset, a model, a thruster layout, a mission, an
    arm model, a TPIK configuration, a recorded pilot's sticks), not packaged, and the Python
    files behind a pilot, link model or control law of the user's
    (:func:`~testbed.run.plugins.target_files`)."""
    vehicle = scenario.vehicle
    named = [scenario.link.preset, vehicle.model, vehicle.thrusters]
    if vehicle.autonomy is not None and vehicle.autonomy.mission is not None:
        named.append(vehicle.autonomy.mission)
    if vehicle.arm is not None:
        named += [vehicle.arm.model, vehicle.arm.tpik]
    files = [name for name in named if Path(name).suffix in (".toml", ".json")]
    if scenario.pilot.kind == "recorded":
        files.append(scenario.pilot.file)
    laws = scenario.control_laws.targets().values()
    for target in (scenario.pilot.factory, scenario.link.model, *laws):
        if target:
            files += target_files(target)
    return files


def scenario_digest(name_or_path: str) -> tuple[str, str]:
    """``(source, SHA-256 hex)`` of a scenario file's content: ``package:<id>`` for a packaged
    scenario (whose file a code update may change), else the path (as
    :func:`~testbed.run.scenario.load_scenario` records it in ``files``)."""
    text = str(name_or_path)
    if text.endswith(".toml") or "/" in text or "\\" in text or Path(text).is_file():
        return file_digests([text])[0]
    with resources.as_file(scenario_dir().joinpath(f"{text}.toml")) as path:
        return f"package:{text}", file_digests([str(path)])[0][1]


def file_digests(paths: Sequence[str]) -> tuple[tuple[str, str], ...]:
    """``(path, SHA-256 hex)`` of each file, in order, once each; "" for one that cannot be
    read or is not a regular file (a device such as ``/dev/zero`` never ends), which the build,
    reading files bounded, then names."""
    digests: dict[str, str] = {}
    for path in paths:
        digests[path] = ""
        if Path(path).is_file():
            try:
                with Path(path).open("rb") as handle:
                    digests[path] = hashlib.file_digest(handle, "sha256").hexdigest()
            except OSError:
                pass
    return tuple(digests.items())
