"""What a run records of its images, and what it writes of them.

The vehicle node logs each image it captures (its number, capture time, the true pixels and
the encoded size) and which image each reply frame carried; the operator node logs each image
it completes (the frame that finished it and the decoded pixels) and its transfer counters
(:class:`ImageLog`). The image number never travels: the operator's record is matched to the
capture through the frame id of the chunk that completed it (recording only, as for commands
and odometry).

From the log: the picture quality (:func:`psnr_db`, :func:`roi_psnr_db` [dB], 8-bit peak),
``images.csv``, ``image_progress.csv``, ``images.npz`` and the ``images`` section of
``metrics.json`` (times [s] of simulated time, sizes [B]). The ``[images]`` section and the
builders of both ends are :mod:`testbed.run.images`'s; the strip of images is
:mod:`testbed.report.images`'s.
"""

from __future__ import annotations

import csv
import itertools
import math
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from testbed.imaging import decode
from testbed.protocol import ImageSettings

__all__ = [
    "IMAGE_COLUMNS",
    "CapturedImage",
    "ImageLog",
    "ReceivedImage",
    "image_metrics",
    "image_rows",
    "psnr_db",
    "roi_psnr_db",
    "write_images_csv",
    "write_images_npz",
    "write_progress_csv",
]


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
