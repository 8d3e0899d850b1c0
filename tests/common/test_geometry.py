"""testbed.common.geometry, the rotation module, against scipy's Rotation (an independent truth).

Conventions under test: quaternions (w, x, y, z) rotating body FRD vectors into world NED;
Z-Y-X Euler angles (roll, pitch, yaw) [rad]; scipy's quaternions are (x, y, z, w).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from testbed.common.geometry import (
    attitude_error,
    euler_from_quat,
    quat_conjugate,
    quat_from_axis_angle,
    quat_from_euler,
    quat_multiply,
    quat_normalize,
    quat_rotate,
    quat_rotate_inverse,
    rotate,
    rotation_matrix,
    twist_angle,
    wrap_angle,
    yaw_only,
)

angles = st.floats(-math.pi, math.pi, allow_nan=False)


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


@settings(max_examples=60, deadline=None)
@given(unit_quats, st.tuples(*[st.floats(-5, 5)] * 3))
def test_rotation_matrix_matches_scipy_and_quat_rotate(q: tuple, v: tuple) -> None:
    unit = quat_normalize(q)
    rows = rotation_matrix(unit)
    np.testing.assert_allclose(np.array(rows), scipy_rot(unit).as_matrix(), atol=1e-12)
    np.testing.assert_allclose(rotate(rows, v), scipy_rot(unit).apply(v), atol=1e-12)
    np.testing.assert_allclose(rotate(rows, v), quat_rotate(unit, v), atol=1e-12)


def test_yaw_90_points_the_body_forward_axis_east() -> None:
    rows = rotation_matrix(quat_from_euler(0.0, 0.0, math.pi / 2))
    np.testing.assert_allclose(rotate(rows, (1.0, 0.0, 0.0)), (0.0, 1.0, 0.0), atol=1e-15)


def test_euler_pitch_is_clamped_at_the_singularity() -> None:
    # rounding can push 2(wy − zx) just past 1 at pitch +90°; asin must not fail
    q = (math.sqrt(0.5) + 1e-16, 0.0, math.sqrt(0.5) + 1e-16, 0.0)
    assert euler_from_quat(q)[1] == pytest.approx(math.pi / 2)


@settings(max_examples=60, deadline=None)
@given(angles, st.floats(-1.5, 1.5), angles)
def test_yaw_only_keeps_the_scipy_heading(roll: float, pitch: float, yaw: float) -> None:
    heading = yaw_only(quat_from_euler(roll, pitch, yaw))
    expected = Rotation.from_euler("Z", yaw).as_matrix()
    np.testing.assert_allclose(scipy_rot(heading).as_matrix(), expected, atol=1e-12)
