"""What a mission tree reads and writes: its configuration, requests, setpoints and context.

Plain dataclasses, no py_trees and no ECS: :class:`MissionContext` is the mutable exchange
between the caller (the ECS system of :mod:`testbed.vehicle.autonomy`) and the tree of
:mod:`testbed.vehicle.behaviours` (whose docstring tells how each field is consumed);
:class:`GoalRequest` is a GoTo the tree plans one leg for; :class:`PoseSetpoint` is what it
asks the vehicle (or the end effector) to fly. Frames: world NED [m], yaw [rad] clockwise from
north; times are simulation time [s].
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from testbed.common.geometry import Vec3
from testbed.config import check_range

__all__ = ["GoalRequest", "MissionConfig", "MissionContext", "PoseSetpoint"]

_ZERO: Vec3 = (0.0, 0.0, 0.0)


@dataclass(frozen=True, slots=True)
class MissionConfig:
    """Timing and tolerances of the mission tree (defaults: Angler's where it has them).

    Attributes:
        tick_rate_hz: how often the caller should tick the tree [Hz] (Angler 20), in (0, 1000].
        goal_tolerance_m: position error that counts as at the goal [m] (Angler 0.2), > 0.
        yaw_tolerance_rad: heading error that counts as at the goal [rad] (Angler's 0.1 on the
            quaternion vector part is 2·asin(0.1) ≈ 0.2 rad), > 0.
        settle_time_s: the pose must stay within tolerance this long [s], ≥ 0.
        goal_timeout_s: time past the last point to get within tolerance [s] (Angler 10), > 0;
            past it execution fails and the last pose is held.
        setup_timeout_s: time to wait for the vehicle to arm [s] (Angler 15), > 0.
        goto_speed_m_s: cruise speed of a GoTo leg [m/s], > 0.
        goto_yaw_rate_rad_s: turn rate that times a GoTo leg's heading change [rad/s], > 0.
    """

    tick_rate_hz: float = 20.0
    goal_tolerance_m: float = 0.2
    yaw_tolerance_rad: float = 0.2
    settle_time_s: float = 1.0
    goal_timeout_s: float = 10.0
    setup_timeout_s: float = 15.0
    goto_speed_m_s: float = 0.2
    goto_yaw_rate_rad_s: float = 0.3

    def __post_init__(self) -> None:
        check_range(self.tick_rate_hz, "tick_rate_hz", 0.0, 1000.0, "Hz", low_open=True)
        check_range(self.goal_tolerance_m, "goal_tolerance_m", 0.0, math.inf, "m", low_open=True)
        check_range(self.yaw_tolerance_rad, "yaw_tolerance_rad", 0.0, math.pi, "rad", low_open=True)
        check_range(self.settle_time_s, "settle_time_s", 0.0, math.inf, "s")
        check_range(self.goal_timeout_s, "goal_timeout_s", 0.0, math.inf, "s", low_open=True)
        check_range(self.setup_timeout_s, "setup_timeout_s", 0.0, math.inf, "s", low_open=True)
        check_range(self.goto_speed_m_s, "goto_speed_m_s", 0.0, 5.0, "m/s", low_open=True)
        check_range(self.goto_yaw_rate_rad_s, "goto_yaw_rate_rad_s", 0.0, 10.0, low_open=True)

    @property
    def tick_period_s(self) -> float:
        """Time between ticks [s] (Angler 0.05)."""
        return 1.0 / self.tick_rate_hz


@dataclass(frozen=True, slots=True)
class GoalRequest:
    """A supervised GoTo order.

    Attributes:
        position_ned: (3,) goal position [m], world NED.
        yaw_rad: goal heading [rad, clockwise from north], or None to keep the current one.
    """

    position_ned: Vec3
    yaw_rad: float | None = None
    end_effector: bool = False


@dataclass(frozen=True, slots=True)
class PoseSetpoint:
    """What the tree asks the pose controller for this tick.

    Attributes:
        position_ned: (3,) desired position [m], world NED.
        yaw_rad: desired heading [rad, clockwise from north].
        velocity_ned: (3,) feed-forward velocity [m/s], world NED.
        end_effector: the position is the end effector's (the yaw stays the vehicle's).
        yaw_rate_rad_s: feed-forward heading rate [rad/s] (the trajectory's).
    """

    position_ned: Vec3
    yaw_rad: float
    velocity_ned: Vec3 = _ZERO
    end_effector: bool = False
    yaw_rate_rad_s: float = 0.0


@dataclass(slots=True)
class MissionContext:
    """The tree's inputs and outputs (module docstring: who writes what, and when).

    Attributes:
        time_s: the clock [s] (simulation time).
        armed: the vehicle reports itself armed.
        disarm_requested: the pilot or the link wants the vehicle disarmed (a level).
        estimate_position_ned: (3,) estimated position [m], world NED.
        estimate_yaw_rad: estimated heading [rad, clockwise from north].
        end_effector_position_ned: (3,) the end effector's estimated position [m], world NED,
            or None (no arm).
        manipulator_armed: the arm reports itself armed.
        start_requested: one-shot: start the loaded mission (consumed by the tick).
        goal: one-shot: a GoTo order (consumed by the tick), or None.
        cancel_requested: one-shot: drop the plan and hold the current pose (consumed).
        request_arm: output: True to ask for arming, False for disarming, None for no change.
        request_manipulator: output: the same for the arm.
        pose_setpoint: output: this tick's setpoint, or None (nothing commanded).
        status: output: one line on what the tree is doing.
        goal_reached: output: the last plan ended within tolerance (cleared by a new plan).
        tick_count: output: ticks so far.
        plan_count: output: plans made (missions started and GoTo legs).
        disarm_count: output: times the disarm fallback was entered.
        reached_count: output: plans that ended within tolerance.
    """

    time_s: float = 0.0
    armed: bool = False
    disarm_requested: bool = False
    estimate_position_ned: Vec3 = _ZERO
    estimate_yaw_rad: float = 0.0
    end_effector_position_ned: Vec3 | None = None
    manipulator_armed: bool = False
    start_requested: bool = False
    goal: GoalRequest | None = None
    cancel_requested: bool = False
    request_arm: bool | None = None
    request_manipulator: bool | None = None
    pose_setpoint: PoseSetpoint | None = None
    status: str = ""
    goal_reached: bool = False
    tick_count: int = 0
    plan_count: int = 0
    disarm_count: int = 0
    reached_count: int = 0
