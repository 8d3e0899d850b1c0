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

import csv
import itertools
import math
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from testbed.config import check
from testbed.imaging import decode
from testbed.imaging.header import BASE_SIZE as HEADER_BASE_BYTES
from testbed.imaging.header import ROI_SIZE as HEADER_ROI_BYTES
from testbed.operator.video import ImageConsole
from testbed.protocol import ImageSettings, max_image_bytes
from testbed.vehicle.vehicle import Vehicle
from testbed.vehicle.video import CodedImage, ImageSource

__all__ = [
    "IMAGE_COLUMNS",
    "CapturedImage",
    "ImageLog",
    "ImageSettingsChange",
    "ImagesSection",
    "ReceivedImage",
    "image_console",
    "image_metrics",
    "image_rows",
    "image_source_factory",
    "psnr_db",
    "roi_psnr_db",
    "settings_schedule",
    "write_images_csv",
    "write_images_npz",
    "write_progress_csv",
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


@dataclass(frozen=True, slots=True)
class CapturedImage:
    """An image the vehicle captured and coded.

    Attributes:
        number: capture count, from 0.
        t_s: capture time [s].
        pixels: (h, w) uint8 grey, as rendered.
        encoded_bytes: coded size within the budget [B] (without the 2-B image CRC).
        settings: the coder settings it was coded with (budget, region of interest, shift), or
            None when not recorded.
        coded: the coded image (CRC excluded), or empty when not recorded.
    """

    number: int
    t_s: float
    pixels: np.ndarray
    encoded_bytes: int
    settings: ImageSettings | None = None
    coded: bytes = b""


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
        progress: ``(t_s, number, bytes)`` each time the operator's picture grew: the coded
            bytes of image ``number`` (−1 unknown) from its start it held at ``t_s`` [s].
        counters: transfer counters (``chunks_sent``, ``chunks_received``, ``crc_failures``,
            ``spoiled``, ``duplicates``, ``inconsistent``, ``settings_sent``,
            ``settings_acknowledged``).
    """

    captured: dict[int, CapturedImage] = field(default_factory=dict)
    reply_images: dict[int, int] = field(default_factory=dict)
    received: list[ReceivedImage] = field(default_factory=list)
    progress: list[tuple[float, int, int]] = field(default_factory=list)
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


def roi_psnr_db(reference: np.ndarray, image: np.ndarray, settings: ImageSettings | None) -> float:
    """:func:`psnr_db` inside the region of interest the image was coded with [dB], or NaN for
    an image coded without one (no settings, or a shift of 0) or of another shape."""
    if settings is None or settings.roi_shift == 0 or reference.shape != image.shape:
        return math.nan
    height, width = reference.shape[:2]
    rows = slice(min(settings.y0, height - 1), min(settings.y1, height - 1) + 1)
    columns = slice(min(settings.x0, width - 1), min(settings.x1, width - 1) + 1)
    return psnr_db(reference[rows, columns], image[rows, columns])


IMAGE_COLUMNS = (
    "number",
    "captured_s",
    "completed_s",
    "latency_s",
    "encoded_bytes",
    "chunks",
    "budget_bytes",
    "roi",
    "roi_shift",
    "psnr_db",
    "roi_psnr_db",
    "replies",
)
"""The columns of ``images.csv`` (:func:`image_rows`)."""


def image_rows(log: ImageLog, chunk_bytes: int) -> list[list[object]]:
    """One row per captured image, in capture order (the columns of :data:`IMAGE_COLUMNS`).

    ``completed_s`` and ``latency_s`` (capture to completion) are empty for an image the
    operator did not complete; ``chunks`` is the replies it takes, ⌈(coded + 2-B CRC) /
    chunk⌉; ``roi`` is ``x0 y0 x1 y1`` (empty without one); ``psnr_db`` is empty for an image
    not completed, ``undecodable`` for one whose bits decode to no picture, 99 for a lossless
    one (as in ``metrics.json``); ``roi_psnr_db`` the same inside the region of interest;
    ``replies`` the vehicle's replies that carried a chunk of it (``chunks`` plus the chunks
    sent again: selective repeat on a lossy link needs ≈ chunks / q, q a cycle's delivery
    probability).
    """
    completed = {image.number: image for image in log.received if image.number >= 0}
    replies = Counter(log.reply_images.values())
    rows: list[list[object]] = []
    for number in sorted(log.captured):
        source = log.captured[number]
        settings = source.settings
        roi = ""
        if settings is not None and settings.roi_shift:
            roi = f"{settings.x0} {settings.y0} {settings.x1} {settings.y1}"
        row: list[object] = [
            number,
            f"{source.t_s:.6f}",
            "",
            "",
            source.encoded_bytes,
            -(-(source.encoded_bytes + 2) // chunk_bytes),
            "" if settings is None else settings.budget_bytes,
            roi,
            "" if settings is None else (settings.roi_shift if roi else 0),
            "",
            "",
            replies.get(number, 0),
        ]
        image = completed.get(number)
        if image is not None:
            row[2] = f"{image.t_s:.6f}"
            row[3] = f"{image.t_s - source.t_s:.6f}"
            psnr = psnr_db(source.pixels, image.pixels)
            if math.isnan(psnr):
                row[9] = "undecodable"
            else:
                row[9] = f"{min(99.0, psnr):.3f}"
                inside = roi_psnr_db(source.pixels, image.pixels, settings)
                row[10] = "" if math.isnan(inside) else f"{min(99.0, inside):.3f}"
        rows.append(row)
    return rows


def write_images_csv(log: ImageLog, chunk_bytes: int, path: Path) -> None:
    """Write ``images.csv``: :func:`image_rows` under the header :data:`IMAGE_COLUMNS`."""
    with path.open("w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle, lineterminator="\n")
        writer.writerow(IMAGE_COLUMNS)
        writer.writerows(image_rows(log, chunk_bytes))


PROGRESS_COLUMNS = ("t_s", "number", "bytes", "age_s", "psnr_db")
"""The columns of ``image_progress.csv`` (:func:`progress_rows`)."""


def progress_rows(log: ImageLog) -> list[list[object]]:
    """One row each time the operator's picture grew (the paper's progressive feedback: the
    picture sharpens as chunks arrive), in time order: ``t_s`` [s], the image's ``number``,
    the coded ``bytes`` from its start the operator held, ``age_s`` (how old the scene it
    shows is: t − capture [s]) and ``psnr_db`` of those bytes decoded against the captured
    picture (empty before the coder's header is in; 99 lossless, as in ``images.csv``)."""
    rows: list[list[object]] = []
    for t_s, number, size in log.progress:
        source = log.captured.get(number)
        if source is None or not source.coded:
            rows.append([f"{t_s:.6f}", number, size, "", ""])
            continue
        height, width = source.pixels.shape[:2]
        picture = decode(source.coded[:size], max_pixels=height * width)
        psnr = psnr_db(source.pixels, picture)
        shown = "" if math.isnan(psnr) else f"{min(99.0, psnr):.3f}"
        rows.append([f"{t_s:.6f}", number, size, f"{t_s - source.t_s:.6f}", shown])
    return rows


def write_progress_csv(log: ImageLog, path: Path) -> None:
    """Write ``image_progress.csv``: :func:`progress_rows` under :data:`PROGRESS_COLUMNS`."""
    with path.open("w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle, lineterminator="\n")
        writer.writerow(PROGRESS_COLUMNS)
        writer.writerows(progress_rows(log))


def write_images_npz(log: ImageLog, path: Path) -> None:
    """Write ``images.npz`` (``numpy.load``): every captured picture and every picture the
    operator completed, for measures of one's own (SSIM, a detector's score, a video).

    Arrays: ``captured`` (k, h, w) uint8 grey as rendered, ``captured_number`` (k,) and
    ``captured_s`` (k,) [s]; ``received`` (m, h, w) uint8 as the operator decoded them (zeros
    where the bits decode to no picture), ``received_number`` (m,) (the captured number; −1
    unknown), ``completed_s`` (m,) [s] and ``received_decodable`` (m,) bool. Compressed, and
    the same bytes for the same run.
    """
    numbers = sorted(log.captured)
    shape = next((log.captured[n].pixels.shape for n in numbers), (0, 0))
    captured = np.zeros((len(numbers), *shape), dtype=np.uint8)
    for row, number in enumerate(numbers):
        captured[row] = log.captured[number].pixels
    received = np.zeros((len(log.received), *shape), dtype=np.uint8)
    decodable = np.zeros(len(log.received), dtype=np.bool_)
    for row, image in enumerate(log.received):
        if image.pixels.shape == shape:
            received[row], decodable[row] = image.pixels, True
    with path.open("wb") as handle:
        np.savez_compressed(
            handle,
            captured=captured,
            captured_number=np.array(numbers, dtype=np.int64),
            captured_s=np.array([log.captured[n].t_s for n in numbers], dtype=np.float64),
            received=received,
            received_number=np.array([r.number for r in log.received], dtype=np.int64),
            completed_s=np.array([r.t_s for r in log.received], dtype=np.float64),
            received_decodable=decodable,
        )


def _summary(values: list[float], *keys: str) -> dict[str, float]:
    """``mean``/``p95``/``max``/``min`` (those named) of ``values``; NaN for none."""
    array = np.asarray(values, dtype=float)
    if not array.size:
        return dict.fromkeys(keys, math.nan)
    reducers = {
        "mean": lambda a: float(a.mean()),
        "p95": lambda a: float(np.percentile(a, 95)),
        "max": lambda a: float(a.max()),
        "min": lambda a: float(a.min()),
    }
    return {key: reducers[key](array) for key in keys}


def image_metrics(log: ImageLog, sim_s: float) -> dict[str, Any]:
    """The ``images`` section of ``metrics.json``, over the whole run (images flow from the
    first order; ``metrics.settle_s`` does not apply).

    Keys: ``captured``, ``completed``, ``per_minute`` (completed per minute of simulated time:
    the image in flight at the end, and the start-up before the first, count against it),
    ``completion_interval_s`` {``mean``} between consecutive completions (60 / it is the
    steady rate), ``latency_s`` {``mean``, ``p95``, ``max``} from capture to completion,
    ``bytes_delivered`` (coded bytes of the completed images), ``undecodable`` (completed
    images whose bits decode to no picture of the captured size: a budget too small for the
    coder's header), ``psnr_db`` {``mean``, ``min``} of each other completed image against its
    capture (a lossless image counts as 99 dB; NaN when there is none), ``roi_psnr_db``
    {``mean``, ``min``} the same inside the region of interest, over the images coded with one,
    and the transfer counters.
    """
    latencies: list[float] = []
    psnrs: list[float] = []
    inside: list[float] = []
    undecodable = 0
    for image in log.received:
        source = log.captured.get(image.number)
        if source is None:
            continue
        latencies.append(image.t_s - source.t_s)
        psnr = psnr_db(source.pixels, image.pixels)
        if math.isnan(psnr):  # decoded to another shape (a budget too small for the header)
            undecodable += 1
            continue
        psnrs.append(min(99.0, psnr))
        roi = roi_psnr_db(source.pixels, image.pixels, source.settings)
        if not math.isnan(roi):
            inside.append(min(99.0, roi))
    times = [image.t_s for image in log.received]
    intervals = [later - earlier for earlier, later in itertools.pairwise(times)]
    return {
        "captured": len(log.captured),
        "completed": len(log.received),
        "per_minute": 60.0 * len(log.received) / sim_s if sim_s > 0 else math.nan,
        "completion_interval_s": _summary(intervals, "mean"),
        "latency_s": _summary(latencies, "mean", "p95", "max"),
        "bytes_delivered": sum(image.encoded_bytes for image in log.received),
        "undecodable": undecodable,
        "psnr_db": _summary(psnrs, "mean", "min"),
        "roi_psnr_db": _summary(inside, "mean", "min"),
        **{key: log.counters[key] for key in sorted(log.counters)},
    }
