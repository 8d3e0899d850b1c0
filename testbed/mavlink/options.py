"""What the endpoint is told of the vehicle it presents: :class:`EndpointOptions`.

``testbed.mavlink`` never reads the vehicle's own configuration (it does not import
``testbed.vehicle``): whoever builds the endpoint hands these facts over —
:func:`testbed.run.mavlink_run.endpoint_options` for a MAVLink run, from the vehicle's
configuration and its position loop's reach. Values only; nothing here acts.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from testbed.ecs import Origin
from testbed.mavlink.motors import ServoOutputs

__all__ = ["EndpointOptions"]


@dataclass(frozen=True, slots=True)
class EndpointOptions:
    """How the endpoint presents the vehicle.

    Attributes:
        battery_voltage_v: battery voltage reported [V] (the thrusters' supply).
        param_overrides: boot values replacing the table's (``FRAME_CONFIG`` of the layout,
            ``BARO_SPEC_GRAV`` of the depth sensor…).
        origin: the origin of the endpoint's writes (REMOTE on the vehicle, as a peer's
            intents arrive; LOCAL in a gateway's operator world).
        params_per_update: PARAM_VALUEs a channel sends per update during a parameter download
            (ArduPilot paces them by link bandwidth).
        servos: which thruster's pulse each SERVO_OUTPUT_RAW channel carries (ArduSub's motor
            numbering for an ArduSub frame; by default thruster k on servo k + 1).
        guided_leash_m: how far a GUIDED target moving at a velocity may run ahead of the
            reported position, horizontally [m]: the distance from which the vehicle's position
            loop asks for its top speed (unlimited by default; :mod:`~testbed.mavlink.guided`).
    """

    battery_voltage_v: float = 14.8
    param_overrides: dict[str, float] = field(default_factory=dict)
    origin: Origin = Origin.REMOTE
    params_per_update: int = 20
    servos: ServoOutputs = field(default_factory=ServoOutputs)
    guided_leash_m: float = math.inf
