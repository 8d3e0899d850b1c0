"""Image feedback in a run: the ``[images]`` section and the builders of both ends.

**The section.** With ``enabled = true`` the vehicle captures a frame with its camera
(``[vehicle.camera]``), codes it with :mod:`testbed.imaging` within the operator's byte budget
and sends it in ``chunk_bytes`` chunks, one per reply, the operator asking for its first missing
chunk (:mod:`testbed.protocol.image_transfer`). The operator's coder settings (budget, region of
interest, shift) travel as ``ImageSettings`` orders: the scenario's at the start, then each
entry of ``changes`` at its time.

**The ends.** :func:`image_source_factory` builds the vehicle's
:class:`~testbed.vehicle.video.ImageSource` on its camera; :func:`image_console` the operator's
:class:`~testbed.operator.video.ImageConsole` with the settings schedule.

**The record.** What a run records of its images (captures, completions, the picture's
growth, transfer counters) and the files and metrics made of it are
:mod:`testbed.run.image_record`'s; the strip of images is :mod:`testbed.report.images`'s.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from testbed.config import check
from testbed.imaging.header import BASE_SIZE as HEADER_BASE_BYTES
from testbed.imaging.header import ROI_SIZE as HEADER_ROI_BYTES
from testbed.operator.video import ImageConsole
from testbed.protocol import ImageSettings, max_image_bytes
from testbed.vehicle.vehicle import Vehicle
from testbed.vehicle.video import CodedImage, ImageSource

__all__ = [
    "ImageSettingsChange",
    "ImagesSection",
    "image_console",
    "image_source_factory",
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
        check(
            self.t_s >= 0.0 and math.isfinite(self.t_s),
            "t_s",
            f"must be a finite time ≥ 0 [s], got {self.t_s}",
        )
        if self.budget_bytes is not None:
            check(self.budget_bytes >= 1, "budget_bytes", f"must be ≥ 1, got {self.budget_bytes}")
        _check_roi(self.roi)
        if self.roi_shift is not None:
            check(0 <= self.roi_shift <= 15, "roi_shift", f"must be 0..15, got {self.roi_shift}")
        check(
            not (self.roi == () and self.roi_shift),
            "roi_shift",
            f"{self.roi_shift} raises no region: this change clears it (roi = [])",
        )


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
        where = ["", *(f"changes[{i}]." for i in range(len(self.changes)))]
        shift_set = (False, *(c.roi_shift is not None for c in self.changes))
        for at, set_here, (_, _, roi, shift) in zip(
            where, shift_set, _settings_in_force(self), strict=True
        ):
            check(
                not roi or shift > 0,
                f"{at}roi_shift" if set_here else f"{at}roi",
                f"the region {list(roi)} needs roi_shift ≥ 1 to be coded (roi_shift is 0: the "
                "coder would ignore it)",
            )
        for at, (_, settings) in zip(where, settings_schedule(self), strict=True):
            key = f"{at}budget_bytes"
            least = _least_budget(settings)
            check(
                settings.budget_bytes >= least,
                key,
                f"must be ≥ {least} (the coder's {least - 1}-B header"
                f"{' with a region of interest' if settings.roi_shift else ''} and a byte of "
                f"image), got {settings.budget_bytes}",
            )


def _least_budget(settings: ImageSettings) -> int:
    """The smallest budget that codes any of the image [B]: the coder's header, one more."""
    header = HEADER_BASE_BYTES + (HEADER_ROI_BYTES if settings.roi_shift else 0)
    return header + 1


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


def _settings_in_force(
    images: ImagesSection,
) -> list[tuple[float, int, tuple[int, ...], int]]:
    """``(t_s, budget_bytes, roi, roi_shift)`` in force from the start and from each change
    (a change's keys left out keep their previous value)."""
    budget, roi, shift = images.budget_bytes, images.roi, images.roi_shift
    steps = [(0.0, budget, roi, shift)]
    for change in images.changes:
        budget = budget if change.budget_bytes is None else change.budget_bytes
        roi = roi if change.roi is None else change.roi
        shift = shift if change.roi_shift is None else change.roi_shift
        steps.append((change.t_s, budget, roi, shift))
    return steps


def settings_schedule(images: ImagesSection) -> list[tuple[float, ImageSettings]]:
    """The operator's ``ImageSettings`` orders: the section's at 0 s, then each change."""
    schedule: list[tuple[float, ImageSettings]] = []
    for t_s, budget, roi, shift in _settings_in_force(images):
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
