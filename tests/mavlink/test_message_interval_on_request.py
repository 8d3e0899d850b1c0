"""GET/SET_MESSAGE_INTERVAL of a message sent on request but streamed in no group.

Independent truth: ArduPilot 4.5's ``GCS_Common.cpp``. HOME_POSITION (242),
GPS_GLOBAL_ORIGIN (49) and ATTITUDE_QUATERNION (31) have an ``ap_message`` (MSG_HOME,
MSG_ORIGIN, MSG_ATTITUDE_QUATERNION) that no ArduSub stream group holds (its
``STREAM_EXTRA1_msgs``: MSG_ATTITUDE, MSG_SIMSTATE, MSG_AHRS2, MSG_AHRS3, MSG_PID_TUNING), so
``GCS_MAVLINK::handle_command_get_message_interval`` reaches::

    uint16_t interval_ms = 0;
    if (!get_ap_message_interval(id, interval_ms)) {
        // not streaming this message at the moment...
        mavlink_msg_message_interval_send(chan, mavlink_id, -1); // disabled
        return MAV_RESULT_ACCEPTED;
    }

and ``GCS_MAVLINK::set_message_interval`` hands any such id to ``set_ap_message_interval``
(a bucket: streamed, ``return MAV_RESULT_ACCEPTED;``), then answers ``interval_ms * 1000``.
The endpoint used to answer GET with 0 ("not available") and SET with UNSUPPORTED, and streamed
ATTITUDE_QUATERNION with EXTRA1.
"""

from __future__ import annotations

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mav

from tests.mavlink.gcs import SimGcs

GET = mav.MAV_CMD_GET_MESSAGE_INTERVAL
SET = mav.MAV_CMD_SET_MESSAGE_INTERVAL
ON_REQUEST = {
    mav.MAVLINK_MSG_ID_HOME_POSITION: "HOME_POSITION",
    mav.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN: "GPS_GLOBAL_ORIGIN",
    mav.MAVLINK_MSG_ID_ATTITUDE_QUATERNION: "ATTITUDE_QUATERNION",
}


def _acks(gcs: SimGcs, command: int) -> list[int]:
    return [m.result for m in gcs.of("COMMAND_ACK") if m.command == command]


@pytest.mark.parametrize("message_id", sorted(ON_REQUEST))
def test_a_message_not_streamed_is_answered_disabled_and_accepted(
    gcs: SimGcs, message_id: int
) -> None:
    """``mavlink_msg_message_interval_send(chan, mavlink_id, -1); // disabled`` then
    ``return MAV_RESULT_ACCEPTED;`` — not 0 ("not available", for ids with no ap_message) and
    not a refusal; and the message is not streamed meanwhile."""
    gcs.send(gcs.command(GET, message_id))
    gcs.run(1.0)
    assert _acks(gcs, GET) == [mav.MAV_RESULT_ACCEPTED]
    answers = [(m.message_id, m.interval_us) for m in gcs.of("MESSAGE_INTERVAL")]
    assert answers == [(message_id, -1)]
    assert not gcs.of(ON_REQUEST[message_id])


@pytest.mark.parametrize("message_id", sorted(ON_REQUEST))
def test_set_message_interval_streams_it_and_minus_one_stops_it(
    gcs: SimGcs, message_id: int
) -> None:
    """``set_message_interval``: 250 000 µs → ``interval_ms = interval_us / 1000`` = 250 ms,
    ``set_ap_message_interval`` puts it in a bucket → ACCEPTED; GET then answers
    ``interval_ms * 1000`` = 250 000 and the message arrives 4 times a second; −1 ("stop
    sending": ``interval_ms = 0``) is ACCEPTED, answered −1, and nothing more arrives."""
    name = ON_REQUEST[message_id]
    gcs.send(gcs.command(SET, message_id, 250_000), gcs.command(GET, message_id))
    gcs.run(0.05)
    assert _acks(gcs, SET) == [mav.MAV_RESULT_ACCEPTED]
    assert gcs.last("MESSAGE_INTERVAL").interval_us == 250_000
    gcs.clear()
    gcs.run(2.0)
    assert len(gcs.of(name)) == pytest.approx(8, abs=1)
    gcs.send(gcs.command(SET, message_id, -1), gcs.command(GET, message_id))
    gcs.run(0.05)
    assert gcs.last("MESSAGE_INTERVAL").interval_us == -1
    gcs.clear()
    gcs.run(1.0)
    assert not gcs.of(name)


def test_zero_restores_the_default_which_is_off(gcs: SimGcs) -> None:
    """0 is "reset to default rate": ``get_default_interval_for_ap_message`` finds MSG_HOME in
    no stream, so ``interval_ms = 0`` — off, answered −1."""
    home = mav.MAVLINK_MSG_ID_HOME_POSITION
    gcs.send(gcs.command(SET, home, 100_000), gcs.command(SET, home, 0), gcs.command(GET, home))
    gcs.run(0.05)
    assert _acks(gcs, SET) == [mav.MAV_RESULT_ACCEPTED] * 2
    assert gcs.last("MESSAGE_INTERVAL").interval_us == -1
    gcs.clear()
    gcs.run(1.0)
    assert not gcs.of("HOME_POSITION")


def test_extra1_streams_attitude_without_its_quaternion(gcs: SimGcs) -> None:
    """REQUEST_DATA_STREAM EXTRA1 at 10 Hz: ATTITUDE ten times a second, ATTITUDE_QUATERNION
    never (ArduSub's ``STREAM_EXTRA1_msgs`` does not hold it)."""
    gcs.send(gcs.mav.request_data_stream_encode(1, 1, mav.MAV_DATA_STREAM_EXTRA1, 10, 1))
    gcs.run(0.05)
    gcs.clear()
    gcs.run(2.0)
    assert len(gcs.of("ATTITUDE")) == pytest.approx(20, abs=1)
    assert not gcs.of("ATTITUDE_QUATERNION")
