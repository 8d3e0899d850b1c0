"""testbed.vehicle.control: PID, depth/attitude hold, pilot, failsafe (rotations: test_geometry)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from testbed.common.geometry import attitude_error, quat_from_euler, quat_rotate, yaw_only
from testbed.config import ConfigError, build
from testbed.vehicle.control import (
    PID,
    AttitudeController,
    AttitudeGains,
    DepthController,
    FailsafeConfig,
    PidGains,
    failsafe_level,
)
from testbed.vehicle.pilot import PilotGains, pilot_trims, pilot_wrench, shape_stick

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


def test_a_held_setpoint_feeds_its_mean_rate_forward_not_spikes() -> None:
    # a yaw ramp at 0.2 rad/s sampled at 40 Hz, seen by a 100-Hz loop: the target steps by
    # 5 mrad every 2 or 3 frames; kd = 1 with the body still makes the yaw output the target
    # rate fed forward [deg/s]
    ctrl = AttitudeController(AttitudeGains(yaw=PidGains(kd=1.0, max_output=1e9)))
    level = (1.0, 0.0, 0.0, 0.0)
    omega, dt = 0.2, 0.01
    outputs = []
    for frame in range(231):  # the ramp for 2 s, then held still for 0.3 s
        sampled = min(2.0, math.floor(frame * dt * 40.0 + 1e-9) / 40.0)  # last 40-Hz sample
        target = quat_from_euler(0.0, 0.0, omega * sampled)
        outputs.append(ctrl.update(target, level, (0.0, 0.0, 0.0), dt)[2])
    fed = np.radians(outputs)
    # it adds up to the ramp's angle (closed form: ω·2 s, as rotation vectors of the 80
    # 5-mrad steps) and stops once the target does
    steps = 80 * 2.0 * math.sin(omega * 0.025 / 2.0)
    assert np.sum(fed) * dt == pytest.approx(steps, rel=0.025)  # 1.8 % over: the held rates
    assert np.all(fed[210:] == 0.0)
    # once the mean interval has settled, every frame of the ramp feeds a rate within 10 % of
    # ω; one frame's difference gives 2.5 ω on the frames the target stepped and 0 between
    assert np.all(np.abs(fed[20:200] - omega) <= 0.1 * omega)


def test_a_lone_step_after_a_still_spell_kicks_little_and_stops() -> None:
    ctrl = AttitudeController(AttitudeGains(yaw=PidGains(kd=1.0, max_output=1e9)))
    level = (1.0, 0.0, 0.0, 0.0)
    for _ in range(100):  # 1 s still
        ctrl.update(level, level, (0.0, 0.0, 0.0), 0.01)
    step = quat_from_euler(0.0, 0.0, math.radians(10.0))
    fed = [ctrl.update(step, level, (0.0, 0.0, 0.0), 0.01)[2] for _ in range(30)]
    # the step as a rotation vector (2·sin(5°) rad) spread over MAX_TARGET_RATE_HOLD_S
    # (0.25 s, not the 1 s since the first target): 25 frames of it, then nothing
    rate = math.degrees(2.0 * math.sin(math.radians(5.0))) / 0.25
    np.testing.assert_allclose(fed[:25], rate, rtol=1e-9)
    assert fed[25:] == [0.0] * 5


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


def test_pilot_trims_are_cubic_stick_times_the_full_stick_rates() -> None:
    gains = PilotGains()
    sticks = (0.0, 0.0, 0.5, -1.0, 0.04, 0.5)  # pitch inside the 0.05 dead zone
    depth, roll, pitch, yaw = pilot_trims(sticks, gains=gains)
    assert depth == pytest.approx(0.125 * 0.3)  # 0.5³ of 0.3 m/s
    assert roll == pytest.approx(-math.radians(35.0))
    assert pitch == 0.0
    assert yaw == pytest.approx(0.125 * math.radians(100.0))
    precise = pilot_trims(sticks, gains=gains, precision=True)
    assert precise[0] == pytest.approx(0.125 * 0.2)
    assert precise[3] == pytest.approx(0.125 * math.radians(60.0))


def test_the_compiled_pilot_shape_gives_the_python_laws_bits() -> None:
    """The pilot interface's kernel (:func:`pilot_shape`, the laws compiled) against the same
    laws run by CPython (two implementations of the IEEE operations), over random sticks, every
    mode, and gains written with whole numbers."""
    from testbed.vehicle.control_kernels import pilot_shape
    from testbed.vehicle.pilot import pilot_gains_array, pilot_level_wrench

    rng = np.random.default_rng(5)
    maxima = (80.0, 80.0, 120.0, 0.0, 12.0, 20.0)
    for gains in (PilotGains(), PilotGains(translation=(1, 2, 1), dead_zone=0, normal_scale=1)):
        for _ in range(50):
            sticks = tuple(float(v) for v in rng.uniform(-1.3, 1.3, 6))
            modes = tuple(bool(b) for b in rng.integers(0, 2, 3))
            precision, depth_hold, attitude_hold = modes
            wrench, trims = pilot_shape(sticks, maxima, pilot_gains_array(gains), *modes)
            assert wrench == pilot_level_wrench(
                sticks,
                maxima,
                gains=gains,
                precision=precision,
                depth_hold=depth_hold,
                attitude_hold=attitude_hold,
            )
            assert trims == pilot_trims(sticks, gains=gains, precision=precision)
            assert all(type(v) is float for v in (*wrench, *trims))


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


def test_the_yaw_trim_never_takes_the_heading_target_past_its_lead_limit() -> None:
    """trim_targets turns the heading target by the yaw trim unless that takes it more than
    MAX_HEADING_LEAD_RAD ahead of the measured heading; turning back is always allowed; the
    lead is the rotation about world down, so near ±90° of pitch (where the Euler yaw is
    undefined) a small real lead is a small lead. Truth: Euler yaws of level attitudes, and
    attitudes built by a rotation about world down."""
    from testbed.common.geometry import euler_from_quat, quat_from_axis_angle, quat_multiply
    from testbed.vehicle.pilot import MAX_HEADING_LEAD_RAD, trim_targets

    step = math.radians(1.0)
    limit = MAX_HEADING_LEAD_RAD
    measured = quat_from_euler(0.0, 0.0, 0.3)

    def turned(lead_rad: float, rate: float, now: tuple[float, ...] = measured) -> float:
        """How far one 1-s trim at ``rate`` [rad/s] turned a target ``lead_rad`` ahead."""
        target = quat_multiply(quat_from_axis_angle((0.0, 0.0, 1.0), lead_rad), now)
        _, q = trim_targets(1.0, target, (0.0, 0.0, 0.0, rate), 1.0, False, True, now)
        before, after = euler_from_quat(target)[2], euler_from_quat(q)[2]
        return math.remainder(after - before, math.tau)

    assert turned(limit - 2 * step, step) == pytest.approx(step)  # within the limit: turns
    assert turned(limit - 0.5 * step, step) == pytest.approx(0.0, abs=1e-12)  # waits
    assert turned(limit + 10 * step, -step) == pytest.approx(-step)  # back towards it: turns
    assert turned(-(limit - 0.5 * step), -step) == pytest.approx(0.0, abs=1e-12)  # left too
    nose_up = quat_from_euler(0.0, math.radians(89.5), 0.3)  # the Euler yaw is ill-defined
    target = quat_multiply(quat_from_axis_angle((0.0, 0.0, 1.0), math.radians(2.0)), nose_up)
    _, q = trim_targets(1.0, target, (0.0, 0.0, 0.0, step), 1.0, False, True, nose_up)
    expected = quat_multiply(quat_from_axis_angle((0.0, 0.0, 1.0), step), target)
    assert np.allclose(q, expected, atol=1e-12) or np.allclose(q, [-c for c in expected])
