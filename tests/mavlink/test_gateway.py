"""The MAVLink gateway through the narrow link, end to end in real time: pymavlink's ``mavutil``
drives the simulated vehicle through the shore endpoint and the simulated s100 link (and the
tether), and what it sees and what the run measured match the link model's closed forms.

Closed forms (REFERENCE.md §1.6–1.8; docs/channel.md): a ``Move`` order is a 13-B frame, a
state reply a 20-B frame; each crossing takes the intrinsic delay plus its airtime,
``D_up = 85.28 + 54.7 ms``, ``D_down = 85.28 + 84.2 ms``; orders leave once per token gap
``T = max(13, 13)·8/175 s = 0.594 s``. The newest stick read at the gateway waits at most one
stick interval for the next slot. Every bound adds what the run measured (scheduler lateness,
compute time, the real interval between the sticks sent), never a wall-clock allowance.
"""

from __future__ import annotations

import math
import os
import threading
import time
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest
from pymavlink.dialects.v20 import ardupilotmega as mav

from testbed.channel import load_link_config
from testbed.protocol import encode_frame
from testbed.run.mavlink_gateway import GATEWAY_PERIOD_S, run_gateway
from testbed.run.runner import RunResult
from testbed.run.scenario import load_scenario
from tests.mavlink.rt_session import GatewaySession

S100 = load_link_config("s100")
ORDER_BYTES, REPLY_BYTES = 13, 20  # the paper's WAFrame sizes (REFERENCE §1.6)
D_UP_S = S100.intrinsic_delay_s + 8 * ORDER_BYTES / S100.bitrate_bps
D_DOWN_S = S100.intrinsic_delay_s + 8 * REPLY_BYTES / S100.bitrate_bps
GAP_S = ORDER_BYTES * 8 / 175  # telerobotics 2021-01
FRAME_S = 0.01  # the vehicle's control period


def _runner(*overrides: str) -> Any:
    scenario = load_scenario("s100-teleop-v1", ["metrics.settle_s=2", *overrides])

    def run(links: list[Any], stop: threading.Event) -> RunResult:
        return run_gateway(scenario, links, duration_s=120.0, stop=stop)

    return run


@pytest.fixture
def session() -> Iterator[GatewaySession]:
    s = GatewaySession(_runner())
    yield s
    s.close()


def test_the_paper_frame_sizes_are_the_codec_s() -> None:
    assert len(encode_frame(bytes(7))) == ORDER_BYTES  # a Move order's payload
    assert len(encode_frame(bytes(14))) == REPLY_BYTES  # a reply without an image chunk


def test_a_ground_station_flies_the_vehicle_through_the_s100_link(
    session: GatewaySession,
) -> None:
    gcs = session.gcs
    hb = gcs.wait_heartbeat(timeout=15.0)
    assert hb is not None and (hb.type, hb.autopilot, hb.get_srcSystem()) == (12, 3, 1)

    # parameters come from the shore's cache: the whole table faster than the link could carry
    # it, at its bitrate, as the PARAM_VALUE messages' own bytes (≥ 97 × 37 B × 8 / 1900 bit/s
    # ≈ 15 s), before any gap or delay; on an idle machine it takes a few ms. (A bound of one
    # token gap failed beside busy processes, at 0.94 s, with the cache doing its job.)
    start = time.monotonic()
    gcs.param_fetch_all()
    session.until(lambda: gcs.param_state and len(gcs.params) >= 90)
    fetch_s = time.monotonic() - start
    values = [msg for _, msg in session.seen.get("PARAM_VALUE", [])]
    packer = mav.MAVLink(None, srcSystem=1, srcComponent=1)
    through_link_s = sum(len(v.pack(packer)) for v in values) * 8 / S100.bitrate_bps
    assert len(values) >= 90 and through_link_s > 10.0, (len(values), through_link_s)
    assert fetch_s < through_link_s, (fetch_s, through_link_s)
    assert gcs.params["FS_GCS_ENABLE"] == 2
    gcs.mav.command_long_send(1, 1, mav.MAV_CMD_REQUEST_MESSAGE, 0, 148, 0, 0, 0, 0, 0, 0)
    version = session.until(lambda: session.latest.get("AUTOPILOT_VERSION"))
    assert version.capabilities & mav.MAV_PROTOCOL_CAPABILITY_MAVLINK2

    def banners() -> list[str]:  # the gateway's, among ArduSub's own texts
        seen = session.seen.get("STATUSTEXT", [])
        return [m.text for _, m in seen if m.text.startswith("Gateway ")]

    assert session.until(banners)[0].startswith("Gateway s100 1.9 kbit/s")

    # bad MAVLink into the gateway: counted, never raised, never acted on
    noise = bytes(b for b in os.urandom(300) if b not in (0xFD, 0xFE))
    intruder = mav.MAVLink(None, srcSystem=42, srcComponent=190)
    bad_crc = bytearray(intruder.heartbeat_encode(6, 8, 0, 0, 4).pack(intruder))
    bad_crc[-1] ^= 0xFF
    gcs.write(noise + bytes(bad_crc))
    gcs.write(intruder.manual_control_encode(1, 1000, 0, 500, 0, 0).pack(intruder) * 5)

    # arming is acknowledged on shore at once; the heartbeat shows it only once the vehicle's
    # state has come back: an order's crossing and a reply's, at the least
    session.pump(1.0)
    sent = time.monotonic()
    gcs.mav.command_long_send(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)
    assert session.ack(400) == mav.MAV_RESULT_ACCEPTED
    session.heartbeat(lambda hb: hb.base_mode & 128)
    assert time.monotonic() - sent >= D_UP_S + D_DOWN_S

    gcs.mav.set_mode_send(1, mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 2)  # ALT_HOLD
    assert session.ack(mav.MAVLINK_MSG_ID_SET_MODE) == mav.MAV_RESULT_ACCEPTED
    session.heartbeat(lambda hb: hb.custom_mode == 2)
    gcs.mav.set_mode_send(1, mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 16)  # POSHOLD: refused
    assert session.ack(mav.MAVLINK_MSG_ID_SET_MODE) == mav.MAV_RESULT_FAILED

    session.sticks = (1000, 0, 500, 0)  # forward
    session.pump(6.0)
    # stale state is not dressed as fresh: the state's time is behind the gateway's clock by
    # at least the reply's crossing (the gateway's clock when an ATTITUDE left is at most that of
    # the next SYSTEM_TIME received after it), and the gateway says how old it is
    clocks = session.seen["SYSTEM_TIME"]
    behind = [
        next(c.time_boot_ms for r, c in clocks if r >= received) - attitude.time_boot_ms
        for received, attitude in session.seen["ATTITUDE"][-20:]
        if clocks[-1][0] >= received
    ]
    assert len(behind) >= 5 and min(behind) >= 1000 * D_DOWN_S - 1, behind
    ages = [m.value for _, m in session.seen["NAMED_VALUE_FLOAT"] if m.name == "LinkAge"]
    assert len(ages) >= 10 and min(ages[-10:]) >= D_DOWN_S - 1e-3

    session.sticks = (0, 0, 500, 0)
    gcs.mav.command_long_send(1, 1, 400, 0, 0, 0, 0, 0, 0, 0, 0)
    assert session.ack(400) == mav.MAV_RESULT_ACCEPTED
    session.heartbeat(lambda hb: not hb.base_mode & 128)
    stick_gap_s = session.max_stick_gap_s()
    result = session.finish()
    m = result.metrics
    section = m["mavlink"]
    assert section["rejected"]["wrong_sysid"] == 5
    assert section["rejected"]["crc"] == 1 and section["rejected"]["garbage"] >= 1

    series = result.recorder.series()
    forward = series["rx_x"] > 0.4
    assert forward.any() and series["u"][forward].max() > 0.2  # it moved ahead
    assert series["armed"].max() == 1.0 and series["armed"][-1] == 0.0

    late_s = section["scheduler_lateness_ms"]["max"] / 1000.0
    compute_s = section["gateway_compute_ms"]["max"] / 1000.0
    # command lag (stick read at the gateway → vehicle frame applying it): one crossing, plus
    # at most one stick interval to the slot, a gateway period and a vehicle frame
    lag = m["command_lag_s"]
    high = D_UP_S + stick_gap_s + GATEWAY_PERIOD_S + FRAME_S + late_s
    assert lag["n"] >= 15
    assert D_UP_S - late_s <= lag["p50"] <= lag["max"] <= high, (lag, high)
    wall = section["gcs_to_thruster_ms"]
    assert wall["n"] >= 15
    assert 1000 * (D_UP_S - late_s) <= wall["p50"] <= wall["max"] <= 1000 * (high + compute_s)
    # age of the command on the vehicle: E[lag] + T/2 (renewal-reward, q = 1), to within the
    # lag's own spread over the finite window
    window_s = m["sim_s"] - 2.0
    tolerance = stick_gap_s + GAP_S**2 / window_s + late_s
    assert m["command_age_s"]["mean"] == pytest.approx(lag["mean"] + GAP_S / 2, abs=tolerance)
    # age of the vehicle state on shore: a reply's crossing + T/2, plus the state's own age
    # when the reply left (under one vehicle frame); the age the gateway reports lags the
    # truth by that part only
    truth = m["odometry_age_s"]["mean"]
    low = D_DOWN_S + GAP_S / 2 - GAP_S**2 / window_s - late_s
    assert low <= truth <= D_DOWN_S + GAP_S / 2 + FRAME_S + tolerance
    reported = section["state_age_s"]["mean"]
    assert truth - FRAME_S - tolerance <= reported <= truth + tolerance


def test_over_the_tether_the_change_set_gateway_answers_within_a_few_frames() -> None:
    scenario = load_scenario("tether-teleop-v1", ["metrics.settle_s=1"])
    session = GatewaySession(
        lambda links, stop: run_gateway(scenario, links, duration_s=60.0, stop=stop)
    )
    try:
        gcs = session.gcs
        assert gcs.wait_heartbeat(timeout=15.0) is not None
        gcs.mav.command_long_send(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)
        session.heartbeat(lambda hb: hb.base_mode & 128)
        session.sticks = (1000, 0, 500, 0)
        session.pump(3.0)
        result = session.finish()
    finally:
        session.close()
    section = result.metrics["mavlink"]
    tether = load_link_config("tether")
    late_s = section["scheduler_lateness_ms"]["max"] / 1000.0
    # change-set every 10 ms at 100 Hz: a gateway period, an uplink period, the tether's
    # crossing, a vehicle frame
    bound_ms = 1000 * (GATEWAY_PERIOD_S + 0.01 + tether.intrinsic_delay_s + FRAME_S + late_s)
    wall = section["gcs_to_thruster_ms"]
    # n: stick packets read in distinct gateway periods (≈ 75 in 3 s at 25 Hz; a loaded host
    # reads several in one late period and only the newest is timed), so only a floor
    assert wall["n"] >= 10 and wall["p50"] <= bound_ms + section["gateway_compute_ms"]["max"]
    assert section["state_age_s"]["mean"] < 0.05 + late_s
    series = result.recorder.series()
    assert np.nanmax(series["u"]) > 0.2 and math.isfinite(section["state_age_s"]["mean"])


def test_ardusubs_gcs_failsafe_through_the_link_is_in_the_runs_outputs(
    session: GatewaySession,
) -> None:
    """A ground station that falls silent past FS_GCS_TIMEOUT (1 s here) with FS_GCS_ENABLE 2:
    the shore's ArduSub failsafe disarms the vehicle through the link, and the run's outputs
    say so as a direct MAVLink run's do — ``vehicle,ardusub_failsafe,gcs`` in events.csv, the
    failsafe column 1 from then on (a MAVLink user's review: the gateway recorded neither)."""
    gcs = session.gcs
    assert gcs.wait_heartbeat(timeout=15.0) is not None
    gcs.param_set_send("FS_GCS_TIMEOUT", 1.0)
    session.until(
        lambda: (
            (p := session.latest.get("PARAM_VALUE")) is not None
            and p.param_id == "FS_GCS_TIMEOUT"
            and p.param_value == 1.0
        )
    )
    gcs.mav.command_long_send(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)
    assert session.ack(400) == mav.MAV_RESULT_ACCEPTED
    session.heartbeat(lambda hb: hb.base_mode & 128)
    lost = session.heartbeat(lambda hb: not hb.base_mode & 128, heartbeats=False, sticks=False)
    assert lost.system_status == mav.MAV_STATE_CRITICAL
    result = session.finish()
    assert result.metrics["mavlink"]["failsafes"]["gcs"] == 1
    events = [(e.kind, e.detail, e.t_s) for e in result.recorder.events if e.node == "vehicle"]
    story = [(kind, detail) for kind, detail, _ in events]
    assert story.index(("arm", "")) < story.index(("ardusub_failsafe", "gcs"))
    assert ("disarm", "") in story[story.index(("ardusub_failsafe", "gcs")) :]
    t_lost = next(t for kind, _, t in events if kind == "ardusub_failsafe")
    series = result.recorder.series()
    assert not series["failsafe"][series["t_s"] < t_lost].any()
    assert series["failsafe"][-1] == 1.0
