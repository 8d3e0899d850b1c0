"""Scenario sweeps: a grid of scenario overrides × seeds, run as independent runs, resumable.

A sweep file (TOML, ``testbed/scenarios/sweeps/*.toml`` or any path) names a base scenario,
fixed overrides (``[set]``), a grid over any scenario keys (``[grid]``: lists of values, or
``{scale = "log" | "linear", start, stop, num, include = [...]}`` ranges), the seeds of every
point and the metrics to aggregate. :func:`expand` turns it into a deterministic run list:
points are the Cartesian product of the axes in file order (last axis fastest), and every
(point, seed) is one :class:`RunSpec`.

:func:`run_sweep` runs the specs through a backend — a local process pool or a
``dask.distributed`` cluster (an address, or ``"local"`` for a ``LocalCluster``) — and records
each finished run in ``OUT/runs.jsonl``: one JSON line per run, appended in batches with one
``write`` and an ``fsync``. A torn last line (a kill in the middle of a write) is cut off on
``--resume``, which skips every (point, seed) already recorded. ``OUT/results.csv`` (one row per
run: point, seed, grid values, status, error, flattened metrics; sorted by point and seed) and
``OUT/aggregate.csv`` (per point and metric: n, median, p95, mean and a 95 % Student-t
confidence interval of the mean) are regenerated from the journal by write-and-rename, so they
never hold a partial row. A run that raises is recorded with ``status = "failed"`` and its
error; the sweep goes on. ``wall_s`` and ``rtf`` are left out of the rows so that the same sweep
gives the same rows on any backend, interrupted or not.

A top-level module (DESIGN.md, "Layering"): it may import every layer; only the CLI imports it.
"""

from __future__ import annotations

import csv
import io
import itertools
import json
import math
import os
import sys
import time
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any, Literal, TextIO

import numpy as np

from testbed.config import ConfigError, build, check, load_toml

__all__ = [
    "RangeSpec",
    "RunOutcome",
    "RunSpec",
    "Sweep",
    "SweepSummary",
    "aggregate_rows",
    "execute_run",
    "expand",
    "flatten_metrics",
    "format_summary",
    "load_sweep",
    "read_journal",
    "results_csv",
    "run_sweep",
    "sweep_names",
    "toml_literal",
]

SCHEMA_VERSION = 1
RESERVED_COLUMNS = ("point", "seed", "status", "error")
"""Columns every result row starts with (grid columns follow ``seed``)."""
EXCLUDED_METRICS = ("scenario", "seed", "wall_s", "rtf")
"""``metrics.json`` keys left out of result rows: already in the row, or wall-clock dependent."""
DEFAULT_METRICS = (
    "link.uplink.per",
    "link.downlink.per",
    "command_lag_s.mean",
    "command_age_s.mean",
    "odometry_age_s.mean",
    "energy_wh",
)
_SIGNIFICANT_DIGITS = 12
_SWEEP_DIR = "scenarios/sweeps"


# --- the sweep file --------------------------------------------------------------------------


@dataclass(frozen=True, slots=True, kw_only=True)
class RangeSpec:
    """A numeric grid axis given as a range.

    Attributes:
        scale: ``"linear"`` (evenly spaced) or ``"log"`` (evenly spaced exponents).
        start, stop: the end values, both included; > 0 for ``"log"``.
        num: number of values, ≥ 1 (1 gives ``start``).
        include: extra values merged in (e.g. ``[0.0]`` in front of a log range of BER).
    """

    scale: Literal["linear", "log"]
    start: float
    stop: float
    num: int
    include: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        check(math.isfinite(self.start), "start", f"must be finite, got {self.start}")
        check(math.isfinite(self.stop), "stop", f"must be finite, got {self.stop}")
        check(self.num >= 1, "num", f"must be ≥ 1, got {self.num}")
        if self.scale == "log":
            check(self.start > 0.0, "start", f"must be > 0 on a log scale, got {self.start}")
            check(self.stop > 0.0, "stop", f"must be > 0 on a log scale, got {self.stop}")

    def values(self) -> tuple[float, ...]:
        """The axis values, ascending, rounded to 12 significant digits (``1e-05``, not
        ``1.0000000000000001e-05``), duplicates removed."""
        if self.scale == "log":  # with num = 1 both give [start]
            raw = list(np.geomspace(self.start, self.stop, self.num))
        else:
            raw = list(np.linspace(self.start, self.stop, self.num))
        rounded = {float(f"{v:.{_SIGNIFICANT_DIGITS}g}") for v in (*raw, *self.include)}
        return tuple(sorted(rounded))


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
        check(self.schema == SCHEMA_VERSION, "schema", f"unsupported version {self.schema}")
        if isinstance(self.seeds, int):
            check(self.seeds >= 1, "seeds", f"must be ≥ 1 (a count) or a list, got {self.seeds}")
        else:
            check(len(self.seeds) > 0, "seeds", "must not be empty")
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
    """

    id: str
    description: str
    scenario: str
    overrides: tuple[str, ...]
    axes: tuple[tuple[str, tuple[Any, ...]], ...]
    seeds: tuple[int, ...]
    metrics: tuple[str, ...]
    source: str

    @property
    def points(self) -> list[dict[str, Any]]:
        """Every grid point as ``{key: value}``, last axis fastest."""
        keys = [key for key, _ in self.axes]
        return [
            dict(zip(keys, combo, strict=True))
            for combo in itertools.product(*(v for _, v in self.axes))
        ]

    def identity(self) -> dict[str, Any]:
        """What a results directory must match to be resumed (not the aggregated metrics)."""
        return {
            "id": self.id,
            "scenario": self.scenario,
            "overrides": list(self.overrides),
            "axes": [[key, [toml_literal(v) for v in values]] for key, values in self.axes],
            "seeds": list(self.seeds),
        }


@dataclass(frozen=True, slots=True)
class RunSpec:
    """One independent run: base scenario, overrides (fixed ones, then the point's), seed."""

    point: int
    seed: int
    scenario: str
    overrides: tuple[str, ...]


@dataclass(frozen=True, slots=True)
class RunOutcome:
    """What a worker hands back: flattened metrics, or the error of a failed run."""

    point: int
    seed: int
    metrics: dict[str, Any] | None
    error: str


def sweep_names() -> list[str]:
    """Ids of the packaged sweeps (``testbed/scenarios/sweeps/*.toml``), sorted."""
    folder = resources.files("testbed").joinpath(_SWEEP_DIR)
    return sorted(
        e.name.removesuffix(".toml") for e in folder.iterdir() if e.name.endswith(".toml")
    )


def toml_literal(value: Any) -> str:
    """``value`` as a TOML value, so it survives ``--set``-style parsing exactly."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float):
        return repr(value)  # repr round-trips floats; TOML reads inf, nan, 1e-05
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, list | tuple):
        return "[" + ", ".join(toml_literal(v) for v in value) + "]"
    if isinstance(value, Mapping):
        items = ", ".join(f"{json.dumps(str(k))} = {toml_literal(v)}" for k, v in value.items())
        return "{" + items + "}"
    raise TypeError(f"cannot write {value!r} as TOML")  # TOML data holds no other types


def _flatten_table(table: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """Nested tables → dotted keys; a table with a ``scale`` key is a range, not a level."""
    flat: dict[str, Any] = {}
    for key, value in table.items():
        dotted = f"{prefix}{key}"
        if isinstance(value, Mapping) and "scale" not in value:
            flat.update(_flatten_table(value, f"{dotted}."))
        else:
            flat[dotted] = value
    return flat


def load_sweep(name_or_path: str, overrides: Sequence[str] = ()) -> Sweep:
    """Load a packaged sweep by id, or a sweep file by path, and check every point loads.

    Args:
        name_or_path: a packaged id (:func:`sweep_names`) or a ``.toml`` path. A relative
            ``scenario`` path in the file is taken relative to the file.
        overrides: ``KEY=VALUE`` scenario overrides (the CLI's ``--set``) for every run.

    Raises:
        ConfigError: one line naming the file and key: missing file, malformed TOML, unknown or
            missing key, bad value, a key both fixed and swept, or a grid point whose scenario
            does not load (named by its values).
    """
    from testbed.run.scenario import load_scenario

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
    scenario = top.scenario
    if base_dir is not None and (scenario.endswith(".toml") or "/" in scenario):
        scenario = str((base_dir / scenario).resolve())
    fixed = [f"{k}={toml_literal(v)}" for k, v in _flatten_table(top.set).items()]
    axes = []
    for key, spec in _flatten_table(top.grid).items():
        where = f"grid.{key}"
        if key in RESERVED_COLUMNS:
            raise ConfigError(f"{source}: {where}: {key!r} cannot be swept (use seeds)")
        if key in _flatten_table(top.set):
            raise ConfigError(f"{source}: {where}: also fixed in [set]")
        values: tuple[Any, ...]
        if isinstance(spec, Mapping):
            values = build(RangeSpec, spec, source=source, prefix=f"{where}.").values()
        elif isinstance(spec, list) and spec:
            values = tuple(spec)
        else:
            raise ConfigError(f"{source}: {where}: expected a non-empty array or a range table")
        axes.append((key, values))
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
    load_scenario(sweep.scenario, sweep.overrides)  # the base alone: its errors name --set
    for point in sweep.points:
        try:
            load_scenario(sweep.scenario, (*sweep.overrides, *_point_overrides(point)))
        except ConfigError as err:
            raise ConfigError(f"{source}: grid point {_describe(point)}: {err}") from None
    return sweep


def _point_overrides(point: Mapping[str, Any]) -> tuple[str, ...]:
    return tuple(f"{key}={toml_literal(value)}" for key, value in point.items())


def _describe(point: Mapping[str, Any]) -> str:
    return ", ".join(f"{key}={toml_literal(value)}" for key, value in point.items())


def expand(sweep: Sweep) -> list[RunSpec]:
    """The run list: every (point, seed), ordered by point then seed."""
    return [
        RunSpec(index, seed, sweep.scenario, (*sweep.overrides, *_point_overrides(point)))
        for index, point in enumerate(sweep.points)
        for seed in sweep.seeds
    ]


# --- one run -----------------------------------------------------------------------------------


def flatten_metrics(metrics: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """``metrics.json`` content → ``{"link.uplink.per": 0.0, ...}``: Python scalars only (numpy
    scalars converted), NaN and ±inf → None."""
    flat: dict[str, Any] = {}
    for key, value in metrics.items():
        dotted = f"{prefix}{key}"
        if isinstance(value, np.generic):  # numpy scalars → Python (and their plain repr)
            value = value.item()
        if isinstance(value, Mapping):
            flat.update(flatten_metrics(value, f"{dotted}."))
        elif isinstance(value, float) and not math.isfinite(value):
            flat[dotted] = None
        else:
            flat[dotted] = value
    return flat


def execute_run(spec: RunSpec) -> RunOutcome:
    """Load and run one (point, seed); any exception becomes a failed outcome, never a raise."""
    try:
        from testbed.run.runner import run_scenario
        from testbed.run.scenario import load_scenario

        result = run_scenario(load_scenario(spec.scenario, spec.overrides), seed=spec.seed)
        flat = flatten_metrics(result.metrics)
        for key in EXCLUDED_METRICS:
            flat.pop(key, None)
        return RunOutcome(spec.point, spec.seed, flat, "")
    except Exception as err:  # a failed run is a result to record, not a reason to stop
        message = " ".join(f"{type(err).__name__}: {err}".split())  # one line
        return RunOutcome(spec.point, spec.seed, None, message)


# --- backends ----------------------------------------------------------------------------------


def _pool_outcomes(specs: Sequence[RunSpec], workers: int) -> Iterator[RunOutcome]:
    """Run on a local process pool (spawned interpreters); yield outcomes as they finish."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed

    context = multiprocessing.get_context("spawn")
    executor = ProcessPoolExecutor(max_workers=workers, mp_context=context)
    try:
        futures = [executor.submit(execute_run, spec) for spec in specs]
        for future in as_completed(futures):
            yield future.result()
    finally:
        executor.shutdown(wait=True, cancel_futures=True)


def _dask_outcomes(specs: Sequence[RunSpec], address: str, workers: int) -> Iterator[RunOutcome]:
    """Run on a dask.distributed cluster (``"local"`` starts a LocalCluster of ``workers``)."""
    import importlib
    import logging

    # distributed is untyped for mypy; used through Any
    distributed: Any = importlib.import_module("distributed")
    Client, LocalCluster = distributed.Client, distributed.LocalCluster  # noqa: N806  # classes
    as_completed = distributed.as_completed

    cluster = None
    if address == "local":
        cluster = LocalCluster(
            n_workers=workers,
            threads_per_worker=1,
            processes=True,
            dashboard_address=None,
            silence_logs=logging.ERROR,
        )
        client = Client(cluster)
    else:
        try:
            client = Client(address, timeout=10)
        except OSError as err:
            raise ConfigError(f"--dask: cannot reach {address}: {err}") from None
    try:
        futures = [client.submit(execute_run, spec, pure=False) for spec in specs]
        for future in as_completed(futures):
            yield future.result()
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


# --- results -------------------------------------------------------------------------------------


def read_journal(path: Path, *, repair: bool = False) -> list[dict[str, Any]]:
    """The rows in ``runs.jsonl``; with ``repair``, cut off a torn tail (no final newline).

    Raises:
        ConfigError: a complete line that is not a JSON record (the file was edited).
    """
    data = path.read_bytes() if path.exists() else b""
    complete = data[: data.rfind(b"\n") + 1]
    try:
        rows = [json.loads(line) for line in complete.splitlines()]
    except ValueError:
        raise ConfigError(f"{path}: damaged record (not written by testbed sweep)") from None
    if repair and len(complete) < len(data):
        with path.open("r+b") as handle:
            handle.truncate(len(complete))
            os.fsync(handle.fileno())
    return rows


def _append(path: Path, rows: Sequence[Mapping[str, Any]]) -> None:
    """Append rows as JSON lines in one write, then fsync."""
    data = "".join(json.dumps(row, allow_nan=False) + "\n" for row in rows).encode()
    fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
    try:
        view = memoryview(data)
        while view:
            view = view[os.write(fd, view) :]
        os.fsync(fd)
    finally:
        os.close(fd)


def _write_atomic(path: Path, text: str) -> None:
    tmp = path.with_name(path.name + ".tmp")
    with tmp.open("w", encoding="utf-8", newline="") as handle:
        handle.write(text)
        handle.flush()
        os.fsync(handle.fileno())
    os.replace(tmp, path)


def _cell(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, list | dict):
        return toml_literal(value)
    return str(value)


def _csv_text(columns: Sequence[str], rows: Sequence[Mapping[str, Any]]) -> str:
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(columns)
    for row in rows:
        writer.writerow([_cell(row.get(c)) for c in columns])
    return buffer.getvalue()


def _sorted_unique(rows: Sequence[Mapping[str, Any]]) -> list[Mapping[str, Any]]:
    by_key: dict[tuple[int, int], Mapping[str, Any]] = {}
    for row in rows:
        by_key.setdefault((row["point"], row["seed"]), row)
    return [by_key[key] for key in sorted(by_key)]


def results_csv(sweep: Sweep, rows: Sequence[Mapping[str, Any]]) -> str:
    """The results table: one row per (point, seed), sorted; metric columns in first-seen
    order."""
    rows = _sorted_unique(rows)
    head = ["point", "seed", *(key for key, _ in sweep.axes), "status", "error"]
    metric_columns: dict[str, None] = {}
    for row in rows:
        for key in row:
            if key not in head:
                metric_columns.setdefault(key)
    return _csv_text([*head, *metric_columns], rows)


def aggregate_rows(sweep: Sweep, rows: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """Per point: ``n_ok``, ``n_failed`` and, for each aggregated metric, ``n``, ``median``,
    ``p95``, ``mean``, ``ci_low``, ``ci_high`` (95 % Student-t interval of the mean; None with
    fewer than two values). Missing values (None) are left out per metric.

    Raises:
        ConfigError: a metric no successful row has (listing the known ones).
    """
    from scipy import stats

    rows = _sorted_unique(rows)
    ok = [r for r in rows if r["status"] == "ok"]
    known = sorted({k for r in ok for k in r} - {"point", "seed", "status", "error"})
    for name in sweep.metrics:
        if ok and name not in known:
            raise ConfigError(
                f"{sweep.source}: metrics: unknown metric {name!r} (known: {', '.join(known)})"
            )
    table = []
    for index, point in enumerate(sweep.points):
        mine = [r for r in rows if r["point"] == index]
        good = [r for r in mine if r["status"] == "ok"]
        out: dict[str, Any] = {"point": index, **point}
        out["n_ok"], out["n_failed"] = len(good), len(mine) - len(good)
        for name in sweep.metrics:
            values = np.array([r[name] for r in good if r.get(name) is not None], dtype=float)
            n = values.size
            stat: dict[str, Any] = dict.fromkeys(("median", "p95", "mean", "ci_low", "ci_high"))
            if n:
                mean = float(values.mean())
                stat.update(median=float(np.median(values)), mean=mean)
                stat["p95"] = float(np.percentile(values, 95))
            if n >= 2:
                half = float(stats.t.ppf(0.975, n - 1) * values.std(ddof=1) / math.sqrt(n))
                stat.update(ci_low=mean - half, ci_high=mean + half)
            out[f"{name}.n"] = n
            out.update({f"{name}.{k}": v for k, v in stat.items()})
        table.append(out)
    return table


# --- driving a sweep ---------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class SweepSummary:
    """How a sweep ended: runs in all, run now, every failed run ``(point, seed, grid values,
    error)`` recorded earlier or now, wall time of this invocation [s], the results directory."""

    total: int
    ran: int
    failed: tuple[tuple[int, int, str, str], ...]
    wall_s: float
    out: Path


class _Progress:
    """A tqdm bar on a terminal; otherwise a plain line at most every ``interval_s``."""

    def __init__(self, total: int, done: int, stream: TextIO, label: str) -> None:
        self.total, self.done, self.failed = total, done, 0
        self.stream, self.label = stream, label
        self.start = self.last = time.monotonic()
        self.first_done = done
        self.bar = None
        if stream.isatty():
            from tqdm import tqdm

            self.bar = tqdm(total=total, initial=done, unit="run", file=stream, desc=label)

    def update(self, failed: bool, *, interval_s: float = 1.0) -> None:
        self.done += 1
        self.failed += failed
        if self.bar is not None:
            self.bar.update(1)
            return
        now = time.monotonic()
        if now - self.last < interval_s and self.done < self.total:
            return
        self.last = now
        rate = (self.done - self.first_done) / max(now - self.start, 1e-9)
        eta = (self.total - self.done) / rate if rate > 0 else math.inf
        print(
            f"{self.label}: {self.done}/{self.total} runs ({self.failed} failed), "
            f"{rate:.2f} runs/s, ETA {eta:.0f} s",
            file=self.stream,
            flush=True,
        )

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def run_sweep(
    sweep: Sweep,
    out: Path,
    *,
    workers: int | None = None,
    dask: str | None = None,
    resume: bool = False,
    flush_interval_s: float = 1.0,
    stream: TextIO | None = None,
) -> SweepSummary:
    """Run every (point, seed) not yet recorded in ``out`` and write the tables.

    Args:
        sweep: the loaded sweep.
        out: results directory (``sweep.json``, ``runs.jsonl``, ``results.csv``,
            ``aggregate.csv``).
        workers: local processes (default: one per core), or LocalCluster workers.
        dask: None for the process pool; a scheduler address; or ``"local"``.
        resume: continue a sweep already in ``out``; without it ``out`` must hold no sweep.
        flush_interval_s: how long finished runs may wait before they are written [s].
        stream: progress output (default: stderr).

    Raises:
        ConfigError: ``out`` holds another sweep, or a sweep and no ``resume``; bad workers.
    """
    stream = sys.stderr if stream is None else stream
    workers = workers if workers is not None else (os.cpu_count() or 1)
    if workers < 1:
        raise ConfigError(f"--workers: must be ≥ 1, got {workers}")
    manifest = out / "sweep.json"
    journal = out / "runs.jsonl"
    identity = json.dumps(sweep.identity(), indent=1, sort_keys=True) + "\n"
    if manifest.exists():
        if not resume:
            raise ConfigError(f"--out: {out} already holds a sweep (add --resume to continue)")
        if manifest.read_text(encoding="utf-8") != identity:
            raise ConfigError(f"--resume: {out} holds a different sweep than {sweep.source}")
    elif out.exists() and not out.is_dir():
        raise ConfigError(f"--out: {out} exists and is not a directory")
    out.mkdir(parents=True, exist_ok=True)
    _write_atomic(manifest, identity)
    rows = read_journal(journal, repair=True)
    done = {(r["point"], r["seed"]) for r in rows}
    specs = [s for s in expand(sweep) if (s.point, s.seed) not in done]
    points = sweep.points
    total = len(points) * len(sweep.seeds)
    progress = _Progress(total, total - len(specs), stream, sweep.id)
    start = time.monotonic()
    pending: list[dict[str, Any]] = []
    last_flush = start

    def flush() -> None:
        nonlocal last_flush
        if pending:
            _append(journal, pending)
            rows.extend(pending)
            pending.clear()
        _write_atomic(out / "results.csv", results_csv(sweep, rows))
        last_flush = time.monotonic()

    # generators: the pool or cluster starts only when iterated, i.e. when there is work
    outcomes = (
        _pool_outcomes(specs, workers) if dask is None else _dask_outcomes(specs, dask, workers)
    )
    try:
        for outcome in outcomes if specs else ():
            status = "ok" if outcome.metrics is not None else "failed"
            pending.append(
                {"point": outcome.point, "seed": outcome.seed, **points[outcome.point]}
                | {"status": status, "error": outcome.error, **(outcome.metrics or {})}
            )
            if time.monotonic() - last_flush >= flush_interval_s:
                flush()
            progress.update(outcome.metrics is None)
        flush()
    finally:
        progress.close()
    table = aggregate_rows(sweep, rows)
    columns: dict[str, None] = {}
    for entry in table:
        columns.update(dict.fromkeys(entry))
    _write_atomic(out / "aggregate.csv", _csv_text(list(columns), table))
    failed = tuple(
        (r["point"], r["seed"], _describe(points[r["point"]]), r["error"])
        for r in _sorted_unique(rows)
        if r["status"] != "ok"
    )
    return SweepSummary(total, len(specs), failed, time.monotonic() - start, out)


def format_summary(sweep: Sweep, summary: SweepSummary) -> str:
    """A few lines a person reads after a sweep, listing every failed run."""
    lines = [
        f"{sweep.id}: {summary.total} runs, {len(summary.failed)} failed; "
        f"{summary.ran} run now in {summary.wall_s:.1f} s"
    ]
    for point, seed, values, error in summary.failed:
        lines.append(f"  FAILED point {point} seed {seed} ({values}): {error}")
    out = summary.out
    lines.append(f"  wrote {out / 'results.csv'} and {out / 'aggregate.csv'}")
    return "\n".join(lines)
