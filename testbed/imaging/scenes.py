"""Deterministic synthetic test frames for the image coder.

A stand-in for rendered camera frames where the renderer (pybullet) may not be imported: a pool
floor seen from an ROV, with tiles, sand texture, caustics, an amphora and a marker panel. The
scene has what a wavelet coder is judged on: smooth gradients, sharp straight and curved edges,
periodic texture, fine detail and sensor noise. Only numpy is used; randomness comes from the
generator passed in.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray


def _smooth_noise(
    rng: np.random.Generator, height: int, width: int, cells: int
) -> NDArray[np.float64]:
    """(height, width) band-limited noise in [-1, 1]: bilinear upsampling of a coarse grid."""
    gh, gw = cells + 2, int(cells * width / height) + 2
    grid = rng.uniform(-1.0, 1.0, size=(gh, gw))
    ys = np.linspace(0.0, gh - 1.001, height)
    xs = np.linspace(0.0, gw - 1.001, width)
    y0, x0 = ys.astype(int), xs.astype(int)
    fy, fx = (ys - y0)[:, None], (xs - x0)[None, :]
    a = grid[y0][:, x0]
    b = grid[y0][:, x0 + 1]
    c = grid[y0 + 1][:, x0]
    d = grid[y0 + 1][:, x0 + 1]
    out: NDArray[np.float64] = (a * (1 - fx) + b * fx) * (1 - fy) + (c * (1 - fx) + d * fx) * fy
    return out


def pool_scene(width: int, height: int, rng: np.random.Generator) -> NDArray[np.uint8]:
    """A grey pool-floor frame with an amphora and a marker panel.

    Args:
        width: image width [px], at least 16.
        height: image height [px], at least 16.
        rng: source of the sand texture, caustic phases and sensor noise.

    Returns:
        (height, width) uint8 grey image, row 0 at the top.

    Raises:
        ValueError: if the image is smaller than 16 x 16 pixels.
    """
    if width < 16 or height < 16:
        raise ValueError(f"pool_scene needs at least 16 x 16 pixels, got {width} x {height}")
    v = (np.arange(height, dtype=np.float64)[:, None] + 0.5) / height  # 0 top .. 1 bottom
    u = (np.arange(width, dtype=np.float64)[None, :] + 0.5) / width
    # Water column: brighter near the surface, floor in perspective below the horizon.
    img = 60.0 + 70.0 * (1.0 - v) + 0.0 * u
    horizon = 0.32
    floor = v > horizon
    depth = np.where(floor, (v - horizon) / (1.0 - horizon), 1e-3)  # 0 at horizon .. 1 at bottom
    fx = (u - 0.5) / (0.15 + depth) * 3.0  # floor coordinates in tiles
    fz = 1.0 / (0.12 + depth) * 1.5
    grout = (np.abs(fx - np.round(fx)) < 0.04) | (np.abs(fz - np.round(fz)) < 0.05)
    sand = _smooth_noise(rng, height, width, 12) * 12.0 + _smooth_noise(rng, height, width, 40) * 6
    phase = rng.uniform(0, 2 * np.pi, size=3)
    caustic = (
        np.sin(fx * 4.1 + phase[0])
        + np.sin(fz * 3.3 + phase[1])
        + np.sin((fx + fz) * 2.7 + phase[2])
    ) ** 2
    floor_val = 105.0 + 40.0 * depth + sand + 5.0 * caustic - 45.0 * grout
    img = np.where(floor, floor_val, img)
    # Amphora: an ellipse body, a neck and a shadow, lit from the upper left.
    cx, cy = 0.34, 0.62
    ax, ay = 0.11, 0.20
    body = ((u - cx) / ax) ** 2 + ((v - cy) / ay) ** 2
    neck = (np.abs(u - cx) < 0.035) & (v > cy - ay - 0.12) & (v < cy - ay + 0.02)
    lip = (np.abs(u - cx) < 0.055) & (np.abs(v - (cy - ay - 0.12)) < 0.015)
    shadow = (((u - cx - 0.05) / (ax * 1.1)) ** 2 + ((v - cy - 0.05) / (ay * 0.9)) ** 2) < 1.0
    img = np.where(shadow & floor, img * 0.6, img)
    shade = 150.0 - 70.0 * ((u - cx + 0.05) / ax) - 30.0 * ((v - cy) / ay)
    amphora = (body < 1.0) | neck | lip
    img = np.where(amphora, np.clip(shade, 40.0, 210.0), img)
    bands = amphora & (np.abs(v - cy + 0.05) < 0.012)
    img = np.where(bands, 55.0, img)
    # Marker panel: a bright plate with a dark frame, bars and a checker patch.
    px0, px1, py0, py1 = 0.60, 0.88, 0.38, 0.72
    panel = (u > px0) & (u < px1) & (v > py0) & (v < py1)
    inner = (u > px0 + 0.02) & (u < px1 - 0.02) & (v > py0 + 0.03) & (v < py1 - 0.03)
    img = np.where(panel, 40.0, img)
    img = np.where(inner, 215.0, img)
    bars = inner & (v < py0 + 0.15) & (np.floor((u - px0) * 60.0) % 2 == 0)
    img = np.where(bars, 30.0, img)
    checker = inner & (v > py0 + 0.18) & (u < px0 + 0.14)
    cells = (np.floor((u - px0) * 50.0) + np.floor((v - py0) * 40.0)) % 2 == 0
    img = np.where(checker & cells, 25.0, img)
    disc = ((u - px0 - 0.2) / 0.04) ** 2 + ((v - py0 - 0.25) / 0.055) ** 2 < 1.0
    img = np.where(disc & inner, 90.0, img)
    img = img + rng.normal(0.0, 2.0, size=img.shape)
    return np.clip(np.round(img), 0, 255).astype(np.uint8)
