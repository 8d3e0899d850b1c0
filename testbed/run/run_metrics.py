"""A run's recording reduced to ``metrics.json``: the link per direction, the command path,
stick tracking, attitude, the mission of a vehicle under autonomy and its navigation filter.

:func:`compute_metrics` is what :func:`~testbed.run.runner.run_scenario` (and a live session)
call at the end of a run; the statistics themselves (ages of information, lags, errors) are
:mod:`testbed.run.metrics`'. README: "metrics.json" lists every key.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

import testbed
from testbed.channel import Trace, direction_counts
from testbed.common.components import MissionStatus
from testbed.protocol import VEHICLE_HEADER_SIZE
from testbed.run.image_record import image_metrics
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
from testbed.run.nodes import FRAME_OVERHEAD
from testbed.run.recorder import Recorder, failsafe_engagements
from testbed.run.scenario_config import Scenario
from testbed.run.sections import LONGEST_ORDER_FRAME_BYTES, ORDER_FRAME_BYTES
from testbed.vehicle.autonomy import Autonomy
from testbed.vehicle.localization import KalmanLocalizer, Navigation

__all__ = [
    "CAPSIZE_DEG",
    "TokenCycle",
    "compute_metrics",
    "max_tilt",
    "mission_metrics",
    "navigation_metrics",
    "received_from_the_link",
    "stick_lag_s",
    "stick_tracking",
    "token_cycle",
]


@dataclass(frozen=True, slots=True)
class TokenCycle:
    """A token-passing teleop link's cycle against its gap rule (closed form, clean link).

    Attributes:
        order_frame_bytes: the order [B] whose cycle this is.
        gap_s: the master's gap after that order [s].
        round_trip_s: from the order's start to the end of its longest reply's arrival [s]
            (:meth:`~testbed.run.sections.LinkSection.token_round_trip_s`), at the distance
            between the operator's modem and the vehicle's start.
        reply_frame_bytes: the longest reply's frame [B] (the state, plus an image chunk when
            images are on).
    """

    order_frame_bytes: int
    gap_s: float
    round_trip_s: float
    reply_frame_bytes: int

    @property
    def fits(self) -> bool:
        """Whether each reply is in before the next order starts."""
        return self.round_trip_s <= self.gap_s

    def warning(self, ipg: str) -> str:
        """One line for a cycle that does not fit (what happens and what to set instead)."""
        return (
            f"link: a {self.order_frame_bytes}-B order and its {self.reply_frame_bytes}-B reply "
            f"take {self.round_trip_s:.3f} s, longer than the {ipg} gap of {self.gap_s:.3f} s: "
            "orders go out before replies are in (collisions in half duplex, image chunks "
            f"asked again); link.ipg = 'fixed' with link.ipg_s ≥ {self.round_trip_s:.3f} waits "
            "for each reply"
        )


def token_cycle(scenario: Scenario) -> TokenCycle | None:
    """The scenario's tightest :class:`TokenCycle` (a move order's or the longest order's,
    whichever leaves the least time to spare), or None for a link without token-passing
    teleop, or one whose air time is a model of the user's (``link.model``: the closed form
    knows only the preset's bit rate)."""
    link = scenario.link
    if link.mac != "token" or link.codec != "teleop" or link.model:
        return None
    chunk = scenario.images.chunk_bytes if scenario.images.enabled else 0
    reply_bytes = FRAME_OVERHEAD + VEHICLE_HEADER_SIZE + chunk
    distance_m = math.dist(scenario.vehicle.start_position_ned_m, link.operator_position_ned_m)
    cycles = [
        TokenCycle(
            order_frame_bytes=order_bytes,
            gap_s=link.ipg_policy.gap_after(order_bytes),
            round_trip_s=link.token_round_trip_s(order_bytes, reply_bytes, distance_m),
            reply_frame_bytes=reply_bytes,
        )
        for order_bytes in (ORDER_FRAME_BYTES, LONGEST_ORDER_FRAME_BYTES)
    ]
    return min(cycles, key=lambda cycle: cycle.gap_s - cycle.round_trip_s)


def _own_pilot(scenario: Scenario) -> dict[str, Any]:
    """``{"pilot": {"factory", "args"}}`` for a pilot of the user's own, else nothing."""
    pilot = scenario.pilot
    if pilot.kind != "python":
        return {}
    return {"pilot": {"factory": pilot.factory, "args": plain_args(pilot.args)}}


def _own_control_laws(scenario: Scenario) -> dict[str, Any]:
    """``{"depth_law": {"factory", "args"}, "attitude_law": ...}`` for the holds of the
    user's own that ``[vehicle.control]`` names (neither: nothing)."""
    laws = scenario.control_laws
    return {
        f"{name}_law": {"factory": target, "args": plain_args(getattr(laws, f"{name}_args"))}
        for name, target in laws.targets().items()
    }


def plain_args(args: dict[str, Any]) -> dict[str, Any]:
    """A factory's keyword arguments as JSON holds them (a TOML date as its text)."""
    plain: dict[str, Any] = json.loads(json.dumps(args, default=str))
    return plain


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

    ``frames_corrupted`` = settled − delivered − collided − outage − out of range: the frames
    lost to bit errors (the receiver's decoder refused them), as ``testbed link`` counts them; a
    frame whose bit errors all fell in its last packet's padding decodes and is delivered (the
    trace marks that packet ``corrupt``), so delivered + corrupted + the other losses = settled.

    ``per`` = 1 − delivered / settled, over the frames whose every packet had reached the
    receiver (or been lost) when the run ended: a frame still queued or on the air at the end
    is neither delivered nor lost, and a frame the sender's FIFO dropped was never on the air
    (``drop_rate`` = dropped / sent counts those).
    """
    counts = direction_counts(trace.events, src, dst)
    lost_otherwise = counts.frames_collided + counts.frames_outage + counts.frames_out_of_range
    return {
        "frames_sent": counts.frames_sent,
        "frames_delivered": decoded,
        "frames_corrupted": max(0, counts.frames_settled - decoded - lost_otherwise),
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
    ignored_setpoints: int | None = None,
) -> dict[str, Any]:
    """Reduce a recording to the ``metrics.json`` content (README: "metrics.json").

    ``ignored_setpoints`` (the vehicle's count of operator setpoints it could not apply: not a
    number, out of range) is ``events.ignored_setpoints``; None = not known here.

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
    ipg_s = link.ipg_policy.gap_after(ORDER_FRAME_BYTES) if link.mac == "token" else math.nan
    cycle = token_cycle(scenario)
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
    depth_error = series["down_m"][after] - series["depth_target_m"][after]
    if sim_s > settle:
        command_age = age_of_information(recorder.command_updates, settle, sim_s)
        odometry_age = age_of_information(recorder.odometry_updates, settle, sim_s)
    else:  # a run ended early, before its settling time: nothing to average
        command_age = odometry_age = {"mean": math.nan, "p95": math.nan}
    metrics: dict[str, Any] = {
        "scenario": scenario.id,
        "inputs": {  # what ran: enough to run it again
            "testbed": testbed.__version__,
            "source": scenario.source,
            "overrides": list(scenario.overrides),
            "files": dict(scenario.files),
            **_own_pilot(scenario),
            **_own_control_laws(scenario),
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
        "token_round_trip_s": math.nan if cycle is None else cycle.round_trip_s,
        "reply_fits_gap": None if cycle is None else cycle.fits,
        "command_lag_s": summary(lags),
        "command_age_s": command_age,
        "signal_lag_s": signal,
        "signal_lag_reference": recorder.stick_source,
        "odometry_age_s": odometry_age,
        "velocity_tracking_rmse": rmse,
        "attitude_error_deg": attitude,
        "depth_error_m": distribution(depth_error[~np.isnan(depth_error)]),
        "energy_wh": energy_wh,
        "max_tilt_deg": max_tilt(series),
        "frames_rejected": dict(recorder.frames_rejected),
        "events": {
            "failsafe": failsafe_engagements(recorder.events),
            "failsafe_surfaced": sum(
                1 for e in recorder.events if e.kind == "failsafe" and e.detail == "SURFACE"
            ),
            "thruster_fault": sum(1 for e in recorder.events if e.kind == "thruster_fault"),
            "ignored_setpoints": ignored_setpoints,
        },
    }
    if scenario.images.enabled:
        metrics["images"] = image_metrics(recorder.images, sim_s)
    if recorder.arm is not None:
        metrics["arm"] = recorder.arm.metrics()
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


_LOSS_COUNTERS = ("unlocked", "dropouts")
"""What a source that can miss samples counts (the DVL: no bottom lock, random dropout)."""


def navigation_metrics(navigation: Navigation) -> dict[str, Any]:
    """The ``"navigation"`` key of ``metrics.json`` (a vehicle with ``[vehicle.navigation]``):
    what the sources delivered and what the filter did with it.

    ``delivered``: measurements handed to the localizer, by source (``"depth"`` for the depth
    sensor), every fitted source named (0: it never delivered). ``lost``: for a source that
    can miss samples (the DVL), its samples without bottom lock (``unlocked``) and those lost
    to random dropout (``dropouts``). ``filter``: the default localizer's counters
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
    delivered = {source.name: 0 for source in navigation.sources}  # a silent one shows 0
    if navigation.depth_sigma_m > 0.0:
        delivered["depth"] = 0
    delivered.update(navigation.delivered)
    lost = {
        source.name: {key: int(getattr(source, key)) for key in _LOSS_COUNTERS}
        for source in navigation.sources
        if all(hasattr(source, key) for key in _LOSS_COUNTERS)
    }
    return {
        "delivered": dict(sorted(delivered.items())),
        "lost": lost,
        "filter": filter_counts,
        "by_source": by_source,
        "gate_probability": gate,
    }


_STICK_AXES = (("x", "u"), ("y", "v"), ("z", "w"), ("yaw", "r"))
"""The stick axes of the series (``cmd_*``, ``rx_*``) and the body velocity each asks for."""


CAPSIZE_DEG = 90.0
"""Roll or pitch beyond which a vehicle counts as capsized [deg] (upside down or on its end)."""


def max_tilt(series: Mapping[str, np.ndarray]) -> dict[str, float]:
    """``max_tilt_deg``: the largest |roll| and |pitch| over the whole run [deg] and when the
    first of them passed :data:`CAPSIZE_DEG` (``capsized_s`` [s]; NaN: never)."""
    roll, pitch = np.abs(series["roll_deg"]), np.abs(series["pitch_deg"])
    over = np.flatnonzero((roll > CAPSIZE_DEG) | (pitch > CAPSIZE_DEG))
    return {
        "roll": float(roll.max()) if roll.size else math.nan,
        "pitch": float(pitch.max()) if pitch.size else math.nan,
        "capsized_s": float(series["t_s"][over[0]]) if over.size else math.nan,
    }


def received_from_the_link(series: Mapping[str, np.ndarray]) -> np.ndarray:
    """(n,) bool: the rows whose ``rx_*`` sticks are the last the link delivered, armed with
    no failsafe engaged (otherwise the vehicle flies centred sticks whatever arrives)."""
    return np.asarray((series["armed"] > 0.5) & (series["failsafe"] == 0.0), dtype=bool)


def stick_lag_s(
    series: Mapping[str, np.ndarray], axis: str, after: np.ndarray, max_lag_s: float
) -> float:
    """``signal_lag_s.<axis>`` [s]: :func:`~testbed.run.metrics.signal_lag_s` of the pilot's
    ``cmd_<axis>`` against the vehicle's ``rx_<axis>`` over the rows ``after`` (the settle
    time), counting the received samples that are the link's (:func:`received_from_the_link`);
    NaN with ten or fewer of those."""
    linked = received_from_the_link(series)[after]
    if linked.sum() <= 10:
        return math.nan
    t, commanded, received = (series[c][after] for c in ("t_s", f"cmd_{axis}", f"rx_{axis}"))
    return signal_lag_s(t, commanded, received, max_lag_s=max_lag_s, valid=linked)


def stick_tracking(
    series: dict[str, np.ndarray],
    after: np.ndarray,
    *,
    under_autonomy: bool,
    max_lag_s: float = SIGNAL_LAG_WINDOW_S,
) -> tuple[dict[str, float], dict[str, float]]:
    """``signal_lag_s`` and ``velocity_tracking_rmse`` of ``metrics.json``: how the sticks the
    vehicle applies follow the pilot's, and how its body velocity follows what they ask for.

    Both are taken at or after the settle time (``after``): the RMS over the armed rows, the
    lag over the rows whose received sticks are the link's (:func:`received_from_the_link`:
    armed, no failsafe holding them centred). Under autonomy
    the vehicle flies its mission and never the sticks (it records them centred: ``rx_*`` = 0,
    ``ref_*`` = 0), so there is nothing to track: every axis is NaN (null in the file), not the
    vehicle's RMS speed against a zero demand.

    Args:
        series: :meth:`Recorder.series` columns.
        after: (n,) bool, the rows at or after ``metrics.settle_s``.
        under_autonomy: the vehicle has ``[vehicle.autonomy]``.
        max_lag_s: the upper end of the lag's search [s] (the link's
            :attr:`~testbed.run.sections.LinkSection.signal_lag_window_s`).

    Returns:
        ``(signal_lag_s, velocity_tracking_rmse)``, each keyed ``x``, ``y``, ``z``, ``yaw``:
        the lag [s] and the RMS velocity difference [m/s; rad/s for yaw], body FRD.
    """
    if under_autonomy:
        nothing = {axis: math.nan for axis, _ in _STICK_AXES}
        return nothing, dict(nothing)
    flying = after & (series["armed"] > 0.5)
    signal = {axis: stick_lag_s(series, axis, after, max_lag_s) for axis, _ in _STICK_AXES}
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
    yaw_target = None if reaching else series["target_yaw_deg"][flying]
    settling, arrival = settling_time_s(
        t[flying], truth[flying], target[flying], tolerance_m, yaw_target
    )
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
