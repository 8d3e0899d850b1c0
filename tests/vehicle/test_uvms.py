"""The vehicle-manipulator system end to end: ISMC + TPIK in closed loop, determinism, camera.

Scenarios ``uvms-station-keeping-v1`` and ``uvms-waypoint-v1`` (BlueROV2 Heavy + the
Reach-Alpha-5-like arm, current, model mismatch, arm coupling on), shortened. The independent
truths: the end effector's position from the arm's numpy FK on the physics truth (pose and
pybullet's joint angles), the mission's published goal tolerance, the open-loop drift of the
same arm on a free hull (momentum, measured here by the plant alone), byte equality of two
runs, and the pinhole projection of the arm's links into the forward camera.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray

from testbed.run.outputs import write_run
from testbed.run.runner import run_scenario
from testbed.run.scenario import load_scenario
from testbed.run.scenario_config import Scenario
from testbed.vehicle.arm import load_arm_model
from testbed.vehicle.arm_kinematics import end_effector_ned, link_centres_body
from testbed.vehicle.camera import CameraConfig, camera_pose
from testbed.vehicle.hydrodynamics import load_model
from testbed.vehicle.manipulation import EndEffectorTarget
from testbed.vehicle.physics import Physics
from testbed.vehicle.vehicle import Vehicle

FloatArray = NDArray[np.float64]
DT_S = 1.0 / 240.0
NO_LINK_FAILSAFE = ["vehicle.failsafe.hold_after_s=86000", "vehicle.failsafe.surface_after_s=86400"]
ARM_RGB = (0.85, 0.85, 0.8)


def ee_series(series: dict[str, FloatArray]) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Time, the end effector's truth and its target (rows with a target, armed)."""
    truth = np.column_stack([series["ee_n"], series["ee_e"], series["ee_d"]])
    target = np.column_stack([series["ee_target_n"], series["ee_target_e"], series["ee_target_d"]])
    rows = (series["armed"] > 0.5) & np.isfinite(target).all(axis=1)
    return series["t_s"][rows], truth[rows], target[rows]


def open_loop_ee_drift_m() -> float:
    """The tool point's displacement [m] caused by the free hull's motion (zero thrust, trim
    and coupling on) while axis_e turns at its limit for 2 s: the final joints' FK on the moved
    hull minus the same FK on the hull where it started."""
    arm = load_arm_model()
    with Physics(load_model("bluerov2-heavy"), arm=arm, start_position_ned=(0.0, 0.0, 5.0)) as sim:
        _, p0, q0, _ = sim.state_floats()
        sim.command_arm([arm.joints[0].velocity_rad_s, 0.0, 0.0, 0.0])
        for _ in range(round(2.0 / DT_S)):
            sim.step((0.0,) * 6)
        _, p1, q1, _ = sim.state_floats()
        joints = sim.arm_state()[0]
    moved, _ = end_effector_ned(arm, joints, p1, q1)
    still, _ = end_effector_ned(arm, joints, p0, q0)
    return float(np.linalg.norm(moved - still))


# --- closed loop --------------------------------------------------------------------------


def test_ismc_holds_the_end_effector_far_better_than_the_open_loop_drift() -> None:
    """Truth: the mission tree's goal tolerance (0.2 m, Angler) and the open-loop drift. The
    station-keeping scenario, 20 s, one trial, through the runner: every armed sample's
    end-effector error (the approach included) is inside the goal tolerance; after the 10 s
    settle its mean is below a fifth, and its maximum below 0.3, of the 2-s open-loop drift of
    the tool point on the free hull (axis_e at its limit, no control)."""
    scenario = load_scenario(
        "uvms-station-keeping-v1", ["duration_s=20", "trials=1", "metrics.settle_s=10"]
    )
    result = run_scenario(scenario)
    t, truth, target = ee_series(result.recorder.series())
    error = np.linalg.norm(truth - target, axis=1)
    settled = error[t >= 10.0]
    assert settled.size >= 150  # 20 Hz over the last 10 s
    tolerance = scenario.vehicle.autonomy.tree.goal_tolerance_m
    drift = open_loop_ee_drift_m()
    assert error.max() < tolerance
    assert settled.mean() < 0.2 * drift
    assert settled.max() < 0.3 * drift
    assert result.metrics["mission"]["goals_reached"] == 1


def test_waypoint_leg_reaches_its_target_and_the_tpik_moves_the_joints() -> None:
    """Truth: the arm's numpy FK on the physics truth (pose, pybullet's joint angles) against
    the mission's waypoint and goal tolerance. The waypoint scenario's vehicle, built directly
    (no link: its failsafe off), flown 40 s: the TPIK solves at its 30 Hz, the end effector
    tracks the moving target within the tolerance throughout and ends within 5 cm of (1, 1,
    0.5) m; the joints really move: axis_d swings both ways, over > 0.04 rad (a joint merely
    sagging under load would drift one way)."""
    scenario = load_scenario("uvms-waypoint-v1", NO_LINK_FAILSAFE)
    tolerance = scenario.vehicle.autonomy.tree.goal_tolerance_m
    with Vehicle(scenario.vehicle, np.random.default_rng(0)) as v:
        arm = v.manipulator
        assert arm is not None
        q0 = np.array(arm.q_rad)
        joints, errors = [], []
        for k in range(1, 401):
            v.advance(0.1 * k)
            _, position, quaternion, _ = v.physics.state_floats()
            q = v.physics.arm_state()[0]
            joints.append(q)
            target = v.world.get(v.entity, EndEffectorTarget)
            if target is not None:
                ee, _ = end_effector_ned(arm.model, q, position, quaternion)
                errors.append(float(np.linalg.norm(ee - np.asarray(target.position_ned_m))))
        final = np.linalg.norm(ee - np.array([1.0, 1.0, 0.5]))
        solves = arm.solves
    assert len(errors) > 380  # the target is flown from the mission's start (1 s) on
    assert max(errors) < tolerance
    assert final < 0.05
    assert solves >= 0.95 * 30.0 * 39.0
    swing = np.array(joints)[:, 1] - q0[1]
    assert swing.min() < -0.01 and swing.max() > 0.01
    assert swing.max() - swing.min() > 0.04


# --- determinism --------------------------------------------------------------------------


def short_run(scenario: Scenario, seed: int, out: Path) -> tuple[dict[str, FloatArray], bytes]:
    result = run_scenario(scenario, seed=seed)
    write_run(result, out)
    return result.recorder.series(), (out / "series.csv").read_bytes()


def test_same_seed_gives_byte_identical_series_and_another_seed_differs(tmp_path: Path) -> None:
    """Truth: byte equality. The station-keeping scenario shortened to 6 s (TPIK flying from
    1 s) twice with seed 0: every series column and series.csv identical byte for byte; seed
    1 (other sensor noise and current): the end-effector columns differ."""
    scenario = load_scenario(
        "uvms-station-keeping-v1", ["duration_s=6", "trials=1", "metrics.settle_s=2"]
    )
    first, first_csv = short_run(scenario, 0, tmp_path / "a")
    second, second_csv = short_run(scenario, 0, tmp_path / "b")
    other, other_csv = short_run(scenario, 1, tmp_path / "c")
    assert first.keys() == second.keys()
    for key in first:
        assert first[key].tobytes() == second[key].tobytes(), key
    assert first_csv == second_csv
    assert other_csv != first_csv
    assert first["ee_n"].tobytes() != other["ee_n"].tobytes()
    assert np.isfinite(first["ee_target_n"]).any()


# --- camera -------------------------------------------------------------------------------


def project(camera: CameraConfig, point_frd: FloatArray) -> tuple[int, int]:
    """The rendered pixel (row, column) of a body point (FRD, from CO): the pinhole model of
    the camera (x right, y down, z along the axis pitched down by the mount pitch), at the
    renderer's supersampled size."""
    pitch = np.radians(camera.mount_pitch_deg)
    forward = np.array([np.cos(pitch), 0.0, np.sin(pitch)])
    down = np.array([-np.sin(pitch), 0.0, np.cos(pitch)])
    d = point_frd - np.asarray(camera.mount_position_m)
    x, y, z = d[1], float(d @ down), float(d @ forward)
    width, height = camera.render_size_px
    f = 0.5 * height / np.tan(np.radians(0.5 * camera.vertical_fov_deg))
    return int(np.floor(0.5 * height + f * y / z)), int(np.floor(0.5 * width + f * x / z))


def test_the_forward_camera_sees_the_arm_reaching_forward() -> None:
    """Truth: the pinhole projection of the arm's links (numpy FK) and the arm's paint. At the
    initial (forward-reaching) pose the arm is in the default camera's view, near the top
    right: the rendered image with the arm differs from the arm-less one in > 500 rendered
    pixels; there R = G and B/R is the paint's 0.8/0.85 (lighting scales the channels
    alike); the projection of the wrist's centre of volume (the centre of its drawn cylinder)
    falls on such pixels, and the forearm's projects above the image, where the changed pixels
    leave through the top edge."""
    camera = CameraConfig(enabled=True)
    model, arm = load_model("bluerov2-heavy"), load_arm_model()
    images = []
    for with_arm in (None, arm):
        with Physics(model, arm=with_arm, start_position_ned=(0.0, 0.0, 5.0)) as sim:
            _, position, quaternion, _ = sim.state_floats()
            rgb, _ = sim.render(camera_pose(position, quaternion, camera), camera)
            images.append(rgb.astype(float))
    bare, armed = images
    changed = np.any(bare != armed, axis=2)
    assert changed.sum() > 500
    pixels = armed[changed]
    assert np.array_equal(pixels[:, 0], pixels[:, 1])
    lit = pixels[pixels[:, 0] > 20]
    ratio = lit[:, 2] / lit[:, 0]
    assert lit.shape[0] > 0.9 * pixels.shape[0]
    assert np.median(ratio) == pytest.approx(ARM_RGB[2] / ARM_RGB[0], abs=0.01)
    assert np.mean(np.abs(ratio - ARM_RGB[2] / ARM_RGB[0]) < 0.03) > 0.9
    _, cov = link_centres_body(arm, arm.initial_q_rad)
    height, width = changed.shape
    i, j = project(camera, cov[4])  # link_b, the wrist
    assert 0 <= i < height and 0 <= j < width
    assert changed[max(i - 1, 0) : i + 2, max(j - 1, 0) : j + 2].any()
    i, j = project(camera, cov[3])  # link_c, the forearm
    assert i < 0 and 0 <= j < width
    assert changed[0].any()
