"""SET_MESSAGE_INTERVAL's param2 read as ArduPilot reads it, by pymavlink.

Independent truth: ArduPilot 4.5's ``GCS_MAVLINK::handle_command_set_message_interval`` and
``set_message_interval`` (``GCS_Common.cpp``), restated: param2 is cast to an int32 (toward 0);
0 is "reset to default rate", −1 "stop sending", any other value below 1000 µs — a negative
one too — 1 ms ("don't squash sub-ms times to zero"), above 60 000 000 µs 60 000 ms, else
``interval_us / 1000`` in integer milliseconds; ``set_ap_message_interval`` keeps at least 80 %
of the 400-Hz loop period (1–3 ms → 3 ms); GET_MESSAGE_INTERVAL answers the interval kept,
``interval_ms * 1000``. A garbled or careless ground station's 3e9 µs or 1e30 µs must be
ACCEPTED as the minute's cap, and the answer to a later GET_MESSAGE_INTERVAL must be a
MESSAGE_INTERVAL pymavlink decodes (its ``interval_us`` is an int32), not an exception out of
the endpoint. The endpoint serves at most 50 Hz (docs/mavlink.md), so ArduPilot's 3 ms is sent
every 20 ms, while GET_MESSAGE_INTERVAL answers 3000 µs as ArduPilot would.
"""

from __future__ import annotations

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mav

from tests.mavlink.gcs import SimGcs

ARDUPILOT_CAP_US = 60_000_000  # interval_us > 60000000 → interval_ms = 60000
FASTEST_SERVED_US = 20_000  # the endpoint's 50 Hz, where ArduPilot's 1 ms is served
ARDUPILOT_FLOOR_US = 3_000  # 2500 µs loop / 800, in a uint16: what ArduPilot keeps for 1 ms
ATTITUDE = mav.MAVLINK_MSG_ID_ATTITUDE


@pytest.mark.parametrize("message_id", [mav.MAVLINK_MSG_ID_ATTITUDE, 235])  # 235: HIGH_LATENCY2
@pytest.mark.parametrize("interval_us", [61e6, 3e9, 1e30])
def test_an_interval_past_a_minute_is_a_minute_and_answered_as_one(
    gcs: SimGcs, message_id: int, interval_us: float
) -> None:
    set_interval = mav.MAV_CMD_SET_MESSAGE_INTERVAL
    gcs.send(gcs.command(set_interval, message_id, interval_us))
    gcs.send(gcs.command(mav.MAV_CMD_GET_MESSAGE_INTERVAL, message_id))
    gcs.run(0.05)
    acks = {m.command: m.result for m in gcs.of("COMMAND_ACK")}
    assert acks[set_interval] == mav.MAV_RESULT_ACCEPTED
    assert acks[mav.MAV_CMD_GET_MESSAGE_INTERVAL] == mav.MAV_RESULT_ACCEPTED
    answer = gcs.last("MESSAGE_INTERVAL")
    assert (answer.message_id, answer.interval_us) == (message_id, ARDUPILOT_CAP_US)


def test_an_interval_within_the_minute_is_kept(gcs: SimGcs) -> None:
    """Below the cap ArduPilot keeps the interval (59 000 000 µs / 1000 → 59 000 ms)."""
    gcs.send(gcs.command(mav.MAV_CMD_SET_MESSAGE_INTERVAL, mav.MAVLINK_MSG_ID_ATTITUDE, 59e6))
    gcs.send(gcs.command(mav.MAV_CMD_GET_MESSAGE_INTERVAL, mav.MAVLINK_MSG_ID_ATTITUDE))
    gcs.run(0.05)
    assert gcs.last("MESSAGE_INTERVAL").interval_us == 59_000_000


def _set_then_get(gcs: SimGcs, interval_us: float) -> tuple[int, int]:
    """SET_MESSAGE_INTERVAL of ATTITUDE then GET_MESSAGE_INTERVAL: (the set's ACK result, the
    interval answered [µs])."""
    gcs.clear()
    gcs.send(gcs.command(mav.MAV_CMD_SET_MESSAGE_INTERVAL, ATTITUDE, interval_us))
    gcs.send(gcs.command(mav.MAV_CMD_GET_MESSAGE_INTERVAL, ATTITUDE))
    gcs.run(0.05)
    acks = {m.command: m.result for m in gcs.of("COMMAND_ACK")}
    return acks[mav.MAV_CMD_SET_MESSAGE_INTERVAL], gcs.last("MESSAGE_INTERVAL").interval_us


@pytest.mark.parametrize("interval_us", [-2.0, -999.0, -1000.0, -5e6, -3e9])
def test_a_negative_interval_other_than_minus_one_is_as_fast_as_served(
    gcs: SimGcs, interval_us: float
) -> None:
    """ArduPilot: a negative interval other than −1 is below 1000, so 1 ms — the message as
    fast as it goes, not off (it used to be switched off): ATTITUDE then arrives at the
    endpoint's 50 Hz, and GET_MESSAGE_INTERVAL answers the 3 ms ArduPilot keeps."""
    assert _set_then_get(gcs, interval_us) == (mav.MAV_RESULT_ACCEPTED, ARDUPILOT_FLOOR_US)
    gcs.clear()
    gcs.run(1.0)
    assert len(gcs.of("ATTITUDE")) == pytest.approx(1e6 / FASTEST_SERVED_US, abs=1)


@pytest.mark.parametrize(
    ("interval_us", "kept_us"),
    [(1_000, 3_000), (2_999, 3_000), (3_999, 3_000), (4_000, 4_000), (19_999, 19_000)],
)
def test_get_answers_the_interval_ardupilot_keeps_while_50_hz_is_served(
    gcs: SimGcs, interval_us: float, kept_us: int
) -> None:
    """ArduPilot's ``set_ap_message_interval`` keeps what was asked (whole ms) unless it is
    faster than 80 % of the loop rate: ``interval_ms * 800 < loop_period_us`` (2500 µs, ArduSub's
    400 Hz: ``AP_Scheduler``) makes it ``2500 / 800.0f`` = 3.125 → 3 ms; its
    ``handle_command_get_message_interval`` answers that × 1000. So 1–3 ms is answered 3000 µs
    (it was the endpoint's 20 000 µs cap), 4–19 ms as asked, while ATTITUDE still arrives at
    the endpoint's 50 Hz."""
    assert _set_then_get(gcs, interval_us) == (mav.MAV_RESULT_ACCEPTED, kept_us)
    gcs.clear()
    gcs.run(1.0)
    assert len(gcs.of("ATTITUDE")) == pytest.approx(1e6 / FASTEST_SERVED_US, abs=1)
    gcs.send(gcs.command(mav.MAV_CMD_GET_MESSAGE_INTERVAL, ATTITUDE))
    gcs.run(0.05)
    assert gcs.last("MESSAGE_INTERVAL").interval_us == kept_us  # still, while served at 50 Hz
    gcs.send(gcs.mav.request_data_stream_encode(1, 1, mav.MAV_DATA_STREAM_EXTRA1, 4, 1))
    gcs.send(gcs.command(mav.MAV_CMD_GET_MESSAGE_INTERVAL, ATTITUDE))
    gcs.run(0.05)
    assert gcs.last("MESSAGE_INTERVAL").interval_us == 250_000  # the group's rate replaces it


def test_param2_is_cast_to_an_int32_toward_zero_first(gcs: SimGcs) -> None:
    """(int32_t)param2 before the rules: −1.5 is −1, off; ±0.5 is 0, the default (the boot
    interval answered before anything was set); 25 999 µs is 25 ms (integer milliseconds)."""
    gcs.send(gcs.command(mav.MAV_CMD_GET_MESSAGE_INTERVAL, ATTITUDE))
    gcs.run(0.05)
    default_us = gcs.last("MESSAGE_INTERVAL").interval_us
    assert default_us > FASTEST_SERVED_US  # SR0_EXTRA1's boot rate, slower than 50 Hz
    accepted = mav.MAV_RESULT_ACCEPTED
    assert _set_then_get(gcs, -1.5) == (accepted, -1)
    gcs.clear()
    gcs.run(0.5)
    assert not gcs.of("ATTITUDE")
    assert _set_then_get(gcs, 0.5) == (accepted, default_us)
    assert _set_then_get(gcs, 25_999.0) == (accepted, 25_000)
    assert _set_then_get(gcs, -0.5) == (accepted, default_us)


def _results(gcs: SimGcs, command: int) -> list[int]:
    return [m.result for m in gcs.of("COMMAND_ACK") if m.command == command]


def test_an_unknown_message_id_is_denied_as_in_ardusub_4_5_and_is_said(gcs: SimGcs) -> None:
    """ArduPilot 4.5's ``set_message_interval`` for an id with no ``ap_message`` (9999, or
    STATUSTEXT 253, which is never streamed) says "No ap_message for mavlink id (N)" before it
    reads the interval and answers MAV_RESULT_DENIED, param2 0 too (it was UNSUPPORTED, unsaid;
    MAVSDK's integration logs against ArduPilot show the same "Command Denied" beside that text).
    ``handle_command_get_message_interval`` answers such an id MESSAGE_INTERVAL 0 ("not
    available") and FAILED (it was UNSUPPORTED with no MESSAGE_INTERVAL), an id past the uint16
    field cut to it (70 000 → 4464)."""
    set_interval, get_interval = mav.MAV_CMD_SET_MESSAGE_INTERVAL, mav.MAV_CMD_GET_MESSAGE_INTERVAL
    gcs.send(gcs.command(set_interval, 9999, 100_000))
    gcs.send(gcs.command(set_interval, mav.MAVLINK_MSG_ID_STATUSTEXT, 100_000))
    gcs.send(gcs.command(set_interval, 9999, 0))
    gcs.run(0.05)
    assert _results(gcs, set_interval) == [mav.MAV_RESULT_DENIED] * 3
    texts = [m.text for m in gcs.of("STATUSTEXT") if m.text.startswith("No ap_message")]
    assert texts == [f"No ap_message for mavlink id ({n})" for n in (9999, 253, 9999)]
    assert {m.severity for m in gcs.of("STATUSTEXT")} == {mav.MAV_SEVERITY_INFO}
    gcs.clear()
    gcs.send(gcs.command(get_interval, 9999), gcs.command(get_interval, 70_000))
    gcs.run(0.05)
    assert _results(gcs, get_interval) == [mav.MAV_RESULT_FAILED] * 2
    answers = [(m.message_id, m.interval_us) for m in gcs.of("MESSAGE_INTERVAL")]
    assert answers == [(9999, 0), (70_000 & 0xFFFF, 0)]
    assert _set_then_get(gcs, 100_000) == (mav.MAV_RESULT_ACCEPTED, 100_000)  # a known one still


def test_a_group_rate_is_answered_as_ardupilots_whole_milliseconds(gcs: SimGcs) -> None:
    """A message streamed at its group's rate is answered as ArduPilot keeps it:
    ``get_interval_for_stream`` is ``1000 / rate`` in integers, so GLOBAL_POSITION_INT at
    SR0_POSITION's 3 Hz is 333 000 µs (it was 333 333), ATTITUDE after REQUEST_DATA_STREAM
    EXTRA1 at 7 Hz 142 000 (was 142 857) and at 100 Hz 10 000 — while served at 50 Hz (it was
    answered as the cap, 20 000)."""
    get_interval = mav.MAV_CMD_GET_MESSAGE_INTERVAL
    gcs.send(gcs.command(get_interval, mav.MAVLINK_MSG_ID_GLOBAL_POSITION_INT))
    gcs.run(0.05)
    assert gcs.last("MESSAGE_INTERVAL").interval_us == 333_000
    for rate_hz, answer_us in ((7, 142_000), (100, 10_000)):
        gcs.clear()
        gcs.send(gcs.mav.request_data_stream_encode(1, 1, mav.MAV_DATA_STREAM_EXTRA1, rate_hz, 1))
        gcs.send(gcs.command(get_interval, ATTITUDE))
        gcs.run(1.0)
        assert gcs.last("MESSAGE_INTERVAL").interval_us == answer_us
        assert len(gcs.of("ATTITUDE")) == pytest.approx(min(rate_hz, 50), abs=1)
