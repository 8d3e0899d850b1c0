"""Hardware in the loop: the run's nodes in real time, their frames through serial modems.

:func:`run_hil` runs the same :class:`~testbed.run.nodes.VehicleNode` and
:class:`~testbed.run.nodes.OperatorNode` as :func:`~testbed.run.runner.run_scenario`, built
by the same functions, under ``simpy.rt.RealtimeEnvironment(strict=False)``. Instead of a modem
on the simulated medium, each node holds a :class:`~testbed.run.hil_modem.HilModem`: the simulated
modem's interface on a :class:`~testbed.hil.LinkEndpoint`, i.e. a serial port (any pyserial
URL) through a modem adapter. Modes:

* ``both``: operator and simulated vehicle on this computer, each node on its own modem, the two
  modems talking over the real link (the paper's Fig. 4a);
* ``vehicle`` / ``operator``: one node here, its peer on another computer.

The modems, the frame ledger (ground truth the wire does not carry, with both nodes here), the
poll process that hands received frames to the nodes and the link events they record are in
:mod:`testbed.run.hil_modem`; the run's ``metrics.json`` in :mod:`testbed.run.hil_metrics`.

Scheduler lateness (instrumentation): each time the poll process wakes it records how late it
runs against the wall-clock instant the real-time environment scheduled it for
(:func:`~testbed.run.wall_clock.rt_lateness_ns`); ``metrics.json`` reports it as
``hil.scheduler_lateness_ms``. Every event of the run (vehicle frames, orders, hand-overs) is
late by as much as the poll beside it, so tests derive their real-time bounds from it (a loaded
machine runs late; the model does not change).

Scenario faults: thruster faults apply to the vehicle as in simulation; a link outage window
makes both endpoints refuse frames sent and discard frames received inside it (the real link
keeps running). The scenario's ``[link]`` channel parameters are not used: the real link is the
channel; its codec, medium access and rates are.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable, Mapping

import numpy as np
import simpy.rt

from testbed.channel import Trace
from testbed.hil import LinkEndpoint
from testbed.run.failures import reduce_run, run_error
from testbed.run.hil_metrics import hil_metrics
from testbed.run.hil_modem import DIRECTIONS, POLL_S, FrameLedger, HilModem, run_poll
from testbed.run.interrupts import deferred_interrupts, interrupt_of
from testbed.run.nodes import OperatorNode, VehicleNode
from testbed.run.recorder import Recorder
from testbed.run.runner import (
    RunResult,
    make_operator_node,
    make_vehicle_node,
    run_pilots,
    tally_images,
)
from testbed.run.scenario_config import Scenario
from testbed.run.wall_clock import SAMPLES_KEPT

__all__ = ["run_hil"]


def run_hil(
    scenario: Scenario,
    endpoints: Mapping[str, LinkEndpoint],
    *,
    seed: int | None = None,
    duration_s: float | None = None,
    poll_s: float = POLL_S,
    modem: str = "",
    on_start: Callable[[], None] | None = None,
) -> RunResult:
    """Run ``scenario`` in real time with its link on real ports.

    Args:
        scenario: the loaded scenario (its channel preset is not used).
        endpoints: ``{"operator": …, "vehicle": …}`` for both nodes here, or one of them for a
            node whose peer runs on another computer. Closed when the run ends (or fails).
        seed: overrides the scenario's seed (vehicle sensors and current).
        duration_s: run length [s of wall-clock time], > ``metrics.settle_s``; None = the
            scenario's. Ctrl-C or SIGTERM (a ``KeyboardInterrupt``) ends the run early at any
            time, even before ``metrics.settle_s``: the result then has ``stopped`` set and its
            metrics cover the ``sim_s`` reached (those needing the settled window are NaN).
        poll_s: period at which received frames are handed to the nodes [s].
        modem: the modem kind, for the record (``metrics.json`` ``hil.modem``).
        on_start: called once the nodes are built (the vehicle's physics loaded, its kernels
            compiled) as the real-time clock starts, e.g. to tell the user the session runs.

    Returns:
        The metrics (:func:`hil_metrics`) and the recording; ``stopped`` is the interrupt that
        ended the run early, or None.

    Raises:
        ValueError: no endpoint, an unknown role, a duration not beyond the scenario's
            ``metrics.settle_s``, or a non-positive poll period.
    """
    roles = set(endpoints)
    duration = scenario.duration_s if duration_s is None else duration_s
    settle_s = scenario.metrics.settle_s
    problem = ""
    if not roles or not roles <= set(DIRECTIONS["uplink"]):
        problem = f"endpoints must be keyed 'operator' and/or 'vehicle', got {sorted(roles)}"
    elif not poll_s > 0.0:
        problem = f"poll_s must be > 0, got {poll_s}"
    elif not duration > settle_s:
        problem = f"duration_s must exceed metrics.settle_s ({settle_s:g} s), got {duration:g}"
    seed = scenario.seed if seed is None else seed
    recorder = Recorder(trace=Trace())
    try:  # a bad argument, or a pilot of the user's own failing, closes the ports
        if problem:
            raise ValueError(problem)
        operator_pilot, recorded_pilot = run_pilots(scenario, seed, recorder)
    except BaseException:
        for endpoint in endpoints.values():
            endpoint.close()
        raise
    _, vehicle_seed = np.random.SeedSequence(seed).spawn(2)
    env = simpy.rt.RealtimeEnvironment(factor=1.0, strict=False)
    ledger = FrameLedger()
    outages = [(o.start_s, o.end_s) for o in scenario.faults.link_outages]
    for start_s, end_s in outages:
        recorder.event(start_s, "scenario", "outage", f"until {end_s:g} s")
    modems = {
        role: HilModem(
            env,
            role,
            _peer(role),
            endpoints[role],
            trace=recorder.trace,
            ledger=ledger,
            outages=outages,
        )
        for role in sorted(roles, reverse=True)  # vehicle first, as in the simulated run
    }
    vehicle_node: VehicleNode | None = None
    operator_node: OperatorNode | None = None
    lateness_ns: deque[int] = deque(maxlen=SAMPLES_KEPT)
    stopped: KeyboardInterrupt | None = None
    failed: Exception | None = None
    start: float | None = None
    try:
        if "vehicle" in modems:
            rng = np.random.default_rng(vehicle_seed)
            vehicle_node = make_vehicle_node(
                env, scenario, rng, modems["vehicle"], recorder, pilot=recorded_pilot, seed=seed
            )
            env.process(vehicle_node.run())
        if "operator" in modems:
            replies = {} if vehicle_node is None else vehicle_node.reply_odometry_s
            operator_node = make_operator_node(
                env, scenario, modems["operator"], recorder, replies, pilot=operator_pilot
            )
            env.process(operator_node.run())
        env.process(run_poll(env, list(modems.values()), poll_s, lateness_ns))
        env.sync()  # start the clock now, after the vehicle's physics has loaded
        start = time.perf_counter()
        if on_start is not None:
            on_start()
        env.run(until=duration)
    except BaseException as error:  # Ctrl-C or SIGTERM: keep what ran, marked partial
        # an error part way (a pilot of the user's) keeps what ran too, unless nothing ran yet
        if (stopped := interrupt_of(error)) is None and (
            start is None or (failed := run_error(error)) is None
        ):
            _close(vehicle_node, endpoints)
            raise
    with deferred_interrupts() as closing:  # a second Ctrl-C: the run is ending anyway
        wall_s = 0.0 if start is None else time.perf_counter() - start
        _close(vehicle_node, endpoints)
    stopped = stopped or (closing[0] if closing else None)

    def reduce(failure: str | None) -> RunResult:
        """What ran, reduced; ``failure`` is the error's line when one ended it."""
        early = stopped is not None or failure is not None
        if failure is not None:
            recorder.event(float(env.now), "testbed", "failed", failure)
        tally_images(recorder, vehicle_node, operator_node)
        metrics = hil_metrics(
            scenario,
            seed,
            recorder,
            modems,
            ledger,
            duration_s=float(env.now) if early else duration,
            wall_s=wall_s,
            vehicle_node=vehicle_node,
            operator_node=operator_node,
            poll_s=poll_s,
            modem=modem,
            lateness_ns=lateness_ns,
        )
        return RunResult(scenario, seed, metrics, recorder, stopped, failure)

    return reduce_run(reduce, failed, float(env.now), stopped)  # reduced whole, even on Ctrl-C


def _close(vehicle_node: VehicleNode | None, endpoints: Mapping[str, LinkEndpoint]) -> None:
    """Release the vehicle's physics and the endpoints' ports and threads."""
    if vehicle_node is not None:
        vehicle_node.vehicle.close()
    for endpoint in endpoints.values():
        endpoint.close()


def _peer(role: str) -> str:
    return "vehicle" if role == "operator" else "operator"
