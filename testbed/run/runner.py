"""One run, wired: scenario → environment, link, nodes, recorder → metrics and output files.

:func:`run_scenario` makes one ``SeedSequence(seed)`` and spawns a generator for each random
subsystem (the link's bit errors, the vehicle's sensors and current), builds one simpy
``Environment``, the medium with both modems, the vehicle node and the operator node, schedules
the scenario's faults, runs for the scenario's duration and reduces the recording to metrics
(:func:`~testbed.run.run_metrics.compute_metrics`); :func:`testbed.run.outputs.write_run`
writes ``metrics.json``, ``events.csv``, ``series.csv`` and the plots. Same scenario and seed ⇒
the same ``metrics.json`` byte for byte, apart from ``wall_s`` and ``rtf``.
"""

from __future__ import annotations

import contextlib
import gc
import math
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from functools import partial
from typing import Any

import numpy as np
import simpy

from testbed.channel import Medium, Modem, Trace
from testbed.channel.model import LinkModel, model_name
from testbed.common.components import MissionStatus
from testbed.ecs import Phase
from testbed.operator.pilots import PURE_PILOTS, Pilot, SampleHold, is_pure
from testbed.operator.station import OperatorStation, SessionPlan
from testbed.operator.user_pilots import UserPilot
from testbed.run.failures import reduce_run, run_error
from testbed.run.images import image_console, image_source_factory
from testbed.run.interrupts import deferred_interrupts, interrupt_of
from testbed.run.link_log import LinkStateLog
from testbed.run.nodes import LinkModem, OperatorNode, VehicleNode
from testbed.run.observer import VehicleObserver
from testbed.run.plugin_calls import scenario_control_laws, scenario_link_model, scenario_pilot
from testbed.run.recorder import Recorder
from testbed.run.run_metrics import compute_metrics, plain_args
from testbed.run.scenario_config import Scenario
from testbed.vehicle.autonomy import Autonomy
from testbed.vehicle.localization import Navigation
from testbed.vehicle.resources import Controllers
from testbed.vehicle.vehicle import Vehicle

__all__ = [
    "RunResult",
    "goals_acked",
    "make_operator_node",
    "make_vehicle_node",
    "note_copies_lost_transmitting",
    "observed_pilot",
    "run_pilots",
    "run_scenario",
    "tally_images",
]


@dataclass(frozen=True, slots=True)
class RunResult:
    """One finished run.

    Attributes:
        scenario: what was run.
        seed: the seed used.
        metrics: the ``metrics.json`` content as computed: NaN where the file has ``null``
            (:func:`~testbed.run.outputs.write_run` converts them).
        recorder: everything recorded (for plots and further analysis).
        stopped: the interrupt (Ctrl-C, or SIGTERM raised as a ``KeyboardInterrupt``
            subclass) that ended the run before its end, or None; the metrics then cover
            the ``sim_s`` reached.
        failure: for what ran before an error ended the run (:mod:`testbed.run.failures`),
            that error in one line; None otherwise. The metrics cover the ``sim_s`` reached.
    """

    scenario: Scenario
    seed: int
    metrics: dict[str, Any]
    recorder: Recorder
    stopped: KeyboardInterrupt | None = None
    failure: str | None = None


def make_vehicle_node(
    env: simpy.Environment,
    scenario: Scenario,
    rng: np.random.Generator,
    modem: LinkModem,
    recorder: Recorder,
    *,
    pilot: Pilot,
    seed: int,
) -> VehicleNode:
    """The scenario's vehicle node on ``modem`` (simulated or HIL), with its thruster faults
    scheduled. ``rng`` feeds the vehicle's sensors and current; ``pilot`` is what the recorder
    samples for the ``cmd_*`` columns (:func:`observed_pilot`'s second). The holds of the
    user's own that ``[vehicle.control]`` names are made for it afresh, for a run of seed
    ``seed`` (:func:`~testbed.run.plugin_calls.scenario_control_laws`: a factory that fails stops it
    before the vehicle is built).

    Raises:
        ConfigError: a control law's factory failed or made no law.
    """
    depth_law, attitude_law = scenario_control_laws(scenario, seed)
    link = scenario.link
    factory = partial(Vehicle, scenario.vehicle, rng)
    node = VehicleNode(
        env,
        factory,
        modem,
        codec=link.codec,
        token=link.mac == "token",
        downlink_rate_hz=link.downlink_rate_hz,
        recorder=recorder,
        snapshot_period_s=link.snapshot_period_s,
        image_source=image_source_factory(scenario.images) if scenario.images.enabled else None,
    )
    vehicle = node.vehicle
    vehicle.controllers.depth_law, vehicle.controllers.attitude_law = depth_law, attitude_law
    observer = VehicleObserver(
        recorder,
        pilot,
        vehicle.reference_velocity,
        scenario.metrics.sample_rate_hz,
    )
    vehicle.schedule.add(Phase.POST_UPDATE, observer, name="record_vehicle")
    for fault in scenario.faults.thrusters:

        def fail(_: simpy.Event, fault: Any = fault) -> None:
            vehicle.fail_thruster(fault.thruster, fault.mode, fault.value)
            recorder.event(env.now, "vehicle", "thruster_fault", f"{fault.thruster} {fault.mode}")

        env.timeout(fault.t_s).callbacks.append(fail)
    return node


def make_operator_node(
    env: simpy.Environment,
    scenario: Scenario,
    modem: LinkModem,
    recorder: Recorder,
    reply_odometry_s: dict[int, float],
    *,
    pilot: Pilot,
) -> OperatorNode:
    """The scenario's operator node on ``modem`` (simulated or HIL). ``reply_odometry_s`` is
    the vehicle node's map of reply frame → odometry sample time (recording only; empty when
    the vehicle runs elsewhere); ``pilot`` is the station's (:func:`observed_pilot`'s
    first)."""
    link = scenario.link
    token = link.mac == "token"
    plan = SessionPlan(
        mode=scenario.operator.control_mode,
        arm_at_s=scenario.operator.arm_at_s,
        depth_m=scenario.operator.depth_m,
        precision=scenario.operator.precision,
    )
    return OperatorNode(
        env,
        OperatorStation(pilot, plan),
        modem,
        codec=link.codec,
        ipg=link.ipg_policy if token else None,
        uplink_rate_hz=link.uplink_rate_hz,
        recorder=recorder,
        reply_odometry_s=reply_odometry_s,
        snapshot_period_s=link.snapshot_period_s,
        console=image_console(
            scenario.images, scenario.vehicle.camera.width_px * scenario.vehicle.camera.height_px
        ),
    )


@contextlib.contextmanager
def long_lived_frozen() -> Iterator[None]:
    """Keep every object alive on entry out of the cyclic garbage collector's passes until the
    exit (:func:`gc.freeze`, undone by :func:`gc.unfreeze`; both move whole generations, so
    they cost nothing).

    A run allocates containers steadily (link events, change sets), and every few thousand of
    them Python's collector makes a full pass over every tracked object of the process, the
    modules and compiled kernels included: ≈ 64 ms each, 3 in a 120-s ``tether-teleop-v1``
    (≈ 6 % of its wall time). Objects made during the run are still collected as before; what
    was alive at the start is left alone, as it lives through the run anyway.
    """
    gc.freeze()
    try:
        yield
    finally:
        gc.unfreeze()


def observed_pilot(pilot: Pilot) -> tuple[Pilot, Pilot]:
    """``(the operator's pilot, the recorder's view of it)``: a pilot that is a pure function of
    time (:func:`~testbed.operator.pilots.is_pure`: the packaged ones, or one that says so)
    both times, as the recorder may sample it again; any other pilot through a
    :class:`~testbed.operator.pilots.SampleHold`, so that only the operator samples it (its
    state, if it keeps any, advances at the operator's frames alone) and the recorder sees the
    operator's samples, held between frames. A pilot that is not a packaged one is called
    through a :class:`~testbed.operator.user_pilots.UserPilot` both times: an exception it
    raises, or a sample a run cannot fly, is a one-line
    :class:`~testbed.operator.pilots.PilotError` naming it, the call and its time.

    Raises:
        TypeError: ``pilot`` has no ``sample`` method (it is refused before anything runs).
    """
    if not callable(getattr(pilot, "sample", None)):
        raise TypeError(
            "pilot: expected an object with sample(t_s) -> PilotSample "
            f"(testbed.operator.pilots.Pilot), got {type(pilot).__name__}"
        )
    if type(pilot) in PURE_PILOTS:  # packaged: built from a checked scenario, not wrapped
        return pilot, pilot
    checked = UserPilot(pilot)  # the user's: what it raises or returns is a PilotError
    if is_pure(pilot):
        return checked, checked
    hold = SampleHold(checked)
    return hold, hold.held


def run_pilots(
    scenario: Scenario, seed: int, recorder: Recorder, pilot: Pilot | None = None
) -> tuple[Pilot, Pilot]:
    """``(the operator's pilot, the recorder's view of it)`` for a run of seed ``seed``
    (:func:`observed_pilot` of ``pilot``, or of the scenario's own made afresh), the recorder
    told when it sees the operator's samples rather than the pilot itself."""
    operator, recorded = observed_pilot(scenario_pilot(scenario, seed) if pilot is None else pilot)
    if recorded is not operator:
        recorder.stick_source = "operator samples"
    return operator, recorded


VehicleSetup = Callable[[Vehicle], None]
"""A user's hook on the built vehicle (:func:`run_scenario`'s ``vehicle_setup``)."""


def run_scenario(
    scenario: Scenario,
    *,
    seed: int | None = None,
    pilot: Pilot | None = None,
    vehicle_setup: VehicleSetup | None = None,
    link_model: LinkModel | None = None,
) -> RunResult:
    """Simulate ``scenario`` once.

    Args:
        scenario: the loaded scenario.
        seed: overrides the scenario's seed.
        pilot: replaces the scenario's pilot (``[pilot]`` is then unused): any object with
            ``sample(t_s) -> PilotSample`` (:class:`~testbed.operator.pilots.Pilot`). The
            operator station samples it once per operator frame, at increasing times; it may
            keep state. Unless it is a packaged pilot, the recorder does not call it: the
            ``cmd_*`` columns hold the operator's samples between frames. The same object is
            used as is, so give each run a fresh one if it keeps state.
        vehicle_setup: called once with the built
            :class:`~testbed.vehicle.vehicle.Vehicle` before its first frame (the recorder's
            system is already on its schedule). It may change the vehicle's own parts: put a
            :class:`~testbed.vehicle.localization.Localizer` or a
            :class:`~testbed.vehicle.nav_sensors.NavSource` in its
            :class:`~testbed.vehicle.localization.Navigation` resource
            (``vehicle.world.resource(Navigation)``, present when the vehicle has a
            navigation or an autonomy), fly the depth or attitude hold with a law of the
            user's (``vehicle.controllers.depth_law``/``attitude_law``,
            :mod:`testbed.vehicle.control_laws`; it replaces one ``[vehicle.control]`` names,
            and ``inputs.depth_law``/``attitude_law`` then name its class), add a system to
            ``vehicle.schedule`` (an observer of its world, a disturbance: it runs last in its
            phase, in UPDATE after the allocation), read ``vehicle.config``. It may not step
            the vehicle, replace its world or entity, or reach the link, the operator or the
            recorder. Keep runs repeatable: any randomness from generators you seed
            yourself (the run's own generators are not handed out), and no wall-clock time.
        link_model: a link model of your own for the scenario's link
            (:class:`~testbed.channel.model.LinkModel`: the air time of a transmission and a
            receiver's bit errors; the scenario's ``[link]`` keeps the rest: MAC, delays,
            range, buffers); replaces the scenario's ``link.model``. Recorded as
            ``inputs.link_model`` in the metrics (its class, or the scenario's target).

    Returns:
        The metrics and the recording.
    """
    seed = scenario.seed if seed is None else seed
    recorder = Recorder(trace=Trace())
    operator_pilot, recorded_pilot = run_pilots(scenario, seed, recorder, pilot)
    model = scenario_link_model(scenario, seed) if link_model is None else link_model
    recorder.link_state = LinkStateLog.of(model)
    link_seed, vehicle_seed = np.random.SeedSequence(seed).spawn(2)
    env = simpy.Environment()
    link = scenario.link
    medium = Medium(
        env, link.channel, np.random.default_rng(link_seed), recorder.trace, model=model
    )
    for outage in scenario.faults.link_outages:
        medium.add_outage(outage.start_s, outage.end_s)
        recorder.event(outage.start_s, "scenario", "outage", f"until {outage.end_s:g} s")

    holder: dict[str, VehicleNode] = {}
    vehicle_modem = medium.attach("vehicle", lambda: holder["node"].vehicle.truth.position_ned_m)
    rng = np.random.default_rng(vehicle_seed)
    vehicle_node = make_vehicle_node(
        env, scenario, rng, vehicle_modem, recorder, pilot=recorded_pilot, seed=seed
    )
    holder["node"] = vehicle_node
    controllers = vehicle_node.vehicle.controllers
    scenario_laws = (controllers.depth_law, controllers.attitude_law)
    position = link.operator_position_ned_m
    try:
        if vehicle_setup is not None:
            vehicle_setup(vehicle_node.vehicle)
        operator_modem = medium.attach("operator", lambda: position)  # the model's error_model
    except BaseException:
        vehicle_node.vehicle.close()
        raise
    operator_node = make_operator_node(
        env,
        scenario,
        operator_modem,
        recorder,
        vehicle_node.reply_odometry_s,
        pilot=operator_pilot,
    )
    vehicle = vehicle_node.vehicle
    env.process(vehicle_node.run())
    env.process(operator_node.run())
    start = time.perf_counter()
    stopped: KeyboardInterrupt | None = None
    failed: Exception | None = None
    try:
        with long_lived_frozen():
            env.run(until=scenario.duration_s)
    except BaseException as error:  # keep what ran (the caller writes it, marked)
        if (stopped := interrupt_of(error)) is None and (failed := run_error(error)) is None:
            vehicle.close()  # GeneratorExit: not a run's
            raise
    wall_s = time.perf_counter() - start

    def reduce(failure: str | None) -> RunResult:
        """What ran, reduced; ``failure`` is the error's line when one ended it."""
        if failure is not None:
            recorder.event(float(env.now), "testbed", "failed", failure)
        early = stopped is not None or failure is not None
        metrics = _run_metrics(
            scenario, seed, recorder, vehicle_node, operator_node, wall_s, env.now, early
        )
        note_copies_lost_transmitting(metrics, vehicle_modem, operator_modem)
        inputs = metrics["inputs"]
        if pilot is not None:  # the scenario's [pilot] did not fly: name what did
            inputs["pilot"] = {"object": model_name(pilot)}
        flown = (controllers.depth_law, controllers.attitude_law)
        for name, law, own in zip(("depth_law", "attitude_law"), flown, scenario_laws, strict=True):
            if law is not own:  # vehicle_setup put a law of its own (or the packaged PID) in
                inputs.pop(name, None)
                if law is not None:
                    inputs[name] = {"object": model_name(law)}
        if link_model is not None:
            inputs["link_model"] = model_name(link_model)
            # the closed form knows the preset's bit rate only, not the model's air time
            metrics["token_round_trip_s"], metrics["reply_fits_gap"] = math.nan, None
        elif model is not None:
            inputs["link_model"] = scenario.link.model
            inputs["link_model_args"] = plain_args(scenario.link.model_args)
        return RunResult(scenario, seed, metrics, recorder, stopped, failure)

    with deferred_interrupts() as closing:  # what ran is reduced whole, even on Ctrl-C now
        vehicle.close()
        tally_images(recorder, vehicle_node, operator_node)
    stopped = stopped or (closing[0] if closing else None)
    return reduce_run(reduce, failed, float(env.now), stopped)


def _run_metrics(
    scenario: Scenario,
    seed: int,
    recorder: Recorder,
    vehicle_node: VehicleNode,
    operator_node: OperatorNode,
    wall_s: float,
    now_s: float,
    early: bool,
) -> dict[str, Any]:
    """:func:`compute_metrics` of a simulated run that reached ``now_s`` [s] (its end unless
    it ended ``early``: an interrupt or an error)."""
    vehicle = vehicle_node.vehicle
    return compute_metrics(
        scenario,
        seed,
        recorder,
        sim_s=float(now_s) if early else scenario.duration_s,
        wall_s=wall_s,
        energy_wh=vehicle_node.energy_wh,
        payload_bytes={
            "uplink": vehicle_node.port.payload_bytes,
            "downlink": operator_node.port.payload_bytes,
        },
        mission_status=vehicle.world.get(vehicle.entity, MissionStatus),
        goals_acked=goals_acked(operator_node),
        autonomy=vehicle.world.resource(Autonomy) if vehicle.world.has_resource(Autonomy) else None,
        navigation=(
            vehicle.world.resource(Navigation) if vehicle.world.has_resource(Navigation) else None
        ),
        ignored_setpoints=vehicle.world.resource(Controllers).ignored_setpoints,
    )


def goals_acked(operator: OperatorNode) -> int | None:
    """The goals the operator's teleop end saw acknowledged (``counters.goals_acked``), or
    None when its link has no such counter (the change-set codec, an older teleop end)."""
    teleop = getattr(operator.link, "teleop", None)
    value = getattr(getattr(teleop, "counters", None), "goals_acked", None)
    return value if isinstance(value, int) and not isinstance(value, bool) else None


def note_copies_lost_transmitting(
    metrics: dict[str, Any], vehicle_modem: LinkModem, operator_modem: LinkModem
) -> None:
    """Add ``copies_lost_transmitting`` to ``metrics["link"]``'s directions: of the copies lost
    to collisions, those lost to the half-duplex receiver's own transmission (``deaf`` in the
    trace). Simulated modems only (:class:`~testbed.channel.Modem`; a serial one cannot tell)."""
    for direction, receiver in (("uplink", vehicle_modem), ("downlink", operator_modem)):
        if isinstance(receiver, Modem):
            metrics["link"][direction]["copies_lost_transmitting"] = receiver.counters.rx_deaf


def tally_images(
    recorder: Recorder, vehicle: VehicleNode | None, operator: OperatorNode | None
) -> None:
    """Copy the image transfer counters of both ends (those running here) into the image log."""
    log = recorder.images
    if vehicle is not None and vehicle.images is not None:
        sent = vehicle.images.sender.counters
        log.count("chunks_sent", sent.chunks_sent)
    if operator is not None and operator.console is not None:
        got = operator.console.assembler.counters
        log.count("chunks_received", operator.console.chunks_received)
        for key in ("crc_failures", "spoiled", "duplicates", "inconsistent"):
            log.count(key, getattr(got, key))
        log.count("settings_sent", operator.console.settings_sent)
        log.count("settings_acknowledged", operator.console.settings_acknowledged)
