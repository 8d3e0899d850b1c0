"""MAVLink: the simulated vehicle speaks ArduSub, so a real ground station drives it.

* :mod:`~testbed.mavlink.endpoint` — :class:`VehicleEndpoint`, the sans-IO ArduSub-compatible
  core (fed bytes and the time, returns packets per :class:`Channel`, one ground-station link:
  :mod:`~testbed.mavlink.channel`; what it sends on which link, and its STATUSTEXT queue, in
  :mod:`~testbed.mavlink.outbound`), a pilot of an ECS world, told of the vehicle by its
  :class:`EndpointOptions` (:mod:`~testbed.mavlink.options`);
  its request handlers in :mod:`~testbed.mavlink.commands` and
  :mod:`~testbed.mavlink.param_protocol`, the pilot's sticks in
  :mod:`~testbed.mavlink.pilot_input`, GUIDED's targets in :mod:`~testbed.mavlink.guided` and
  :mod:`~testbed.mavlink.attitude_target`, the motor test in :mod:`~testbed.mavlink.motor_test`,
  its failsafes in :mod:`~testbed.mavlink.failsafe`, its stream rates in
  :mod:`~testbed.mavlink.streams`, MAVLink's high-latency mode (HIGH_LATENCY2,
  MAV_CMD_CONTROL_HIGH_LATENCY) in :mod:`~testbed.mavlink.high_latency`.
* :mod:`~testbed.mavlink.vehicle_snapshot` — the vehicle's components read at one instant
  (:class:`VehicleSnapshot`); :mod:`~testbed.mavlink.telemetry` — a snapshot as ArduSub's
  telemetry messages.
* :mod:`~testbed.mavlink.ardusub` — ArduSub's numbers: modes, heartbeat flags, stream groups,
  MANUAL_CONTROL scaling.
* :mod:`~testbed.mavlink.motors` — ArduSub's motor numbering of a frame (``AP_Motors6DOF``),
  the servo outputs and MOT_n_DIRECTION of a thruster layout, and how a changed MOT_n_DIRECTION
  changes a thruster's pulse.
* :mod:`~testbed.mavlink.params` — the parameter table (``data/ardusub_params.csv``).
* :mod:`~testbed.mavlink.wire` — pymavlink's ``ardupilotmega`` dialect as a bytes codec.
* :mod:`~testbed.mavlink.links` — UDP, TCP and serial links with reader threads.

The real-time run that puts a vehicle behind the endpoint is :mod:`testbed.run.mavlink_run`.
Imports: ``common``, ``ecs``, ``hil`` (serial transport), pymavlink and the standard library.
"""

from __future__ import annotations

from .channel import OUTBOX_LIMIT, Channel
from .endpoint import VehicleEndpoint
from .motors import ServoOutputs, servo_outputs
from .options import EndpointOptions, PositionLoop
from .params import Param, ParamTable, load_params
from .telemetry import HOME_LAT_LON_DEG
from .vehicle_snapshot import VehicleSnapshot
from .wire import MavlinkWire

__all__ = [
    "HOME_LAT_LON_DEG",
    "OUTBOX_LIMIT",
    "Channel",
    "EndpointOptions",
    "MavlinkWire",
    "Param",
    "ParamTable",
    "PositionLoop",
    "ServoOutputs",
    "VehicleEndpoint",
    "VehicleSnapshot",
    "load_params",
    "servo_outputs",
]
