"""HEARTBEAT's rate per link, set and read by SET/GET_MESSAGE_INTERVAL, as ArduPilot does it.

Independent truth, ArduPilot's ``libraries/GCS_MAVLink`` (a 4.5 branch; the newest stored
master-era copy agrees on all of this): ``mavlink_id_to_ap_message_id`` maps HEARTBEAT to
MSG_HEARTBEAT, one of ``GCS.h``'s ``deferred_message[]`` (heartbeat, next param, HIGH_LATENCY2);
``initialise_message_intervals_from_streamrates`` sets it to 1000 ms on every link but a
high-latency one. ``set_message_interval`` takes param2 as for any message (0: the default,
which ``get_default_interval_for_ap_message`` gives as 1000 ms for MSG_HEARTBEAT; −1: 0 ms,
stop) and ``set_ap_message_interval`` stores it in that link's deferred message, stamping
``last_sent_ms`` now (so the next heartbeat is one interval later) and answers ACCEPTED;
``handle_command_get_message_interval`` answers ``interval_ms * 1000``, or −1 for 0. The
endpoint used to answer SET UNSUPPORTED and GET 0.
"""

from __future__ import annotations

from itertools import pairwise
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mav

from tests.mavlink.gcs import FRAME_S, SimGcs

HEARTBEAT = mav.MAVLINK_MSG_ID_HEARTBEAT


class _OtherLink:
    """A second link on the same endpoint, decoded by pymavlink after every step."""

    def __init__(self, gcs: SimGcs) -> None:
        self.channel = gcs.endpoint.open_channel("other")
        self.decoder = mav.MAVLink(None)
        self.heartbeat_steps: list[int] = []

    def restart(self) -> None:
        """Forget what it got so far (and what is queued for it)."""
        self.channel.take()
        self.heartbeat_steps.clear()

    def collect(self, k: int) -> None:
        for packet in self.channel.take():
            for m in self.decoder.parse_buffer(packet) or []:
                if m.get_type() == "HEARTBEAT":
                    self.heartbeat_steps.append(k)


def _heartbeat_steps(gcs: SimGcs, seconds: float, other: _OtherLink | None = None) -> list[int]:
    """Run ``seconds``; the steps at which this link (and ``other``) got a HEARTBEAT."""
    steps: list[int] = []
    for k in range(round(seconds / FRAME_S)):
        before = len(gcs.messages)
        gcs.step()
        steps += [k for m in gcs.messages[before:] if m.get_type() == "HEARTBEAT"]
        if other is not None:
            other.collect(k)
    return steps


def _gaps(steps: list[int]) -> set[int]:
    return {b - a for a, b in pairwise(steps)}


def _ask(gcs: SimGcs, *commands: Any) -> tuple[dict[int, int], Any]:
    """Send ``commands`` in one step; the ACK results by command and the last MESSAGE_INTERVAL."""
    gcs.clear()
    gcs.send(*commands)
    gcs.step()
    acks = {m.command: m.result for m in gcs.of("COMMAND_ACK")}
    intervals = gcs.of("MESSAGE_INTERVAL")
    return acks, intervals[-1] if intervals else None


def _get(gcs: SimGcs) -> Any:
    return gcs.command(mav.MAV_CMD_GET_MESSAGE_INTERVAL, HEARTBEAT)


def _set(gcs: SimGcs, interval_us: float) -> Any:
    return gcs.command(mav.MAV_CMD_SET_MESSAGE_INTERVAL, HEARTBEAT, interval_us)


def test_get_reads_back_the_one_second_default(gcs: SimGcs) -> None:
    acks, answer = _ask(gcs, _get(gcs))
    assert acks[mav.MAV_CMD_GET_MESSAGE_INTERVAL] == mav.MAV_RESULT_ACCEPTED
    assert (answer.message_id, answer.interval_us) == (HEARTBEAT, 1_000_000)


def test_set_changes_this_links_heartbeat_only(gcs: SimGcs) -> None:
    """250 ms on this link: ACCEPTED, read back as 250 000 µs, the first heartbeat one interval
    after the command and then every 25 frames (± 1: the vehicle's frames land near the 10-ms
    grid, not on it); the other link keeps its 1 Hz."""
    other = _OtherLink(gcs)
    _heartbeat_steps(gcs, 0.5, other)
    acks, answer = _ask(gcs, _set(gcs, 250_000), _get(gcs))
    assert acks[mav.MAV_CMD_SET_MESSAGE_INTERVAL] == mav.MAV_RESULT_ACCEPTED
    assert acks[mav.MAV_CMD_GET_MESSAGE_INTERVAL] == mav.MAV_RESULT_ACCEPTED
    assert answer.interval_us == 250_000
    other.restart()
    steps = _heartbeat_steps(gcs, 4.0, other)  # step 0 here is 1 frame after the command
    assert 23 <= steps[0] <= 25  # one interval (25 frames) after the command's frame
    assert _gaps(steps) <= {24, 25, 26} and len(steps) == 16
    assert _gaps(other.heartbeat_steps) <= {99, 100, 101} and len(other.heartbeat_steps) == 4


def test_minus_one_stops_it_and_zero_restores_the_second(gcs: SimGcs) -> None:
    """−1: no heartbeat on this link (GET −1), the other link unaffected; 0: back to the 1-s
    default (GET 1 000 000), its first one a second after the command."""
    other = _OtherLink(gcs)
    _heartbeat_steps(gcs, 0.5, other)
    acks, answer = _ask(gcs, _set(gcs, -1), _get(gcs))
    assert acks[mav.MAV_CMD_SET_MESSAGE_INTERVAL] == mav.MAV_RESULT_ACCEPTED
    assert answer.interval_us == -1
    other.restart()
    assert _heartbeat_steps(gcs, 3.0, other) == []
    assert len(other.heartbeat_steps) == 3
    acks, answer = _ask(gcs, _set(gcs, 0), _get(gcs))
    assert acks[mav.MAV_CMD_SET_MESSAGE_INTERVAL] == mav.MAV_RESULT_ACCEPTED
    assert answer.interval_us == 1_000_000
    steps = _heartbeat_steps(gcs, 3.2)  # step 0 here is 1 frame after the command
    assert len(steps) == 3 and 98 <= steps[0] <= 100 and _gaps(steps) <= {99, 100, 101}


def test_a_sub_millisecond_request_is_kept_as_ardupilot_keeps_it(gcs: SimGcs) -> None:
    """500 µs is 1 ms ("don't squash sub-ms times to zero"), kept as 3 ms (80 % of the 400-Hz
    loop, ``set_ap_message_interval``'s cap): GET answers 3000; the endpoint serves 50 Hz."""
    _, answer = _ask(gcs, _set(gcs, 500), _get(gcs))
    assert answer.interval_us == 3_000
    steps = _heartbeat_steps(gcs, 2.0)
    assert _gaps(steps) <= {1, 2, 3} and 98 <= len(steps) <= 100  # 20 ms apart on average
