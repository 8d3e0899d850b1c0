"""MAVLink's high-latency mode over the S100 (``s100-mavlink-hl-v1``) against the link's closed
form, in simulated time.

The vehicle's HIGH_LATENCY2 (a ``F_HL = 52 + 6``-byte frame: pymavlink's packed message, which
MAVLink 2 trims of its zero tail, in the link's 6-byte frame) leaves every ``T = 5 s`` and crosses
in ``D = intrinsic + 8·F_HL/R`` (85.28 + 244.2 ms). The ground station takes it in at its next
slot (every ``1/λ = 594 ms``), so each update's age on arrival is in ``[D, D + 1/λ]`` — plus, on
the half-duplex S100, the wait of a vehicle that was hearing a stick frame (≤ its airtime
``8·F_MC/R`` + the queue gap) — and the operator's state age, a sawtooth, averages between
``D + T/2`` and ``D + T/2 + 1/λ`` and stays under ``D + T + 1/λ`` (full duplex). Half duplex: a
HIGH_LATENCY2 is lost exactly when a stick frame starts within the intrinsic delay either side
of its start (neither modem hears the other yet), so a fraction ``2·intrinsic·λ`` (28.7 %) of
them; an update lost leaves the state a further ``T`` old. The sticks cross in
``D_up = intrinsic + 8·F_MC/R`` (207.4 ms) plus the wait for the vehicle's frame (its next
control instant on the physics grid).
"""

from __future__ import annotations

import itertools
import math
from typing import Any

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mav

from testbed.channel import EventKind
from testbed.run.runner import run_scenario
from testbed.run.scenario import load_scenario

T_S = 5.0  # ArduPilot's HIGH_LATENCY2 interval on a high-latency link
FRAME_OVERHEAD = 6  # the link's frame around a payload (the raw baseline's 23 B → 29 B)


def _packed(message: Any) -> int:
    return len(message.pack(mav.MAVLink(None, 1, 1)))


HL2_BYTES = FRAME_OVERHEAD + _packed(
    mav.MAVLink_high_latency2_message(1, 12, 3, 2, 1, 1, -1, 0, 50, 0, 0, 50, 0, 0, 1, 0, 0, 0, 0,
                                      -128, 0, 100, 0, 323, -47, 0, 0)
)  # fmt: skip
STICK_BYTES = FRAME_OVERHEAD + _packed(mav.MAVLink_manual_control_message(1, 100, 0, 500, 0, 0))


def _run(overrides: list[str]) -> tuple[Any, dict[str, float]]:
    scenario = load_scenario("s100-mavlink-hl-v1", overrides)
    result = run_scenario(scenario)
    ch = scenario.link.channel
    form = {
        "D": ch.intrinsic_delay_s + 8 * HL2_BYTES / ch.bitrate_bps,
        "D_up": ch.intrinsic_delay_s + 8 * STICK_BYTES / ch.bitrate_bps,
        "stick_air": 8 * STICK_BYTES / ch.bitrate_bps + ch.queue_gap_s,
        "slot": 1.0 / scenario.link.uplink_rate_hz,
        "intrinsic": ch.intrinsic_delay_s,
        # the wait for the vehicle frame that applies a stick: its next frame, the first
        # physics instant at or after the next control instant
        "frame": 1.0 / scenario.vehicle.control_rate_hz + scenario.vehicle.physics_dt_s,
    }
    return result, form


def _hl2_frames(result: Any) -> dict[int, float]:
    """The vehicle's HIGH_LATENCY2 frames: frame id → when written to its modem."""
    return {
        e.frame_id: e.t_s
        for e in result.recorder.trace.events
        if e.src == "vehicle" and e.kind is EventKind.ENQUEUE and e.size_bytes == HL2_BYTES
    }


def test_full_duplex_state_age_bytes_and_command_lag_are_the_links_closed_form() -> None:
    result, f = _run(["link.duplex=full", "duration_s=60"])
    frames = _hl2_frames(result)
    written = sorted(frames.values())
    assert len(written) == 11  # 5, 10, … 55 s
    assert all(b - a == pytest.approx(T_S, abs=0.011) for a, b in itertools.pairwise(written))
    updates = result.recorder.odometry_updates  # (taken in, sampled) at the ground station
    assert [s for _, s in updates] == pytest.approx(written, abs=0.011)
    for taken_s, sampled_s in updates:
        assert f["D"] - 1e-9 <= taken_s - sampled_s <= f["D"] + f["slot"] + 1e-9
    age = result.metrics["odometry_age_s"]
    assert f["D"] + T_S / 2 <= age["mean"] <= f["D"] + T_S / 2 + f["slot"]
    assert age["p95"] <= f["D"] + T_S + f["slot"]
    # what the link carried: one HIGH_LATENCY2 frame per T down; one stick frame a slot up
    down = [e for e in result.recorder.trace.events if e.kind is EventKind.DELIVER]
    steady = [e for e in down if e.src == "vehicle" and e.t_s > 10.0]
    assert {e.size_bytes for e in steady} == {HL2_BYTES}
    assert len(steady) * HL2_BYTES / 50.0 == pytest.approx(HL2_BYTES / T_S, rel=0.11)
    sticks = [e for e in down if e.src == "operator" and e.size_bytes == STICK_BYTES]
    assert len(sticks) == pytest.approx(60.0 / f["slot"], abs=2)
    lag = result.metrics["command_lag_s"]
    assert lag["n"] > 0.9 * len(sticks) * (55.0 / 60.0)  # from the pilot's start at 5 s
    assert f["D_up"] <= lag["p50"] and lag["max"] <= f["D_up"] + f["frame"]


def test_half_duplex_loses_the_updates_a_stick_frame_overlaps_and_the_age_grows_by_t() -> None:
    result, f = _run(["duration_s=300"])
    events = result.recorder.trace.events
    frames = _hl2_frames(result)
    starts = {
        e.frame_id: e.t_s for e in events if e.kind is EventKind.TX_START and e.frame_id in frames
    }
    delivered = {e.frame_id for e in events if e.kind is EventKind.DELIVER}
    stick_starts = [
        e.t_s
        for e in events
        if e.kind is EventKind.TX_START and e.src == "operator" and e.size_bytes == STICK_BYTES
    ]
    lost = 0
    for frame_id, start_s in starts.items():
        # an HL2 that waited behind a stick frame's reception started after it ended
        assert start_s - frames[frame_id] <= f["stick_air"] + 0.011
        overlapped = any(abs(t - start_s) < f["intrinsic"] for t in stick_starts)
        assert (frame_id not in delivered) == overlapped
        lost += overlapped
    assert len(starts) == len(frames) == 59  # 5 … 295 s
    assert lost / len(frames) == pytest.approx(2 * f["intrinsic"] / f["slot"], abs=0.06)
    # the state the operator holds: each update D to D + the wait + a slot old when taken in,
    # and a lost one's successor T later
    updates = result.recorder.odometry_updates
    assert len(updates) == len(frames) - lost
    for taken_s, sampled_s in updates:
        assert f["D"] - 1e-9 <= taken_s - sampled_s <= f["D"] + f["stick_air"] + f["slot"]
    gaps = [b - a for (_, a), (_, b) in itertools.pairwise(updates)]
    assert all(math.remainder(g, T_S) == pytest.approx(0.0, abs=0.011) for g in gaps)
    assert sum(round(g / T_S) - 1 for g in gaps) == lost  # every missing update, a T more
    age = result.metrics["odometry_age_s"]
    assert age["mean"] > f["D"] + T_S / 2  # the losses only add
    # the commands still cross: armed, the sticks flown within D_up + the wait + a frame
    assert any(e.kind == "arm" for e in result.recorder.events)
    lag = result.metrics["command_lag_s"]
    assert f["D_up"] <= lag["p50"] <= f["D_up"] + f["frame"]
    # a stick frame waits at most for an HL2's reception to end (its airtime)
    assert lag["max"] <= f["D_up"] + f["D"] - f["intrinsic"] + f["frame"]


def test_the_vehicle_ends_armed_over_the_packaged_link() -> None:
    """Over the packaged half-duplex link the arm request, sent once (QGC waits 120 s for an
    ACK there) and again when a HIGH_LATENCY2 sampled after it still shows the vehicle
    disarmed, arms the vehicle within one interval and a crossing of the request."""
    scenario = load_scenario("s100-mavlink-hl-v1", ["duration_s=20"])
    result = run_scenario(scenario)
    arms = [e.t_s for e in result.recorder.events if e.kind == "arm"]
    assert arms and arms[0] <= scenario.operator.arm_at_s + 2 * T_S
