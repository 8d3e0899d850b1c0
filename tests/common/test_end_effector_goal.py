"""End-effector goals: the EndEffectorSetpoint component (id 108), over the teleop codec as an
EndEffectorGoTo order, over the change-set codec, and from the supervisor pilot's goals.

Expected bytes are worked out by hand from the documented layouts (the EndEffectorGoTo body in
``orders.py``, the change-set entry in ``changeset.py``), not taken from the encoders.
"""

from __future__ import annotations

import math
import struct

import pytest

import testbed.common.components as common_components
import testbed.vehicle.components as vehicle_components
from testbed.common.changeset_receiver import ApplyStatus, ChangeSetReceiver
from testbed.common.changeset_sender import ChangeSetSender
from testbed.common.components import (
    REPLICATED,
    ControlMode,
    EndEffectorSetpoint,
    GoalCancel,
    ModeRequest,
    PositionReading,
    PositionSetpoint,
    register_components,
)
from testbed.common.teleop import TeleopOperatorEnd, TeleopVehicleEnd
from testbed.config import ConfigError, FieldError, build
from testbed.ecs import ComponentRegistry, Entity, Origin, Replicate, Side, World
from testbed.operator.pilots import GoalOrder, GoalStep, SupervisorPilot
from testbed.operator.station import OperatorStation, SessionPlan
from testbed.protocol import (
    Frame,
    FrameDecoder,
    GoTo,
    Move,
    OperatorMessage,
    decode_operator_message,
    encode_frame,
)
from testbed.protocol.orders import EndEffectorGoTo
from testbed.run.sections import PilotSection

# ------------------------------------------------------------------------------ helpers


def operator_end() -> tuple[World, Entity, TeleopOperatorEnd]:
    world = World()
    intents = world.spawn()
    return world, intents, TeleopOperatorEnd(world, intents)


def vehicle_end(*, fix: bool = True) -> tuple[World, Entity, Entity, TeleopVehicleEnd]:
    world = World()
    vehicle = world.spawn()
    intents = world.spawn()
    if fix:
        world.set(vehicle, PositionReading(0.0, (0.0, 0.0, 1.0)))
    return world, vehicle, intents, TeleopVehicleEnd(world, vehicle, intents)


def deliver(payload: bytes) -> bytes:
    """Frame a payload and recover it with a stream decoder fed one byte at a time."""
    decoder = FrameDecoder()
    events = [event for byte in encode_frame(payload) for event in decoder.feed(bytes((byte,)))]
    assert len(events) == 1 and isinstance(events[0], Frame)
    return events[0].payload


def order_of(payload: bytes) -> OperatorMessage:
    message = decode_operator_message(payload)
    assert isinstance(message, OperatorMessage)
    return message


# ---------------------------------------------------------------------------- component


def test_registered_operator_owned_as_108_and_exported_by_both_modules() -> None:
    assert (EndEffectorSetpoint, 108, Side.OPERATOR) in REPLICATED
    assert len({type_id for _, type_id, _ in REPLICATED}) == len(REPLICATED)
    registry = ComponentRegistry()
    register_components(registry)
    assert registry.owner_of(EndEffectorSetpoint) is Side.OPERATOR
    assert "EndEffectorSetpoint" in common_components.__all__
    assert "EndEffectorSetpoint" in vehicle_components.__all__
    assert vehicle_components.EndEffectorSetpoint is EndEffectorSetpoint
    assert EndEffectorSetpoint((1.0, 2.0, 3.0)) == EndEffectorSetpoint((1.0, 2.0, 3.0), 0.0, False)


def test_the_change_set_codec_replicates_it_under_id_108() -> None:
    registry = ComponentRegistry()
    register_components(registry)
    op_world = World()
    entity = op_world.spawn(Replicate())
    setpoint = EndEffectorSetpoint((1.5, -2.25, 3.0), 0.5, True)
    op_world.set(entity, setpoint)
    sender = ChangeSetSender(op_world, registry, Side.OPERATOR)
    payloads = sender.poll()
    value = struct.pack(">dddd?", 1.5, -2.25, 3.0, 0.5, True)  # 4 × binary64 + a bool: 33 B
    assert payloads == [
        bytes.fromhex("01 02 0000 01")  # version 1, operator side, sequence 0, one entry
        + bytes.fromhex("01 00000001 006c 21")  # ADDED, sender entity 1, type id 108, 33 B
        + value
    ]
    v_world = World()
    receiver = ChangeSetReceiver(v_world, registry, Side.VEHICLE)
    assert receiver.apply(payloads[0]).status is ApplyStatus.APPLIED
    mirror = receiver.local_entity(1)
    assert mirror is not None
    assert v_world.get(mirror, EndEffectorSetpoint) == setpoint
    assert v_world.origin_of(mirror, EndEffectorSetpoint) is Origin.REMOTE

    op_world.set(entity, EndEffectorSetpoint((0.0, 0.0, 0.0)))
    (changed,) = sender.poll()
    assert changed[5:13] == bytes.fromhex("02 00000001 006c 21")  # CHANGED
    assert receiver.apply(changed).status is ApplyStatus.APPLIED
    assert v_world.get(mirror, EndEffectorSetpoint) == EndEffectorSetpoint((0.0, 0.0, 0.0))


def test_the_vehicle_cannot_write_the_operators_end_effector_setpoint() -> None:
    registry = ComponentRegistry()
    register_components(registry)
    v_world = World()
    v_world.spawn(Replicate(), EndEffectorSetpoint((1.0, 0.0, 0.0)))
    assert ChangeSetSender(v_world, registry, Side.VEHICLE).poll() == []  # not the vehicle's


# ------------------------------------------------------------------- the teleop codec


def test_an_end_effector_setpoint_arrives_as_the_same_setpoint() -> None:
    op_world, op_intents, op_end = operator_end()
    sent = EndEffectorSetpoint((3.0, -1.25, 2.5))  # on the 1-cm grid, no tool yaw
    op_world.set(op_intents, sent)
    payload = op_end.encode_order()
    # header: seq bit 1, type 8 = 0x88; 300 = 0x012C, −125 = 0xFF83, 250 = 0x00FA; no yaw 0xFFFF
    assert payload == bytes.fromhex("00 88 012C FF83 00FA FFFF")
    assert len(encode_frame(payload)) == 16

    world, vehicle, intents, end = vehicle_end()
    assert end.apply_order(deliver(payload), 1.0) is True
    assert world.get(intents, EndEffectorSetpoint) == sent
    assert world.origin_of(intents, EndEffectorSetpoint) is Origin.REMOTE
    # the arm's goal, not the vehicle's: no position setpoint, no mode change
    assert world.get(intents, PositionSetpoint) is None
    assert world.get(intents, ModeRequest) is None
    assert world.components(vehicle) == (PositionReading(0.0, (0.0, 0.0, 1.0)),)
    assert end.order_ack_bit is True and end.counters.applied == 1


@pytest.mark.parametrize(
    ("yaw_deg", "code", "arrives_deg"),
    [
        (-90.0, 27000, -90.0),  # 270.00°, back in (−180, 180]
        (12.345, 1234, 12.34),  # 0.01° steps, round half to even
        (359.996, 0, 0.0),  # rounds up to a full turn
        (180.0, 18000, 180.0),
    ],
)
def test_the_tool_yaw_travels_in_hundredths_of_a_degree(
    yaw_deg: float, code: int, arrives_deg: float
) -> None:
    op_world, op_intents, op_end = operator_end()
    op_world.set(op_intents, EndEffectorSetpoint((0.5, 0.0, 1.0), math.radians(yaw_deg), True))
    payload = op_end.encode_order()
    assert order_of(payload).order == EndEffectorGoTo(50, 0, 100, code)
    assert payload[-2:] == code.to_bytes(2, "big")
    world, _, intents, end = vehicle_end()
    assert end.apply_order(payload, 1.0)
    arrived = world.get(intents, EndEffectorSetpoint)
    assert arrived is not None and arrived.use_yaw
    assert arrived.position_ned_m == (0.5, 0.0, 1.0)
    assert math.isclose(arrived.yaw_rad, math.radians(arrives_deg), abs_tol=1e-12)


def test_positions_beyond_the_int16_centimetres_are_clamped() -> None:
    op_world, op_intents, op_end = operator_end()
    op_world.set(op_intents, EndEffectorSetpoint((400.0, -400.0, 0.004)))
    assert order_of(op_end.encode_order()).order == EndEffectorGoTo(32767, -32768, 0)


def test_refused_without_a_position_fix() -> None:
    world, _, intents, end = vehicle_end(fix=False)
    payload = OperatorMessage(False, False, 0, True, False, EndEffectorGoTo(1, 2, 3)).encode()
    assert end.apply_order(payload, 1.0) is False
    assert end.counters.unsupported == 1 and world.components(intents) == ()
    assert end.order_ack_bit is False  # not applied, so not acknowledged


def test_sent_again_with_the_same_bit_until_a_reply_acknowledges_it() -> None:
    op_world, op_intents, op_end = operator_end()
    op_world.set(op_intents, EndEffectorSetpoint((1.0, 2.0, 3.0)))
    world, _, intents, end = vehicle_end()
    first = op_end.encode_order()  # lost on the way
    assert order_of(first).order == EndEffectorGoTo(100, 200, 300)
    assert first[1] == 0x88
    reply = end.encode_reply()  # a reply to an earlier order: acknowledges bit 0, not 1
    assert op_end.apply_reply(reply, 0.5) is not None
    second = op_end.encode_order()
    assert second == first and op_end.counters.goals_acked == 0
    assert end.apply_order(second, 1.0)
    assert world.get(intents, EndEffectorSetpoint) == EndEffectorSetpoint((1.0, 2.0, 3.0))
    assert op_end.apply_reply(end.encode_reply(), 1.2) is not None
    assert op_end.counters.goals_acked == 1
    follow = order_of(op_end.encode_order())  # acknowledged: the sticks again, a new bit
    assert isinstance(follow.order, Move) and follow.order_seq_bit is False
    assert op_end.counters.goals_acked == 1


def test_a_newer_end_effector_goal_replaces_one_not_yet_acknowledged() -> None:
    op_world, op_intents, op_end = operator_end()
    op_world.set(op_intents, EndEffectorSetpoint((1.0, 0.0, 0.0)))
    assert order_of(op_end.encode_order()).order == EndEffectorGoTo(100, 0, 0)
    op_world.set(op_intents, EndEffectorSetpoint((2.0, 0.0, 0.0)))
    newer = order_of(op_end.encode_order())
    assert newer.order == EndEffectorGoTo(200, 0, 0) and newer.order_seq_bit is False
    assert order_of(op_end.encode_order()) == newer  # the newer one is what is resent


def test_a_vehicle_goal_and_an_end_effector_goal_both_arrive() -> None:
    op_world, op_intents, op_end = operator_end()
    op_world.set(op_intents, PositionSetpoint((1.0, 2.0, 3.0), 0.0, True))
    op_world.set(op_intents, EndEffectorSetpoint((1.5, 2.0, 3.5)))
    world, _, intents, end = vehicle_end()
    goto = op_end.encode_order()
    assert order_of(goto).order == GoTo(100, 200, 300, 0)  # the vehicle's goal first
    assert op_end.encode_order() == goto  # not acknowledged: the arm's goal waits behind it
    assert end.apply_order(goto, 1.0)
    assert op_end.apply_reply(end.encode_reply(), 1.1) is not None
    arm = op_end.encode_order()
    assert order_of(arm).order == EndEffectorGoTo(150, 200, 350) and arm[1] & 0x80 == 0
    assert end.apply_order(arm, 1.2)
    assert op_end.apply_reply(end.encode_reply(), 1.3) is not None
    assert op_end.counters.goals_acked == 2
    assert world.get(intents, PositionSetpoint) == PositionSetpoint((1.0, 2.0, 3.0), 0.0, True)
    assert world.get(intents, EndEffectorSetpoint) == EndEffectorSetpoint((1.5, 2.0, 3.5))
    assert world.get(intents, ModeRequest) == ModeRequest(ControlMode.GUIDED)  # from the GoTo
    assert isinstance(order_of(op_end.encode_order()).order, Move)


def test_a_cancel_drops_an_end_effector_goal_and_the_bit_cancels_it_on_the_vehicle() -> None:
    op_world, op_intents, op_end = operator_end()
    op_world.set(op_intents, EndEffectorSetpoint((1.0, 0.0, 1.0)))
    world, _, intents, end = vehicle_end()
    assert end.apply_order(op_end.encode_order(), 1.0)  # applied, the reply not back yet
    op_world.set(op_intents, GoalCancel(1))
    payload = op_end.encode_order()
    message = order_of(payload)
    assert isinstance(message.order, Move) and message.cancel_order  # not the goal again
    assert payload[1] & 0x40  # header byte 1 bit 6: cancel last order
    assert end.apply_order(payload, 1.1)
    assert world.get(intents, GoalCancel) == GoalCancel(1) and end.counters.cancels == 1
    assert world.origin_of(intents, GoalCancel) is Origin.REMOTE
    # the cancel bit stays set until a reply says cancelled; the goal is not sent again
    again = order_of(op_end.encode_order())
    assert isinstance(again.order, Move) and again.cancel_order
    assert end.apply_order(again.encode(), 1.2)
    assert end.counters.cancels == 1  # the bit's rising edge only


def test_a_new_end_effector_goal_after_a_cancel_clears_the_cancel_bit() -> None:
    op_world, op_intents, op_end = operator_end()
    op_world.set(op_intents, GoalCancel(1))
    assert op_end.encode_order()[1] & 0x40
    op_world.set(op_intents, EndEffectorSetpoint((0.0, 1.0, 0.0)))
    payload = op_end.encode_order()
    assert payload[1] & 0x4F == 0x08  # the goal, no cancel bit


# ------------------------------------------------------------- the supervisor pilot


def test_an_end_effector_goal_makes_the_station_write_an_end_effector_setpoint() -> None:
    pilot = SupervisorPilot(
        (
            GoalStep(1.0, (1.0, 2.0, 3.0), 90.0, frame="end_effector"),
            GoalStep(2.0, (4.0, 5.0, 6.0)),
            GoalStep(3.0, cancel=True),
        )
    )
    assert pilot.sample(1.5).goal == GoalOrder(0, (1.0, 2.0, 3.0), 90.0, "end_effector")
    assert pilot.sample(2.5).goal == GoalOrder(1, (4.0, 5.0, 6.0), None, "vehicle")
    station = OperatorStation(pilot, SessionPlan(arm_at_s=100.0))
    world, entity = station.world, station.entity
    station.frame(1.5)
    setpoint = world.get(entity, EndEffectorSetpoint)
    assert setpoint is not None and setpoint.use_yaw
    assert setpoint.position_ned_m == (1.0, 2.0, 3.0)
    assert math.isclose(setpoint.yaw_rad, math.pi / 2)
    assert world.get(entity, PositionSetpoint) is None
    station.frame(2.5)
    assert world.get(entity, PositionSetpoint) == PositionSetpoint((4.0, 5.0, 6.0), 0.0, False)
    assert world.get(entity, EndEffectorSetpoint) == setpoint  # the arm's goal is untouched
    station.frame(3.5)
    assert world.get(entity, GoalCancel) == GoalCancel(3)


def test_the_frame_defaults_to_the_vehicle_and_is_checked() -> None:
    assert GoalStep(0.0, (0.0, 0.0, 0.0)).frame == "vehicle"
    with pytest.raises(FieldError, match="must be one of") as err:
        GoalStep(0.0, (0.0, 0.0, 0.0), frame="arm")  # type: ignore[arg-type]  # bad on purpose
    assert err.value.key == "frame"
    with pytest.raises(FieldError, match="cancel") as err:
        GoalStep(0.0, cancel=True, frame="end_effector")
    assert err.value.key == "frame"


def test_a_bad_frame_in_a_scenario_is_a_config_error_naming_the_key() -> None:
    goal = {"t_s": 1.0, "position_ned_m": [1.0, 2.0, 3.0], "frame": "end_effector"}
    section = build(
        PilotSection, {"kind": "supervisor", "goals": [goal]}, source="s.toml", prefix="pilot."
    )
    assert section.goals[0].frame == "end_effector"
    assert isinstance(section.pilot(), SupervisorPilot)
    bad = {"kind": "supervisor", "goals": [goal, {**goal, "frame": "gripper"}]}
    with pytest.raises(ConfigError, match=r"s\.toml: pilot\.goals\[1\]\.frame: .*'gripper'"):
        build(PilotSection, bad, source="s.toml", prefix="pilot.")
    cancel = {"kind": "supervisor", "goals": [{"t_s": 1.0, "cancel": True, "frame": "vehicle"}]}
    assert build(PilotSection, cancel, source="s.toml", prefix="pilot.").goals[0].cancel


@pytest.mark.parametrize("order", [GoTo(100, 0, -200, 0), EndEffectorGoTo(100, 0, -1)])
def test_a_goal_above_the_surface_is_refused_and_counted(order: GoTo | EndEffectorGoTo) -> None:
    """A remote value: counted unsupported as a goal without a fix is, never raised; the
    vehicle's intents are untouched. A goal at the surface (z = 0) is taken."""
    world, _, intents, end = vehicle_end()
    payload = OperatorMessage(False, False, 0, True, False, order).encode()
    assert end.apply_order(payload, 1.0) is False
    assert end.counters.unsupported == 1 and world.components(intents) == ()
    assert end.order_ack_bit is False  # not applied, so not acknowledged
    surface = OperatorMessage(False, False, 0, True, False, GoTo(100, 0, 0, 0)).encode()
    assert end.apply_order(surface, 2.0) is True
