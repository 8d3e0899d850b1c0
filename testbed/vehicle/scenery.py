"""The pool the camera looks at: a tiled pool and a few objects, as plain data for the renderer.

Scenery. :func:`pool_scenery` describes a tiled pool (floor with lane line and sand, walls
with a waterline band and targets, a rippled surface) and a few objects in front of the start
pose: three amphorae, a valve panel and a pipe. Textures are computed here from a
deterministic hash (no RNG), so every run and every machine sees the same pool.

:meth:`testbed.vehicle.physics.Physics.add_scenery` turns a :class:`Scenery` into visual-only
pybullet bodies. Pure numpy: no pybullet here.
"""

from __future__ import annotations

import math
import struct
import zlib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from testbed.common.geometry import quat_from_euler

__all__ = ["LIGHT_TOWARDS_NED", "Quad", "Scenery", "Solid", "png_bytes", "pool_scenery"]

Vec3 = tuple[float, float, float]
Rgb = tuple[float, float, float]
FloatImage = NDArray[np.float64]

LIGHT_TOWARDS_NED: Vec3 = (0.2, 0.3, -1.0)
"""Direction towards the scenery's directional light (the sun, through the surface), NED."""


@dataclass(frozen=True, slots=True)
class Solid:
    """A coloured primitive, visual only (no collision, no mass).

    Attributes:
        kind: ``"box"`` (size = full extents x, y, z), ``"sphere"`` (size = radius,),
            ``"cylinder"`` or ``"capsule"`` (size = radius, length of the straight part along
            the shape's z axis).
        position_ned_m: (3,) centre [m], NED.
        euler_rad: (3,) roll, pitch, yaw of the shape's axes [rad], ZYX, shape → NED.
        size_m: see ``kind`` [m].
        rgb: colour, each channel in [0, 1].
    """

    kind: Literal["box", "sphere", "cylinder", "capsule"]
    position_ned_m: Vec3
    size_m: tuple[float, ...]
    rgb: Rgb
    euler_rad: Vec3 = (0.0, 0.0, 0.0)

    @property
    def quaternion_wxyz(self) -> tuple[float, float, float, float]:
        """The shape's attitude, shape → NED."""
        return quat_from_euler(*self.euler_rad)


@dataclass(frozen=True, slots=True)
class Quad:
    """A textured rectangle, visible from one side.

    Texture pixel (row i, column j) of an (H, W) texture lies at
    ``top_left + (j + ½)/W · right + (i + ½)/H · down``; the quad faces the viewer for whom
    ``right`` points right and ``down`` points down (normal ``down × right``).

    Attributes:
        top_left_ned_m: (3,) corner [m], NED.
        right_ned_m: (3,) edge along the texture's columns [m], NED.
        down_ned_m: (3,) edge along the texture's rows [m], NED.
        texture: name of a texture in :attr:`Scenery.textures`.
    """

    top_left_ned_m: Vec3
    right_ned_m: Vec3
    down_ned_m: Vec3
    texture: str

    @property
    def corners_ned_m(self) -> tuple[Vec3, Vec3, Vec3, Vec3]:
        """The four corners [m], NED: top left, top right, bottom right, bottom left."""
        o, r, d = self.top_left_ned_m, self.right_ned_m, self.down_ned_m
        return (o, _plus(o, r), _plus(_plus(o, r), d), _plus(o, d))

    @property
    def normal_ned(self) -> Vec3:
        """Unit normal of the visible side, ``down × right``, NED."""
        n = np.cross(self.down_ned_m, self.right_ned_m)
        x, y, z = (n / np.linalg.norm(n)).tolist()
        return (x, y, z)


@dataclass(frozen=True, slots=True, eq=False)
class Scenery:
    """What the camera can see besides the vehicle: decoration only, never collided with.

    Attributes:
        quads: textured rectangles.
        solids: coloured primitives.
        textures: name → (H, W, 3) uint8 RGB image.
    """

    quads: tuple[Quad, ...] = ()
    solids: tuple[Solid, ...] = ()
    textures: Mapping[str, NDArray[np.uint8]] = field(default_factory=dict)

    def write_textures(self, folder: str | Path) -> dict[str, str]:
        """Write each texture as a PNG file in ``folder``; returns name → path."""
        paths = {}
        for index, (name, image) in enumerate(self.textures.items()):
            path = Path(folder) / f"texture{index}.png"
            path.write_bytes(png_bytes(image))
            paths[name] = str(path)
        return paths


def _plus(a: Vec3, b: Vec3) -> Vec3:
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])


def png_bytes(image: NDArray[np.uint8]) -> bytes:
    """An (H, W, 3) uint8 RGB image as a PNG file (8-bit truecolour, no filter)."""
    height, width, channels = image.shape
    if channels != 3 or image.dtype != np.uint8:
        raise ValueError(f"expected (H, W, 3) uint8, got {image.shape} {image.dtype}")
    rows = np.concatenate([np.zeros((height, 1), np.uint8), image.reshape(height, -1)], axis=1)

    def chunk(kind: bytes, data: bytes) -> bytes:
        return (
            struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))
        )

    header = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", header)
        + chunk(b"IDAT", zlib.compress(rows.tobytes(), 6))
        + chunk(b"IEND", b"")
    )


def _hash01(ix: NDArray[np.int64], iy: NDArray[np.int64], seed: int) -> FloatImage:
    """Deterministic pseudo-random values in [0, 1) on an integer lattice (a 32-bit mix)."""
    h = (ix.astype(np.uint32) * np.uint32(0x8DA6B343)) ^ (
        iy.astype(np.uint32) * np.uint32(0xD8163841)
    )
    h ^= np.uint32(seed * 0x9E3779B1 & 0xFFFFFFFF)
    h ^= h >> np.uint32(15)
    h *= np.uint32(0x2C1B3C6D)
    h ^= h >> np.uint32(12)
    h *= np.uint32(0x297A2D39)
    h ^= h >> np.uint32(15)
    values: FloatImage = h.astype(np.float64) / 2.0**32
    return values


def _noise(a_m: FloatImage, b_m: FloatImage, cell_m: float, seed: int) -> FloatImage:
    """Smooth value noise in [0, 1) over coordinates (a, b) [m] with lattice spacing ``cell_m``."""
    fa, fb = a_m / cell_m, b_m / cell_m
    ia, ib = np.floor(fa).astype(np.int64), np.floor(fb).astype(np.int64)
    ta, tb = fa - ia, fb - ib
    ta, tb = ta * ta * (3 - 2 * ta), tb * tb * (3 - 2 * tb)
    v00, v10 = _hash01(ia, ib, seed), _hash01(ia + 1, ib, seed)
    v01, v11 = _hash01(ia, ib + 1, seed), _hash01(ia + 1, ib + 1, seed)
    top = v00 + (v10 - v00) * ta
    bottom = v01 + (v11 - v01) * ta
    result: FloatImage = top + (bottom - top) * tb
    return result


def _grid(rows_m: float, cols_m: float, texel_m: float) -> tuple[FloatImage, FloatImage]:
    """Texel-centre coordinates (row, column) [m] of a texture covering rows_m × cols_m."""
    n_rows, n_cols = max(1, round(rows_m / texel_m)), max(1, round(cols_m / texel_m))
    r = (np.arange(n_rows) + 0.5) * (rows_m / n_rows)
    c = (np.arange(n_cols) + 0.5) * (cols_m / n_cols)
    return np.broadcast_to(r[:, None], (n_rows, n_cols)), np.broadcast_to(
        c[None, :], (n_rows, n_cols)
    )


def _tiles(r: FloatImage, c: FloatImage, tile_m: float, seed: int) -> FloatImage:
    """Brightness factor of a tiled surface: grout lines, tile-to-tile shade, fine grain."""
    grout_m = 0.012
    in_grout = (np.mod(r, tile_m) < grout_m) | (np.mod(c, tile_m) < grout_m)
    shade = 0.94 + 0.06 * _hash01(
        np.floor(r / tile_m).astype(np.int64), np.floor(c / tile_m).astype(np.int64), seed
    )
    grain = 0.9 + 0.1 * _noise(r, c, 0.03, seed + 1)
    return np.where(in_grout, 0.55, shade * grain)


def _paint(factor: FloatImage, rgb: Rgb) -> NDArray[np.uint8]:
    out = factor[..., None] * np.asarray(rgb, dtype=np.float64)[None, None, :] * 255.0
    return np.clip(np.rint(out), 0, 255).astype(np.uint8)


def _floor_texture(length_m: float, width_m: float) -> NDArray[np.uint8]:
    """Pool floor seen from above, north up: tiles, sand and silt, a lane line with a T end."""
    r, c = _grid(length_m, width_m, 0.02)
    north, east = 0.5 * length_m - r, c - 0.5 * width_m
    sand = (
        0.75
        + 0.12 * _noise(r, c, 0.6, 11)
        + 0.08 * _noise(r, c, 0.15, 12)
        + 0.05 * _noise(r, c, 0.04, 13)
    )
    silt = np.clip((_noise(r, c, 1.8, 14) - 0.55) * 2.5, 0.0, 0.6)  # dark patches, metres wide
    factor = _tiles(r, c, 0.25, 10) * sand * (1.0 - 0.5 * silt)
    image = _paint(factor, (0.85, 0.9, 0.92)).astype(np.float64)
    end = 0.5 * length_m - 1.0
    lane = (np.abs(east) < 0.125) & (np.abs(north) < end)
    lane |= (np.abs(north - end) < 0.125) & (np.abs(east) < 0.5)
    image[lane] *= np.array([0.25, 0.3, 0.6])
    return np.clip(np.rint(image), 0, 255).astype(np.uint8)


def _wall_texture(span_m: float, depth_m: float, seed: int) -> NDArray[np.uint8]:
    """A wall seen from the water: tiles, a dark waterline band, a target cross, a depth ruler."""
    r, c = _grid(depth_m, span_m, 0.02)
    along = c - 0.5 * span_m
    grime = 1.0 - 0.25 * np.clip(r / depth_m, 0.0, 1.0) * _noise(r, c, 0.5, seed + 3)
    factor = _tiles(r, c, 0.25, seed) * grime
    image = _paint(factor, (0.8, 0.88, 0.9)).astype(np.float64)
    dark = np.array([0.2, 0.25, 0.5])
    image[r < 0.2] *= dark  # waterline band
    cross_row = 0.5 * depth_m
    cross = ((np.abs(along) < 0.1) & (np.abs(r - cross_row) < 0.5)) | (
        (np.abs(r - cross_row) < 0.1) & (np.abs(along) < 0.5)
    )
    image[cross] *= dark
    ruler = (np.abs(along + 0.3 * span_m) < 0.1) & (np.mod(r, 0.5) < 0.25) & (r > 0.2)
    image[ruler] *= np.array([0.1, 0.1, 0.1])
    return np.clip(np.rint(image), 0, 255).astype(np.uint8)


def _surface_texture(length_m: float, width_m: float) -> NDArray[np.uint8]:
    """The water surface from below: bright, with ripples and caustic-like bands."""
    r, c = _grid(width_m, length_m, 0.05)
    waves = np.sin(2.1 * r + 1.3 * c) + np.sin(0.7 * r - 2.9 * c + 1.0) + np.sin(3.7 * c + 0.4 * r)
    factor = 0.8 + 0.05 * waves + 0.1 * _noise(r, c, 0.4, 31)
    return _paint(factor, (0.85, 0.95, 1.0))


def _panel_texture() -> NDArray[np.uint8]:
    """The valve panel's face: a 3 × 4 grid of coloured squares and a ring gauge."""
    r, c = _grid(0.8, 1.0, 0.01)
    image = np.full((*r.shape, 3), 230.0)
    colours = [
        (220, 40, 30),
        (30, 160, 60),
        (30, 60, 200),
        (240, 210, 30),
        (20, 20, 20),
        (255, 255, 255),
    ]
    for k in range(12):
        row, col = divmod(k, 4)
        top, left = 0.08 + 0.22 * row, 0.06 + 0.16 * col
        square = (r >= top) & (r < top + 0.16) & (c >= left) & (c < left + 0.12)
        image[square] = colours[(k * 5) % len(colours)]
    radius = np.hypot(r - 0.4, c - 0.82)
    image[(radius > 0.08) & (radius < 0.12)] = (20, 20, 20)
    image[(np.abs(r - 0.4) < 0.012) & (radius < 0.08)] = (200, 30, 30)
    return np.clip(np.rint(image), 0, 255).astype(np.uint8)


def _amphora(
    north_m: float, east_m: float, floor_m: float, lying: bool, height_m: float
) -> list[Solid]:
    """A terracotta amphora: spike foot, belly, shoulder, neck, lip and (upright) two handles.

    Upright on its foot, or lying on its belly along north with the handles broken off.
    """
    clay, dark = (0.72, 0.38, 0.22), (0.55, 0.28, 0.16)
    s = height_m / 0.8
    # (height above the foot's tip [m], kind, size)
    parts: list[tuple[float, Literal["capsule", "sphere", "cylinder"], tuple[float, ...], Rgb]] = [
        (0.08 * s, "capsule", (0.035 * s, 0.1 * s), dark),
        (0.32 * s, "capsule", (0.16 * s, 0.16 * s), clay),
        (0.50 * s, "sphere", (0.135 * s,), clay),
        (0.66 * s, "cylinder", (0.05 * s, 0.22 * s), clay),
        (0.77 * s, "cylinder", (0.07 * s, 0.04 * s), dark),
    ]
    solids = []
    for along, kind, size, rgb in parts:
        if lying:
            centre = (north_m + along - 0.4 * s, east_m, floor_m - 0.16 * s)
            solids.append(Solid(kind, centre, size, rgb, (0.0, math.pi / 2, 0.0)))
        else:
            solids.append(Solid(kind, (north_m, east_m, floor_m - along), size, rgb))
    if not lying:
        for side in (-1.0, 1.0):
            centre = (north_m, east_m + side * 0.1 * s, floor_m - 0.62 * s)
            handle = Solid("capsule", centre, (0.018 * s, 0.13 * s), dark, (-side * 0.5, 0.0, 0.0))
            solids.append(handle)
    return solids


def pool_scenery(length_m: float = 10.0, width_m: float = 6.0, depth_m: float = 3.0) -> Scenery:
    """The pool as the camera sees it, centred on the surface origin (NED), +x north.

    Floor at z = ``depth_m``, walls at x = ±length/2 and y = ±width/2, surface at z = 0. In
    front of a vehicle at the origin looking north: three amphorae (two upright, one lying),
    a yellow pipe across the floor and a valve panel on legs facing south.

    Args:
        length_m: extent along north [m].
        width_m: extent along east [m].
        depth_m: water depth [m].
    """
    hl, hw, d = 0.5 * length_m, 0.5 * width_m, depth_m
    textures = {
        "floor": _floor_texture(length_m, width_m),
        "wall_ns": _wall_texture(width_m, d, 20),
        "wall_ew": _wall_texture(length_m, d, 40),
        "surface": _surface_texture(length_m, width_m),
        "panel": _panel_texture(),
    }
    quads: tuple[Quad, ...] = (
        Quad((hl, -hw, d), (0.0, width_m, 0.0), (-length_m, 0.0, 0.0), "floor"),
        Quad((hl, -hw, 0.0), (0.0, width_m, 0.0), (0.0, 0.0, d), "wall_ns"),  # north
        Quad((-hl, hw, 0.0), (0.0, -width_m, 0.0), (0.0, 0.0, d), "wall_ns"),  # south
        Quad((-hl, -hw, 0.0), (length_m, 0.0, 0.0), (0.0, 0.0, d), "wall_ew"),  # west
        Quad((hl, hw, 0.0), (-length_m, 0.0, 0.0), (0.0, 0.0, d), "wall_ew"),  # east
        Quad((-hl, -hw, 0.0), (0.0, width_m, 0.0), (length_m, 0.0, 0.0), "surface"),
    )
    panel_n, panel_top = min(3.8, hl - 0.3), d - 1.3
    quads += (Quad((panel_n - 0.035, -0.5, panel_top), (0.0, 1.0, 0.0), (0.0, 0.0, 0.8), "panel"),)
    steel, yellow = (0.45, 0.47, 0.5), (0.95, 0.75, 0.1)
    solids = [
        Solid("box", (panel_n, 0.0, panel_top + 0.4), (0.06, 1.04, 0.84), steel),
        Solid("box", (panel_n, -0.45, d - 0.25), (0.05, 0.05, 0.5), steel),
        Solid("box", (panel_n, 0.45, d - 0.25), (0.05, 0.05, 0.5), steel),
        Solid(
            "cylinder",
            (panel_n - 0.05, 0.32, panel_top + 0.4),
            (0.06, 0.04),
            (0.8, 0.1, 0.1),
            (0.0, math.pi / 2, 0.0),
        ),
        Solid("cylinder", (2.2, 0.4, d - 0.08), (0.08, 3.0), yellow, (math.pi / 2, 0.0, 0.3)),
    ]
    solids += _amphora(3.0, -1.0, d, False, 0.8)
    solids += _amphora(3.3, -1.6, d, False, 0.6)
    solids += _amphora(2.6, 1.2, d, True, 0.7)
    return Scenery(quads=quads, solids=tuple(solids), textures=textures)
