"""What both ends of the teleop codec share: modes and goals as the wire carries them.

The control-mode mapping onto the protocol's 3-bit mode, the two goal intents and their orders
(:class:`PositionSetpoint` ↔ ``GoTo``, :class:`EndEffectorSetpoint` ↔ ``EndEffectorGoTo``)
both ways with the wire's units, the counters each end keeps and the shape of a reply's image
fields. Positions are world NED [m] in the components and int16 cm on the wire (±327.67 m);
headings are the yaw of the NED body frame, rad in (−π, π] in the components, whole degrees
[0, 360) in a ``GoTo``, 0.01° [0, 36000) in an ``EndEffectorGoTo``'s tool yaw.

The ends themselves are :mod:`testbed.common.teleop_operator` and
:mod:`testbed.common.teleop_vehicle`; the codec as a whole is described in
:mod:`testbed.common.teleop`. Nothing here reads or writes a world.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

from testbed.common.components import ControlMode, EndEffectorSetpoint, PositionSetpoint
from testbed.protocol import GoTo, Mode
from testbed.protocol.orders import EndEffectorGoTo

__all__ = [
    "GOAL_ORDERS",
    "GoalOrder",
    "GoalSetpoint",
    "ReplyChunk",
    "TeleopCounters",
    "goal_order",
    "goal_setpoint",
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

GoalSetpoint = PositionSetpoint | EndEffectorSetpoint
"""An intent that travels as a goal order (sent again until acknowledged)."""
GoalOrder = GoTo | EndEffectorGoTo
"""The goal orders, one per :data:`GoalSetpoint` kind."""
GOAL_ORDERS: dict[type[GoalSetpoint], type[GoalOrder]] = {
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


def goal_order(target: GoalSetpoint, reported_heading_deg: float) -> GoalOrder:
    """The order of a goal intent.

    Int16 cm, clamped (±327.67 m, the wire's range), for both, a depth above the surface
    clamped to it (0 m: the vehicle refuses a negative one, and a vehicle flown directly takes
    such a goal at the surface too); a GoTo's heading in whole degrees (the setpoint's, or the
    vehicle's last reported one), an EndEffectorGoTo's tool yaw in 0.01° (or none).

    Args:
        target: the goal intent (world NED [m], yaw [rad]).
        reported_heading_deg: the vehicle's last reported heading [deg], the GoTo's heading
            when the setpoint keeps the heading (``use_yaw`` false).
    """
    x, y, z = (max(-32768, min(32767, round(100.0 * v))) for v in target.position_ned_m)
    z = max(0, z)
    if isinstance(target, EndEffectorSetpoint):
        yaw = round(100.0 * math.degrees(target.yaw_rad)) % _YAW_CDEG
        return EndEffectorGoTo(x, y, z, yaw if target.use_yaw else None)
    heading = math.degrees(target.yaw_rad) if target.use_yaw else reported_heading_deg
    return GoTo(x, y, z, round(heading) % 360)


def goal_setpoint(order: GoalOrder) -> GoalSetpoint:
    """The goal intent a goal order carries (cm → m; the angle → rad in (−π, π])."""
    target = (order.x_cm / 100.0, order.y_cm / 100.0, order.z_cm / 100.0)
    if isinstance(order, GoTo):
        yaw = math.remainder(math.radians(order.heading % 360), math.tau)
        return PositionSetpoint(target, yaw, True)
    if order.yaw_cdeg is None:
        return EndEffectorSetpoint(target)
    yaw = math.remainder(math.radians(order.yaw_cdeg / 100.0), math.tau)
    return EndEffectorSetpoint(target, yaw, True)
