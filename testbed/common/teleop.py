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

Where it lives: :mod:`testbed.common.teleop_operator` (the operator's end),
:mod:`testbed.common.teleop_vehicle` (the vehicle's end) and :mod:`testbed.common.teleop_wire`
(what both share: the mode mapping, goal intents ↔ goal orders, the counters, a reply's image
fields). This module is the codec's contract and its one import path: it holds no code of its
own, only the names the nodes, the gateway and the tests import.
"""

from __future__ import annotations

from testbed.common.teleop_operator import TeleopOperatorEnd
from testbed.common.teleop_vehicle import TeleopVehicleEnd
from testbed.common.teleop_wire import ReplyChunk, TeleopCounters, mode_from_wire, mode_to_wire

__all__ = [
    "ReplyChunk",
    "TeleopCounters",
    "TeleopOperatorEnd",
    "TeleopVehicleEnd",
    "mode_from_wire",
    "mode_to_wire",
]
