"""A real ground station drives the simulated vehicle: the vehicle in real time, MAVLink its pilot.

:func:`run_mavlink` runs the scenario's vehicle (built as :func:`~testbed.run.runner.run_scenario`
builds it, thruster faults and the recorder's observer included) under
``simpy.rt.RealtimeEnvironment(strict=False)``, with a
:class:`~testbed.mavlink.VehicleEndpoint` as its pilot on one or more ground-station links
(:mod:`testbed.mavlink.links`: UDP, TCP, serial). There is no operator node and no narrow link:
the ground station is the operator, directly (the gateway through the narrow link is a later
step).

Each vehicle frame (:class:`MavlinkVehicleNode`): PRE_UPDATE drains every link's reader queue
into the endpoint (which writes the operator-owned intents on the vehicle's operator entity);
POST_UPDATE, after the thrusters were commanded, runs the endpoint's failsafes and telemetry and
hands its packets to the links. Nothing calls into simpy from a reader thread.

ArduSub's MOT_n_DIRECTION acts on the vehicle's thrusters (:func:`install_motor_directions`,
:mod:`testbed.mavlink.motors`): a system after the vehicle's allocation gives motor n's ESC the
pulse ArduSub's mixer would with that direction.

The vehicle's own stale-command failsafe (``vehicle.failsafe``) is switched off for the run
(its timeouts set to a day): ArduSub's FS_PILOT_* and FS_GCS_* parameters govern a MAVLink
vehicle instead (:mod:`testbed.mavlink.failsafe`).

Measured (``metrics.json`` ``mavlink``): ``gcs_to_thruster_ms`` — from the reader thread's read
of a datagram holding accepted pilot input to the end of the frame that commanded the thrusters
from it; ``scheduler_lateness_ms`` — how late each frame ran against its real-time schedule
(:func:`~testbed.run.wall_clock.rt_lateness_ns`); ``frame_compute_ms`` — each frame's own time
(ingest to publish). A packet read just after a frame drained its queue waits for the next
frame, so the latency's bound is two frame periods plus the frame's lateness and compute time,
whatever the machine's load. The recorder's command lag is the same path on the simulated clock
(arrival → applying frame); the ground station's own sampling instant is not on the wire.
"""

from __future__ import annotations

import dataclasses
import math
import threading
import time
from collections import Counter, deque
from collections.abc import Generator, Mapping, Sequence
from typing import Any

import numpy as np
import simpy
import simpy.rt

from testbed.channel import Trace
from testbed.common.components import ThrusterOutput
from testbed.ecs import Phase, World
from testbed.hil import latency_summary_ms
from testbed.mavlink import (
    EndpointOptions,
    PositionLoop,
    ServoOutputs,
    VehicleEndpoint,
    servo_outputs,
)
from testbed.mavlink.ardusub import sticks_from_rc
from testbed.mavlink.links import Intake, Link
from testbed.operator.pilots import PilotSample
from testbed.run.failures import reduce_run, run_error
from testbed.run.interrupts import interrupt_of
from testbed.run.observer import VehicleObserver
from testbed.run.plugin_calls import scenario_control_laws
from testbed.run.recorder import Recorder
from testbed.run.run_metrics import compute_metrics
from testbed.run.runner import RunResult
from testbed.run.scenario_config import Scenario
from testbed.run.wall_clock import SAMPLES_KEPT, rt_lateness_ns
from testbed.vehicle.guidance import PositionGains
from testbed.vehicle.resources import Actuation, Controllers, SimClock
from testbed.vehicle.thruster_config import ThrusterConfig
from testbed.vehicle.vehicle import Vehicle
from testbed.vehicle.vehicle_config import VehicleConfig

__all__ = [
    "EndpointPilot",
    "MavlinkVehicleNode",
    "endpoint_options",
    "endpoint_section",
    "install_motor_directions",
    "layout_servos",
    "mavlink_metrics",
    "mavlink_vehicle_config",
    "run_mavlink",
]

_DAY_S = 86400.0


class EndpointPilot:
    """The recorder's view of the pilot: the sticks the endpoint (the vehicle's, or the shore
    gateway's) last received from the ground station."""

    def __init__(self, endpoint: VehicleEndpoint) -> None:
        self._endpoint = endpoint

    def sample(self, t_s: float) -> PilotSample:
        del t_s
        return PilotSample(sticks_from_rc(self._endpoint.rc.channels))


def layout_servos(layout: ThrusterConfig) -> ServoOutputs:
    """The servo outputs of a thruster layout: ArduSub's motor numbering and MOT_n_DIRECTION
    for a layout that declares its ArduSub frame (``[ardusub]``), else each thruster on its
    ``pwm_channel`` (FRAME_CONFIG 7); :func:`~testbed.mavlink.motors.servo_outputs`.

    Raises:
        ConfigError: the layout's ArduSub numbering disagrees with ArduSub's factors.
    """
    frame = layout.ardusub
    return servo_outputs(
        None if frame is None else frame.frame_config,
        layout.ardusub_motor_columns,
        layout.matrix,
        layout.ccw_mask.tolist(),
        [t.pwm_channel for t in layout.thrusters],
        source=layout.name,
    )


def endpoint_options(
    config: VehicleConfig,
    layout: ThrusterConfig,
    boot_params: Mapping[str, float] | None = None,
) -> EndpointOptions:
    """How the endpoint presents a vehicle of ``config`` with thruster ``layout``: its supply
    voltage, ArduSub's servo numbering of the layout, and the boot parameters FRAME_CONFIG and
    MOT_n_DIRECTION (the layout's), BARO_SPEC_GRAV (the depth sensor's), then ``boot_params``
    (``--param``) over them; GUIDED's loops (its stopping point on entry, the leash of a
    moving target): the position loop's gain and top speed, the depth hold's kp/kd."""
    servos = layout_servos(layout)
    overrides = {
        **servos.param_overrides(),
        "BARO_SPEC_GRAV": config.sensors.depth.spec_grav,
        **(boot_params or {}),
    }
    loop, depth = PositionGains(), config.gains.depth  # the vehicle's GUIDED loops
    depth_gain = depth.kp / depth.kd if depth.kd > 0.0 else math.inf
    guided = PositionLoop(loop.kp_1_s, loop.max_speed_m_s, depth_gain)
    return EndpointOptions(config.supply_voltage_v, overrides, servos=servos, guided_loop=guided)


def install_motor_directions(vehicle: Vehicle, endpoint: VehicleEndpoint) -> None:
    """Make the endpoint's MOT_n_DIRECTION act on ``vehicle``'s thrusters: a system after the
    allocation (UPDATE, before the plant is actuated) gives each thruster whose motor's
    direction differs from the layout's the pulse ArduSub's mixer would
    (``1500 + clamp(factor · (pulse − 1500), ±400)``,
    :meth:`~testbed.mavlink.ServoOutputs.direction_factors`) and the T200's force and current for
    it. Not while disarmed (every pulse 1500) nor during a motor test, whose pulses ArduSub
    writes unmixed (``output_test_num``). With the layout's directions it changes nothing."""
    servos = endpoint.options.servos
    params = endpoint.params

    def direction(n: int) -> float | None:
        name = f"MOT_{n}_DIRECTION"
        return None if params.index_of(name) is None else params[name]

    def apply_motor_directions(world: World) -> None:
        factors = servos.direction_factors(direction)
        if not factors:
            return
        ctl = world.resource(Controllers)
        act = world.resource(Actuation)
        n = act.matrix.shape[1]
        if not ctl.flags.armed or len(ctl.thruster_test) == n:
            return
        out = world.get(ctl.vehicle, ThrusterOutput)
        if out is None:
            return
        pwm = np.asarray(out.pwm_us, dtype=np.float64)
        for thruster, factor in factors.items():
            if thruster < n:
                pwm[thruster] = 1500.0 + min(400.0, max(-400.0, factor * (pwm[thruster] - 1500.0)))
        t200 = act.allocator.t200
        forces = np.asarray(out.forces_n, dtype=np.float64)
        mixed = t200.forces_for_pwms(pwm, act.allocator.config.ccw_mask)
        for thruster in factors:
            if thruster < n:
                forces[thruster] = mixed[thruster]
        act.commanded_forces_n[:] = forces
        currents = t200.currents_for_forces(forces)
        world.set(
            ctl.vehicle,
            ThrusterOutput(
                tuple(forces.tolist()), tuple(pwm.tolist()), tuple(currents.tolist()), out.scale
            ),
        )

    vehicle.schedule.add(Phase.UPDATE, apply_motor_directions)


def mavlink_vehicle_config(config: VehicleConfig) -> VehicleConfig:
    """``config`` with its stale-command failsafe off (module docstring)."""
    failsafe = dataclasses.replace(
        config.failsafe, hold_after_s=_DAY_S - 1.0, surface_after_s=_DAY_S
    )
    return dataclasses.replace(config, failsafe=failsafe)


class MavlinkVehicleNode:
    """The vehicle with the endpoint as its pilot, in (real) simpy time.

    Args:
        env: the environment (real time in :func:`run_mavlink`; any in tests).
        scenario: the scenario (its vehicle, faults and metrics settings).
        rng: the vehicle's generator.
        links: the ground-station links (one endpoint channel each).
        recorder: ground-truth sink.
        stop: ends the node's process at the next frame once set (from any thread).
        boot_params: ArduSub parameters' values at boot (``--param``), over the layout's.
        seed: the run's seed, of the generators the scenario's control laws are given
            (:func:`~testbed.run.plugin_calls.scenario_control_laws`); None = the scenario's.
    """

    def __init__(
        self,
        env: simpy.Environment,
        scenario: Scenario,
        rng: np.random.Generator,
        links: Sequence[Link],
        recorder: Recorder,
        stop: threading.Event | None = None,
        boot_params: Mapping[str, float] | None = None,
        seed: int | None = None,
    ) -> None:
        self.env = env
        self._stop = stop
        self.recorder = recorder
        self._failsafes = FailsafeNotes(recorder)
        config = mavlink_vehicle_config(scenario.vehicle)
        law_seed = scenario.seed if seed is None else seed
        depth_law, attitude_law = scenario_control_laws(scenario, law_seed)  # before the vehicle
        self.vehicle = Vehicle(config, rng, inbound=(self._ingest,), outbound=(self._publish,))
        vehicle = self.vehicle
        vehicle.controllers.depth_law, vehicle.controllers.attitude_law = depth_law, attitude_law
        options = endpoint_options(config, vehicle.thruster_config, boot_params)
        self.endpoint = VehicleEndpoint(
            vehicle.world, vehicle.entity, vehicle.operator_entity, options
        )
        install_motor_directions(vehicle, self.endpoint)
        self.links = list(links)
        self.channels = [self.endpoint.open_channel(link.url) for link in self.links]
        self.intakes = [Intake(link.inbox) for link in self.links]
        observer = VehicleObserver(
            recorder,
            EndpointPilot(self.endpoint),
            vehicle.reference_velocity,
            scenario.metrics.sample_rate_hz,
            other_failsafe=lambda: self.endpoint.failsafe.active,  # the vehicle's own is off
        )
        vehicle.schedule.add(Phase.POST_UPDATE, observer, name="record_vehicle")
        for fault in scenario.faults.thrusters:

            def fail(_: simpy.Event, fault: Any = fault) -> None:
                vehicle.fail_thruster(fault.thruster, fault.mode, fault.value or None)
                recorder.event(
                    env.now, "vehicle", "thruster_fault", f"{fault.thruster} {fault.mode}"
                )

            env.timeout(fault.t_s).callbacks.append(fail)
        self.gcs_to_thruster_ns: deque[int] = deque(maxlen=SAMPLES_KEPT)
        self.lateness_ns: deque[int] = deque(maxlen=SAMPLES_KEPT)
        self.compute_ns: deque[int] = deque(maxlen=SAMPLES_KEPT)
        self._frame_reads: list[int] = []
        self._ingest_ns = 0

    def run(self, until_s: float = math.inf) -> Generator[simpy.Event, Any, None]:
        """simpy process: each vehicle frame at its own instant, physics in between, until
        ``until_s`` [s] or until ``stop`` is set (checked each frame)."""
        env = self.env
        vehicle = self.vehicle
        stop = self._stop
        while stop is None or not stop.is_set():
            t_frame = vehicle.next_frame_s
            if t_frame >= until_s:
                yield env.timeout(max(0.0, until_s - env.now))
                return
            if t_frame > env.now:
                yield env.timeout(t_frame - env.now)
            vehicle.advance(t_frame + 0.5 * vehicle.physics.dt_s)

    def _ingest(self, world: World) -> None:
        """PRE_UPDATE: the packets the links' reader threads queued, into the endpoint (up to
        :data:`~testbed.mavlink.links.INGEST_BYTES_PER_FRAME` a link; the rest next frame)."""
        now = world.resource(SimClock).time_s
        env = self.env
        if isinstance(env, simpy.rt.RealtimeEnvironment):
            self.lateness_ns.append(rt_lateness_ns(env))
        self._ingest_ns = start = time.perf_counter_ns()
        reads = self._frame_reads
        reads.clear()
        for intake, channel in zip(self.intakes, self.channels, strict=True):
            for received in intake.take():
                age_s = max(0.0, (start - received.read_ns) * 1e-9)
                arrived_s = now - age_s
                if self.endpoint.receive(channel, received.data, now, arrived_s, end=received.end):
                    reads.append(received.read_ns)
                    self.recorder.command_updates.append((now, arrived_s))

    def _publish(self, world: World) -> None:
        """POST_UPDATE: latency of this frame's pilot input; failsafes, telemetry, sending."""
        done = time.perf_counter_ns()
        self.gcs_to_thruster_ns.extend(done - read for read in self._frame_reads)
        self.compute_ns.append(done - self._ingest_ns)
        now = world.resource(SimClock).time_s
        self.endpoint.update(now)
        self._failsafes(self.endpoint.failsafe.triggered, now)
        for link, channel in zip(self.links, self.channels, strict=True):
            for packet in channel.take():
                link.send(packet)


class FailsafeNotes:
    """Records ``vehicle,ardusub_failsafe,<kind>`` in ``events.csv`` each time ArduSub's
    pilot-input or GCS failsafe acts (its trigger count for that kind went up).

    Args:
        recorder: where the events go.
    """

    def __init__(self, recorder: Recorder) -> None:
        self._recorder = recorder
        self._noted: Counter[str] = Counter()

    def __call__(self, triggered: Counter[str], now_s: float) -> None:
        """Note the kinds whose count rose since the last call, at ``now_s`` [s]."""
        if triggered != self._noted:
            for kind in sorted(triggered - self._noted):
                self._recorder.event(now_s, "vehicle", "ardusub_failsafe", kind)
            self._noted = triggered.copy()


def run_mavlink(
    scenario: Scenario,
    links: Sequence[Link],
    *,
    seed: int | None = None,
    duration_s: float | None = None,
    stop: threading.Event | None = None,
    boot_params: Mapping[str, float] | None = None,
) -> RunResult:
    """Run the scenario's vehicle in real time for ``duration_s`` [s] with the ground stations
    on ``links`` as its pilot; the links are closed when the run ends. ``stop``, once set from
    any thread, ends the run at the next frame (a complete run of the time reached).
    ``boot_params`` are ArduSub parameters' values at boot (``testbed mavlink --param``: what
    the vehicle reads once, at boot, such as SYSID_THISMAV and JS_GAIN_DEFAULT, too).

    Ctrl-C or SIGTERM (a ``KeyboardInterrupt``) ends it early: ``stopped`` is set and the
    metrics cover the ``sim_s`` reached.

    Raises:
        ValueError: no link, or a duration not > 0.
        Exception: an error that ended the run part way (a control law of the user's raising),
            carrying what ran (:func:`~testbed.run.failures.partial_run`).
    """
    duration = scenario.duration_s if duration_s is None else duration_s
    if not links or not (math.isfinite(duration) and duration > 0.0):
        for link in links:
            link.close()
        raise ValueError(f"need a link and a duration > 0 s, got {len(links)}, {duration}")
    seed = scenario.seed if seed is None else seed
    _, vehicle_seed = np.random.SeedSequence(seed).spawn(2)
    env = simpy.rt.RealtimeEnvironment(factor=1.0, strict=False)
    recorder = Recorder(trace=Trace())
    node: MavlinkVehicleNode | None = None
    stopped: KeyboardInterrupt | None = None
    failed: Exception | None = None
    start: float | None = None
    try:
        rng = np.random.default_rng(vehicle_seed)
        node = MavlinkVehicleNode(env, scenario, rng, links, recorder, stop, boot_params, seed)
        process = env.process(node.run(duration))
        env.sync()  # start the clock now, after pybullet has loaded
        start = time.perf_counter()
        env.run(until=process)  # the duration, or the stop event, whichever comes first
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
        for link in links:
            link.close()
    reached = float(env.now)  # the duration, unless interrupted or stopped

    def reduce(failure: str | None) -> RunResult:
        """What ran, reduced; ``failure`` is the error's line when one ended it."""
        if failure is not None:
            recorder.event(reached, "testbed", "failed", failure)
        metrics = compute_metrics(
            scenario,
            seed,
            recorder,
            sim_s=reached,
            wall_s=wall_s,
            energy_wh=math.nan if node is None else node.vehicle.power.energy_j / 3600.0,
            payload_bytes={"uplink": 0, "downlink": 0},
        )
        if node is not None:
            metrics["mavlink"] = mavlink_metrics(node, reached)
        return RunResult(scenario, seed, metrics, recorder, stopped, failure)

    return reduce_run(reduce, failed, reached, stopped)  # reduced whole, even on Ctrl-C now


def mavlink_metrics(node: MavlinkVehicleNode, duration_s: float) -> dict[str, Any]:
    """The ``mavlink`` section of ``metrics.json``.

    Keys: :func:`endpoint_section`'s; ``gcs_to_thruster_ms``, ``scheduler_lateness_ms`` and
    ``frame_compute_ms`` (``p50``, ``p95``, ``max``, ``mean``, ``n``; module docstring);
    ``frame_period_s``.
    """
    counters = endpoint_section(node.endpoint, node.links, duration_s)
    counters["gcs_to_thruster_ms"] = latency_summary_ms(node.gcs_to_thruster_ns)
    counters["scheduler_lateness_ms"] = latency_summary_ms(node.lateness_ns)
    counters["frame_compute_ms"] = latency_summary_ms(node.compute_ns)
    counters["frame_period_s"] = 1.0 / node.vehicle.config.control_rate_hz
    return counters


def endpoint_section(
    endpoint: VehicleEndpoint, links: Sequence[Link], duration_s: float
) -> dict[str, Any]:
    """An endpoint's counters for ``metrics.json``: ``received`` and ``sent`` by message type,
    ``accepted``, ``rejected`` by reason, ``pilot_inputs``, ``param_sets``, ``failsafes``,
    ``bytes_in``, ``bytes_out`` (:meth:`~testbed.mavlink.VehicleEndpoint.counters`);
    ``telemetry_hz`` (packets sent per second, by type); ``links`` (per URL: bytes and packets
    in and out, drops)."""
    counters: dict[str, Any] = endpoint.counters()
    sent: dict[str, int] = counters["sent"]
    counters["telemetry_hz"] = {
        name: count / duration_s if duration_s > 0 else math.nan for name, count in sent.items()
    }
    counters["links"] = {link.url: link.counters() for link in links}
    return counters
