"""MAV_CMD_DO_MOTOR_TEST as ArduSub runs it, pymavlink as the ground station (QGroundControl's
motor page's traffic: armed, the command repeated at 20 Hz), in simulated time.

Independent truth: ArduSub's rules from ``ArduSub/motors.cpp`` (armed only, param6 BOARD, PWM or
percent of RC3 1100..1900 µs, output channel from 0, 0.5-s keep-alive then disarm, 10-s
cooldown) restated here, and ArduSub's mixer row of motor 1 (``AP_Motors6DOF.cpp``, Vectored:
yaw +1, forward −1, lateral +1) with MOT_1_DIRECTION read over the parameter protocol: a pulse
above 1500 µs on motor 1 must yaw the physics truth right while it backs and slides right."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest
from pymavlink.dialects.v20 import ardupilotmega as mav

from testbed.common.components import Armed, ThrusterOutput
from testbed.ecs import Origin
from testbed.mavlink import EndpointOptions
from testbed.mavlink.shore import ShoreEndpoint
from testbed.run.mavlink_gateway import GatewayStation, gateway_link_facts
from testbed.run.mavlink_run import run_mavlink
from testbed.run.scenario import load_scenario
from tests.mavlink.gcs import NO_VEHICLE_FAILSAFE, SimGcs
from tests.mavlink.rt_session import GatewaySession

ACCEPTED, FAILED = mav.MAV_RESULT_ACCEPTED, mav.MAV_RESULT_FAILED
PWM, PERCENT, PILOT = 1, 0, 2  # MOTOR_TEST_THROTTLE_TYPE
BOARD = 2  # MOTOR_TEST_ORDER_BOARD


def motor_test(
    gcs: SimGcs, motor: float, throttle: float, kind: float = PWM, order: float = BOARD
) -> Any:
    """QGroundControl's DO_MOTOR_TEST: motor from 0, throttle, timeout 0, 0 motors, order."""
    return gcs.command(mav.MAV_CMD_DO_MOTOR_TEST, motor, kind, throttle, 0, 0, order)


def results(gcs: SimGcs) -> list[int]:
    return [m.result for m in gcs.of("COMMAND_ACK") if m.command == mav.MAV_CMD_DO_MOTOR_TEST]


def texts(gcs: SimGcs) -> list[str]:
    return [m.text for m in gcs.of("STATUSTEXT")]


def servos(gcs: SimGcs) -> list[int]:
    message = gcs.last("SERVO_OUTPUT_RAW")
    return [getattr(message, f"servo{k}_raw") for k in range(1, 9)]


def keep_testing(gcs: SimGcs, seconds: float, message: Any, x: int = 0) -> None:
    """``message`` at 20 Hz (QGroundControl's timer), the sticks at 25 Hz, for ``seconds``."""
    sticks = gcs.flying(x=x)

    def each(k: int) -> list[Any]:
        return [*sticks(k), *([message] if k % 5 == 0 else [])]

    gcs.run(seconds, each)


def armed(gcs: SimGcs) -> None:
    gcs.send(gcs.heartbeat(), gcs.arm())
    gcs.run(1.01, gcs.flying())
    assert gcs.last("HEARTBEAT").base_mode & 128


def test_disarmed_the_test_is_refused_and_retried_only_after_two_seconds(gcs: SimGcs) -> None:
    gcs.send(gcs.heartbeat())
    gcs.run(0.5, gcs.flying())
    gcs.send(motor_test(gcs, 0, 1700))
    gcs.run(0.1, gcs.flying())
    assert results(gcs) == [FAILED]
    assert texts(gcs) == ["Arm motors before testing motors.", "motor test initialization failed!"]
    gcs.send(motor_test(gcs, 0, 1700))  # within 2 s: failed silently
    gcs.run(2.0, gcs.flying())
    assert results(gcs) == [FAILED, FAILED] and len(texts(gcs)) == 2
    gcs.send(motor_test(gcs, 0, 1700))  # after 2 s: a new start, refused again
    gcs.run(0.1, gcs.flying())
    assert results(gcs) == [FAILED] * 3 and len(texts(gcs)) == 4
    assert servos(gcs)[:6] == [1500] * 6


def test_an_arm_or_disarm_acknowledged_is_in_effect_for_the_next_command(gcs: SimGcs) -> None:
    """ArduSub arms and disarms inside the command's handler (``init_arm_motors``): an ARM
    followed by DO_MOTOR_TEST in the same frame starts the test, a DISARM followed by one
    fails it, as a ground station that does not wait between them expects (a user's report:
    the motor test after an ACCEPTED arm was refused until the vehicle's next frame). And the
    usual order, the motor test sent once the arm's ACK arrived, is accepted."""
    gcs.send(gcs.heartbeat())
    gcs.run(0.5, gcs.flying())
    gcs.send(gcs.arm(), motor_test(gcs, 0, 1700))  # one frame's input
    gcs.step()
    acks = [(m.command, m.result) for m in gcs.of("COMMAND_ACK")]
    assert acks == [(mav.MAV_CMD_COMPONENT_ARM_DISARM, ACCEPTED), (209, ACCEPTED)]
    keep_testing(gcs, 0.3, motor_test(gcs, 0, 1700))
    column = gcs.vehicle.thruster_config.ardusub_motor_columns[0]
    assert thrust(gcs).pwm_us[column] == 1700.0 and thrust(gcs).forces_n[column] != 0.0
    gcs.clear()
    gcs.send(gcs.arm(False), motor_test(gcs, 0, 1700))  # disarmed first: nothing written
    gcs.step()
    assert [m.result for m in gcs.of("COMMAND_ACK")] == [ACCEPTED, FAILED]
    assert not any(thrust(gcs).forces_n)
    gcs.run(11.0, gcs.flying())  # the test timed out: past its 10-s cooldown
    gcs.clear()
    gcs.send(gcs.arm())
    while not gcs.of("COMMAND_ACK"):  # a script that waits for the arm's ACK
        gcs.step()
    gcs.send(motor_test(gcs, 0, 1600))
    gcs.step()
    assert [m.result for m in gcs.of("COMMAND_ACK")] == [ACCEPTED, ACCEPTED]


def test_motor_one_spins_the_thruster_ardusub_calls_motor_one(gcs: SimGcs) -> None:
    gcs.send(gcs.mav.param_request_read_encode(1, 1, b"MOT_1_DIRECTION", -1))
    armed(gcs)
    direction = gcs.last("PARAM_VALUE").param_value
    keep_testing(gcs, 2.0, motor_test(gcs, 0, 1700))
    assert set(results(gcs)) == {ACCEPTED}
    assert servos(gcs)[:6] == [1700, 1500, 1500, 1500, 1500, 1500]
    output = gcs.vehicle.world.get(gcs.vehicle.entity, ThrusterOutput)
    assert output is not None
    column = gcs.vehicle.thruster_config.ardusub_motor_columns[0]
    assert output.pwm_us[column] == 1700.0 and output.forces_n[column] != 0.0
    assert sum(1 for f in output.forces_n if f != 0.0) == 1  # only that thruster pushes
    # ArduSub's motor 1: output > 0 ⇔ pulse − 1500 has MOT_1_DIRECTION's sign; its factors
    # yaw +1, forward −1, lateral +1: the vehicle turns right, backs and slides right
    sign = np.sign((1700 - 1500) * direction)
    u, v, _ = gcs.vehicle.truth.velocity_m_s
    r = gcs.vehicle.truth.rates_rad_s[2]
    assert (np.sign(r), np.sign(u), np.sign(v)) == (sign, -sign, sign)
    assert abs(r) > 0.05


def test_the_test_times_out_half_a_second_after_the_last_command_and_disarms(
    gcs: SimGcs,
) -> None:
    armed(gcs)
    keep_testing(gcs, 1.0, motor_test(gcs, 0, 1650))
    last_s = gcs.now_s - 0.05  # the last of the 20-Hz commands
    gcs.clear()
    gcs.run(0.45 - 0.05, gcs.flying())  # 0.4 s after it: still testing
    assert "Motor test timed out!" not in texts(gcs)
    gcs.run(0.2, gcs.flying())
    assert "Motor test timed out!" in texts(gcs)
    gcs.run(1.01, gcs.flying())
    assert not gcs.last("HEARTBEAT").base_mode & 128  # ArduSub disarms
    assert servos(gcs)[:6] == [1500] * 6
    assert gcs.endpoint.motor_test.timed_out_s == pytest.approx(last_s + 0.5, abs=0.02)
    # re-armed, a new test within 10 s of the timeout is refused; after them it runs
    gcs.clear()
    armed(gcs)
    assert servos(gcs)[:6] == [1500] * 6  # the timed-out test left no thruster driven
    assert not any(thrust(gcs).forces_n)
    gcs.send(motor_test(gcs, 0, 1600))
    gcs.run(0.1, gcs.flying())
    assert results(gcs) == [FAILED]
    assert "10 second cooldown required after motor test" in texts(gcs)
    gcs.run(9.0, gcs.flying())
    keep_testing(gcs, 0.5, motor_test(gcs, 0, 1600))
    assert results(gcs)[-1] == ACCEPTED and servos(gcs)[0] == 1600


def test_disarmed_mid_test_commands_fail_and_a_rearmed_vehicle_drives_nothing_until_told(
    gcs: SimGcs,
) -> None:
    """``output_test_num`` writes only while armed (FAILED otherwise), and arming puts every
    motor at 1500 µs (``enable_motor_output``): the pulse given before the disarm is gone."""
    armed(gcs)
    keep_testing(gcs, 0.5, motor_test(gcs, 0, 1700))
    assert servos(gcs)[0] == 1700
    gcs.clear()
    gcs.send(gcs.arm(False))
    keep_testing(gcs, 0.3, motor_test(gcs, 0, 1700))  # QGroundControl's slider still held
    vehicle_armed = gcs.vehicle.world.get(gcs.vehicle.entity, Armed)
    assert vehicle_armed is not None and not vehicle_armed.armed
    assert results(gcs)[-3:] == [FAILED] * 3
    assert gcs.endpoint.motor_test.active  # the commands keep the test alive, as ArduSub's
    gcs.clear()
    gcs.send(gcs.arm())  # the slider released: no more commands
    gcs.run(0.3, gcs.flying())  # under the 0.5-s keep-alive: the test still runs
    assert gcs.endpoint.motor_test.active
    assert thrust(gcs).pwm_us == (1500.0,) * 6 and not any(thrust(gcs).forces_n)
    assert servos(gcs)[:6] == [1500] * 6


def test_a_pulse_out_of_range_is_written_as_ardusubs_types_do_not_raised(gcs: SimGcs) -> None:
    """param3 −5000 µs: int16_t −5000, written as the uint16_t 60536 (ArduSub's ``rc_write``);
    SERVO_OUTPUT_RAW reports it and the thruster gets the T200 table's end, nothing raises."""
    armed(gcs)
    keep_testing(gcs, 0.6, motor_test(gcs, 0, -5000.7))
    assert set(results(gcs)) == {ACCEPTED}
    assert servos(gcs)[:6] == [65536 - 5000, 1500, 1500, 1500, 1500, 1500]
    column = gcs.vehicle.thruster_config.ardusub_motor_columns[0]
    assert thrust(gcs).pwm_us[column] == 60536.0
    t200 = gcs.vehicle.actuation.allocator.t200
    ends = {t200.force_for_pwm(1100.0), t200.force_for_pwm(1900.0)}
    assert thrust(gcs).forces_n[column] in ends


def thrust(gcs: SimGcs) -> ThrusterOutput:
    output = gcs.vehicle.world.get(gcs.vehicle.entity, ThrusterOutput)
    assert output is not None
    return output


def test_percent_as_qgroundcontrol_sends_it_and_each_pulse_stays_until_changed(
    gcs: SimGcs,
) -> None:
    armed(gcs)
    keep_testing(gcs, 0.5, motor_test(gcs, 4, 75, kind=PERCENT))  # 1100 + 0.75 × 800
    assert servos(gcs)[:6] == [1500, 1500, 1500, 1500, 1700, 1500]
    keep_testing(gcs, 0.5, motor_test(gcs, 2, 25, kind=PERCENT))  # another motor: 1300
    assert servos(gcs)[:6] == [1500, 1500, 1300, 1500, 1700, 1500]
    keep_testing(gcs, 0.5, motor_test(gcs, 4, 50, kind=PERCENT))  # the slider released
    keep_testing(gcs, 0.5, motor_test(gcs, 2, 150, kind=PERCENT))  # constrained to 100 %
    assert servos(gcs)[:6] == [1500, 1500, 1900, 1500, 1500, 1500]
    assert set(results(gcs)) == {ACCEPTED}


def test_while_testing_the_sticks_do_not_drive_the_thrusters(gcs: SimGcs) -> None:
    armed(gcs)
    keep_testing(gcs, 3.0, motor_test(gcs, 0, 1500), x=1000)  # full forward stick
    assert servos(gcs)[:6] == [1500] * 6
    assert abs(gcs.truth_surge_m_s()) < 0.02


def test_bad_commands_fail_as_ardusubs_and_are_counted_not_raised(gcs: SimGcs) -> None:
    armed(gcs)
    keep_testing(gcs, 0.2, motor_test(gcs, 0, 1600))  # the test runs
    gcs.clear()
    gcs.send(
        motor_test(gcs, 0, 1700, order=0),  # MOTOR_TEST_ORDER_DEFAULT
        motor_test(gcs, 0, 1700, kind=PILOT),
        motor_test(gcs, 0, 1700, kind=3),  # compass calibration: not a throttle
        motor_test(gcs, 6, 1700),  # no motor 7 on the Vectored frame
        motor_test(gcs, 12, 1700),  # beyond AP_MOTORS_MAX_NUM_MOTORS
        motor_test(gcs, math.nan, 1700),
        motor_test(gcs, -1, 1700),
        motor_test(gcs, 0, math.nan),
        motor_test(gcs, 0, math.inf, kind=PERCENT),
    )
    gcs.run(0.05, gcs.flying())
    assert results(gcs) == [FAILED] * 9
    assert texts(gcs) == ["bad test type 0.00", "bad throttle type 2.00"]
    assert gcs.endpoint.rejected["bad_field"] == 3
    keep_testing(gcs, 1.0, motor_test(gcs, 1, 1500))  # the test went on, motor 1 untouched
    assert servos(gcs)[:6] == [1600, 1500, 1500, 1500, 1500, 1500]


def test_through_the_gateway_the_thrusters_are_out_of_reach() -> None:
    scenario = load_scenario("s100-teleop-v1", list(NO_VEHICLE_FAILSAFE))
    station = GatewayStation()
    options = EndpointOptions(origin=Origin.LOCAL)
    shore = ShoreEndpoint(station.world, station.entity, gateway_link_facts(scenario), options)
    channel = shore.open_channel("gcs")
    sender = SimGcs.make_sender(255)
    packet = sender.command_long_encode(1, 1, mav.MAV_CMD_DO_MOTOR_TEST, 0, 0, 1, 1700, 0, 0, 2, 0)
    shore.receive(channel, packet.pack(sender), 1.0)
    shore.update(1.0)  # STATUSTEXT goes out at the end of an update, as ArduPilot's
    decoder = mav.MAVLink(None)
    replies = [m for p in channel.take() for m in decoder.parse_buffer(p) or []]
    acks = [m.result for m in replies if m.get_type() == "COMMAND_ACK"]
    assert acks == [FAILED]
    assert "Motor test: thrusters beyond the link" in [
        m.text for m in replies if m.get_type() == "STATUSTEXT"
    ]


def test_in_real_time_an_arm_and_a_motor_test_in_one_datagram_start_the_test() -> None:
    """≈ 4 s real time, pymavlink's ``mavutil`` on 127.0.0.1 in front of ``run_mavlink``: ARM
    and DO_MOTOR_TEST written as one datagram (so one vehicle frame reads both) are both
    ACCEPTED and motor 1's servo shows the pulse; DISARM and DO_MOTOR_TEST in one datagram:
    the test command FAILED (ArduSub disarmed inside the first)."""
    scenario = load_scenario("s100-teleop-v1")
    session = GatewaySession(
        lambda links, stop: run_mavlink(scenario, links, duration_s=60.0, stop=stop)
    )
    try:
        gcs = session.gcs
        assert gcs.wait_heartbeat(timeout=session.wait_s) is not None
        session.pump(0.3)

        def command(cmd: int, *params: float) -> bytes:
            p = [*params, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0][:7]
            return bytes(gcs.mav.command_long_encode(1, 1, cmd, 0, *p).pack(gcs.mav))

        test = command(mav.MAV_CMD_DO_MOTOR_TEST, 0, PWM, 1700, 0, 0, BOARD)
        gcs.write(command(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1) + test)
        session.until(lambda: len(session.seen.get("COMMAND_ACK", [])) >= 2)
        first = [(m.command, m.result) for _, m in session.seen["COMMAND_ACK"][:2]]
        assert first == [(400, ACCEPTED), (209, ACCEPTED)]

        def testing() -> bool:  # the keep-alive (QGroundControl's is 20 Hz), until SERVO1 shows it
            gcs.write(test)
            servo = session.latest.get("SERVO_OUTPUT_RAW")
            return servo is not None and servo.servo1_raw == 1700

        session.until(testing)
        count = len(session.seen["COMMAND_ACK"])  # a keep-alive's ACK may still come
        gcs.write(command(mav.MAV_CMD_COMPONENT_ARM_DISARM, 0) + test)

        def after_disarm() -> list[tuple[int, int]]:
            later = [(m.command, m.result) for _, m in session.seen["COMMAND_ACK"][count:]]
            disarm = later.index((400, ACCEPTED)) if (400, ACCEPTED) in later else len(later)
            return later[disarm : disarm + 2] if len(later) >= disarm + 2 else []

        assert session.until(after_disarm) == [(400, ACCEPTED), (209, FAILED)]
        result = session.finish()
    finally:
        session.close()
    section = result.metrics["mavlink"]
    assert section["rejected"].get("command_refused", 0) == 1  # the one after the disarm
