"""``testbed.run.hil_modem``: the frame ledger and a node's modem on a real port, in plain simpy
time over fake endpoints (no ports, no threads).

Truth is what was sent: frame ids in send order, one sequence for both senders as the simulated
medium gives them; frames handed to the receiving node byte for byte; a frame the port dropped
before it reached the line counted as a drop, never as a loss on the air. The modems over real
ports and emulated links are tested in tests/run/test_realtime.py.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import simpy

from testbed.channel import Delivery, EventKind, Trace
from testbed.protocol import Frame, encode_frame
from testbed.run.hil_modem import FrameLedger, HilModem, poll_modems


def test_ledger_numbers_frames_in_send_order_and_counts_skipped_ones_lost() -> None:
    ledger = FrameLedger()
    ids = [ledger.record_sent("operator", bytes([k]), 0.1 * k) for k in range(3)]
    ids.append(ledger.record_sent("vehicle", b"reply", 0.5))
    assert ids == [0, 1, 2, 3]  # one sequence for both senders, like the medium's
    assert ledger.match("operator", b"\x01") == (1, 0.1 * 1)  # frame 0 was lost
    assert ledger.match("operator", b"\x01") is None  # already matched
    assert ledger.match("operator", b"nothing sent") is None
    assert ledger.match("vehicle", b"reply") == (3, 0.5)
    assert (ledger.matched["operator"], ledger.lost["operator"]) == (1, 1)
    assert ledger.settled("operator") == 2  # frame 2 may still be on its way
    assert ledger.settled("vehicle") == 1


def test_ledger_forgets_beyond_its_horizon_as_lost() -> None:
    ledger = FrameLedger(horizon=4)
    for k in range(6):
        ledger.record_sent("operator", bytes([k]), float(k))
    assert ledger.lost["operator"] == 2
    assert ledger.match("operator", b"\x00") is None
    assert ledger.match("operator", b"\x05") == (5, 5.0)
    assert ledger.settled("operator") == 6


@dataclass
class FakeTransport:
    """Where a port's writer thread leaves the frames it dropped after accepting them."""

    dropped_frames: deque[bytes]


@dataclass
class FakeEndpoint:
    """The part of a LinkEndpoint a HilModem uses: a wire to another fake, no threads."""

    sent: list[bytes]
    peer: FakeEndpoint | None = None
    accept: bool = True
    transport: FakeTransport = field(default_factory=lambda: FakeTransport(deque()))

    def send(self, frame: bytes) -> bool:
        if not self.accept:
            return False
        self.sent.append(frame)
        return True

    def deliver(self, handler: Callable[[Frame], None]) -> int:
        assert self.peer is not None
        frames = [Frame(payload) for payload in _payloads(self.peer.sent)]
        self.peer.sent.clear()
        for frame in frames:
            handler(frame)
        return len(frames)


def _payloads(frames: list[bytes]) -> list[bytes]:
    return [frame[4:-2] for frame in frames]  # WAFrame: 3 preamble + length … CRC-16


def _pair(trace: Trace, outages: list[tuple[float, float]]) -> tuple[HilModem, HilModem]:
    env = simpy.Environment()
    wire_a, wire_b = FakeEndpoint([]), FakeEndpoint([])
    wire_a.peer, wire_b.peer = wire_b, wire_a
    ledger = FrameLedger()
    ends: Any = (wire_a, wire_b)  # fakes standing in for LinkEndpoints
    operator = HilModem(env, "operator", "vehicle", ends[0], trace=trace, ledger=ledger)
    vehicle = HilModem(
        env, "vehicle", "operator", ends[1], trace=trace, ledger=ledger, outages=outages
    )
    return operator, vehicle


def test_modem_hands_each_frame_to_the_node_with_the_senders_frame_id() -> None:
    trace = Trace()
    operator, vehicle = _pair(trace, [])
    got: list[Delivery] = []
    vehicle.on_receive = got.append
    frames = [encode_frame(b"order %d" % k) for k in range(3)]
    for frame in frames:
        assert operator.send(frame)
    sent_ids = [0, 1, 2]
    assert operator.last_frame_id == 2
    assert vehicle.poll() == 3
    assert [d.data for d in got] == frames  # whole frames, byte for byte
    assert [d.frame_id for d in got] == sent_ids
    assert all(d.src == "operator" and (d.part, d.parts) == (0, 1) for d in got)
    kinds = [(e.kind, e.src, e.dst) for e in trace.events]
    assert kinds.count((EventKind.ENQUEUE, "operator", "*")) == 3
    assert kinds.count((EventKind.TX_START, "operator", "*")) == 3
    assert kinds.count((EventKind.DELIVER, "operator", "vehicle")) == 3


def test_modem_refuses_and_discards_in_an_outage_and_reports_drops() -> None:
    trace = Trace()
    operator, vehicle = _pair(trace, [(0.0, 1.0)])
    got: list[Delivery] = []
    vehicle.on_receive = got.append
    operator.send(encode_frame(b"x"))  # the operator has no outage window: it goes out
    assert vehicle.poll() == 1 and got == []  # …and the vehicle discards it in its window
    assert vehicle.send(encode_frame(b"y")) is False
    assert (vehicle.outage_refused, vehicle.outage_discarded) == (1, 1)
    assert len(trace.of_kind(EventKind.OUTAGE)) == 2
    fake: Any = operator.endpoint
    fake.accept = False
    assert operator.send(encode_frame(b"z")) is False
    assert len(trace.of_kind(EventKind.DROP)) == 1


def test_ledger_leaves_a_dropped_frame_out_of_the_settled_ones() -> None:
    ledger = FrameLedger()
    for k in range(3):
        ledger.record_sent("operator", bytes([k]), float(k))
    assert ledger.dropped("operator", b"\x01") == 1
    assert ledger.dropped("operator", b"\x01") == -1  # no longer outstanding
    assert ledger.match("operator", b"\x02") == (2, 2.0)  # frame 0 lost, frame 1 not
    assert (ledger.matched["operator"], ledger.lost["operator"]) == (1, 1)
    assert ledger.settled("operator") == 2


def test_frames_the_port_dropped_are_drops_not_losses_on_the_air() -> None:
    """The port went down under frame 1 (its writer dropped it after accepting it) and frame
    2's queue was full: a review's HIL run counted such frames lost on the air once the port
    came back (PER 11.76 % on a link with no bit error), or not at all when it did not."""
    trace = Trace()
    operator, vehicle = _pair(trace, [])
    got: list[Delivery] = []
    vehicle.on_receive = got.append
    frames = [encode_frame(b"order %d" % k) for k in range(4)]
    fake: Any = operator.endpoint
    assert operator.send(frames[0]) and operator.send(frames[1])
    fake.transport.dropped_frames.append(fake.sent.pop())  # the writer's drop: never written
    fake.accept = False
    assert operator.send(frames[2]) is False  # refused at once: the queue is full
    fake.accept = True
    assert operator.send(frames[3])
    poll_modems([vehicle, operator])  # the vehicle first, as the runs poll
    assert [d.frame_id for d in got] == [0, 3]
    ledger = operator._ledger
    assert ledger.lost.get("operator", 0) == 0 and ledger.settled("operator") == 2
    assert [e.frame_id for e in trace.of_kind(EventKind.DROP)] == [2, 1]
