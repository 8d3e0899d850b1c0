"""ArduSub's MAVLink conventions as data and pure functions (REFERENCE.md §4).

Mode numbers (ArduSub ``mode.h``) and which of them the simulator flies; the heartbeat's
``base_mode`` and ``system_status``; the stream groups of REQUEST_DATA_STREAM; the pilot
input path of ``joystick.cpp`` (MANUAL_CONTROL → RC channel pulse widths, with the joystick
gain) and ``AP_Motors6DOF``'s reading of those channels (pulse → ±1 over 400 µs), which gives
the (6,) sticks of a :class:`~testbed.common.components.MovementCommand`. No I/O, no state.

Frames: MANUAL_CONTROL x forward, y right, z up (0..1000, 500 neutral), r clockwise seen from
above; the testbed's sticks are body FRD (surge, sway, heave + down, roll, pitch, yaw), so
only heave changes sign.
"""

from __future__ import annotations

from testbed.common.components import ControlMode

__all__ = [
    "ARDUSUB_MODES",
    "BASE_MODE_ALWAYS",
    "FIRMWARE_VERSION",
    "FLIGHT_SW_VERSION",
    "GIT_HASH",
    "GUIDED_MODES",
    "MAV_MODE_FLAG_CUSTOM_MODE_ENABLED",
    "MAV_MODE_FLAG_GUIDED_ENABLED",
    "MAV_MODE_FLAG_SAFETY_ARMED",
    "NEUTRAL_PWM",
    "POSITION_MODES",
    "ROLL_PITCH_INPUT_MAX",
    "SIMULATED_MODES",
    "STREAM_GROUPS",
    "RcInput",
    "base_mode",
    "manual_control_from_sticks",
    "manual_control_pwm",
    "rc_angle",
    "sticks_from_rc",
]

ARDUSUB_MODES = {
    0: "STABILIZE",
    1: "ACRO",
    2: "ALT_HOLD",
    3: "AUTO",
    4: "GUIDED",
    7: "CIRCLE",
    9: "SURFACE",
    16: "POSHOLD",
    19: "MANUAL",
    20: "MOTOR_DETECT",
    21: "SURFTRAK",
}
"""ArduSub's mode numbers (``mode.h``) → names; 19 MANUAL is the boot mode."""
SIMULATED_MODES = {
    19: ControlMode.MANUAL,
    0: ControlMode.STABILIZE,
    2: ControlMode.DEPTH_HOLD,
    4: ControlMode.GUIDED,
}
"""The modes the simulated vehicle flies, by ArduSub number (GUIDED only with a position
estimate, :data:`POSITION_MODES`)."""
POSITION_MODES = frozenset({3, 4, 7, 16})
"""AUTO, GUIDED, CIRCLE, POSHOLD: ArduSub refuses them without a position estimate."""
GUIDED_MODES = frozenset({3, 4, 7, 16})
"""Modes whose heartbeat carries the GUIDED flag (ArduSub: AUTO, GUIDED, CIRCLE, POSHOLD)."""

MAV_MODE_FLAG_CUSTOM_MODE_ENABLED = 1
MAV_MODE_FLAG_GUIDED_ENABLED = 8
MAV_MODE_FLAG_STABILIZE_ENABLED = 16
MAV_MODE_FLAG_MANUAL_INPUT_ENABLED = 64
MAV_MODE_FLAG_SAFETY_ARMED = 128
BASE_MODE_ALWAYS = (
    MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    | MAV_MODE_FLAG_STABILIZE_ENABLED
    | MAV_MODE_FLAG_MANUAL_INPUT_ENABLED
)
"""81: the flags ArduSub's heartbeat always sets (custom, stabilize, manual input)."""

FIRMWARE_VERSION = (4, 5, 3)
"""The ArduSub release the endpoint presents itself as (major, minor, patch)."""
FLIGHT_SW_VERSION = (
    FIRMWARE_VERSION[0] << 24 | FIRMWARE_VERSION[1] << 16 | FIRMWARE_VERSION[2] << 8 | 255
)
"""AUTOPILOT_VERSION.flight_sw_version: major<<24 | minor<<16 | patch<<8 | 255 (official)."""
GIT_HASH = b"testbed0"
"""AUTOPILOT_VERSION.flight_custom_version: 8 characters (a real build's git hash)."""

NEUTRAL_PWM = 1500
ROLL_PITCH_INPUT_MAX = 4500
"""ArduSub's ``config.h``: the range of an angle RC channel's ``control_in`` (±4500; the yaw
channel's too, ``Sub::init_rc_in``)."""
_PWM_HALF_RANGE = 400.0
"""AP_Motors6DOF reads a channel as (pwm − 1500) / 400 → ±1 (1100..1900 µs)."""

STREAM_GROUPS: dict[int, tuple[str, ...]] = {
    1: ("RAW_IMU", "SCALED_PRESSURE", "SCALED_PRESSURE2"),
    2: ("SYS_STATUS", "GPS_RAW_INT", "NAMED_VALUE_FLOAT"),
    3: ("RC_CHANNELS", "SERVO_OUTPUT_RAW"),
    6: ("GLOBAL_POSITION_INT", "LOCAL_POSITION_NED"),
    10: ("ATTITUDE",),
    11: ("VFR_HUD",),
    12: ("SYSTEM_TIME", "BATTERY_STATUS"),
}
"""MAV_DATA_STREAM id → the messages of that group the endpoint sends (RAW_SENSORS 1,
EXTENDED_STATUS 2, RC_CHANNELS 3, POSITION 6, EXTRA1 10, EXTRA2 11, EXTRA3 12); ArduSub's
groups hold more messages, which the simulator has no source for. ATTITUDE_QUATERNION is in
none: ArduSub's ``STREAM_EXTRA1_msgs`` holds ATTITUDE, SIMSTATE, AHRS2, AHRS3, PID_TUNING, so it is
sent only on request (:data:`~testbed.mavlink.streams.ON_REQUEST`)."""


def base_mode(custom_mode: int, armed: bool) -> int:
    """The heartbeat's ``base_mode``: 81, + 8 in guided modes, + 128 armed (81 / 209 / 217)."""
    flags = BASE_MODE_ALWAYS
    if custom_mode in GUIDED_MODES:
        flags |= MAV_MODE_FLAG_GUIDED_ENABLED
    if armed:
        flags |= MAV_MODE_FLAG_SAFETY_ARMED
    return flags


def _clamp(value: float, low: float, high: float) -> float:
    return low if value < low else high if value > high else value


def boot_gain(default: float, low: float, high: float, steps: int) -> float:
    """The joystick gain ArduSub starts with (``Sub::init_joystick``, at boot only; a
    JS_GAIN_* set later takes effect at the next boot, or through the gain buttons): the
    default within [low, high] when it is within them (±0.01) or with one step, else the step
    nearest the middle; then within [0.1, 1]."""
    steps = max(1, steps)
    if steps == 1 or low - 0.01 < default < high + 0.01:
        gain = min(max(default, low), high)
    else:
        gain = low + (steps // 2 - 1) * (high - low) / (steps - 1)
    return min(max(gain, 0.1), 1.0)


def manual_control_pwm(
    x: int, y: int, z: int, r: int, *, gain: float, throttle_gain: float = 1.0
) -> dict[int, int]:
    """ArduSub's ``joystick.cpp``: MANUAL_CONTROL axes → RC channel pulse widths [µs].

    Args:
        x: forward, −1000..1000.
        y: lateral (right), −1000..1000.
        z: throttle (up), 0..1000, 500 neutral.
        r: yaw (clockwise), −1000..1000.
        gain: the joystick gain in [JS_GAIN_MIN, JS_GAIN_MAX] (boot JS_GAIN_DEFAULT).
        throttle_gain: JS_THR_GAIN.

    Returns:
        {channel: µs} for channels 3 throttle, 4 yaw, 5 forward, 6 lateral; each clamped to
        1100..1900 (gain 0.5: x 1000 → 1700; z 1000 → 1700, z 0 → 1300).
    """
    rpy_scale = 0.4 * gain
    throttle_scale = 0.8 * gain * throttle_gain
    throttle_base = NEUTRAL_PWM - 500.0 * throttle_scale
    return {
        3: round(_clamp(throttle_base + z * throttle_scale, 1100.0, 1900.0)),
        4: round(_clamp(NEUTRAL_PWM + r * rpy_scale, 1100.0, 1900.0)),
        5: round(_clamp(NEUTRAL_PWM + x * rpy_scale, 1100.0, 1900.0)),
        6: round(_clamp(NEUTRAL_PWM + y * rpy_scale, 1100.0, 1900.0)),
    }


def _c_div(numerator: int, denominator: int) -> int:
    """C's integer division: the quotient truncated toward zero."""
    quotient = abs(numerator) // abs(denominator)
    return quotient if (numerator < 0) == (denominator < 0) else -quotient


def rc_angle(
    pwm: int, *, minimum: int, trim: int, maximum: int, dead_zone: int, reversed_: bool
) -> int:
    """An angle RC channel's ``control_in`` as ArduPilot's ``RC_Channel::pwm_to_angle_dz_trim``
    computes it (ArduSub's yaw channel: ±:data:`ROLL_PITCH_INPUT_MAX`, RC4_DZ 40 µs by
    ``set_default_dead_zone``): the pulse constrained to [minimum, maximum], 0 within the dead
    zone around the trim, else scaled from the dead zone's edge to the end, in int32 arithmetic
    (the quotient truncated toward zero).

    Args:
        pwm: the channel's pulse [µs].
        minimum: RCn_MIN [µs].
        trim: RCn_TRIM [µs].
        maximum: RCn_MAX [µs].
        dead_zone: RCn_DZ [µs].
        reversed_: RCn_REVERSED.

    Returns:
        ``control_in`` (1600 µs → 750, 1900 µs → 4500 with the defaults).
    """
    high = trim + dead_zone
    low = trim - dead_zone
    sign = -1 if reversed_ else 1
    r_in = minimum if pwm < minimum else maximum if pwm > maximum else pwm  # constrain_int16
    if r_in > high and maximum != high:
        return sign * _c_div(ROLL_PITCH_INPUT_MAX * (r_in - high), maximum - high)
    if r_in < low and low != minimum:
        return sign * _c_div(ROLL_PITCH_INPUT_MAX * (r_in - low), low - minimum)
    return 0


class RcInput:
    """The vehicle's 18 RC input channels [µs], as MANUAL_CONTROL and RC_CHANNELS_OVERRIDE
    set them (channels 1–6 neutral 1500, the rest 0 = no signal until overridden)."""

    __slots__ = ("channels",)

    def __init__(self) -> None:
        self.channels = [NEUTRAL_PWM] * 6 + [0] * 12

    def neutral(self) -> None:
        """ArduSub's ``set_neutral_controls``: the six motion channels to 1500."""
        self.channels[:6] = [NEUTRAL_PWM] * 6


def sticks_from_rc(channels: list[int]) -> tuple[float, float, float, float, float, float]:
    """RC channels (1 pitch, 2 roll, 3 throttle, 4 yaw, 5 forward, 6 lateral) → (6,) sticks
    in [−1, 1], body FRD: surge, sway, heave (+ down), roll, pitch, yaw. A channel at 0 (no
    signal) reads neutral."""

    def axis(channel: int) -> float:
        pwm = channels[channel - 1]
        if pwm == 0:
            return 0.0
        return _clamp((pwm - NEUTRAL_PWM) / _PWM_HALF_RANGE, -1.0, 1.0)

    return (axis(5), axis(6), 0.0 - axis(3) + 0.0, axis(2), axis(1), axis(4))


def manual_control_from_sticks(
    sticks: tuple[float, float, float, float, float, float],
    *,
    gain: float,
    throttle_gain: float = 1.0,
) -> tuple[int, int, int, int]:
    """The MAVLink MANUAL_CONTROL axes (x, y, z, r) a ground station sends for ``sticks``
    (surge, sway, heave + down, roll, pitch, yaw in [−1, 1]): the inverse of
    :func:`manual_control_pwm` then :func:`sticks_from_rc` at ``gain`` (a stick beyond what
    the gain reaches is clamped to the axis' range)."""
    surge, sway, heave, _, _, yaw = sticks

    def rpy(value: float) -> int:
        return round(_clamp(1000.0 * value / gain, -1000.0, 1000.0))

    throttle_scale = 0.8 * gain * throttle_gain
    z = 500.0 - 400.0 * heave / throttle_scale
    return rpy(surge), rpy(sway), round(_clamp(z, 0.0, 1000.0)), rpy(yaw)
