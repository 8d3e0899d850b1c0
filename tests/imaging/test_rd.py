"""Rate-distortion of the coder against JPEG 2000 (OpenJPEG via Pillow) and baseline JPEG.

Frames: the synthetic pool scene and the vehicle's forward camera rendered by pybullet (through
the public ``Vehicle.capture_image``), each at 160 x 120 and 320 x 240. Run with ``-s`` to see the
table. Asserted: within 1 dB of JPEG 2000 at every budget, and above baseline JPEG wherever JPEG
can get under the budget.
"""

from __future__ import annotations

import io
import math

import numpy as np
import pytest
from PIL import Image

from testbed.imaging import decode, encode, pool_scene
from testbed.vehicle.camera import CameraConfig
from testbed.vehicle.vehicle import Vehicle
from testbed.vehicle.vehicle_config import VehicleConfig

BUDGETS = (300, 600, 1200, 2400)


def psnr_db(a: np.ndarray, b: np.ndarray) -> float:
    mse = float(np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2))
    return float(10.0 * np.log10(255.0**2 / mse))


def jpeg2000_at(img: np.ndarray, budget: int) -> tuple[int, float]:
    """Bytes and PSNR of the largest raw J2K codestream (9/7, rate-controlled) within budget."""
    ratio = img.size / budget
    for _ in range(60):
        buf = io.BytesIO()
        Image.fromarray(img).save(
            buf, "JPEG2000", no_jp2=True, irreversible=True, quality_mode="rates",
            quality_layers=[ratio],
        )  # fmt: skip
        if buf.tell() <= budget:
            out = np.asarray(Image.open(io.BytesIO(buf.getvalue())))
            return buf.tell(), psnr_db(img, out)
        ratio *= 1.03
    raise AssertionError("OpenJPEG never got under the budget")


def jpeg_at(img: np.ndarray, budget: int) -> tuple[int, float] | None:
    """Bytes and PSNR of the best baseline JPEG (quality 1..95) within budget, None if none fits."""
    best = None
    for quality in range(1, 96):
        buf = io.BytesIO()
        Image.fromarray(img).save(buf, "JPEG", quality=quality)
        if buf.tell() > budget:
            break
        best = (buf.tell(), psnr_db(img, np.asarray(Image.open(io.BytesIO(buf.getvalue())))))
    return best


POSES = {
    "spawn": ((0.0, 0.0, 0.5), (0.0, 0.0, 0.0)),
    "close-panel": ((2.5, 0.0, 1.5), (0.0, 0.0, 0.0)),
    "yaw-east": ((1.0, -1.0, 1.0), (0.0, 0.0, math.radians(60.0))),
    "deep-south": ((0.0, 1.5, 2.2), (0.0, 0.0, math.radians(200.0))),
}
"""Vehicle poses (NED position [m], roll/pitch/yaw [rad]) the rendered frames are taken from:
the spawn pose, a close-up of the valve panel, a view across the pool, a deep view south."""


def rendered_frame(width: int, height: int, pose: str = "spawn") -> np.ndarray:
    """The forward camera's first frame from the vehicle at ``pose`` in the pool scene."""
    camera = CameraConfig(enabled=True, width_px=width, height_px=height)
    position, euler = POSES[pose]
    config = VehicleConfig(camera=camera, start_position_ned_m=position, start_euler_rad=euler)
    with Vehicle(config, np.random.default_rng(3)) as vehicle:
        captured = vehicle.capture_image()
    assert captured is not None
    return np.asarray(captured.pixels)


@pytest.mark.parametrize("source", ["synthetic", *(f"rendered:{pose}" for pose in POSES)])
@pytest.mark.parametrize(("width", "height"), [(160, 120), (320, 240)])
def test_rate_distortion_against_jpeg2000_and_jpeg(source: str, width: int, height: int) -> None:
    if source == "synthetic":
        img = pool_scene(width, height, np.random.default_rng(1))
    else:
        img = rendered_frame(width, height, source.split(":", 1)[1])
    assert img.shape == (height, width) and img.std() > 10.0  # real content
    print(f"\n{source} {width}x{height}  budget  ours[dB]  J2K[B]  J2K[dB]  JPEG[B]  JPEG[dB]")
    for budget in BUDGETS:
        stream = encode(img, budget)
        ours = psnr_db(img, decode(stream))
        j2k_bytes, j2k = jpeg2000_at(img, budget)
        jpg = jpeg_at(img, budget)
        jpg_txt = f"{jpg[0]:7d}  {jpg[1]:8.2f}" if jpg else "      -         -"
        print(f"          {budget:6d}  {ours:8.2f}  {j2k_bytes:6d}  {j2k:7.2f}  {jpg_txt}")
        assert len(stream) == budget
        assert ours > j2k - 1.0
        if jpg is not None:
            assert ours > jpg[1]
