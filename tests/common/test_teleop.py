"""Compact teleop codec: hand-computed order and reply bytes, arming, headings, round trips, fuzz.

Expected bytes are worked out by hand from the bit layouts of REFERENCE §1.3–1.6 (not from the
protocol encoders); frames are checked with a bit-by-bit CRC-16/XMODEM; attitudes with SciPy's
Z-Y-X Euler rotations.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from testbed.common.components import (
    ActiveMode,
    Armed,
    ArmRequest,
    AttitudeSetpoint,
    ControlMode,
    GoalCancel,
    MissionStatus,
    ModeRequest,
    MovementCommand,
    Odometry,
    PositionReading,
    PositionSetpoint,
)
from testbed.common.geometry import Quaternion
from testbed.common.teleop import (
    TeleopOperatorEnd,
    TeleopVehicleEnd,
    mode_from_wire,
    mode_to_wire,
)
from testbed.ecs import Entity, Origin, World
from testbed.protocol import (
    DisableKeepHeading,
    Frame,
    FrameDecoder,
    GoTo,
    HoldChannel,
    ImageSettings,
    KeepHeading,
    Mode,
    Move,
    NoOrder,
    OperatorMessage,
    Order,
    OrderIncoming,
    VehicleMessage,
    decode_operator_message,
    decode_vehicle_message,
    encode_frame,
)
from tests.strategies import crc16_bitwise

# ------------------------------------------------------------------------------ helpers


def quat_wxyz(roll_deg: float, pitch_deg: float, yaw_deg: float) -> Quaternion:
    """Body → NED attitude from Z-Y-X Euler angles, by SciPy (intrinsic yaw, pitch, roll)."""
    x, y, z, w = Rotation.from_euler("ZYX", [yaw_deg, pitch_deg, roll_deg], degrees=True).as_quat()
    return (float(w), float(x), float(y), float(z))


def same_rotation(a: Quaternion, b: Quaternion, tol: float = 1e-9) -> bool:
    """Whether two unit quaternions are the same rotation (q and −q are)."""
    return abs(abs(sum(p * q for p, q in zip(a, b, strict=True))) - 1.0) < tol


def operator_end() -> tuple[World, Entity, TeleopOperatorEnd]:
    world = World()
    intents = world.spawn()
    return world, intents, TeleopOperatorEnd(world, intents)


def vehicle_end() -> tuple[World, Entity, Entity, TeleopVehicleEnd]:
    world = World()
    vehicle = world.spawn()
    intents = world.spawn()
    return world, vehicle, intents, TeleopVehicleEnd(world, vehicle, intents)


def reply(
    *, armed: bool, mode: int = 2, heading: int = 0, ack: bool = False, cancelled: bool = False
) -> bytes:
    """A hand-built 14-byte reply payload: only the flags and heading vary, pose otherwise 0
    (flags: bit 7 ready, 6 order-sequence ack, 5 last order cancelled, 3 armed, 2..0 mode)."""
    flags = 0x80 | (0x40 if ack else 0) | (0x20 if cancelled else 0) | (0x08 if armed else 0) | mode
    attitude = heading << 31
    return bytes((0x0C, flags)) + bytes(6) + attitude.to_bytes(5, "big") + b"\x00"


def order_flags(payload: bytes) -> tuple[bool, bool]:
    """(arm, disarm) of a Move payload (header byte 1 type 1; flags are the last byte)."""
    assert payload[1] & 0x0F == 1 and len(payload) == 7
    return bool(payload[6] & 0x80), bool(payload[6] & 0x40)


# ------------------------------------------------------------------------ mode mapping


def test_modes_map_both_ways_and_the_vehicle_has_no_pos_hold() -> None:
    assert mode_to_wire(ControlMode.MANUAL) is Mode.MANUAL
    assert mode_to_wire(ControlMode.STABILIZE) is Mode.STABILIZE
    assert mode_to_wire(ControlMode.DEPTH_HOLD) is Mode.DEPTH_HOLD
    # the wire codes are the 3-bit REFERENCE codes, not ArduSub's mode numbers
    assert mode_to_wire(ControlMode.GUIDED) is Mode.GUIDED
    assert [int(mode_to_wire(m)) for m in ControlMode] == [0, 1, 2, 4]
    for mode in ControlMode:
        assert mode_from_wire(mode_to_wire(mode)) is mode
    assert mode_from_wire(Mode.POS_HOLD) is None
    assert mode_from_wire(Mode.GUIDED) is ControlMode.GUIDED


# ---------------------------------------------------------------------- encoding orders


def test_move_order_bytes_and_frames_by_hand() -> None:
    world, intents, end = operator_end()
    sticks = (0.5, -1.0, 0.0, 0.7, -0.3, 0.25)  # roll and pitch sticks are not carried
    world.set(intents, MovementCommand(7, 0.25, sticks))
    world.set(intents, ModeRequest(ControlMode.DEPTH_HOLD))
    world.set(intents, ArmRequest(True, 1))

    payload = end.encode_order()
    # byte 0: no image; byte 1: seq bit 1 (first order), type 1 (move);
    # x = round(63.5) = 64 = 0x40, y = −127 = 0x81, z = 0, yaw = round(31.75) = 32 = 0x20;
    # flags: arm (bit 7) | DEPTH_HOLD (2) = 0x82
    assert payload == bytes((0x00, 0x81, 0x40, 0x81, 0x00, 0x20, 0x82))

    frame = encode_frame(payload)  # WAFrame: 0x55 ×3 · len · payload · CRC over all of it
    head = bytes((0x55, 0x55, 0x55, 0x07)) + payload
    assert frame == head + crc16_bitwise(head).to_bytes(2, "big")
    assert len(frame) == 13
    assert len(encode_frame(payload, preamble_len=1)) == 11  # REFERENCE §1.6 table


def test_order_sequence_bit_alternates() -> None:
    world, intents, end = operator_end()
    bits = []
    for seq in range(6):
        world.set(intents, MovementCommand(seq, 0.1 * seq, (0.0,) * 6))
        payload = end.encode_order()
        bits.append(payload[1] >> 7)
        assert bool(bits[-1]) is end.order_seq_bit
    assert bits == [1, 0, 1, 0, 1, 0]


def test_no_intents_yet_is_a_neutral_manual_move() -> None:
    _, _, end = operator_end()
    assert end.encode_order() == bytes((0x00, 0x81, 0, 0, 0, 0, 0x00))


def test_arm_flag_until_the_vehicle_reports_armed_then_dropped() -> None:
    world, intents, end = operator_end()
    world.set(intents, ArmRequest(True, 1))
    assert order_flags(end.encode_order()) == (True, False)  # no reply yet
    assert end.apply_reply(reply(armed=False), 1.0)
    assert order_flags(end.encode_order()) == (True, False)  # not armed yet: keep asking
    assert end.apply_reply(reply(armed=True), 2.0)
    assert order_flags(end.encode_order()) == (False, False)
    assert order_flags(end.encode_order()) == (False, False)


def test_disarm_request_sends_the_disarm_flag_until_reported() -> None:
    world, intents, end = operator_end()
    world.set(intents, ArmRequest(True, 1))
    end.apply_reply(reply(armed=True), 1.0)
    assert order_flags(end.encode_order()) == (False, False)
    world.set(intents, ArmRequest(False, 2))
    assert order_flags(end.encode_order()) == (False, True)
    assert order_flags(end.encode_order()) == (False, True)
    end.apply_reply(reply(armed=False), 2.0)
    assert order_flags(end.encode_order()) == (False, False)


def test_disarm_request_for_a_disarmed_vehicle_sends_nothing() -> None:
    world, intents, end = operator_end()
    world.set(intents, ArmRequest(False, 1))
    assert order_flags(end.encode_order()) == (False, False)


def test_a_vehicle_side_disarm_is_not_overridden_by_an_old_arm_request() -> None:
    """A request counts once per seq: after a failsafe disarm only a new request re-arms."""
    world, intents, end = operator_end()
    world.set(intents, ArmRequest(True, 1))
    assert order_flags(end.encode_order()) == (True, False)
    end.apply_reply(reply(armed=False), 0.5)  # the state before the arm was applied
    assert order_flags(end.encode_order()) == (True, False)  # (ignored by an armed vehicle)
    end.apply_reply(reply(armed=True), 1.0)
    end.apply_reply(reply(armed=False), 9.0)  # e.g. surfaced and disarmed by the failsafe
    assert order_flags(end.encode_order()) == (False, False)
    world.set(intents, ArmRequest(True, 2))
    assert order_flags(end.encode_order()) == (True, False)


@pytest.mark.parametrize("first", [True, False])
def test_a_second_request_made_before_the_firsts_reply_is_not_lost(first: bool) -> None:
    """Arm, then disarm before the arm's reply came (and the reverse): the vehicle ends in the
    second request's state. The vehicle answers each order with the state from before it
    applies it (its reply goes out as the order arrives), so the first order's reply shows the
    old state, which the second request asked for: taken as done, the second was never sent
    and the vehicle stayed as the first left it (a user review through the S100 gateway)."""
    world, intents, end = operator_end()
    vehicle_armed = not first

    def exchange() -> bool:
        """One token cycle's order; the vehicle's state before it applied the order."""
        nonlocal vehicle_armed
        arm, disarm = order_flags(end.encode_order())
        before = vehicle_armed
        vehicle_armed = (vehicle_armed or arm) and not disarm
        return before

    end.apply_reply(reply(armed=vehicle_armed), 0.0)
    world.set(intents, ArmRequest(first, 1))
    in_flight = exchange()  # the first request's order is out and applied...
    assert vehicle_armed is first
    world.set(intents, ArmRequest(not first, 2))  # ...and the second is asked before its reply
    end.apply_reply(reply(armed=in_flight), 1.0)
    for k in range(4):
        end.apply_reply(reply(armed=exchange()), 2.0 + k)
    assert vehicle_armed is (not first)
    assert order_flags(end.encode_order()) == (False, False)  # settled: nothing more asked


def test_changed_attitude_setpoint_becomes_keep_heading_in_whole_degrees() -> None:
    world, intents, end = operator_end()
    world.set(intents, AttitudeSetpoint(quat_wxyz(12.0, -7.0, 123.6)))
    payload = end.encode_order()
    # byte 1: seq bit 1 | type 2; body: round(123.6) = 124 = 0x007C, u16 big-endian
    assert payload == bytes((0x00, 0x82, 0x00, 0x7C))
    assert len(encode_frame(payload)) == 10
    # unchanged setpoint: back to moves
    assert end.encode_order()[1] & 0x0F == 1
    # a negative yaw is sent as its compass heading: round(−30.2) = −30 → 330 = 0x014A
    world.set(intents, AttitudeSetpoint(quat_wxyz(0.0, 0.0, -30.2)))
    assert end.encode_order() == bytes((0x00, 0x82, 0x01, 0x4A))


def test_roll_or_pitch_only_change_does_not_resend_the_same_heading() -> None:
    world, intents, end = operator_end()
    world.set(intents, AttitudeSetpoint(quat_wxyz(0.0, 0.0, 40.0)))
    assert end.encode_order()[1] & 0x0F == 2
    for roll_deg in (5.0, 10.0, 15.0):  # roll and pitch cannot travel: nothing new to send
        world.set(intents, AttitudeSetpoint(quat_wxyz(roll_deg, -roll_deg, 40.2)))
        assert end.encode_order()[1] & 0x0F == 1
    world.set(intents, AttitudeSetpoint(quat_wxyz(15.0, -15.0, 41.0)))
    assert end.encode_order()[2:] == (41).to_bytes(2, "big")


def test_arming_goes_before_a_changed_heading() -> None:
    world, intents, end = operator_end()
    world.set(intents, ArmRequest(True, 1))
    world.set(intents, AttitudeSetpoint(quat_wxyz(0.0, 0.0, 90.0)))
    assert order_flags(end.encode_order()) == (True, False)
    end.apply_reply(reply(armed=True), 1.0)
    assert end.encode_order() == bytes((0x00, 0x02, 0x00, 0x5A))  # seq bit 0, heading 90


# ------------------------------------------------------------------------- applying orders


def deliver(payload: bytes) -> bytes:
    """Frame a payload and recover it with a stream decoder fed one byte at a time."""
    decoder = FrameDecoder()
    events = [event for byte in encode_frame(payload) for event in decoder.feed(bytes((byte,)))]
    assert len(events) == 1 and isinstance(events[0], Frame)
    return events[0].payload


def test_round_trip_operator_world_to_vehicle_world() -> None:
    op_world, op_intents, op_end = operator_end()
    op_world.set(op_intents, MovementCommand(41, 0.3, (0.5, -1.0, 0.0, 0.7, -0.3, 0.25)))
    op_world.set(op_intents, ModeRequest(ControlMode.DEPTH_HOLD))
    op_world.set(op_intents, ArmRequest(True, 1))
    world, vehicle, intents, end = vehicle_end()

    assert end.apply_order(deliver(op_end.encode_order()), 3.5)
    # the wire has no sample time or operator seq: the vehicle numbers and stamps on arrival
    assert world.get(intents, MovementCommand) == MovementCommand(
        1, 3.5, (64 / 127, -1.0, 0.0, 0.0, 0.0, 32 / 127)
    )
    assert world.get(intents, ModeRequest) == ModeRequest(ControlMode.DEPTH_HOLD)
    assert world.get(intents, ArmRequest) == ArmRequest(True, 1)
    for cls in (MovementCommand, ModeRequest, ArmRequest):
        assert world.origin_of(intents, cls) is Origin.REMOTE
    assert world.components(vehicle) == ()  # the vehicle's own state is not touched
    assert end.order_ack_bit is True
    assert (end.counters.applied, end.counters.malformed, end.counters.unsupported) == (1, 0, 0)


def test_arm_request_written_only_on_a_change_of_armed_state() -> None:
    op_world, op_intents, op_end = operator_end()
    op_world.set(op_intents, ArmRequest(True, 1))
    world, vehicle, intents, end = vehicle_end()

    end.apply_order(op_end.encode_order(), 1.0)
    assert world.get(intents, ArmRequest) == ArmRequest(True, 1)
    world.set(vehicle, Armed(True))  # the vehicle armed
    world.advance()
    tick = world.changed_tick(intents, ArmRequest)
    payload = op_end.encode_order()
    assert order_flags(payload) == (True, False)  # the reply saying armed is not back yet
    end.apply_order(payload, 2.0)
    assert world.changed_tick(intents, ArmRequest) == tick  # already armed: no new request

    op_world.set(op_intents, ArmRequest(False, 2))
    op_end.apply_reply(end.encode_reply(), 2.5)
    end.apply_order(op_end.encode_order(), 3.0)
    assert world.get(intents, ArmRequest) == ArmRequest(False, 2)
    assert world.origin_of(intents, ArmRequest) is Origin.REMOTE


def test_the_vehicle_arms_on_the_flags_rising_edge_only() -> None:
    """A flag held over several orders is one press (as ArduSub, a disarm by the vehicle
    itself stays until the operator asks again): after the vehicle's own disarm, more flagged
    orders do not arm it; an order without the flag, then one with it, do."""
    op_world, op_intents, op_end = operator_end()
    op_world.set(op_intents, ArmRequest(True, 1))
    world, vehicle, intents, end = vehicle_end()
    flagged = op_end.encode_order()
    assert order_flags(flagged) == (True, False)
    end.apply_order(flagged, 1.0)
    assert world.get(intents, ArmRequest) == ArmRequest(True, 1)
    world.set(vehicle, Armed(False))  # its failsafe disarmed it
    world.advance()
    tick = world.changed_tick(intents, ArmRequest)
    end.apply_order(op_end.encode_order(), 2.0)  # still flagged: no reply settled it
    assert world.changed_tick(intents, ArmRequest) == tick
    op_world.set(op_intents, ArmRequest(True, 2))  # the operator asks again
    dropped, again = op_end.encode_order(), op_end.encode_order()
    assert (order_flags(dropped), order_flags(again)) == ((False, False), (True, False))
    end.apply_order(dropped, 3.0)
    end.apply_order(again, 3.5)
    assert world.get(intents, ArmRequest) == ArmRequest(True, 2)


def test_a_reply_acknowledging_the_flagged_order_settles_the_request() -> None:
    """Under token passing a reply answers the last order: one that acknowledges the order
    carrying the arm flag settles the request, though its state is from before the vehicle
    applied it (disarmed), so a link lost right after leaves no flag up."""
    op_world, op_intents, op_end = operator_end()
    op_world.set(op_intents, ArmRequest(True, 1))
    *_, end = vehicle_end()
    flagged = op_end.encode_order()
    end.acknowledge(decode_operator_message(flagged))  # type: ignore[arg-type]
    reply = end.encode_reply()  # answers at once: the state before the order is applied
    assert not decode_vehicle_message(reply).state.armed  # type: ignore[union-attr]
    op_end.apply_reply(reply, 1.2)
    assert order_flags(op_end.encode_order()) == (False, False)


def test_each_move_is_a_new_command_with_a_new_seq() -> None:
    op_world, op_intents, op_end = operator_end()
    world, _, intents, end = vehicle_end()
    for k in range(1, 5):
        op_world.set(op_intents, MovementCommand(100 + k, 0.0, (0.1 * k, 0, 0, 0, 0, 0)))
        end.apply_order(op_end.encode_order(), 0.5 * k)
        command = world.get(intents, MovementCommand)
        assert command is not None
        assert (command.seq, command.sampled_s) == (k, 0.5 * k)
        assert command.sticks[0] == round(12.7 * k) / 127
        assert end.order_ack_bit is op_end.order_seq_bit


def test_keep_heading_sets_a_level_attitude_setpoint() -> None:
    op_world, op_intents, op_end = operator_end()
    op_world.set(op_intents, AttitudeSetpoint(quat_wxyz(12.0, -7.0, 123.6)))
    world, _, intents, end = vehicle_end()
    assert end.apply_order(op_end.encode_order(), 1.0)
    setpoint = world.get(intents, AttitudeSetpoint)
    assert setpoint is not None
    assert same_rotation(setpoint.quaternion_wxyz, quat_wxyz(0.0, 0.0, 124.0))
    assert world.origin_of(intents, AttitudeSetpoint) is Origin.REMOTE
    assert world.get(intents, MovementCommand) is None


@pytest.mark.parametrize(
    "order",
    [
        NoOrder(),
        HoldChannel(5),
        GoTo(100, -200, 300, 45),
        OrderIncoming(),
        Move(10, 0, 0, 0, arm=True, mode=Mode.GUIDED),
        Move(10, 0, 0, 0, mode=Mode.POS_HOLD),
    ],
)
def test_unsupported_orders_are_counted_and_change_nothing(order: Order) -> None:
    world, vehicle, intents, end = vehicle_end()
    payload = OperatorMessage(False, False, 0, True, False, order).encode()
    assert end.apply_order(payload, 1.0) is False
    assert (end.counters.applied, end.counters.malformed, end.counters.unsupported) == (0, 0, 1)
    assert world.components(intents) == () and world.components(vehicle) == ()
    assert end.order_ack_bit is False


@pytest.mark.parametrize(
    "payload",
    [
        b"",
        b"\x00",
        bytes((0x00, 0x81, 0x40, 0x81, 0x00, 0x20)),  # move truncated by one byte
        bytes((0x00, 0x81, 0x40, 0x81, 0x00, 0x20, 0x82, 0x00)),  # one byte too many
        bytes((0x00, 0x89, 0, 0, 0, 0, 0)),  # order type 9 does not exist
        bytes((0x00, 0x8F)),  # order type 15
        bytes((0x00, 0xA1, 0, 0, 0, 0, 0)),  # header reserved bit 5
        bytes((0x00, 0x81, 0x80, 0, 0, 0, 0)),  # x = −128 is not a code
        bytes((0x00, 0x81, 0, 0, 0, 0, 0x08)),  # move flags reserved bit 3
        bytes((0x00, 0x81, 0, 0, 0, 0, 0x05)),  # mode 5
        bytes((0x00, 0x82, 0x01, 0x68)),  # heading 360
    ],
)
def test_malformed_orders_are_counted_never_raised(payload: bytes) -> None:
    world, _, intents, end = vehicle_end()
    assert end.apply_order(payload, 1.0) is False
    assert (end.counters.applied, end.counters.malformed, end.counters.unsupported) == (0, 1, 0)
    assert world.components(intents) == ()


# ------------------------------------------------------------------------------- replies


def test_reply_bytes_by_hand() -> None:
    world, vehicle, _, end = vehicle_end()
    world.set(vehicle, Odometry(4.0, (1.234, -0.056, 2.007), quat_wxyz(10.02, -5.01, -90.4)))
    world.set(vehicle, Armed(True))
    world.set(vehicle, ActiveMode(ControlMode.DEPTH_HOLD))
    payload = end.encode_reply()
    assert len(payload) == 14 and len(encode_frame(payload)) == 20
    # state flags: ready 0x80 | keeping heading 0x10 | armed 0x08 | DEPTH_HOLD 2 = 0x9A
    # x = 123.4 cm → 123, y = −5.6 cm → −6, z = 200.7 cm → 201 (int16 big-endian)
    # heading −90.4° → 269.6° → 270; roll 10.02° → 200.4 → 200; pitch −5.01° → −100.2 → −100
    bits = "100001110" + "0000011001000" + "1111110011100" + "00000"  # 9 + 13 + 13 + 5 bits
    attitude = int(bits, 2).to_bytes(5, "big")
    assert attitude == bytes((0x87, 0x03, 0x23, 0xF3, 0x80))
    expected = (
        bytes((0x0C, 0x9A))
        + struct.pack(">hhh", 123, -6, 201)
        + attitude
        + b"\x00"  # no image: chunk info 0, no chunk
    )
    assert payload == expected


def test_reply_echoes_the_order_sequence_bit_and_keeping_heading_follows_the_mode() -> None:
    world, vehicle, _, end = vehicle_end()
    assert end.encode_reply()[1] == 0x80  # ready, MANUAL, disarmed, nothing yet applied
    op_world, op_intents, op_end = operator_end()
    op_world.set(op_intents, ModeRequest(ControlMode.STABILIZE))
    end.apply_order(op_end.encode_order(), 0.0)  # seq bit 1
    world.set(vehicle, ActiveMode(ControlMode.STABILIZE))
    assert end.encode_reply()[1] == 0x80 | 0x40 | 0x10 | 0x01
    end.apply_order(op_end.encode_order(), 0.1)  # seq bit 0
    world.set(vehicle, ActiveMode(ControlMode.MANUAL))
    assert end.encode_reply()[1] == 0x80


def test_operator_applies_a_reply_as_remote_vehicle_state() -> None:
    v_world, vehicle, _, v_end = vehicle_end()
    v_world.set(vehicle, Odometry(4.0, (1.234, -0.056, 2.007), quat_wxyz(10.02, -5.01, -90.4)))
    v_world.set(vehicle, Armed(True))
    v_world.set(vehicle, ActiveMode(ControlMode.DEPTH_HOLD))
    world, intents, end = operator_end()

    assert end.apply_reply(deliver(v_end.encode_reply()), 7.25)
    odometry = world.get(end.vehicle, Odometry)
    assert odometry is not None
    assert odometry.sampled_s == 7.25  # the arrival time: the wire carries none
    assert odometry.position_ned_m == pytest.approx((1.23, -0.06, 2.01), abs=1e-12)
    assert same_rotation(odometry.quaternion_wxyz, quat_wxyz(10.0, -5.0, 270.0))
    assert world.get(end.vehicle, Armed) == Armed(True)
    assert world.get(end.vehicle, ActiveMode) == ActiveMode(ControlMode.DEPTH_HOLD)
    for cls in (Odometry, Armed, ActiveMode):
        assert world.origin_of(end.vehicle, cls) is Origin.REMOTE
    assert world.components(intents) == ()  # the operator's intents are its own
    assert (end.counters.applied, end.counters.malformed) == (1, 0)


def test_reply_quantisation_errors_are_bounded() -> None:
    rng = np.random.default_rng(20240611)
    v_world, vehicle, _, v_end = vehicle_end()
    world, _, end = operator_end()
    for k in range(200):
        x_m, y_m, z_m = (float(v) for v in rng.uniform(-300.0, 300.0, 3))
        position = (x_m, y_m, z_m)
        roll, pitch = (float(v) for v in rng.uniform(-80.0, 80.0, 2))
        yaw = float(rng.uniform(-180.0, 180.0))
        v_world.set(vehicle, Odometry(0.0, position, quat_wxyz(roll, pitch, yaw)))
        assert end.apply_reply(v_end.encode_reply(), float(k))
        odometry = world.get(end.vehicle, Odometry)
        assert odometry is not None
        assert np.max(np.abs(np.subtract(odometry.position_ned_m, position))) <= 0.005 + 1e-9
        x, y, z, w = (*odometry.quaternion_wxyz[1:], odometry.quaternion_wxyz[0])
        yaw_r, pitch_r, roll_r = Rotation.from_quat([x, y, z, w]).as_euler("ZYX", degrees=True)
        assert abs(roll_r - roll) <= 0.025 + 1e-6
        assert abs(pitch_r - pitch) <= 0.025 + 1e-6
        assert abs((yaw_r - yaw + 180.0) % 360.0 - 180.0) <= 0.5 + 1e-6


def test_reply_in_a_mode_the_vehicle_lacks_keeps_the_last_known_mode() -> None:
    world, _, end = operator_end()
    assert end.apply_reply(reply(armed=False, mode=2), 1.0)
    assert end.apply_reply(reply(armed=True, mode=3), 2.0)  # POS_HOLD
    assert world.get(end.vehicle, ActiveMode) == ActiveMode(ControlMode.DEPTH_HOLD)
    assert world.get(end.vehicle, Armed) == Armed(True)


@pytest.mark.parametrize(
    "payload",
    [
        b"",
        reply(armed=True)[:13],  # truncated
        bytes((0x00, 0x81, 0x40, 0x81, 0x00, 0x20, 0x82)),  # an order, not a reply
        bytes((0x0B,)) + reply(armed=True)[1:],  # state length 11
        reply(armed=True, heading=360),
        reply(armed=True, mode=5),
        reply(armed=True)[:13] + b"\x00" + bytes(151),  # chunk of 151 B
    ],
)
def test_malformed_replies_are_counted_never_raised(payload: bytes) -> None:
    world, _, end = operator_end()
    assert end.apply_reply(payload, 1.0) is None
    assert (end.counters.applied, end.counters.malformed) == (0, 1)
    assert world.components(end.vehicle) == ()


# ---------------------------------------------------------------------------------- fuzz

_BODY_SIZES = {0: 0, 1: 5, 2: 2, 3: 1, 4: 8, 5: 0, 6: 8, 7: 0, 8: 8}


def classify_order(payload: bytes) -> str:
    """'applied', 'unsupported' or 'malformed', straight from the REFERENCE §1.3 layout."""
    if len(payload) < 2 or payload[1] & 0x30 or (payload[1] & 0x0F) not in _BODY_SIZES:
        return "malformed"
    code = payload[1] & 0x0F
    body = payload[2:]
    if len(body) != _BODY_SIZES[code]:
        return "malformed"
    if code == 1:
        if 0x80 in body[:4] or body[4] & 0x38 or body[4] & 7 > 4:
            return "malformed"
        return "applied" if body[4] & 7 <= 2 else "unsupported"
    if code == 2:
        return "applied" if int.from_bytes(body, "big") <= 359 else "malformed"
    if code == 4:  # image settings: the vehicle's image source takes them
        return "malformed" if body[5] & 0x0E else "applied"
    if code == 8:  # end-effector go-to: yaw codes 36000..65534 are reserved
        return "malformed" if 36000 <= int.from_bytes(body[6:8], "big") < 0xFFFF else "unsupported"
    return "unsupported"


def classify_reply(payload: bytes) -> str:
    """'applied' or 'malformed', straight from the REFERENCE §1.4 layout."""
    if not 14 <= len(payload) <= 164 or payload[0] & 0x3F != 12 or payload[1] & 7 > 4:
        return "malformed"
    attitude = int.from_bytes(payload[8:13], "big")
    heading = attitude >> 31
    roll = (attitude >> 18) & 0x1FFF
    pitch = (attitude >> 5) & 0x1FFF
    if attitude & 0x1F or heading > 359:
        return "malformed"
    if any(abs(c - 0x2000 if c & 0x1000 else c) > 3600 for c in (roll, pitch)):
        return "malformed"
    return "applied"


def mutate(rng: np.random.Generator, valid: list[bytes]) -> bytes:
    """Random bytes, a bit-flipped valid payload, or a truncated/extended one."""
    kind = rng.integers(3)
    if kind == 0:
        return rng.bytes(int(rng.integers(0, 24)))
    base = bytearray(valid[int(rng.integers(len(valid)))])
    if kind == 1:
        for _ in range(int(rng.integers(1, 4))):
            bit = int(rng.integers(8 * len(base)))
            base[bit // 8] ^= 0x80 >> (bit % 8)
        return bytes(base)
    cut = int(rng.integers(0, len(base) + 3))
    return bytes(base[:cut]) + rng.bytes(max(0, cut - len(base)))


def test_fuzz_orders_are_applied_counted_or_rejected_never_raised() -> None:
    rng = np.random.default_rng(7)
    valid = [
        OperatorMessage(False, False, 0, True, False, order).encode()
        for order in (
            Move(64, -127, 0, 32, True, False, Mode.DEPTH_HOLD),
            Move(1, 2, 3, 4, False, True, Mode.MANUAL),
            KeepHeading(359),
            GoTo(1, 2, 3, 4),
            ImageSettings(1, 2, 3, 4, 5, False, 6),
            HoldChannel(9),
        )
    ]
    world, vehicle, intents, end = vehicle_end()
    expected = {"applied": 0, "malformed": 0, "unsupported": 0}
    n = 3000
    for k in range(n):
        payload = mutate(rng, valid)
        outcome = classify_order(payload)
        expected[outcome] += 1
        assert end.apply_order(payload, float(k)) is (outcome == "applied")
        command = world.get(intents, MovementCommand)
        if command is not None:
            assert all(-1.0 <= s <= 1.0 for s in command.sticks)
            assert command.sticks[3:5] == (0.0, 0.0)
    counters = end.counters
    assert expected == {
        "applied": counters.applied,
        "malformed": counters.malformed,
        "unsupported": counters.unsupported,
    }
    assert min(expected.values()) > 50  # the mix exercised every outcome
    assert world.components(vehicle) == ()


def test_fuzz_replies_are_applied_or_counted_never_raised() -> None:
    rng = np.random.default_rng(11)
    v_world, vehicle, _, v_end = vehicle_end()
    valid = []
    for yaw in (-170.0, 0.0, 95.0):
        v_world.set(vehicle, Odometry(0.0, (1.0, -2.0, 3.0), quat_wxyz(-30.0, 20.0, yaw)))
        v_world.set(vehicle, Armed(yaw > 0))
        valid.append(v_end.encode_reply())
    world, _, end = operator_end()
    applied = malformed = 0
    n = 3000
    for k in range(n):
        payload = mutate(rng, valid)
        ok = classify_reply(payload) == "applied"
        applied += ok
        malformed += not ok
        assert (end.apply_reply(payload, float(k)) is not None) is ok
    assert (end.counters.applied, end.counters.malformed, end.counters.unsupported) == (
        applied,
        malformed,
        0,
    )
    assert min(applied, malformed) > 100
    odometry = world.get(end.vehicle, Odometry)
    assert odometry is not None and math.isclose(
        math.fsum(v * v for v in odometry.quaternion_wxyz), 1.0
    )


def test_image_settings_order_is_acknowledged_and_leaves_the_intents_alone() -> None:
    world, _, intents, end = vehicle_end()
    settings = ImageSettings(10, 20, 60, 50, 4, True, 600)
    payload = OperatorMessage(False, False, 0, True, False, settings).encode()
    assert end.apply_order(payload, 1.0) is True
    assert (end.counters.applied, end.counters.unsupported) == (1, 0)
    assert end.order_ack_bit is True  # echoed in the next reply: the operator knows it landed
    assert world.components(intents) == ()


def test_image_settings_after_a_move_renew_its_sticks_as_contact() -> None:
    """A settings order takes the gap a move order would have: the sticks last sent stay in
    force, renewed as a newer command (same sticks, same arrival time, so its age keeps
    growing), which the vehicle's failsafe counts as contact."""
    world, _, intents, end = vehicle_end()
    move = Move(64, -32, 0, 16, False, False, Mode.DEPTH_HOLD)
    end.apply_order(OperatorMessage(False, False, 0, False, False, move).encode(), 1.0)
    first = world.get(intents, MovementCommand)
    assert first is not None and first.sampled_s == 1.0
    settings = ImageSettings(10, 20, 60, 50, 4, True, 600)
    assert end.apply_order(OperatorMessage(False, False, 0, True, False, settings).encode(), 1.6)
    renewed = world.get(intents, MovementCommand)
    assert renewed == MovementCommand(first.seq + 1, 1.0, first.sticks)


def test_order_header_carries_the_image_request_and_settings_replace_the_move() -> None:
    world = World()
    intents = world.spawn()
    end = TeleopOperatorEnd(world, intents)
    settings = ImageSettings(0, 0, 159, 119, 2, True, 1200)
    message = decode_operator_message(end.encode_order((True, False, 37), settings))
    assert isinstance(message, OperatorMessage)
    assert (message.image_seq_bit, message.cancel_image, message.first_missing_chunk) == (
        True,
        False,
        37,
    )
    assert message.order == settings
    plain = decode_operator_message(end.encode_order())
    assert isinstance(plain, OperatorMessage) and isinstance(plain.order, Move)
    assert (plain.image_seq_bit, plain.first_missing_chunk) == (False, 0)


def test_reply_with_a_40_byte_chunk_is_the_papers_60_byte_frame() -> None:
    @dataclass(frozen=True)
    class Chunk:
        first: bool = True
        last: bool = False
        image_seq_bit: bool = True
        cancel: bool = False
        index: int = 5
        data: bytes = bytes(range(40))

    _, _, _, end = vehicle_end()
    payload = end.encode_reply(Chunk())
    assert len(encode_frame(payload)) == 60  # REFERENCE §1.6: 6 + 1 + 12 + 1 + 40
    message = decode_vehicle_message(payload)
    assert isinstance(message, VehicleMessage)
    assert (message.first_chunk, message.last_chunk, message.image_seq_bit) == (True, False, True)
    assert (message.chunk_index, message.chunk) == (5, bytes(range(40)))
    assert len(encode_frame(end.encode_reply())) == 20


def test_position_setpoint_travels_as_goto_and_the_vehicle_flies_it_in_guided() -> None:
    op_world, op_intents, op_end = operator_end()
    op_world.set(op_intents, ModeRequest(ControlMode.GUIDED))
    op_world.set(op_intents, PositionSetpoint((3.004, -1.006, 1.5), math.radians(-90.0), True))
    payload = op_end.encode_order()
    message = decode_operator_message(payload)
    assert isinstance(message, OperatorMessage)
    assert message.order == GoTo(300, -101, 150, 270)  # 1 cm, whole degrees mod 360
    assert payload[1] == 0x86  # sequence bit 1, no cancel, type 6
    again = op_end.encode_order()  # no reply acknowledged it: the same order, the same bit
    assert again == payload and op_end.counters.goals_acked == 0
    assert op_end.apply_reply(reply(armed=True, mode=4, ack=False), 1.0)  # acks another bit
    assert op_end.encode_order() == payload
    assert op_end.apply_reply(reply(armed=True, mode=4, ack=True), 1.2)
    assert op_end.counters.goals_acked == 1
    follow = decode_operator_message(op_end.encode_order())  # acknowledged: a Move follows
    assert isinstance(follow, OperatorMessage) and isinstance(follow.order, Move)
    assert follow.order.mode is Mode.GUIDED and follow.order_seq_bit is False

    world, vehicle, intents, end = vehicle_end()
    assert end.apply_order(payload, 1.0) is False  # no position fix: refused
    assert end.counters.unsupported == 1 and world.components(intents) == ()
    world.set(vehicle, PositionReading(0.9, (0.0, 0.0, 1.0)))
    assert end.apply_order(payload, 1.0) is True
    setpoint = world.get(intents, PositionSetpoint)
    assert setpoint is not None and setpoint.use_yaw
    assert setpoint.position_ned_m == (3.0, -1.01, 1.5)
    assert math.isclose(setpoint.yaw_rad, math.radians(-90.0))
    assert world.get(intents, ModeRequest) == ModeRequest(ControlMode.GUIDED)
    assert world.origin_of(intents, PositionSetpoint) is Origin.REMOTE


def test_goto_without_a_heading_carries_the_vehicles_reported_heading() -> None:
    world, intents, end = operator_end()
    assert end.apply_reply(reply(armed=True, mode=4, heading=123), 1.0)
    world.set(intents, PositionSetpoint((1.0, 2.0, 0.5)))
    message = decode_operator_message(end.encode_order())
    assert isinstance(message, OperatorMessage)
    assert message.order == GoTo(100, 200, 50, 123)


# --------------------------------------------------------------------- supervised control


def test_a_goal_cancel_sets_the_header_bit_until_a_reply_says_cancelled() -> None:
    world, intents, end = operator_end()
    assert end.encode_order()[1] & 0x40 == 0
    world.set(intents, GoalCancel(1))
    first, second = end.encode_order(), end.encode_order()
    assert first[1] & 0x40 and second[1] & 0x40  # bit 6 of byte 1: cancel last order
    assert end.apply_reply(reply(armed=True, mode=4, cancelled=True), 1.0)
    assert end.encode_order()[1] & 0x40 == 0
    world.set(intents, GoalCancel(1))  # the same cancel again is no new cancel
    assert end.encode_order()[1] & 0x40 == 0


def test_a_cancel_drops_a_goto_not_yet_acknowledged() -> None:
    world, intents, end = operator_end()
    world.set(intents, PositionSetpoint((1.0, 0.0, 1.0)))
    assert end.encode_order()[1] & 0x0F == 6
    world.set(intents, GoalCancel(1))
    payload = end.encode_order()
    assert payload[1] & 0x0F == 1 and payload[1] & 0x40  # a Move carrying the cancel bit


def test_the_cancel_bits_rising_edge_and_disable_keep_heading_cancel_the_goal() -> None:
    world, _vehicle, intents, end = vehicle_end()
    move = Move(0, 0, 0, 0, mode=Mode.DEPTH_HOLD)
    for seq_bit, cancel in ((True, True), (False, True), (True, False), (False, True)):
        payload = OperatorMessage(False, False, 0, seq_bit, cancel, move).encode()
        assert end.apply_order(payload, 1.0)
    assert world.get(intents, GoalCancel) == GoalCancel(2)  # two rising edges
    assert world.origin_of(intents, GoalCancel) is Origin.REMOTE
    payload = OperatorMessage(False, False, 0, True, False, DisableKeepHeading()).encode()
    assert end.apply_order(payload, 2.0)
    assert world.get(intents, GoalCancel) == GoalCancel(3) and end.counters.cancels == 3


def test_reply_flags_follow_the_vehicles_mission_status() -> None:
    world, vehicle, _intents, end = vehicle_end()
    assert end.encode_reply()[1] & 0xA0 == 0x80  # no autonomy: ready, nothing cancelled
    world.set(vehicle, MissionStatus(False, False, 1, 0))
    assert end.encode_reply()[1] & 0xA0 == 0x00  # a goal in progress: not ready
    world.set(vehicle, MissionStatus(True, True, 1, 0))
    assert end.encode_reply()[1] & 0xA0 == 0xA0
    op_world, _, op_end = operator_end()
    assert op_end.apply_reply(end.encode_reply(), 3.0)
    assert op_world.get(op_end.vehicle, MissionStatus) == MissionStatus(True, True)


def test_a_goal_above_the_surface_travels_at_the_surface_and_the_vehicle_takes_it() -> None:
    """A ground station's GUIDED target 3 m above the surface: flown directly, the vehicle's
    position loop holds it at the surface hold depth; through the narrow link it went as a
    negative GoTo depth, which the vehicle refuses (a goal above the surface), so it flew the
    previous target on (a user review). It travels at 0 m now, as a goal the vehicle takes;
    beyond the wire's ±327.67 m a coordinate is clamped to it."""
    world, intents, end = operator_end()
    assert end.apply_reply(reply(armed=True, mode=4, heading=0), 1.0)
    world.set(intents, PositionSetpoint((2.0, 500.0, -3.0)))
    payload = end.encode_order()
    message = decode_operator_message(payload)
    assert isinstance(message, OperatorMessage)
    assert message.order == GoTo(200, 32767, 0, 0)
    v_world, vehicle, v_intents, v_end = vehicle_end()
    v_world.set(vehicle, PositionReading(0.9, (0.0, 0.0, 1.0)))
    assert v_end.apply_order(payload, 1.0) is True
    setpoint = v_world.get(v_intents, PositionSetpoint)
    assert setpoint is not None and setpoint.position_ned_m == (2.0, 327.67, 0.0)
