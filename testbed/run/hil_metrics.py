"""The ``metrics.json`` of a hardware-in-the-loop run, from what the real ports observed.

:func:`hil_metrics` rebuilds :func:`~testbed.run.run_metrics.compute_metrics`'s link section
per direction from the :class:`~testbed.run.hil_modem.HilModem` counters and the
:class:`~testbed.run.hil_modem.FrameLedger`, leaves out (null) what the ends running here cannot
know, and adds a ``hil`` section (added latency, token round trips, scheduler lateness, port
reports). Used by :func:`~testbed.run.realtime.run_hil`, the live console over real modems and
the MAVLink gateway; it reads the records of a run and runs nothing.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping, Sequence
from typing import Any

from testbed.channel import EventKind, Trace
from testbed.hil import endpoint_report, latency_summary_ms
from testbed.run.hil_modem import DIRECTIONS, FrameLedger, HilModem
from testbed.run.metrics import summary
from testbed.run.nodes import OperatorNode, VehicleNode
from testbed.run.recorder import Recorder
from testbed.run.run_metrics import compute_metrics
from testbed.run.scenario_config import Scenario
from testbed.vehicle.resources import Controllers

__all__ = ["hil_metrics"]


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
    :func:`~testbed.run.wall_clock.rt_lateness_ns`; same keys as ``added_latency_ms``);
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
