"""The horizontal position loop's velocity demand, one law for the vehicle and for what its
MAVLink endpoint reports of it.

A proportional pull toward the target, capped in speed: ``v = kp · e``, scaled down to
``max_speed`` when longer, in the frame of the error (world NED, north and east [m] → [m/s]).
:class:`~testbed.vehicle.guidance.PositionController` flies it;
:mod:`testbed.mavlink.high_latency` reports its magnitude as HIGH_LATENCY2's ``airspeed_sp``.
"""

from __future__ import annotations

import math

__all__ = ["velocity_demand_ne"]


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
