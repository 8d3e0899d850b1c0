"""Image feedback in a run: the ``[images]`` section, the builders of both ends, and what a
run records of its images (the ``images`` section of ``metrics.json``).

**The section.** With ``enabled = true`` the vehicle captures a frame with its camera
(``[vehicle.camera]``), codes it with :mod:`testbed.imaging` within the operator's byte budget
and sends it in ``chunk_bytes`` chunks, one per reply, the operator asking for its first missing
chunk (:mod:`testbed.protocol.image_transfer`). The operator's coder settings (budget, region of
interest, shift) travel as ``ImageSettings`` orders: the scenario's at the start, then each
entry of ``changes`` at its time.

**The ends.** :func:`image_source_factory` builds the vehicle's
:class:`~testbed.vehicle.video.ImageSource` on its camera; :func:`image_console` the operator's
:class:`~testbed.operator.video.ImageConsole` with the settings schedule.

**The record.** The vehicle node logs each image it captures (its number, capture time, the
true pixels and the encoded size) and which image each reply frame carried; the operator node
logs each image it completes (the frame that finished it and the decoded pixels) and its
transfer counters. The image number never travels: the operator's record is matched to the
capture through the frame id of the chunk that completed it (recording only, as for commands
and odometry). The strip of images is :mod:`testbed.report.images`'s.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from testbed.config import check
from testbed.operator.video import ImageConsole
from testbed.protocol import ImageSettings, max_image_bytes
from testbed.vehicle.vehicle import Vehicle
from testbed.vehicle.video import CodedImage, ImageSource

__all__ = [
    "CapturedImage",
    "ImageLog",
    "ImageSettingsChange",
    "ImagesSection",
    "ReceivedImage",
    "image_console",
    "image_metrics",
    "image_source_factory",
    "psnr_db",
    "settings_schedule",
]


def _check_roi(roi: tuple[int, ...] | None) -> None:
    """A region of interest is empty (none) or four inclusive pixel bounds in order."""
    if not roi:
        return
    check(len(roi) == 4, "roi", f"must have 4 values or none, got {list(roi)}")
    x0, y0, x1, y1 = roi
    check(
        all(0 <= v <= 1023 for v in roi) and x0 <= x1 and y0 <= y1,
        "roi",
        f"must be [x0, y0, x1, y1] inclusive pixels, 0..1023, x0 ≤ x1, y0 ≤ y1, got {list(roi)}",
    )


@dataclass(frozen=True, slots=True)
class ImageSettingsChange:
    """New coder settings the operator sends at ``t_s`` (an ``ImageSettings`` order).

    Keys left out keep their previous value; ``roi = []`` clears the region of interest.

    Attributes:
        t_s: when the operator sends them [s], ≥ 0.
        budget_bytes: byte budget of the next images [B].
        roi: region of interest [x0, y0, x1, y1] (inclusive pixels), or () for none.
        roi_shift: bit planes the region is raised by, 0..15.
    """

    t_s: float
    budget_bytes: int | None = None
    roi: tuple[int, ...] | None = None
    roi_shift: int | None = None

    def __post_init__(self) -> None:
        check(self.t_s >= 0.0 and math.isfinite(self.t_s), "t_s", f"must be ≥ 0, got {self.t_s}")
        if self.budget_bytes is not None:
            check(self.budget_bytes >= 1, "budget_bytes", f"must be ≥ 1, got {self.budget_bytes}")
        _check_roi(self.roi)
        if self.roi_shift is not None:
            check(0 <= self.roi_shift <= 15, "roi_shift", f"must be 0..15, got {self.roi_shift}")


@dataclass(frozen=True, slots=True)
class ImagesSection:
    """Image feedback settings.

    Attributes:
        enabled: send images in the replies (needs ``vehicle.camera.enabled``, the teleop codec
            and token passing).
        chunk_bytes: image bytes per reply [B], 1..150 (40 in the paper: a 60-B reply frame).
        selective_repeat: True: the operator asks for its first missing chunk and lost chunks
            are sent again. False: the paper's behaviour, chunks streamed in order and an image
            with a lost chunk is spoiled.
        budget_bytes: byte budget of each image [B], ≤ 64·chunk_bytes − 2.
        roi: region of interest [x0, y0, x1, y1] (inclusive pixels) or () for none.
        roi_shift: bit planes the region is raised by (Maxshift), 0..15.
        changes: settings the operator sends later, in time order.
        strip_images: images shown in the run's ``images.png`` strip (captured over received),
            0..100.
    """

    enabled: bool = False
    chunk_bytes: int = 40
    selective_repeat: bool = True
    budget_bytes: int = 1200
    roi: tuple[int, ...] = ()
    roi_shift: int = 0
    changes: tuple[ImageSettingsChange, ...] = ()
    strip_images: int = 6

    def __post_init__(self) -> None:
        chunk = self.chunk_bytes
        check(1 <= chunk <= 150, "chunk_bytes", f"must be 1..150, got {chunk}")
        limit = max_image_bytes(self.chunk_bytes)
        check(
            1 <= self.budget_bytes <= limit,
            "budget_bytes",
            f"must be 1..{limit} (64 chunks of {self.chunk_bytes} B minus the 2-B CRC), "
            f"got {self.budget_bytes}",
        )
        _check_roi(self.roi)
        check(0 <= self.roi_shift <= 15, "roi_shift", f"must be 0..15, got {self.roi_shift}")
        check(
            0 <= self.strip_images <= 100,
            "strip_images",
            f"must be 0..100, got {self.strip_images}",
        )
        for i, change in enumerate(self.changes):
            if change.budget_bytes is not None:
                check(
                    change.budget_bytes <= limit,
                    f"changes[{i}].budget_bytes",
                    f"must be ≤ {limit} (64 chunks of {self.chunk_bytes} B minus the CRC), "
                    f"got {change.budget_bytes}",
                )
            if i:
                check(
                    change.t_s >= self.changes[i - 1].t_s,
                    f"changes[{i}].t_s",
                    f"must be ≥ the previous change's t_s ({self.changes[i - 1].t_s})",
                )


def image_source_factory(images: ImagesSection) -> Callable[..., ImageSource]:
    """Builds the vehicle's image source on its camera (``VehicleNode(image_source=...)``)."""

    def build(vehicle: Vehicle, on_image: Callable[[CodedImage], None]) -> ImageSource:
        def capture() -> tuple[float, np.ndarray] | None:
            image = vehicle.capture_image()
            return None if image is None else (image.time_s, image.pixels)

        camera = vehicle.config.camera
        return ImageSource(
            capture,
            width_px=camera.width_px,
            height_px=camera.height_px,
            chunk_bytes=images.chunk_bytes,
            selective_repeat=images.selective_repeat,
            settings=settings_schedule(images)[0][1],  # both ends configured alike
            on_image=on_image,
        )

    return build


def settings_schedule(images: ImagesSection) -> list[tuple[float, ImageSettings]]:
    """The operator's ``ImageSettings`` orders: the section's at 0 s, then each change."""
    budget, roi, shift = images.budget_bytes, images.roi, images.roi_shift
    schedule: list[tuple[float, ImageSettings]] = []
    for t_s, change in [(0.0, None), *((c.t_s, c) for c in images.changes)]:
        if change is not None:
            budget = budget if change.budget_bytes is None else change.budget_bytes
            roi = roi if change.roi is None else change.roi
            shift = shift if change.roi_shift is None else change.roi_shift
        x0, y0, x1, y1 = roi if roi else (0, 0, 0, 0)
        schedule.append((t_s, ImageSettings(x0, y0, x1, y1, shift if roi else 0, True, budget)))
    return schedule


def image_console(images: ImagesSection, max_pixels: int) -> ImageConsole | None:
    """The operator's image console for the section (decoding images of at most
    ``max_pixels``, the camera's width × height), or None when images are off."""
    if not images.enabled:
        return None
    return ImageConsole(
        chunk_bytes=images.chunk_bytes,
        selective_repeat=images.selective_repeat,
        schedule=settings_schedule(images),
        max_pixels=max_pixels,
    )


@dataclass(frozen=True, slots=True)
class CapturedImage:
    """An image the vehicle captured and coded.

    Attributes:
        number: capture count, from 0.
        t_s: capture time [s].
        pixels: (h, w) uint8 grey, as rendered.
        encoded_bytes: coded size within the budget [B] (without the 2-B image CRC).
    """

    number: int
    t_s: float
    pixels: np.ndarray
    encoded_bytes: int


@dataclass(frozen=True, slots=True)
class ReceivedImage:
    """An image the operator completed (all chunks in, image CRC checked).

    Attributes:
        number: the captured image's number (from the completing frame's id; -1 if unknown).
        t_s: completion time [s].
        pixels: (h, w) uint8 grey, decoded.
        encoded_bytes: the image's coded size [B] (CRC excluded).
    """

    number: int
    t_s: float
    pixels: np.ndarray
    encoded_bytes: int


@dataclass(slots=True)
class ImageLog:
    """Append-only image record of one run.

    Attributes:
        captured: image number → the captured image.
        reply_images: downlink frame id → number of the image whose chunk the reply carried.
        received: completed images in completion order.
        counters: transfer counters (``chunks_sent``, ``chunks_received``, ``crc_failures``,
            ``spoiled``, ``duplicates``, ``settings_sent``, ``settings_applied``).
    """

    captured: dict[int, CapturedImage] = field(default_factory=dict)
    reply_images: dict[int, int] = field(default_factory=dict)
    received: list[ReceivedImage] = field(default_factory=list)
    counters: dict[str, int] = field(default_factory=dict)

    def count(self, key: str, n: int = 1) -> None:
        """Add ``n`` to counter ``key``."""
        self.counters[key] = self.counters.get(key, 0) + n


def psnr_db(reference: np.ndarray, image: np.ndarray) -> float:
    """Peak signal-to-noise ratio of ``image`` against ``reference`` [dB], 8-bit peak 255.

    Identical images give ``inf``; images of different shapes give NaN.
    """
    if reference.shape != image.shape:
        return math.nan
    error = reference.astype(np.float64) - image.astype(np.float64)
    mse = float(np.mean(error * error))
    return math.inf if mse == 0.0 else 10.0 * math.log10(255.0**2 / mse)


def image_metrics(log: ImageLog, sim_s: float) -> dict[str, Any]:
    """The ``images`` section of ``metrics.json``.

    Keys: ``captured``, ``completed``, ``per_minute`` (completed per minute of simulated time),
    ``latency_s`` {``mean``, ``p95``, ``max``} from capture to completion, ``bytes_delivered``
    (coded bytes of the completed images), ``undecodable`` (completed images whose bits decode
    to no picture of the captured size: a budget too small for the coder's header),
    ``psnr_db`` {``mean``, ``min``} of each other completed image against its capture (a
    lossless image counts as 99 dB; NaN when there is none), and the transfer counters.
    """
    latencies: list[float] = []
    psnrs: list[float] = []
    undecodable = 0
    for image in log.received:
        source = log.captured.get(image.number)
        if source is None:
            continue
        latencies.append(image.t_s - source.t_s)
        psnr = psnr_db(source.pixels, image.pixels)
        if math.isnan(psnr):  # decoded to another shape (a budget too small for the header)
            undecodable += 1
        else:
            psnrs.append(min(99.0, psnr))
    nan = math.nan
    latency = np.asarray(latencies, dtype=float)
    quality = np.asarray([p for p in psnrs if math.isfinite(p)], dtype=float)
    return {
        "captured": len(log.captured),
        "completed": len(log.received),
        "per_minute": 60.0 * len(log.received) / sim_s if sim_s > 0 else nan,
        "latency_s": {
            "mean": float(latency.mean()) if latency.size else nan,
            "p95": float(np.percentile(latency, 95)) if latency.size else nan,
            "max": float(latency.max()) if latency.size else nan,
        },
        "bytes_delivered": sum(image.encoded_bytes for image in log.received),
        "undecodable": undecodable,
        "psnr_db": {
            "mean": float(quality.mean()) if quality.size else nan,
            "min": float(quality.min()) if quality.size else nan,
        },
        **{key: log.counters[key] for key in sorted(log.counters)},
    }
