"""The sans-IO endpoint against pymavlink-encoded messages, a real vehicle behind it, in
simulated time: connect, version, parameters, modes, arming, sticks, gating, failsafes."""

from __future__ import annotations

import math
from typing import Any

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mav

from testbed.common.components import ActiveMode, CommandStatus, ControlMode, MovementCommand
from testbed.mavlink.ardusub import manual_control_pwm, sticks_from_rc
from tests.mavlink.gcs import SimGcs

ACCEPTED = mav.MAV_RESULT_ACCEPTED
FAILED = mav.MAV_RESULT_FAILED


def acks(gcs: SimGcs, cmd: int) -> list[int]:
    return [m.result for m in gcs.of("COMMAND_ACK") if m.command == cmd]


def test_heartbeat_is_ardusubs_from_system_1_component_1_in_mavlink2(gcs: SimGcs) -> None:
    gcs.run(1.05)
    beats = gcs.of("HEARTBEAT")
    assert len(beats) == 2  # 1 Hz, the first at once
    hb = beats[-1]
    assert (hb.type, hb.autopilot) == (mav.MAV_TYPE_SUBMARINE, mav.MAV_AUTOPILOT_ARDUPILOTMEGA)
    assert (hb.custom_mode, hb.base_mode) == (19, 81)  # disarmed MANUAL
    assert hb.system_status == mav.MAV_STATE_STANDBY
    assert (hb.get_srcSystem(), hb.get_srcComponent()) == (1, 1)
    assert all(packet[0] == 0xFD for packet in gcs.packets)  # MAVLink 2 start byte


def test_autopilot_version_on_request_message_and_on_capabilities_request(gcs: SimGcs) -> None:
    gcs.send(gcs.command(mav.MAV_CMD_REQUEST_MESSAGE, mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION))
    gcs.send(gcs.command(mav.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, 1))
    gcs.send(gcs.command(mav.MAV_CMD_REQUEST_MESSAGE, 397))  # component metadata: none
    gcs.step()
    versions = gcs.of("AUTOPILOT_VERSION")
    assert len(versions) == 2
    version = versions[0]
    assert version.flight_sw_version >> 24 == 4 and version.flight_sw_version & 0xFF == 255
    assert version.capabilities & mav.MAV_PROTOCOL_CAPABILITY_MAVLINK2
    assert acks(gcs, mav.MAV_CMD_REQUEST_MESSAGE) == [ACCEPTED, mav.MAV_RESULT_UNSUPPORTED]
    assert acks(gcs, mav.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES) == [ACCEPTED]


def test_home_and_origin_are_where_the_global_position_puts_the_local_origin(
    gcs: SimGcs,
) -> None:
    """HOME_POSITION on REQUEST_MESSAGE(242) and on GET_HOME_POSITION, GPS_GLOBAL_ORIGIN on
    REQUEST_MESSAGE(49) (a MAVLink user's review: MAVProxy asked 26 times in 55 s, refused):
    both at the point GLOBAL_POSITION_INT gives for the local frame's origin at the surface
    (the second method: the vehicle's own global position, less its local offset)."""
    gcs.send(gcs.command(mav.MAV_CMD_REQUEST_MESSAGE, mav.MAVLINK_MSG_ID_HOME_POSITION))
    gcs.send(gcs.command(mav.MAV_CMD_GET_HOME_POSITION))
    gcs.send(gcs.command(mav.MAV_CMD_REQUEST_MESSAGE, mav.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN))
    gcs.send(gcs.command(mav.MAV_CMD_REQUEST_MESSAGE, mav.MAVLINK_MSG_ID_LOCAL_POSITION_NED))
    gcs.send(gcs.command(mav.MAV_CMD_REQUEST_MESSAGE, mav.MAVLINK_MSG_ID_GLOBAL_POSITION_INT))
    gcs.step()
    homes, origin = gcs.of("HOME_POSITION"), gcs.last("GPS_GLOBAL_ORIGIN")
    local, where = gcs.last("LOCAL_POSITION_NED"), gcs.last("GLOBAL_POSITION_INT")
    assert len(homes) == 2 and acks(gcs, mav.MAV_CMD_GET_HOME_POSITION) == [ACCEPTED]
    earth_m = 6378137.0  # WGS-84 equatorial radius: the flat-earth offset's scale
    lat = where.lat * 1e-7 - math.degrees(local.x / earth_m)
    lon = where.lon * 1e-7 - math.degrees(
        local.y / (earth_m * math.cos(math.radians(homes[0].latitude * 1e-7)))
    )
    for home in homes:
        assert (home.x, home.y, home.z, home.altitude) == (0.0, 0.0, 0.0, 0)
        assert home.latitude * 1e-7 == pytest.approx(lat, abs=2e-7)
        assert home.longitude * 1e-7 == pytest.approx(lon, abs=2e-7)
    assert (origin.latitude, origin.longitude) == (homes[0].latitude, homes[0].longitude)
    version = autopilot_version_of(gcs)
    assert version.capabilities & mav.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED


def test_home_and_origin_carry_the_time_since_boot(gcs: SimGcs) -> None:
    """ArduPilot's ``GCS_MAVLINK::send_home_position`` and ``send_gps_global_origin``
    (``GCS_Common.cpp``) end with ``AP_HAL::micros64()``, the time since boot [µs], in the
    ``time_usec`` extension field, and HOME_POSITION's ``q`` is ``{1.0f, 0.0f, 0.0f, 0.0f}``:
    the vehicle's time when the request arrives. Both used to leave ``time_usec`` 0."""
    gcs.run(2.0)
    for message_id in (mav.MAVLINK_MSG_ID_HOME_POSITION, mav.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN):
        gcs.send(gcs.command(mav.MAV_CMD_REQUEST_MESSAGE, message_id))
    asked_s = gcs.now_s  # the step below hands the requests over at this vehicle time
    gcs.step()
    home, origin = gcs.last("HOME_POSITION"), gcs.last("GPS_GLOBAL_ORIGIN")
    assert asked_s >= 2.0
    assert home.time_usec == origin.time_usec == pytest.approx(asked_s * 1e6, abs=1.0)
    assert list(home.q) == [1.0, 0.0, 0.0, 0.0]


def autopilot_version_of(gcs: SimGcs) -> Any:
    gcs.send(gcs.command(mav.MAV_CMD_REQUEST_MESSAGE, mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION))
    gcs.step()
    return gcs.last("AUTOPILOT_VERSION")


def test_a_mission_upload_is_refused_at_once_and_a_clear_acknowledged(gcs: SimGcs) -> None:
    """MISSION_COUNT gets MISSION_ACK UNSUPPORTED (no AUTO missions here) instead of silence,
    on which QGroundControl's upload times out; MISSION_CLEAR_ALL is ACCEPTED (nothing held)."""
    gcs.send(gcs.mav.mission_count_encode(1, 1, 3, 0))
    gcs.send(gcs.mav.mission_clear_all_encode(1, 1, 0))
    gcs.step()
    acks_seen = [(m.type, m.target_system) for m in gcs.of("MISSION_ACK")]
    assert acks_seen == [(mav.MAV_MISSION_UNSUPPORTED, 255), (mav.MAV_MISSION_ACCEPTED, 255)]


def test_full_parameter_download_then_set_read_and_refusals(gcs: SimGcs) -> None:
    gcs.send(gcs.mav.param_request_list_encode(1, 1))
    gcs.run(0.5)
    values = gcs.of("PARAM_VALUE")
    count = len(gcs.endpoint.params)
    assert count > 50
    assert sorted(v.param_index for v in values) == list(range(count))
    assert {v.param_count for v in values} == {count}
    by_name = {v.param_id: v.param_value for v in values}
    assert by_name["SYSID_THISMAV"] == 1 and by_name["SYSID_MYGCS"] == 255  # ArduSub 4.5's name
    assert by_name["FS_PILOT_TIMEOUT"] == 3.0 and by_name["JS_GAIN_DEFAULT"] == 0.5
    assert {"FRAME_CONFIG", "FS_GCS_ENABLE", "BARO_SPEC_GRAV", "SERVO1_FUNCTION"} <= set(by_name)
    assert any(m.text.startswith("ArduSub V4") for m in gcs.of("STATUSTEXT"))
    gcs.clear()
    gcs.send(gcs.param_set("FS_GCS_ENABLE", 3))
    gcs.send(gcs.param_set("FS_PILOT_TIMEOUT", 9.0))  # beyond ArduSub's 0.1..3: refused
    gcs.send(gcs.param_set("NO_SUCH_PARAM", 1.0))
    gcs.send(gcs.mav.param_request_read_encode(1, 1, b"MAV_GCS_SYSID", -1))  # 4.7's name
    gcs.send(gcs.mav.param_request_read_encode(1, 1, b"", 0))
    gcs.step()
    echoed = [(v.param_id, v.param_value) for v in gcs.of("PARAM_VALUE")]
    first = gcs.endpoint.params.params[0].name
    assert echoed == [
        ("FS_GCS_ENABLE", 3.0),
        ("FS_PILOT_TIMEOUT", 3.0),
        ("MAV_GCS_SYSID", 255.0),  # answered by the name asked
        (first, 1.0),
    ]
    assert gcs.endpoint.params["FS_GCS_ENABLE"] == 3
    assert gcs.endpoint.rejected["param_refused"] == 2


def test_modes_are_acknowledged_reflected_in_the_heartbeat_and_unsimulated_ones_refused(
    gcs: SimGcs,
) -> None:
    gcs.send(gcs.set_mode(0))
    gcs.run(1.01)
    # SET_MODE is acknowledged with its message id (11), as ArduPilot's handle_set_mode does
    assert acks(gcs, mav.MAVLINK_MSG_ID_SET_MODE) == [ACCEPTED]
    assert gcs.last("HEARTBEAT").custom_mode == 0
    gcs.send(gcs.command(mav.MAV_CMD_DO_SET_MODE, 1, 2))  # ALT_HOLD by COMMAND_LONG
    gcs.run(1.01)
    assert acks(gcs, mav.MAV_CMD_DO_SET_MODE) == [ACCEPTED]
    assert gcs.last("HEARTBEAT").custom_mode == 2
    active = gcs.vehicle.world.get(gcs.vehicle.entity, ActiveMode)
    assert active is not None and active.mode is ControlMode.DEPTH_HOLD
    gcs.clear()
    for refused in (16, 3, 9, 5):  # POSHOLD, AUTO, SURFACE: not simulated; unknown
        gcs.send(gcs.set_mode(refused))
    gcs.send(gcs.mav.set_mode_encode(1, 0, 19))  # no custom-mode flag
    gcs.run(1.01)
    denied = mav.MAV_RESULT_DENIED  # no custom-mode flag: "supported, invalid parameters"
    assert acks(gcs, mav.MAVLINK_MSG_ID_SET_MODE) == [FAILED] * 4 + [denied]
    assert gcs.last("HEARTBEAT").custom_mode == 2
    assert any(m.text == "Flight mode change failed" for m in gcs.of("STATUSTEXT"))


def test_every_command_is_counted_once_as_what_its_ack_said(gcs: SimGcs) -> None:
    """``accepted`` counts the ACCEPTED commands only, a refusal is counted once under its
    reason (``mode_refused``) or, with none, ``command_refused`` (a refused mode was counted
    both accepted and mode_refused)."""
    endpoint = gcs.endpoint
    gcs.run(0.5)
    accepted, rejected = endpoint.accepted, sum(endpoint.rejected.values())
    gcs.clear()
    gcs.send(gcs.set_mode(16))  # POSHOLD: FAILED, mode_refused
    gcs.send(gcs.mav.set_mode_encode(1, 0, 19))  # no custom-mode flag: DENIED, no reason
    gcs.send(gcs.command(mav.MAV_CMD_DO_SET_MODE, 1, 3))  # AUTO by COMMAND_LONG: FAILED
    gcs.send(gcs.command(mav.MAV_CMD_DO_MOTOR_TEST, 1, 1, 1600, 1))  # disarmed: FAILED
    gcs.send(gcs.set_mode(0))  # STABILIZE: ACCEPTED
    gcs.step()
    replies = acks(gcs, mav.MAVLINK_MSG_ID_SET_MODE) + acks(gcs, mav.MAV_CMD_DO_SET_MODE)
    assert replies == [FAILED, mav.MAV_RESULT_DENIED, ACCEPTED, FAILED]
    assert acks(gcs, mav.MAV_CMD_DO_MOTOR_TEST) == [FAILED]
    assert endpoint.accepted == accepted + 1
    assert endpoint.rejected["mode_refused"] == 2
    assert endpoint.rejected["command_refused"] == 2
    assert sum(endpoint.rejected.values()) == rejected + 4


def test_arm_and_disarm_are_acknowledged_and_in_the_heartbeat(gcs: SimGcs) -> None:
    gcs.send(gcs.heartbeat(), gcs.arm())
    gcs.run(1.01, gcs.flying())
    assert acks(gcs, mav.MAV_CMD_COMPONENT_ARM_DISARM) == [ACCEPTED]
    hb = gcs.last("HEARTBEAT")
    assert hb.base_mode == 209 and hb.system_status == mav.MAV_STATE_ACTIVE
    gcs.send(gcs.arm(False))
    gcs.run(1.01, gcs.flying())
    assert gcs.last("HEARTBEAT").base_mode == 81


def test_manual_control_scaling_is_ardusubs() -> None:
    half = manual_control_pwm(1000, 0, 1000, 0, gain=0.5)
    assert half[5] == 1700 and half[3] == 1700
    assert manual_control_pwm(0, 0, 0, 0, gain=0.5)[3] == 1300
    assert manual_control_pwm(0, 0, 500, 0, gain=0.5)[3] == 1500
    full = manual_control_pwm(1000, -1000, 500, 1000, gain=1.0)
    assert (full[5], full[6], full[4]) == (1900, 1100, 1900)
    channels = [1500, 1500, 1700, 1500, 1700, 1500]
    assert sticks_from_rc(channels) == (0.5, 0.0, -0.5, 0.0, 0.0, 0.0)  # heave + is down


def test_forward_stick_drives_the_thrusters_and_the_vehicle(gcs: SimGcs) -> None:
    gcs.send(gcs.heartbeat(), gcs.arm())
    gcs.run(0.5, gcs.flying())
    assert gcs.last("SERVO_OUTPUT_RAW").servo1_raw == 1500
    gcs.run(4.0, gcs.flying(x=1000))
    servo = gcs.last("SERVO_OUTPUT_RAW")
    pulses = [getattr(servo, f"servo{k}_raw") for k in range(1, 7)]
    assert max(abs(p - 1500) for p in pulses) > 25
    assert gcs.truth_surge_m_s() > 0.2
    assert gcs.last("VFR_HUD").groundspeed >= 0.0
    # ArduSub reads JS_GAIN_DEFAULT at boot only (Sub::init_joystick): set now, the gain stays
    gcs.send(gcs.param_set("JS_GAIN_DEFAULT", 1.0))
    gcs.run(0.1, gcs.flying(x=1000))
    assert gcs.endpoint.gain == 0.5 and gcs.endpoint.rc.channels[4] == 1700  # 1500 + 0.4·0.5·1000
    assert gcs.last("PARAM_VALUE").param_value == 1.0  # stored and echoed for the next boot


def test_vfr_hud_airspeed_is_ardupilots_fallback_not_the_ground_speed(gcs: SimGcs) -> None:
    """ArduPilot's ``GCS_MAVLINK::vfr_hud_airspeed`` (``GCS_Common.cpp``; ArduSub does not
    override it): a healthy airspeed sensor's reading, else the GPS's ground speed. This
    vehicle's SYS_STATUS shows neither sensor present, so VFR_HUD's airspeed is 0 while it
    moves (it used to repeat the horizontal speed), and ``groundspeed`` carries that speed."""
    gcs.send(gcs.heartbeat(), gcs.arm())
    gcs.run(4.0, gcs.flying(x=1000))
    present = gcs.last("SYS_STATUS").onboard_control_sensors_present
    absent = mav.MAV_SYS_STATUS_SENSOR_GPS | mav.MAV_SYS_STATUS_SENSOR_DIFFERENTIAL_PRESSURE
    assert present & absent == 0
    hud = gcs.last("VFR_HUD")
    assert gcs.truth_surge_m_s() > 0.2 and hud.groundspeed > 0.2
    assert hud.airspeed == 0.0


def test_vfr_hud_throttle_is_ardusubs_truncated_percentage(gcs: SimGcs) -> None:
    """ArduSub's ``GCS_MAVLINK_Sub::vfr_hud_throttle`` (``ArduSub/GCS_MAVLink_Sub.cpp``) is
    ``(int16_t)(motors.get_throttle() * 100)``: the percentage truncated, not rounded. RC 3 at
    1561 µs is a throttle of (1561 − 1100) / 800 = 0.57625: 57 (it was rounded to 58); 1336 µs,
    0.295: 29 (was 30); the ends 0 and 100."""
    for pwm, percent in ((1561, 57), (1336, 29), (1100, 0), (1900, 100)):
        override = gcs.mav.rc_channels_override_encode(1, 1, 0, 0, pwm, 0, 0, 0, 0, 0)
        gcs.run(0.6, lambda k, o=override: [o] if k % 4 == 0 else [])  # RC_CHANNELS at 2 Hz
        assert gcs.last("RC_CHANNELS").chan3_raw == pwm
        assert gcs.last("VFR_HUD").throttle == percent


def test_vfr_hud_heading_is_ardupilots_truncated_whole_degrees(gcs: SimGcs) -> None:
    """ArduPilot's ``GCS_MAVLINK::send_vfr_hud`` (``GCS_Common.cpp``) sends
    ``(ahrs.yaw_sensor / 100) % 360``, ``yaw_sensor`` the yaw in centidegrees truncated and
    wrapped to 0..35999 (``AP_AHRS::update_cd_values``): the whole degrees of the heading, never
    rounded up. Turning, each VFR_HUD's heading is the floor of the ATTITUDE yaw sent with it
    (the same step, the same state), also where the fraction is ≥ 0.5 (it used to round)."""
    gcs.send(gcs.heartbeat(), gcs.arm())
    gcs.run(0.2, gcs.flying())
    pairs = []
    for k in range(round(6.0 / 0.01)):
        gcs.send(*([gcs.sticks(r=400)] if k % 4 == 0 else []))
        before = len(gcs.messages)
        gcs.step()
        new = gcs.messages[before:]
        huds = [m for m in new if m.get_type() == "VFR_HUD"]
        attitudes = [m for m in new if m.get_type() == "ATTITUDE"]
        if huds and attitudes:
            pairs.append((huds[-1].heading, math.degrees(attitudes[-1].yaw) % 360.0))
    rounding_differs = 0
    for heading, yaw_deg in pairs:
        fraction = yaw_deg - math.floor(yaw_deg)
        if 1e-3 < fraction < 1.0 - 1e-3:  # clear of float32's resolution at a whole degree
            assert heading == math.floor(yaw_deg)
            rounding_differs += fraction > 0.5
    headings = {heading for heading, _ in pairs}
    assert len(pairs) >= 50 and len(headings) >= 20 and rounding_differs >= 10


def test_alt_hold_holds_depth_where_manual_drifts(gcs: SimGcs) -> None:
    gcs.send(gcs.heartbeat(), gcs.arm(), gcs.set_mode(2))
    gcs.run(1.0, gcs.flying())
    start = gcs.truth_depth_m()
    gcs.run(8.0, gcs.flying())
    assert abs(gcs.truth_depth_m() - start) < 0.05
    reported = gcs.last("GLOBAL_POSITION_INT").relative_alt / 1000.0
    assert reported == pytest.approx(-gcs.truth_depth_m(), abs=0.05)  # negative below
    gcs.send(gcs.set_mode(19))
    gcs.run(8.0, gcs.flying())
    assert abs(gcs.truth_depth_m() - start) > 0.1  # positively buoyant: it rises


def test_manual_control_from_another_system_is_ignored_and_counted(gcs: SimGcs) -> None:
    intruder = SimGcs.make_sender(42)
    # COMMAND_LONG is not gated on the sender (ArduSub's is not): the intruder arms
    gcs.send(intruder.command_long_encode(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0), sender=intruder)
    gcs.run(1.01)
    assert gcs.last("HEARTBEAT").base_mode == 209

    def intruding(k: int) -> list[object]:
        return [intruder.manual_control_encode(1, 1000, 0, 500, 0, 0)] if k % 4 == 0 else []

    for k in range(200):
        gcs.send(*intruding(k), sender=intruder)
        gcs.step()
    endpoint = gcs.endpoint
    assert endpoint.rejected["wrong_sysid"] == 50
    assert endpoint.pilot_inputs == 0
    vehicle = gcs.vehicle
    command = vehicle.world.get(vehicle.operator_entity, MovementCommand)
    assert command is None or not any(command.sticks)  # at most the failsafe's neutral
    status = vehicle.world.get(vehicle.entity, CommandStatus)
    assert status is None or (command is not None and status.seq == command.seq)
    assert abs(gcs.truth_surge_m_s()) < 0.05
    gcs.send(gcs.mav.manual_control_encode(7, 1000, 0, 500, 0, 0))  # not addressed to us
    gcs.step()
    assert endpoint.rejected["wrong_target"] == 1 and endpoint.pilot_inputs == 0


@pytest.mark.parametrize(
    ("action", "mode", "armed"), [(2, 19, False), (3, 2, True), (4, 2, True), (1, 19, True)]
)
def test_gcs_heartbeat_loss_acts_per_fs_gcs_enable(action: int, mode: int, armed: bool) -> None:
    gcs = SimGcs()
    try:
        gcs.send(gcs.param_set("FS_PILOT_INPUT", 0), gcs.param_set("FS_GCS_ENABLE", action))
        gcs.send(gcs.heartbeat(), gcs.arm())
        gcs.run(3.0, gcs.flying())
        assert gcs.last("HEARTBEAT").system_status == mav.MAV_STATE_ACTIVE
        gcs.run(6.5)  # silence: > FS_GCS_TIMEOUT (5 s) after the last contact
        hb = gcs.last("HEARTBEAT")
        assert bool(hb.base_mode & 128) is armed and hb.custom_mode == mode
        assert hb.system_status == mav.MAV_STATE_CRITICAL
        assert any("heartbeat lost" in m.text for m in gcs.of("STATUSTEXT"))
        assert gcs.endpoint.failsafe.triggered["gcs"] == 1
        gcs.run(1.0, gcs.flying())  # the GCS is back: cleared, the mode is not restored
        assert gcs.last("HEARTBEAT").custom_mode == mode
        assert not gcs.endpoint.failsafe.gcs
    finally:
        gcs.close()


@pytest.mark.parametrize("contact", [True, False])
def test_gcs_failsafe_off_when_disabled_or_before_first_contact(contact: bool) -> None:
    gcs = SimGcs()
    try:
        gcs.send(gcs.param_set("FS_PILOT_INPUT", 0))
        if contact:  # a heartbeat, but the failsafe is off
            gcs.send(gcs.param_set("FS_GCS_ENABLE", 0), gcs.heartbeat())
        gcs.send(gcs.arm())  # a command is no contact
        gcs.run(8.0)
        assert gcs.last("HEARTBEAT").base_mode == 209
        assert gcs.endpoint.failsafe.triggered["gcs"] == 0
    finally:
        gcs.close()


def test_pilot_input_loss_disarms_after_fs_pilot_timeout(gcs: SimGcs) -> None:
    gcs.send(gcs.param_set("FS_PILOT_TIMEOUT", 1.0), gcs.heartbeat(), gcs.arm())
    gcs.run(2.0, gcs.flying(x=500))
    assert gcs.last("HEARTBEAT").base_mode == 209
    gcs.clear()
    for k in range(150):  # heartbeats go on, sticks stop
        gcs.send(*([gcs.heartbeat()] if k % 50 == 0 else []))
        gcs.step()
    assert gcs.last("HEARTBEAT").base_mode == 81
    assert [m.text for m in gcs.of("STATUSTEXT")] == ["Lost manual control"]
    command = gcs.vehicle.world.get(gcs.vehicle.operator_entity, MovementCommand)
    assert command is not None and not any(command.sticks)  # neutral


def test_mission_timesync_and_stream_control(gcs: SimGcs) -> None:
    gcs.send(gcs.mav.mission_request_list_encode(1, 1, 0))
    gcs.send(gcs.mav.timesync_encode(0, 123456789))
    gcs.send(gcs.mav.request_data_stream_encode(1, 1, 0, 0, 0))  # everything off
    gcs.send(gcs.mav.request_data_stream_encode(1, 1, mav.MAV_DATA_STREAM_EXTRA1, 20, 1))
    gcs.send(gcs.command(mav.MAV_CMD_SET_MESSAGE_INTERVAL, mav.MAVLINK_MSG_ID_VFR_HUD, 200_000))
    gcs.send(gcs.command(mav.MAV_CMD_GET_MESSAGE_INTERVAL, mav.MAVLINK_MSG_ID_VFR_HUD))
    gcs.run(2.0)
    count = gcs.last("MISSION_COUNT")
    assert (count.count, count.target_system, count.target_component) == (0, 255, 190)
    sync = gcs.last("TIMESYNC")
    assert sync.ts1 == 123456789 and sync.tc1 > 0
    assert len(gcs.of("ATTITUDE")) == 40  # 20 Hz for 2 s
    assert len(gcs.of("VFR_HUD")) == 10  # every 200 ms
    assert gcs.of("SYS_STATUS") == [] and gcs.of("GLOBAL_POSITION_INT") == []
    assert gcs.last("MESSAGE_INTERVAL").interval_us == 200_000
    assert acks(gcs, mav.MAV_CMD_SET_MESSAGE_INTERVAL) == [ACCEPTED]


def test_rc_channels_override_is_pilot_input_too(gcs: SimGcs) -> None:
    def override(k: int) -> list[object]:
        if k % 4:
            return []
        channels = [65535, 65535, 1500, 1500, 1800, 65535, 65535, 65535]  # ch5 forward
        return [gcs.mav.rc_channels_override_encode(1, 1, *channels)]

    gcs.send(gcs.heartbeat(), gcs.arm())
    gcs.run(3.0, override)
    command = gcs.vehicle.world.get(gcs.vehicle.operator_entity, MovementCommand)
    assert command is not None and command.sticks[0] == 0.75
    assert gcs.truth_surge_m_s() > 0.1
    assert gcs.endpoint.failsafe.triggered["pilot_input"] == 0
    assert gcs.last("RC_CHANNELS").chan5_raw == 1800
    gains = [m.value for m in gcs.of("NAMED_VALUE_FLOAT") if m.name == "PilotGain"]
    assert gains and gains[-1] == 0.5


def test_the_gcs_id_takes_effect_at_once_this_vehicles_at_the_next_boot(gcs: SimGcs) -> None:
    """SYSID_MYGCS is read live (ArduPilot's sysid_my_gcs()); SYSID_THISMAV once, at boot
    (GCS::init): set during a session it is stored and echoed, and the vehicle stays system 1,
    so the ground station that set it does not lose the vehicle (a user review: it vanished)."""
    gcs.send(gcs.param_set("SYSID_MYGCS", 200), gcs.param_set("SYSID_THISMAV", 7))
    gcs.run(1.01)
    assert gcs.last("HEARTBEAT").get_srcSystem() == 1
    echoed = {m.param_id: m.param_value for m in gcs.of("PARAM_VALUE")}
    assert echoed["SYSID_THISMAV"] == 7 and echoed["SYSID_MYGCS"] == 200
    gcs.send(gcs.mav.manual_control_encode(1, 500, 0, 500, 0, 0))  # from 255: no longer the GCS
    other = SimGcs.make_sender(200)
    gcs.send(other.manual_control_encode(7, 500, 0, 500, 0, 0), sender=other)  # wrong target
    gcs.send(other.manual_control_encode(1, 500, 0, 500, 0, 0), sender=other)  # accepted
    gcs.step()
    endpoint = gcs.endpoint
    assert dict(endpoint.rejected) == {"wrong_sysid": 1, "wrong_target": 1}
    assert endpoint.pilot_inputs == 1
