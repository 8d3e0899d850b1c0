"""testbed.channel.trace: what became of each frame, per packet and per direction, on hand-made
traces whose outcomes are decided by hand.

The trace: the operator sends frames 0–7, 9 and 10 to the vehicle (a buoy listens too), the
vehicle sends frame 8. Packets are 20 B, sent 0.1 s apart, each on the air for 0.1 s.

| frame | packets | what the vehicle (or operator) got        | outcome       | settled |
|-------|---------|-------------------------------------------|---------------|---------|
| 0     | 1       | delivered                                 | delivered     | yes     |
| 1     | 2       | corrupted, collided                       | collided      | yes     |
| 2     | 1       | outage                                    | outage        | yes     |
| 3     | 1       | out of range                              | out_of_range  | yes     |
| 4     | -       | dropped by the full FIFO                  | dropped       | no      |
| 5     | 2       | delivered, second still on the air at end | pending       | no      |
| 6     | 2       | corrupted, second still on the air at end | corrupted     | no      |
| 7     | -       | still queued at the end                   | pending       | no      |
| 8     | 1       | operator: delivered; buoy: collided       | collided      | yes     |
| 9     | 2       | outage, corrupted                         | outage        | yes     |
| 10    | 2       | out of range, outage                      | outage        | yes     |
"""

from __future__ import annotations

import math

import pytest

from testbed.channel import (
    DirectionCounts,
    EventKind,
    FrameOutcome,
    LinkEvent,
    Trace,
    direction_counts,
    frame_outcomes,
    transmissions,
)
from tests.interrupts import interrupt_at_line

K = EventKind
F = FrameOutcome
OP, VEH, BUOY, ALL = "operator", "vehicle", "buoy", "*"
PACKET_BYTES = 20


def _frame(t_s: float, src: str, frame_id: int, packets: int, *, ended: int) -> list[LinkEvent]:
    """Enqueue ``frame_id`` and start ``packets`` packets 0.1 s apart; the first ``ended`` of
    them also finish (the rest are on the air when the trace stops)."""
    events = [LinkEvent(t_s, K.ENQUEUE, src, ALL, frame_id, 0, PACKET_BYTES * packets)]
    for part in range(packets):
        start = t_s + 0.1 * part
        events.append(LinkEvent(start, K.TX_START, src, ALL, frame_id, part, PACKET_BYTES))
        if part < ended:
            end = LinkEvent(start + 0.1, K.TX_END, src, ALL, frame_id, part, PACKET_BYTES)
            events.append(end)
    return events


RECEIVED = {  # frame id → (kind, receiver, packet) of every copy that reached a receiver
    0: [(K.DELIVER, VEH, 0)],
    1: [(K.CORRUPT, VEH, 0), (K.COLLIDE, VEH, 1)],
    2: [(K.OUTAGE, VEH, 0)],
    3: [(K.OUT_OF_RANGE, VEH, 0)],
    5: [(K.DELIVER, VEH, 0)],
    6: [(K.CORRUPT, VEH, 0)],
    8: [(K.DELIVER, OP, 0), (K.COLLIDE, BUOY, 0)],
    9: [(K.OUTAGE, VEH, 0), (K.CORRUPT, VEH, 1)],
    10: [(K.OUT_OF_RANGE, VEH, 0), (K.OUTAGE, VEH, 1)],
}
SENT = [  # (t_s, sender, frame id, packets started, packets finished), in time order
    (0.0, OP, 0, 1, 1),
    (1.0, OP, 1, 2, 2),
    (2.0, OP, 2, 1, 1),
    (3.0, OP, 3, 1, 1),
    (5.0, VEH, 8, 1, 1),
    (6.0, OP, 9, 2, 2),
    (7.0, OP, 10, 2, 2),
    (9.0, OP, 5, 2, 1),
    (9.5, OP, 6, 2, 1),
]


def hand_made_events() -> list[LinkEvent]:
    """The trace of the table in this module's docstring: each packet's copies arrive as it
    ends (frame 4 is dropped at 4.0 s, frame 7 queued at 9.9 s)."""
    events = []
    for t_s, src, frame_id, packets, ended in SENT:
        events += _frame(t_s, src, frame_id, packets, ended=ended)
        for kind, dst, part in RECEIVED.get(frame_id, []):
            bits = 3 if kind is K.CORRUPT else 0
            arrival = t_s + 0.1 * (part + 1)
            events.append(LinkEvent(arrival, kind, src, dst, frame_id, part, PACKET_BYTES, bits))
    events += [
        LinkEvent(4.0, K.ENQUEUE, OP, ALL, 4, 0, 100),
        LinkEvent(4.0, K.DROP, OP, ALL, 4, 0, 100),
        LinkEvent(9.9, K.ENQUEUE, OP, ALL, 7, 0, 40),
    ]
    return events


EXPECTED = {
    0: F.DELIVERED,
    1: F.COLLIDED,
    2: F.OUTAGE,
    3: F.OUT_OF_RANGE,
    4: F.DROPPED,
    5: F.PENDING,
    6: F.CORRUPTED,
    7: F.PENDING,
    8: F.COLLIDED,
    9: F.OUTAGE,
    10: F.OUTAGE,
}


# --- frame outcomes -----------------------------------------------------------------------------


def test_frame_outcomes_match_the_hand_classified_trace() -> None:
    assert frame_outcomes(hand_made_events()) == EXPECTED


def test_frame_outcomes_do_not_depend_on_recording_order() -> None:
    assert frame_outcomes(reversed(hand_made_events())) == EXPECTED


def test_a_loss_only_trace_still_classifies_its_lost_frames() -> None:
    trace = Trace(kinds=(K.COLLIDE, K.OUT_OF_RANGE))
    for event in hand_made_events():
        trace.record(*event)
    # frame 10's outage was not recorded: its one known packet makes it out of range
    expected = {1: F.COLLIDED, 3: F.OUT_OF_RANGE, 8: F.COLLIDED, 10: F.OUT_OF_RANGE}
    assert frame_outcomes(trace) == expected
    assert transmissions(trace) == []


# --- transmissions ------------------------------------------------------------------------------


def test_transmissions_pair_starts_with_ends_and_keep_each_packets_own_outcome() -> None:
    sent = transmissions(hand_made_events())
    assert len(sent) == 14  # frames 0, 2, 3, 8 one packet each; 1, 5, 6, 9, 10 two each
    assert [x.start_s for x in sent] == sorted(x.start_s for x in sent)
    by_packet = {(x.frame_id, x.part): x for x in sent}
    assert by_packet[1, 0].outcome is F.CORRUPTED and by_packet[1, 1].outcome is F.COLLIDED
    assert by_packet[8, 0].outcome is F.COLLIDED  # worst over the operator and the buoy
    assert by_packet[10, 0].outcome is F.OUT_OF_RANGE and by_packet[10, 1].outcome is F.OUTAGE
    assert by_packet[5, 0].outcome is F.DELIVERED and by_packet[5, 1].outcome is F.PENDING
    assert by_packet[1, 1].start_s == pytest.approx(1.1)
    assert by_packet[1, 1].end_s == pytest.approx(1.2)
    assert by_packet[6, 1].end_s == by_packet[6, 1].start_s == pytest.approx(9.6)  # no tx_end
    assert (by_packet[8, 0].src, by_packet[8, 0].size_bytes) == (VEH, PACKET_BYTES)
    assert not {4, 7} & {x.frame_id for x in sent}  # dropped or queued: never on the air


# --- per-direction counts -----------------------------------------------------------------------


def test_direction_counts_of_the_operators_frames_at_the_vehicle() -> None:
    counts = direction_counts(hand_made_events(), OP, VEH)
    assert counts == DirectionCounts(
        frames_sent=10,  # every enqueue: frames 0-7, 9, 10
        frames_dropped=1,  # 4
        frames_collided=1,  # 1 (collided beats its corrupted packet)
        frames_outage=3,  # 2, 9 (beats corrupted), 10 (beats out of range)
        frames_out_of_range=1,  # 3
        frames_corrupted=1,  # 6, although its second packet is still on the air
        frames_settled=6,  # 0, 1, 2, 3, 9, 10; not 5 and 6 (on the air), 4 and 7 (never sent)
        mean_on_air_bytes=(20 + 40 + 20 + 20 + 100 + 40 + 40 + 40 + 40 + 40) / 10,
    )


def test_direction_counts_take_only_the_named_receivers_copies() -> None:
    at_operator = direction_counts(hand_made_events(), VEH, OP)
    at_buoy = direction_counts(hand_made_events(), VEH, BUOY)
    assert (at_operator.frames_sent, at_operator.frames_settled) == (1, 1)
    assert at_operator.frames_collided == 0  # the buoy's collision is not the operator's
    assert (at_buoy.frames_sent, at_buoy.frames_settled, at_buoy.frames_collided) == (1, 1, 1)
    nothing_heard = direction_counts(hand_made_events(), OP, BUOY)
    assert (nothing_heard.frames_sent, nothing_heard.frames_dropped) == (10, 1)
    assert nothing_heard.frames_settled == 0  # the buoy received none of the operator's packets
    assert nothing_heard.frames_collided == nothing_heard.frames_corrupted == 0


def test_direction_counts_of_an_empty_trace() -> None:
    counts = direction_counts(Trace(), OP, VEH)
    assert (counts.frames_sent, counts.frames_settled, counts.frames_dropped) == (0, 0, 0)
    assert math.isnan(counts.mean_on_air_bytes)


def test_an_interrupt_anywhere_in_a_flush_loses_and_repeats_no_event() -> None:
    # Ctrl-C (or the CLI's SIGTERM) raises where the program is; a run it ends writes its
    # trace. Whatever line of the flush it lands on, the trace then holds every event recorded,
    # each once, in order, its columns of one length, and it records on.
    names = ["operator", "vehicle", "buoy", "relay"]
    truth = [  # a node first heard in the interrupted chunk ("glider"): its name is coded then
        LinkEvent(0.01 * i, K.TX_START, src, names[(i + 1) % 4], i, i % 3, 20 + i % 40)
        for i in range(3000)
        for src in ["glider" if i >= 2500 and i % 7 == 0 else names[i % 4]]
    ]
    k = 1
    while True:
        trace = Trace()
        for event in truth[:1500]:
            trace.record(*event)
        trace.columns()  # the first half in the columns (and a view of them held)
        for event in truth[1500:2999]:
            trace.record(*event)
        with interrupt_at_line(k, Trace._flush) as seen:
            trace.record(*truth[2999])
            trace.columns()  # flushes, unless an interrupt landed before it did
        assert list(trace.events) == truth, k
        columns = trace.columns()
        assert len(columns.t_s) == len(columns.frame_id) == len(columns.bit_errors) == 3000
        extra = LinkEvent(99.0, K.DELIVER, "vehicle", "operator", 9999, 0, 13)
        trace.record(*extra)
        assert list(trace.events) == [*truth, extra] and len(trace) == 3001
        if not seen["raised"]:  # past the flush's last line: every line has been tried
            break
        k += 1
    assert k > 20  # the flush and what it calls ran that many lines, each interrupted once


def test_a_copy_lost_to_a_deaf_receiver_is_a_collided_frame() -> None:
    """``deaf`` (the half-duplex receiver was transmitting) loses the frame as a collision does:
    ``collided`` in the outcomes and the counts, and it outranks a corrupted packet."""
    events = [
        *_frame(0.0, OP, 0, 1, ended=1),
        LinkEvent(0.1, K.DEAF, OP, VEH, 0, 0, PACKET_BYTES),
        *_frame(1.0, OP, 1, 2, ended=2),
        LinkEvent(1.1, K.CORRUPT, OP, VEH, 1, 0, PACKET_BYTES, 2),
        LinkEvent(1.2, K.DEAF, OP, VEH, 1, 1, PACKET_BYTES),
        *_frame(2.0, OP, 2, 1, ended=1),
        LinkEvent(2.1, K.DELIVER, OP, VEH, 2, 0, PACKET_BYTES),
    ]
    assert frame_outcomes(events) == {0: F.COLLIDED, 1: F.COLLIDED, 2: F.DELIVERED}
    counts = direction_counts(events, OP, VEH)
    assert (counts.frames_collided, counts.frames_corrupted, counts.frames_settled) == (2, 0, 3)
