"""What an operator's order gap carries when several intents wait: a Move that disarms, arms
or takes the vehicle out of GUIDED goes before a heading or goal that changes every gap.

Truth: the protocol's own decoder (:func:`decode_operator_message`) for what goes on the wire,
and the vehicle's end applying that payload for what the vehicle is asked. A ground station
streaming targets through the gateway changes its goal or heading at every token gap; before,
each gap carried the new goal, so a disarm (or a pilot taking back the sticks in DEPTH_HOLD)
never went while the stream lasted.
"""

from __future__ import annotations

import math

from testbed.common.components import (
    Armed,
    ArmRequest,
    AttitudeSetpoint,
    ControlMode,
    ModeRequest,
    PositionReading,
    PositionSetpoint,
)
from testbed.common.geometry import quat_from_euler
from testbed.common.teleop import TeleopOperatorEnd, TeleopVehicleEnd, mode_to_wire
from testbed.ecs import Entity, Origin, World
from testbed.protocol import GoTo, KeepHeading, Move, OperatorMessage, decode_operator_message


def _reply(*, armed: bool, mode: int, ack: bool) -> bytes:
    """A 14-byte reply payload with only the flags set (bit 7 ready, 6 order-sequence ack,
    3 armed, 2..0 mode), as in tests/common/test_teleop.py."""
    flags = 0x80 | (0x40 if ack else 0) | (0x08 if armed else 0) | mode
    return bytes((0x0C, flags)) + bytes(12)


def _order(end: TeleopOperatorEnd) -> object:
    message = decode_operator_message(end.encode_order())
    assert isinstance(message, OperatorMessage)
    return message.order


def _armed_guided_operator() -> tuple[World, Entity, TeleopOperatorEnd]:
    world = World()
    intents = world.spawn()
    end = TeleopOperatorEnd(world, intents)
    world.set(intents, ArmRequest(True, 1))
    world.set(intents, ModeRequest(ControlMode.GUIDED))
    assert isinstance(_order(end), Move)  # the arm
    assert end.apply_reply(_reply(armed=True, mode=mode_to_wire(ControlMode.GUIDED), ack=True), 0.1)
    return world, intents, end


def test_a_disarm_goes_before_a_goal_streamed_every_gap() -> None:
    world, intents, end = _armed_guided_operator()
    guided = mode_to_wire(ControlMode.GUIDED)
    for k in range(3):  # a ground station's position target, new at every gap
        world.set(intents, PositionSetpoint((1.0 + 0.1 * k, 0.0, 1.0), 0.0, True))
        assert isinstance(_order(end), GoTo)
        end.apply_reply(_reply(armed=True, mode=guided, ack=end.order_seq_bit), 0.2 + 0.1 * k)
    world.set(intents, ArmRequest(False, 2))
    world.set(intents, PositionSetpoint((2.0, 0.0, 1.0), 0.0, True))
    payload = end.encode_order()
    message = decode_operator_message(payload)
    assert isinstance(message, OperatorMessage) and isinstance(message.order, Move)
    assert message.order.disarm and not message.order.arm

    vehicle_world = World()  # the vehicle's end, armed, is asked to disarm
    vehicle, vehicle_intents = vehicle_world.spawn(), vehicle_world.spawn()
    vehicle_end = TeleopVehicleEnd(vehicle_world, vehicle, vehicle_intents)
    vehicle_world.set(vehicle, Armed(True), origin=Origin.LOCAL)
    vehicle_world.set(vehicle, PositionReading(0.0, (0.0, 0.0, 1.0)), origin=Origin.LOCAL)
    assert vehicle_end.apply_order(payload, 1.0)
    request = vehicle_world.get(vehicle_intents, ArmRequest)
    assert request is not None and not request.armed
    # the goal goes at the next gap, once the reply shows the vehicle disarmed
    end.apply_reply(_reply(armed=False, mode=guided, ack=False), 1.1)
    assert isinstance(_order(end), GoTo)


def test_leaving_guided_goes_before_a_heading_streamed_every_gap() -> None:
    world, intents, end = _armed_guided_operator()
    guided = mode_to_wire(ControlMode.GUIDED)
    for k in range(3):  # a heading target, new at every gap
        yaw = math.radians(10.0 * (k + 1))
        world.set(intents, AttitudeSetpoint(quat_from_euler(0.0, 0.0, yaw)))
        assert isinstance(_order(end), KeepHeading)
        end.apply_reply(_reply(armed=True, mode=guided, ack=end.order_seq_bit), 0.2 + 0.1 * k)
    world.set(intents, ModeRequest(ControlMode.DEPTH_HOLD))  # the pilot takes the sticks back
    world.set(intents, AttitudeSetpoint(quat_from_euler(0.0, 0.0, math.radians(45.0))))
    order = _order(end)
    assert isinstance(order, Move) and order.mode == mode_to_wire(ControlMode.DEPTH_HOLD)
    assert isinstance(_order(end), KeepHeading)  # then the heading, at the next gap


def test_a_goto_carries_the_change_to_guided_without_a_gap_of_its_own() -> None:
    """GUIDED is what the vehicle flies a GoTo in (its end sets the mode on a GoTo): the GoTo
    goes at once; once acknowledged, the Moves carry GUIDED."""
    world = World()
    intents = world.spawn()
    end = TeleopOperatorEnd(world, intents)
    world.set(intents, ModeRequest(ControlMode.DEPTH_HOLD))
    assert isinstance(_order(end), Move)
    world.set(intents, ModeRequest(ControlMode.GUIDED))
    world.set(intents, PositionSetpoint((1.0, 0.0, 1.0), 0.0, True))
    assert isinstance(_order(end), GoTo)
    guided = mode_to_wire(ControlMode.GUIDED)
    assert end.apply_reply(_reply(armed=False, mode=guided, ack=end.order_seq_bit), 0.1)
    assert end.counters.goals_acked == 1
    order = _order(end)
    assert isinstance(order, Move) and order.mode == mode_to_wire(ControlMode.GUIDED)
