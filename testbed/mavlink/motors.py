"""ArduSub's motors: which thruster is which motor, which way ArduSub drives it, its servo output.

ArduSub numbers a frame's thrusters by its mixer, ``AP_Motors6DOF::setup_motors`` (ArduSub 4.5,
``libraries/AP_Motors/AP_Motors6DOF.cpp``): motor n gets a row of factors (roll, pitch, yaw,
throttle, forward, lateral) and its output, a thrust in [−1, 1], goes to SERVO n as
``1500 + 400 · MOT_n_DIRECTION · output`` µs (``calc_thrust_to_pwm`` after
``output_armed_stabilizing``'s ``_motor_reverse`` factor; 1100–1900 µs). :data:`FRAME_FACTORS`
holds the rows of the two BlueROV2 frames, SUB_FRAME_VECTORED (FRAME_CONFIG 1, the BlueROV2)
and SUB_FRAME_VECTORED_6DOF (2, the Heavy), copied as numbers from that function.

A thruster layout that is one of those frames names its thrusters in ArduSub's motor order
(the layout file's ``[ardusub]`` table; the run layer passes it in). :func:`servo_outputs`
checks the order against the factors — every factor of motor n must push the layout's
thruster the same way, up to one sign s (ArduSub's positive output is force along s × the
layout's ``direction``) — and derives the MOT_n_DIRECTION the simulated vehicle behaves as:
its PWM is the T200's for the force, mirrored about 1500 µs for a CCW propeller, so ArduSub's
output reaches the same force with MOT_n_DIRECTION = s for a CW propeller and −s for a CCW one.
SERVO_OUTPUT_RAW then carries motor n's pulse width on servo n. A layout that is no ArduSub
frame reports each thruster on its own ``pwm_channel`` + 1 (FRAME_CONFIG 7, custom).

**MOT_n_DIRECTION acts** as ArduSub's ``_motor_reverse[n]`` does: the mixer's last step
(``output_armed_stabilizing*``: ``_thrust_rpyt_out[i] = constrain(_motor_reverse[i] · (rpy +
linear), −1, 1)``, read every loop, so a PARAM_SET acts at once) scales motor n's output by it.
The simulated pulse is the one the layout's direction gives (``directions``); with the parameter
at d instead, ArduSub's output is d / direction times that one, so motor n's ESC gets
``1500 + constrain((d / direction) · (pulse − 1500), −400, 400)`` µs (d = −direction: the pulse
mirrored about 1500, the thruster pushing the other way with the T200's force for the mirrored
pulse; 0: stopped). :meth:`ServoOutputs.direction_factors` gives those ratios; the run layer
applies them to the vehicle's thrusters after its allocation (``testbed.run.mavlink_run``). The
motor test is not mixed: ``AP_MotorsMatrix::output_test_num`` writes its pulse as is, so
MOT_n_DIRECTION does not change a DO_MOTOR_TEST's output.

Axes: ArduSub's forward, lateral, throttle (up), roll, pitch, yaw are the body wrench's
X, Y, −Z, K, M, N (FRD). numpy and the config error only.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from testbed.config import ConfigError

__all__ = [
    "CUSTOM_FRAME",
    "FRAME_FACTORS",
    "SERVO_CHANNELS",
    "MotorFactors",
    "ServoOutputs",
    "servo_outputs",
]

SERVO_CHANNELS = 16
"""SERVO_OUTPUT_RAW's channels (servo1_raw … servo16_raw)."""
CUSTOM_FRAME = 7
"""FRAME_CONFIG of a layout that is none of ArduSub's frames (SUB_FRAME_CUSTOM)."""


@dataclass(frozen=True, slots=True)
class MotorFactors:
    """One motor's row of ``add_motor_raw_6dof`` factors (ArduSub's axes, module docstring)."""

    roll: float
    pitch: float
    yaw: float
    throttle: float
    forward: float
    lateral: float

    @property
    def wrench(self) -> tuple[float, float, float, float, float, float]:
        """The factors on the body wrench's axes (X, Y, Z, K, M, N), FRD: throttle is up, −Z."""
        return (self.forward, self.lateral, -self.throttle, self.roll, self.pitch, self.yaw)


def _rows(*rows: tuple[float, ...]) -> tuple[MotorFactors, ...]:
    return tuple(MotorFactors(*row) for row in rows)


FRAME_FACTORS: dict[int, tuple[MotorFactors, ...]] = {
    #      roll  pitch  yaw  throttle  forward  lateral   (AP_Motors6DOF::setup_motors)
    1: _rows(  # SUB_FRAME_VECTORED
        (0, 0, 1, 0, -1, 1),
        (0, 0, -1, 0, -1, -1),
        (0, 0, -1, 0, 1, 1),
        (0, 0, 1, 0, 1, -1),
        (1, 0, 0, -1, 0, 0),
        (-1, 0, 0, -1, 0, 0),
    ),
    2: _rows(  # SUB_FRAME_VECTORED_6DOF
        (0, 0, 1, 0, -1, 1),
        (0, 0, -1, 0, -1, -1),
        (0, 0, -1, 0, 1, 1),
        (0, 0, 1, 0, 1, -1),
        (1, -1, 0, -1, 0, 0),
        (-1, -1, 0, -1, 0, 0),
        (1, 1, 0, -1, 0, 0),
        (-1, 1, 0, -1, 0, 0),
    ),
}
"""FRAME_CONFIG → motor 1, 2, …'s factor rows (ArduSub 4.5 ``AP_Motors6DOF.cpp``)."""


@dataclass(frozen=True, slots=True)
class ServoOutputs:
    """Where each thruster's pulse goes on SERVO_OUTPUT_RAW, and the frame it is reported as.

    Attributes:
        thrusters: (16,) the thruster (column of the layout, index of ``ThrusterOutput``)
            driving SERVO k + 1, −1 for an output that drives none (reported 0 µs, "unused").
        frame_config: ArduSub's FRAME_CONFIG (:data:`CUSTOM_FRAME` for a layout of its own).
        directions: MOT_1_DIRECTION, MOT_2_DIRECTION, … the vehicle behaves as (±1; empty for
            a custom layout, whose table values stay ArduSub's default 1).
    """

    thrusters: tuple[int, ...] = tuple(range(SERVO_CHANNELS))
    frame_config: int = CUSTOM_FRAME
    directions: tuple[int, ...] = ()

    @property
    def motors(self) -> int:
        """Motors the frame has (servo outputs that drive a thruster)."""
        return sum(1 for t in self.thrusters if t >= 0)

    def param_overrides(self) -> dict[str, float]:
        """Boot values for FRAME_CONFIG and the MOT_n_DIRECTION parameters."""
        out = {"FRAME_CONFIG": float(self.frame_config)}
        for n, direction in enumerate(self.directions, start=1):
            out[f"MOT_{n}_DIRECTION"] = float(direction)
        return out

    def direction_factors(self, direction: Callable[[int], float | None]) -> dict[int, float]:
        """Thruster (layout column) → MOT_n_DIRECTION / the layout's direction of its motor n,
        for the motors where that is not 1 (module docstring); ``direction(n)`` is the live
        MOT_n_DIRECTION (None: no such parameter, the layout's). A custom layout's directions
        are 1 (the table's default)."""
        out: dict[int, float] = {}
        for n, thruster in enumerate(self.thrusters, start=1):
            if thruster < 0:
                continue
            value = direction(n)
            if value is None:
                continue
            layout = self.directions[n - 1] if n <= len(self.directions) else 1
            if value != layout:
                out[thruster] = value / layout
        return out

    def pulses(self, pwm_us: Sequence[float]) -> tuple[int, ...]:
        """(16,) SERVO_OUTPUT_RAW pulses [µs] from the per-thruster ``pwm_us`` (0 = unused,
        also before the first allocation, when ``pwm_us`` is empty)."""
        n = len(pwm_us)
        return tuple(round(pwm_us[t]) if 0 <= t < n else 0 for t in self.thrusters)


def servo_outputs(
    frame_config: int | None,
    motor_columns: Sequence[int],
    matrix: np.ndarray,
    ccw: Sequence[bool],
    pwm_channels: Sequence[int],
    *,
    source: str = "layout",
) -> ServoOutputs:
    """The servo outputs of a thruster layout (module docstring).

    Args:
        frame_config: the ArduSub FRAME_CONFIG the layout declares, or None (custom).
        motor_columns: the layout's column of ArduSub's motor 1, 2, … (with ``frame_config``).
        matrix: (6, n) the layout's configuration matrix T: column i is the body wrench
            (X, Y, Z, K, M, N) [N, N·m], FRD, of a unit positive force of thruster i.
        ccw: (n,) whether thruster i has a counter-clockwise (PWM-mirrored) propeller.
        pwm_channels: (n,) each thruster's output channel (0-based), used without a frame.
        source: the layout's name, for errors.

    Returns:
        The servo map, FRAME_CONFIG and MOT_n_DIRECTION values.

    Raises:
        ConfigError: a frame whose factors are not tabled here, a motor or thruster count
            other than the frame's, a channel beyond SERVO16, or a motor whose thruster pushes
            against its factors (the layout's numbering is not ArduSub's).
    """
    if frame_config is None:
        thrusters = [-1] * SERVO_CHANNELS
        for column, channel in enumerate(pwm_channels):
            if channel >= SERVO_CHANNELS:
                raise ConfigError(f"{source}: pwm_channel {channel}: beyond SERVO{SERVO_CHANNELS}")
            thrusters[channel] = column
        return ServoOutputs(tuple(thrusters))
    factors = FRAME_FACTORS.get(frame_config)
    if factors is None:
        known = ", ".join(str(k) for k in sorted(FRAME_FACTORS))
        raise ConfigError(
            f"{source}: ardusub.frame_config: {frame_config} has no motor table here "
            f"(known: {known})"
        )
    if len(motor_columns) != len(factors):
        raise ConfigError(
            f"{source}: ardusub.motors: FRAME_CONFIG {frame_config} has {len(factors)} motors, "
            f"the layout names {len(motor_columns)}"
        )
    thrusters_n = np.asarray(matrix).shape[1]
    if thrusters_n != len(factors):  # ArduSub would leave a thruster undriven
        raise ConfigError(
            f"{source}: ardusub.motors: FRAME_CONFIG {frame_config} drives {len(factors)} "
            f"motors, the layout has {thrusters_n} thrusters (each must be one of its motors)"
        )
    directions = []
    for n, (column, row) in enumerate(zip(motor_columns, factors, strict=True), start=1):
        wrench = np.asarray(row.wrench, dtype=float)
        pushes = np.asarray(matrix, dtype=float)[:, column]
        used = wrench != 0.0
        signs = set(np.sign(wrench[used] * pushes[used]).tolist())
        if len(signs) != 1 or 0.0 in signs:
            raise ConfigError(
                f"{source}: ardusub.motors: motor {n} (column {column}) does not push along "
                f"FRAME_CONFIG {frame_config}'s factors for motor {n}"
            )
        s = int(signs.pop())
        directions.append(-s if ccw[column] else s)
    thrusters = [*motor_columns, *([-1] * (SERVO_CHANNELS - len(motor_columns)))]
    return ServoOutputs(tuple(thrusters), frame_config, tuple(directions))
