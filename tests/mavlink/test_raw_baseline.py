"""The raw-MAVLink baseline (``s100-mavlink-raw-v1``) against the link's closed form.

The uplink alone (full duplex, so the vehicle's telemetry cannot collide with it): the ground
station writes a 29-B MANUAL_CONTROL frame every 1/25 s into the modem's 500-B buffer; the
modem sends one write per transmission, each taking ``S = intrinsic + 8·29/R + gap =
85.28 + 122.1 + 0.1 ms``. Offered 25 frames/s, carried ``1/S`` ≈ 4.8 frames/s: the queue grows
at the excess rate until the buffer cap, then the excess is dropped at that rate. A command
queued at time t before the cap waits for the n = λt commands ahead of it: its lag grows as
``(λS − 1)·t``; once the buffer is full it holds ``⌊500/29⌋ = 17`` frames, so a command's lag is
between 17 and 18 services (plus the wait for the vehicle's frame).
"""

from __future__ import annotations

import numpy as np
import pytest
from pymavlink.dialects.v20 import ardupilotmega as mav

from testbed.channel import EventKind
from testbed.run.mavlink_links import RawMavlinkVehicleLink
from testbed.run.runner import run_scenario
from testbed.run.scenario import load_scenario
from testbed.vehicle.vehicle import Vehicle
from testbed.vehicle.vehicle_config import VehicleConfig

RATE_HZ = 25.0
FRAME_BYTES = 29  # MANUAL_CONTROL 23 B (REFERENCE §4.9) in a 6-B frame
BUFFER_BYTES = 500


@pytest.fixture(scope="module")
def uplink() -> dict[str, object]:
    scenario = load_scenario("s100-mavlink-raw-v1", ["link.duplex=full", "duration_s=30"])
    result = run_scenario(scenario)
    channel = scenario.link.channel
    service = channel.intrinsic_delay_s + 8 * FRAME_BYTES / channel.bitrate_bps
    return {"result": result, "S": service + channel.queue_gap_s}


def test_the_uplink_carries_one_frame_per_service_time_and_drops_the_excess(
    uplink: dict[str, object],
) -> None:
    result = uplink["result"]
    service = float(uplink["S"])  # type: ignore[arg-type]
    metrics = result.metrics  # type: ignore[attr-defined]
    events = result.recorder.trace.events  # type: ignore[attr-defined]
    sim_s = metrics["sim_s"]
    up = metrics["link"]["uplink"]
    # carried: one frame per service time, the whole run (the queue never empties)
    assert up["frames_delivered"] == pytest.approx(sim_s / service, rel=0.02)
    # the queue fills at the excess byte rate, then drops at the excess frame rate
    drops = [e.t_s for e in events if e.kind is EventKind.DROP and e.src == "operator"]
    excess_bytes_s = RATE_HZ * FRAME_BYTES - FRAME_BYTES / service
    # the connect burst at t = 0 (QGC's seven REQUEST_DATA_STREAMs, a heartbeat, the sticks)
    # starts the queue, less the frame that goes on the air at once
    burst = [
        e.size_bytes
        for e in events
        if e.src == "operator" and e.t_s == 0.0 and e.kind is EventKind.ENQUEUE
    ]
    first_full_s = (BUFFER_BYTES - (sum(burst) - burst[0])) / excess_bytes_s
    assert drops[0] == pytest.approx(first_full_s, abs=2 / RATE_HZ + 0.1)
    late = [t for t in drops if t > 5.0]
    rate = len(late) / (sim_s - 5.0)
    offered = sum(
        1 for e in events if e.kind is EventKind.ENQUEUE and e.src == "operator" and e.t_s > 5.0
    ) / (sim_s - 5.0)
    assert rate == pytest.approx(offered - 1 / service, rel=0.03)
    assert offered * 8 * FRAME_BYTES > 2.5 * 1900  # offered ≫ the bitrate (5.8 vs 1.9 kbit/s)


def test_the_command_lag_grows_at_the_excess_rate_then_sits_at_the_buffer_s_depth(
    uplink: dict[str, object],
) -> None:
    result = uplink["result"]
    service = float(uplink["S"])  # type: ignore[arg-type]
    recorder = result.recorder  # type: ignore[attr-defined]
    pairs = sorted(
        (recorder.commands_sampled[seq], applied - recorder.commands_sampled[seq])
        for seq, applied in recorder.commands_applied.items()
        if seq in recorder.commands_sampled
    )
    sampled = np.array([p[0] for p in pairs])
    lag = np.array([p[1] for p in pairs])
    growing = (sampled > 0.05) & (sampled < 0.45)  # before the buffer is first full (0.52 s)
    slope = np.polyfit(sampled[growing], lag[growing], 1)[0]
    assert slope == pytest.approx(RATE_HZ * service - 1.0, rel=0.15)
    depth = BUFFER_BYTES // FRAME_BYTES
    steady = lag[sampled > 5.0]
    assert steady.min() >= (depth - 1) * service
    assert steady.max() <= (depth + 1) * service + 0.01  # + the wait for a vehicle frame
    assert result.metrics["command_lag_s"]["p50"] > 10 * service  # type: ignore[attr-defined]


def test_on_the_half_duplex_s100_both_saturated_ends_lose_everything() -> None:
    metrics = run_scenario(load_scenario("s100-mavlink-raw-v1", ["duration_s=20"])).metrics
    for direction in ("uplink", "downlink"):
        link = metrics["link"][direction]
        assert link["frames_delivered"] == 0 and link["frames_collided"] > 0
        assert link["frames_dropped"] > 0.5 * link["frames_sent"]


def test_the_raw_links_vehicle_presents_ardusubs_frame_as_the_direct_endpoint_does() -> None:
    """Over the narrow link the vehicle's endpoint is the same ArduSub vehicle as directly: the
    BlueROV2's FRAME_CONFIG 1 (Vectored) with MOT_n_DIRECTION from its propellers (+1 for the
    CCW M1, M2, M5 and -1 for the CW M3, M4, M6: bluerov2.toml's header, from ArduSub's
    factors), read back with pymavlink from the link's own bytes (the baseline's endpoint kept
    the table's defaults: every direction +1, servos in the layout's order)."""
    vehicle = Vehicle(
        VehicleConfig(model="bluerov2", thrusters="bluerov2"), np.random.default_rng(0)
    )
    try:
        link = RawMavlinkVehicleLink(vehicle)
        gcs = mav.MAVLink(None, srcSystem=255, srcComponent=190)
        names = ["FRAME_CONFIG", *(f"MOT_{n}_DIRECTION" for n in range(1, 7))]
        for frame_id, name in enumerate(names):
            request = gcs.param_request_read_encode(1, 1, name.encode(), -1).pack(gcs)
            link.ingest([(request, frame_id)], 0.0)
        values = {
            m.param_id: m.param_value
            for data in link.outbound(0.0)
            for m in gcs.parse_buffer(data) or []
            if m.get_type() == "PARAM_VALUE"
        }
    finally:
        vehicle.close()
    assert [values[name] for name in names] == [1.0, 1.0, 1.0, -1.0, -1.0, 1.0, -1.0]
