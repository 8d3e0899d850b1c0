"""End to end in real time: pymavlink's ``mavutil`` as the ground station on 127.0.0.1, the
vehicle behind ``run_mavlink`` on a UDP link (SITL's ``udpout``), one short session (≈ 12 s).

Bounds come from the model and what the run measured (frame period, scheduler lateness, frame
compute time), never from wall-clock allowances; waits have generous timeouts that only a
broken endpoint would reach.
"""

from __future__ import annotations

import os
from collections.abc import Iterator

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mav

from testbed.run.mavlink_run import run_mavlink
from testbed.run.scenario import load_scenario
from tests.mavlink.rt_session import GatewaySession

WAIT_S = 10.0  # only a broken endpoint waits this long


@pytest.fixture
def session() -> Iterator[GatewaySession]:
    scenario = load_scenario("s100-teleop-v1")
    s = GatewaySession(
        lambda links, stop: run_mavlink(scenario, links, duration_s=120.0, stop=stop),
        wait_s=WAIT_S,
    )
    yield s
    s.close()


def test_a_ground_station_connects_configures_flies_and_loses_contact(
    session: GatewaySession,
) -> None:
    gcs = session.gcs
    hb = gcs.wait_heartbeat(timeout=WAIT_S)
    assert hb is not None and (hb.type, hb.autopilot) == (12, 3)
    assert (hb.get_srcSystem(), hb.get_srcComponent()) == (1, 1)

    gcs.mav.command_long_send(1, 1, mav.MAV_CMD_REQUEST_MESSAGE, 0, 148, 0, 0, 0, 0, 0, 0)
    version = session.until(lambda: session.latest.get("AUTOPILOT_VERSION"))
    assert version.capabilities & mav.MAV_PROTOCOL_CAPABILITY_MAVLINK2

    gcs.param_fetch_all()  # the full download, as pymavlink's own client does it
    session.until(lambda: gcs.param_state and len(gcs.params) >= 90)
    assert gcs.params["SYSID_THISMAV"] == 1 and gcs.params["FS_GCS_ENABLE"] == 2
    assert gcs.params["FS_GCS_TIMEOUT"] == 5.0  # ArduSub's default, kept while it flies: a
    # loaded host that holds this process up for seconds must not look like a lost GCS

    # garbage and an intruder on the same link are counted, never acted on
    noise = bytes(b for b in os.urandom(300) if b not in (0xFD, 0xFE))  # no start bytes
    intruder = mav.MAVLink(None, srcSystem=42, srcComponent=190)
    bad_crc = bytearray(intruder.heartbeat_encode(6, 8, 0, 0, 4).pack(intruder))
    bad_crc[-1] ^= 0xFF
    gcs.write(noise + bytes(bad_crc))
    gcs.write(intruder.manual_control_encode(1, 1000, 0, 500, 0, 0).pack(intruder) * 5)

    gcs.mav.command_long_send(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)
    assert session.ack(400) == mav.MAV_RESULT_ACCEPTED
    armed = session.heartbeat(lambda hb: hb.base_mode & 128)
    assert armed.base_mode == 209 and armed.system_status == mav.MAV_STATE_ACTIVE

    session.sticks = (1000, 0, 500, 0)  # full forward
    session.pump(3.0)
    servo = session.latest["SERVO_OUTPUT_RAW"]
    assert max(abs(getattr(servo, f"servo{k}_raw") - 1500) for k in range(1, 7)) > 25

    session.sticks = (0, 0, 500, 0)
    gcs.mav.set_mode_send(1, mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 2)  # ALT_HOLD
    assert session.ack(mav.MAVLINK_MSG_ID_SET_MODE) == mav.MAV_RESULT_ACCEPTED
    session.heartbeat(lambda hb: hb.custom_mode == 2)
    session.pump(1.0)
    start = session.latest["VFR_HUD"].alt
    session.pump(2.5)
    assert abs(session.latest["VFR_HUD"].alt - start) < 0.1  # depth held (alt < 0 below)

    gcs.mav.set_mode_send(1, mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 16)  # POSHOLD: refused
    assert session.ack(mav.MAVLINK_MSG_ID_SET_MODE) == mav.MAV_RESULT_FAILED

    gcs.param_set_send("FS_GCS_TIMEOUT", 2.0)  # lose the GCS sooner than ArduSub's 5 s
    session.until(
        lambda: (
            (p := session.latest.get("PARAM_VALUE")) is not None
            and p.param_id == "FS_GCS_TIMEOUT"
            and p.param_value == 2.0
        )
    )
    # silence: no heartbeat, no sticks, beyond FS_GCS_TIMEOUT → FS_GCS_ENABLE 2 disarms
    lost = session.heartbeat(lambda hb: not hb.base_mode & 128, heartbeats=False, sticks=False)
    assert lost.system_status == mav.MAV_STATE_CRITICAL

    result = session.finish()
    section = result.metrics["mavlink"]
    assert section["failsafes"]["gcs"] == 1
    # events.csv tells the session's story: arming, ALT_HOLD, the GCS failsafe, its disarm
    story = [(e.kind, e.detail) for e in result.recorder.events if e.node == "vehicle"]
    arm, alt_hold = story.index(("arm", "")), story.index(("mode", "DEPTH_HOLD"))
    lost = story.index(("ardusub_failsafe", "gcs"))
    assert arm < alt_hold < lost and ("disarm", "") in story[lost:]
    assert section["rejected"]["wrong_sysid"] == 5
    assert section["rejected"]["crc"] == 1 and section["rejected"]["garbage"] >= 1
    assert section["received"]["PARAM_REQUEST_LIST"] >= 1
    assert section["sent"]["PARAM_VALUE"] >= len(gcs.params)

    # every stick packet reached the thrusters within two frame periods, plus the lateness
    # and compute time the run measured (a loaded machine widens the bound, not the rule)
    latency = section["gcs_to_thruster_ms"]
    bound_ms = (
        2000.0 * section["frame_period_s"]
        + section["scheduler_lateness_ms"]["max"]
        + section["frame_compute_ms"]["max"]
    )
    assert latency["n"] >= 50 and latency["max"] <= bound_ms

    series = result.recorder.series()
    forward = series["rx_x"] > 0.4
    assert forward.any() and series["u"][forward].max() > 0.2  # the vehicle moved ahead
    # series.csv as the ground station saw it: ALT_HOLD (custom_mode 2) from the ACK on; the
    # GCS failsafe (system_status CRITICAL, never cleared: no heartbeat came back) in the
    # failsafe column — ArduSub's failsafe, the vehicle's own being off in a MAVLink run
    assert series["mode"][0] == 19.0 and series["mode"][-1] == 2.0
    assert series["failsafe"][0] == 0.0 and series["failsafe"][-1] == 1.0
    t_lost = next(e.t_s for e in result.recorder.events if e.kind == "ardusub_failsafe")
    assert not series["failsafe"][series["t_s"] < t_lost].any()
