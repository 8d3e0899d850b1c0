"""SERVO_OUTPUT_RAW in ArduSub's motor numbering: pymavlink as the ground station on the BlueROV2
(Vectored) and the Heavy (Vectored_6DOF), in simulated time.

The independent truth is ArduSub's mixer as ``AP_Motors6DOF::setup_motors`` (ArduSub 4.5,
``libraries/AP_Motors/AP_Motors6DOF.cpp``) writes it, restated here from that file: motor n's
output is Σ factor × command and its pulse ``1500 + 400 · MOT_n_DIRECTION · output``, so a pure
forward, yaw or up command moves servo n to the side of 1500 µs given by the sign of its factor
times MOT_n_DIRECTION (which the test reads over the parameter protocol, as QGroundControl's
motor page does). The simulated vehicle's allocator and T200 curve set the magnitudes, not the
signs.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator

import numpy as np
import pytest
from pymavlink.dialects.v20 import ardupilotmega as mav

from testbed.config import ConfigError
from testbed.run.mavlink_run import layout_servos
from testbed.vehicle.thruster_config import load_thruster_config
from tests.mavlink.gcs import SimGcs

HEAVY = ("vehicle.thrusters=bluerov2-heavy", "vehicle.model=bluerov2-heavy")
# AP_Motors6DOF::setup_motors factor rows, (yaw, throttle, forward) of motor 1, 2, …
VECTORED = [(1, 0, -1), (-1, 0, -1), (-1, 0, 1), (1, 0, 1), (0, -1, 0), (0, -1, 0)]
VECTORED_6DOF = [*VECTORED[:4], *[(0, -1, 0)] * 4]
# where ArduSub's frame diagrams put motor 1, 2, …: (sign of x, sign of y), body FRD
QUADRANTS = [(1, 1), (1, -1), (-1, 1), (-1, -1)]


@pytest.fixture(params=[("bluerov2", (), VECTORED, 1), ("bluerov2-heavy", HEAVY, VECTORED_6DOF, 2)])
def vehicle(request: pytest.FixtureRequest) -> Iterator[tuple[SimGcs, list[tuple[int, ...]], int]]:
    name, overrides, factors, frame = request.param
    gcs = SimGcs(overrides=overrides)
    assert gcs.vehicle.config.thrusters == name
    yield gcs, factors, frame
    gcs.close()


def read_param(gcs: SimGcs, name: str) -> float:
    gcs.send(gcs.mav.param_request_read_encode(1, 1, name.encode(), -1))
    gcs.step()
    return float(next(m for m in reversed(gcs.of("PARAM_VALUE")) if m.param_id == name).param_value)


def servos(gcs: SimGcs) -> list[int]:
    message = gcs.last("SERVO_OUTPUT_RAW")
    return [getattr(message, f"servo{k}_raw") for k in range(1, 17)]


def test_the_packaged_layouts_put_ardusubs_motors_where_its_frame_diagram_does() -> None:
    for name, motors in (("bluerov2", 6), ("bluerov2-heavy", 8)):
        layout = load_thruster_config(name)
        columns = layout.ardusub_motor_columns
        assert len(columns) == motors
        corners = [layout.thrusters[c].position_m for c in columns]
        assert [(int(np.sign(p[0])), int(np.sign(p[1]))) for p in corners[:4]] == QUADRANTS
        if motors == 8:  # the Heavy's verticals: front-right, front-left, back-right, back-left
            assert [(int(np.sign(p[0])), int(np.sign(p[1]))) for p in corners[4:]] == QUADRANTS
        else:  # the BlueROV2's: right, left
            assert [int(np.sign(p[1])) for p in corners[4:]] == [1, -1]
    # the standard vehicle's file lists its thrusters in mate-rov's order, not ArduSub's
    assert layout_servos(load_thruster_config("bluerov2")).thrusters[:6] == (1, 0, 3, 2, 4, 5)


def test_a_numbering_that_is_not_ardusubs_is_refused_in_one_line() -> None:
    layout = load_thruster_config("bluerov2")
    assert layout.ardusub is not None
    m = layout.ardusub.motors
    swapped = dataclasses.replace(layout.ardusub, motors=(m[1], m[0], *m[2:]))
    with pytest.raises(ConfigError, match=r"bluerov2: ardusub.motors: motor 1 .* factors"):
        layout_servos(dataclasses.replace(layout, ardusub=swapped))
    short = dataclasses.replace(layout.ardusub, motors=m[:5])
    with pytest.raises(ConfigError, match="FRAME_CONFIG 1 has 6 motors"):
        layout_servos(dataclasses.replace(layout, ardusub=short))
    # a thruster the frame's motors leave out: ArduSub would never drive it
    extra = dataclasses.replace(layout.thrusters[0], name="Spare", pwm_channel=6)
    seven = dataclasses.replace(layout, thrusters=(*layout.thrusters, extra))
    with pytest.raises(ConfigError, match="drives 6 motors, the layout has 7 thrusters"):
        layout_servos(seven)
    # a layout of its own reports its thrusters on their pwm_channel + 1
    six = layout_servos(load_thruster_config("ecs-6dof"))
    assert six.frame_config == 7 and six.directions == ()
    assert six.thrusters[:6] == (0, 1, 5, 2, 3, 4)  # VerticalBackLeft kept channel 2


@pytest.mark.parametrize(
    ("sticks", "axis"),
    [({"x": 1000}, 2), ({"r": 1000}, 0), ({"z": 1000}, 1)],
    ids=["forward", "yaw-right", "up"],
)
def test_servo_n_carries_ardusub_motor_n_on_its_side_of_neutral(
    vehicle: tuple[SimGcs, list[tuple[int, ...]], int], sticks: dict[str, int], axis: int
) -> None:
    gcs, factors, frame = vehicle
    assert read_param(gcs, "FRAME_CONFIG") == frame
    directions = [read_param(gcs, f"MOT_{n}_DIRECTION") for n in range(1, len(factors) + 1)]
    gcs.send(gcs.heartbeat(), gcs.arm())
    gcs.run(0.5, gcs.flying())
    neutral = servos(gcs)
    assert neutral == [1500] * len(factors) + [0] * (16 - len(factors))  # unused outputs: 0

    def each(k: int) -> list[object]:
        return [gcs.mav.manual_control_encode(1, *_axes(sticks), 0)] if k % 4 == 0 else []

    gcs.run(1.0, each)
    pulses = servos(gcs)
    for n, (row, direction) in enumerate(zip(factors, directions, strict=True)):
        expected = int(np.sign(row[axis] * direction))
        if expected:
            assert np.sign(pulses[n] - 1500) == expected, (n + 1, pulses)
            assert 1100 <= pulses[n] <= 1900
        else:  # a motor the command does not use stays near neutral
            assert abs(pulses[n] - 1500) < 40, (n + 1, pulses)
    assert pulses[len(factors) :] == [0] * (16 - len(factors))


def _axes(sticks: dict[str, int]) -> tuple[int, int, int, int]:
    return (sticks.get("x", 0), sticks.get("y", 0), sticks.get("z", 500), sticks.get("r", 0))


def test_the_reported_directions_are_the_propellers(
    vehicle: tuple[SimGcs, list[tuple[int, ...]], int],
) -> None:
    """MOT_n_DIRECTION: +1 where the propeller is CCW (its PWM mirrored), −1 where CW: ArduSub's
    positive output pushes each of these thrusters against its layout ``direction``."""
    gcs, factors, _ = vehicle
    layout = gcs.vehicle.thruster_config
    ccw = [layout.thrusters[c].handedness == "ccw" for c in layout.ardusub_motor_columns]
    directions = [read_param(gcs, f"MOT_{n}_DIRECTION") for n in range(1, len(factors) + 1)]
    assert directions == [1.0 if c else -1.0 for c in ccw]
    assert gcs.last("PARAM_VALUE").param_type == mav.MAV_PARAM_TYPE_INT8
