"""The ``[images]`` section of a scenario: visual feedback over the narrow link.

With ``enabled = true`` the vehicle captures a frame with its camera (``[vehicle.camera]``),
codes it with :mod:`testbed.imaging` within the operator's byte budget and sends it in
``chunk_bytes`` chunks, one per reply, the operator asking for its first missing chunk
(:mod:`testbed.protocol.image_transfer`). The operator's coder settings (budget, region of
interest, shift) travel as ``ImageSettings`` orders: the scenario's at the start, then each entry
of ``changes`` at its time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from testbed.config import check
from testbed.protocol import max_image_bytes

__all__ = ["ImageSettingsChange", "ImagesSection"]


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
        strip_images: images shown in the run's ``images.png`` strip (captured over received).
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
        check(self.strip_images >= 0, "strip_images", f"must be ≥ 0, got {self.strip_images}")
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
