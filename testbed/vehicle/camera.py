"""The vehicle's forward camera: configuration, pose and the underwater look.

Rendering itself is pybullet's CPU renderer, behind :meth:`testbed.vehicle.physics.Physics.render`;
this module is pure numpy and never imports pybullet (nor physics, which imports it).

Frames. World NED, body FRD (origin CO). The camera sits at ``mount_position_m`` (FRD) and
looks along the body's forward axis pitched down by ``mount_pitch_deg``. Its optical frame is
the usual pinhole one: x right (= body right), y down, z forward along the optical axis. A point
at (x, y, z) in that frame lands at the continuous pixel coordinates
``u = cx + f·x/z`` (column, to the right), ``v = cy + f·y/z`` (row, down), with
``f = (height/2)/tan(vertical_fov/2)`` and ``(cx, cy) = (width/2, height/2)``, where pixel
(row i, column j) covers [j, j+1) × [i, i+1); so pixel centres sit at j + 0.5, i + 0.5.

Underwater look. Each pixel's grey (ITU-R BT.601 luma of the rendered RGB) is blended toward
the water's grey by the transmission ``exp(−c·d)`` over the ray's length d from the optical
centre (the depth buffer's z, linearised with the projection's near/far planes, times the
ray's secant): ``g = g₀·e^{−cd} + water·(1 − e^{−cd})``; where no geometry is hit, water.
The renderer samples textures at the nearest texel, so fine tile joints alias; each pixel is
the mean of ``supersampling``² rendered samples, blended one by one (a sensor pixel integrates
the light over its area), then sensor noise (from a generator passed in) and rounding.

The pool and its objects are :mod:`testbed.vehicle.scenery`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from testbed.common.geometry import quat_rotate
from testbed.config import check, check_range, check_ranges

__all__ = [
    "CameraConfig",
    "CameraPose",
    "CapturedImage",
    "camera_pose",
    "grey_from_rgb",
    "linear_depth_m",
    "ray_length_m",
    "underwater_grey",
]

Vec3 = tuple[float, float, float]
Rgb = tuple[float, float, float]
GreyImage = NDArray[np.uint8]
FloatImage = NDArray[np.float64]

BT601 = (0.299, 0.587, 0.114)
"""ITU-R BT.601 luma weights of R, G, B."""


@dataclass(frozen=True, slots=True)
class CameraConfig:
    """The forward camera (disabled by default: no scenery, no rendering, nothing changes).

    Attributes:
        enabled: render images on request (and build the pool scenery).
        width_px: image width [px], 8–1024 (the image-settings ROI addresses 10 bits).
        height_px: image height [px], 8–1024.
        vertical_fov_deg: vertical field of view [deg], in (0, 180).
        max_rate_hz: highest capture rate [Hz], in [1e-3, 1000]; captures closer than
            ``1/max_rate_hz`` apart are refused
            (:meth:`testbed.vehicle.vehicle.Vehicle.capture_image` returns None).
        mount_position_m: (3,) optical centre in the body [m], FRD, from CO; each in [−10, 10].
        mount_pitch_deg: tilt of the optical axis below the body's forward axis [deg]
            (0 = looking straight ahead, positive = down), in [−90, 90].
        near_m: near clipping plane [m], in [1e-3, 10].
        far_m: far clipping plane [m], > near, ≤ 1000.
        attenuation_per_m: water's attenuation coefficient c [1/m], in [0, 100] (0 = clear
            air).
        water_grey: grey level of water seen at infinite range, 0–255.
        noise_std_grey: standard deviation of additive Gaussian sensor noise [grey levels],
            in [0, 255]; drawn from the generator given to the capture (0 = none).
        supersampling: k, 1–4: each pixel averages k × k rendered samples (the renderer
            samples textures at nearest texels; k = 1 aliases fine tile joints into moiré).
    """

    enabled: bool = False
    width_px: int = 160
    height_px: int = 120
    vertical_fov_deg: float = 60.0
    max_rate_hz: float = 1.0
    mount_position_m: tuple[float, float, float] = (0.2, 0.0, 0.0)
    mount_pitch_deg: float = 20.0
    near_m: float = 0.05
    far_m: float = 20.0
    attenuation_per_m: float = 0.15
    water_grey: float = 95.0
    noise_std_grey: float = 0.0
    supersampling: int = 2

    def __post_init__(self) -> None:
        for key in ("width_px", "height_px"):
            value = getattr(self, key)
            check(8 <= value <= 1024, key, f"must be in [8, 1024] px, got {value}")
        fov = self.vertical_fov_deg
        check(0.0 < fov < 180.0, "vertical_fov_deg", f"must be in (0, 180), got {fov}")
        check_range(self.max_rate_hz, "max_rate_hz", 1e-3, 1000.0, "Hz")
        check_ranges(self.mount_position_m, "mount_position_m", -10.0, 10.0, "m")
        check_range(self.mount_pitch_deg, "mount_pitch_deg", -90.0, 90.0, "deg")
        check_range(self.near_m, "near_m", 1e-3, 10.0, "m")
        check_range(self.far_m, "far_m", 0.0, 1000.0, "m", low_open=True)
        check(
            self.far_m > self.near_m,
            "far_m",
            f"must be > near_m ({self.near_m}), got {self.far_m}",
        )
        check_range(self.attenuation_per_m, "attenuation_per_m", 0.0, 100.0, "1/m")
        check_range(self.water_grey, "water_grey", 0.0, 255.0)
        check_range(self.noise_std_grey, "noise_std_grey", 0.0, 255.0)
        k = self.supersampling
        check(1 <= k <= 4, "supersampling", f"must be in [1, 4], got {k}")

    @property
    def focal_length_px(self) -> float:
        """Pinhole focal length f [px] from the vertical field of view."""
        return 0.5 * self.height_px / math.tan(math.radians(0.5 * self.vertical_fov_deg))

    @property
    def render_size_px(self) -> tuple[int, int]:
        """(width, height) of the render [px]: the image's times ``supersampling``."""
        return (self.width_px * self.supersampling, self.height_px * self.supersampling)

    @property
    def projection_matrix(self) -> tuple[float, ...]:
        """The OpenGL projection (16 values, column-major) of the render, half-pixel centred.

        gluPerspective's matrix from the vertical field of view, the aspect and near/far, with
        the frustum moved by half a render pixel left and down: pybullet's TinyRenderer samples
        pixel (row i, column j) at (j, i + 1) of the continuous image rather than at the pixel
        centre (j + ½, i + ½), which would put everything half a pixel right and up.
        """
        width, height = self.render_size_px
        f = 1.0 / math.tan(math.radians(0.5 * self.vertical_fov_deg))
        near, far = self.near_m, self.far_m
        depth = (far + near) / (near - far)
        shift_x, shift_y = 1.0 / width, 1.0 / height
        return (
            f * height / width, 0.0, 0.0, 0.0,
            0.0, f, 0.0, 0.0,
            shift_x, shift_y, depth, -1.0,
            0.0, 0.0, 2.0 * far * near / (near - far), 0.0,
        )  # fmt: skip

    @property
    def min_interval_s(self) -> float:
        """Shortest time between two captures [s]."""
        return 1.0 / self.max_rate_hz


@dataclass(frozen=True, slots=True)
class CameraPose:
    """The camera's optical centre and axes in the world.

    Attributes:
        position_ned_m: (3,) optical centre [m], NED.
        forward_ned: (3,) unit optical axis (camera z), NED.
        right_ned: (3,) unit image-right axis (camera x), NED.
        down_ned: (3,) unit image-down axis (camera y), NED.
    """

    position_ned_m: Vec3
    forward_ned: Vec3
    right_ned: Vec3
    down_ned: Vec3

    @property
    def up_ned(self) -> Vec3:
        """(3,) unit image-up axis (−camera y), NED."""
        return (-self.down_ned[0], -self.down_ned[1], -self.down_ned[2])


@dataclass(frozen=True, slots=True, eq=False)
class CapturedImage:
    """One camera frame and where it was taken.

    Attributes:
        time_s: simulated time of the capture [s].
        pixels: (height, width) grey image, uint8, row 0 at the top (read-only).
        pose: the camera's pose at the capture (from the plant's true pose).
        vehicle_position_ned_m: (3,) true position of CO [m], NED.
        vehicle_quaternion_wxyz: (4,) true attitude, body FRD → NED.
    """

    time_s: float
    pixels: GreyImage
    pose: CameraPose
    vehicle_position_ned_m: Vec3
    vehicle_quaternion_wxyz: tuple[float, float, float, float]


def camera_pose(
    position_ned_m: Vec3, quaternion_wxyz: tuple[float, float, float, float], config: CameraConfig
) -> CameraPose:
    """The camera's pose from the body's: the mount offset and pitch carried by the attitude.

    Args:
        position_ned_m: (3,) position of CO [m], NED.
        quaternion_wxyz: (4,) attitude, body FRD → NED.
        config: the camera (mount position and pitch).
    """
    q = quaternion_wxyz
    offset = quat_rotate(q, config.mount_position_m)
    pitch = math.radians(config.mount_pitch_deg)
    cos_p, sin_p = math.cos(pitch), math.sin(pitch)
    # the optical axis is the body's x turned down (towards +z FRD) by the mount pitch
    return CameraPose(
        position_ned_m=(
            position_ned_m[0] + offset[0],
            position_ned_m[1] + offset[1],
            position_ned_m[2] + offset[2],
        ),
        forward_ned=quat_rotate(q, (cos_p, 0.0, sin_p)),
        right_ned=quat_rotate(q, (0.0, 1.0, 0.0)),
        down_ned=quat_rotate(q, (-sin_p, 0.0, cos_p)),
    )


def linear_depth_m(zbuffer: NDArray[np.floating], near_m: float, far_m: float) -> FloatImage:
    """Distance along the optical axis [m] from an OpenGL depth buffer in [0, 1].

    Inverts the perspective projection's depth mapping:
    ``z = far·near / (far − (far − near)·buffer)``; a buffer value of 1 is the far plane.
    """
    buffer = np.asarray(zbuffer, dtype=np.float64)
    depth: FloatImage = far_m * near_m / (far_m - (far_m - near_m) * buffer)
    return depth


def ray_length_m(depth_m: FloatImage, vertical_fov_deg: float) -> FloatImage:
    """(h, w) distance [m] from the optical centre to the surface seen in each pixel.

    Args:
        depth_m: (h, w) distance along the optical axis [m] (:func:`linear_depth_m`) of an
            image whose pixels are square and whose height spans ``vertical_fov_deg``.
        vertical_fov_deg: the image's vertical field of view [deg].
    """
    height, width = depth_m.shape
    f = 0.5 * height / math.tan(math.radians(0.5 * vertical_fov_deg))
    x = (np.arange(width) + 0.5 - 0.5 * width) / f
    y = (np.arange(height) + 0.5 - 0.5 * height) / f
    secant = np.sqrt(1.0 + x[None, :] ** 2 + y[:, None] ** 2)
    length: FloatImage = depth_m * secant
    return length


def grey_from_rgb(rgb: NDArray[np.uint8]) -> FloatImage:
    """(h, w) ITU-R BT.601 luma [0–255] of an (h, w, 3 or 4) RGB(A) image (alpha ignored)."""
    r, g, b = (rgb[..., k].astype(np.float64) for k in range(3))
    grey: FloatImage = BT601[0] * r + BT601[1] * g + BT601[2] * b
    return grey


def underwater_grey(
    rgb: NDArray[np.uint8],
    zbuffer: NDArray[np.floating],
    config: CameraConfig,
    rng: np.random.Generator | None = None,
) -> GreyImage:
    """The rendered frame as the camera sees it under water: grey, veiled by distance, noisy.

    Args:
        rgb: (k·h, k·w, 3 or 4) rendered colour, uint8, k = ``config.supersampling``.
        zbuffer: (k·h, k·w) the renderer's depth buffer in [0, 1] (1 = nothing hit).
        config: the camera.
        rng: generator for the sensor noise; required when ``config.noise_std_grey > 0``.

    Returns:
        (h, w) grey image, uint8: each pixel the mean of its k × k rendered samples.

    Raises:
        ValueError: renders of the wrong size, or noise configured without a generator.
    """
    k, height, width = config.supersampling, config.height_px, config.width_px
    if rgb.shape[:2] != (k * height, k * width) or zbuffer.shape != rgb.shape[:2]:
        raise ValueError(f"expected {k * height} x {k * width} renders, got {rgb.shape[:2]}")
    grey = grey_from_rgb(rgb)
    buffer = np.asarray(zbuffer, dtype=np.float64)
    depth = linear_depth_m(buffer, config.near_m, config.far_m)
    distance = ray_length_m(depth, config.vertical_fov_deg)
    transmission = np.where(buffer < 1.0, np.exp(-config.attenuation_per_m * distance), 0.0)
    grey = grey * transmission + config.water_grey * (1.0 - transmission)
    grey = grey.reshape(height, k, width, k).mean(axis=(1, 3))  # each pixel sums its k x k
    if config.noise_std_grey > 0.0:
        if rng is None:
            raise ValueError("noise_std_grey > 0 needs a numpy Generator")
        grey = grey + rng.normal(0.0, config.noise_std_grey, size=grey.shape)
    result: GreyImage = np.clip(np.rint(grey), 0, 255).astype(np.uint8)
    return result
