"""The forward camera: pinhole geometry, depth and the underwater blend, scene content, rate.

Independent truths: the pinhole projection computed here from scipy's rotation of the vehicle's
Euler angles (not :func:`camera_pose`), the analytic ray length to a plane, BT.601 weights
written out, Pillow's PNG decoder, and the plant run without scenery for the dynamics.
"""

from __future__ import annotations

import dataclasses
import io
import math

import numpy as np
import pybullet
import pytest
from numpy.typing import NDArray
from PIL import Image
from scipy.spatial.transform import Rotation

from testbed.config import ConfigError, build
from testbed.vehicle.camera import CameraConfig, camera_pose, linear_depth_m, underwater_grey
from testbed.vehicle.hydrodynamics import HydroModel, load_model
from testbed.vehicle.physics import Physics
from testbed.vehicle.scenery import Quad, Scenery, Solid, png_bytes
from testbed.vehicle.vehicle import Vehicle
from testbed.vehicle.vehicle_config import VehicleConfig, load_vehicle_config

# black water and no haze: only lit geometry is non-zero
CLEAR = CameraConfig(
    enabled=True, mount_pitch_deg=0.0, attenuation_per_m=0.0, water_grey=0.0, supersampling=1
)
EYE_DEPTH_M = 10.0  # open water, far from anything


@pytest.fixture(scope="module")
def wu() -> HydroModel:
    return load_model("bluerov2")


def capture(sim: Physics, config: CameraConfig) -> NDArray[np.uint8]:
    _, position, quaternion, _ = sim.state_floats()
    rgb, zbuffer = sim.render(camera_pose(position, quaternion, config), config)
    return underwater_grey(rgb, zbuffer, config)


def pinhole(
    point_ned: tuple[float, float, float],
    position_ned: tuple[float, float, float],
    euler_rad: tuple[float, float, float],
    config: CameraConfig,
) -> tuple[float, float]:
    """(column, row) pixel-index coordinates of a world point, from scipy's rotation."""
    roll, pitch, yaw = euler_rad
    body = Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_matrix()  # FRD → NED
    tilt = math.radians(config.mount_pitch_deg)
    forward = body @ [math.cos(tilt), 0.0, math.sin(tilt)]
    right = body @ [0.0, 1.0, 0.0]
    down = body @ [-math.sin(tilt), 0.0, math.cos(tilt)]
    eye = np.asarray(position_ned) + body @ np.asarray(config.mount_position_m)
    rel = np.asarray(point_ned) - eye
    x, y, z = rel @ right, rel @ down, rel @ forward
    f = 0.5 * config.height_px / math.tan(math.radians(0.5 * config.vertical_fov_deg))
    # continuous coordinates put pixel j's centre at j + 0.5
    return (0.5 * config.width_px + f * x / z - 0.5, 0.5 * config.height_px + f * y / z - 0.5)


def centroid(image: NDArray[np.uint8], threshold: int = 0) -> tuple[float, float]:
    rows, cols = np.nonzero(image > threshold)
    assert rows.size > 0, "nothing visible"
    return (float(cols.mean()), float(rows.mean()))


# --- geometry ---------------------------------------------------------------------------------


MARKER_CASES = [
    # (marker NED, vehicle position NED, vehicle euler, mount pitch deg)
    ((3.0, 0.0, EYE_DEPTH_M), (0.0, 0.0, EYE_DEPTH_M), (0.0, 0.0, 0.0), 0.0),
    ((3.0, 1.0, EYE_DEPTH_M - 0.6), (0.0, 0.0, EYE_DEPTH_M), (0.0, 0.0, 0.0), 0.0),
    ((2.5, -0.9, EYE_DEPTH_M + 1.4), (0.0, 0.0, EYE_DEPTH_M), (0.0, 0.0, 0.0), 20.0),
    ((1.5, 3.5, EYE_DEPTH_M + 0.5), (0.3, 0.2, EYE_DEPTH_M), (0.15, -0.1, 1.0), 20.0),
]


@pytest.mark.parametrize("supersampling", [1, 2])
@pytest.mark.parametrize(("marker", "position", "euler", "tilt_deg"), MARKER_CASES)
def test_a_marker_appears_where_the_pinhole_model_puts_it(
    wu: HydroModel,
    marker: tuple[float, float, float],
    position: tuple[float, float, float],
    euler: tuple[float, float, float],
    tilt_deg: float,
    supersampling: int,
) -> None:
    config = dataclasses.replace(CLEAR, mount_pitch_deg=tilt_deg, supersampling=supersampling)
    with Physics(wu, start_position_ned=position, start_euler_rad=euler) as sim:
        sim.add_scenery(Scenery(solids=(Solid("sphere", marker, (0.08,), (1.0, 1.0, 1.0)),)))
        image = capture(sim, config)
    expected = pinhole(marker, position, euler, config)
    found = centroid(image)
    assert found == pytest.approx(expected, abs=0.35)


def test_image_right_is_body_right_and_image_down_is_body_down(wu: HydroModel) -> None:
    start = (0.0, 0.0, EYE_DEPTH_M)
    with Physics(wu, start_position_ned=start) as sim:
        markers = ((3.0, 1.0, EYE_DEPTH_M + 0.5), (3.0, -1.0, EYE_DEPTH_M - 0.5))
        sim.add_scenery(
            Scenery(solids=tuple(Solid("box", m, (0.2,) * 3, (1, 1, 1)) for m in markers))
        )
        image = capture(sim, CLEAR)
    right_low, left_high = image[60:, 80:], image[:60, :80]  # east and deeper; west and shallower
    assert right_low.max() > 50 and left_high.max() > 50
    assert image[:60, 80:].max() == 0 and image[60:, :80].max() == 0


def test_yawing_right_by_90_degrees_swaps_the_north_and_east_markers(wu: HydroModel) -> None:
    start = (0.0, 0.0, EYE_DEPTH_M)
    north = (3.0, 0.0, EYE_DEPTH_M)
    east = (0.0, 3.0, EYE_DEPTH_M)
    with Physics(wu, start_position_ned=start) as sim:
        sim.add_scenery(Scenery(solids=(Solid("sphere", north, (0.1,), (1.0, 1.0, 1.0)),)))
        ahead = capture(sim, CLEAR)
        sim.reset(euler_rad=(0.0, 0.0, math.pi / 2))
        turned = capture(sim, CLEAR)
        sim.add_scenery(Scenery(solids=(Solid("sphere", east, (0.1,), (1.0, 1.0, 1.0)),)))
        east_seen = capture(sim, CLEAR)
    assert centroid(ahead) == pytest.approx(pinhole(north, start, (0, 0, 0), CLEAR), abs=0.35)
    assert turned.max() == 0  # north is 90° to the left, outside the 37.6° half-width
    yawed = (0.0, 0.0, math.pi / 2)
    assert centroid(east_seen) == pytest.approx(pinhole(east, start, yawed, CLEAR), abs=0.35)


def test_quad_texture_rows_and_columns_land_as_documented(wu: HydroModel) -> None:
    texture = np.zeros((4, 4, 3), np.uint8)
    texture[:2, :2] = 255  # the top-left quarter
    quad = Quad((3.0, -1.0, EYE_DEPTH_M - 1.0), (0.0, 2.0, 0.0), (0.0, 0.0, 2.0), "checker")
    with Physics(wu, start_position_ned=(0.0, 0.0, EYE_DEPTH_M)) as sim:
        sim.add_scenery(Scenery(quads=(quad,), textures={"checker": texture}))
        image = capture(sim, CLEAR)
    # the white quarter's centre: a quarter of each edge in from the top-left corner
    expected = pinhole((3.0, -0.5, EYE_DEPTH_M - 0.5), (0.0, 0.0, EYE_DEPTH_M), (0, 0, 0), CLEAR)
    assert centroid(image, threshold=100) == pytest.approx(expected, abs=1.0)


# --- depth and the underwater blend -----------------------------------------------------------


def wall_in_front(wu: HydroModel, distance_m: float) -> Physics:
    """A plant at 10 m depth heading north with a wide flat wall ``distance_m`` from the eye."""
    sim = Physics(wu, start_position_ned=(0.0, 0.0, EYE_DEPTH_M))
    eye_n = CLEAR.mount_position_m[0]
    centre = (eye_n + distance_m + 0.05, 0.0, EYE_DEPTH_M)
    sim.add_scenery(Scenery(solids=(Solid("box", centre, (0.1, 60.0, 60.0), (0.6, 0.6, 0.6)),)))
    return sim


def ray_lengths(distance_m: float, config: CameraConfig) -> NDArray[np.float64]:
    """Distance from the eye (heading north, level) along each pixel centre's ray to the wall."""
    f = config.focal_length_px
    east = (np.arange(config.width_px) + 0.5 - config.width_px / 2) / f
    down = (np.arange(config.height_px) + 0.5 - config.height_px / 2) / f
    rays = np.stack(np.broadcast_arrays(1.0, east[None, :], down[:, None]), axis=-1)
    unit = rays / np.linalg.norm(rays, axis=-1, keepdims=True)  # NED directions
    lengths: NDArray[np.float64] = distance_m / unit[..., 0]  # meet the plane north = distance
    return lengths


@pytest.mark.parametrize("distance_m", [1.5, 4.0, 10.0])
def test_depth_buffer_linearises_to_the_distance_of_a_plane(
    wu: HydroModel, distance_m: float
) -> None:
    with wall_in_front(wu, distance_m) as sim:
        _, position, quaternion, _ = sim.state_floats()
        _, zbuffer = sim.render(camera_pose(position, quaternion, CLEAR), CLEAR)
    depth = linear_depth_m(zbuffer, CLEAR.near_m, CLEAR.far_m)
    assert np.abs(depth - distance_m).max() < 1e-3 * distance_m


@pytest.mark.parametrize("distance_m", [1.5, 4.0, 10.0])
def test_a_flat_wall_fades_into_the_water_as_exp_minus_c_d(
    wu: HydroModel, distance_m: float
) -> None:
    murky = dataclasses.replace(CLEAR, attenuation_per_m=0.15, water_grey=200.0)
    with wall_in_front(wu, distance_m) as sim:
        _, position, quaternion, _ = sim.state_floats()
        rgb, zbuffer = sim.render(camera_pose(position, quaternion, CLEAR), CLEAR)
        seen = underwater_grey(rgb, zbuffer, murky).astype(float)
    luma = rgb[..., 0] * 0.299 + rgb[..., 1] * 0.587 + rgb[..., 2] * 0.114
    transmission = np.exp(-0.15 * ray_lengths(distance_m, CLEAR))
    expected = luma * transmission + 200.0 * (1.0 - transmission)
    assert np.abs(seen - expected).max() <= 0.5 + 1e-3  # one rounding (and float32 depth)
    assert 40.0 < luma.mean() < 180.0  # a lit wall, so the blend is tested on real values


def test_nothing_in_view_is_water(wu: HydroModel) -> None:
    config = dataclasses.replace(CLEAR, water_grey=77.0, attenuation_per_m=0.3)
    with Physics(wu, start_position_ned=(0.0, 0.0, EYE_DEPTH_M)) as sim:
        sim.add_scenery(Scenery())
        image = capture(sim, config)
    assert (image == 77).all()


# --- the vehicle's camera in the pool ---------------------------------------------------------


def camera_vehicle(seed: int = 1, **camera: object) -> Vehicle:
    config = load_vehicle_config({"camera": {"enabled": True, **camera}})
    return Vehicle(config, np.random.default_rng(seed))


@pytest.fixture(scope="module")
def start_frame() -> NDArray[np.uint8]:
    with camera_vehicle() as vehicle:
        image = vehicle.capture_image()
    assert image is not None
    return image.pixels


def test_the_start_view_has_real_detail(start_frame: NDArray[np.uint8]) -> None:
    assert start_frame.shape == (120, 160) and start_frame.dtype == np.uint8
    grey = start_frame.astype(float)
    assert grey.std() > 10.0  # floor, walls, surface and objects, not a flat field
    gradient = np.abs(np.diff(grey, axis=1)).mean() + np.abs(np.diff(grey, axis=0)).mean()
    assert gradient > 3.0  # tile joints, edges and sand: detail at pixel scale
    spectrum = np.abs(np.fft.fft2(grey - grey.mean())) ** 2
    fy, fx = np.meshgrid(np.fft.fftfreq(120), np.fft.fftfreq(160), indexing="ij")
    high = np.hypot(fx, fy) > 0.125  # above a quarter of the Nyquist frequency
    assert spectrum[high].sum() / spectrum.sum() > 0.05
    assert start_frame.min() < 80 and start_frame.max() > 130  # dark lane line, bright tiles


def test_captures_are_deterministic_and_move_with_the_vehicle(
    start_frame: NDArray[np.uint8],
) -> None:
    with camera_vehicle(seed=99) as vehicle:  # another seed: the scenery does not use it
        again = vehicle.capture_image()
        vehicle.physics.reset(position_ned=(0.5, 0.3, 1.0))
        vehicle.advance(vehicle.config.camera.min_interval_s)
        moved = vehicle.capture_image()
    assert again is not None and moved is not None
    assert again.pixels.tobytes() == start_frame.tobytes()
    assert np.mean(moved.pixels != start_frame) > 0.5


def test_capture_records_the_true_pose(wu: HydroModel) -> None:
    with camera_vehicle() as vehicle:
        vehicle.advance(0.5)
        image = vehicle.capture_image()
        truth = vehicle.state()
    assert image is not None
    assert image.time_s == pytest.approx(0.5, abs=vehicle.physics.dt_s)
    assert image.vehicle_position_ned_m == pytest.approx(truth.position_ned.tolist(), abs=1e-12)
    assert image.vehicle_quaternion_wxyz == pytest.approx(truth.quaternion_wxyz.tolist())
    eye = np.asarray(truth.position_ned) + Rotation.from_quat(
        np.roll(truth.quaternion_wxyz, -1)
    ).apply([0.2, 0.0, 0.0])
    assert image.pose.position_ned_m == pytest.approx(eye.tolist(), abs=1e-9)
    assert not image.pixels.flags.writeable


def test_capture_rate_is_limited_and_early_calls_return_none() -> None:
    with camera_vehicle(max_rate_hz=2.0) as vehicle:
        first = vehicle.capture_image()
        assert first is not None and first.time_s == 0.0
        assert vehicle.capture_image() is None  # same instant
        assert vehicle.next_capture_s == pytest.approx(0.5)
        vehicle.advance(0.45)
        assert vehicle.capture_image() is None
        vehicle.advance(0.5)
        second = vehicle.capture_image()
        assert second is not None and second.time_s == pytest.approx(0.5, abs=1e-9)
        assert vehicle.next_capture_s == pytest.approx(1.0)


def test_sensor_noise_comes_from_the_vehicle_generator(start_frame: NDArray[np.uint8]) -> None:
    images = []
    for seed in (5, 5, 6):
        with camera_vehicle(seed, noise_std_grey=3.0) as vehicle:
            image = vehicle.capture_image()
        assert image is not None
        images.append(image.pixels)
    assert images[0].tobytes() == images[1].tobytes()
    assert images[0].tobytes() != images[2].tobytes()
    difference = images[0].astype(float) - start_frame
    # N(0, 3²) plus the clean image's rounding (uniform, var 1/12), each rounded once more
    assert difference.std() == pytest.approx(math.sqrt(9.0 + 2.0 / 12.0), rel=0.05)
    assert abs(difference.mean()) < 0.1


def test_noise_without_a_generator_is_refused() -> None:
    config = dataclasses.replace(CLEAR, noise_std_grey=1.0)
    rgb = np.zeros((120, 160, 3), np.uint8)
    with pytest.raises(ValueError, match="Generator"):
        underwater_grey(rgb, np.ones((120, 160), np.float32), config)


# --- the disabled default --------------------------------------------------------------------


def test_the_default_camera_is_disabled_and_adds_nothing() -> None:
    assert VehicleConfig().camera == CameraConfig()
    assert not CameraConfig().enabled
    with Vehicle(VehicleConfig(), np.random.default_rng(1)) as vehicle:
        client = vehicle.physics.client_id
        assert pybullet.getNumBodies(physicsClientId=client) == 1  # the hull alone
        with pytest.raises(RuntimeError, match="disabled"):
            vehicle.capture_image()


def test_the_scenery_leaves_the_closed_loop_run_bit_identical() -> None:
    states = []
    for camera in (CameraConfig(), CameraConfig(enabled=True)):
        with Vehicle(VehicleConfig(camera=camera), np.random.default_rng(3)) as vehicle:
            vehicle.arm()
            vehicle.command((0.6, 0.2, -0.3, 0.0, 0.0, 0.4))
            vehicle.advance(4.0)
            state = vehicle.state()
            states.append(np.concatenate([state.position_ned, state.quaternion_wxyz, state.nu]))
    assert np.abs(states[1][:3]).max() > 0.5  # it went somewhere (into the amphorae's pool)
    assert states[0].tobytes() == states[1].tobytes()


def test_scenery_has_no_collision(wu: HydroModel) -> None:
    """A surge through a box of scenery is the same as a surge through open water."""
    wrench = [40.0, 0.0, -2.0, 0.0, 0.0, 0.0]
    finals = []
    for scenery in (None, Scenery(solids=(Solid("box", (1.0, 0.0, 10.0), (1, 1, 1), (1, 1, 1)),))):
        with Physics(wu, start_position_ned=(0.0, 0.0, EYE_DEPTH_M)) as sim:
            if scenery is not None:
                sim.add_scenery(scenery)
            for _ in range(480):
                sim.step(wrench)
            finals.append(sim.state().position_ned.tobytes())
    assert finals[0] == finals[1]


# --- configuration and files -----------------------------------------------------------------


@pytest.mark.parametrize(
    ("key", "value"),
    [
        ("width_px", 4),
        ("height_px", 2000),
        ("vertical_fov_deg", 180.0),
        ("max_rate_hz", 0.0),
        ("mount_pitch_deg", 95.0),
        ("near_m", 0.0),
        ("far_m", 0.01),
        ("attenuation_per_m", -0.1),
        ("water_grey", 256.0),
        ("noise_std_grey", -1.0),
        ("supersampling", 0),
    ],
)
def test_bad_camera_values_are_named_by_key(key: str, value: object) -> None:
    with pytest.raises(ConfigError, match=rf"camera\.{key}:"):
        load_vehicle_config({"camera": {key: value}})


def test_camera_table_builds_from_toml_values() -> None:
    config = build(CameraConfig, {"enabled": True, "width_px": 320, "mount_position_m": [0, 0, 1]})
    assert config.width_px == 320 and config.mount_position_m == (0.0, 0.0, 1.0)
    assert config.focal_length_px == pytest.approx(60.0 / math.tan(math.radians(30.0)))
    assert config.render_size_px == (640, 240)


@pytest.mark.parametrize("size", [(160, 120), (320, 240)])
def test_projection_is_pybullets_perspective_moved_half_a_pixel(size: tuple[int, int]) -> None:
    config = CameraConfig(width_px=size[0], height_px=size[1], vertical_fov_deg=55.0)
    width, height = config.render_size_px
    reference = pybullet.computeProjectionMatrixFOV(55.0, width / height, 0.05, 20.0)
    ours = np.array(config.projection_matrix)
    assert ours[[8, 9]] == pytest.approx([1.0 / width, 1.0 / height])
    ours[[8, 9]] = 0.0
    assert ours == pytest.approx(np.array(reference), rel=1e-6)


def test_png_bytes_decode_to_the_same_pixels() -> None:
    rng = np.random.default_rng(4)
    image = rng.integers(0, 256, size=(7, 11, 3), dtype=np.uint8)
    decoded = np.asarray(Image.open(io.BytesIO(png_bytes(image))).convert("RGB"))
    assert np.array_equal(decoded, image)
