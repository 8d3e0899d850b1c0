"""The teleop codec's vehicle end: orders as the operator's intents, the state as replies.

:class:`TeleopVehicleEnd` decodes each order and writes what it asks for onto the entity that
carries the operator's intents in the vehicle's world (origin REMOTE): sticks as a
:class:`MovementCommand` stamped with the arrival time, arm and mode requests, a heading as an
:class:`AttitudeSetpoint`, goals as a :class:`PositionSetpoint` (flown in GUIDED) or an
:class:`EndEffectorSetpoint`, and the header's cancel bit (its rising edge) or a
``DisableKeepHeading`` as a :class:`GoalCancel` that also removes the position goal. Its replies
carry the vehicle's :class:`Odometry`, :class:`Armed` and :class:`ActiveMode` as a
``VehicleState``, the order sequence bit it acknowledges, and the ready and last-order-cancelled
flags: a vehicle with autonomy's from its :class:`MissionStatus`; one without is ready, and
cancelled from the cancel it applied until the next goal order it takes. The codec's contract
as a whole is in :mod:`testbed.common.teleop`.

Units and frames: sticks in [−1, 1] (int8/127 on the wire); positions world NED [m] (int16 cm
on the wire, 1 cm in the state); headings the yaw of the NED body frame (whole degrees on the
wire; the state's roll and pitch 0.05°). Goals need a position fix (:class:`PositionReading`):
without one, and for a goal above the surface, an order is refused and counted unsupported.
Garbled payloads are counted, never raised. The operator's end is
:mod:`testbed.common.teleop_operator`; what both share, :mod:`testbed.common.teleop_wire`.
"""

from __future__ import annotations

import math

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
from testbed.common.geometry import euler_from_quat, quat_from_euler
from testbed.common.teleop_wire import (
    ReplyChunk,
    TeleopCounters,
    goal_setpoint,
    mode_from_wire,
    mode_to_wire,
)
from testbed.ecs import Entity, Origin, World
from testbed.protocol import (
    DisableKeepHeading,
    GoTo,
    ImageSettings,
    KeepHeading,
    MalformedPayload,
    Move,
    OperatorMessage,
    VehicleMessage,
    VehicleState,
    decode_operator_message,
)
from testbed.protocol.orders import EndEffectorGoTo

__all__ = ["TeleopVehicleEnd"]


class TeleopVehicleEnd:
    """The vehicle's end: applies orders as operator intents, encodes replies from its state.

    Args:
        world: the vehicle's world.
        vehicle: the entity carrying the vehicle's own state.
        intents: the entity the operator's intents are written to (origin REMOTE).

    Attributes:
        counters: what happened to the orders.
        order_ack_bit: the sequence bit of the last order applied (echoed in replies).
    """

    def __init__(self, world: World, vehicle: Entity, intents: Entity) -> None:
        self._world = world
        self._vehicle = vehicle
        self._intents = intents
        self.counters = TeleopCounters()
        self.order_ack_bit = False
        self._seq = 0
        self._arm_seq = 0
        self._arm_held = False  # the last intact Move carried the arm flag
        self._cancel_seq = 0
        self._cancelling = False  # the last intact order carried the cancel bit
        self._goal_cancelled = False  # (no MissionStatus) a cancel was applied since the last goal

    def apply_order(self, payload: bytes, now_s: float) -> bool:
        """Apply an order's intents; False (counted) if the payload is garbled or unsupported."""
        message = decode_operator_message(payload)
        if isinstance(message, MalformedPayload):
            self.counters.malformed += 1
            return False
        order = message.order
        world = self._world
        intents = self._intents
        if message.cancel_order and not self._cancelling:
            self._cancel()
        self._cancelling = message.cancel_order
        has_fix = world.has(self._vehicle, PositionReading)
        if isinstance(order, Move):
            mode = mode_from_wire(order.mode)
            if mode is None or (mode is ControlMode.GUIDED and not has_fix):
                self.counters.unsupported += 1
                return False
            armed = world.get(self._vehicle, Armed)
            is_armed = armed is not None and armed.armed
            # the arm flag arms on its rising edge only (as ArduSub, a disarm by the vehicle
            # itself stays until the operator asks again): a flag held over several orders is
            # one request; it drops for an order between two
            arm = order.arm and not is_armed and not self._arm_held
            self._arm_held = order.arm
            if arm or (order.disarm and is_armed):
                self._arm_seq += 1
                request = ArmRequest(order.arm, self._arm_seq)
                world.set(intents, request, origin=Origin.REMOTE)
            world.set(intents, ModeRequest(mode), origin=Origin.REMOTE)
            x, y, z, yaw = order.axes
            self._seq += 1
            command = MovementCommand(self._seq, now_s, (x, y, z, 0.0, 0.0, yaw))
            world.set(intents, command, origin=Origin.REMOTE)
        elif isinstance(order, GoTo | EndEffectorGoTo):
            if not has_fix or order.z_cm < 0:  # a goal in the fix's frame, in the water
                self.counters.unsupported += 1
                return False
            world.set(intents, goal_setpoint(order), origin=Origin.REMOTE)
            self._goal_cancelled = False  # a new goal: the last order is no longer cancelled
            if isinstance(order, GoTo):  # the vehicle flies its goal in GUIDED
                world.set(intents, ModeRequest(ControlMode.GUIDED), origin=Origin.REMOTE)
        elif isinstance(order, KeepHeading):
            yaw = math.radians(order.heading_deg)
            world.set(
                intents, AttitudeSetpoint(quat_from_euler(0.0, 0.0, yaw)), origin=Origin.REMOTE
            )
        elif isinstance(order, DisableKeepHeading):
            self._cancel()
        elif isinstance(order, ImageSettings):  # the coder's (the image source takes them)
            # An order in the gap a move order would have used: the sticks last sent stay in
            # force and the operator is in contact, so the stick command is renewed (same sticks,
            # same arrival time: its age keeps growing) for the failsafe to count it — else one
            # settings order under token passing (two gaps between moves, 1.19 s on the S100)
            # outlasts the 1-s hold timeout and holds a vehicle whose operator is there.
            last = world.get(intents, MovementCommand)
            if last is not None:
                self._seq += 1
                renewed = MovementCommand(self._seq, last.sampled_s, last.sticks)
                world.set(intents, renewed, origin=Origin.REMOTE)
        else:
            self.counters.unsupported += 1
            return False
        self.order_ack_bit = message.order_seq_bit
        self.counters.applied += 1
        return True

    def _cancel(self) -> None:
        """Write a new :class:`GoalCancel` intent (the vehicle's autonomy drops its goal) and
        remove the position goal (GUIDED's position loop lets go of it)."""
        self._cancel_seq += 1
        self.counters.cancels += 1
        self._goal_cancelled = True
        world = self._world
        world.set(self._intents, GoalCancel(self._cancel_seq), origin=Origin.REMOTE)
        world.remove(self._intents, PositionSetpoint, origin=Origin.REMOTE)

    def acknowledge(self, message: OperatorMessage) -> None:
        """Echo this intact order's sequence bit in the replies from now on.

        A token-passing reply answers its order at once, before the order is applied at the
        vehicle's next frame; the reply still acknowledges the order it answers.
        """
        self.order_ack_bit = message.order_seq_bit

    def encode_reply(self, chunk: ReplyChunk | None = None) -> bytes:
        """The payload of a reply: the vehicle state and an image chunk, if any.

        Args:
            chunk: the image chunk to carry; None = no image (14 B; a 20-B frame). A 40-B
                chunk makes a 54-B payload (60-B frame).
        """
        world = self._world
        vehicle = self._vehicle
        odometry = world.get(vehicle, Odometry)
        armed = world.get(vehicle, Armed)
        active = world.get(vehicle, ActiveMode)
        mode = ControlMode.MANUAL if active is None else active.mode
        if odometry is None:
            position: tuple[float, float, float] = (0.0, 0.0, 0.0)
            roll = pitch = yaw = 0.0
        else:
            position = odometry.position_ned_m
            roll, pitch, yaw = euler_from_quat(odometry.quaternion_wxyz)
        # A vehicle with autonomy reports its mission's flags; one without has no goal in
        # progress (ready) and has honoured a cancel once it applied it: dropping the position
        # goal is all there is to do (until the next goal order it applies).
        mission = world.get(vehicle, MissionStatus)
        state = VehicleState(
            ready=mission is None or mission.ready,
            order_ack_bit=self.order_ack_bit,
            last_order_cancelled=self._goal_cancelled if mission is None else mission.cancelled,
            keeping_heading=mode is not ControlMode.MANUAL,
            armed=armed is not None and armed.armed,
            mode=mode_to_wire(mode),
            x_m=position[0],
            y_m=position[1],
            z_m=position[2],
            heading_deg=math.degrees(yaw) % 360.0,
            roll_deg=math.degrees(roll),
            pitch_deg=math.degrees(pitch),
        )
        if chunk is None:
            return VehicleMessage(False, False, state, False, False, 0, b"").encode()
        return VehicleMessage(
            chunk.first,
            chunk.last,
            state,
            chunk.image_seq_bit,
            chunk.cancel,
            chunk.index,
            chunk.data,
        ).encode()
