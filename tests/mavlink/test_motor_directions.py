"""MOT_n_DIRECTION acts as ArduSub 4.5's ``_motor_reverse`` does, pymavlink as the ground station.

Independent truth, restated from ArduPilot's source: ``AP_Motors6DOF::output_armed_stabilizing*``
ends the mixer with ``_thrust_rpyt_out[i] = constrain(_motor_reverse[i] · (rpy + linear), −1, 1)``
and ``calc_thrust_to_pwm`` writes ``1500 + 400 · thrust``: motor n's pulse offset from 1500 µs
is multiplied by MOT_n_DIRECTION, read every loop (a PARAM_SET acts at once). So flipping the
direction the layout needs mirrors motor n's pulse about 1500 µs, and the thruster then pushes
with the T200 table's force for the mirrored pulse. ``AP_MotorsMatrix::output_test_num`` (the
motor test) writes its pulse unmixed: MOT_n_DIRECTION does not touch a DO_MOTOR_TEST.
ArduSub's Vectored factors of motor 1 (yaw +1, forward −1, lateral +1): with its output reversed
a forward stick turns the vehicle right and slides it right (motors 1 and 2 no longer cancel).
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest
import simpy
from pymavlink.dialects.v20 import ardupilotmega as mav

from testbed.common.components import ThrusterOutput
from testbed.common.geometry import euler_from_quat
from testbed.run.mavlink_links import RawMavlinkVehicleLink
from testbed.run.mavlink_run import MavlinkVehicleNode, install_motor_directions
from testbed.run.recorder import Recorder
from testbed.run.scenario import load_scenario
from testbed.vehicle.thrusters import T200
from tests.mavlink.gcs import NO_VEHICLE_FAILSAFE, SimGcs

MANUAL = 19


@pytest.fixture
def pair() -> Iterator[tuple[SimGcs, SimGcs]]:
    """Two identical vehicles (same seed) with MOT_n_DIRECTION acting: the layout's directions
    and one to be changed."""
    stations = (SimGcs(), SimGcs())
    for station in stations:
        install_motor_directions(station.vehicle, station.endpoint)
    yield stations
    for station in stations:
        station.close()


def boot_direction(gcs: SimGcs, n: int) -> float:
    """MOT_n_DIRECTION as the vehicle reports it over the parameter protocol."""
    gcs.send(gcs.mav.param_request_read_encode(1, 1, f"MOT_{n}_DIRECTION".encode(), -1))
    gcs.step()
    value = gcs.last("PARAM_VALUE")
    assert value.param_id == f"MOT_{n}_DIRECTION"
    return float(value.param_value)


def output(gcs: SimGcs) -> ThrusterOutput:
    out = gcs.vehicle.world.get(gcs.vehicle.entity, ThrusterOutput)
    assert out is not None
    return out


def servo(gcs: SimGcs, n: int) -> int:
    return int(getattr(gcs.last("SERVO_OUTPUT_RAW"), f"servo{n}_raw"))


def arm_in_manual(gcs: SimGcs) -> None:
    gcs.send(gcs.heartbeat(), gcs.arm(), gcs.set_mode(MANUAL))
    gcs.run(0.5, gcs.flying())


def test_a_reversed_motor_gets_the_mirrored_pulse_and_the_t200s_force_for_it(
    pair: tuple[SimGcs, SimGcs],
) -> None:
    """The same forward stick on two identical vehicles, one with MOT_1_DIRECTION set against
    its propeller: at the first frame the stick drives, motor 1's ESC gets 3000 − the pulse the
    other gets (the thrust output negated), its thruster pushes the T200 table's force for that
    pulse (its propeller's handedness), SERVO_OUTPUT_RAW's servo 1 says so, and every other
    thruster is untouched."""
    default, flipped = pair
    direction = boot_direction(flipped, 1)
    assert direction in (1.0, -1.0)
    flipped.send(flipped.param_set("MOT_1_DIRECTION", -direction))
    default.send(default.param_set("MOT_2_DIRECTION", boot_direction(default, 2)))  # unchanged
    for gcs in pair:
        arm_in_manual(gcs)
        gcs.send(gcs.sticks(x=800))
        while not any(output(gcs).forces_n):
            gcs.step()
    assert default.now_s == flipped.now_s  # the same frame on both
    layout = flipped.vehicle.thruster_config
    motor1 = layout.ardusub_motor_columns[0]
    mine, theirs = output(flipped), output(default)
    assert flipped.vehicle.actuation.commanded_forces_n[motor1] == mine.forces_n[motor1]
    assert theirs.pwm_us[motor1] != 1500.0
    assert mine.pwm_us[motor1] == pytest.approx(3000.0 - theirs.pwm_us[motor1], abs=1e-9)
    t200 = T200.from_table(flipped.vehicle.config.supply_voltage_v)
    handedness = layout.thrusters[motor1].handedness
    expected = t200.force_for_pwm(mine.pwm_us[motor1], handedness)
    assert mine.forces_n[motor1] == pytest.approx(expected)
    assert np.sign(mine.forces_n[motor1]) == -np.sign(theirs.forces_n[motor1])
    others = [k for k in range(layout.n_thrusters) if k != motor1]
    assert [mine.pwm_us[k] for k in others] == [theirs.pwm_us[k] for k in others]
    assert [mine.forces_n[k] for k in others] == [theirs.forces_n[k] for k in others]
    # the PARAM_SET is stored and echoed; SERVO_OUTPUT_RAW shows the pulse
    assert boot_direction(flipped, 1) == -direction
    flipped.send(flipped.mav.request_data_stream_encode(1, 1, 3, 50, 1))
    flipped.run(0.05, flipped.flying(x=800))
    assert servo(flipped, 1) == round(output(flipped).pwm_us[motor1])
    assert np.sign(servo(flipped, 1) - 1500) == -np.sign(theirs.pwm_us[motor1] - 1500)


def test_with_motor_one_reversed_the_bluerov2_turns_right_on_a_forward_stick(
    pair: tuple[SimGcs, SimGcs],
) -> None:
    """ArduSub's motor-1 factors (yaw +1, forward −1, lateral +1): reversed, a forward stick
    yaws the physics truth right and slides it right at a fraction of the forward speed; with
    the layout's direction the same stick flies straight ahead."""
    default, flipped = pair
    flipped.send(flipped.param_set("MOT_1_DIRECTION", -boot_direction(flipped, 1)))
    yaw, rate, sway, surge = {}, {}, {}, {}
    for name, gcs in (("default", default), ("flipped", flipped)):
        arm_in_manual(gcs)
        gcs.run(2.0, gcs.flying(x=1000))
        truth = gcs.vehicle.truth
        yaw[name] = np.degrees(euler_from_quat(tuple(truth.quaternion_wxyz))[2])
        rate[name] = truth.rates_rad_s[2]
        surge[name], sway[name] = truth.velocity_m_s[0], truth.velocity_m_s[1]
    assert abs(yaw["default"]) < 1.0 and abs(rate["default"]) < 0.01
    assert surge["default"] > 0.2 and abs(sway["default"]) < 0.02
    assert yaw["flipped"] > 20.0 and rate["flipped"] > 0.2  # right, clockwise from above
    assert sway["flipped"] > 0.0 and 0.0 < surge["flipped"] < surge["default"]


def test_a_motor_test_is_not_mixed_so_mot_n_direction_does_not_change_it(
    pair: tuple[SimGcs, SimGcs],
) -> None:
    """DO_MOTOR_TEST motor 1 at 1700 µs with MOT_1_DIRECTION flipped: ArduSub's
    ``output_test_num`` writes 1700 µs, so the thruster pushes the T200 table's force for
    1700 µs, as with the layout's direction."""
    default, flipped = pair
    flipped.send(flipped.param_set("MOT_1_DIRECTION", -boot_direction(flipped, 1)))
    test = default.command(mav.MAV_CMD_DO_MOTOR_TEST, 0, 1, 1700, 0, 0, 2)
    for gcs in pair:
        arm_in_manual(gcs)

        def each(k: int, gcs: SimGcs = gcs) -> list[Any]:
            return [*gcs.flying()(k), *([test] if k % 5 == 0 else [])]

        gcs.run(0.5, each)
    layout = flipped.vehicle.thruster_config
    motor1 = layout.ardusub_motor_columns[0]
    t200 = T200.from_table(flipped.vehicle.config.supply_voltage_v)
    force = t200.force_for_pwm(1700.0, layout.thrusters[motor1].handedness)
    for gcs in pair:
        assert output(gcs).pwm_us[motor1] == 1700.0
        assert output(gcs).forces_n[motor1] == pytest.approx(force)


def test_with_the_layouts_directions_a_flight_is_unchanged() -> None:
    """A flight with MOT_n_DIRECTION acting and the layout's directions (one of them set again
    to its own value) is the flight of a vehicle without it, frame for frame."""
    plain, acting = SimGcs(), SimGcs()
    try:
        install_motor_directions(acting.vehicle, acting.endpoint)
        acting.send(acting.param_set("MOT_3_DIRECTION", boot_direction(acting, 3)))
        plain.send(plain.param_set("MOT_3_DIRECTION", boot_direction(plain, 3)))
        trace: dict[str, list[Any]] = {"plain": [], "acting": []}
        for name, gcs in (("plain", plain), ("acting", acting)):
            gcs.send(gcs.heartbeat(), gcs.arm(), gcs.set_mode(2))
            for k in range(300):
                gcs.send(*gcs.flying(x=600, z=300)(k))
                gcs.step()
                trace[name].append((output(gcs), tuple(gcs.vehicle.truth.position_ned_m)))
        assert trace["plain"] == trace["acting"]
        assert any(f != 0.0 for f in trace["acting"][-1][0].forces_n)
    finally:
        plain.close()
        acting.close()


@pytest.mark.parametrize("where", ["mavlink", "mavlink-raw"])
def test_the_runs_vehicles_act_on_it(where: str) -> None:
    """The vehicles the runs build behind an endpoint (``testbed mavlink``'s node, the raw
    MAVLink link's vehicle) act on MOT_n_DIRECTION: set on the endpoint, motor 1's pulse is
    mirrored against the same vehicle's pulse a frame before the set."""
    scenario = load_scenario("s100-mavlink-raw-v1", list(NO_VEHICLE_FAILSAFE))
    env = simpy.Environment()
    if where == "mavlink":
        node = MavlinkVehicleNode(env, scenario, np.random.default_rng(0), [], Recorder())
        vehicle, endpoint = node.vehicle, node.endpoint
    else:
        from testbed.vehicle.vehicle import Vehicle

        vehicle = Vehicle(scenario.vehicle, np.random.default_rng(0))
        endpoint = RawMavlinkVehicleLink(vehicle).endpoint
    try:
        endpoint.request_arm(True, 0.0)
        endpoint.rc.channels[4] = 1700  # forward
        endpoint.write_sticks(0.0)
        vehicle.advance(0.5)
        motor1 = vehicle.thruster_config.ardusub_motor_columns[0]
        before = vehicle.world.get(vehicle.entity, ThrusterOutput)
        assert before is not None and before.pwm_us[motor1] != 1500.0
        endpoint.params.set("MOT_1_DIRECTION", -endpoint.params["MOT_1_DIRECTION"])
        vehicle.advance(vehicle.time_s + 0.011)  # one frame, the sticks held
        after = vehicle.world.get(vehicle.entity, ThrusterOutput)
        assert after is not None
        assert after.pwm_us[motor1] - 1500.0 == pytest.approx(
            -(before.pwm_us[motor1] - 1500.0), abs=2.0
        )
    finally:
        vehicle.close()
