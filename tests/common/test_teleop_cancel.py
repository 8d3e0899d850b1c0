"""The order header's "cancel last order" bit against a vehicle without autonomy.

The protocol's handshake (REFERENCE §1.3–1.4; docs/autonomy.md, "Supervised control over the
link"): a cancel raises bit 6 of the order header's byte 1 on the orders after it until a reply
says the last order was cancelled (bit 5 of the state's flags), then the bit goes down; the
vehicle cancels on the bit's rising edge. A vehicle with no mission to drop (s100-teleop-v1's
BlueROV2: no autonomy, no ``MissionStatus``) has honoured a cancel once it applied it. Its
replies used to say "not cancelled" for ever, so after one cancel the bit stayed up on every
order of the run, and a second cancel with no goal between was no rising edge: lost.

The end-to-end test reads the frames off the simulated wire (the bytes each modem was handed,
parsed by hand: preamble, length, payload, CRC-16/XMODEM checked bit by bit) and times them by
the channel's trace; the vehicle's own count of the cancels it applied is the other judge.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import pytest

from testbed.channel import EventKind, Modem
from testbed.common.components import (
    GoalCancel,
    MissionStatus,
    PositionReading,
    PositionSetpoint,
)
from testbed.common.teleop import TeleopOperatorEnd, TeleopVehicleEnd
from testbed.ecs import Entity, World
from testbed.protocol import DisableKeepHeading, GoTo, Mode, Move, OperatorMessage
from testbed.run import links
from testbed.run.runner import RunResult, run_scenario
from testbed.run.scenario import load_scenario
from tests.strategies import crc16_bitwise

PREAMBLE = b"\x55\x55\x55"  # the default 3-byte preamble (REFERENCE §1.6)
MOVE, GOTO = 1, 6  # order types (header byte 1, bits 3..0)
CANCELS_S = (15.0, 25.0, 45.0)  # the second follows the first with no goal between
GOALS_S = (5.0, 35.0)
SUPERVISOR = """[pilot]
kind = "supervisor"
start_s = 0.0
goals = [
    { t_s = 5.0, position_ned_m = [1.0, 0.0, 1.0], yaw_deg = 0.0 },
    { t_s = 15.0, cancel = true },
    { t_s = 25.0, cancel = true },
    { t_s = 35.0, position_ned_m = [0.0, 0.0, 1.0] },
    { t_s = 45.0, cancel = true },
]

"""


@dataclass(frozen=True)
class Sent:
    """One frame on the wire: when it was queued and delivered [s], and its payload."""

    queued_s: float
    delivered_s: float
    payload: bytes


def payload_of(frame: bytes) -> bytes:
    """The payload of one whole frame, its preamble, length and CRC checked."""
    assert frame[:3] == PREAMBLE
    length = frame[3]
    assert len(frame) >= 4 + length + 2
    body = frame[: 4 + length]
    assert int.from_bytes(frame[4 + length : 6 + length], "big") == crc16_bitwise(body)
    return body[4:]


def cancel_bit(order: bytes) -> bool:
    return bool(order[1] & 0x40)


def order_type(order: bytes) -> int:
    return order[1] & 0x0F


def cancelled_flag(reply: bytes) -> bool:
    """Bit 5 of the state's flags byte (the reply's byte 1: byte 0 is the chunk flags)."""
    return bool(reply[1] & 0x20)


@pytest.fixture(scope="module")
def cancels_run(
    tmp_path_factory: pytest.TempPathFactory,
) -> tuple[RunResult, list[Sent], list[Sent], list[TeleopVehicleEnd]]:
    """s100-teleop-v1 at BER 0 with a supervisor: two GoTos and three cancels, 55 s."""
    text = resources.files("testbed").joinpath("scenarios", "s100-teleop-v1.toml").read_text()
    text = re.sub(r"\[pilot\].*?(?=\[metrics\])", SUPERVISOR, text, flags=re.DOTALL)
    path = Path(tmp_path_factory.mktemp("cancel")) / "s100-teleop-v1.toml"
    path.write_text(text, encoding="utf-8")
    scenario = load_scenario(str(path), ["duration_s=55", "link.ber=0", "metrics.settle_s=0"])
    frames: dict[int, tuple[str, bytes]] = {}
    ends: list[TeleopVehicleEnd] = []
    send = Modem.send

    def recording_send(self: Modem, data: bytes) -> bool:
        queued = send(self, data)
        frames[self.last_frame_id] = (self.name, bytes(data))
        return queued

    class RecordedEnd(TeleopVehicleEnd):
        def __init__(self, world: World, vehicle: Entity, intents: Entity) -> None:
            super().__init__(world, vehicle, intents)
            ends.append(self)

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(Modem, "send", recording_send)
        patch.setattr(links, "TeleopVehicleEnd", RecordedEnd)
        result = run_scenario(scenario, seed=0)
    trace = result.recorder.trace
    queued = {e.frame_id: e.t_s for e in trace.of_kind(EventKind.ENQUEUE)}
    delivered = {e.frame_id: e.t_s for e in trace.of_kind(EventKind.DELIVER)}
    orders, replies = [], []
    for frame_id, (sender, frame) in sorted(frames.items()):
        arrived_s = delivered.get(frame_id, math.inf)  # the last may still be on the air
        sent = Sent(queued[frame_id], arrived_s, payload_of(frame))
        (orders if sender == "operator" else replies).append(sent)
    return result, orders, replies, ends


def test_every_cancel_is_a_rising_edge_and_the_vehicle_applies_each(
    cancels_run: tuple[RunResult, list[Sent], list[Sent], list[TeleopVehicleEnd]],
) -> None:
    """The first order after each cancel raises the bit, the one before it had it down; the
    second cancel (no goal since the first) used to find the bit still up: lost."""
    _, orders, _, ends = cancels_run
    for cancel_s in CANCELS_S:
        before = [o for o in orders if o.queued_s < cancel_s][-1]
        after = next(o for o in orders if o.queued_s >= cancel_s)
        assert not cancel_bit(before.payload) and cancel_bit(after.payload), cancel_s
    (end,) = ends
    assert end.counters.cancels == len(CANCELS_S)


def test_the_bit_goes_down_once_a_reply_says_cancelled(
    cancels_run: tuple[RunResult, list[Sent], list[Sent], list[TeleopVehicleEnd]],
) -> None:
    """Each cancel is acknowledged (a reply with the flag, answering an order after it) within
    two token gaps, and every order queued after that reply arrived — up to the next cancel —
    has the bit down (it used to stay up to the end of the run)."""
    result, orders, replies, _ = cancels_run
    gap_s = orders[1].queued_s - orders[0].queued_s
    ends_s = (*CANCELS_S[1:], result.scenario.duration_s)
    for cancel_s, next_s in zip(CANCELS_S, ends_s, strict=True):
        first_up = next(o for o in orders if o.queued_s >= cancel_s)
        ack = next(
            r for r in replies if r.queued_s > first_up.queued_s and cancelled_flag(r.payload)
        )
        assert ack.delivered_s - first_up.queued_s < 2 * gap_s
        later = [o for o in orders if ack.delivered_s < o.queued_s < next_s]
        assert later and not any(cancel_bit(o.payload) for o in later), cancel_s
    assert sum(cancel_bit(o.payload) for o in orders) <= 2 * len(CANCELS_S)


def test_a_goal_the_vehicle_takes_clears_the_flag(
    cancels_run: tuple[RunResult, list[Sent], list[Sent], list[TeleopVehicleEnd]],
) -> None:
    """The GoTo at 35 s is a new goal: the replies after it was delivered say "not cancelled"
    until the next cancel (the flag is the last goal's, as a mission's is)."""
    _, orders, replies, _ = cancels_run
    (goto,) = [o for o in orders if order_type(o.payload) == GOTO and o.queued_s > GOALS_S[1]]
    between = [r for r in replies if goto.delivered_s < r.queued_s < CANCELS_S[2]]
    assert between and not any(cancelled_flag(r.payload) for r in between)


# ----------------------------------------------------------------------- the vehicle's end


def vehicle_end() -> tuple[World, Entity, Entity, TeleopVehicleEnd]:
    """A vehicle's world with a position fix (GoTos are taken), its intents and its end."""
    world = World()
    vehicle, intents = world.spawn(), world.spawn()
    world.set(vehicle, PositionReading(0.0, (0.0, 0.0, 1.0)))
    return world, vehicle, intents, TeleopVehicleEnd(world, vehicle, intents)


def order(seq_bit: bool, cancel: bool, body: Move | GoTo | DisableKeepHeading) -> bytes:
    return OperatorMessage(False, False, 0, seq_bit, cancel, body).encode()


def flag(end: TeleopVehicleEnd) -> bool:
    return cancelled_flag(end.encode_reply())


def test_without_a_mission_the_flag_says_a_cancel_was_applied_until_the_next_goal() -> None:
    world, _, intents, end = vehicle_end()
    move = Move(0, 0, 0, 0, mode=Mode.DEPTH_HOLD)
    assert end.apply_order(order(True, False, move), 1.0) and not flag(end)  # nothing cancelled
    assert end.apply_order(order(False, True, move), 1.1) and flag(end)  # the bit's edge
    assert end.apply_order(order(True, False, GoTo(100, 0, 100, 0)), 1.2) and not flag(end)
    assert end.apply_order(order(False, False, DisableKeepHeading()), 1.3) and flag(end)
    assert not end.apply_order(order(True, False, GoTo(100, 0, -100, 0)), 1.4)  # refused
    assert flag(end)  # a goal the vehicle did not take leaves the last one cancelled
    assert world.get(intents, PositionSetpoint) is None  # the goal dropped
    assert end.counters.cancels == 2


def test_with_a_mission_the_flag_is_the_missions() -> None:
    """A vehicle with autonomy: its MissionStatus decides, whatever the end applied."""
    world, vehicle, _, end = vehicle_end()
    world.set(vehicle, MissionStatus(True, False, 1, 0))
    move = Move(0, 0, 0, 0, mode=Mode.DEPTH_HOLD)
    assert end.apply_order(order(True, True, move), 1.0) and end.counters.cancels == 1
    assert not flag(end)  # the tree has not taken the cancel yet
    world.set(vehicle, MissionStatus(True, True, 1, 0))
    assert flag(end)
    assert end.apply_order(order(False, False, GoTo(100, 0, 100, 0)), 1.1)
    assert flag(end)  # until the tree takes the goal


def test_two_cancels_in_a_row_both_reach_a_vehicle_without_a_mission() -> None:
    """The two ends in lock step (each order applied, its reply back before the next): the
    second cancel is a new rising edge because the first was acknowledged."""
    op_world = World()
    intents = op_world.spawn()
    operator = TeleopOperatorEnd(op_world, intents)
    _, _, _, vehicle = vehicle_end()
    bits = []
    for step in range(8):
        if step in (1, 5):
            op_world.set(intents, GoalCancel(step))
        payload = operator.encode_order()
        bits.append(cancel_bit(payload))
        assert vehicle.apply_order(payload, float(step))
        assert operator.apply_reply(vehicle.encode_reply(), float(step) + 0.5) is not None
    assert bits == [False, True, False, False, False, True, False, False]
    assert vehicle.counters.cancels == 2
    assert op_world.get(operator.vehicle, MissionStatus) == MissionStatus(True, True)
