"""The kinematic pose layer: a target pose → the body twist the ISMC (:mod:`.ismc`) tracks.

A proportional law on the pose error, pure and stateless (:func:`pose_twist`)::

    v_ned  = v_ff + k_position · (p_target − p)          world velocity demand [m/s], NED
    (u v w) = Rᵀ · v_ned, norm-limited to max_speed_m_s   body FRD (R: body → NED)
    ψ̇_d = ψ̇_ff + k_yaw · wrap(ψ_target − ψ)   (0 without a target yaw), |ψ̇_d| ≤ max_yaw_rate_rad_s
    φ̇_d = −k_level · φ,  θ̇_d = −k_level · θ,             |·| ≤ max_level_rate_rad_s
    (p q r) = T(φ, θ)⁻¹ · (φ̇_d, θ̇_d, ψ̇_d)                 Z-Y-X Euler rates → body rates

with (φ, θ, ψ) the Z-Y-X Euler angles of the attitude and wrap into (−π, π]. While nothing
saturates, each position axis closes as exp(−k_position·t) in the world (a feed-forward
velocity is tracked with no lag) and yaw, roll and pitch as exp(−k·t); so does the heading
error of a turning target, whose rate ψ̇_ff is fed forward (without it a target turning at ω
is followed ω/k_yaw behind: 18° at 9°/s and k_yaw 0.5). The norm limit keeps
the direction of the linear demand; T⁻¹ is regular at every attitude (T itself is singular at
θ = ±90°, which the rates never need).

Frames: world NED, body FRD; positions are the body origin CO's (as the plant reports them),
twists ν = (u v w p q r) at CO. This is the stand-in for Angler's set-based TPIK (REFERENCE
§3.8): the arm issue replaces it with TPIK, which produces the same body twist (plus joint
rates) from prioritised tasks. Standard library and :mod:`testbed.common.geometry` only.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from testbed.common.geometry import Quaternion, euler_from_quat, quat_rotate_inverse, wrap_angle
from testbed.config import check_range

__all__ = ["PoseGains", "pose_twist"]

Twist = tuple[float, float, float, float, float, float]


@dataclass(frozen=True, slots=True)
class PoseGains:
    """Gains and limits of the kinematic pose law (module docstring).

    Attributes:
        k_position_1_s: speed demanded per metre of position error [1/s], in (0, 10].
        k_yaw_1_s: yaw rate demanded per radian of heading error [1/s], in (0, 10].
        k_level_1_s: roll and pitch rates demanded per radian, back to level [1/s], in [0, 10]
            (0: no roll or pitch command).
        max_speed_m_s: limit on the norm of the linear twist [m/s], in (0, 3].
        max_yaw_rate_rad_s: limit on |ψ̇_d| [rad/s], in (0, 3].
        max_level_rate_rad_s: limit on |φ̇_d| and |θ̇_d| [rad/s], in (0, 3].
    """

    k_position_1_s: float = 0.5
    k_yaw_1_s: float = 0.5
    k_level_1_s: float = 1.0
    max_speed_m_s: float = 0.5
    max_yaw_rate_rad_s: float = 0.5
    max_level_rate_rad_s: float = 0.5

    def __post_init__(self) -> None:
        check_range(self.k_position_1_s, "k_position_1_s", 0.0, 10.0, "1/s", low_open=True)
        check_range(self.k_yaw_1_s, "k_yaw_1_s", 0.0, 10.0, "1/s", low_open=True)
        check_range(self.k_level_1_s, "k_level_1_s", 0.0, 10.0, "1/s")
        check_range(self.max_speed_m_s, "max_speed_m_s", 0.0, 3.0, "m/s", low_open=True)
        for key in ("max_yaw_rate_rad_s", "max_level_rate_rad_s"):
            check_range(getattr(self, key), key, 0.0, 3.0, "rad/s", low_open=True)


def _clamp(value: float, limit: float) -> float:
    return limit if value > limit else -limit if value < -limit else value


def pose_twist(
    target_position_ned: Sequence[float],
    target_yaw_rad: float | None,
    position_ned: Sequence[float],
    quaternion_wxyz: Quaternion,
    gains: PoseGains,
    feedforward_velocity_ned: Sequence[float] | None = None,
    feedforward_yaw_rate_rad_s: float = 0.0,
) -> Twist:
    """The body twist that moves the vehicle towards a target pose (module docstring).

    Args:
        target_position_ned: (3,) target position of CO [m], NED.
        target_yaw_rad: target heading [rad, clockwise from north], or None to hold no heading
            (ψ̇_d = 0).
        position_ned: (3,) current position of CO [m], NED (the position estimate).
        quaternion_wxyz: (4,) current attitude, body FRD → NED, unit (the attitude estimate).
        gains: the law's gains and limits.
        feedforward_velocity_ned: (3,) the trajectory's velocity at this instant [m/s], NED;
            None for a fixed target.
        feedforward_yaw_rate_rad_s: the trajectory's heading rate at this instant [rad/s]
            (ψ̇_ff; 0 for a fixed heading; ignored without a target yaw).

    Returns:
        (6,) body twist (u v w p q r) [m/s, rad/s], FRD: the ISMC's ``v_cmd``.
    """
    g = gains
    k = g.k_position_1_s
    vn = k * (target_position_ned[0] - position_ned[0])
    ve = k * (target_position_ned[1] - position_ned[1])
    vd = k * (target_position_ned[2] - position_ned[2])
    if feedforward_velocity_ned is not None:
        vn += feedforward_velocity_ned[0]
        ve += feedforward_velocity_ned[1]
        vd += feedforward_velocity_ned[2]
    u, v, w = quat_rotate_inverse(quaternion_wxyz, (vn, ve, vd))
    speed = math.sqrt(u * u + v * v + w * w)
    if speed > g.max_speed_m_s:
        scale = g.max_speed_m_s / speed
        u, v, w = u * scale, v * scale, w * scale

    roll, pitch, yaw = euler_from_quat(quaternion_wxyz)
    if target_yaw_rad is None:
        yaw_rate = 0.0
    else:
        demand = g.k_yaw_1_s * wrap_angle(target_yaw_rad - yaw)
        if feedforward_yaw_rate_rad_s:  # (adding 0.0 would turn a −0.0 demand into +0.0)
            demand += feedforward_yaw_rate_rad_s
        yaw_rate = _clamp(demand, g.max_yaw_rate_rad_s)
    roll_rate = _clamp(-g.k_level_1_s * roll, g.max_level_rate_rad_s)
    pitch_rate = _clamp(-g.k_level_1_s * pitch, g.max_level_rate_rad_s)
    # body rates from Z-Y-X Euler rates: ω = T(φ, θ)⁻¹·Θ̇ (Fossen 2011, §2.2.1)
    sr, cr = math.sin(roll), math.cos(roll)
    sp, cp = math.sin(pitch), math.cos(pitch)
    p = roll_rate - sp * yaw_rate
    q = cr * pitch_rate + sr * cp * yaw_rate
    r = -sr * pitch_rate + cr * cp * yaw_rate
    return (u, v, w, p, q, r)
