"""MAV_CMD_DO_MOTOR_TEST as ArduSub runs it (QGroundControl's motor page): armed, kept alive.

ArduSub 4.5 (``ArduSub/motors.cpp``: ``handle_do_motor_test``, ``init_motor_test``,
``verify_motor_test``, ``motors_output``; ``AP_MotorsMatrix::output_test_num``; the command's
result in ``GCS_Mavlink.cpp``: ACCEPTED when the output was set, else FAILED):

- The first command starts the test, which needs the vehicle **armed** ("Arm motors before
  testing motors."; armed as the last acknowledged arm or disarm left it, even before the
  vehicle's next frame applies it: ArduSub arms inside the arm command's handler, so an ARM
  and a DO_MOTOR_TEST read together start the test:
  :attr:`~testbed.mavlink.endpoint.VehicleEndpoint.armed`), and no failed test in the last
  10 s ("10 second cooldown required after motor test"); a failed start says "motor test
  initialization failed!" and the next 2 s of commands fail silently. Starting puts every
  motor at 1500 µs and stops the mixer: the pilot's sticks and the holds no longer drive the
  thrusters.
- Each command: param6 must be MOTOR_TEST_ORDER_BOARD (2, "bad test type"), param2 the throttle
  type, PWM (1: param3 µs, as is) or PERCENT (0: param3 constrained to 0..100 % of RC3_MIN..
  RC3_MAX, 1100..1900 µs, 50 % = 1500); PILOT (2) is refused ("bad throttle type"). param1 is
  the output channel from 0 (motor 1 on SERVO1), as QGroundControl sends it; a channel beyond 11
  or without a motor fails. The pulse is written to that motor and stays until another command
  changes it; param4 (the timeout) is not used. The pulse is ``output_test_num``'s: param3
  truncated to an int16_t and written by ``rc_write`` as a uint16_t, so a negative one reaches
  the output as 65536 + it (SERVO_OUTPUT_RAW reports it so); and it is written only while
  armed: disarmed, even during a test, the command fails.
- The test lives while commands keep coming: 0.5 s after the last one ArduSub says "Motor test
  timed out!", stops the test, **disarms**, and a new test needs 10 s of cooldown.

Here the pulses become the vehicle's :class:`~testbed.common.components.ThrusterTest` (per
thruster, through the layout's servo map, :class:`~testbed.mavlink.motors.ServoOutputs`), which
the vehicle's allocation flies instead of the mixer while armed: SERVO_OUTPUT_RAW shows them and
the thrusters push with the T200's force for them (beyond its table, the table's end). A disarm
ends the thrust at once (the vehicle drives nothing disarmed) and puts every motor back at
1500 µs, as ArduSub's arming does (``enable_motor_output``), so a re-armed vehicle drives
nothing until the next command; the test itself ends at the timeout, as ArduSub's. A shore gateway
cannot reach the thrusters: its commands fail. Malformed parameters (NaN, out of range) fail the
command, counted ``bad_field``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from pymavlink.dialects.v20 import ardupilotmega as mav

from testbed.common.components import ThrusterTest

if TYPE_CHECKING:
    from testbed.mavlink.endpoint import VehicleEndpoint

__all__ = [
    "COOLDOWN_S",
    "KEEPALIVE_S",
    "MAX_MOTORS",
    "MotorTest",
    "do_motor_test",
    "update_motor_test",
]

KEEPALIVE_S = 0.5
"""A test ends this long after its last command [s] (``verify_motor_test``: 2 Hz at least)."""
COOLDOWN_S = 10.0
"""No new test this long after one timed out [s]."""
RETRY_S = 2.0
"""After a failed start, commands fail silently this long [s]."""
MAX_MOTORS = 12
"""AP_MOTORS_MAX_NUM_MOTORS: output channels 0..11."""
_ORDER_BOARD = mav.MOTOR_TEST_ORDER_BOARD
_PWM = mav.MOTOR_TEST_THROTTLE_PWM
_PERCENT = mav.MOTOR_TEST_THROTTLE_PERCENT
_PILOT = mav.MOTOR_TEST_THROTTLE_PILOT
_FAILED = int(mav.MAV_RESULT_FAILED)
_ACCEPTED = int(mav.MAV_RESULT_ACCEPTED)


@dataclass(slots=True)
class MotorTest:
    """The endpoint's motor-test state (mutable).

    Attributes:
        active: a test is running (ArduSub's ``ap.motor_test``).
        pulses_us: output channel → the pulse written to it [µs] while active.
        last_command_s: the last DO_MOTOR_TEST's time [s].
        start_failed_s: when a start last failed [s].
        timed_out_s: when a test last timed out [s] (None: never; the cooldown's start).
    """

    active: bool = False
    pulses_us: dict[int, int] = field(default_factory=dict)
    last_command_s: float = -math.inf
    start_failed_s: float = -math.inf
    timed_out_s: float | None = None


def _warn(endpoint: VehicleEndpoint, severity: int, text: str) -> bool:
    endpoint.statustext(severity, text)
    return False


def _start(endpoint: VehicleEndpoint, test: MotorTest, now_s: float) -> bool:
    """``init_motor_test``: the cooldown, then armed; every motor at 1500 µs."""
    if test.timed_out_s is not None and now_s < test.timed_out_s + COOLDOWN_S:
        text = "10 second cooldown required after motor test"
        return _warn(endpoint, mav.MAV_SEVERITY_CRITICAL, text)
    if not endpoint.can_test_motors:
        return _warn(endpoint, mav.MAV_SEVERITY_WARNING, "Motor test: thrusters beyond the link")
    if not endpoint.armed:
        return _warn(endpoint, mav.MAV_SEVERITY_WARNING, "Arm motors before testing motors.")
    test.active = True
    _neutral(endpoint, test)
    return True


def _neutral(endpoint: VehicleEndpoint, test: MotorTest) -> None:
    """Every motor at 1500 µs (``enable_motor_output``: the test's start, and arming)."""
    thrusters = endpoint.options.servos.thrusters[:MAX_MOTORS]
    test.pulses_us = {channel: 1500 for channel, t in enumerate(thrusters) if t >= 0}


def do_motor_test(endpoint: VehicleEndpoint, params: tuple[float, ...], now_s: float) -> int:
    """One DO_MOTOR_TEST (module docstring): the MAV_RESULT.

    Args:
        endpoint: the endpoint.
        params: the command's param1 … param7 (param5, 6 of a COMMAND_INT: x, y).
        now_s: the time [s].
    """
    test = endpoint.motor_test
    test.last_command_s = now_s
    if not test.active:
        if now_s <= test.start_failed_s + RETRY_S:
            return _FAILED
        if not _start(endpoint, test, now_s):
            endpoint.statustext(mav.MAV_SEVERITY_WARNING, "motor test initialization failed!")
            test.start_failed_s = now_s
            return _FAILED
    motor, throttle_type, throttle, test_type = params[0], params[1], params[2], params[5]
    if test_type != _ORDER_BOARD:
        _warn(endpoint, mav.MAV_SEVERITY_WARNING, f"bad test type {test_type:0.2f}")
        return _FAILED
    if throttle_type == _PILOT:
        _warn(endpoint, mav.MAV_SEVERITY_WARNING, f"bad throttle type {throttle_type:0.2f}")
        return _FAILED
    if throttle_type == _PERCENT and math.isfinite(throttle):
        low, high = endpoint.params["RC3_MIN"], endpoint.params["RC3_MAX"]
        throttle = low + min(100.0, max(0.0, throttle)) / 100.0 * (high - low)
    elif throttle_type != _PWM:
        return _FAILED  # another type, or NaN
    channel = int(motor) if math.isfinite(motor) and 0.0 <= motor < 256.0 else None
    if channel is None or not math.isfinite(throttle) or not -32768.0 < throttle < 32768.0:
        endpoint.reject("bad_field")
        return _FAILED
    if channel not in test.pulses_us:  # beyond AP_MOTORS_MAX_NUM_MOTORS, or no motor there
        return _FAILED
    if not endpoint.armed:  # output_test_num: the motors armed
        return _FAILED
    test.pulses_us[channel] = int(throttle) & 0xFFFF  # int16_t, truncated; rc_write's uint16_t
    _write(endpoint, test)
    return _ACCEPTED


def _write(endpoint: VehicleEndpoint, test: MotorTest) -> None:
    """The pulses as the vehicle's ThrusterTest, per thruster (empty when no test runs)."""
    if not test.active:
        endpoint.write(ThrusterTest())
        return
    thrusters = endpoint.options.servos.thrusters
    pwm = [1500.0] * endpoint.options.servos.motors
    for channel, pulse in test.pulses_us.items():
        pwm[thrusters[channel]] = float(pulse)
    endpoint.write(ThrusterTest(tuple(pwm)))


def update_motor_test(endpoint: VehicleEndpoint, now_s: float) -> None:
    """``verify_motor_test``: a test without a command for :data:`KEEPALIVE_S` ends, and the
    vehicle disarms; a test whose vehicle is disarmed has every motor back at 1500 µs (what
    re-arming writes)."""
    test = endpoint.motor_test
    if not test.active:
        return
    if not endpoint.armed and any(p != 1500 for p in test.pulses_us.values()):
        _neutral(endpoint, test)
        _write(endpoint, test)
    if now_s > test.last_command_s + KEEPALIVE_S:
        endpoint.statustext(mav.MAV_SEVERITY_INFO, "Motor test timed out!")
        test.active = False
        test.pulses_us = {}
        test.timed_out_s = now_s
        _write(endpoint, test)
        endpoint.request_arm(False, now_s)
