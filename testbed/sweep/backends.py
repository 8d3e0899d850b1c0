"""Running the specs: one run (:func:`execute_run`) and the backends that run many.

:func:`outcomes` runs specs on a local process pool (spawned interpreters) or on a
``dask.distributed`` cluster (an address, or ``"local"`` for a ``LocalCluster``) and yields a
:class:`RunOutcome` per run as runs finish, in any order. A run that raises becomes a failed
outcome with its error: a backend never stops for one run.

Workers die with the sweep (no orphans under PID 1, tests/sweep/test_signals.py):

- every local worker process (pool workers, and the LocalCluster's worker processes through
  the :mod:`testbed.sweep.worker_setup` preload) asks the kernel for SIGKILL when its parent
  dies (``prctl(PR_SET_PDEATHSIG)``, Linux), then checks that the parent did not die before;
- they are started with SIGINT blocked (the mask is inherited across spawn), so a Ctrl-C to
  the terminal's process group reaches the sweep only, which stops them itself;
- closing the outcome generator before the end (an interrupt) kills the pool's workers or
  closes the cluster instead of waiting for the runs in progress.

The multiprocessing resource tracker needs nothing: it exits when the last process holding
its pipe (the sweep and its workers) is gone.
"""

from __future__ import annotations

import contextlib
import os
import re
import signal
import sys
import threading
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from testbed.config import ConfigError
from testbed.run.failures import describe
from testbed.run.interrupts import deferred_interrupts
from testbed.sweep.aggregate import flatten_metrics
from testbed.sweep.spec import RunSpec

if TYPE_CHECKING:
    from testbed.run.scenario_config import Scenario

__all__ = [
    "EXCLUDED_METRICS",
    "SCENARIO_KEYS",
    "RunOutcome",
    "WorkerLostError",
    "check_dask_address",
    "die_with_parent",
    "execute_run",
    "outcomes",
    "scheduler_client",
    "sigint_blocked",
]

EXCLUDED_METRICS = ("scenario", "inputs", "seed", "wall_s", "rtf", "signal_lag_reference")
"""``metrics.json`` keys left out of result rows: already in the row or the sweep's files,
wall-clock dependent, or a label the same for every run of a sweep (a sweep runs the
scenario's own pilot: ``signal_lag_reference`` is ``"pilot"``)."""
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


class WorkerLostError(Exception):
    """A worker process of the local pool died (killed by a signal: the OOM killer, a kill
    -9): the pool cannot go on. The runs that finished are kept; ``--resume`` runs the rest."""


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
    """Load and run one (point, seed); any exception becomes a failed outcome, never a raise.

    An interrupt is not a failure of the run: a run that Ctrl-C (or the CLI's SIGTERM) stopped
    part way (:attr:`~testbed.run.runner.RunResult.stopped`) raises that interrupt, so the
    caller stops too instead of taking its partial metrics for a run's.
    """
    try:
        from testbed.run.runner import run_scenario
        from testbed.run.scenario import load_scenario

        result = run_scenario(load_scenario(spec.scenario, spec.overrides), seed=spec.seed)
        if result.stopped is not None:
            raise result.stopped
        kept = {k: v for k, v in result.metrics.items() if k not in EXCLUDED_METRICS}
        flat = flatten_metrics(kept)
        for key, value in _scenario_values(result.scenario).items():
            flat.setdefault(key, value)
        return RunOutcome(spec.point, spec.seed, flat, "")
    except Exception as err:  # a failed run is a result to record, not a reason to stop
        return RunOutcome(spec.point, spec.seed, None, describe(err))


_PR_SET_PDEATHSIG = 1  # linux/prctl.h
PARENT_PID_ENV = "TESTBED_SWEEP_PARENT_PID"
"""Environment variable holding the sweep's PID for the LocalCluster workers' preload."""


def die_with_parent(parent_pid: int) -> None:
    """In a worker: get SIGKILL when the parent dies (Linux), and exit if it already has.

    ``PR_SET_PDEATHSIG`` fires when the thread that started this process ends: the pool's
    workers are started by the sweep's main thread, the LocalCluster's by its event-loop
    thread, both living as long as the sweep needs them. Elsewhere a no-op (dask's own
    parent-pipe watch still applies there).
    """
    if sys.platform.startswith("linux"):
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0)
    if os.getppid() != parent_pid:  # the parent died before the prctl: nobody will signal us
        os._exit(1)


def _pool_worker_init(parent_pid: int) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the sweep's to handle
    die_with_parent(parent_pid)


@contextlib.contextmanager
def sigint_blocked() -> Iterator[None]:
    """Block SIGINT in this thread while processes and threads are started inside: they
    inherit the mask, so a Ctrl-C to the process group does not reach the workers (a SIGINT
    to this process stays pending and is raised on leaving). Only on the main thread."""
    if threading.current_thread() is not threading.main_thread() or not hasattr(
        signal, "pthread_sigmask"
    ):
        yield
        return
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def _pool_outcomes(specs: Sequence[RunSpec], workers: int) -> Iterator[RunOutcome]:
    """Run on a local process pool (spawned interpreters); yield outcomes as they finish.

    Closed before the end (an interrupt), it kills the workers rather than waiting for the
    runs in progress. A worker that dies (SIGKILL, the OOM killer) breaks the pool: the runs
    that finished are still yielded, then :class:`WorkerLostError` is raised."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed
    from concurrent.futures.process import BrokenProcessPool

    context = multiprocessing.get_context("spawn")
    finished = False
    with sigint_blocked():  # the executor's workers and manager thread inherit the mask
        executor = ProcessPoolExecutor(
            max_workers=workers,
            mp_context=context,
            initializer=_pool_worker_init,
            initargs=(os.getpid(),),
        )
    try:
        with sigint_blocked():
            futures = [executor.submit(execute_run, spec) for spec in specs]
        broken = False
        for future in as_completed(futures):
            try:
                outcome = future.result()
            except BrokenProcessPool:  # a worker died: every run not finished fails with it
                broken = True
                continue
            yield outcome  # runs that finished before the death are kept
        if broken:
            raise WorkerLostError(
                "a worker process of the sweep died (killed by a signal: out of memory?)"
            )
        finished = True
    finally:
        if not finished:
            # ProcessPoolExecutor has no public terminate (3.14 adds terminate_workers)
            processes = dict(getattr(executor, "_processes", None) or {})
            for process in processes.values():
                with contextlib.suppress(OSError, ValueError):
                    process.kill()
            for process in processes.values():
                with contextlib.suppress(OSError, ValueError, AssertionError):
                    process.join()
        executor.shutdown(wait=True, cancel_futures=True)


LOCAL_HTTP_ADDRESS = "127.0.0.1:0"
"""Where a ``--dask local`` cluster's scheduler serves its HTTP endpoints (health, metrics; the
dashboard is off): this host only, a port the system picks. distributed's default, 8787, when
taken (a second sweep at once, tests in parallel) made it warn in the user's terminal."""


_DASK_ADDRESS = re.compile(
    r"^(?:(?:tcp|tls|ws|wss|ucx)://)?(?:\[[0-9A-Fa-f:.]+\]|[\w.-]+):(?P<port>\d{1,5})$"
)
_MAX_PORT = 65535


def check_dask_address(address: str) -> None:
    """``--dask``: ``local`` or ``[scheme://]host:port`` with a port in [1, 65535]; else
    :class:`ConfigError`."""
    if address == "local":
        return
    match = _DASK_ADDRESS.match(address)
    if match is None:
        raise ConfigError(
            f"--dask: expected 'local' or a scheduler address like tcp://host:8786, got {address!r}"
        )
    port = int(match["port"])
    if not 1 <= port <= _MAX_PORT:
        raise ConfigError(f"--dask: port must be in [1, {_MAX_PORT}], got {port} in {address!r}")


def _distributed() -> Any:
    """The ``distributed`` module (untyped for mypy; used through Any), imported when asked."""
    import importlib

    return importlib.import_module("distributed")


def _connect(address: str) -> Any:
    """A client of the scheduler at ``address``, connected (within 10 s).

    Raises:
        ConfigError: a bad address, or a scheduler that cannot be reached (one line).
    """
    check_dask_address(address)
    try:
        return _distributed().Client(address, timeout=10)
    except Exception as err:  # OSError, TimeoutError, ValueError: one line, not a trace
        message = " ".join(str(err).split()) or type(err).__name__
        raise ConfigError(f"--dask: cannot reach {address}: {message}") from None


@contextlib.contextmanager
def scheduler_client(dask: str | None) -> Iterator[Any]:
    """The client of a remote scheduler (``--dask ADDRESS``), connected on entering and closed
    on leaving; None for the process pool and ``"local"`` (their workers start with the runs).

    A sweep enters it before it writes anything, so an unreachable scheduler leaves the
    results directory as it was.

    Raises:
        ConfigError: the scheduler cannot be reached (on entering).
    """
    if dask is None or dask == "local":
        yield None
        return
    client = _connect(dask)
    try:
        yield client
    finally:
        with contextlib.suppress(Exception):
            client.close(timeout=10)


def _dask_outcomes(
    specs: Sequence[RunSpec], address: str, workers: int, client: Any = None
) -> Iterator[RunOutcome]:
    """Run on a dask.distributed cluster (``"local"`` starts a LocalCluster of ``workers``).

    A run whose result the client cannot get (its worker was lost more often than the
    scheduler's ``allowed-failures``: ``KilledWorker``; a remote worker that cannot unpickle
    it) is a failed outcome with that error, run again by ``--resume``; the sweep goes on
    (the cluster replaces lost workers).

    A remote scheduler's ``client`` (:func:`scheduler_client`) stays its caller's to close;
    without one it is connected here and closed at the end."""
    import logging

    distributed = _distributed()
    Client, LocalCluster = distributed.Client, distributed.LocalCluster  # noqa: N806  # classes
    as_completed = distributed.as_completed

    check_dask_address(address)
    cluster = None
    finished = False
    own_client = client is None
    try:  # from the start: a Ctrl-C held while the cluster starts is raised as that ends
        if address == "local":
            os.environ[PARENT_PID_ENV] = str(os.getpid())  # read by the preload in each worker
            # the event-loop thread that starts the worker processes inherits the blocked
            # SIGINT, and so do they; the preload makes them die with this process
            with sigint_blocked():
                cluster = LocalCluster(
                    n_workers=workers,
                    threads_per_worker=1,
                    processes=True,
                    dashboard_address=None,  # no dashboard
                    # and its HTTP endpoints, served anyway, on a free port (the default, 8787,
                    # when taken, warned on stderr and moved)
                    scheduler_kwargs={"dashboard_address": LOCAL_HTTP_ADDRESS},
                    silence_logs=logging.CRITICAL,
                    preload=["testbed.sweep.worker_setup"],
                )
                client = Client(cluster)
        elif own_client:
            client = _connect(address)
        futures = [client.submit(execute_run, spec, pure=False) for spec in specs]
        spec_of = {future.key: spec for future, spec in zip(futures, specs, strict=True)}
        for future in as_completed(futures):
            try:
                yield future.result()
            except Exception as err:  # on the client: a lost worker (KilledWorker), a task
                spec = spec_of[future.key]  # that cannot be unpickled there…: a failed run
                message = " ".join(f"{type(err).__name__}: {err}".split())
                yield RunOutcome(spec.point, spec.seed, None, f"dask: {message}")
        finished = True
    finally:
        # Closed whole: a Ctrl-C that cut cluster.close left the cluster half closed, and the
        # process then waited ≈ 10 s at exit for it (12.5 s from the Ctrl-C, measured).
        with deferred_interrupts() as late:
            if not finished:  # interrupted: what closing the comms logs (tracebacks) is noise
                logging.getLogger("distributed").setLevel(logging.CRITICAL + 1)
            if cluster is not None and not finished:
                _kill_local_workers(cluster)
            if own_client and client is not None:
                with contextlib.suppress(Exception):
                    client.close(timeout=10)
            if cluster is not None:
                with contextlib.suppress(Exception):
                    cluster.close(timeout=10)
        if late and finished:  # the runs were all in: the interrupt is the sweep's now
            raise late[0]


def _kill_local_workers(cluster: Any) -> None:
    """Interrupted: SIGKILL the LocalCluster's worker processes (runs in progress are lost
    anyway), so that closing does not wait for them."""
    for nanny in list(getattr(cluster, "workers", {}).values()):
        pid = getattr(getattr(nanny, "process", None), "pid", None)
        if pid:
            with contextlib.suppress(OSError):
                os.kill(pid, signal.SIGKILL)


def outcomes(
    specs: Sequence[RunSpec], workers: int, dask: str | None, client: Any = None
) -> Iterator[RunOutcome]:
    """Run ``specs`` and yield their outcomes as they finish.

    A generator: the pool or cluster starts only when it is iterated, i.e. when there is work.

    Args:
        specs: the runs.
        workers: local processes, or LocalCluster workers.
        dask: None for the process pool; a scheduler address; or ``"local"``.
        client: the remote scheduler's client, already connected (:func:`scheduler_client`);
            None: connected when iterated.

    Raises:
        ConfigError: a scheduler address that cannot be reached (when iterated, without
            ``client``).
    """
    if dask is None:
        return _pool_outcomes(specs, workers)
    return _dask_outcomes(specs, dask, workers, client)
