"""The compact teleop codec: ECS intents and state as the narrow-band paper's orders and replies.

On a narrow link (S100, M64) the full change-set codec does not fit: the paper sends one
7-byte order (13-byte frame) per inter-packet gap and gets one reply carrying the 12-byte
vehicle state (REFERENCE §1.3–1.6). This module maps the replicated components onto those
layouts and back:

operator → vehicle (:class:`TeleopOperatorEnd.encode_order`, :class:`TeleopVehicleEnd.apply_order`)
    the latest :class:`MovementCommand` becomes a ``Move`` (x, y, z, yaw stick codes, int8, so
    sticks are quantised to 1/127), with the arm/disarm flags while an :class:`ArmRequest` is
    neither reflected in the vehicle's reported state nor acknowledged in an order that carried
    it (once per request: a later disarm by the vehicle itself is not undone; the vehicle arms
    on the flag's rising edge only, so a new request after a flag still up drops it for one
    order), and the requested mode; a changed :class:`AttitudeSetpoint`
    becomes a ``KeepHeading`` when its heading in whole degrees changed (only the heading
    travels, roll and pitch setpoints cannot); a changed :class:`PositionSetpoint` becomes a
    ``GoTo`` (1 cm; its heading, or the vehicle's reported one when the setpoint keeps the
    heading), which the vehicle flies as that setpoint in GUIDED — refused (counted
    unsupported) by a vehicle without a position fix, as is a ``Move`` asking for GUIDED, and a
    goal above the surface (a negative depth, either goal order; the operator's end sends a
    goal above the surface at 0 m, and coordinates beyond ±327.67 m at that bound); a
    changed :class:`EndEffectorSetpoint` becomes an ``EndEffectorGoTo`` (the extension's code
    8: 1 cm, the tool yaw in 0.01° or none), which the vehicle writes back as that setpoint
    (its mode untouched; refused without a position fix too, the target being in the fix's
    frame). Each new order toggles the order sequence bit. Both are *goals* and go through
    one path: a goal order is sent again, with the same sequence bit, in every gap until a
    reply acknowledges that bit (a lost goal is not lost: ``counters.goals_acked`` counts the
    acknowledged ones); a newer goal of the same kind replaces one not yet acknowledged, a
    goal of the other kind waits for that acknowledgement (neither is dropped). A new
    :class:`GoalCancel` drops the unacknowledged goal, whichever kind, and sets the header's
    "cancel last order" bit on every order until a reply says the last order was cancelled.
    The vehicle turns the bit's rising edge, and a ``DisableKeepHeading``, into a
    :class:`GoalCancel` of its own intents (which cancels either goal) and removes the
    :class:`PositionSetpoint` a ``GoTo`` left there (a vehicle without autonomy flies it in
    GUIDED until then). A goal intent the operator removed is forgotten: written again, the
    same goal is a new order. What a gap carries
    when several wait: a ``Move`` that arms, disarms or leaves for a mode other than GUIDED
    first (a heading or goal changing every gap, as a ground station streaming targets
    through the gateway, would otherwise starve a disarm, or a pilot taking back the sticks);
    then the coder's settings, a changed heading, a goal (a ``GoTo`` also carries a change to
    GUIDED, which its vehicle flies it in), a goal not yet acknowledged, and the ``Move``.
vehicle → operator (:class:`TeleopVehicleEnd.encode_reply`, :class:`TeleopOperatorEnd.apply_reply`)
    :class:`Odometry`, :class:`Armed` and :class:`ActiveMode` become a ``VehicleState`` (1 cm,
    1° heading, 0.05° roll/pitch) in a reply without an image chunk (20-byte frame); a
    vehicle with autonomy sets the state's ready and last-order-cancelled flags from its
    :class:`MissionStatus`; one without is always ready, and says the last order was
    cancelled once it has applied a cancel (the bit's rising edge or a ``DisableKeepHeading``:
    dropping its position goal is all a cancel asks of it) until it takes the next goal order
    (else the operator's cancel bit stayed up for the rest of the run, and a second cancel with
    no goal between was no new edge). The operator's end keeps the flags as a
    :class:`MissionStatus` of its own.

What the wire does not carry is not invented: a ``Move`` has no sample time, so the vehicle
stamps the :class:`MovementCommand` it writes with the arrival time, and the operator stamps the
:class:`Odometry` it writes with the reply's arrival time. (The simulation's recorder knows the
true times through the frame ids; nodes never see them.) Garbled payloads are counted and
ignored, never raised. Each end writes only the other side's components, with origin REMOTE.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

from testbed.common.components import (
    ActiveMode,
    Armed,
    ArmRequest,
    AttitudeSetpoint,
    ControlMode,
    EndEffectorSetpoint,
    GoalCancel,
    MissionStatus,
    ModeRequest,
    MovementCommand,
    Odometry,
    PositionReading,
    PositionSetpoint,
)
from testbed.common.geometry import euler_from_quat, quat_from_euler
from testbed.ecs import Entity, Origin, World
from testbed.protocol import (
    DisableKeepHeading,
    GoTo,
    ImageSettings,
    KeepHeading,
    MalformedPayload,
    Mode,
    Move,
    OperatorMessage,
    VehicleMessage,
    VehicleState,
    decode_operator_message,
    decode_vehicle_message,
)
from testbed.protocol.orders import EndEffectorGoTo

__all__ = [
    "ReplyChunk",
    "TeleopCounters",
    "TeleopOperatorEnd",
    "TeleopVehicleEnd",
    "mode_from_wire",
    "mode_to_wire",
]

_TO_WIRE = {
    ControlMode.MANUAL: Mode.MANUAL,
    ControlMode.STABILIZE: Mode.STABILIZE,
    ControlMode.DEPTH_HOLD: Mode.DEPTH_HOLD,
    ControlMode.GUIDED: Mode.GUIDED,
}
_FROM_WIRE = {wire: mode for mode, wire in _TO_WIRE.items()}

_GoalSetpoint = PositionSetpoint | EndEffectorSetpoint
"""An intent that travels as a goal order (sent again until acknowledged)."""
_GoalOrder = GoTo | EndEffectorGoTo
"""The goal orders, one per :data:`_GoalSetpoint` kind."""
_GOAL_ORDERS: dict[type[_GoalSetpoint], type[_GoalOrder]] = {
    PositionSetpoint: GoTo,
    EndEffectorSetpoint: EndEffectorGoTo,
}
"""Goal intent → its order, in the order changed goals are taken within one gap."""
_YAW_CDEG = 36000  # the EndEffectorGoTo's tool yaw codes per turn


class ReplyChunk(Protocol):
    """The image fields of a reply (what an image sender hands out for each reply)."""

    @property
    def first(self) -> bool: ...
    @property
    def last(self) -> bool: ...
    @property
    def image_seq_bit(self) -> bool: ...
    @property
    def cancel(self) -> bool: ...
    @property
    def index(self) -> int: ...
    @property
    def data(self) -> bytes: ...


def mode_to_wire(mode: ControlMode) -> Mode:
    """The protocol's 3-bit mode for a vehicle control mode."""
    return _TO_WIRE[mode]


def mode_from_wire(mode: Mode) -> ControlMode | None:
    """The vehicle control mode for a protocol mode, or None if the vehicle has no such mode."""
    return _FROM_WIRE.get(mode)


@dataclass(slots=True)
class TeleopCounters:
    """What one end did with the payloads it was given.

    Attributes:
        applied: payloads decoded and applied.
        malformed: payloads that did not decode (garbled past the CRC, or a foreign layout).
        unsupported: orders decoded but not supported by this vehicle (e.g. POS_HOLD, or
            GUIDED and go-to without a position fix).
        goals_acked: (operator end) goal orders (GoTo, EndEffectorGoTo) a reply acknowledged.
        cancels: (vehicle end) goal cancels applied.
    """

    applied: int = 0
    malformed: int = 0
    unsupported: int = 0
    goals_acked: int = 0
    cancels: int = 0


class TeleopOperatorEnd:
    """The operator's end: encodes orders from its intents, applies the vehicle's replies.

    Args:
        world: the operator's world.
        intents: the entity carrying the operator's intents.

    Attributes:
        vehicle: the entity that holds the vehicle's state as last received (origin REMOTE).
        counters: what happened to the replies.
        order_seq_bit: the sequence bit of the last order encoded.
    """

    def __init__(self, world: World, intents: Entity) -> None:
        self._world = world
        self._intents = intents
        self.vehicle: Entity = world.spawn()
        self.counters = TeleopCounters()
        self.order_seq_bit = False
        self._sent_attitude: AttitudeSetpoint | None = None
        self._sent_heading: KeepHeading | None = None
        self._sent_mode: ControlMode | None = None  # the mode the last Move carried
        self._sent_goals: dict[type[_GoalSetpoint], _GoalSetpoint] = {}
        self._settled_arm: ArmRequest | None = None
        self._orders_encoded = 0
        self._arm_request: tuple[ArmRequest, int] | None = None  # the request, its first order
        self._arm_flag_up = False  # the last order carried the arm flag
        self._flag_bit: bool | None = None  # the sequence bit of the request's last flag order
        self._pending_goal: tuple[_GoalOrder, bool] | None = None  # the order and its seq bit
        self._sent_cancel: GoalCancel | None = None
        self._pending_cancel = False

    def encode_order(
        self,
        image_request: tuple[bool, bool, int] = (False, False, 0),
        image_settings: ImageSettings | None = None,
    ) -> bytes:
        """The payload of the next order (one per inter-packet gap).

        Args:
            image_request: the header's image fields: (expected image sequence bit, cancel the
                image, index of the first missing chunk).
            image_settings: send these coder settings as this gap's order (unless a Move that
                arms, disarms or changes the mode is due, which goes first: module docstring).
        """
        world = self._world
        intents = self._intents
        cancel = world.get(intents, GoalCancel)
        if cancel is not None and cancel != self._sent_cancel:
            self._sent_cancel, self._pending_cancel = cancel, True
            self._pending_goal = None  # the cancel supersedes a goal not yet acknowledged
        request = world.get(intents, ArmRequest)
        self._orders_encoded += 1  # this order's number
        new_request = False
        if request is not None and (self._arm_request is None or self._arm_request[0] != request):
            self._arm_request, self._flag_bit = (request, self._orders_encoded), None
            new_request = True
        reported = world.get(self.vehicle, Armed)
        vehicle_armed = reported is not None and reported.armed
        arm = disarm = False
        if request is not None and request != self._settled_arm:
            arm = request.armed and not vehicle_armed
            disarm = not request.armed and vehicle_armed
        if new_request and arm and self._arm_flag_up:  # the arm flag drops for one order:
            arm = False  # the vehicle arms on its rising edge, a new press
        mode_request = world.get(intents, ModeRequest)
        mode = ControlMode.MANUAL if mode_request is None else mode_request.mode
        # A Move that arms, disarms or leaves for a mode other than GUIDED goes before any
        # heading or goal (one changing every gap, as a ground station streaming targets, would
        # starve it: a pilot taking back the sticks, a disarm). GUIDED is what a GoTo asks the
        # vehicle for anyway, so a GoTo sent goes as that mode change.
        leaves_mode = mode_request is not None and mode != self._sent_mode
        move_first = arm or disarm or (leaves_mode and mode is not ControlMode.GUIDED)
        setpoint = world.get(intents, AttitudeSetpoint)
        order: Move | KeepHeading | _GoalOrder | ImageSettings | None = None
        resent_bit: bool | None = None  # a goal sent again keeps its sequence bit
        if image_settings is not None and not move_first:
            order = image_settings
        elif setpoint is not None and setpoint != self._sent_attitude and not move_first:
            self._sent_attitude = setpoint
            yaw_deg = math.degrees(euler_from_quat(setpoint.quaternion_wxyz)[2])
            heading = KeepHeading.from_degrees(yaw_deg)
            if heading != self._sent_heading:  # a roll/pitch-only change has nothing to send
                self._sent_heading = order = heading
        target = None if order is not None or move_first else self._changed_goal()
        if target is not None:
            self._sent_goals[type(target)] = target
            order = self._goal_order(target)
            if isinstance(order, GoTo):
                self._sent_mode = ControlMode.GUIDED  # the vehicle flies a GoTo in GUIDED
            self._pending_goal = (order, not self.order_seq_bit)
            self._pending_cancel = False
        elif order is None and self._pending_goal is not None and not move_first:
            order, resent_bit = self._pending_goal  # again, until a reply acknowledges it
        if resent_bit is None:
            self.order_seq_bit = not self.order_seq_bit
        if order is None:
            command = world.get(intents, MovementCommand)
            sticks = (0.0,) * 6 if command is None else command.sticks
            self._sent_mode = mode
            order = Move.from_axes(
                sticks[0], sticks[1], sticks[2], sticks[5], arm, disarm, mode_to_wire(mode)
            )
        seq_bit, cancel_image, first_missing = image_request
        order_bit = self.order_seq_bit if resent_bit is None else resent_bit
        move = isinstance(order, Move)
        self._arm_flag_up = move and arm
        if move and (arm or disarm):
            self._flag_bit = order_bit
        message = OperatorMessage(
            seq_bit, cancel_image, first_missing, order_bit, self._pending_cancel, order
        )
        return message.encode()

    def _changed_goal(self) -> _GoalSetpoint | None:
        """The goal intent to send as a new order now: the first kind (vehicle, then end
        effector) whose intent changed since it was last sent, skipping a kind other than the
        one still waiting for its acknowledgement (it goes once that one is acknowledged)."""
        pending = self._pending_goal
        for kind, order_type in _GOAL_ORDERS.items():
            target = self._world.get(self._intents, kind)
            if target is None:
                self._sent_goals.pop(kind, None)  # removed: the same goal again is new
                continue
            if target == self._sent_goals.get(kind):
                continue
            if pending is None or isinstance(pending[0], order_type):
                return target
        return None

    def _goal_order(self, target: _GoalSetpoint) -> _GoalOrder:
        """The order of a goal intent: int16 cm, clamped (±327.67 m, the wire's range), for
        both, a depth above the surface clamped to it (0 m: the vehicle refuses a negative one,
        and a vehicle flown directly takes such a goal at the surface too); a GoTo's heading in
        whole degrees (the setpoint's, or the vehicle's last reported one), an
        EndEffectorGoTo's tool yaw in 0.01° (or none)."""
        x, y, z = (max(-32768, min(32767, round(100.0 * v))) for v in target.position_ned_m)
        z = max(0, z)
        if isinstance(target, EndEffectorSetpoint):
            yaw = round(100.0 * math.degrees(target.yaw_rad)) % _YAW_CDEG
            return EndEffectorGoTo(x, y, z, yaw if target.use_yaw else None)
        if target.use_yaw:
            heading = math.degrees(target.yaw_rad)
        else:
            odometry = self._world.get(self.vehicle, Odometry)
            quaternion = (1.0, 0.0, 0.0, 0.0) if odometry is None else odometry.quaternion_wxyz
            heading = math.degrees(euler_from_quat(quaternion)[2])
        return GoTo(x, y, z, round(heading) % 360)

    def apply_reply(self, payload: bytes, now_s: float) -> VehicleMessage | None:
        """Apply a reply's state to the vehicle entity.

        Returns:
            The decoded reply (its image chunk is the caller's), or None (counted) if it is
            garbled.
        """
        message = decode_vehicle_message(payload)
        if isinstance(message, MalformedPayload):
            self.counters.malformed += 1
            return None
        state = message.state
        world = self._world
        vehicle = self.vehicle
        roll, pitch, yaw = (
            math.radians(a) for a in (state.roll_deg, state.pitch_deg, state.heading_deg)
        )
        odometry = Odometry(
            now_s, (state.x_m, state.y_m, state.z_m), quat_from_euler(roll, pitch, yaw)
        )
        world.set(vehicle, odometry, origin=Origin.REMOTE)
        world.set(vehicle, Armed(state.armed), origin=Origin.REMOTE)
        # A request is settled once a reply shows it done: done once, a later change on the
        # vehicle's side (a failsafe disarm) is not undone; only a new request (new seq) asks
        # again. The reply answers the last order and shows the state from before the vehicle
        # applied it, so only a reply to an order after the request's first shows the request
        # applied (one to that order may show the state an earlier order is about to change:
        # arm, then disarm before the arm's reply came, settled the disarm on the stale
        # 'disarmed' and the vehicle stayed armed).
        # A request is also settled once a reply acknowledges an order that carried its flag
        # (under token passing a reply answers the last order): the vehicle has it and acts on
        # it at once, so a link lost just after need not leave the flag up, to arm the vehicle
        # again when the link comes back after its own failsafe disarmed it.
        request = world.get(self._intents, ArmRequest)
        carried = self._arm_request
        current = carried is not None and carried[0] == request
        shown = current and carried is not None and self._orders_encoded > carried[1]
        acked = current and self._flag_bit is not None and state.order_ack_bit == self._flag_bit
        if request is not None and ((shown and request.armed == state.armed) or acked):
            self._settled_arm = request
        mode = mode_from_wire(state.mode)
        if mode is not None:
            world.set(vehicle, ActiveMode(mode), origin=Origin.REMOTE)
        status = MissionStatus(state.ready, state.last_order_cancelled)
        world.set(vehicle, status, origin=Origin.REMOTE)
        pending = self._pending_goal
        if pending is not None and state.order_ack_bit == pending[1]:
            self._pending_goal = None
            self.counters.goals_acked += 1
        if self._pending_cancel and state.last_order_cancelled:
            self._pending_cancel = False
        self.counters.applied += 1
        return message


def _goal_setpoint(order: _GoalOrder) -> _GoalSetpoint:
    """The goal intent a goal order carries (cm → m; the angle → rad in (−π, π])."""
    target = (order.x_cm / 100.0, order.y_cm / 100.0, order.z_cm / 100.0)
    if isinstance(order, GoTo):
        yaw = math.remainder(math.radians(order.heading % 360), math.tau)
        return PositionSetpoint(target, yaw, True)
    if order.yaw_cdeg is None:
        return EndEffectorSetpoint(target)
    yaw = math.remainder(math.radians(order.yaw_cdeg / 100.0), math.tau)
    return EndEffectorSetpoint(target, yaw, True)


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
            world.set(intents, _goal_setpoint(order), origin=Origin.REMOTE)
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
