"""The sweep file: its TOML layout, the loaded :class:`Sweep` and its run list.

:func:`load_sweep` reads a packaged sweep (``testbed/scenarios/sweeps/*.toml``) or a file, checks
that every grid point gives a scenario that loads, and :func:`expand` turns it into one
:class:`RunSpec` per (point, seed): points are the Cartesian product of the axes in file order
(last axis fastest). The file's tables are read as scenario keys, and grid values written
back as TOML for the runs, by :mod:`testbed.sweep.keys`.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any, Literal, TextIO

import numpy as np

from testbed.config import ConfigError, build, check, load_toml
from testbed.sweep.keys import (
    fixed_and_swept,
    flatten_section,
    override_keys,
    repeated_value,
    toml_literal,
)

__all__ = [
    "DEFAULT_METRICS",
    "MAX_RANGE_NUM",
    "MAX_RUNS",
    "MAX_SEEDS",
    "RESERVED_COLUMNS",
    "SCHEMA_VERSION",
    "RangeSpec",
    "RunSpec",
    "Sweep",
    "check_points",
    "describe_point",
    "expand",
    "load_sweep",
    "sweep_description",
    "sweep_names",
    "toml_literal",
]

SCHEMA_VERSION = 1
RESERVED_COLUMNS = ("point", "seed", "status", "error")
"""Columns every result row starts with (grid columns follow ``seed``)."""
DEFAULT_METRICS = (
    "link.uplink.per",
    "link.downlink.per",
    "command_lag_s.mean",
    "command_age_s.mean",
    "odometry_age_s.mean",
    "energy_wh",
)
MAX_RUNS = 100_000
"""Most runs (grid points × seeds) one sweep may hold. Every grid point is loaded once before
the first run (≈ 5–9 ms each: up to ≈ 15 min here), every run's row stays in memory while the
sweep runs (a few kB each: ≈ 0.5 GB here), and 100,000 runs of 60 s take ≈ 14 h on two cores;
a larger study is several sweeps."""
MAX_SEEDS = 10_000
"""Most seeds per grid point (the count, or the list's length): far more than a confidence
interval needs; checked before the seed list is built."""
MAX_RANGE_NUM = 10_000
"""Most values of one range axis (``num``): checked before numpy allocates them."""
_SIGNIFICANT_DIGITS = 12
_SWEEP_DIR = "scenarios/sweeps"


@dataclass(frozen=True, slots=True, kw_only=True)
class RangeSpec:
    """A numeric grid axis given as a range.

    Attributes:
        scale: ``"linear"`` (evenly spaced) or ``"log"`` (evenly spaced exponents).
        start, stop: the end values, both included; > 0 for ``"log"``.
        num: number of values, in [1, :data:`MAX_RANGE_NUM`] (1 gives ``start``).
        include: extra values merged in (e.g. ``[0.0]`` in front of a log range of BER).
    """

    scale: Literal["linear", "log"]
    start: float
    stop: float
    num: int
    include: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        check(all(math.isfinite(v) for v in self.include), "include", "must be finite")
        check(math.isfinite(self.start), "start", f"must be finite, got {self.start}")
        check(math.isfinite(self.stop), "stop", f"must be finite, got {self.stop}")
        check(self.num >= 1, "num", f"must be ≥ 1, got {self.num}")
        check(self.num <= MAX_RANGE_NUM, "num", f"must be ≤ {MAX_RANGE_NUM}, got {self.num}")
        if self.scale == "log":
            check(self.start > 0.0, "start", f"must be > 0 on a log scale, got {self.start}")
            check(self.stop > 0.0, "stop", f"must be > 0 on a log scale, got {self.stop}")
        spaced = self._spaced()
        check(
            len(set(spaced)) == self.num,
            "num",
            f"{self.num} values from {self.start!r} to {self.stop!r} are only "
            f"{len(set(spaced))} distinct ones at {_SIGNIFICANT_DIGITS} significant digits",
        )
        extra = [_rounded(v) for v in self.include]
        for value in extra:
            check(
                value not in spaced and extra.count(value) == 1,
                "include",
                f"{value!r} is already in the range or repeated",
            )

    def _spaced(self) -> list[float]:
        """The ``num`` evenly spaced values (exponents on a log scale), rounded."""
        if self.scale == "log":  # with num = 1 both give [start]
            raw = np.geomspace(self.start, self.stop, self.num)
        else:
            raw = np.linspace(self.start, self.stop, self.num)
        return [_rounded(float(v)) for v in raw]

    def values(self) -> tuple[float, ...]:
        """The axis values, ascending, rounded to 12 significant digits (``1e-05``, not
        ``1.0000000000000001e-05``): ``num`` distinct ones and every ``include`` value."""
        return tuple(sorted({*self._spaced(), *(_rounded(v) for v in self.include)}))


def _rounded(value: float) -> float:
    """``value`` to :data:`_SIGNIFICANT_DIGITS` significant digits."""
    return float(f"{value:.{_SIGNIFICANT_DIGITS}g}")


@dataclass(frozen=True, slots=True)
class _SweepFile:
    schema: int
    id: str
    description: str
    scenario: str
    grid: dict[str, Any]
    seeds: int | tuple[int, ...] = 1
    set: dict[str, Any] = field(default_factory=dict)
    metrics: tuple[str, ...] = DEFAULT_METRICS

    def __post_init__(self) -> None:
        from testbed.run.scenario_config import ID_PATTERN  # slow to import: loads the vehicle

        check(self.schema == SCHEMA_VERSION, "schema", f"unsupported version {self.schema}")
        check(  # it names the default results folder, sweeps/<id>/
            ID_PATTERN.fullmatch(self.id) is not None,  # `$` alone lets a final newline in
            "id",
            f"must match {ID_PATTERN.pattern} (e.g. 'ber-vs-lag-v1'), got {self.id!r}",
        )
        if isinstance(self.seeds, int):
            check(self.seeds >= 1, "seeds", f"must be ≥ 1 (a count) or a list, got {self.seeds}")
            check(self.seeds <= MAX_SEEDS, "seeds", f"must be ≤ {MAX_SEEDS}, got {self.seeds}")
        else:
            check(len(self.seeds) > 0, "seeds", "must not be empty")
            count = len(self.seeds)
            check(count <= MAX_SEEDS, "seeds", f"must hold ≤ {MAX_SEEDS} seeds, got {count}")
            check(all(s >= 0 for s in self.seeds), "seeds", "must be ≥ 0")
            check(len(set(self.seeds)) == len(self.seeds), "seeds", "must not repeat")
        check(bool(self.grid), "grid", "must have at least one axis")
        check(len(set(self.metrics)) == len(self.metrics), "metrics", "must not repeat")


@dataclass(frozen=True, slots=True)
class Sweep:
    """A loaded sweep.

    Attributes:
        id: the sweep id (``ber-vs-lag-v1``).
        description: one line.
        scenario: the base scenario: a packaged id or an absolute ``.toml`` path.
        overrides: ``KEY=VALUE`` overrides applied to every run (the file's ``[set]``, then
            the CLI's ``--set``).
        axes: ``(dotted key, values)`` per grid axis, in file order.
        seeds: the seeds of every point.
        metrics: flattened metric names to aggregate (``command_lag_s.mean``).
        source: where it was loaded from, for messages.
        inputs: ``(file, SHA-256 hex)`` of what the runs read: the scenario file
            (``package:<id>`` for a packaged one) and every user file (model, layout, preset,
            mission) that the base or any grid point names, sorted (:func:`load_sweep`).
    """

    id: str
    description: str
    scenario: str
    overrides: tuple[str, ...]
    axes: tuple[tuple[str, tuple[Any, ...]], ...]
    seeds: tuple[int, ...]
    metrics: tuple[str, ...]
    source: str
    inputs: tuple[tuple[str, str], ...] = ()

    @property
    def points(self) -> list[dict[str, Any]]:
        """Every grid point as ``{key: value}``, last axis fastest."""
        keys = [key for key, _ in self.axes]
        return [
            dict(zip(keys, combo, strict=True))
            for combo in itertools.product(*(v for _, v in self.axes))
        ]


@dataclass(frozen=True, slots=True)
class RunSpec:
    """One independent run: base scenario, overrides (fixed ones, then the point's), seed."""

    point: int
    seed: int
    scenario: str
    overrides: tuple[str, ...]


def sweep_names() -> list[str]:
    """Ids of the packaged sweeps (``testbed/scenarios/sweeps/*.toml``), sorted."""
    folder = resources.files("testbed").joinpath(_SWEEP_DIR)
    return sorted(
        e.name.removesuffix(".toml") for e in folder.iterdir() if e.name.endswith(".toml")
    )


def sweep_description(name: str) -> str:
    """The ``description`` of the packaged sweep ``name`` (as its file has it, unchecked)."""
    entry = resources.files("testbed").joinpath(_SWEEP_DIR, f"{name}.toml")
    with resources.as_file(entry) as path:
        return str(load_toml(path).get("description", ""))


def load_sweep(
    name_or_path: str, overrides: Sequence[str] = (), *, stream: TextIO | None = None
) -> Sweep:
    """Load a packaged sweep by id, or a sweep file by path, and check every point loads.

    Args:
        name_or_path: a packaged id (:func:`sweep_names`) or a ``.toml`` path. Relative paths
            in the file (its ``scenario``, and user files named in ``[set]`` or ``[grid]``:
            a preset, model, layout, mission...) are taken from the file's folder and kept
            absolute, as a scenario file's are.
        overrides: ``KEY=VALUE`` scenario overrides (the CLI's ``--set``) for every run.
        stream: where the progress of the grid check goes (a bar on a terminal, else a line
            every second once it takes longer than that); None: no progress.

    Raises:
        ConfigError: one line naming the file and key: missing file, malformed TOML, unknown or
            missing key, bad value, a key both fixed (``[set]`` or ``--set``) and swept, a
            repeated grid value, more than :data:`MAX_RUNS` runs, or a grid point whose
            scenario does not load (named by its values).
    """
    from testbed.run.scenario import load_scenario
    from testbed.run.scenario_files import FILE_KEY_NAMES, path_beside, scenario_digest

    text = str(name_or_path)
    base_dir: Path | None = None
    if text.endswith(".toml") or "/" in text or "\\" in text or Path(text).is_file():
        source, data = text, load_toml(text)
        base_dir = Path(text).resolve().parent
    else:
        known = sweep_names()
        if text not in known:
            raise ConfigError(f"sweep {text!r}: unknown sweep id (known: {', '.join(known)})")
        source = f"package:{text}"
        entry = resources.files("testbed").joinpath(_SWEEP_DIR, f"{text}.toml")
        with resources.as_file(entry) as path:
            data = load_toml(path)
    top = build(_SweepFile, data, source=source)
    if source.startswith("package:") and top.id != text:
        raise ConfigError(f"{source}: id: must equal the file name, got {top.id!r}")
    scenario = _scenario_of(top.scenario, base_dir, source)

    def beside(key: str, value: Any) -> Any:  # a user file named in the sweep file
        if base_dir is None or key not in FILE_KEY_NAMES:
            return value
        return path_beside(value, base_dir)

    fixed_values = {k: beside(k, v) for k, v in flatten_section(top.set, "set", source).items()}
    fixed = [f"{k}={toml_literal(v)}" for k, v in fixed_values.items()]
    axes = []
    for key, spec in flatten_section(top.grid, "grid", source, keep_empty=True).items():
        where = f"grid.{key}"
        if key in RESERVED_COLUMNS:
            raise ConfigError(f"{source}: {where}: {key!r} cannot be swept (use seeds)")
        if fixed_and_swept(fixed_values, [key]) is not None:
            raise ConfigError(f"{source}: {where}: also fixed in [set]")
        values: tuple[Any, ...]
        if isinstance(spec, Mapping) and spec:
            values = build(RangeSpec, spec, source=source, prefix=f"{where}.").values()
        elif isinstance(spec, list) and spec:
            values = tuple(spec)
            if (twice := repeated_value(values)) is not None:
                raise ConfigError(
                    f"{source}: {where}: must not repeat a value, got {toml_literal(twice)} twice"
                )
        else:
            raise ConfigError(f"{source}: {where}: expected a non-empty array or a range table")
        axes.append((key, tuple(beside(key, value) for value in values)))
    if not axes:
        raise ConfigError(f"{source}: grid: must have at least one axis")
    clash = fixed_and_swept(override_keys(overrides), [key for key, _ in axes])
    if clash is not None:
        raise ConfigError(f"--set: {clash[0]}: also swept in [grid]")
    seed_count = top.seeds if isinstance(top.seeds, int) else len(top.seeds)
    points = math.prod(len(values) for _, values in axes)
    if points * seed_count > MAX_RUNS:
        raise ConfigError(
            f"{source}: grid, seeds: {points} points × {seed_count} seeds = "
            f"{points * seed_count} runs, more than the {MAX_RUNS} a sweep may hold"
        )
    seeds = tuple(range(top.seeds)) if isinstance(top.seeds, int) else top.seeds
    sweep = Sweep(
        id=top.id,
        description=top.description,
        scenario=scenario,
        overrides=(*fixed, *overrides),
        axes=tuple(axes),
        seeds=seeds,
        metrics=top.metrics,
        source=source,
    )
    # the base with the file's [set], then with --set too: each error names where it is
    files = dict([scenario_digest(sweep.scenario)])
    files.update(load_scenario(sweep.scenario, fixed, overrides_source=f"{source}: [set]").files)
    files.update(load_scenario(sweep.scenario, sweep.overrides).files)
    files.update(check_points(sweep, stream))
    return dataclasses.replace(sweep, inputs=tuple(sorted(files.items())))


def _scenario_of(scenario: str, base_dir: Path | None, source: str) -> str:
    """The sweep file's ``scenario``: a packaged id, or a path (relative ones taken from the
    sweep file's folder ``base_dir``) made absolute.

    Raises:
        ConfigError: an unknown id, or a path that names no file (naming the sweep file and
            its ``scenario`` key).
    """
    from testbed.run.scenario_files import scenario_names

    if scenario.endswith(".toml") or "/" in scenario or "\\" in scenario:
        path = Path(scenario) if base_dir is None else (base_dir / scenario).resolve()
        if not path.is_file():
            raise ConfigError(f"{source}: scenario: {path}: file not found")
        return str(path)
    known = scenario_names()
    if scenario not in known:
        raise ConfigError(
            f"{source}: scenario: unknown scenario id {scenario!r} (known: {', '.join(known)})"
        )
    return scenario


def check_points(sweep: Sweep, stream: TextIO | None = None) -> dict[str, str]:
    """Load the scenario of every grid point through the scenario loader, before any run.

    First each axis value on its own (the other axes at their first value), so that a bad value
    of a large grid fails at once, named by its key and value; then every remaining point, in
    grid order: the loader has cross-key rules (``link.ipg_s`` needs ``link.ipg = 'fixed'``,
    times must be < ``duration_s``, images need the camera and token MAC...), so a point made of
    values that are fine one by one may still not load. Each point is loaded once.

    Returns:
        ``{file: SHA-256 hex}`` of the user files the points read (their scenario's ``files``).

    Raises:
        ConfigError: ``<source>: grid point key=value, ...: <key>: <what is wrong>``.
    """
    from testbed.run.scenario import load_scenario
    from testbed.sweep.progress import Progress

    keys = [key for key, _ in sweep.axes]
    literals = [tuple(toml_literal(v) for v in values) for _, values in sweep.axes]
    total = math.prod(len(values) for values in literals)
    progress = None
    if stream is not None:
        progress = Progress(total, 0, stream, f"{sweep.id}: checking", unit="grid points")
    checked: set[tuple[int, ...]] = set()
    files: dict[str, str] = {}

    def check_one(index: tuple[int, ...]) -> None:
        point = tuple(f"{keys[a]}={literals[a][i]}" for a, i in enumerate(index))
        where = f"{sweep.source}: grid point {', '.join(point)}"
        try:
            scenario = load_scenario(
                sweep.scenario, (*sweep.overrides, *point), overrides_source=where
            )
        except ConfigError:
            if progress is not None:
                progress.close()
            raise
        checked.add(index)
        files.update(scenario.files)
        if progress is not None:
            progress.update(False)

    try:
        for axis, values in enumerate(literals):  # one value at a time
            for i in range(len(values)):
                index = tuple(i if a == axis else 0 for a in range(len(keys)))
                if index not in checked:
                    check_one(index)
        for index in itertools.product(*(range(len(v)) for v in literals)):  # every point
            if index not in checked:
                check_one(index)
    finally:
        if progress is not None:
            progress.close()
    return files


def _point_overrides(point: Mapping[str, Any]) -> tuple[str, ...]:
    return tuple(f"{key}={toml_literal(value)}" for key, value in point.items())


def describe_point(point: Mapping[str, Any]) -> str:
    """``key=value, …`` of a grid point, values as TOML (for messages)."""
    return ", ".join(_point_overrides(point))


def expand(sweep: Sweep) -> list[RunSpec]:
    """The run list: every (point, seed), ordered by point then seed."""
    return [
        RunSpec(index, seed, sweep.scenario, (*sweep.overrides, *_point_overrides(point)))
        for index, point in enumerate(sweep.points)
        for seed in sweep.seeds
    ]
