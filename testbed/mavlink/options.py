"""What the endpoint is told of the vehicle it presents: :class:`EndpointOptions`, and the
vehicle's GUIDED loops as ArduSub's position controller would describe them
(:class:`PositionLoop`).

``testbed.mavlink`` never reads the vehicle's own configuration (it does not import
``testbed.vehicle``): whoever builds the endpoint hands these facts over —
:func:`testbed.run.mavlink_run.endpoint_options` for a MAVLink run, from the vehicle's
configuration and its position loop's gains. Values only; nothing here acts.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from testbed.ecs import Origin
from testbed.mavlink.motors import ServoOutputs

__all__ = ["EndpointOptions", "PositionLoop"]


@dataclass(frozen=True, slots=True)
class PositionLoop:
    """The vehicle's GUIDED loops in the terms of ArduSub's position controller: the gain that
    turns a position error into a speed demand, and that demand's limit. GUIDED's stopping
    point (:mod:`~testbed.mavlink.guided_entry`) and the leash of a moving target
    (:mod:`~testbed.mavlink.guided`) are computed with them. The simulated loops shape no
    acceleration (ArduSub's sqrt controller does, with its accel_max): their demand is linear
    in the error, up to the speed limit.

    Attributes:
        gain_1_s: the horizontal loop's speed demand per metre of error [1/s] (ArduSub's
            PSC_POSXY_P), finite and > 0.
        max_speed_m_s: the largest horizontal speed it demands [m/s] (ArduSub's
            ``_vel_max_xy_cms``), finite and > 0.
        depth_gain_1_s: the depth loop's speed demand per metre of error [1/s] (ArduSub's
            PSC_POSZ_P): for a PD force law ``kp·e − kd·v = kd·((kp/kd)·e − v)``, kp/kd; ≥ 0,
            ∞ allowed (0: no vertical stopping distance, as ArduSub's for kP ≤ 0; ∞: a law
            without damping, which brakes at once).

    Raises:
        ValueError: a gain or the speed out of its range (local misuse).
    """

    gain_1_s: float
    max_speed_m_s: float
    depth_gain_1_s: float

    def __post_init__(self) -> None:
        for name in ("gain_1_s", "max_speed_m_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"PositionLoop.{name} must be finite and > 0, got {value!r}")
        if not self.depth_gain_1_s >= 0.0:
            raise ValueError(f"PositionLoop.depth_gain_1_s must be >= 0, got {self.depth_gain_1_s}")

    @property
    def leash_m(self) -> float:
        """The horizontal error from which the loop demands its top speed [m]:
        ``max_speed_m_s / gain_1_s``."""
        return self.max_speed_m_s / self.gain_1_s


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
        guided_loop: the vehicle's GUIDED loops (:class:`PositionLoop`); None when unknown (a
            gateway): GUIDED then holds the reported position on entry and leashes no moving
            target.
    """

    battery_voltage_v: float = 14.8
    param_overrides: dict[str, float] = field(default_factory=dict)
    origin: Origin = Origin.REMOTE
    params_per_update: int = 20
    servos: ServoOutputs = field(default_factory=ServoOutputs)
    guided_loop: PositionLoop | None = None

    @property
    def guided_leash_m(self) -> float:
        """How far a GUIDED target moving at a velocity may run ahead of the reported position,
        horizontally [m]: the loop's :attr:`PositionLoop.leash_m`, from which it already asks
        for its top speed (∞ without a loop; :mod:`~testbed.mavlink.guided`)."""
        loop = self.guided_loop
        return math.inf if loop is None else loop.leash_m
