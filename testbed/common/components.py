"""The components both nodes replicate: the contract between operator and vehicle.

Components are frozen slotted dataclasses of plain values (``==`` is meaningful, so
``world.set`` records a change only when a value really changed). Each type registered by
:func:`register_components` replicates under a stable id and has one owner: the **operator**
owns intents (sticks with their sample time and sequence number, arm and mode requests,
setpoints), the **vehicle** owns state (sensor readings, odometry, armed, mode, control targets,
failsafe, thruster outputs, command status). A side never writes what the other owns.

Replicated fields cannot be ``None`` (the registry forbids unions), so "no setpoint yet" is
expressed by the component's absence. :class:`ThrusterTest` is an operator intent that does not
replicate (not in :data:`REPLICATED`): only a pilot on the vehicle's own node writes it (the
MAVLink endpoint of a direct run; no link carries a motor test). No logic here; standard library
and the ECS registry only.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

from testbed.common.geometry import Quaternion, Vec3
from testbed.ecs import ComponentRegistry, Side

__all__ = [
    "REPLICATED",
    "ActiveMode",
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
    "GoalCancel",
    "ImuReading",
    "MissionStatus",
    "ModeRequest",
    "MovementCommand",
    "Odometry",
    "PositionReading",
    "PositionSetpoint",
    "ThrusterOutput",
    "ThrusterTest",
    "register_components",
]


class ControlMode(enum.IntEnum):
    """Vehicle control modes (ArduSub numbers where one exists: MANUAL 19, STABILIZE 0,
    ALT_HOLD 2, GUIDED 4)."""

    MANUAL = 19
    """Sticks map to forces and torques; no closed loop."""
    STABILIZE = 0
    """Attitude hold; sticks trim the attitude target; translation as in manual."""
    DEPTH_HOLD = 2
    """Attitude and depth hold; heave stick trims the depth target; level-frame translation."""
    GUIDED = 4
    """Go to the :class:`PositionSetpoint` (needs a position fix): horizontal position loop,
    depth and heading held; sticks ignored. Without a fix or a setpoint it holds like
    DEPTH_HOLD."""


class FailsafeLevel(enum.IntEnum):
    """Vehicle-side command-staleness failsafe state."""

    NOMINAL = 0
    HOLD = 1
    """Commands stale beyond the first timeout: hold depth and heading, sticks ignored."""
    SURFACE = 2
    """Stale beyond the second timeout: rise to the surface, then disarm (latched)."""


# ------------------------------------------------------------------ operator-owned intents


@dataclass(frozen=True, slots=True)
class MovementCommand:
    """The pilot's sticks: (6,) in [−1, 1] — surge, sway, heave, roll, pitch, yaw.

    Attributes:
        seq: sequence number, increasing; the vehicle ignores anything not newer.
        sampled_s: operator time the sticks were sampled [s] (for command-latency metrics).
        sticks: (6,) stick positions.
    """

    seq: int
    sampled_s: float
    sticks: tuple[float, float, float, float, float, float]


@dataclass(frozen=True, slots=True)
class ArmRequest:
    """Arm (True) or disarm (False); a new ``seq`` makes a repeated request count again."""

    armed: bool
    seq: int


@dataclass(frozen=True, slots=True)
class ModeRequest:
    """Requested control mode and precision (finer stick scaling)."""

    mode: ControlMode
    precision: bool = False


@dataclass(frozen=True, slots=True)
class DepthSetpoint:
    """Depth target [m, positive down]; applied when it changes."""

    depth_m: float


@dataclass(frozen=True, slots=True)
class PositionSetpoint:
    """Go-to target for GUIDED mode, in the position fix's world NED frame.

    Attributes:
        position_ned_m: (3,) target of the body origin [m]: north, east, down (z = the depth
            target).
        yaw_rad: heading on the way and on arrival [rad, clockwise from north], used when
            ``use_yaw``; otherwise the heading held when the setpoint arrived is kept.
        use_yaw: whether ``yaw_rad`` applies.
    """

    position_ned_m: Vec3
    yaw_rad: float = 0.0
    use_yaw: bool = False


@dataclass(frozen=True, slots=True)
class EndEffectorSetpoint:
    """Go-to target of the manipulator arm's tool point (the end effector: the point the
    gripper closes on), in the position fix's world NED frame — the same frame as
    :class:`PositionSetpoint`, but for the arm's tool, not the vehicle's body origin.

    Over the teleop codec it travels as an ``EndEffectorGoTo`` order (1 cm, 0.01° tool yaw); a
    later :class:`GoalCancel` cancels it, as it does a position setpoint.

    Attributes:
        position_ned_m: (3,) target of the tool point [m]: north, east, down.
        yaw_rad: the tool's yaw about the world down axis [rad, clockwise from north], used
            when ``use_yaw``; otherwise the tool keeps its yaw. The vehicle's TPIK (no tool
            orientation task by default) aims the vehicle's heading there: its arm reaches
            straight ahead, so the tool points along the vehicle.
        use_yaw: whether ``yaw_rad`` applies.
    """

    position_ned_m: Vec3
    yaw_rad: float = 0.0
    use_yaw: bool = False


@dataclass(frozen=True, slots=True)
class ThrusterTest:
    """Thrusters driven at given pulses instead of the allocation's: ArduSub's motor test.

    Acts only while armed; local to the vehicle's node (module docstring).

    Attributes:
        pwm_us: (n,) pulse per thruster, in the layout's (allocation) order [µs], as the ESC
            gets it (a CCW propeller's mirror applies, 1500 stops); empty: no test, the
            allocation runs.
    """

    pwm_us: tuple[float, ...] = ()


@dataclass(frozen=True, slots=True)
class AttitudeSetpoint:
    """Attitude target (body → NED, w x y z); applied when it changes."""

    quaternion_wxyz: tuple[float, float, float, float]


# ------------------------------------------------------------------- vehicle-owned state


@dataclass(frozen=True, slots=True)
class Armed:
    """Whether the thrusters may run."""

    armed: bool


@dataclass(frozen=True, slots=True)
class ActiveMode:
    """The mode the vehicle is in."""

    mode: ControlMode
    precision: bool = False


@dataclass(frozen=True, slots=True)
class GoalCancel:
    """The operator cancels the vehicle's current goal (supervised control): it holds where it
    is. A new ``seq`` is a new cancel; over the teleop codec it is the order header's
    "cancel last order" bit.

    Attributes:
        seq: cancel sequence number (increasing).
    """

    seq: int


@dataclass(frozen=True, slots=True)
class MissionStatus:
    """What the vehicle's mission logic reports (vehicles with autonomy only).

    Attributes:
        ready: no goal in progress (the last one was reached, given up or cancelled, or
            none was given): the protocol's "ready" flag.
        cancelled: the last goal was cancelled by the operator: the protocol's "last order
            cancelled" flag (cleared by the next goal).
        goals: goals received (mission starts and GoTo orders).
        reached: goals reached within tolerance.
    """

    ready: bool
    cancelled: bool = False
    goals: int = 0
    reached: int = 0


@dataclass(frozen=True, slots=True)
class ControlTargets:
    """The targets the closed loops are holding (set from setpoints, trimmed by sticks)."""

    depth_m: float
    quaternion_wxyz: tuple[float, float, float, float]


@dataclass(frozen=True, slots=True)
class FailsafeStatus:
    """Failsafe state and the vehicle time it was entered [s]."""

    level: FailsafeLevel
    since_s: float


@dataclass(frozen=True, slots=True)
class CommandStatus:
    """The last accepted movement command: its sequence number, receive time and age at receipt.

    Attributes:
        seq: sequence number of the last accepted command.
        received_s: vehicle time it arrived [s].
        latency_s: ``received_s − sampled_s`` (sampling to arrival; same clock in simulation).
    """

    seq: int
    received_s: float
    latency_s: float


@dataclass(frozen=True, slots=True)
class ThrusterOutput:
    """Per-thruster commands of the last allocation.

    Attributes:
        forces_n: (n,) commanded forces [N].
        pwm_us: (n,) PWM pulse widths [µs].
        currents_a: (n,) predicted currents [A].
        scale: current-limit scale α applied (1 = none).
    """

    forces_n: tuple[float, ...]
    pwm_us: tuple[float, ...]
    currents_a: tuple[float, ...]
    scale: float


@dataclass(frozen=True, slots=True)
class Odometry:
    """The vehicle's own estimate of where it is, as it reports it to the operator.

    Attributes:
        sampled_s: vehicle time of the estimate [s] (on the operator's side over the teleop
            codec, whose wire carries no time: the reply's arrival time).
        position_ned_m: (3,) body-origin position [m], world NED (x, y from the position fix
            when fitted, else 0; z from the depth sensor).
        quaternion_wxyz: attitude from the IMU, body → NED.
    """

    sampled_s: float
    position_ned_m: Vec3
    quaternion_wxyz: Quaternion


# ------------------------------------------------------------------------ sensor readings


@dataclass(frozen=True, slots=True)
class ImuReading:
    """One IMU output: attitude (body → NED, w x y z) and body rates (p, q, r) [rad/s], FRD."""

    time_s: float
    quaternion_wxyz: Quaternion
    rates_rad_s: Vec3


@dataclass(frozen=True, slots=True)
class DepthReading:
    """One depth-sensor output: absolute pressure [Pa] and the depth [m, positive down]."""

    time_s: float
    pressure_pa: float
    depth_m: float


@dataclass(frozen=True, slots=True)
class PositionReading:
    """One position fix: NED position of the body origin [m]."""

    time_s: float
    position_ned_m: Vec3


# ------------------------------------------------------------------------- registration

REPLICATED: tuple[tuple[type[object], int, Side], ...] = (
    (MovementCommand, 101, Side.OPERATOR),
    (ArmRequest, 102, Side.OPERATOR),
    (ModeRequest, 103, Side.OPERATOR),
    (DepthSetpoint, 104, Side.OPERATOR),
    (AttitudeSetpoint, 105, Side.OPERATOR),
    (PositionSetpoint, 106, Side.OPERATOR),
    (GoalCancel, 107, Side.OPERATOR),
    (EndEffectorSetpoint, 108, Side.OPERATOR),
    (ImuReading, 151, Side.VEHICLE),
    (DepthReading, 152, Side.VEHICLE),
    (PositionReading, 153, Side.VEHICLE),
    (Armed, 154, Side.VEHICLE),
    (ActiveMode, 155, Side.VEHICLE),
    (ControlTargets, 156, Side.VEHICLE),
    (FailsafeStatus, 157, Side.VEHICLE),
    (CommandStatus, 158, Side.VEHICLE),
    (ThrusterOutput, 159, Side.VEHICLE),
    (Odometry, 160, Side.VEHICLE),
    (MissionStatus, 161, Side.VEHICLE),
)
"""(type, stable id, owner) of every replicated component. Ids never change
meaning: add new ones, do not renumber."""


def register_components(registry: ComponentRegistry) -> None:
    """Register every replicated component type with its id and owner."""
    for cls, type_id, owner in REPLICATED:
        registry.register(cls, type_id, owner)
