"""Where GUIDED holds when it is entered: ArduSub 4.5's stopping point, with the vehicle's own
loops.

ArduSub 4.5: ``Sub::set_mode`` → ``ModeGuided::init`` → ``guided_pos_control_start``:
``wp_nav.wp_and_spline_init()``, then ``wp_nav.get_wp_stopping_point(stopping_point)`` and
``wp_nav.set_wp_destination(stopping_point)``. ``AC_WPNav::get_wp_stopping_point`` is
``AC_PosControl::get_stopping_point_xy_cm`` and ``get_stopping_point_z_cm``, from the position
estimate and the velocity estimate:

- horizontally, the position plus, along the horizontal velocity ``v``,
  ``stopping_distance(min(|v|, vel_max_xy), kP_xy, accel_max_xy)``;
- vertically, the altitude plus ``stopping_distance(v_up, kP_z, accel_max_z)`` constrained to
  [−POSCONTROL_STOPPING_DIST_DOWN_MAX, POSCONTROL_STOPPING_DIST_UP_MAX] = [−2 m, +3 m] (no
  distance when kP_z ≤ 0);

``stopping_distance`` (AP_Math ``control.cpp``) is ``inv_sqrt_controller``: the error at which
the position controller's speed demand equals the present speed, ``v / kP`` while
``v < accel_max / kP`` (the demand's linear part), ``accel_max / (2 kP²) + v² / (2 accel_max)``
beyond (its square-root part).

Here the vehicle's own loops stand for ArduSub's (:class:`~testbed.mavlink.options.PositionLoop`,
:attr:`~testbed.mavlink.options.EndpointOptions.guided_loop`): the horizontal position loop
(``testbed.vehicle.guidance``: demand 0.8 /s × error, ≤ 0.5 m/s) and the depth hold (a PD
force law, kp/kd = 100 / 40 = 2.5 /s as a speed demand per metre; a depth law of the user's
own is not described by them: the packaged hold's gains stand in). Neither shapes acceleration
(their demand is linear in the error: accel_max → ∞), so the stopping distance is the linear
part's for every speed (:mod:`testbed.common.velocity_demand`, which the vehicle's own hold
without a goal uses too): horizontally ``min(|v|, max_speed) / gain`` (0.3 m/s → 0.375 m, at most
0.5 / 0.8 = 0.625 m), vertically ``v_down / depth_gain`` (0.4 s of the vertical speed) within
[−3 m, +2 m] and no shallower than the surface. At that point the loops' demand is the speed
the vehicle has, so they do not brake it at the switch: it coasts on and is brought back to
the point. The velocity is the endpoint's estimate (the reported positions, differenced and
low-passed: LOCAL_POSITION_NED's), ArduSub's the EKF's. Without a loop (a gateway, which knows
the vehicle only by its reported state) the stopping point is the reported position.

The heading is the auto-yaw state's (:mod:`~testbed.mavlink.guided_yaw`), untouched.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from testbed.common.velocity_demand import stopping_distance_m, stopping_point_ne
from testbed.mavlink import guided_yaw

if TYPE_CHECKING:
    from testbed.mavlink.endpoint import VehicleEndpoint
    from testbed.mavlink.options import PositionLoop

__all__ = [
    "STOPPING_DIST_DOWN_MAX_M",
    "STOPPING_DIST_UP_MAX_M",
    "hold_where_entered",
    "stopping_point",
]

STOPPING_DIST_UP_MAX_M = 3.0
"""ArduPilot's POSCONTROL_STOPPING_DIST_UP_MAX (300 cm): the vertical stopping distance while
climbing is at most this [m]."""
STOPPING_DIST_DOWN_MAX_M = 2.0
"""ArduPilot's POSCONTROL_STOPPING_DIST_DOWN_MAX (200 cm): the vertical stopping distance while
descending is at most this [m]."""


def stopping_point(
    position_ned_m: tuple[float, float, float],
    velocity_ned_m_s: tuple[float, float, float],
    loop: PositionLoop | None,
) -> tuple[float, float, float]:
    """ArduSub's stopping point (module docstring) with the vehicle's loops.

    Args:
        position_ned_m: (3,) the position estimate [m], NED (z the depth).
        velocity_ned_m_s: (3,) the velocity estimate [m/s], NED.
        loop: the vehicle's loops; None: the position itself.

    Returns:
        (3,) the point [m], NED, the depth ≥ 0.
    """
    north, east, depth = position_ned_m
    if loop is None:
        return (north, east, depth)
    vn, ve, vd = velocity_ned_m_s
    north, east = stopping_point_ne((north, east), (vn, ve), loop.gain_1_s, loop.max_speed_m_s)
    down = stopping_distance_m(vd, loop.depth_gain_1_s)
    down = max(-STOPPING_DIST_UP_MAX_M, min(STOPPING_DIST_DOWN_MAX_M, down))
    return (north, east, max(0.0, depth + down))


def hold_where_entered(endpoint: VehicleEndpoint) -> None:
    """GUIDED entered from another mode: its target is the stopping point of the reported
    position and velocity (module docstring), not a target from an earlier GUIDED; the heading
    the auto-yaw state's."""
    snapshot = endpoint.snapshot_now()
    hold = stopping_point(
        snapshot.position_ned_m, snapshot.velocity_ned_m_s, endpoint.options.guided_loop
    )
    guided_yaw.start_position_control(endpoint, hold)
    endpoint.request_position(hold)
