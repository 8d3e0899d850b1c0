"""The vehicle's local ECS components, plus the shared replicated ones re-exported.

The replicated components (operator intents, vehicle state) are the contract of both nodes and
live in :mod:`testbed.common.components`; they are re-exported here for the vehicle's modules.
The types defined here are local to the vehicle node and never replicate: the controllers'
force intents, the achieved wrench and the tag of the vehicle's own entity.
"""

from __future__ import annotations

from dataclasses import dataclass

from testbed.common.components import (
    REPLICATED,
    ActiveMode,
    Armed,
    ArmRequest,
    AttitudeSetpoint,
    CommandStatus,
    ControlMode,
    ControlTargets,
    DepthReading,
    DepthSetpoint,
    EndEffectorSetpoint,
    FailsafeLevel,
    FailsafeStatus,
    GoalCancel,
    ImuReading,
    MissionStatus,
    ModeRequest,
    MovementCommand,
    Odometry,
    PositionReading,
    PositionSetpoint,
    ThrusterOutput,
    ThrusterTest,
    register_components,
)

__all__ = [
    "REPLICATED",
    "ActiveMode",
    "AppliedWrench",
    "ArmRequest",
    "Armed",
    "AttitudeSetpoint",
    "CommandStatus",
    "ControlMode",
    "ControlTargets",
    "DepthReading",
    "DepthSetpoint",
    "EndEffectorSetpoint",
    "FailsafeLevel",
    "FailsafeStatus",
    "ForceIntent",
    "GoalCancel",
    "ImuReading",
    "MissionStatus",
    "ModeRequest",
    "MovementCommand",
    "Odometry",
    "PoseTarget",
    "PositionReading",
    "PositionSetpoint",
    "ThrusterOutput",
    "ThrusterTest",
    "VehicleTag",
    "register_components",
]


@dataclass(frozen=True, slots=True)
class VehicleTag:
    """Marks the vehicle's own entity (the one carrying its state)."""


@dataclass(frozen=True, slots=True)
class ForceIntent:
    """One controller's contribution to the body wrench (X, Y, Z, K, M, N) [N, N·m], FRD.

    Each source (pilot, depth, attitude, …) owns one entity with this component; the allocation
    system sums them all (the ECS paper's "force order control intents").
    """

    source: str
    wrench: tuple[float, float, float, float, float, float]


@dataclass(frozen=True, slots=True)
class AppliedWrench:
    """The wrench the thrusters actually produced at the last frame: ``T @ actual forces``.

    Attributes:
        requested: (6,) the summed intents [N, N·m], body FRD.
        achieved: (6,) from the actual (lagged, failed, saturated) thruster forces.
    """

    requested: tuple[float, float, float, float, float, float]
    achieved: tuple[float, float, float, float, float, float]


@dataclass(frozen=True, slots=True)
class PoseTarget:
    """The pose the vehicle's autonomy is flying to this instant (its mission tree's output).

    Attributes:
        time_s: vehicle time the tree set it [s].
        position_ned_m: (3,) target of the body origin [m], world NED.
        yaw_rad: target heading [rad, clockwise from north].
        velocity_ned_m_s: (3,) the trajectory's velocity there [m/s], world NED (feed-forward;
            the position moves on at this velocity until the next tick).
        yaw_rate_rad_s: the trajectory's heading rate there [rad/s] (feed-forward; the heading
            moves on at this rate until the next tick).
    """

    time_s: float
    position_ned_m: tuple[float, float, float]
    yaw_rad: float
    velocity_ned_m_s: tuple[float, float, float] = (0.0, 0.0, 0.0)
    yaw_rate_rad_s: float = 0.0
