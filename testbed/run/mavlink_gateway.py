"""The MAVLink gateway through the narrow link: both nodes in real time, MAVLink on shore.

:func:`run_gateway` runs the scenario's vehicle node and an operator node under
``simpy.rt.RealtimeEnvironment(strict=False)``, their frames through the scenario's simulated
channel (the medium of :func:`~testbed.run.runner.run_scenario`, in real time) or through two
serial modems (the HIL endpoints of :func:`~testbed.run.realtime.run_hil`, polled every
millisecond). The operator node's station (:class:`GatewayStation`) has no pilot of its own: a
:class:`~testbed.mavlink.shore.ShoreEndpoint` on its world is the pilot. The ground station
talks to that endpoint at full rate on 127.0.0.1; the node's link codec turns the intents it
writes into orders at the token rate (teleop: ``Move`` with the arm/mode flags, ``KeepHeading``)
and the replies' 12-byte state into the mirrored copy the endpoint reports, with its true age.

:class:`GatewayNode` is a simpy process every :data:`GATEWAY_PERIOD_S`: it drains the ground
stations' reader queues into the endpoint, runs the endpoint's failsafes and telemetry and hands
its packets to the links. Nothing calls into simpy from a reader thread.

Measured (``metrics.json`` ``mavlink``): ``gcs_to_thruster_ms`` — from the reader thread's read
of a datagram holding accepted stick input to the end of the vehicle frame that first applied
the order carrying it (wall clock); ``scheduler_lateness_ms`` — how late the gateway process ran
against its schedule (:func:`~testbed.run.wall_clock.rt_lateness_ns`); ``state_age_s`` — the
age of the state the endpoint reports (sampled every gateway period: its time average). The
recorder's ``command_lag_s`` (stick arrival at the gateway → applying vehicle frame) and
``odometry_age_s`` (the true age of the state on shore) are the simulated run's, on the
real-time clock. Their closed forms (docs/mavlink.md): a stick read at the gateway waits for the
next token slot (at most the ground station's stick interval for the newest one), crosses in
intrinsic delay + airtime of the order and waits for the next vehicle frame.
"""

from __future__ import annotations

import math
import threading
import time
from collections import deque
from collections.abc import Generator, Mapping, Sequence
from typing import Any

import numpy as np
import simpy
import simpy.rt

from testbed.channel import Medium, Trace
from testbed.ecs import Origin, Phase, Schedule, World
from testbed.hil import LinkEndpoint, latency_summary_ms
from testbed.mavlink import EndpointOptions
from testbed.mavlink.links import Intake, Link
from testbed.mavlink.shore import LinkFacts, ShoreEndpoint
from testbed.operator.pilots import PilotSample
from testbed.operator.station import OperatorStation, SessionPlan
from testbed.protocol import encode_frame
from testbed.run.failures import reduce_run, run_error
from testbed.run.hil_metrics import hil_metrics
from testbed.run.hil_modem import FrameLedger, HilModem, run_poll
from testbed.run.images import image_source_factory
from testbed.run.interrupts import interrupt_of
from testbed.run.link_log import LinkStateLog
from testbed.run.mavlink_run import EndpointPilot, FailsafeNotes, endpoint_section
from testbed.run.metrics import summary
from testbed.run.nodes import OperatorNode, VehicleNode
from testbed.run.observer import VehicleObserver
from testbed.run.plugin_calls import scenario_control_laws, scenario_link_model
from testbed.run.recorder import Recorder
from testbed.run.run_metrics import compute_metrics
from testbed.run.runner import RunResult, note_copies_lost_transmitting
from testbed.run.scenario_config import Scenario
from testbed.run.wall_clock import SAMPLES_KEPT, rt_lateness_ns
from testbed.vehicle.vehicle import Vehicle

__all__ = [
    "GATEWAY_PERIOD_S",
    "GatewayNode",
    "GatewayStation",
    "gateway_link_facts",
    "run_gateway",
]

GATEWAY_PERIOD_S = 0.01
"""The gateway process's period [s] (the vehicle's frame period: telemetry up to 50 Hz)."""
_ORDER_PAYLOAD_BYTES = 7
"""A ``Move`` order's payload [B]."""
_STATE_REPLY_PAYLOAD_BYTES = 14
"""A reply without an image chunk [B] (header, 12-byte state, chunk header)."""


class _Idle:
    """The station's pilot when the endpoint writes the intents: never sampled."""

    def sample(self, t_s: float) -> PilotSample:
        del t_s
        return PilotSample((0.0,) * 6)


class GatewayStation(OperatorStation):
    """The operator's station with no pilot and no session plan: the shore endpoint writes its
    intents (sticks, arm and mode requests, depth) on :attr:`entity`; the node's link system
    is the only one in its schedule."""

    def __init__(self) -> None:
        super().__init__(_Idle(), SessionPlan(arm_at_s=math.inf))
        self.schedule = Schedule()


def gateway_link_facts(scenario: Scenario, name: str | None = None) -> LinkFacts:
    """What the gateway tells the ground station about the scenario's link (its model).

    Token-passing teleop: the state comes once per gap after a ``Move`` order; the reply is
    stamped at arrival, so its sample time is the arrival less the reply's transit (intrinsic
    delay + airtime of the 20-B frame). Change-set: once per downlink period, the sample time
    travels with the state. Stale after three state periods (at least 1 s) plus the transit.
    """
    link = scenario.link
    channel = link.channel
    if link.codec == "teleop" and link.mac == "token":
        period = link.ipg_policy.gap_after(len(encode_frame(bytes(_ORDER_PAYLOAD_BYTES))))
        reply_bytes = len(encode_frame(bytes(_STATE_REPLY_PAYLOAD_BYTES)))
        correction = channel.intrinsic_delay_s + 8.0 * reply_bytes / channel.bitrate_bps
    else:
        period = 1.0 / link.downlink_rate_hz
        correction = 0.0
    return LinkFacts(
        name=name or link.preset,
        bitrate_bps=channel.bitrate_bps,
        state_period_s=period,
        arrival_correction_s=correction,
        stale_after_s=max(1.0, 3.0 * period) + correction,
        position_fix=scenario.vehicle.sensors.position is not None,
        carries_setpoints=link.codec == "changeset",  # every intent replicated
    )


class GatewayNode:
    """The shore endpoint on the operator station's world, served in (real) simpy time.

    Args:
        env: the environment.
        station: the operator's station (its world is what the endpoint pilots).
        links: the ground-station links (one endpoint channel each).
        facts: the link facts the endpoint reports.
        stop: ends the process at its next wake-up once set (from any thread).
        boot_params: ArduSub parameters' values at boot (``--param``).
        failsafe_notes: records ArduSub's failsafes as they act, or None.
    """

    def __init__(
        self,
        env: simpy.Environment,
        station: GatewayStation,
        links: Sequence[Link],
        facts: LinkFacts,
        stop: threading.Event | None = None,
        boot_params: Mapping[str, float] | None = None,
        failsafe_notes: FailsafeNotes | None = None,
    ) -> None:
        self.env = env
        self._failsafe_notes = failsafe_notes
        self.station = station
        self.endpoint = ShoreEndpoint(
            station.world,
            station.entity,
            facts,
            EndpointOptions(param_overrides=dict(boot_params or {}), origin=Origin.LOCAL),
        )
        self.links = list(links)
        self.channels = [self.endpoint.open_channel(link.url) for link in self.links]
        self.intakes = [Intake(link.inbox) for link in self.links]
        self.read_ns: dict[float, int] = {}
        """Sample time of each stick command the endpoint wrote → its datagram's read [ns]."""
        self.lateness_ns: deque[int] = deque(maxlen=SAMPLES_KEPT)
        self.compute_ns: deque[int] = deque(maxlen=SAMPLES_KEPT)
        self.state_age_s: deque[float] = deque(maxlen=SAMPLES_KEPT)
        self._stop = stop

    def run(self, period_s: float = GATEWAY_PERIOD_S) -> Generator[simpy.Event, Any, None]:
        """simpy process: serve the ground stations every ``period_s`` [s] until stopped."""
        env = self.env
        rt = env if isinstance(env, simpy.rt.RealtimeEnvironment) else None
        while self._stop is None or not self._stop.is_set():
            if rt is not None:
                self.lateness_ns.append(rt_lateness_ns(rt))
            self.serve(float(env.now))
            yield env.timeout(period_s)

    def serve(self, now_s: float) -> None:
        """Drain each link into the endpoint (up to
        :data:`~testbed.mavlink.links.INGEST_BYTES_PER_FRAME`; the rest next time), update it
        and send what it queued."""
        start = time.perf_counter_ns()
        endpoint = self.endpoint
        station = self.station
        for intake, channel in zip(self.intakes, self.channels, strict=True):
            for received in intake.take():
                arrived_s = now_s - max(0.0, (start - received.read_ns) * 1e-9)
                if endpoint.receive(channel, received.data, now_s, arrived_s, end=received.end):
                    command = station.latest_command()
                    if command is not None:
                        self.read_ns[command.sampled_s] = received.read_ns
        endpoint.update(now_s)
        if self._failsafe_notes is not None:
            self._failsafe_notes(endpoint.failsafe.triggered, now_s)
        self.state_age_s.append(endpoint.state_age_s)
        for link, channel in zip(self.links, self.channels, strict=True):
            for packet in channel.take():
                link.send(packet)
        self.compute_ns.append(time.perf_counter_ns() - start)


class _ThrusterProbe:
    """Vehicle POST_UPDATE: for each command the vehicle applied this frame, the wall time
    since its datagram was read at the gateway [ns] (the thrusters were commanded from it)."""

    def __init__(self, recorder: Recorder, gateway: GatewayNode) -> None:
        self._updates = recorder.command_updates
        self._gateway = gateway
        self._seen = 0
        self.latency_ns: deque[int] = deque(maxlen=SAMPLES_KEPT)

    def __call__(self, world: World) -> None:
        del world
        updates = self._updates
        if len(updates) == self._seen:
            return
        done = time.perf_counter_ns()
        reads = self._gateway.read_ns
        for _, sampled_s in updates[self._seen :]:
            read = reads.get(sampled_s)
            if read is not None:
                self.latency_ns.append(done - read)
        self._seen = len(updates)


def _vehicle_node(
    env: simpy.Environment,
    scenario: Scenario,
    rng: np.random.Generator,
    modem: Any,
    recorder: Recorder,
    gateway: GatewayNode,
    seed: int,
) -> tuple[VehicleNode, _ThrusterProbe]:
    """The scenario's vehicle node (as :func:`~testbed.run.runner.make_vehicle_node` builds
    it, its laws for a run of seed ``seed``), recorded against the sticks the ground station
    holds, with the latency probe."""
    depth_law, attitude_law = scenario_control_laws(scenario, seed)  # before the vehicle is built
    link = scenario.link
    images = image_source_factory(scenario.images) if scenario.images.enabled else None
    node = VehicleNode(
        env,
        lambda **systems: Vehicle(scenario.vehicle, rng, **systems),
        modem,
        codec=link.codec,
        token=link.mac == "token",
        downlink_rate_hz=link.downlink_rate_hz,
        recorder=recorder,
        snapshot_period_s=link.snapshot_period_s,
        image_source=images,
    )
    vehicle = node.vehicle
    vehicle.controllers.depth_law, vehicle.controllers.attitude_law = depth_law, attitude_law
    observer = VehicleObserver(
        recorder,
        EndpointPilot(gateway.endpoint),
        vehicle.reference_velocity,
        scenario.metrics.sample_rate_hz,
        other_failsafe=lambda: gateway.endpoint.failsafe.active,  # acting through the link
    )
    vehicle.schedule.add(Phase.POST_UPDATE, observer, name="record_vehicle")
    probe = _ThrusterProbe(recorder, gateway)
    vehicle.schedule.add(Phase.POST_UPDATE, probe, name="gcs_to_thruster")
    for fault in scenario.faults.thrusters:

        def fail(_: simpy.Event, fault: Any = fault) -> None:
            vehicle.fail_thruster(fault.thruster, fault.mode, fault.value or None)
            recorder.event(env.now, "vehicle", "thruster_fault", f"{fault.thruster} {fault.mode}")

        env.timeout(fault.t_s).callbacks.append(fail)
    return node, probe


def run_gateway(
    scenario: Scenario,
    links: Sequence[Link],
    *,
    seed: int | None = None,
    duration_s: float | None = None,
    stop: threading.Event | None = None,
    hil: Mapping[str, LinkEndpoint] | None = None,
    modem: str = "",
    boot_params: Mapping[str, float] | None = None,
) -> RunResult:
    """Run both nodes in real time for ``duration_s`` [s], the ground stations on ``links``
    driving the vehicle through the shore endpoint and the scenario's link.

    Args:
        scenario: the scenario (its link: preset, codec, MAC; its vehicle and faults).
        links: the ground-station links; closed when the run ends.
        seed: overrides the scenario's seed (link errors, vehicle sensors).
        duration_s: run length [s]; None = the scenario's.
        stop: once set from any thread, ends the run at the gateway's next wake-up.
        hil: ``{"operator": …, "vehicle": …}`` serial modem endpoints instead of the simulated
            channel (closed when the run ends); the channel preset then only informs
            :class:`~testbed.mavlink.shore.LinkFacts`.
        modem: the HIL modem kind, for the record.
        boot_params: the shore endpoint's ArduSub parameters at boot (``--param``).

    Returns:
        The metrics (those of ``testbed run`` or ``testbed hil``, plus ``mavlink``) and the
        recording; ``stopped`` is set by Ctrl-C or SIGTERM.

    Raises:
        ValueError: no link, a duration not > 0, or HIL endpoints not keyed by both roles.
        Exception: an error that ended the run part way (a control law of the user's raising),
            carrying what ran (:func:`~testbed.run.failures.partial_run`).
    """
    duration = scenario.duration_s if duration_s is None else duration_s
    problem = ""
    if not links or not (math.isfinite(duration) and duration > 0.0):
        problem = f"need a link and a duration > 0 s, got {len(links)}, {duration}"
    elif hil is not None and set(hil) != {"operator", "vehicle"}:
        problem = f"hil endpoints must be 'operator' and 'vehicle', got {sorted(hil)}"
    if problem:
        for gcs in links:
            gcs.close()
        for endpoint in (hil or {}).values():
            endpoint.close()
        raise ValueError(problem)
    seed = scenario.seed if seed is None else seed
    link_seed, vehicle_seed = np.random.SeedSequence(seed).spawn(2)
    env = simpy.rt.RealtimeEnvironment(factor=1.0, strict=False)
    recorder = Recorder(trace=Trace())
    link = scenario.link
    station = GatewayStation()
    facts = gateway_link_facts(scenario, modem or None)
    gateway = GatewayNode(env, station, links, facts, stop, boot_params, FailsafeNotes(recorder))
    holder: dict[str, VehicleNode] = {}
    modems: dict[str, Any] = {}
    ledger = FrameLedger()
    poll_lateness: deque[int] = deque(maxlen=SAMPLES_KEPT)
    if hil is None:
        model = scenario_link_model(scenario, seed)
        recorder.link_state = LinkStateLog.of(model)
        medium = Medium(
            env, link.channel, np.random.default_rng(link_seed), recorder.trace, model=model
        )
        for outage in scenario.faults.link_outages:
            medium.add_outage(outage.start_s, outage.end_s)
            recorder.event(outage.start_s, "scenario", "outage", f"until {outage.end_s:g} s")
        modems["vehicle"] = medium.attach(
            "vehicle", lambda: holder["node"].vehicle.truth.position_ned_m
        )
        position = link.operator_position_ned_m
        modems["operator"] = medium.attach("operator", lambda: position)
    else:
        outages = [(o.start_s, o.end_s) for o in scenario.faults.link_outages]
        for role, peer in (("vehicle", "operator"), ("operator", "vehicle")):
            modems[role] = HilModem(
                env, role, peer, hil[role], trace=recorder.trace, ledger=ledger, outages=outages
            )
    node: VehicleNode | None = None
    probe: _ThrusterProbe | None = None
    stopped: KeyboardInterrupt | None = None
    failed: Exception | None = None
    start: float | None = None
    operator: OperatorNode | None = None
    try:
        rng = np.random.default_rng(vehicle_seed)
        node, probe = _vehicle_node(env, scenario, rng, modems["vehicle"], recorder, gateway, seed)
        holder["node"] = node
        operator = OperatorNode(
            env,
            station,
            modems["operator"],
            codec=link.codec,
            ipg=link.ipg_policy if link.mac == "token" else None,
            uplink_rate_hz=link.uplink_rate_hz,
            recorder=recorder,
            reply_odometry_s=node.reply_odometry_s,
            snapshot_period_s=link.snapshot_period_s,
        )
        env.process(node.run())
        env.process(operator.run())
        if hil is not None:
            env.process(run_poll(env, list(modems.values()), lateness_ns=poll_lateness))
        process = env.process(gateway.run())
        env.sync()  # start the clock now, after pybullet has loaded
        start = time.perf_counter()
        env.run(until=simpy.AnyOf(env, [process, env.timeout(duration)]))
    except BaseException as error:  # Ctrl-C or SIGTERM (also wrapped): keep what ran
        # an error part way (a control law of the user's) keeps what ran, unless nothing ran yet
        if (stopped := interrupt_of(error)) is None and (
            start is None or (failed := run_error(error)) is None
        ):
            raise
    finally:
        wall_s = 0.0 if start is None else time.perf_counter() - start
        if node is not None:
            node.vehicle.close()
        for gcs in links:
            gcs.close()
        for endpoint in (hil or {}).values():
            endpoint.close()
    reached = min(float(env.now), duration)
    energy = math.nan if node is None else node.energy_wh

    def reduce(failure: str | None) -> RunResult:
        """What ran, reduced; ``failure`` is the error's line when one ended it."""
        if failure is not None:
            recorder.event(reached, "testbed", "failed", failure)
        if hil is None:
            metrics = compute_metrics(
                scenario,
                seed,
                recorder,
                sim_s=reached,
                wall_s=wall_s,
                energy_wh=energy,
                payload_bytes={
                    "uplink": 0 if node is None else node.port.payload_bytes,
                    "downlink": 0 if operator is None else operator.port.payload_bytes,
                },
            )
            if node is not None and operator is not None:
                note_copies_lost_transmitting(metrics, node.port.modem, operator.port.modem)
        else:
            metrics = hil_metrics(
                scenario,
                seed,
                recorder,
                modems,
                ledger,
                duration_s=reached,
                wall_s=wall_s,
                vehicle_node=node,
                operator_node=operator,
                poll_s=0.001,
                modem=modem,
                lateness_ns=poll_lateness,
            )
        metrics["mavlink"] = gateway_metrics(gateway, probe, reached)
        return RunResult(scenario, seed, metrics, recorder, stopped, failure)

    return reduce_run(reduce, failed, reached, stopped)  # reduced whole, even on Ctrl-C now


def gateway_metrics(
    gateway: GatewayNode, probe: _ThrusterProbe | None, duration_s: float
) -> dict[str, Any]:
    """The ``mavlink`` section of a gateway run: the endpoint's counters
    (:func:`~testbed.run.mavlink_run.endpoint_section`), ``gcs_to_thruster_ms``,
    ``scheduler_lateness_ms`` and ``gateway_compute_ms`` (``p50``, ``p95``, ``max``, ``mean``,
    ``n``), ``state_age_s`` (``mean``, ``p50``, ``p95``, ``max``, ``n``: the reported state's
    age, every gateway period), ``frame_period_s`` (the gateway's) and ``gateway`` true."""
    section = endpoint_section(gateway.endpoint, gateway.links, duration_s)
    section["gateway"] = True
    section["gcs_to_thruster_ms"] = latency_summary_ms(() if probe is None else probe.latency_ns)
    section["scheduler_lateness_ms"] = latency_summary_ms(gateway.lateness_ns)
    section["gateway_compute_ms"] = latency_summary_ms(gateway.compute_ns)
    ages = [a for a in gateway.state_age_s if math.isfinite(a)]
    section["state_age_s"] = summary(ages)
    section["frame_period_s"] = GATEWAY_PERIOD_S
    return section
