"""The teleop codec's operator end: the operator's intents as orders, the replies as state.

:class:`TeleopOperatorEnd` turns the intents on the operator's entity — sticks
(:class:`MovementCommand`), arm and mode requests, a heading (:class:`AttitudeSetpoint`), goals
(:class:`PositionSetpoint`, :class:`EndEffectorSetpoint`) and :class:`GoalCancel` — into one
order per inter-packet gap, and writes each reply's state onto an entity of its own that mirrors
the vehicle (origin REMOTE): :class:`Odometry`, :class:`Armed`, :class:`ActiveMode` and the
reply's flags as a :class:`MissionStatus`. Which order a gap carries, how goals are sent again
until acknowledged, and how the arm flag and the header's cancel bit are raised and lowered is
the codec's contract, in :mod:`testbed.common.teleop`.

Units and frames: sticks in [−1, 1] (int8 codes on the wire, 1/127); positions world NED [m]
(int16 cm on the wire); headings the yaw of the NED body frame (whole degrees on the wire, from
the quaternion's yaw). The state written is stamped with the reply's arrival time ``now_s``
[s], the wire carrying no time. Garbled replies are counted, never raised. The vehicle's end
is :mod:`testbed.common.teleop_vehicle`; what both share, :mod:`testbed.common.teleop_wire`.
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
)
from testbed.common.geometry import euler_from_quat, quat_from_euler
from testbed.common.teleop_wire import (
    GOAL_ORDERS,
    GoalOrder,
    GoalSetpoint,
    TeleopCounters,
    goal_order,
    mode_from_wire,
    mode_to_wire,
)
from testbed.ecs import Entity, Origin, World
from testbed.protocol import (
    GoTo,
    ImageSettings,
    KeepHeading,
    MalformedPayload,
    Move,
    OperatorMessage,
    VehicleMessage,
    decode_vehicle_message,
)

__all__ = ["TeleopOperatorEnd"]


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
        self._sent_goals: dict[type[GoalSetpoint], GoalSetpoint] = {}
        self._settled_arm: ArmRequest | None = None
        self._orders_encoded = 0
        self._arm_request: tuple[ArmRequest, int] | None = None  # the request, its first order
        self._arm_flag_up = False  # the last order carried the arm flag
        self._flag_bit: bool | None = None  # the sequence bit of the request's last flag order
        self._pending_goal: tuple[GoalOrder, bool] | None = None  # the order and its seq bit
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
        order: Move | KeepHeading | GoalOrder | ImageSettings | None = None
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

    def _changed_goal(self) -> GoalSetpoint | None:
        """The goal intent to send as a new order now: the first kind (vehicle, then end
        effector) whose intent changed since it was last sent, skipping a kind other than the
        one still waiting for its acknowledgement (it goes once that one is acknowledged)."""
        pending = self._pending_goal
        for kind, order_type in GOAL_ORDERS.items():
            target = self._world.get(self._intents, kind)
            if target is None:
                self._sent_goals.pop(kind, None)  # removed: the same goal again is new
                continue
            if target == self._sent_goals.get(kind):
                continue
            if pending is None or isinstance(pending[0], order_type):
                return target
        return None

    def _goal_order(self, target: GoalSetpoint) -> GoalOrder:
        """The order of a goal intent (:func:`~testbed.common.teleop_wire.goal_order`), a
        GoTo that keeps the heading taking the vehicle's last reported one (0° before any)."""
        odometry = self._world.get(self.vehicle, Odometry)
        quaternion = (1.0, 0.0, 0.0, 0.0) if odometry is None else odometry.quaternion_wxyz
        return goal_order(target, math.degrees(euler_from_quat(quaternion)[2]))

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
