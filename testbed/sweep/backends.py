"""Running the specs: one run (:func:`execute_run`) and the backends that run many.

:func:`outcomes` runs specs on a local process pool (spawned interpreters) or on a
``dask.distributed`` cluster (an address, or ``"local"`` for a ``LocalCluster``) and yields a
:class:`RunOutcome` per run as runs finish, in any order. A run that raises becomes a failed
outcome with its error: a backend never stops for one run.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from testbed.config import ConfigError
from testbed.sweep.aggregate import flatten_metrics
from testbed.sweep.spec import RunSpec

if TYPE_CHECKING:
    from testbed.run.scenario import Scenario

__all__ = ["EXCLUDED_METRICS", "SCENARIO_KEYS", "RunOutcome", "execute_run", "outcomes"]

EXCLUDED_METRICS = ("scenario", "seed", "wall_s", "rtf")
"""``metrics.json`` keys left out of result rows: already in the row, or wall-clock dependent."""
SCENARIO_KEYS = ("images.chunk_bytes", "images.selective_repeat")
"""Scenario values added to the rows of runs with images (after the metrics), so that plots of
the rows need not know the sweep file: the chunk size and transfer mode of the closed forms."""


@dataclass(frozen=True, slots=True)
class RunOutcome:
    """What a worker hands back: flattened metrics, or the error of a failed run."""

    point: int
    seed: int
    metrics: dict[str, Any] | None
    error: str


def _scenario_values(scenario: Scenario) -> dict[str, Any]:
    """The :data:`SCENARIO_KEYS` of ``scenario`` that apply to it (none without images)."""
    if not scenario.images.enabled:
        return {}
    images = scenario.images
    return {
        "images.chunk_bytes": images.chunk_bytes,
        "images.selective_repeat": images.selective_repeat,
    }


def execute_run(spec: RunSpec) -> RunOutcome:
    """Load and run one (point, seed); any exception becomes a failed outcome, never a raise."""
    try:
        from testbed.run.runner import run_scenario
        from testbed.run.scenario import load_scenario

        result = run_scenario(load_scenario(spec.scenario, spec.overrides), seed=spec.seed)
        flat = flatten_metrics(result.metrics)
        for key in EXCLUDED_METRICS:
            flat.pop(key, None)
        for key, value in _scenario_values(result.scenario).items():
            flat.setdefault(key, value)
        return RunOutcome(spec.point, spec.seed, flat, "")
    except Exception as err:  # a failed run is a result to record, not a reason to stop
        message = " ".join(f"{type(err).__name__}: {err}".split())  # one line
        return RunOutcome(spec.point, spec.seed, None, message)


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


def outcomes(specs: Sequence[RunSpec], workers: int, dask: str | None) -> Iterator[RunOutcome]:
    """Run ``specs`` and yield their outcomes as they finish.

    A generator: the pool or cluster starts only when it is iterated, i.e. when there is work.

    Args:
        specs: the runs.
        workers: local processes, or LocalCluster workers.
        dask: None for the process pool; a scheduler address; or ``"local"``.

    Raises:
        ConfigError: a scheduler address that cannot be reached (when iterated).
    """
    if dask is None:
        return _pool_outcomes(specs, workers)
    return _dask_outcomes(specs, dask, workers)
