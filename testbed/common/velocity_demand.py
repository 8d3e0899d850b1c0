"""The horizontal position loop's velocity demand, and its inverse, the stopping point: one law
for the vehicle and for what its MAVLink endpoint reports of it.

A proportional pull toward the target, capped in speed: ``v = kp · e``, scaled down to
``max_speed`` when longer, in the frame of the error (world NED, north and east [m] → [m/s]).
:class:`~testbed.vehicle.guidance.PositionController` flies it;
:mod:`testbed.mavlink.high_latency` reports its magnitude as HIGH_LATENCY2's ``airspeed_sp``.

Its stopping distance is the error at which the demand equals the present speed, ArduPilot's
``stopping_distance`` (AP_Math ``control.cpp``, ``inv_sqrt_controller``) for a demand without
acceleration shaping (``accel_max → ∞``: the linear part for every speed): ``min(|v|, max_speed)
/ kp``, so a target there asks for the speed the vehicle has and the switch does not brake it.
The stopping point lies that far ahead along the velocity. GUIDED's target on entry
(:mod:`testbed.mavlink.guided_entry`) and the vehicle's hold when GUIDED has no goal
(:func:`testbed.vehicle.systems.control_position`) are that point.
"""

from __future__ import annotations

import math

__all__ = ["stopping_distance_m", "stopping_point_ne", "velocity_demand_ne"]


def velocity_demand_ne(
    error_ne_m: tuple[float, float], kp_1_s: float, max_speed_m_s: float
) -> tuple[float, float]:
    """``kp_1_s · error_ne_m`` [m/s], scaled to ``max_speed_m_s`` [m/s] when faster.

    Args:
        error_ne_m: target minus position, north and east [m].
        kp_1_s: the loop's gain [1/s].
        max_speed_m_s: the demand's largest speed [m/s].
    """
    vdn, vde = kp_1_s * error_ne_m[0], kp_1_s * error_ne_m[1]
    speed = math.hypot(vdn, vde)
    if speed > max_speed_m_s:
        vdn, vde = vdn * max_speed_m_s / speed, vde * max_speed_m_s / speed
    return vdn, vde


def stopping_distance_m(speed_m_s: float, kp_1_s: float) -> float:
    """The error at which a linear demand ``kp_1_s × error`` equals ``speed_m_s`` [m] (signed
    as the speed); 0 for a gain that is 0 (ArduPilot: no distance for kP ≤ 0) or ∞.

    Args:
        speed_m_s: the speed along the axis [m/s].
        kp_1_s: the loop's gain [1/s].
    """
    return speed_m_s / kp_1_s if 0.0 < kp_1_s < math.inf else 0.0


def stopping_point_ne(
    position_ne_m: tuple[float, float],
    velocity_ne_m_s: tuple[float, float],
    kp_1_s: float,
    max_speed_m_s: float,
) -> tuple[float, float]:
    """The horizontal stopping point (module docstring): the position plus, along the
    velocity, ``stopping_distance_m(min(|v|, max_speed_m_s), kp_1_s)``.

    Args:
        position_ne_m: the position estimate, north and east [m].
        velocity_ne_m_s: the velocity estimate, north and east [m/s].
        kp_1_s: the loop's gain [1/s].
        max_speed_m_s: the loop's speed limit [m/s].

    Returns:
        The point, north and east [m].
    """
    north, east = position_ne_m
    vn, ve = velocity_ne_m_s
    speed = math.hypot(vn, ve)
    if speed > 0.0:
        along = stopping_distance_m(min(speed, max_speed_m_s), kp_1_s)
        north, east = north + vn * along / speed, east + ve * along / speed
    return (north, east)
