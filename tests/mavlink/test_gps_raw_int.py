"""GPS_RAW_INT of a vehicle with no GPS, as ArduSub 4.5 streams it.

Independent truth: ArduSub's stream groups put MSG_GPS_RAW in EXTENDED_STATUS
(``STREAM_EXTENDED_STATUS_msgs[] = { MSG_SYS_STATUS, MSG_POWER_STATUS, MSG_MEMINFO,
MSG_CURRENT_WAYPOINT, MSG_GPS_RAW, … MSG_NAMED_FLOAT }``), and ArduPilot 4.5's
``AP_GPS::send_mavlink_gps_raw`` (``libraries/AP_GPS/AP_GPS.cpp``) sends it unconditionally::

    mavlink_msg_gps_raw_int_send(chan, last_fix_time_ms(0)*(uint64_t)1000, status(0),
        loc.lat, loc.lng, loc.alt * 10UL, get_hdop(0), get_vdop(0), ground_speed(0)*100,
        ground_course(0)*100, num_sats(0), height_elipsoid_mm, hacc * 1000, vacc * 1000,
        sacc * 1000, 0, gps_yaw_cdeg(0));

With no receiver found, ``AP_GPS::detect_instance`` leaves ``state[instance].status = NO_GPS;
state[instance].hdop = GPS_UNKNOWN_DOP; state[instance].vdop = GPS_UNKNOWN_DOP;`` (UINT16_MAX),
the location and speeds zero, and the accuracies keep their ``0.0f``. The endpoint used to send
no GPS_RAW_INT and answer SET_MESSAGE_INTERVAL of id 24 DENIED, GET 0 and FAILED.
"""

from __future__ import annotations

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mav

from tests.mavlink.gcs import SimGcs

GPS_RAW_INT = mav.MAVLINK_MSG_ID_GPS_RAW_INT
NO_GPS_FIELDS = {
    "time_usec": 0,  # last_fix_time_ms(0) * 1000: never a fix
    "fix_type": mav.GPS_FIX_TYPE_NO_GPS,  # status(0) == NO_GPS
    "lat": 0,
    "lon": 0,
    "alt": 0,  # the zero Location
    "eph": 65535,
    "epv": 65535,  # GPS_UNKNOWN_DOP
    "vel": 0,
    "cog": 0,
    "satellites_visible": 0,
    "alt_ellipsoid": 0,  # no undulation
    "h_acc": 0,
    "v_acc": 0,
    "vel_acc": 0,  # hacc, vacc, sacc stay 0.0f
    "hdg_acc": 0,
    "yaw": 0,  # gps_yaw_cdeg(0): no GPS yaw configured
}


def test_gps_raw_int_is_streamed_with_extended_status_and_says_no_gps(gcs: SimGcs) -> None:
    """At SR0_EXT_STAT's 2 Hz, beside SYS_STATUS; every field as ArduPilot sends it with no
    receiver."""
    gcs.run(2.0)
    raws = gcs.of("GPS_RAW_INT")
    assert len(raws) == pytest.approx(len(gcs.of("SYS_STATUS")), abs=1)
    assert len(raws) == pytest.approx(4, abs=1)
    for raw in raws:
        assert {name: getattr(raw, name) for name in NO_GPS_FIELDS} == NO_GPS_FIELDS


def test_its_interval_is_the_groups_and_settable(gcs: SimGcs) -> None:
    """GET_MESSAGE_INTERVAL answers the group's ``get_interval_for_stream`` (1000 / 2 = 500 ms →
    500 000 µs), ACCEPTED; SET_MESSAGE_INTERVAL is ACCEPTED (MSG_GPS_RAW is an ap_message) and
    REQUEST_DATA_STREAM EXTENDED_STATUS stop stops it."""
    get, set_ = mav.MAV_CMD_GET_MESSAGE_INTERVAL, mav.MAV_CMD_SET_MESSAGE_INTERVAL
    gcs.send(gcs.command(get, GPS_RAW_INT))
    gcs.run(0.05)
    assert gcs.last("MESSAGE_INTERVAL").interval_us == 500_000
    gcs.send(gcs.command(set_, GPS_RAW_INT, 100_000), gcs.command(get, GPS_RAW_INT))
    gcs.run(0.05)
    results = {m.command: m.result for m in gcs.of("COMMAND_ACK")}
    assert results == {get: mav.MAV_RESULT_ACCEPTED, set_: mav.MAV_RESULT_ACCEPTED}
    assert gcs.last("MESSAGE_INTERVAL").interval_us == 100_000
    gcs.clear()
    gcs.run(1.0)
    assert len(gcs.of("GPS_RAW_INT")) == pytest.approx(10, abs=1)
    stop = gcs.mav.request_data_stream_encode(1, 1, mav.MAV_DATA_STREAM_EXTENDED_STATUS, 0, 0)
    gcs.send(stop)
    gcs.run(0.05)
    gcs.clear()
    gcs.run(1.0)
    assert not gcs.of("GPS_RAW_INT")
