"""One run, wired: scenario → environment, link, nodes, recorder → metrics and output files.

:func:`run_scenario` makes one ``SeedSequence(seed)`` and spawns a generator for each random
subsystem (the link's bit errors, the vehicle's sensors and current), builds one simpy
``Environment``, the medium with both modems, the vehicle node and the operator node, schedules
the scenario's faults, runs for the scenario's duration and reduces the recording to metrics
(:func:`compute_metrics`); :func:`testbed.run.outputs.write_run` writes ``metrics.json``,
``events.csv``, ``series.csv`` and the plots. Same scenario and seed ⇒ the same ``metrics.json``
byte for byte, apart from ``wall_s`` and ``rtf``.
"""

from __future__ import annotations

import contextlib
import dataclasses
import gc
import math
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from functools import partial
from typing import Any

import numpy as np
import simpy

from testbed.channel import Medium, Trace, direction_counts
from testbed.common.components import ControlMode, MissionStatus
from testbed.ecs import Phase
from testbed.operator.pilots import PURE_PILOTS, Pilot, SampleHold
from testbed.operator.station import OperatorStation, SessionPlan
from testbed.run.images import image_console, image_metrics, image_source_factory
from testbed.run.interrupts import interrupt_of
from testbed.run.metrics import (
    SIGNAL_LAG_WINDOW_S,
    age_of_information,
    distribution,
    error_statistics,
    position_error,
    settling_time_s,
    signal_lag_s,
    summary,
    tracked_positions,
    yaw_error_deg,
)
from testbed.run.nodes import FRAME_OVERHEAD, LinkModem, OperatorNode, VehicleNode
from testbed.run.recorder import Recorder, VehicleObserver, failsafe_engagements
from testbed.run.scenario import Scenario
from testbed.vehicle.autonomy import Autonomy
from testbed.vehicle.localization import KalmanLocalizer, Navigation
from testbed.vehicle.vehicle import Vehicle

__all__ = [
    "RunResult",
    "compute_metrics",
    "goals_acked",
    "make_operator_node",
    "make_vehicle_node",
    "mission_metrics",
    "observed_pilot",
    "run_scenario",
    "stick_tracking",
    "tally_images",
]

_MODES = {
    "manual": ControlMode.MANUAL,
    "stabilize": ControlMode.STABILIZE,
    "depth_hold": ControlMode.DEPTH_HOLD,
}
_ORDER_PAYLOAD_BYTES = 7
"""A ``Move`` order's payload [B] (2-byte header + 5-byte body): the IPG rules size on it."""


@dataclass(frozen=True, slots=True)
class RunResult:
    """One finished run.

    Attributes:
        scenario: what was run.
        seed: the seed used.
        metrics: the ``metrics.json`` content.
        recorder: everything recorded (for plots and further analysis).
        stopped: the interrupt (Ctrl-C, or SIGTERM raised as a ``KeyboardInterrupt``
            subclass) that ended the run before its end, or None; the metrics then cover
            the ``sim_s`` reached.
    """

    scenario: Scenario
    seed: int
    metrics: dict[str, Any]
    recorder: Recorder
    stopped: KeyboardInterrupt | None = None


def make_vehicle_node(
    env: simpy.Environment,
    scenario: Scenario,
    rng: np.random.Generator,
    modem: LinkModem,
    recorder: Recorder,
    *,
    pilot: Pilot | None = None,
) -> VehicleNode:
    """The scenario's vehicle node on ``modem`` (simulated or HIL), with its thruster faults
    scheduled. ``rng`` feeds the vehicle's sensors and current; ``pilot`` is what the recorder
    samples for the ``cmd_*`` columns (default: the scenario's, a pure function of time)."""
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
    observer = VehicleObserver(
        recorder,
        scenario.pilot.pilot() if pilot is None else pilot,
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
    pilot: Pilot | None = None,
) -> OperatorNode:
    """The scenario's operator node on ``modem`` (simulated or HIL). ``reply_odometry_s`` is
    the vehicle node's map of reply frame → odometry sample time (recording only; empty when
    the vehicle runs elsewhere); ``pilot`` replaces the scenario's."""
    link = scenario.link
    token = link.mac == "token"
    plan = SessionPlan(
        mode=_MODES[scenario.operator.mode],
        arm_at_s=scenario.operator.arm_at_s,
        depth_m=scenario.operator.depth_m,
        precision=scenario.operator.precision,
    )
    return OperatorNode(
        env,
        OperatorStation(scenario.pilot.pilot() if pilot is None else pilot, plan),
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
    """``(the operator's pilot, the recorder's view of it)``: a packaged pilot
    (:data:`~testbed.operator.pilots.PURE_PILOTS`, a pure function of time) both times, as the
    recorder may sample it again; any other pilot through a
    :class:`~testbed.operator.pilots.SampleHold`, so that only the operator samples it (its
    state, if it keeps any, advances at the operator's frames alone) and the recorder sees the
    operator's samples, held between frames."""
    if isinstance(pilot, PURE_PILOTS):
        return pilot, pilot
    hold = SampleHold(pilot)
    return hold, hold.held


VehicleSetup = Callable[[Vehicle], None]
"""A user's hook on the built vehicle (:func:`run_scenario`'s ``vehicle_setup``)."""


def run_scenario(
    scenario: Scenario,
    *,
    seed: int | None = None,
    pilot: Pilot | None = None,
    vehicle_setup: VehicleSetup | None = None,
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
            navigation or an autonomy), add a system to ``vehicle.schedule`` (an observer of
            its world, a disturbance), read ``vehicle.config``. It may not step the vehicle,
            replace its world or entity, or reach the link, the operator or the recorder. Keep
            runs repeatable: any randomness from generators you seed yourself (the run's own
            generators are not handed out), and no wall-clock time.

    Returns:
        The metrics and the recording.
    """
    seed = scenario.seed if seed is None else seed
    operator_pilot, recorded_pilot = observed_pilot(
        scenario.pilot.pilot() if pilot is None else pilot
    )
    link_seed, vehicle_seed = np.random.SeedSequence(seed).spawn(2)
    env = simpy.Environment()
    recorder = Recorder(trace=Trace())
    link = scenario.link
    medium = Medium(env, link.channel, np.random.default_rng(link_seed), recorder.trace)
    for outage in scenario.faults.link_outages:
        medium.add_outage(outage.start_s, outage.end_s)
        recorder.event(outage.start_s, "scenario", "outage", f"until {outage.end_s:g} s")

    holder: dict[str, VehicleNode] = {}
    vehicle_modem = medium.attach("vehicle", lambda: holder["node"].vehicle.truth.position_ned_m)
    rng = np.random.default_rng(vehicle_seed)
    vehicle_node = make_vehicle_node(
        env, scenario, rng, vehicle_modem, recorder, pilot=recorded_pilot
    )
    holder["node"] = vehicle_node
    if vehicle_setup is not None:
        try:
            vehicle_setup(vehicle_node.vehicle)
        except BaseException:
            vehicle_node.vehicle.close()
            raise
    position = link.operator_position_ned_m
    operator_modem = medium.attach("operator", lambda: position)
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
    try:
        with long_lived_frozen():
            env.run(until=scenario.duration_s)
    except BaseException as error:  # an interrupt: keep what ran (the caller writes it, marked)
        if (stopped := interrupt_of(error)) is None:
            raise
    finally:
        vehicle.close()
    wall_s = time.perf_counter() - start
    tally_images(recorder, vehicle_node, operator_node)
    metrics = compute_metrics(
        scenario,
        seed,
        recorder,
        sim_s=scenario.duration_s if stopped is None else float(env.now),
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
    )
    return RunResult(scenario, seed, metrics, recorder, stopped)


def goals_acked(operator: OperatorNode) -> int | None:
    """The goals the operator's teleop end saw acknowledged (``counters.goals_acked``), or
    None when its link has no such counter (the change-set codec, an older teleop end)."""
    teleop = getattr(operator.link, "teleop", None)
    value = getattr(getattr(teleop, "counters", None), "goals_acked", None)
    return value if isinstance(value, int) and not isinstance(value, bool) else None


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


def _link_direction(
    trace: Trace,
    src: str,
    dst: str,
    decoded: int,
    payload_bytes: int,
    frame_bytes: int,
    sim_s: float,
) -> dict[str, Any]:
    """Per-direction frame counts from the trace (:func:`testbed.channel.direction_counts`:
    a frame counts once, by its worst packet); delivered = frames the receiver decoded.

    ``mean_frame_bytes`` is the frames' own mean length (``frame_bytes`` over the frames sent),
    the length bit errors act on; ``mean_on_air_bytes`` adds the modem's packet padding.

    ``per`` = 1 − delivered / settled, over the frames whose every packet had reached the
    receiver (or been lost) when the run ended: a frame still queued or on the air at the end
    is neither delivered nor lost, and a frame the sender's FIFO dropped was never on the air
    (``drop_rate`` = dropped / sent counts those).
    """
    counts = direction_counts(trace.events, src, dst)
    return {
        "frames_sent": counts.frames_sent,
        "frames_delivered": decoded,
        "frames_corrupted": counts.frames_corrupted,
        "frames_collided": counts.frames_collided,
        "frames_dropped": counts.frames_dropped,
        "frames_outage": counts.frames_outage,
        "frames_out_of_range": counts.frames_out_of_range,
        "per": 1.0 - decoded / counts.frames_settled if counts.frames_settled else math.nan,
        "drop_rate": counts.frames_dropped / counts.frames_sent if counts.frames_sent else math.nan,
        "goodput_bps": 8.0 * payload_bytes / sim_s if sim_s > 0.0 else math.nan,
        "mean_frame_bytes": frame_bytes / counts.frames_sent if counts.frames_sent else math.nan,
        "mean_on_air_bytes": counts.mean_on_air_bytes,
    }


def compute_metrics(
    scenario: Scenario,
    seed: int,
    recorder: Recorder,
    *,
    sim_s: float,
    wall_s: float,
    energy_wh: float,
    payload_bytes: dict[str, int],
    mission_status: MissionStatus | None = None,
    goals_acked: int | None = None,
    autonomy: Autonomy | None = None,
    navigation: Navigation | None = None,
) -> dict[str, Any]:
    """Reduce a recording to the ``metrics.json`` content (README: "metrics.json").

    ``mission_status`` (the vehicle's :class:`MissionStatus` at the end), ``goals_acked``
    (:func:`goals_acked`) and the vehicle's ``autonomy`` resource at the end feed, with the
    recorder's ``mission_reached`` events, the ``"mission"`` key of a vehicle under autonomy
    (:func:`mission_metrics`); None = not known here (null in the file). The vehicle's
    ``navigation`` resource at the end, when it has one, is the ``"navigation"`` key
    (:func:`navigation_metrics`).
    """
    series = recorder.series()
    t = series["t_s"]
    settle = scenario.metrics.settle_s
    after = t >= settle
    link = scenario.link
    ipg_s = (
        link.ipg_policy.gap_after(_ORDER_PAYLOAD_BYTES + FRAME_OVERHEAD)
        if link.mac == "token"
        else math.nan
    )
    sampled_s = recorder.commands_sampled
    commands = [  # (applied, sampled) [s] of each delivered pilot command
        (applied, sampled_s[seq])
        for seq, applied in sorted(recorder.commands_applied.items())
        if seq in sampled_s
    ]
    if not commands:  # change-set codec: the sample time travels with the command
        commands = list(recorder.command_updates)
    lags = [applied - sampled for applied, sampled in commands if applied >= settle]
    signal, rmse = stick_tracking(
        series,
        after,
        under_autonomy=scenario.vehicle.autonomy is not None,
        max_lag_s=link.signal_lag_window_s,
    )
    attitude = {}
    for axis in ("roll", "pitch", "yaw"):
        values = series[f"err_{axis}_deg"][after]
        attitude[axis] = distribution(values[~np.isnan(values)])
    if sim_s > settle:
        command_age = age_of_information(recorder.command_updates, settle, sim_s)
        odometry_age = age_of_information(recorder.odometry_updates, settle, sim_s)
    else:  # a run ended early, before its settling time: nothing to average
        command_age = odometry_age = {"mean": math.nan, "p95": math.nan}
    metrics: dict[str, Any] = {
        "scenario": scenario.id,
        "inputs": {  # what ran: enough to run it again
            "source": scenario.source,
            "overrides": list(scenario.overrides),
            "files": dict(scenario.files),
        },
        "seed": seed,
        "sim_s": sim_s,
        "wall_s": wall_s,
        "rtf": sim_s / wall_s if wall_s > 0 else math.inf,
        "link": {
            "uplink": _link_direction(
                recorder.trace,
                "operator",
                "vehicle",
                recorder.frames_decoded["uplink"],
                payload_bytes["uplink"],
                recorder.frame_bytes_sent["uplink"],
                sim_s,
            ),
            "downlink": _link_direction(
                recorder.trace,
                "vehicle",
                "operator",
                recorder.frames_decoded["downlink"],
                payload_bytes["downlink"],
                recorder.frame_bytes_sent["downlink"],
                sim_s,
            ),
        },
        "ipg_s": ipg_s,
        "command_lag_s": summary(lags),
        "command_age_s": command_age,
        "signal_lag_s": signal,
        "odometry_age_s": odometry_age,
        "velocity_tracking_rmse": rmse,
        "attitude_error_deg": attitude,
        "energy_wh": energy_wh,
        "frames_rejected": dict(recorder.frames_rejected),
        "events": {
            "failsafe": failsafe_engagements(recorder.events),
            "thruster_fault": sum(1 for e in recorder.events if e.kind == "thruster_fault"),
        },
    }
    if scenario.images.enabled:
        metrics["images"] = image_metrics(recorder.images, sim_s)
    autonomy_config = scenario.vehicle.autonomy
    if autonomy_config is not None:
        metrics["mission"] = mission_metrics(
            series,
            settle,
            autonomy_config.tree.goal_tolerance_m,
            status=mission_status,
            orders_acknowledged=goals_acked,
            goals_refused=None if autonomy is None else autonomy.refused,
            ready_s=None if autonomy is None else autonomy.ready_s,
            ready_sigma_m=autonomy_config.ready_sigma_m,
            reached_s=[e.t_s for e in recorder.events if e.kind == "mission_reached"],
        )
    if navigation is not None:
        metrics["navigation"] = navigation_metrics(navigation)
    return metrics


def navigation_metrics(navigation: Navigation) -> dict[str, Any]:
    """The ``"navigation"`` key of ``metrics.json`` (a vehicle with ``[vehicle.navigation]``):
    what the sources delivered and what the filter did with it.

    ``delivered``: measurements handed to the localizer, by source (``"depth"`` for the depth
    sensor). ``filter``: the default localizer's counters
    (:class:`~testbed.vehicle.estimation.FilterCounters`: ``accepted``, ``rejected`` by the χ²
    gate, ``invalid``, ``stale``, ``rollbacks``, ``reacquired``), ``by_source``: its
    ``accepted`` and ``rejected`` split by source, and ``gate_probability``: the gate's (the
    filter rejects about 1 − that of good measurements by chance); all None (null) for a
    localizer of one's own.
    """
    localizer = navigation.localizer
    filter_counts: dict[str, int] | None = None
    by_source: dict[str, dict[str, int]] | None = None
    gate: float | None = None
    if isinstance(localizer, KalmanLocalizer):
        gate = localizer.navigator.config.gate_probability
        filter_counts = dataclasses.asdict(localizer.navigator.counters)
        by_source = {
            name: {"accepted": accepted, "rejected": rejected}
            for name, (accepted, rejected) in localizer.navigator.source_counters.items()
        }
    return {
        "delivered": dict(sorted(navigation.delivered.items())),
        "filter": filter_counts,
        "by_source": by_source,
        "gate_probability": gate,
    }


_STICK_AXES = (("x", "u"), ("y", "v"), ("z", "w"), ("yaw", "r"))
"""The stick axes of the series (``cmd_*``, ``rx_*``) and the body velocity each asks for."""


def stick_tracking(
    series: dict[str, np.ndarray],
    after: np.ndarray,
    *,
    under_autonomy: bool,
    max_lag_s: float = SIGNAL_LAG_WINDOW_S,
) -> tuple[dict[str, float], dict[str, float]]:
    """``signal_lag_s`` and ``velocity_tracking_rmse`` of ``metrics.json``: how the sticks the
    vehicle applies follow the pilot's, and how its body velocity follows what they ask for.

    Both are taken over the armed rows at or after the settle time (``after``). Under autonomy
    the vehicle flies its mission and never the sticks (it records them centred: ``rx_*`` = 0,
    ``ref_*`` = 0), so there is nothing to track: every axis is NaN (null in the file), not the
    vehicle's RMS speed against a zero demand.

    Args:
        series: :meth:`Recorder.series` columns.
        after: (n,) bool, the rows at or after ``metrics.settle_s``.
        under_autonomy: the vehicle has ``[vehicle.autonomy]``.
        max_lag_s: the upper end of the lag's search [s] (the link's
            :attr:`~testbed.run.scenario.LinkSection.signal_lag_window_s`).

    Returns:
        ``(signal_lag_s, velocity_tracking_rmse)``, each keyed ``x``, ``y``, ``z``, ``yaw``:
        the lag [s] and the RMS velocity difference [m/s; rad/s for yaw], body FRD.
    """
    if under_autonomy:
        nothing = {axis: math.nan for axis, _ in _STICK_AXES}
        return nothing, dict(nothing)
    t = series["t_s"]
    flying = after & (series["armed"] > 0.5)
    signal = {
        axis: signal_lag_s(
            t[flying],
            series[f"cmd_{axis}"][flying],
            series[f"rx_{axis}"][flying],
            max_lag_s=max_lag_s,
        )
        if flying.sum() > 10
        else math.nan
        for axis, _ in _STICK_AXES
    }
    rmse = {
        axis: float(np.sqrt(np.mean((series[f"ref_{v}"][flying] - series[v][flying]) ** 2)))
        if flying.any()
        else math.nan
        for axis, v in _STICK_AXES
    }
    return signal, rmse


def mission_metrics(
    series: dict[str, np.ndarray],
    settle_s: float,
    tolerance_m: float,
    *,
    status: MissionStatus | None,
    orders_acknowledged: int | None,
    goals_refused: int | None = None,
    ready_s: float | None = None,
    ready_sigma_m: float | None = None,
    reached_s: Sequence[float] = (),
) -> dict[str, Any]:
    """The ``"mission"`` key of ``metrics.json`` (vehicles under autonomy).

    The error rows are those with a pose target, armed, at or after ``settle_s``; on rows
    with an end-effector target the target and the truth are the end effector's (``frame``:
    ``"end_effector"`` when any row has one, else ``"body"``). ``position_error_m``
    (``{mean, std, p95, final}`` of |truth − target| [m], 3-D) and
    ``estimate_error_m`` (``{mean, p95}`` of |estimate − truth| [m] on those rows that have an
    estimate); ``samples`` counts the rows. ``yaw_error_deg`` (``{mean, std, p95}`` of
    |wrap(ψ − ψ*)| [deg], the true heading against the pose target's, on those rows that have a
    pose target: none while an end-effector target is flown). ``final_target_s``: when the
    target arrived at its final value (the last waypoint's time, a GoTo leg's end) [s];
    ``time_to_converge_s``: from then until the error stays within the tree's goal tolerance to
    the last row [s], a duration (:func:`~testbed.run.metrics.settling_time_s`: 0 when the vehicle
    arrived with its target); both over every armed row with a target (the settle time does not
    cut them). ``completion_s``: when the tree last reported a goal reached [s], if the vehicle
    ended ready (no goal in progress), else NaN (the last goal was never reached).

    Args:
        series: :meth:`Recorder.series` columns.
        settle_s: rows before this time [s] are left out.
        tolerance_m: the mission tree's goal tolerance [m].
        status: the vehicle's mission status at the end (goals given and reached), or None.
        orders_acknowledged: goals the operator saw acknowledged, or None.
        goals_refused: the operator's goals the vehicle refused (above the surface), or None.
        ready_s: when the navigation estimate first was within ``ready_sigma_m`` [s] (the
            tree's first tick: nothing arms or flies before), None if never (NaN in the dict:
            null in the file).
        ready_sigma_m: the autonomy's ``ready_sigma_m`` [m] (reported beside ``ready_s``).
    """
    t = series["t_s"]
    body = np.column_stack([series["north_m"], series["east_m"], series["down_m"]])
    truth, target, reaching = tracked_positions(series)
    estimate = np.column_stack([series["est_n"], series["est_e"], series["est_d"]])
    flying = (series["armed"] > 0.5) & np.isfinite(target).all(axis=1)
    rows = (t >= settle_s) & flying
    error = position_error(truth[rows], target[rows])
    nav_error = position_error(estimate[rows], body[rows])
    nav_error = nav_error[np.isfinite(nav_error)]
    heading = yaw_error_deg(series["yaw_deg"][rows], series["target_yaw_deg"][rows])
    settling, arrival = settling_time_s(t[flying], truth[flying], target[flying], tolerance_m)
    return {
        "frame": "end_effector" if reaching else "body",
        "goal_tolerance_m": tolerance_m,
        "samples": int(np.count_nonzero(rows)),
        "position_error_m": error_statistics(error),
        "yaw_error_deg": distribution(heading[np.isfinite(heading)]),
        "time_to_converge_s": settling,
        "final_target_s": arrival,
        "completion_s": (
            reached_s[-1] if reached_s and status is not None and status.ready else math.nan
        ),
        "estimate_error_m": {
            "mean": float(nav_error.mean()) if nav_error.size else math.nan,
            "p95": float(np.percentile(nav_error, 95)) if nav_error.size else math.nan,
        },
        "goals": None if status is None else status.goals,
        "goals_reached": None if status is None else status.reached,
        "orders_acknowledged": orders_acknowledged,
        "goals_refused": goals_refused,
        "ready_s": math.nan if ready_s is None else ready_s,
        "ready_sigma_m": math.nan if ready_sigma_m is None else ready_sigma_m,
    }
