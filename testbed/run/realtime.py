"""Hardware in the loop: the run's nodes in real time, their frames through serial modems.

:func:`run_hil` runs the same :class:`~testbed.run.nodes.VehicleNode` and
:class:`~testbed.run.nodes.OperatorNode` as :func:`~testbed.run.runner.run_scenario`,
built by the same
functions, under ``simpy.rt.RealtimeEnvironment(strict=False)``. Instead of a modem on the
simulated medium, each node holds a :class:`HilModem`: the simulated modem's interface
(``send``, ``on_receive``, ``last_frame_id``) on a :class:`~testbed.hil.LinkEndpoint`, i.e. a
serial port (any pyserial URL) through a modem adapter. Modes:

* ``both``: operator and simulated vehicle on this computer, each node on its own modem, the two
  modems talking over the real link (the paper's Fig. 4a);
* ``vehicle`` / ``operator``: one node here, its peer on another computer.

Threads: each transport reads its port on its own thread and queues the bytes. The
:func:`run_poll` process drains the queues every ``poll_s`` (1 ms): each endpoint decodes the
stream (hunting through garbage, counting corrupt candidates) and each whole frame is handed to
its node's ``on_receive`` as a :class:`~testbed.channel.Delivery` holding that frame's bytes,
which the node feeds to its own decoder exactly as in a simulated run. Nodes never block on I/O
and nothing calls into simpy from another thread. Node code is unchanged.

Scheduler lateness (instrumentation): each time :func:`run_poll` wakes it records how late it
runs against the wall-clock instant the real-time environment scheduled it for
(:func:`rt_lateness_ns`); ``metrics.json`` reports it as ``hil.scheduler_lateness_ms``. Every
event of the run (vehicle frames, orders, hand-overs) is late by as much as the poll beside it,
so tests derive their real-time bounds from it (a loaded machine runs late; the model does not
change).

Ground truth the wire does not carry: in ``both`` mode one :class:`FrameLedger` numbers the
frames both nodes send and recognises each received frame by its bytes, so the recorder follows
a command from its sampling to its application (command lag, age of information) as in
simulation. A node alone cannot know its peer's frame ids or clock: see :func:`hil_metrics` for
what is then left out.

Link events in the recording: ``enqueue`` when a node hands a frame to its modem, ``drop``
when the port refuses it (queue full, port down), ``tx_start`` when it is queued for the port,
``deliver`` when a frame is handed to the receiving node and, with both nodes here,
``tx_end`` at that same instant for the frame the ledger recognised; so the timeline plot
draws each frame's whole time in the link (port, modem, air, host), not its airtime.
``outage`` marks frames refused or discarded in a scenario outage window.

Scenario faults: thruster faults apply to the vehicle as in simulation; a link outage window
makes both endpoints refuse frames sent and discard frames received inside it (the real link
keeps running). The scenario's ``[link]`` channel parameters are not used: the real link is the
channel; its codec, medium access and rates are.

Size: a little over the 500-line guideline, kept whole: the real-time modem, the frame ledger
and the HIL metrics read the same per-run records.
"""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Callable, Generator, Iterable, Mapping, Sequence
from typing import Any

import numpy as np
import simpy
import simpy.rt

from testbed.channel import Delivery, EventKind, Trace
from testbed.channel.trace import BROADCAST
from testbed.hil import LinkEndpoint, endpoint_report, latency_summary_ms
from testbed.protocol import Frame, encode_frame
from testbed.run.failures import reduce_run
from testbed.run.interrupts import deferred_interrupts, interrupt_of
from testbed.run.metrics import summary
from testbed.run.nodes import OperatorNode, VehicleNode
from testbed.run.recorder import Recorder
from testbed.run.run_metrics import compute_metrics
from testbed.run.runner import (
    RunResult,
    make_operator_node,
    make_vehicle_node,
    run_pilots,
    tally_images,
)
from testbed.run.scenario_config import Scenario
from testbed.vehicle.resources import Controllers

__all__ = [
    "DIRECTIONS",
    "POLL_S",
    "FrameLedger",
    "HilModem",
    "hil_metrics",
    "rt_lateness_ns",
    "run_hil",
    "run_poll",
]

POLL_S = 0.001
"""Period at which received bytes are taken from the reader threads [s]."""

DIRECTIONS = {"uplink": ("operator", "vehicle"), "downlink": ("vehicle", "operator")}
"""Link direction → (sender, receiver)."""

_LEDGER_HORIZON = 256
"""Frames per sender the ledger keeps outstanding; older ones are counted lost."""

_LATENESS_SAMPLES = 200_000
"""Scheduler lateness samples kept (the newest): 200 s of 1-ms polls."""


def rt_lateness_ns(env: simpy.rt.RealtimeEnvironment) -> int:
    """How late the real-time environment is running now [ns]: the wall clock less the
    instant ``env.now`` was scheduled for (``real_start + (now − env_start)·factor``, on
    :func:`time.monotonic`, simpy's clock). Called from a process just resumed, it is how late
    that step ran; ≥ 0 except for clock rounding."""
    scheduled_s = env.real_start + (env.now - env.env_start) * env.factor
    return round((time.monotonic() - scheduled_s) * 1e9)


class FrameLedger:
    """Frame ids on a real link: which sent frame a received frame is.

    Ids are given in send order from 0, one sequence for every sender using the ledger, as the
    simulated medium gives them. A received frame is matched with the oldest outstanding frame
    from its sender that has the same bytes; outstanding frames before it are counted lost (a
    modem link delivers in order). Identical frames sent back to back with the first lost are
    matched to the first: its id is then one frame early — harmless for the recorder's lags,
    which differ by one inter-packet gap only in that case.

    Args:
        horizon: outstanding frames kept per sender; older ones are counted lost.
    """

    def __init__(self, horizon: int = _LEDGER_HORIZON) -> None:
        self._horizon = horizon
        self._next_id = 0
        self._outstanding: dict[str, deque[tuple[int, bytes, float]]] = {}
        self.sent: dict[str, int] = {}
        self.matched: dict[str, int] = {}
        self.lost: dict[str, int] = {}

    def record_sent(self, src: str, data: bytes, t_s: float) -> int:
        """Number a frame ``src`` sends at ``t_s`` [s]; returns its id."""
        frame_id = self._next_id
        self._next_id += 1
        self.sent[src] = self.sent.get(src, 0) + 1
        queue = self._outstanding.setdefault(src, deque())
        queue.append((frame_id, bytes(data), t_s))
        if len(queue) > self._horizon:
            queue.popleft()
            self.lost[src] = self.lost.get(src, 0) + 1
        return frame_id

    def match(self, src: str, data: bytes) -> tuple[int, float] | None:
        """The id and send time [s] of the frame from ``src`` that ``data`` is, or None if no
        outstanding frame has these bytes (a peer on another computer, or garbage that passed
        the CRC)."""
        queue = self._outstanding.get(src)
        if not queue:
            return None
        for k, (frame_id, sent, t_s) in enumerate(queue):
            if sent == data:
                for _ in range(k + 1):
                    queue.popleft()
                self.lost[src] = self.lost.get(src, 0) + k
                self.matched[src] = self.matched.get(src, 0) + 1
                return frame_id, t_s
        return None

    def dropped(self, src: str, data: bytes) -> int:
        """The id of the oldest outstanding frame from ``src`` with bytes ``data``, which its
        port dropped before it reached the line: no longer outstanding, and neither delivered
        nor lost on the air (not in :meth:`settled`); −1 if none is outstanding."""
        queue = self._outstanding.get(src)
        for k, (frame_id, sent, _) in enumerate(queue or ()):
            if sent == data:
                assert queue is not None
                del queue[k]
                return frame_id
        return -1

    def settled(self, src: str) -> int:
        """Frames from ``src`` known to have arrived or been lost."""
        return self.matched.get(src, 0) + self.lost.get(src, 0)


class HilModem:
    """A node's modem on a real port, with the simulated modem's interface.

    Args:
        env: the (real-time) environment.
        name: this node (``"operator"`` or ``"vehicle"``).
        peer: the node at the other end.
        endpoint: the port and its frame decoder.
        trace: where the link events go (see the module docstring).
        ledger: frame numbering (shared by both nodes when both run here).
        outages: ``(start_s, end_s)`` windows in which frames are refused and discarded.

    Attributes:
        on_receive: called with one :class:`~testbed.channel.Delivery` per received frame (its
            bytes; ``frame_id`` −1 and ``t_tx_start_s`` NaN when the ledger does not know it).
        last_frame_id: id of the frame most recently handed to :meth:`send`.
        frames_offered: frames handed to :meth:`send`.
        bytes_offered: their bytes [B].
        outage_refused: frames refused in an outage window.
        outage_discarded: frames received in an outage window and discarded.
    """

    def __init__(
        self,
        env: simpy.Environment,
        name: str,
        peer: str,
        endpoint: LinkEndpoint,
        *,
        trace: Trace,
        ledger: FrameLedger,
        outages: Sequence[tuple[float, float]] = (),
    ) -> None:
        self.env = env
        self.name = name
        self.peer = peer
        self.endpoint = endpoint
        self.on_receive: Callable[[Delivery], None] | None = None  # the node's port sets it
        self.last_frame_id = -1
        self.frames_offered = 0
        self.bytes_offered = 0
        self.outage_refused = 0
        self.outage_discarded = 0
        self._trace = trace
        self._ledger = ledger
        self._outages = tuple(outages)

    def _in_outage(self, t_s: float) -> bool:
        return any(start <= t_s < end for start, end in self._outages)

    def send(self, data: bytes) -> bool:
        """Hand one frame to the port's writer thread (never blocks).

        Returns:
            False if it was refused (outage window) or dropped (queue full, port closed).
        """
        now = self.env.now
        frame_id = self._ledger.record_sent(self.name, data, now)
        self.last_frame_id = frame_id
        self.frames_offered += 1
        self.bytes_offered += len(data)
        trace = self._trace
        trace.record(now, EventKind.ENQUEUE, self.name, BROADCAST, frame_id, 0, len(data))
        if self._in_outage(now):
            self.outage_refused += 1
            trace.record(now, EventKind.OUTAGE, self.name, self.peer, frame_id, 0, len(data))
            return False
        if not self.endpoint.send(data):  # the queue full or the port closed: not on the air
            self._ledger.dropped(self.name, data)
            trace.record(now, EventKind.DROP, self.name, BROADCAST, frame_id, 0, len(data))
            return False
        trace.record(now, EventKind.TX_START, self.name, BROADCAST, frame_id, 0, len(data))
        return True

    def note_drops(self) -> None:
        """Record a drop for each frame the port dropped since the last call (accepted by
        :meth:`send`, then the port failed or closed before writing it): out of the PER, as a
        simulated sender's drops are. Call it for every modem before any :meth:`poll`
        (:func:`poll_modems`), so no frame received after a drop counts it lost."""
        dropped = self.endpoint.transport.dropped_frames
        while dropped:
            data = dropped.popleft()
            frame_id = self._ledger.dropped(self.name, data)
            self._trace.record(
                self.env.now, EventKind.DROP, self.name, BROADCAST, frame_id, 0, len(data)
            )

    def poll(self) -> int:
        """Hand every frame received so far to :attr:`on_receive`; returns how many."""
        self.note_drops()
        return self.endpoint.deliver(self._hand_over)

    def _hand_over(self, frame: Frame) -> None:
        now = self.env.now
        data = encode_frame(frame.payload)  # the bytes that crossed, byte for byte
        known = self._ledger.match(self.peer, data)
        frame_id, t_sent = known if known is not None else (-1, math.nan)
        trace = self._trace
        if self._in_outage(now):
            self.outage_discarded += 1
            trace.record(now, EventKind.OUTAGE, self.peer, self.name, frame_id, 0, len(data))
            return
        if known is not None:
            trace.record(now, EventKind.TX_END, self.peer, BROADCAST, frame_id, 0, len(data))
        trace.record(now, EventKind.DELIVER, self.peer, self.name, frame_id, 0, len(data))
        if self.on_receive is not None:
            self.on_receive(Delivery(data, t_sent, now, frame_id, self.peer))


def poll_modems(modems: Iterable[HilModem]) -> None:
    """Note every modem's port drops, then hand each one's received frames to its node."""
    modems = list(modems)
    for modem in modems:
        modem.note_drops()
    for modem in modems:
        modem.poll()


def run_poll(
    env: simpy.Environment,
    modems: Sequence[HilModem],
    period_s: float = POLL_S,
    lateness_ns: deque[int] | list[int] | None = None,
) -> Generator[simpy.Event, Any, None]:
    """simpy process: every ``period_s`` [s], hand each modem's received frames to its node.

    With ``lateness_ns`` (and a real-time ``env``), each wake-up first appends how late it ran
    (:func:`rt_lateness_ns`) [ns]."""
    rt_env = env if isinstance(env, simpy.rt.RealtimeEnvironment) else None
    while True:
        if rt_env is not None and lateness_ns is not None:
            lateness_ns.append(rt_lateness_ns(rt_env))
        poll_modems(modems)
        yield env.timeout(period_s)


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
    lateness_ns: deque[int] = deque(maxlen=_LATENESS_SAMPLES)
    stopped: KeyboardInterrupt | None = None
    failed: Exception | None = None
    start: float | None = None
    try:
        if "vehicle" in modems:
            rng = np.random.default_rng(vehicle_seed)
            vehicle_node = make_vehicle_node(
                env, scenario, rng, modems["vehicle"], recorder, pilot=recorded_pilot
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
        if (stopped := interrupt_of(error)) is None:
            if start is None or not isinstance(error, Exception):  # nothing ran yet
                _close(vehicle_node, endpoints)
                raise
            failed = error  # an error part way (a pilot of the user's): keep what ran too
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


def hil_metrics(
    scenario: Scenario,
    seed: int,
    recorder: Recorder,
    modems: Mapping[str, HilModem],
    ledger: FrameLedger,
    *,
    duration_s: float,
    wall_s: float,
    vehicle_node: VehicleNode | None,
    operator_node: OperatorNode | None,
    poll_s: float,
    modem: str,
    lateness_ns: Sequence[int] | deque[int] = (),
) -> dict[str, Any]:
    """The ``metrics.json`` of a HIL run: :func:`~testbed.run.run_metrics.compute_metrics`'s
    keys, with the link section rebuilt from what the endpoints observed, plus a ``hil`` section.

    Link, per direction: ``frames_sent`` (handed to the sender's modem), ``frames_delivered``
    (decoded by the receiving node), ``frames_corrupted`` (candidates the receiver's decoder
    rejected), ``frames_dropped`` (sender's queue full, port down or closed: never on the line,
    so not in the PER), ``drop_rate`` (dropped / sent), ``frames_outage`` (refused or discarded
    in a scenario outage window), ``per`` (1 − delivered / settled, where settled counts the
    frames the ledger knows arrived or were lost on the line), ``goodput_bps`` and
    ``mean_frame_bytes`` (the frames' own bytes). ``frames_collided``, ``frames_out_of_range``
    and ``mean_on_air_bytes`` are null: only the simulator's trace knows why a frame vanished on
    the air, and a real modem's packet padding is its own. A count that needs the end not
    running here is null too, and so is ``per`` unless both nodes run here.

    ``duration_s`` is the time the run reached (``sim_s``): less than asked for a run ended
    early by Ctrl-C or SIGTERM, possibly ≤ ``metrics.settle_s`` or 0; what needs the settled
    window (ages, tracking, attitude errors) or a positive duration (goodput) is then NaN
    (null in ``metrics.json``), never an exception.

    With one node here (two computers), what needs both ends' clocks or frame ids is null:
    ``command_lag_s``, ``command_age_s``, ``odometry_age_s`` and ``signal_lag_s``; and at the
    operator everything drawn from the vehicle's truth (tracking, attitude errors, energy).

    ``token_round_trip_s`` and ``reply_fits_gap`` are the scenario link's closed form only when
    its preset models the modem in use (``s100``, ``s2c`` for EvoLogics, ``m64``), else null;
    the vehicle's event counts (failsafe, thruster faults) are null at a lone operator, and
    ``events.ignored_setpoints`` is the vehicle's count where it runs here.

    ``hil``: ``mode``, ``modem``, ``poll_s``; ``added_latency_ms`` (port read returned → frame
    handed to the node, both endpoints pooled: ``p50``, ``p95``, ``max``, ``mean``, ``n``);
    ``round_trip_s`` (operator, token passing: order handed to the modem → the reply that
    answers it handed to the node, :func:`_round_trips`); ``scheduler_lateness_ms``
    (``lateness_ns``: how late the poll process ran against its real-time schedule,
    :func:`rt_lateness_ns`; same keys as ``added_latency_ms``);
    ``reopens`` and ``garbage_bytes`` summed over the endpoints; ``endpoints``
    (:func:`~testbed.hil.endpoint_report` per node: bytes and frames in/out, drops, garbage,
    corrupt frames, port faults, latency, adapter counters).
    """
    nan = math.nan
    payload = {
        "uplink": 0 if vehicle_node is None else vehicle_node.port.payload_bytes,
        "downlink": 0 if operator_node is None else operator_node.port.payload_bytes,
    }
    metrics = compute_metrics(
        scenario,
        seed,
        recorder,
        sim_s=duration_s,
        wall_s=wall_s,
        energy_wh=nan if vehicle_node is None else vehicle_node.energy_wh,
        payload_bytes=payload,
        ignored_setpoints=None
        if vehicle_node is None
        else vehicle_node.vehicle.world.resource(Controllers).ignored_setpoints,
    )
    if vehicle_node is None:  # the vehicle's own counts are kept on the other computer
        metrics["events"].update(failsafe=nan, failsafe_surfaced=nan, thruster_fault=nan)
    if _PRESET_OF_MODEM.get(modem) != scenario.link.preset:  # the closed form is another link's
        metrics["token_round_trip_s"], metrics["reply_fits_gap"] = nan, None
    metrics["link"] = {
        direction: _direction(direction, modems, ledger, recorder, payload[direction], duration_s)
        for direction in DIRECTIONS
    }
    if len(modems) == 1:
        metrics["command_lag_s"] = summary([])
        metrics["command_age_s"] = {"mean": nan, "p95": nan}
        metrics["odometry_age_s"] = {"mean": nan, "p95": nan}
        metrics["signal_lag_s"] = {axis: nan for axis in metrics["signal_lag_s"]}
    reports = {role: endpoint_report(m.endpoint) for role, m in sorted(modems.items())}
    token = scenario.link.mac == "token" and scenario.link.codec == "teleop"
    round_trips = _round_trips(recorder.trace) if token and "operator" in modems else []
    latencies = [ns for m in modems.values() for ns in m.endpoint.latencies_ns]
    metrics["hil"] = {
        "mode": "both" if len(modems) == 2 else next(iter(modems)),
        "modem": modem,
        "poll_s": poll_s,
        "added_latency_ms": latency_summary_ms(latencies),
        "round_trip_s": summary(round_trips),
        "scheduler_lateness_ms": latency_summary_ms(lateness_ns),
        "reopens": sum(r["reopens"] for r in reports.values()),
        "garbage_bytes": sum(r["garbage_bytes"] for r in reports.values()),
        "endpoints": reports,
    }
    return metrics


_PRESET_OF_MODEM = {"s100": "s100", "evologics": "s2c", "m64": "m64"}
"""The link preset that models each modem kind: a scenario on another preset describes another
link, and its token cycle's closed form is not this run's."""


def _direction(
    direction: str,
    modems: Mapping[str, HilModem],
    ledger: FrameLedger,
    recorder: Recorder,
    payload_bytes: int,
    duration_s: float,
) -> dict[str, Any]:
    """One direction's link metrics from what the ends running here observed."""
    src, dst = DIRECTIONS[direction]
    sender, receiver = modems.get(src), modems.get(dst)
    nan = math.nan
    outage = 0
    if sender is not None:
        outage += sender.outage_refused
    if receiver is not None:
        outage += receiver.outage_discarded
    delivered = recorder.frames_decoded[direction] if receiver is not None else nan
    settled = ledger.settled(src)
    both = sender is not None and receiver is not None
    sent = sender.frames_offered if sender is not None else nan
    dropped = sender.endpoint.transport.frames_dropped if sender is not None else nan
    return {
        "frames_sent": sent,
        "frames_delivered": delivered,
        "frames_corrupted": receiver.endpoint.corrupt_frames if receiver is not None else nan,
        "frames_collided": nan,
        "frames_dropped": dropped,
        "frames_outage": outage if both else nan,
        "frames_out_of_range": nan,
        "per": 1.0 - delivered / settled if both and settled else nan,
        "drop_rate": dropped / sent if sent else nan,
        "goodput_bps": (
            8.0 * payload_bytes / duration_s if receiver is not None and duration_s > 0 else nan
        ),
        "mean_frame_bytes": (
            sender.bytes_offered / sender.frames_offered
            if sender is not None and sender.frames_offered
            else nan
        ),
        "mean_on_air_bytes": nan,
    }


def _round_trips(trace: Trace) -> list[float]:
    """Token passing at the operator: each reply handed over → time since the order it answers
    was sent [s], for the replies whose order is known.

    A reply answers the one order sent before it that has no reply yet. When a second order
    goes out before the first one's reply (a reply lost, or one a loaded host held past the next
    slot), the next reply may answer either, so it is not paired, and neither is any other
    until the next order; pairing it with the newer order would count a round trip shorter than
    the link can carry.
    """
    out: list[float] = []
    pending: float | None = None
    ambiguous = False
    for event in trace.events:
        if event.kind is EventKind.ENQUEUE and event.src == "operator":
            ambiguous = pending is not None
            pending = event.t_s
        elif event.kind is EventKind.DELIVER and event.dst == "operator" and pending is not None:
            if not ambiguous:
                out.append(event.t_s - pending)
            pending = None
            ambiguous = False
    return out
