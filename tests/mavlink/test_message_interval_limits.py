"""SET_MESSAGE_INTERVAL with an interval past the int32 of MESSAGE_INTERVAL, by pymavlink.

Independent truth: ArduPilot 4.5's ``GCS_MAVLINK::set_message_interval`` (``GCS_Common.cpp``)
reads param2 as an int32 and sets ``interval_ms = 60000`` for any ``interval_us`` above
60 000 000, so GET_MESSAGE_INTERVAL then answers 60 000 000 µs. A garbled or careless
ground station's 3e9 µs or 1e30 µs must be ACCEPTED as that cap, and the answer to a later
GET_MESSAGE_INTERVAL must be a MESSAGE_INTERVAL pymavlink decodes (its ``interval_us`` is an
int32), not an exception out of the endpoint.
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mav

from tests.mavlink.gcs import SimGcs

ARDUPILOT_CAP_US = 60_000_000  # interval_us > 60000000 → interval_ms = 60000


@pytest.fixture
def gcs() -> Iterator[SimGcs]:
    station = SimGcs()
    yield station
    station.close()


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
