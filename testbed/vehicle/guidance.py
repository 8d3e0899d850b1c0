"""GUIDED mode's horizontal position loop: go to a point with the position fix.

A cascaded PD law in the vehicle's **level frame** (yaw-only: x ahead along the heading, y to
the right, horizontal), fed only by the position fix and the IMU's heading, never the truth:

- speed demand ``v_d = k_p · e``, its horizontal norm limited to ``max_speed_m_s`` (so the
  approach runs at a bounded speed and slows down exponentially, time constant ``1/k_p``, over
  the last ``max_speed_m_s / k_p`` metres), with ``e`` the north–east error to the target;
- velocity ``v`` from the fix: the difference of successive fixes, low-passed (time constant
  ``velocity_tau_s``), updated only when a new fix arrives;
- force ``F = k_v · (v_d − v)`` per level axis, clamped to ``max_force_fraction`` of the
  allocator's surge and sway maxima.

Together: ``F = k_v k_p e − k_v v`` while unsaturated, a PD law on the position error with
``k_v`` the damping. No integral term: in still water the steady-state error is the fix's
noise; a water current ``c`` leaves an offset ``drag(c) / (k_v k_p)``. Depth and heading are
the depth and attitude holds' (the system in :mod:`testbed.vehicle.systems` sets their targets
from the setpoint). Pure: no ECS, no randomness.

GUIDED with no goal holds a point of its own (:attr:`PositionController.hold_ne_m`, chosen by
:meth:`PositionController.latch_hold`): ArduSub's stopping point for this loop, the fix plus
``min(|v|, max_speed_m_s) / k_p`` along the velocity estimate
(:func:`~testbed.common.velocity_demand.stopping_point_ne`), where the demand equals the speed
the vehicle has.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from testbed.common.velocity_demand import stopping_point_ne, velocity_demand_ne
from testbed.config import check_range

__all__ = ["FORMED_START_WEIGHT", "PositionController", "PositionGains"]

FORMED_START_WEIGHT = 0.05
"""The velocity estimate counts as formed once its zero start weighs at most this in it."""


@dataclass(frozen=True, slots=True)
class PositionGains:
    """Gains and limits of the horizontal position loop.

    Attributes:
        kp_1_s: speed demanded per metre of error [1/s], in (0, 10].
        max_speed_m_s: approach speed limit [m/s], in (0, 3].
        kv_n_s_m: force per m/s of speed error [N·s/m], in (0, 1000].
        max_force_fraction: force clamp per level axis, as a fraction of the allocator's
            surge / sway maximum, in (0, 1].
        velocity_tau_s: low-pass time constant of the fix-differenced velocity [s], in [0, 5].
        fix_timeout_s: a fix older than this [s] counts as lost (the loop lets go), in (0, 60].
    """

    kp_1_s: float = 0.8
    max_speed_m_s: float = 0.5
    kv_n_s_m: float = 30.0
    max_force_fraction: float = 0.3
    velocity_tau_s: float = 0.15
    fix_timeout_s: float = 0.5

    def __post_init__(self) -> None:
        check_range(self.kp_1_s, "kp_1_s", 0.0, 10.0, "1/s", low_open=True)
        check_range(self.max_speed_m_s, "max_speed_m_s", 0.0, 3.0, "m/s", low_open=True)
        check_range(self.kv_n_s_m, "kv_n_s_m", 0.0, 1000.0, "N·s/m", low_open=True)
        check_range(self.max_force_fraction, "max_force_fraction", 0.0, 1.0, low_open=True)
        check_range(self.velocity_tau_s, "velocity_tau_s", 0.0, 5.0, "s")
        check_range(self.fix_timeout_s, "fix_timeout_s", 0.0, 60.0, "s", low_open=True)


@dataclass(slots=True)
class PositionController:
    """The loop's state: the last fix and the filtered north–east velocity (module docstring).

    Attributes:
        gains: the loop's gains.
        velocity_ne_m_s: (2,) filtered velocity estimate [m/s], north and east.
        hold_ne_m: the point GUIDED holds with no goal, north and east [m] (world NED); None:
            none chosen.
        released: GUIDED's position is let go for an attitude target (ArduSub's angle
            control), until the next goal or GUIDED is left: no hold point is chosen.
    """

    gains: PositionGains = field(default_factory=PositionGains)
    velocity_ne_m_s: tuple[float, float] = (0.0, 0.0)
    hold_ne_m: tuple[float, float] | None = None
    released: bool = False
    _last_fix: tuple[float, float, float] | None = None
    _start_weight: float = 1.0

    def reset(self) -> None:
        """Forget the last fix, the velocity estimate and the hold point."""
        self._last_fix = None
        self._start_weight = 1.0
        self.velocity_ne_m_s = (0.0, 0.0)
        self.hold_ne_m = None

    def latch_hold(self, fix_time_s: float, fix_ne_m: tuple[float, float]) -> bool:
        """Take in the fix and, once the velocity estimate is formed, choose the hold point: the
        stopping point of the fix and that estimate with the loop's gain and speed limit
        (module docstring). A point already chosen stays.

        The estimate starts at zero when the loop starts (GUIDED entered, a fix regained) and
        is formed once that start weighs at most :data:`FORMED_START_WEIGHT` in it (the
        product of the low-pass's ``1 − α`` since: 11 differences at 20 Hz and τ = 0.15 s, 0.55 s;
        the second fix with τ = 0); until then the hold waits, its intent zero.

        Args:
            fix_time_s: the latest fix's time [s].
            fix_ne_m: the latest fix's north, east [m].

        Returns:
            Whether :attr:`hold_ne_m` is set.
        """
        if self.hold_ne_m is None:
            self._observe(fix_time_s, fix_ne_m[0], fix_ne_m[1])
            if self._start_weight <= FORMED_START_WEIGHT:
                g = self.gains
                self.hold_ne_m = stopping_point_ne(
                    fix_ne_m, self.velocity_ne_m_s, g.kp_1_s, g.max_speed_m_s
                )
        return self.hold_ne_m is not None

    def _observe(self, time_s: float, north_m: float, east_m: float) -> None:
        last = self._last_fix
        if last is not None and time_s <= last[0]:
            return  # the same fix again
        self._last_fix = (time_s, north_m, east_m)
        if last is None:
            return
        dt = time_s - last[0]
        raw_n, raw_e = (north_m - last[1]) / dt, (east_m - last[2]) / dt
        tau = self.gains.velocity_tau_s
        alpha = dt / (tau + dt)
        self._start_weight *= 1.0 - alpha
        vn, ve = self.velocity_ne_m_s
        self.velocity_ne_m_s = (vn + alpha * (raw_n - vn), ve + alpha * (raw_e - ve))

    def update(
        self,
        target_ne_m: tuple[float, float],
        fix_time_s: float,
        fix_ne_m: tuple[float, float],
        yaw_rad: float,
        max_force_n: tuple[float, float],
    ) -> tuple[float, float]:
        """One step of the loop.

        Args:
            target_ne_m: target north, east [m] (world NED).
            fix_time_s: the latest fix's time [s] (a repeated time is the same fix).
            fix_ne_m: the latest fix's north, east [m].
            yaw_rad: the IMU's heading [rad, clockwise from north].
            max_force_n: the allocator's surge and sway maxima [N].

        Returns:
            (surge, sway) force [N] in the level frame (x ahead, y right, horizontal).
        """
        g = self.gains
        self._observe(fix_time_s, fix_ne_m[0], fix_ne_m[1])
        error = (target_ne_m[0] - fix_ne_m[0], target_ne_m[1] - fix_ne_m[1])
        vdn, vde = velocity_demand_ne(error, g.kp_1_s, g.max_speed_m_s)
        vn, ve = self.velocity_ne_m_s
        fn, fe = g.kv_n_s_m * (vdn - vn), g.kv_n_s_m * (vde - ve)
        c, s = math.cos(yaw_rad), math.sin(yaw_rad)
        fx, fy = c * fn + s * fe, -s * fn + c * fe
        limit_x = g.max_force_fraction * max_force_n[0]
        limit_y = g.max_force_fraction * max_force_n[1]
        return (max(-limit_x, min(limit_x, fx)), max(-limit_y, min(limit_y, fy)))
