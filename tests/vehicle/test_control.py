"""testbed.vehicle.control: quaternions, swing–twist error, PID, depth/attitude hold, pilot."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from testbed.config import ConfigError, build
from testbed.vehicle.control import (
    PID,
    AttitudeController,
    AttitudeGains,
    DepthController,
    FailsafeConfig,
    PidGains,
    PilotGains,
    attitude_error,
    euler_from_quat,
    failsafe_level,
    pilot_wrench,
    quat_conjugate,
    quat_from_axis_angle,
    quat_from_euler,
    quat_multiply,
    quat_normalize,
    quat_rotate,
    quat_rotate_inverse,
    shape_stick,
    twist_angle,
    wrap_angle,
    yaw_only,
)

angles = st.floats(-math.pi, math.pi, allow_nan=False)
small = st.floats(-1.2, 1.2, allow_nan=False)


def scipy_rot(q: tuple[float, float, float, float]) -> Rotation:
    return Rotation.from_quat([q[1], q[2], q[3], q[0]])


unit_quats = st.tuples(*[st.floats(-1, 1, allow_nan=False)] * 4).filter(
    lambda v: sum(x * x for x in v) > 0.01
)


# ------------------------------------------------------------------------- quaternions


@settings(max_examples=60, deadline=None)
@given(angles, st.floats(-1.5, 1.5), angles)
def test_euler_matches_scipy_zyx(roll: float, pitch: float, yaw: float) -> None:
    q = quat_from_euler(roll, pitch, yaw)
    expected = Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_matrix()
    np.testing.assert_allclose(scipy_rot(q).as_matrix(), expected, atol=1e-12)
    # angles compare on the circle: ±π are the same heading (atan2 may return either)
    difference = np.asarray(euler_from_quat(q)) - (roll, pitch, yaw)
    np.testing.assert_allclose(np.angle(np.exp(1j * difference)), 0.0, atol=1e-9)


@settings(max_examples=60, deadline=None)
@given(unit_quats, unit_quats, st.tuples(*[st.floats(-5, 5)] * 3))
def test_product_and_rotation_match_scipy(a: tuple, b: tuple, v: tuple) -> None:
    qa, qb = quat_normalize(a), quat_normalize(b)
    ra, rb = scipy_rot(qa), scipy_rot(qb)
    np.testing.assert_allclose(
        scipy_rot(quat_multiply(qa, qb)).as_matrix(), (ra * rb).as_matrix(), atol=1e-12
    )
    np.testing.assert_allclose(quat_rotate(qa, v), ra.apply(v), atol=1e-12)
    np.testing.assert_allclose(quat_rotate_inverse(qa, v), ra.inv().apply(v), atol=1e-12)


def test_normalize_rejects_zero() -> None:
    with pytest.raises(ValueError):
        quat_normalize((0.0, 0.0, 0.0, 0.0))


@pytest.mark.parametrize(
    ("angle", "expected"),
    [(0.0, 0.0), (math.pi, math.pi), (-math.pi, math.pi), (3 * math.pi / 2, -math.pi / 2)],
)
def test_wrap_angle(angle: float, expected: float) -> None:
    assert wrap_angle(angle) == pytest.approx(expected)


# ------------------------------------------------------------------- attitude error


def mate_rov_twist(q: tuple, axis: np.ndarray) -> float:
    """mate-rov's instant_twist, transcribed: project, renormalise, sign, 2·acos(w), wrap."""
    v = np.array(q[1:])
    sign = np.sign(v @ axis) or 1.0
    proj = (v @ axis) * axis
    tw = np.array([q[0], *proj])
    tw = tw / np.linalg.norm(tw) * sign
    angle = 2.0 * math.acos(max(-1.0, min(1.0, tw[0])))
    return (angle + math.pi) % (2 * math.pi) - math.pi


@settings(max_examples=100, deadline=None)
@given(unit_quats, unit_quats)
def test_attitude_error_equals_swing_twist_on_rotated_axes(t: tuple, c: tuple) -> None:
    target, current = quat_normalize(t), quat_normalize(c)
    q_err = quat_multiply(target, quat_conjugate(current))
    errors = attitude_error(target, current)
    for i in range(3):
        axis = np.array(quat_rotate(current, np.eye(3)[i]))
        assert twist_angle(q_err, axis) == pytest.approx(errors[i], abs=1e-9)
        if math.hypot(q_err[0], float(np.dot(q_err[1:], axis))) < 1e-6:
            continue  # a half-turn swing about a perpendicular axis: the twist is undefined
        reference = mate_rov_twist(q_err, axis)
        # ±π are the same rotation
        assert abs(wrap_angle(errors[i] - reference)) < 1e-6


@settings(max_examples=60, deadline=None)
@given(unit_quats, st.integers(0, 2), st.floats(-3.0, 3.0))
def test_single_axis_offset_is_recovered(c: tuple, axis: int, delta: float) -> None:
    current = quat_normalize(c)
    unit = [0.0, 0.0, 0.0]
    unit[axis] = 1.0
    target = quat_multiply(current, quat_from_axis_angle(unit, delta))  # body-axis rotation
    errors = attitude_error(target, current)
    expected = [0.0, 0.0, 0.0]
    expected[axis] = delta
    np.testing.assert_allclose(errors, expected, atol=1e-9)


def test_yaw_error_sign_is_a_positive_yaw_torque() -> None:
    # target heading 10° clockwise from above (NED yaw +10°): need +N (FRD) torque
    errors = attitude_error(quat_from_euler(0, 0, math.radians(10)), (1.0, 0.0, 0.0, 0.0))
    assert math.degrees(errors[2]) == pytest.approx(10.0)
    # the long way round wraps to the short way
    errors = attitude_error(quat_from_euler(0, 0, math.radians(170)), quat_from_euler(0, 0, -3.0))
    assert math.degrees(errors[2]) == pytest.approx(170 - math.degrees(-3.0) - 360)


# ------------------------------------------------------------------------------- PID


def test_pi_with_constant_error_integrates_linearly() -> None:
    pid = PID(PidGains(kp=2.0, ki=0.5))
    for _ in range(100):
        out = pid.update(1.5, 0.01)
    assert out == pytest.approx(2.0 * 1.5 + 0.5 * 1.5 * 1.0)


def test_integral_clamp_output_clamp_and_i_zone() -> None:
    pid = PID(PidGains(ki=1.0, max_integral=0.2, anti_windup="clamp"))
    for _ in range(100):
        pid.update(1.0, 0.01)
    assert pid.integral == pytest.approx(0.2)
    pid = PID(PidGains(kp=10.0, max_output=3.0))
    assert pid.update(1.0, 0.01) == 3.0
    assert pid.update(-1.0, 0.01) == -3.0
    pid = PID(PidGains(ki=1.0, i_zone=0.5))
    for _ in range(10):
        pid.update(0.4, 0.1)
    assert pid.integral == pytest.approx(0.4)
    pid.update(0.6, 0.1)  # outside the zone: cleared
    assert pid.integral == 0.0


def test_derivative_low_pass_is_first_order() -> None:
    dt, tau = 0.01, 0.05
    pid = PID(PidGains(kd=1.0, derivative_tau_s=tau))
    pid.update(0.0, dt, error_rate=0.0)
    alpha = dt / (tau + dt)
    for n in range(1, 30):
        out = pid.update(0.0, dt, error_rate=1.0)
        assert out == pytest.approx(1.0 - (1.0 - alpha) ** n)


def test_derivative_from_differenced_error() -> None:
    pid = PID(PidGains(kd=2.0))
    assert pid.update(1.0, 0.1) == 0.0  # no history yet: no kick
    assert pid.update(1.5, 0.1) == pytest.approx(2.0 * 5.0)
    pid.reset()
    assert pid.update(3.0, 0.1) == 0.0


def test_anti_windup_modes() -> None:
    gains = {"kp": 2.0, "ki": 1.0, "max_output": 1.0}  # kp·e alone saturates for e = 1
    clamp = PID(PidGains(**gains, anti_windup="clamp"))
    conditional = PID(PidGains(**gains, anti_windup="conditional"))
    back = PID(PidGains(**gains, anti_windup="back_calculation", tracking_time_s=0.2))
    for _ in range(1000):
        for pid in (clamp, conditional, back):
            pid.update(1.0, 0.01)
    assert clamp.integral == pytest.approx(10.0)
    assert conditional.integral == 0.0
    # back-calculation equilibrium: e + (limit − kp e − ki I)/(Tt ki) = 0
    assert back.integral == pytest.approx((1.0 - 2.0) / 1.0 + 1.0 * 0.2, abs=1e-6)
    # reversing the error: conditional leaves saturation at once, clamp stays wound up
    assert conditional.update(-0.1, 0.01) < 0.0
    assert clamp.update(-0.1, 0.01) == 1.0


def test_pid_rejects_bad_dt_and_config_checks() -> None:
    with pytest.raises(ValueError):
        PID(PidGains(kp=1.0)).update(1.0, 0.0)
    with pytest.raises(ConfigError, match="max_output"):
        build(PidGains, {"kp": 1.0, "max_output": -1.0})
    assert build(PidGains, {"max_output": math.inf}).max_output == math.inf


def test_pi_rejects_constant_disturbance_on_first_order_plant() -> None:
    # v̇ = (u + d − c v)/m; PI on speed reaches the setpoint exactly despite d
    m, c, d, dt = 20.0, 5.0, -3.0, 0.01
    pid = PID(PidGains(kp=40.0, ki=20.0, max_integral=100.0))
    v = 0.0
    for _ in range(3000):
        u = pid.update(0.5 - v, dt)
        v += dt * (u + d - c * v) / m
    assert v == pytest.approx(0.5, abs=1e-4)
    assert pid.i == pytest.approx(c * 0.5 - d, rel=1e-3)


# ---------------------------------------------------------------- attitude / depth


def test_attitude_controller_torque_signs_and_disabled_axis() -> None:
    gains = PidGains(kp=0.5)
    ctrl = AttitudeController(AttitudeGains(roll=gains, pitch=gains, yaw=gains))
    target = quat_from_euler(math.radians(4), math.radians(-2), math.radians(10))
    torque = ctrl.update(target, (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.01)
    errors = [math.degrees(e) for e in attitude_error(target, (1.0, 0.0, 0.0, 0.0))]
    np.testing.assert_allclose(torque, [0.5 * e for e in errors])
    assert torque[0] > 0 and torque[1] < 0 and torque[2] > 0
    torque = ctrl.update(target, (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.01, (True, False, True))
    assert torque[1] == 0.0


def test_attitude_derivative_uses_gyro_and_target_rate() -> None:
    ctrl = AttitudeController(AttitudeGains(yaw=PidGains(kd=1.0)))
    level = (1.0, 0.0, 0.0, 0.0)
    # body yawing at +0.1 rad/s towards a fixed target: d(error)/dt = −0.1 rad/s
    torque = ctrl.update(level, level, (0.0, 0.0, 0.1), 0.01)
    assert torque[2] == pytest.approx(-math.degrees(0.1))
    # target yawing at 0.2 rad/s, body still: +0.2 rad/s
    ctrl.reset()
    ctrl.update(level, level, (0.0, 0.0, 0.0), 0.01)
    moved = quat_from_euler(0.0, 0.0, 0.002)
    torque = ctrl.update(moved, level, (0.0, 0.0, 0.0), 0.01)
    assert torque[2] == pytest.approx(math.degrees(0.2), rel=1e-6)


def test_attitude_loop_settles_a_rigid_body() -> None:
    # J ω̇ = τ − c ω about yaw; mate-rov 2025 yaw gains stabilise a 0.28 kg·m² body
    j, c, dt = 0.28, 0.07, 0.01
    ctrl = AttitudeController(
        AttitudeGains(
            yaw=PidGains(kp=0.3, ki=0.01, kd=0.05, max_integral=10, max_output=5, i_zone=5)
        )
    )
    yaw, rate = 0.0, 0.0
    target = quat_from_euler(0.0, 0.0, math.radians(30))
    for _ in range(2000):
        q = quat_from_euler(0.0, 0.0, yaw)
        tau = ctrl.update(target, q, (0.0, 0.0, rate), dt)[2]
        rate += dt * (tau - c * rate) / j
        yaw += dt * rate
    assert math.degrees(yaw) == pytest.approx(30.0, abs=0.1)


def test_depth_force_is_world_vertical_in_body_frame() -> None:
    ctrl = DepthController(PidGains(kp=100.0), feedforward_n=-2.0)
    level = (1.0, 0.0, 0.0, 0.0)
    np.testing.assert_allclose(ctrl.update(1.0, 0.8, level, 0.01), (0.0, 0.0, 18.0), atol=1e-12)
    rolled = quat_from_euler(math.radians(90), 0.0, 0.3)  # starboard side down
    force = ctrl.update(1.0, 0.8, rolled, 0.01)
    np.testing.assert_allclose(force, (0.0, 18.0, 0.0), atol=1e-9)
    tilted = quat_from_euler(0.2, -0.4, 1.0)
    world = quat_rotate(tilted, ctrl.update(0.5, 0.8, tilted, 0.01))
    np.testing.assert_allclose(world, (0.0, 0.0, -32.0), atol=1e-9)  # too deep: push up


# ----------------------------------------------------------------------------- pilot


def test_shape_stick_cubic_and_dead_zone() -> None:
    assert shape_stick(0.5, 0.8) == pytest.approx(0.1)
    assert shape_stick(-0.5, 0.3) == pytest.approx(-0.0375)
    assert shape_stick(2.0, 0.8) == pytest.approx(0.8)
    assert shape_stick(0.04, 0.8, dead_zone=0.05) == 0.0


def test_pilot_wrench_scales_by_axis_maxima_and_gains() -> None:
    maxima = (73.9, 59.0, 72.8, 6.3, 0.0, 17.7)
    sticks = (1.0, -0.5, 0.5, 1.0, 1.0, -1.0)
    w = pilot_wrench(sticks, maxima, (1.0, 0.0, 0.0, 0.0), gains=PilotGains())
    expected = (0.8 * 73.9, -0.1 * 59.0, 0.1 * 72.8, 0.8 * 6.3, 0.0, -0.8 * 17.7 * 0.5)
    np.testing.assert_allclose(w, expected)
    held = pilot_wrench(
        sticks, maxima, (1.0, 0.0, 0.0, 0.0), gains=PilotGains(), attitude_hold=True
    )
    assert held[3:] == (0.0, 0.0, 0.0)


def test_depth_hold_translation_uses_the_yaw_only_frame() -> None:
    maxima = (50.0, 50.0, 50.0, 5.0, 5.0, 10.0)
    attitude = quat_from_euler(math.radians(10), math.radians(25), math.radians(60))
    w = pilot_wrench(
        (1.0, 0.0, 1.0, 0, 0, 0), maxima, attitude, gains=PilotGains(), depth_hold=True
    )
    world = quat_rotate(attitude, w[:3])
    heading = quat_rotate(yaw_only(attitude), (0.8 * 50.0, 0.0, 0.1 * 0.8 * 50.0))
    np.testing.assert_allclose(world, heading, atol=1e-9)
    precise = pilot_wrench(
        (0.0, 0.0, 1.0, 0, 0, 0),
        maxima,
        attitude,
        gains=PilotGains(),
        depth_hold=True,
        precision=True,
    )
    np.testing.assert_allclose(precise[:3], 0.0, atol=1e-12)


# -------------------------------------------------------------------------- failsafe


def test_failsafe_levels_and_config_checks() -> None:
    cfg = FailsafeConfig(hold_after_s=0.5, surface_after_s=3.0)
    assert [failsafe_level(a, cfg) for a in (0.0, 0.49, 0.5, 2.9, 3.0, 100.0)] == [
        0,
        0,
        1,
        1,
        2,
        2,
    ]
    with pytest.raises(ConfigError, match="surface_after_s"):
        build(FailsafeConfig, {"hold_after_s": 2.0, "surface_after_s": 1.0})
