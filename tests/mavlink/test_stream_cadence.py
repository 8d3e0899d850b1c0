"""A stream group's messages go out every ArduPilot's whole milliseconds.

Independent truth: ArduPilot 4.5's ``GCS_Common.cpp``. ``GCS_MAVLINK::get_interval_for_stream``
keeps a group at ``rate`` Hz as ``interval_ms = 1000 / rate`` in integers (SR0_POSITION's 3 Hz:
333 ms; 7 Hz: 142 ms), and ``update_send`` reschedules the bucket by that many milliseconds::

    const uint16_t interval_ms = get_reschedule_interval_ms(
        deferred_message_bucket[sending_bucket_id]);
    deferred_message_bucket[sending_bucket_id].last_sent_ms += interval_ms;

so the 31st GLOBAL_POSITION_INT at 3 Hz is due 30 × 333 = 9990 ms after the first, not
10 000 ms (every 1/3 s, as the endpoint used to serve it), and at 7 Hz a minute holds
60 000 / 142 = 422.5 intervals, not 420.
"""

from __future__ import annotations

from pymavlink.dialects.v20 import ardupilotmega as mav

from testbed.mavlink.streams import StreamSchedule
from tests.mavlink.gcs import SimGcs


def test_sr0_positions_3_hz_is_due_every_333_ms() -> None:
    """SR0_POSITION's 3 Hz, asked of the schedule every millisecond: the 31st
    GLOBAL_POSITION_INT is due 9990 ms after the first."""
    schedule = StreamSchedule({6: 3.0})
    due_ms = [k for k in range(12_000) if "GLOBAL_POSITION_INT" in schedule.due(k / 1000)]
    assert due_ms[30] - due_ms[0] == 30 * 333


def test_request_data_stream_at_7_hz_is_sent_every_142_ms(gcs: SimGcs) -> None:
    """REQUEST_DATA_STREAM EXTRA1 at 7 Hz, then a minute: the ATTITUDEs sent are one more than
    the whole 142-ms intervals between the first and the last (each goes out at the first
    ~10-ms step at or after it is due, so the span overruns its intervals by less than one).
    Every 1/7 s (142.857 ms) a minute's 420 intervals span 60 000 ms, 422 whole 142-ms ones."""
    stream = gcs.mav.request_data_stream_encode(1, 1, mav.MAV_DATA_STREAM_EXTRA1, 7, 1)
    gcs.send(stream)
    gcs.run(60.0)
    times = [m.time_boot_ms for m in gcs.of("ATTITUDE")]
    assert len(times) == (times[-1] - times[0]) // 142 + 1
